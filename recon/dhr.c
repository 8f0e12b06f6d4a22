/* dhr: the directional-hemispherical reflectance of the final model and its uncertainty (measurement noise by
 * Monte Carlo, interpolation error by the GP posterior, quadrature). */
#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/bigbuf.h"
#include "recon/recon_int.h"
#include "recon/rng.h"

/* DHR quadrature: Gauss-Legendre 32 × 48 azimuth midpoints (error discussed at recon_albedo). */
#define DHR_NMU 32
#define DHR_NPHI 48
/* Misfit counted beyond 3σ_g and 0.02 in the transformed space (2 % in f for the log transform). */
#define MISFIT_Z 3.0
#define MISFIT_MIN 0.02
#define DHR_FLOOR 1e-300  /* refined to 1e-3 relative: an absolute floor let two rules agree on a missed lobe */

/*
 * DHR(θi, λ) = albedo of the final (energy-scaled) model, with the DHR quadrature above.
 * Uncertainty from two estimates of the same error, σ² = max(σ_noise, σ_model)² + σ_quad²:
 *  - σ_noise, the measurement noise: the reconstruction is not linear in the data (the transform that
 *    guarantees f ≥ 0), so the exact formula Var = Σ c_k² σ_k² does not apply. Monte Carlo instead: each
 *    draw perturbs the transformed data by its standard uncertainty (g + σ_g z, z ~ N(0, 1) independent;
 *    σ_g from the given sigmas by the delta method, or the channel's leave-one-out RMS when the file has
 *    none), re-centres, solves with the ONE Cholesky factor of K + Λ (refactored once from the stored
 *    model), and integrates. The energy factor of the nominal model is kept fixed across draws; the trend's
 *    coefficients are refitted in every draw (refit_trend), its roughness is kept.
 *  - σ_model, the interpolation error between the samples (deterministic for a given sampling plan, e.g.
 *    a lobe narrower than the azimuth step; the noise draws cannot see it). The smoothed RBF interpolant is
 *    the posterior mean of the Gaussian-process reading g − μ ~ GP(0, α_λ K), noise α_λ η Λ, so the error
 *    of the linear functional DHR ≈ Σ_q c_q g(x_q) (c_q = quadrature weight × energy factor × df̂/dg at
 *    the nominal model: the delta method through the transform) has the posterior ("kriging") variance
 *      σ_model² = α_λ (cᵀ K_QQ c − bᵀ A⁻¹ b),  b = K_nQ c,  A = K + Λ,
 *    the same A and factor as the fit. The amplitude α_λ is not a free constant: it is estimated from
 *    Rippa's leave-one-out residuals of the channel, which the GP predicts to have variance α_λ/(A⁻¹)_kk:
 *      α_λ = mean_k e_k² (A⁻¹)_kk = mean_k (A⁻¹(g − μ))_k² / (A⁻¹)_kk
 *    (the cross-validation estimate of the scale: it calibrates the error bars on the errors the model
 *    actually makes when a sample is held out). Measured in tests/bench/bench_dhr_honesty.py.
 * The reported value is the nominal model's DHR. σ_model is the GP's whole posterior variance: it already
 * contains the data's noise (through η Λ in A, and through the noisy held-out residuals that set α_λ), so
 * adding σ_noise to it counts the noise twice: measured (bench_dhr_honesty, 8 seeds × 66 wavelengths) the
 * root sum of squares gave z RMS 0.52-0.77 on all three simulator materials (σ 1.3-1.9× too large; 0.68 on
 * the white reference, whose error is pure noise), the larger of the two 0.62-1.02 (paint at 60°: 1.43,
 * a bias of the trend's Fresnel shape). The Monte-Carlo σ_noise stays as a floor, for when the GP's noise
 * model (η Λ) is smaller than the measured noise. σ_quad (quadrature) is independent and added.
 * Beyond the plan's last observation zenith the model is an extrapolation of its form that no sample checks: where
 * the last ring of samples, held out, misses the rest's prediction by a good part of the kriging amplitude
 * (recon_edge_size), σ_X (the model's own change from the edge to each node beyond it, × RECON_EXTRAP_K, summed over
 * the band: recon_int.h) joins the kriging σ in quadrature and is reported in its part (so select's accounting keeps
 * it); recon/reconstruction.md, sessions 12-13. Where the fit's admissibility rule, not the data, set the trend lobe's
 * width, the DHR at the data's own width is a second reading (width_sd): that distance joins the kriging σ in
 * quadrature, and σ_model = max(that, σ_E) (session 18); likewise where the rule rejected the kind that fits the data
 * (the data's best reading over the fit's one-roughness kinds, width_sd).
 */
/* σ_model² of the DHR at one incidence (see recon_dhr_ex): vmod[l] = c_lᵀ K_QQ c_l − b_lᵀ A⁻¹ b_l with
 * c = C[q*L + l] (Q nodes c6, the amplitude √α already folded in), b = K_nQ c (Kq[q*n + k]), A the Cholesky
 * factor; scratch KQQ[Q*Q], soaQ[6Q], U[Q*L], Bt[L*n], X[L*n]. */
static int model_variance(const struct recon_model *m, size_t Q, const double *c6, const double *Kq, const double *A,
			  const double *C, double *KQQ, double *soaQ, double *U, double *Bt,
			  double *X, double *vmod, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl;
	rbf_soa(Q, c6, soaQ);
	rbf_kmatrix_soa(m->kernel, m->shape, Q, c6, Q, soaQ, KQQ);
	cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, (int)Q, (int)L, (int)Q, 1.0, KQQ, (int)Q, C, (int)L, 0.0,
		    U, (int)L);
	cblas_dgemm(CblasRowMajor, CblasTrans, CblasNoTrans, (int)L, (int)n, (int)Q, 1.0, C, (int)L, Kq, (int)n, 0.0,
		    Bt, (int)n);
	memcpy(X, Bt, L * n * sizeof *X);
	if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)L, A, (lapack_int)n, X, (lapack_int)n) != 0)
		return acq_errf(err, ACQ_E_NUMERIC, "dhr: solve failed");
	for (size_t l = 0; l < L; l++) {
		double ckc = 0, bab = 0;
		for (size_t q = 0; q < Q; q++)
			ckc += C[q * L + l] * U[q * L + l];
		for (size_t k = 0; k < n; k++)
			bab += Bt[l * n + k] * X[l * n + k];
		double v = ckc - bab;
		vmod[l] = v > 0 && isfinite(v) ? v : 0.0;
	}
	return 0;
}

/*
 * At one incidence's Q nodes c6 (weights × energy factor in scale[q*L + l]): fold the GP amplitude into the
 * sensitivities C, α_λ where samples are near and α_λ + RECON_PRIOR_ALPHA where none is (recon_unseen: the prior
 * on the unseen part of the hemisphere); and add up the misfit of the
 * nearest sample over the nodes within RECON_PRIOR_R0 of it (nearest-neighbour quadrature, signed) into mis[L].
 * The misfit at a node: where the model holds the sample's feature (data/model within [1/2, 2], log transform) the
 * sample's relative miss times the model at the node (C = scale·(f̂ + ε) on entry, d f̂/d g): a peak the model has
 * but holds 7 % low is 7 % low near it, not by the peak's Δf over the whole neighbourhood (session 7: clear-coat's
 * grazing coat peaks, 68°/68°: data 37.8, model 35.1 sr⁻¹, made σ_misfit 0.022 at 60° against an error of 0.003);
 * elsewhere Δf itself (a feature the model lost, e.g. the Ward spike: its width is unknown, σ must say so).
 */
#define MISFIT_REL_MAX 2.0
struct unseen_in {
	double theta;        /* the incidence */
	const double *wt;    /* [Q] the rule's weights (cosθo dω, Σ = π) */
	const double *Y;     /* [Q × L] the nominal g − μ at the nodes, mud[L] its μ, tb the nodes' trend bases */
	const double *mud, *tb;
	double *aseen;       /* [L] scratch */
	double aedge;        /* recon_edge_size: the last ring's held-out misfit (recon_prior_pockets) */
};
static void unseen_and_misfit(const struct recon_model *m, size_t Q, const double *c6, const double *scale,
			      const double *alpha, const double *dfmis, const double *ratio, const struct unseen_in *in,
			      double *C, double *mis, double *senergy)
{
	size_t L = m->nwl;
	int rel = m->transform == RECON_T_LOG;
	double U = 0, Uw = 0, *aseen = in->aseen, *aunseen = senergy; /* Uw: U of the nodes a lobe can hide in */
	double reach = recon_energy_reach(recon_trend_width(m, 0));
	double ws = recon_trend_width(m, 1), wl = m->trend_alpha > 0 ? ws : INFINITY; /* no trend: no lobe shown */
	for (size_t l = 0; l < L; l++)
		aseen[l] = aunseen[l] = 0;
	for (size_t q = 0; q < Q; q++) {
		size_t k;
		double d = recon_nearest_centre(m, c6 + 6 * q, &k);
		if (d <= RECON_PRIOR_R0)
			for (size_t l = 0; l < L; l++) {
				double r = ratio[k * L + l];
				mis[l] += rel && r >= 1.0 / MISFIT_REL_MAX && r <= MISFIT_REL_MAX ? C[q * L + l] * (r - 1.0)
												 : scale[q * L + l] * dfmis[k * L + l];
			}
		double u = recon_unseen(d);
		double ue = recon_unseen_energy(d, reach);
		U += ue * in->wt[q];
		Uw += ue * in->wt[q] * recon_prior_lobe_hides(d, wl);
		for (size_t l = 0; l < L; l++) {
			double fv = scale[q * L + l] * untransform(m->transform, in->Y[q * L + l] + in->mud[l], m->eps[l],
								   trend_factor(m, in->tb + q * TREND_NB, l));
			aseen[l] += (1 - ue) * fv;
			aunseen[l] += ue * fv;
			C[q * L + l] *= sqrt(alpha[l] + u * RECON_PRIOR_ALPHA);
		}
	}
	double mir[6]; /* the mirror direction, where a specular lobe the samples missed would sit */
	rbf_canon(in->theta, 0.0, in->theta, M_PI, mir);
	double ph = fmax(recon_prior_pockets(U / M_PI, in->aedge, Uw / M_PI), recon_mirror_unseen(m, mir, ws));
	for (size_t l = 0; l < L; l++)
		senergy[l] = recon_prior_energy_sd(ph, aseen[l], aunseen[l]);
}

/*
 * Resolution in the incidence angle: the samples fix the model at the incidences they were taken at (every θi and,
 * by reciprocity, every θo of the data); between them the DHR is an interpolation the data do not check. A lobe
 * narrower than that spacing (a sharp specular lobe that moves with θi) shows as a DHR at θi far from the cubic
 * through the DHRs at the two sampled incidences below and the two above it (the line through the two
 * bracketing ones where fewer exist). For a resolved material the cubic is within O(h⁴) of the curve (a line
 * would not be: at 60° on a microfacet paint its curvature term alone made σ five times too large,
 * test_recon_honesty). Near the normal there is one sampled incidence below θi (8° between samples at 4° and
 * 12°) and the line counts the curve's curvature as unresolved structure (cloth-sheen and sharp-lobe at 8°: σ_res
 * 2.1e-4 and 7.2e-4 against errors of 2.6e-4 and 6.6e-4, z RMS 0.58 and 0.68). The DHR of an isotropic BRDF is
 * an even function of θi (incidence at −θ is incidence at θ turned by 180° about the normal), so the mirror
 * images −θ of the sampled incidences are nodes too, and the cubic through −12°, −4°, 4°, 12° follows an even
 * curvature exactly. The model's own DHR curve may instead have a kink at the normal (its canonical frame is
 * continuous there, not smooth: rough-backscatter at 8° gave 3.2e-4 with the mirrored cubic, 2.2e-5 with the
 * line), which the line follows exactly. The curve is resolved when either interpolant reproduces it, so
 * res[l] = min over the two of |DHR(θi) − interpolant|; 0 at a sampled incidence (within 0.25°) or outside the
 * sampled range.
 */
/*
 * The nominal DHR's quadrature (and the resolution term's DHRs at the sampled incidences): every channel's albedo at
 * θi by the adaptive rule, to TAB_TOL relative. With a trend lobe that the half-vector rule integrates (GGX, phong,
 * the coat kind's coat lobe: trend_hv_alpha), the lobe part T_lobe·e^g goes over half vectors (as in the energy
 * table: DHR_HV_NU² nodes doubled up to DHR_HV_NU_MAX², dense where the lobe is) and the rest, f̂ − T_lobe·e^g (the
 * same function, node by node), on the hemisphere rule, whose start then need not resolve the narrow lobe
 * (recon_lobe_rule with no_trend_lobe); the rest is refined relative to the whole (its floor per channel is the lobe
 * part's value). Both parts are the same integral split exactly, each to TAB_TOL: the DHR moves by ≲ 2·TAB_TOL
 * relative from the single rule's. Why: on the coat kind (α ≈ 0.05) the single rule started at 60 × 120 and doubled
 * to 120 × 240 to confirm it, per incidence; `brdf-recon dhr` at 651 wavelengths cost 13.3 s CPU against 9.0 s on a
 * GGX paint (session 9 profile: 47 % of the excess in that rule's GEMM).
 */
/* σ_quad's floor, relative, where the energy factor steps (a table bound above 1: never on the paper's plans): cut
 * there (quad.c energy_steps), the rules still converge only to about TAB_TOL/2, and their last step under-states
 * the error below a quarter of TAB_TOL (test_dynamic_range's spike, 106 seeds × 2 transforms × 4 channels of a
 * driver: 4 seeds with |error|/σ_quad > 4, up to 16, the errors 1e-4 to 4.3e-4 relative with σ_quad 1.4e-6 to
 * 3.3e-6). With the floor the largest z over those seeds is 1.7. */
#define DHR_STEP_FLOOR (0.25 * TAB_TOL)
#define DHR_HV_NU 16
#define DHR_HV_NU_MAX 256
struct dhr_quad {
	int split, nmu, nphi;
	struct albedo_ws ws, wl; /* hemisphere rule (the rest, or the whole); half vectors (the lobe) */
	double *lob, *dl;
};

static int dhr_quad_init(struct dhr_quad *dq, const struct recon_model *m, struct acq_err *err)
{
	size_t L = m->nwl, qmax;
	double lobe = recon_trend_lobe_coef(m);
	/* as the energy table: not on spiky models (leave-one-out RMS > 1 in ln f), whose e^g is not smooth away from
	 * the trend's lobe */
	int can = m->transform == RECON_T_LOG && trend_hv_alpha(m->trend, m->trend_alpha) > 0 && lobe >= 1e-4 &&
		  m->loo_rms <= 1.0;
	/* nor where the energy factor can step (a table bound above 1): the hemisphere rule cuts at its steps
	 * (quad.c energy_steps), the half-vector rule could not */
	for (size_t i = 0; can && m->ntab >= 2 && i < (m->ntab - 1) * L; i++)
		can = m->tab_alb[i] <= 1.0;
	/* split only when it is cheaper: the rules' nodes up to their usual stop (the start and one doubling, 5 × the
	 * start; the half-vector rule two, 21 × 16²: measured at every incidence on clear-coat and green paint). The
	 * GGX paint (α 0.12) keeps its single rule, 32 × 53 (8.5k nodes against 13k split); the coat kind (α 0.05)
	 * 60 × 120 (36k against 13k) */
	int nmu = DHR_NMU, nphi = DHR_NPHI, smu = DHR_NMU, sphi = DHR_NPHI;
	size_t qs;
	recon_lobe_rule(m, ALB_NMU_MAX, 0, &nmu, &nphi, &qmax);
	recon_lobe_rule(m, ALB_NMU_MAX, 1, &smu, &sphi, &qs);
	dq->split = can && 21.0 * DHR_HV_NU * DHR_HV_NU + 5.0 * smu * sphi < 5.0 * nmu * nphi;
	dq->nmu = dq->split ? smu : nmu;
	dq->nphi = dq->split ? sphi : nphi;
	if (dq->split)
		qmax = qs;
	if (recon_albedo_ws_init(&dq->ws, m, qmax, err))
		return -1;
	dq->ws.indep = 1; /* σ_quad from two rules that share no node (quad.c) */
	if (!dq->split)
		return 0;
	dq->ws.part = RECON_PART_REST;
	dq->lob = malloc(2 * L * sizeof *dq->lob);
	dq->dl = dq->lob ? dq->lob + L : NULL;
	if (!dq->lob)
		return acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory");
	if (recon_albedo_ws_init(&dq->wl, m, (size_t)DHR_HV_NU_MAX * DHR_HV_NU_MAX, err))
		return -1;
	dq->wl.part = RECON_PART_LOBE;
	return 0;
}

static void dhr_quad_free(struct dhr_quad *dq)
{
	recon_albedo_ws_free(&dq->ws);
	recon_albedo_ws_free(&dq->wl);
	free(dq->lob);
}

/* out[L] = every channel's DHR at theta (scaled model), diff[L] (may be NULL) the last refinement step, at least
 * DHR_STEP_FLOOR relative where the rule was cut at the energy factor's steps. */
static int dhr_quad(const struct recon_model *m, double theta, struct dhr_quad *dq, double *out, double *diff,
		    struct acq_err *err)
{
	size_t L = m->nwl;
	if (!dq->split) {
		if (recon_albedo_adaptive(m, theta, dq->nmu, dq->nphi, ALB_NMU_MAX, 0, 1, TAB_TOL, DHR_FLOOR, -HUGE_VAL,
					  &dq->ws, out, diff, err))
			return -1;
		for (size_t l = 0; l < L && diff && dq->ws.nstep > 0; l++) /* cut at the energy factor's steps */
			diff[l] = fmax(diff[l], DHR_STEP_FLOOR * fabs(out[l]));
		return 0;
	}
	if (recon_albedo_adaptive(m, theta, DHR_HV_NU, DHR_HV_NU, DHR_HV_NU_MAX, 0, 1, TAB_TOL, DHR_FLOOR, -HUGE_VAL,
				  &dq->wl, dq->lob, dq->dl, err))
		return -1;
	dq->ws.floor_ch = dq->lob;
	int rc = recon_albedo_adaptive(m, theta, dq->nmu, dq->nphi, ALB_NMU_MAX, 0, 1, TAB_TOL, DHR_FLOOR, -HUGE_VAL,
				       &dq->ws, out, diff, err);
	dq->ws.floor_ch = NULL;
	if (rc)
		return -1;
	for (size_t l = 0; l < L; l++) {
		out[l] += dq->lob[l];
		if (diff)
			diff[l] += dq->dl[l];
	}
	return 0;
}

#define RES_TOL (0.25 * M_PI / 180)
/* The interpolation nodes x[4] about theta (with the mirror images −a when mirror): 0 when theta is sampled or
 * outside the sampled range, else the node count (2-4). */
static int res_nodes(const struct recon_model *m, double theta, int mirror, double x[4])
{
	double lo[2] = { -INFINITY, -INFINITY }, hi[2] = { INFINITY, INFINITY }, tol = RES_TOL;
	for (size_t k = 0; k < 4 * m->n; k++) { /* the two nearest distinct sampled incidences on each side */
		if (k % 4 >= 2 && !mirror)
			continue;
		double a = m->ang[4 * (k / 4) + 2 * (k % 2)];
		if (k % 4 >= 2)
			a = -a;
		if (fabs(a - theta) <= tol)
			return 0; /* sampled */
		if (a < theta) {
			if (a > lo[0] + tol) {
				lo[1] = lo[0];
				lo[0] = a;
			} else if (a < lo[0] - tol && a > lo[1] + tol) {
				lo[1] = a;
			}
		} else {
			if (a < hi[0] - tol) {
				hi[1] = hi[0];
				hi[0] = a;
			} else if (a > hi[0] + tol && a < hi[1] - tol) {
				hi[1] = a;
			}
		}
	}
	if (!isfinite(lo[0]) || !isfinite(hi[0]))
		return 0;
	int np = 0;
	if (isfinite(lo[1]) && isfinite(hi[1]))
		x[np++] = lo[1];
	x[np++] = lo[0];
	x[np++] = hi[0];
	if (np == 3)
		x[np++] = hi[1];
	return np;
}

static int resolution(const struct recon_model *m, double theta, struct dhr_quad *dq, const double *dhr, double *res,
		      struct acq_err *err)
{
	size_t L = m->nwl;
	double x[2][4], ax[8]; /* the nodes of the two interpolants; the distinct incidences |x| they need */
	int np[2], nax = 0;
	for (int v = 0; v < 2; v++) {
		np[v] = res_nodes(m, theta, v, x[v]);
		if (np[v] == 0)
			return 0; /* sampled, or no sample on one side even with the mirror images */
		for (int i = 0; i < np[v]; i++) {
			int j = 0;
			while (j < nax && fabs(ax[j] - fabs(x[v][i])) > 1e-12)
				j++;
			if (j == nax)
				ax[nax++] = fabs(x[v][i]);
		}
	}
	double *dv = malloc((size_t)nax * L * sizeof *dv);
	if (!dv)
		return acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory");
	int rc = 0;
	for (int i = 0; i < nax && !rc; i++)
		rc = dhr_quad(m, ax[i], dq, dv + (size_t)i * L, NULL, err);
	for (size_t l = 0; l < L && !rc; l++)
		res[l] = INFINITY;
	for (int v = 0; v < 2 && !rc; v++) {
		double w[4]; /* Lagrange weights at θ */
		int at[4];
		for (int i = 0; i < np[v]; i++) {
			w[i] = 1;
			for (int j = 0; j < np[v]; j++)
				if (j != i)
					w[i] *= (theta - x[v][j]) / (x[v][i] - x[v][j]);
			at[i] = 0;
			while (fabs(ax[at[i]] - fabs(x[v][i])) > 1e-12)
				at[i]++;
		}
		for (size_t l = 0; l < L; l++) {
			double p = 0;
			for (int i = 0; i < np[v]; i++)
				p += w[i] * fmin(dv[(size_t)at[i] * L + l], 1.0);
			res[l] = fmin(res[l], fabs(dhr[l] - p));
		}
	}
	free(dv);
	return rc ? -1 : 0;
}

/*
 * One Monte-Carlo draw of channel l with the trend refitted: the perturbed data g[k] (relative to the nominal trend)
 * become linear values f = e^(g + ylog) − ε (ylog = ln(T + ε) of the nominal trend at the samples), the trend's
 * coefficients c[TREND_NB] are refitted to them at the nominal roughness (trend_fit_coef, the fit's own rule, on the
 * nominal's terms Bs), and g is made relative to the refitted trend. Why: the trend is fitted to the same noisy
 * data, and a draw that holds it fixed leaves out its coefficients' variance: on the simulator's sharp lobe at 8°
 * the DHR's spread over noise seeds was 7.0e-4 against a σ_noise of 5.5e-4 with the trend held fixed (8 seeds).
 * The roughness itself stays fixed (its search is the fit's costliest step).
 */
static void refit_trend(const struct recon_model *m, size_t l, const double *Bs, const double *ylog, double *g,
			double *f, double *c)
{
	size_t n = m->n;
	double eps = m->eps[l];
	for (size_t k = 0; k < n; k++)
		f[k] = fmax(exp(fmin(g[k] + ylog[k], G_MAX)) - eps, 0.0);
	trend_fit_coef(n, f, eps, Bs, c);
	for (size_t k = 0; k < n; k++)
		g[k] = log(f[k] + eps) - log(trend_dot(c, Bs + k * TREND_NB) + eps);
}

/*
 * The trend's roughness where the data would have it elsewhere (session 18). The fit takes the lobe's width α only
 * where the plan can measure it (trend.c score: samples in the lobe's core and on its flank, else the roughness is
 * inadmissible), so on a coarse plan the fitted α can sit on that bound, not at the data's optimum: acq-sim's clear
 * coat on 4 × 4 × 6 (every mirror direction sampled exactly, the nearest off-mirror samples ≥ 10° away) fits
 * α = 0.0588, the narrowest width with three samples on its flank, against the truth's 0.05 and the data's
 * unrestricted optimum 0.054; the coat's albedo (∝ peak × α²) and the DHR then read +0.008 at 30° (σ 0.003: the
 * kriging σ holds the trend fixed, the Monte-Carlo draws keep its roughness). The profile of the fit's own score (mean
 * squared log residual on the fit's channels, coefficients refitted, the other roughness and the nominal's terms
 * kept) over α without the admissibility rule finds the data's width α*; where the data prefer it by more than one
 * unit of χ² (n·nc·(s(α) − s(α*))/s(α*) > 1: the profile likelihood's 68 % interval excludes the fitted α), the
 * reading at α* (coefficients and GP weights refitted with the one factor of K + ηΛ, the adaptive rule) is a second
 * estimate the plan cannot decide against, and sw[t·L + l] = |DHR(α*) − DHR(α)| the distance of the two (as σ_res).
 * 0 where the fitted α is the data's (every interior optimum: the paper plan) or without a lobe or a log transform.
 * It is an error of the model between the samples independent of the GP's (the trend's form, not the residual field
 * the kriging σ is about), so it joins the kriging σ in quadrature; σ_E, the energy prior's lobe the samples missed,
 * holds the same error where it is larger, so σ_model = max(kriging ⊕ sw, σ_E) (σ_model ⊕ sw instead over-covered
 * where σ_E already held it: acq-sim's sharp lobe 3 × 4 × 6 at 30°, whose phong width the rule also pins, z RMS
 * 0.65 → 0.54; reconstruction.md, session 18).
 * The rule can reject a whole kind, not only a width: acq-sim's sharp lobe (phong n = 250) on 4 × 4 × 6 has two
 * samples on the lobe's flank (10° off the mirror at θ 10°), so the phong kind is inadmissible at the data's width
 * (α 0.089, score 4.3e-5: the noise) and the fit keeps a GGX lobe (α 0.034, score 0.22) that holds the peak and is
 * too narrow beside it: the DHR read 0.17 / 0.11 / 0.12 low at 8 / 30 / 60° against σ 0.02-0.05 (z RMS 9.4 / 6.3 /
 * 2.2), and the GGX profile is flat at its interior optimum (the form, not the width, is wrong). So the profile runs
 * over the fit's other one-roughness kinds too (those it tried: the model's trend_loo; all their terms): one whose
 * best width the rule rejects (trend_lobe_measured) and which fits the data better than the model's own kind at its
 * best is the data's reading instead, with the same χ² test against the fitted model (sharp lobe 4 × 4 × 6: DHR at
 * phong α 0.089 within 0.0005 of the truth; z RMS 1.00 / 0.99 / 0.97). An admissible kind that fits better lost on
 * cross-validation (fit.c: the data, not the rule, decided) and is no second reading.
 */
#define WIDTH_NGRID TREND_NGRID /* the fit's search: log grid over [TREND_ALPHA_MIN, top], golden section about its best */
struct width_ctx {
	const struct recon_model *m;
	size_t n, nc, chan[TREND_NCH];
	const double *f;
	double *B, c[TREND_NB];
	int used[TREND_NB];
	int kind;  /* the trend kind profiled (the model's, or another the fit tried) */
	int lobe;  /* the last width_score's coefficients hold a lobe */
};

/* The fit's score at roughness a without its admissibility rule: mean squared log residual over the scored channels. */
static double width_score(struct width_ctx *w, double a)
{
	const struct recon_model *m = w->m;
	for (size_t k = 0; k < w->n; k++) {
		trend_eval_basis2(w->kind, a, m->trend_alpha2, m->ctr + 6 * k, w->B + k * TREND_NB);
		for (int j = 0; j < TREND_NB; j++)
			if (!w->used[j])
				w->B[k * TREND_NB + j] = 0.0;
	}
	double ss = 0;
	w->lobe = 0;
	for (size_t i = 0; i < w->nc; i++) {
		ss += trend_fit_coef(w->n, w->f + w->chan[i] * w->n, m->eps[w->chan[i]], w->B, w->c);
		for (int j = trend_lobe_first(w->kind); j < TREND_NB; j++)
			w->lobe |= w->c[j] > 0;
	}
	return ss / (double)(w->n * w->nc);
}

/* The data at the centres (imputed values included), as refit_trend: f[l*n + k] for every channel of m. */
static void width_data(const struct recon_model *m, double *f)
{
	size_t n = m->n, L = m->nwl;
	for (size_t k = 0; k < n; k++) {
		double b[TREND_NB];
		trend_at(m, m->ctr + 6 * k, b);
		for (size_t l = 0; l < L; l++)
			f[l * n + k] = fmax(exp(fmin(m->g[l * n + k] + log(trend_factor(m, b, l)), G_MAX)) - m->eps[l], 0.0);
	}
}

static double width_fn(void *w, double x)
{
	return width_score(w, exp(x));
}

/* The fit's search without its rule: log grid of WIDTH_NGRID over [la, lb], golden section about the best; *best, *bs
 * (ln α and its score) are kept where no point beats *bs. */
static void width_search(struct width_ctx *w, double la, double lb, double *best, double *bs)
{
	double h = (lb - la) / (WIDTH_NGRID - 1);
	for (int i = 0; i < WIDTH_NGRID && lb > la; i++) {
		double s = width_score(w, exp(la + h * i));
		if (s < *bs) {
			*bs = s;
			*best = la + h * i;
		}
	}
	trend_golden(width_fn, w, fmax(la, *best - h), fmin(lb, *best + h), best, bs); /* about the best, as trend.c */
}

/* Did the fit try trend kind t (its candidates' leave-one-out scores in the model's metadata: "trend_loo=none:…,ggx:…")? */
static int fit_tried(const struct recon_model *m, int t)
{
	const char *p = strstr(m->meta, "trend_loo="), *name = trend_name(t);
	size_t k = strlen(name);
	for (p = p ? p + 10 : NULL; p && *p && *p != '\n'; p++)
		if ((p[-1] == '=' || p[-1] == ',') && !strncmp(p, name, k) && p[k] == ':')
			return 1;
	return 0;
}

static int width_sd(const struct recon_model *m, const double *A, size_t nth, const double *theta, const double *dhr,
		    double *sw, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl;
	if (m->trend == RECON_TREND_NONE || m->transform != RECON_T_LOG || !(m->trend_alpha > 0))
		return 0;
	/* the width is searched on the whole model's channels even for a view of some of them (select's value
	 * channels: their σ must be the whole model's σ on those channels, test_recon_select test_value_channels) */
	const struct recon_model *mw = m->whole ? m->whole : m;
	size_t Lw = mw->nwl;
	struct width_ctx w = { .m = mw, .n = n, .kind = m->trend };
	w.nc = trend_score_channels(Lw, w.chan); /* the fit's scored channels (fit.c) */
	int lobe = 0;
	for (size_t l = 0; l < Lw; l++)
		for (int j = 0; j < TREND_NB; j++)
			w.used[j] |= mw->tcoef[l * TREND_NB + j] > 0;
	for (int j = trend_lobe_first(m->trend); j < TREND_NB; j++)
		lobe |= w.used[j];
	if (m->trend == RECON_TREND_SHEEN || m->trend == RECON_TREND_ROUGH)
		lobe = w.used[2] || (m->trend == RECON_TREND_SHEEN && w.used[3]);
	if (!lobe)
		return 0; /* no lobe: the roughness is not used */
	int rc = -1;
	double *f = malloc(n * L * sizeof *f), *B = malloc(n * TREND_NB * sizeof *B);
	double *tc = calloc(L * TREND_NB, sizeof *tc), *g = malloc(n * L * sizeof *g), *wv = malloc(n * L * sizeof *wv);
	double *mu = malloc(L * sizeof *mu), *d2 = malloc(nth * L * sizeof *d2);
	double *fw = mw != m ? malloc(n * Lw * sizeof *fw) : f;
	struct dhr_quad dq = { 0 };
	if (!f || !B || !tc || !g || !wv || !mu || !d2 || !fw) {
		acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory");
		goto out;
	}
	width_data(m, f);
	if (fw != f)
		width_data(mw, fw);
	w.f = fw;
	w.B = B;
	double s0 = width_score(&w, m->trend_alpha);
	double la = log(TREND_ALPHA_MIN), lb = log(trend_two_lobes(m->trend) ? 0.5 * m->trend_alpha2 : TREND_ALPHA_MAX);
	double best = log(m->trend_alpha), bs = s0;
	width_search(&w, la, lb, &best, &bs);
	/* the other one-roughness kinds the fit tried, with all their terms: one whose best width the rule rejects (the
	 * plan does not measure it) but which fits the data better is the data's reading (acq-sim's sharp lobe on
	 * 4 × 4 × 6: phong α 0.089, score 4e-5, against the GGX the rule left, 0.22) */
	int kind = m->trend;
	for (int t = RECON_TREND_GGX; t <= RECON_TREND_ROUGH; t++) {
		if (t == m->trend || !fit_tried(m, t))
			continue;
		struct width_ctx wt = w;
		wt.kind = t;
		for (int j = 0; j < TREND_NB; j++)
			wt.used[j] = 1;
		double bt = log(TREND_ALPHA_MAX), st = INFINITY;
		width_search(&wt, la, log(TREND_ALPHA_MAX), &bt, &st);
		if (!(st < bs))
			continue;
		width_score(&wt, exp(bt)); /* its coefficients at its best: a lobe the rule would judge? */
		if (wt.lobe && !trend_lobe_measured(t, exp(bt), n, m->ctr)) {
			bs = st;
			best = bt;
			kind = t;
		}
	}
	if (!(bs > 0) || !((double)(n * w.nc) * (s0 - bs) / bs > 1.0)) {
		rc = 0; /* the data's width is the fitted one */
		goto out;
	}
	if (kind != m->trend) {
		w.kind = kind;
		for (int j = 0; j < TREND_NB; j++)
			w.used[j] = 1;
	}
	/* the model at α*: every channel's coefficients, the data relative to that trend, its GP weights (one factor) */
	struct recon_model ma = *m;
	ma.trend = kind;
	ma.trend_alpha = exp(best);
	width_score(&w, ma.trend_alpha);
	for (size_t l = 0; l < L; l++) {
		trend_fit_coef(n, f + l * n, m->eps[l], B, tc + l * TREND_NB);
		double s = 0;
		for (size_t k = 0; k < n; k++) {
			g[l * n + k] = log(f[l * n + k] + m->eps[l]) - log(trend_dot(tc + l * TREND_NB, B + k * TREND_NB) + m->eps[l]);
			s += g[l * n + k];
		}
		mu[l] = s / (double)n;
		for (size_t k = 0; k < n; k++)
			wv[l * n + k] = g[l * n + k] - mu[l];
	}
	if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)L, A, (lapack_int)n, wv, (lapack_int)n) != 0) {
		acq_errf(err, ACQ_E_NUMERIC, "dhr: solve failed");
		goto out;
	}
	ma.tcoef = tc;
	ma.g = g;
	ma.w = wv;
	ma.mu = mu;
	if (dhr_quad_init(&dq, &ma, err))
		goto out;
	for (size_t t = 0; t < nth; t++)
		if (dhr_quad(&ma, theta[t], &dq, d2 + t * L, NULL, err))
			goto out;
	for (size_t i = 0; i < nth * L; i++)
		sw[i] = isfinite(d2[i]) ? fabs(fmin(d2[i], 1.0) - dhr[i]) : 0.0;
	rc = 0;
out:
	dhr_quad_free(&dq);
	if (fw != f)
		free(fw);
	free(f);
	free(B);
	free(tc);
	free(g);
	free(wv);
	free(mu);
	free(d2);
	return rc;
}

int recon_dhr(const struct recon_model *m, size_t nth, const double *theta, int ndraws, uint64_t seed,
	      double *dhr, double *sig, recon_progress_fn progress, void *pctx, struct acq_err *err)
{
	return recon_dhr_ex(m, nth, theta, ndraws, seed, dhr, sig, NULL, NULL, NULL, progress, pctx, err);
}

int recon_dhr_ex(const struct recon_model *m, size_t nth, const double *theta, int ndraws, uint64_t seed,
		 double *dhr, double *sig, double *sig_noise, double *sig_model, double *sig_quad,
		 recon_progress_fn progress, void *pctx, struct acq_err *err)
{
	struct recon_dhr_parts p = { .noise = sig_noise, .model = sig_model, .quad = sig_quad };
	return recon_dhr_parts(m, nth, theta, ndraws, seed, dhr, sig, &p, progress, pctx, err);
}

int recon_dhr_parts(const struct recon_model *m, size_t nth, const double *theta, int ndraws, uint64_t seed,
		    double *dhr, double *sig, const struct recon_dhr_parts *parts, recon_progress_fn progress, void *pctx,
		    struct acq_err *err)
{
	static const struct recon_dhr_parts none;
	if (!parts)
		parts = &none;
	size_t n = m->n, L = m->nwl, Q = (size_t)DHR_NMU * DHR_NPHI;
	if (nth == 0 || nth > 64)
		return acq_errf(err, ACQ_E_INVAL, "dhr: between 1 and 64 incidences");
	for (size_t t = 0; t < nth; t++)
		if (!(theta[t] >= 0 && theta[t] <= M_PI / 2))
			return acq_errf(err, ACQ_E_RANGE, "dhr: incidence %g° outside [0, 90]", theta[t] * 180 / M_PI);
	if (ndraws < 0 || ndraws > 100000)
		return acq_errf(err, ACQ_E_INVAL, "dhr: draws must be in [0, 100000]");
	if ((double)nth * (double)Q * (double)n * 8.0 > 2e9)
		return acq_errf(err, ACQ_E_RANGE, "dhr: %zu incidences × %zu centres need too much memory", nth, n);
	int rc = -1;
	double *Kq = parts->kq ? NULL : recon_big_alloc(nth * Q * n * sizeof *Kq), *wt = malloc(Q * sizeof *wt);
	const double *Kr = parts->kq ? parts->kq : Kq; /* the rows, given or built below */
	double *c6 = malloc(nth * Q * 6 * sizeof *c6), *scale = malloc(nth * Q * L * sizeof *scale);
	/* the factor and inverse of K + ηΛ, lent (parts.gp_A, gp_Ainv) or built below */
	int lent = parts->gp_A && parts->gp_Ainv;
	double *Aown = lent ? NULL : malloc(n * n * sizeof *Aown), *Aiown = lent ? NULL : malloc(n * n * sizeof *Aiown);
	const double *A = lent ? parts->gp_A : Aown, *Ainv = lent ? parts->gp_Ainv : Aiown;
	double *Wd = malloc(n * L * sizeof *Wd), *Y = malloc(Q * L * sizeof *Y);
	double *mean = calloc(nth * L, sizeof *mean), *m2 = calloc(nth * L, sizeof *m2);
	double *mud = malloc(L * sizeof *mud);
	double *C = malloc(Q * L * sizeof *C), *KQQ = recon_big_alloc(Q * Q * sizeof *KQQ), *soaQ = malloc(6 * Q * sizeof *soaQ);
	double *U = malloc(Q * L * sizeof *U), *Bt = malloc(L * n * sizeof *Bt), *X = malloc(L * n * sizeof *X);
	double *alpha = calloc(L, sizeof *alpha);
	double *dfmis = malloc(n * L * sizeof *dfmis), *mratio = malloc(n * L * sizeof *mratio), *misacc = calloc(nth * L, sizeof *misacc);
	double *sres = calloc(nth * L, sizeof *sres), *swid = calloc(nth * L, sizeof *swid);
	double *vmod = calloc(nth * L, sizeof *vmod), *squad = calloc(nth * L, sizeof *squad);
	double *senergy = calloc(nth * L, sizeof *senergy), *aseen = malloc(L * sizeof *aseen);
	double *tb = malloc(nth * Q * TREND_NB * sizeof *tb), *xsd = calloc(nth * L, sizeof *xsd);
	double *Bs = NULL, *ylog = NULL, *fl = NULL, *cdraw = NULL;
	struct dhr_quad dq = { 0 };
	if (!Kr || !wt || !c6 || !scale || !A || !Wd || !Y || !mean || !m2 || !mud || !C || !KQQ || !soaQ || !U ||
	    !Bt || !X || !Ainv || !alpha || !dfmis || !mratio || !misacc || !sres || !swid || !vmod || !squad || !tb ||
	    !senergy || !aseen || !xsd) {
		acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory");
		goto out;
	}
	for (size_t t = 0; t < nth; t++) {
		if (recon_hemi_nodes(theta[t], DHR_NMU, DHR_NPHI, 0, c6 + t * Q * 6, wt)) {
			acq_errf(err, ACQ_E_INVAL, "dhr: quadrature");
			goto out;
		}
		if (Kq)
			rbf_kmatrix_soa(m->kernel, m->shape, Q, c6 + t * Q * 6, n, m->soa, Kq + t * Q * n);
		for (size_t q = 0; q < Q; q++) {
			const double *c = c6 + (t * Q + q) * 6;
			trend_at(m, c, tb + (t * Q + q) * TREND_NB);
			for (size_t l = 0; l < L; l++)
				scale[(t * Q + q) * L + l] = recon_energy_scale(m, theta_of(c), theta_of(c + 3), l) * wt[q];
		}
	}
	/* the one factorisation of K + Λ, and the leave-one-out amplitude α_λ of every channel */
	if (lent)
		recon_gp_alpha(m, Ainv, alpha);
	else if (recon_gp_setup(m, "dhr", Aown, Aiown, alpha, err))
		goto out;
	/* the extrapolation beyond the last zenith, where the last ring's block leave-out says the form misses it by a
	 * good part of the kriging amplitude (recon_int.h, recon_edge_size) */
	double aedge = recon_edge_size(m, Ainv, alpha);
	if (aedge < 0) {
		acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory");
		goto out;
	}
	double gate = recon_ramp(aedge, RECON_EDGE_A0, RECON_EDGE_A1);
	for (size_t t = 0; t < nth; t++)
		if (recon_extrap_sd(m, Q, c6 + t * Q * 6, wt, gate, xsd + t * L, err))
			goto out;
	if (recon_misfit(m, MISFIT_Z, MISFIT_MIN, dfmis, mratio, NULL, err) < 0)
		goto out;
	/* the trend's coefficients are refitted in every draw (refit_trend) */
	int refit = m->trend != RECON_TREND_NONE && m->transform == RECON_T_LOG && ndraws > 0;
	if (refit) {
		Bs = malloc(n * TREND_NB * sizeof *Bs);
		ylog = malloc(n * L * sizeof *ylog);
		fl = malloc(n * sizeof *fl);
		cdraw = malloc(L * TREND_NB * sizeof *cdraw);
		if (!Bs || !ylog || !fl || !cdraw) {
			acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory");
			goto out;
		}
		int used[TREND_NB] = { 0 };
		for (size_t l = 0; l < L; l++)
			for (int j = 0; j < TREND_NB; j++)
				used[j] |= m->tcoef[l * TREND_NB + j] > 0;
		for (size_t k = 0; k < n; k++) {
			trend_at(m, m->ctr + 6 * k, Bs + k * TREND_NB);
			for (size_t l = 0; l < L; l++)
				ylog[l * n + k] = log(trend_factor(m, Bs + k * TREND_NB, l));
			for (int j = 0; j < TREND_NB; j++) /* the nominal's terms only (a lobe the fit dropped stays out) */
				if (!used[j])
					Bs[k * TREND_NB + j] = 0.0;
		}
	}
	/* draw 0 is the nominal model; draws 1..ndraws are perturbed */
	struct recon_rng r;
	recon_rng_seed(&r, seed);
	for (int d = 0; d <= ndraws; d++) {
		if (progress)
			progress(pctx, "dhr", (double)d / (double)(ndraws + 1));
		if (d == 0) {
			memcpy(Wd, m->w, n * L * sizeof *Wd);
			memcpy(mud, m->mu, L * sizeof *mud);
		} else {
			for (size_t l = 0; l < L; l++) {
				double sum = 0;
				for (size_t k = 0; k < n; k++) {
					double v = m->g[l * n + k] + m->gsig[l * n + k] * recon_rng_normal(&r);
					Wd[l * n + k] = v;
				}
				if (refit)
					refit_trend(m, l, Bs, ylog + l * n, Wd + l * n, fl, cdraw + l * TREND_NB);
				for (size_t k = 0; k < n; k++)
					sum += Wd[l * n + k];
				mud[l] = sum / (double)n;
				for (size_t k = 0; k < n; k++)
					Wd[l * n + k] -= mud[l];
			}
			if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)L, A, (lapack_int)n, Wd,
					   (lapack_int)n) != 0) {
				acq_errf(err, ACQ_E_NUMERIC, "dhr: solve failed");
				goto out;
			}
		}
		for (size_t t = 0; t < nth; t++) {
			cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)Q, (int)L, (int)n, 1.0, Kr + t * Q * n,
				    (int)n, Wd, (int)n, 0.0, Y, (int)L);
			for (size_t l = 0; l < L; l++) {
				if (d == 0) { /* the nominal value itself comes from the adaptive rule below */
					for (size_t q = 0; q < Q; q++)
						C[q * L + l] = scale[(t * Q + q) * L + l] *
							       untransform_deriv(m->transform, Y[q * L + l] + mud[l], m->eps[l],
										 trend_factor(m, tb + (t * Q + q) * TREND_NB, l));
				} else { /* Welford */
					double acc = 0;
					for (size_t q = 0; q < Q; q++) {
						const double *b = tb + (t * Q + q) * TREND_NB;
						double tf = refit ? trend_dot(cdraw + l * TREND_NB, b) + m->eps[l]
								  : trend_factor(m, b, l);
						acc += scale[(t * Q + q) * L + l] *
						       untransform(m->transform, Y[q * L + l] + mud[l], m->eps[l], tf);
					}
					double delta = acc - mean[t * L + l];
					mean[t * L + l] += delta / d;
					m2[t * L + l] += delta * (acc - mean[t * L + l]);
				}
			}
			if (d == 0) {
				struct unseen_in ui = { .theta = theta[t], .wt = wt, .Y = Y, .mud = mud, .tb = tb + t * Q * TREND_NB,
							.aseen = aseen, .aedge = aedge };
				unseen_and_misfit(m, Q, c6 + t * Q * 6, scale + t * Q * L, alpha, dfmis, mratio, &ui, C,
						  misacc + t * L, senergy + t * L);
			}
			if (d == 0 && model_variance(m, Q, c6 + t * Q * 6, Kr + t * Q * n, A, C, KQQ, soaQ, U, Bt, X,
						     vmod + t * L, err))
				goto out;
		}
	}
	/* the nominal DHR by the adaptive rule (the fixed rule above serves the spread and the model variance):
	 * a lobe narrower than the 32 × 48 rule resolves is refined, per channel, up to 256 × 384. The exact
	 * albedo of the scaled model is ≤ 1 by construction, so an estimate above 1 is quadrature error: it is
	 * clipped (which only moves it towards the exact value) and, with the last refinement step (against the
	 * finer rule and the coarser rule's independent twin: dq->ws.indep), kept as the quadrature term of σ. */
	if (dhr_quad_init(&dq, m, err))
		goto out;
	for (size_t t = 0; t < nth; t++) {
		if (dhr_quad(m, theta[t], &dq, dhr + t * L, squad + t * L, err))
			goto out;
		for (size_t l = 0; l < L; l++)
			if (dhr[t * L + l] > 1.0) {
				squad[t * L + l] += dhr[t * L + l] - 1.0;
				dhr[t * L + l] = 1.0;
			}
		if (resolution(m, theta[t], &dq, dhr + t * L, sres + t * L, err))
			goto out;
	}
	/* the lobe's width where the fit's admissibility rule, not the data, set it (width_sd): joins the kriging σ */
	if (width_sd(m, A, nth, theta, dhr, swid, err))
		goto out;
	for (size_t i = 0; i < nth * L; i++) {
		double sn = ndraws > 1 ? sqrt(m2[i] / (ndraws - 1)) : 0.0, sk = sqrt(vmod[i] + xsd[i] * xsd[i]);
		double sm = fmax(hypot(sk, swid[i]), senergy[i]);
		double sb = sn > sm ? sn : sm, smis = fmin(fabs(misacc[i]), 1.0);
		sig[i] = sqrt(sb * sb + squad[i] * squad[i] + smis * smis + sres[i] * sres[i]);
		if (parts->noise)
			parts->noise[i] = sn;
		if (parts->model)
			parts->model[i] = sm;
		if (parts->kriging)
			parts->kriging[i] = sk;
		if (parts->energy)
			parts->energy[i] = senergy[i];
		if (parts->quad)
			parts->quad[i] = squad[i];
		if (parts->misfit)
			parts->misfit[i] = smis;
		if (parts->res)
			parts->res[i] = sres[i];
		if (!isfinite(sig[i]) || !isfinite(dhr[i])) {
			acq_errf(err, ACQ_E_NUMERIC, "dhr: non-finite result");
			goto out;
		}
	}
	rc = 0;
out:
	free(Kq);
	free(wt);
	free(c6);
	free(scale);
	free(Aown);
	free(Wd);
	free(Y);
	free(mean);
	free(m2);
	free(mud);
	free(C);
	free(KQQ);
	free(soaQ);
	free(U);
	free(Bt);
	free(X);
	free(Aiown);
	free(alpha);
	free(dfmis);
	free(mratio);
	free(misacc);
	free(sres);
	free(swid);
	free(vmod);
	free(senergy);
	free(aseen);
	free(squad);
	free(tb);
	free(xsd);
	free(Bs);
	free(ylog);
	free(fl);
	free(cdraw);
	dhr_quad_free(&dq);
	return rc;
}

