/* recon: fitting (transform, merge, leave-one-out search, one Cholesky for all channels), evaluation with
 * the energy factor, albedo tables, DHR with Monte-Carlo uncertainty, and the property checker. */
#include "recon/recon.h"

#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "acq_version.h"

#define RECON_MAX_N 8000
#define MERGE_TOL 1e-9
/* Albedo table: nodes every 10°, bisected; node rules from Gauss-Legendre 10 in cosθo × 12 azimuth midpoints. */
#define TAB_N 10
#define TAB_NMU 10
#define TAB_NPHI 12
#define TAB_TOL 1e-3      /* node rule refined until a doubled rule agrees to this (relative) */
#define TAB_NMU_MAX 160   /* finest node rule: 160 × 192 */
#define TAB_CURV_TOL 0.01 /* largest second difference over an interval (albedo units) before bisecting */
#define TAB_DEPTH 7       /* finest interval 10°/2⁷ ≈ 0.08° */
#define TAB_MAX_NODES 96  /* node budget of the bisection (breadth first) */
#define TAB_BELOW 0.9     /* a node's channel is also done once fine + 4·|fine − coarse| ≤ this: clearly below 1 */
#define TAB_BELOW_DIFF 0.005 /* ... and |fine − coarse| ≤ this (keeps the bisection's noise allowance small) */
#define ALB_NMU_MAX 256   /* finest rule of recon_albedo, the DHR and the checker (Gauss-Legendre limit) */
/* DHR quadrature: Gauss-Legendre 32 × 48 azimuth midpoints (error discussed at recon_albedo). */
#define DHR_NMU 32
#define DHR_NPHI 48
#define DHR_FLOOR 1e-300  /* refined to 1e-3 relative: an absolute floor let two rules agree on a missed lobe */
/* Largest transformed value mapped back (e^69 ≈ 1e30 sr⁻¹): keeps every output finite. */
#define G_MAX 69.0
#ifndef TREND_RULE_SPACING
#define TREND_RULE_SPACING 0.5
#endif

void recon_fit_opts_default(struct recon_fit_opts *o)
{
	memset(o, 0, sizeof *o);
	o->kernel = RBF_K_WENDLAND;
	o->transform = RECON_T_LOG;
	o->shape = 0;
	o->smoothing = -1;
	o->max_cond = 1e12;
	o->trend = -1; /* GGX with the log transform, none with sqrt */
}

const char *recon_transform_name(int t)
{
	return t == RECON_T_LOG ? "log" : t == RECON_T_SQRT ? "sqrt" : NULL;
}

int recon_transform_from_name(const char *name)
{
	if (!name)
		return -1;
	if (!strcmp(name, "log"))
		return RECON_T_LOG;
	if (!strcmp(name, "sqrt"))
		return RECON_T_SQRT;
	return -1;
}

void recon_model_free(struct recon_model *m)
{
	if (!m)
		return;
	free(m->wl);
	free(m->eps);
	free(m->mu);
	free(m->ang);
	free(m->ctr);
	free(m->tctr);
	free(m->soa);
	free(m->lam);
	free(m->w);
	free(m->g);
	free(m->gsig);
	free(m->tcoef);
	free(m->tab_theta);
	free(m->tab_alb);
	free(m);
}

int recon_model_derive(struct recon_model *m, struct acq_err *err)
{
	free(m->ctr);
	free(m->tctr);
	free(m->soa);
	m->ctr = malloc(m->n * 6 * sizeof *m->ctr);
	m->tctr = malloc(m->n * 6 * sizeof *m->tctr);
	m->soa = malloc(m->n * 6 * sizeof *m->soa);
	if (!m->ctr || !m->tctr || !m->soa)
		return acq_errf(err, ACQ_E_NOMEM, "model: out of memory for %zu centres", m->n);
	for (size_t k = 0; k < m->n; k++) {
		const double *a = m->ang + 4 * k;
		rbf_canon(a[0], a[1], a[2], a[3], m->ctr + 6 * k);
		rbf_tau(m->ctr + 6 * k, m->tctr + 6 * k);
	}
	rbf_soa(m->n, m->ctr, m->soa);
	return 0;
}

/* ---- evaluation ------------------------------------------------------------------------------------ */

size_t recon_eval_work_size(const struct recon_model *m)
{
	return (size_t)RECON_EVAL_BLOCK * m->n;
}

/* Map a transformed value back to a BRDF value: non-negative and finite by construction. tf is the trend factor
 * (trend_factor): with a trend T (log transform only) g is relative to it, f̂ = max(0, (T + ε)·e^g − ε);
 * without, tf = 1 and f̂ = max(0, e^g − ε). */
static inline double untransform(int transform, double g, double eps, double tf)
{
	if (!(g == g))
		g = -G_MAX; /* unreachable with finite weights; never let NaN through */
	if (transform == RECON_T_SQRT) {
		if (g > 1e15)
			g = 1e15;
		if (g < -1e15)
			g = -1e15;
		return g * g;
	}
	if (g > G_MAX)
		g = G_MAX;
	double f = exp(g) * tf - eps;
	return f > 0 ? (f < 1e300 ? f : 1e300) : 0.0;
}

/* Trend basis at a canonical point (zeros without a trend); the trend value T of channel l; the trend factor
 * of the map back, T + ε with a trend and 1 without. */
static inline void trend_at(const struct recon_model *m, const double *c6, double b[TREND_NB])
{
	trend_eval_basis(m->trend, m->trend_alpha, c6, b);
}

static inline double trend_val(const struct recon_model *m, const double b[TREND_NB], size_t l)
{
	return trend_dot(m->tcoef + l * TREND_NB, b);
}

static inline double trend_factor(const struct recon_model *m, const double b[TREND_NB], size_t l)
{
	return m->trend == RECON_TREND_GGX ? trend_val(m, b, l) + m->eps[l] : 1.0;
}

size_t recon_tab_interval(const struct recon_model *m, double theta)
{
	size_t lo = 0, hi = m->ntab - 1; /* tab_theta[lo] ≤ θ < tab_theta[hi], or the end interval */
	if (m->ntab < 2 || !(theta > m->tab_theta[0]))
		return 0;
	while (hi - lo > 1) {
		size_t mid = lo + (hi - lo) / 2;
		if (theta < m->tab_theta[mid])
			hi = mid;
		else
			lo = mid;
	}
	return lo;
}

/* Upper bound of the unscaled albedo near θ (interval lookup in the table). */
static double albedo_bound(const struct recon_model *m, double theta, size_t l)
{
	if (m->ntab < 2)
		return 0.0;
	return m->tab_alb[recon_tab_interval(m, theta) * m->nwl + l];
}

/* s = 1 / max(1, A(θi), A(θo)) from the two bounds. */
static inline double energy_scale_of(double a, double b)
{
	double mx = a > b ? a : b;
	return mx > 1.0 ? 1.0 / mx : 1.0;
}

double recon_energy_scale(const struct recon_model *m, double ti, double to, size_t l)
{
	return energy_scale_of(albedo_bound(m, ti, l), albedo_bound(m, to, l));
}

static double theta_of(const double *v)
{
	double z = v[2];
	return z >= 1.0 ? 0.0 : z <= 0.0 ? M_PI / 2 : acos(z);
}

/*
 * One block of b ≤ RECON_EVAL_BLOCK queries for nch channels: chan[k] names the model channel of output
 * column k (chan NULL: every channel in order) and wsub holds those channels' weights, channel-major
 * (nch × n; m->w itself when chan is NULL). out is b × nch, row-major.
 */
static void eval_block(const struct recon_model *m, size_t b, const double *c6, int scaled, size_t nch,
		       const size_t *chan, const double *wsub, double *out, double *work)
{
	size_t n = m->n;
	rbf_kmatrix_soa(m->kernel, m->shape, b, c6, n, m->soa, work);
	/* out (b × nch) = K (b × n) · Wᵀ */
	cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)b, (int)nch, (int)n, 1.0, work, (int)n, wsub,
		    (int)n, 0.0, out, (int)nch);
	for (size_t q = 0; q < b; q++) {
		const double *c = c6 + 6 * q;
		const double *ai = m->tab_alb, *ao = m->tab_alb;
		double tb[TREND_NB];
		trend_at(m, c, tb);
		if (scaled && m->ntab >= 2) {
			ai += recon_tab_interval(m, theta_of(c)) * m->nwl;
			ao += recon_tab_interval(m, theta_of(c + 3)) * m->nwl;
		}
		for (size_t k = 0; k < nch; k++) {
			size_t l = chan ? chan[k] : k;
			double f = untransform(m->transform, out[q * nch + k] + m->mu[l], m->eps[l], trend_factor(m, tb, l));
			if (scaled && m->ntab >= 2)
				f *= energy_scale_of(ai[l], ao[l]);
			out[q * nch + k] = f;
		}
	}
}

void recon_eval_canon(const struct recon_model *m, size_t nq, const double *c6, int scaled, double *out,
		      double *work)
{
	for (size_t q0 = 0; q0 < nq; q0 += RECON_EVAL_BLOCK) {
		size_t b = nq - q0 < RECON_EVAL_BLOCK ? nq - q0 : RECON_EVAL_BLOCK;
		eval_block(m, b, c6 + 6 * q0, scaled, m->nwl, NULL, m->w, out + q0 * m->nwl, work);
	}
}

int recon_eval(const struct recon_model *m, size_t nq, const double *ang, double *out, struct acq_err *err)
{
	double *c6 = malloc((nq ? nq : 1) * 6 * sizeof *c6);
	double *work = malloc(recon_eval_work_size(m) * sizeof *work);
	if (!c6 || !work) {
		free(c6);
		free(work);
		return acq_errf(err, ACQ_E_NOMEM, "eval: out of memory for %zu queries", nq);
	}
	for (size_t q = 0; q < nq; q++) {
		const double *a = ang + 4 * q;
		for (int k = 0; k < 4; k++)
			if (!isfinite(a[k])) {
				free(c6);
				free(work);
				return acq_errf(err, ACQ_E_INVAL, "eval: query %zu has a non-finite angle", q + 1);
			}
		double ti = fmin(fmax(a[0], 0.0), M_PI / 2), to = fmin(fmax(a[2], 0.0), M_PI / 2);
		rbf_canon(ti, a[1], to, a[3], c6 + 6 * q);
	}
	recon_eval_canon(m, nq, c6, 1, out, work);
	free(c6);
	free(work);
	return 0;
}

static void dir_angles(const double v[3], double *th, double *ph)
{
	double x = v[0], y = v[1], z = v[2];
	double r = sqrt(x * x + y * y + z * z);
	if (!(r > 0) || !isfinite(r)) {
		*th = 0;
		*ph = 0;
		return;
	}
	double zz = z / r;
	*th = zz >= 1 ? 0 : zz <= 0 ? M_PI / 2 : acos(zz);
	*ph = atan2(y, x);
}

int recon_eval_dirs(const struct recon_model *m, const double wi[3], const double wo[3], double *out,
		    struct acq_err *err)
{
	double a[4];
	dir_angles(wi, &a[0], &a[1]);
	dir_angles(wo, &a[2], &a[3]);
	return recon_eval(m, 1, a, out, err);
}

/* ---- quadrature -------------------------------------------------------------------------------------- */

/*
 * Hemisphere quadrature of the albedo a(θi) = ∫ f cosθo dωo = ∫₀¹ ∫₀^{2π} f μ dφ dμ (μ = cosθo).
 * μ: Gauss-Legendre with nmu nodes, exact for polynomials of degree 2·nmu − 1 in μ (so exact for a
 * Lambertian, and for cosⁿ lobes about the normal with n < 2·nmu − 1). φ: the integrand is 2π-periodic and
 * even in Δφ (isotropy and mirror), so nphi midpoints on [0, π] are the trapezoid rule with 2·nphi points on
 * the circle, whose error decays faster than any power for smooth integrands (exact for trigonometric
 * polynomials of degree < 2·nphi). The error is therefore set by the narrowest lobe of the interpolant:
 * about (lobe width / node spacing) must stay above ~2; the DHR rule (32 × 48: 2.8° in φ, ~3° in θ near the
 * horizon) resolves lobes down to ~6°, far narrower than a 10 × 10 × 10 angular sampling can reconstruct.
 * The albedo table estimates its own error against a doubled rule and adds it as a margin.
 */
static int hemi_nodes(double theta_i, int nmu, int nphi, int square_rule, double *c6, double *wt)
{
	double x[256], w[256];
	if (rbf_gauss_legendre01(nmu, x, w))
		return -1;
	size_t k = 0;
	for (int i = 0; i < nmu; i++) {
		double mu, wmu;
		if (square_rule) { /* independent rule: Gauss-Legendre in t = μ², dt = 2μ dμ */
			mu = sqrt(x[i]);
			wmu = 0.5 * w[i];
		} else {
			mu = x[i];
			wmu = w[i] * mu;
		}
		double to = acos(mu);
		for (int j = 0; j < nphi; j++) {
			double d = (j + 0.5) * M_PI / nphi;
			rbf_canon(theta_i, 0.0, to, d, c6 + 6 * k);
			wt[k] = wmu * 2.0 * M_PI / nphi;
			k++;
		}
	}
	return 0;
}

/* Workspace of albedo_adaptive, sized for the finest rule it may reach. */
struct albedo_ws {
	size_t qmax, L;
	double *c6, *wt, *work, *vals, *wsub, *fine;
	size_t *chan;
};

static void albedo_ws_free(struct albedo_ws *ws)
{
	free(ws->c6);
	free(ws->wt);
	free(ws->work);
	free(ws->vals);
	free(ws->wsub);
	free(ws->fine);
	free(ws->chan);
	memset(ws, 0, sizeof *ws);
}

static int albedo_ws_init(struct albedo_ws *ws, const struct recon_model *m, size_t qmax, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl;
	memset(ws, 0, sizeof *ws);
	ws->qmax = qmax;
	ws->L = L;
	ws->c6 = malloc(qmax * 6 * sizeof *ws->c6);
	ws->wt = malloc(qmax * sizeof *ws->wt);
	ws->work = malloc(recon_eval_work_size(m) * sizeof *ws->work);
	ws->vals = malloc((size_t)RECON_EVAL_BLOCK * L * sizeof *ws->vals);
	ws->wsub = malloc(L * n * sizeof *ws->wsub);
	ws->fine = malloc(L * sizeof *ws->fine);
	ws->chan = malloc(L * sizeof *ws->chan);
	if (!ws->c6 || !ws->wt || !ws->work || !ws->vals || !ws->wsub || !ws->fine || !ws->chan) {
		albedo_ws_free(ws);
		return acq_errf(err, ACQ_E_NOMEM, "albedo: out of memory");
	}
	return 0;
}

/* acc[k] = albedo of channel chan[k] (k < nch) by the rule nmu × nphi; the weights of those channels are
 * already packed in ws->wsub. Evaluated block by block: memory does not grow with the rule. */
static int albedo_rule(const struct recon_model *m, double theta_i, int nmu, int nphi, int square_rule,
		       int scaled, size_t nch, struct albedo_ws *ws, double *acc, struct acq_err *err)
{
	size_t Q = (size_t)nmu * (size_t)nphi;
	if (Q > ws->qmax || hemi_nodes(theta_i, nmu, nphi, square_rule, ws->c6, ws->wt))
		return acq_errf(err, ACQ_E_INVAL, "albedo: quadrature size %d × %d out of range", nmu, nphi);
	for (size_t k = 0; k < nch; k++)
		acc[k] = 0;
	for (size_t q0 = 0; q0 < Q; q0 += RECON_EVAL_BLOCK) {
		size_t b = Q - q0 < RECON_EVAL_BLOCK ? Q - q0 : RECON_EVAL_BLOCK;
		eval_block(m, b, ws->c6 + 6 * q0, scaled, nch, ws->chan, ws->wsub, ws->vals, ws->work);
		for (size_t q = 0; q < b; q++)
			for (size_t k = 0; k < nch; k++)
				acc[k] += ws->wt[q0 + q] * ws->vals[q * nch + k];
	}
	return 0;
}

/*
 * The starting rule for this model: the narrowest lobe of e^g. Near a peak of height H the C² Wendland
 * kernel of length ℓ gives g ≈ H(1 − 10 d²/ℓ²), so e^g is a Gaussian of width ℓ/√(20H): nodes are spaced
 * by that width (H = the largest range of g over the centres, log transform; the sqrt transform squares,
 * far milder). Two rules that both step over a lobe agree with each other, so refinement alone cannot
 * find it: the start must resolve it. The trend's GGX lobe has a half width ≈ 2α in ωo (D falls to a quarter
 * at tanθh = α): nodes α/2 apart when the lobe can carry 1e-4 of albedo (its albedo is ≤ the sum of its coefficients).
 * nmu, nphi are raised to it (at most nmu_max/2 so one doubling fits); *qmax is the size of the finest rule
 * the ladder can reach.
 */
static void lobe_rule(const struct recon_model *m, int nmu_max, int *nmu, int *nphi, size_t *qmax)
{
	double H = 0;
	if (m->transform != RECON_T_SQRT)
		for (size_t l = 0; l < m->nwl; l++) {
			const double *g = m->g + l * m->n;
			double lo = g[0], hi = g[0];
			for (size_t k = 1; k < m->n; k++) {
				lo = fmin(lo, g[k]);
				hi = fmax(hi, g[k]);
			}
			H = fmax(H, hi - lo);
		}
	double s = m->shape / sqrt(20.0 * (H + 1.0)); /* radians */
	if (m->trend == RECON_TREND_GGX) {
		double lobe = 0;
		for (size_t l = 0; l < m->nwl; l++) {
			double sum = 0; /* the lobe terms' albedo is ≤ the sum of their coefficients */
			for (int j = TREND_LOBE; j < TREND_NB; j++)
				sum += m->tcoef[l * TREND_NB + j];
			lobe = fmax(lobe, sum);
		}
		if (lobe >= 1e-4)
			s = fmin(s, TREND_RULE_SPACING * m->trend_alpha);
	}
	double a = ceil((M_PI / 2) / s), b = ceil(M_PI / s);
	if (a > *nmu)
		*nmu = a < nmu_max / 2 ? (int)a : nmu_max / 2;
	if (b > *nphi)
		*nphi = b < 4 * nmu_max ? (int)b : 4 * nmu_max;
	int tm = *nmu, tp = *nphi;
	while (2 * tm <= nmu_max) {
		tm *= 2;
		tp *= 2;
	}
	*qmax = (size_t)tm * (size_t)tp;
}

/*
 * Albedo of every channel at θi, starting with the rule nmu × nphi and doubling both while a channel
 * disagrees with the doubled rule by more than tol · max(|value|, floor) (relative above floor, absolute
 * below: floor 1 when only the comparison with 1 matters) and the doubled nmu stays ≤ nmu_max. Only
 * the channels still disagreeing are evaluated again, so one narrow lobe does not make every channel pay
 * for the finest rule. A channel is also done once fine + 4·|fine − coarse| ≤ below with |fine − coarse| ≤
 * TAB_BELOW_DIFF (the energy table only
 * compares its bound, fine + 2·|fine − coarse|, with 1: a value clearly below needs no more digits; −∞ turns
 * this off). out[l] is the finest value; diff[l] (may be NULL) the last |fine − coarse|, or 0 when no
 * doubling fits under nmu_max.
 */
static int albedo_adaptive(const struct recon_model *m, double theta_i, int nmu, int nphi, int nmu_max,
			   int square_rule, int scaled, double tol, double floor, double below, struct albedo_ws *ws,
			   double *out,
			   double *diff, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl, nch = L;
	for (size_t l = 0; l < L; l++) {
		ws->chan[l] = l;
		if (diff)
			diff[l] = 0;
	}
	memcpy(ws->wsub, m->w, L * n * sizeof *ws->wsub);
	if (albedo_rule(m, theta_i, nmu, nphi, square_rule, scaled, nch, ws, out, err))
		return -1;
	while (nch > 0 && 2 * nmu <= nmu_max) {
		nmu *= 2;
		nphi *= 2;
		if (albedo_rule(m, theta_i, nmu, nphi, square_rule, scaled, nch, ws, ws->fine, err))
			return -1;
		size_t keep = 0;
		for (size_t k = 0; k < nch; k++) {
			size_t l = ws->chan[k];
			double d = fabs(ws->fine[k] - out[l]), ref = fmax(fabs(ws->fine[k]), floor);
			out[l] = ws->fine[k];
			if (diff)
				diff[l] = d;
			if (!(d <= tol * ref) && !(ws->fine[k] + 4.0 * d <= below && d <= TAB_BELOW_DIFF)) {
				if (keep != k) {
					ws->chan[keep] = l;
					memmove(ws->wsub + keep * n, ws->wsub + k * n, n * sizeof *ws->wsub);
				}
				keep++;
			}
		}
		nch = keep;
	}
	return 0;
}

int recon_albedo(const struct recon_model *m, double theta_i, int nmu, int nphi, int scaled, double *out,
		 struct acq_err *err)
{
	if (!(theta_i >= 0 && theta_i <= M_PI / 2) || nmu < 1 || nphi < 1 || nmu > ALB_NMU_MAX || nphi > 4096)
		return acq_errf(err, ACQ_E_INVAL, "albedo: bad incidence or quadrature size");
	int top = nmu, tphi = nphi;
	while (2 * top <= ALB_NMU_MAX) {
		top *= 2;
		tphi *= 2;
	}
	struct albedo_ws ws;
	if (albedo_ws_init(&ws, m, (size_t)top * (size_t)tphi, err))
		return -1;
	int rc = albedo_adaptive(m, theta_i, nmu, nphi, ALB_NMU_MAX, 0, scaled, TAB_TOL, 1e-300, -HUGE_VAL, &ws, out, NULL,
				 err);
	albedo_ws_free(&ws);
	return rc;
}

/*
 * The energy table: A(θ, λ) ≥ the albedo a(θ, λ) of the unscaled interpolant on each interval of θ.
 * Each node's channels come from albedo_adaptive (from 10 × 12, doubled up to 160 × 192 until two rules
 * agree to TAB_TOL in albedo units, relative above 1: the table is only ever compared with 1), because the
 * map back e^g can make lobes far narrower than the kernel; d is the last difference between rules. The
 * nodes start every 10°; each interval [θ_lo, θ_hi] is probed at its midpoint and, while some channel's
 * second difference Δ = |a_lo − 2a_mid + a_hi| exceeds TAB_CURV_TOL · max(1, a) (plus, where the interval
 * is clearly below 1, what the nodes' quadrature uncertainty can make of it, 3(d_lo + 2d_mid + d_hi)) (a
 * feature narrower than the interval: a spike in θi), bisected, down to 10°/2^TAB_DEPTH. Both halves then get the bound
 * max(a + 2d over the three nodes) + Δ (the interpolation error h²/8·|a''| of a C² function, with a''
 * from Δ, doubled). The evaluated function is s·f̂ with s = 1/max(1, A(θi), A(θo)), whose albedo at θi is
 * ≤ a(θi)/max(1, A(θi)) ≤ 1 whenever A bounds a. `brdf-recon check` verifies it with an independent rule.
 * The work is bounded: intervals are bisected level by level (all of one level before the next) up to
 * TAB_MAX_NODES nodes; an interval left open keeps the bound of the probe that opened it.
 */
struct albtab {
	const struct recon_model *m;
	struct albedo_ws ws;
	int nmu, nphi;      /* starting rule (lobe_rule) */
	double *diff;
	size_t L;
	double margin;
};

/* a[L] = the node's albedo plus its quadrature margin 2d. */
static int albtab_node(struct albtab *T, double theta, double *a, struct acq_err *err)
{
	if (albedo_adaptive(T->m, theta, T->nmu, T->nphi, TAB_NMU_MAX, 0, 0, TAB_TOL, 1.0, TAB_BELOW, &T->ws, a, T->diff,
			    err))
		return -1;
	for (size_t l = 0; l < T->L; l++) {
		double mg = 2.0 * T->diff[l] + 1e-9 * fabs(a[l]);
		if (mg > T->margin)
			T->margin = mg;
		a[l] += mg;
	}
	return 0;
}

/* Nodes th[n] with rows a[n·L] and their last quadrature differences dq[n·L]; interval i (node i to i+1) has
 * done[i] and bound row b[i·L]. */
struct albgrid {
	size_t n;
	double *th, *a, *dq, *b;
	unsigned char *done;
};

static void albgrid_free(struct albgrid *g)
{
	free(g->th);
	free(g->a);
	free(g->dq);
	free(g->b);
	free(g->done);
	memset(g, 0, sizeof *g);
}

static int albgrid_alloc(struct albgrid *g, size_t cap, size_t L)
{
	memset(g, 0, sizeof *g);
	g->th = malloc(cap * sizeof *g->th);
	g->a = malloc(cap * L * sizeof *g->a);
	g->dq = malloc(cap * L * sizeof *g->dq);
	g->b = calloc(cap * L, sizeof *g->b);
	g->done = calloc(cap, 1);
	return g->th && g->a && g->dq && g->b && g->done ? 0 : -1;
}

static void albgrid_push(struct albgrid *g, size_t L, double th, const double *a, const double *dq, const double *b,
			 int done)
{
	g->th[g->n] = th;
	memcpy(g->a + g->n * L, a, L * sizeof *a);
	memcpy(g->dq + g->n * L, dq, L * sizeof *dq);
	if (b)
		memcpy(g->b + g->n * L, b, L * sizeof *b);
	g->done[g->n] = (unsigned char)done;
	g->n++;
}

static int build_albedo_table(struct recon_model *m, struct acq_err *err, recon_progress_fn pf, void *pctx)
{
	size_t L = m->nwl;
	struct albtab T = { .m = m, .L = L };
	struct albgrid g = { 0 }, ng = { 0 };
	double *amid = malloc(2 * L * sizeof *amid), *bnd = amid ? amid + L : NULL;
	T.diff = malloc(L * sizeof *T.diff);
	int rc = -1;
	size_t qmax;
	T.nmu = TAB_NMU;
	T.nphi = TAB_NPHI;
	lobe_rule(m, TAB_NMU_MAX, &T.nmu, &T.nphi, &qmax);
	if (!amid || !T.diff || albgrid_alloc(&g, TAB_MAX_NODES, L) || albedo_ws_init(&T.ws, m, qmax, err)) {
		acq_errf(err, ACQ_E_NOMEM, "albedo table: out of memory");
		goto out;
	}
	double h = (M_PI / 2) / (double)(TAB_N - 1);
	for (size_t t = 0; t < TAB_N; t++) {
		if (pf)
			pf(pctx, "albedo table", 0.5 * (double)t / (double)TAB_N);
		double th = t + 1 == TAB_N ? M_PI / 2 : h * (double)t;
		if (albtab_node(&T, th, amid, err))
			goto out;
		albgrid_push(&g, L, th, amid, T.diff, NULL, 0);
	}
	/* breadth first: every interval of one level is probed before any of the next, so the node budget
	 * is spent evenly where the albedo bends */
	for (int depth = 0; depth <= TAB_DEPTH; depth++) {
		if (pf)
			pf(pctx, "albedo table", 0.5 + 0.5 * (double)depth / (TAB_DEPTH + 1));
		if (albgrid_alloc(&ng, TAB_MAX_NODES, L)) {
			acq_errf(err, ACQ_E_NOMEM, "albedo table: out of memory");
			goto out;
		}
		int again = 0;
		for (size_t i = 0; i + 1 < g.n; i++) {
			const double *alo = g.a + i * L, *ahi = g.a + (i + 1) * L;
			/* the first level always probes; later ones while nodes remain (one per open interval) */
			if (g.done[i] || (depth > 0 && ng.n + (g.n - i) + 1 > TAB_MAX_NODES)) {
				albgrid_push(&ng, L, g.th[i], alo, g.dq + i * L, g.b + i * L, 1);
				continue;
			}
			double tmid = 0.5 * (g.th[i] + g.th[i + 1]);
			if (albtab_node(&T, tmid, amid, err))
				goto out;
			int split = 0;
			const double *dlo = g.dq + i * L, *dhi = g.dq + (i + 1) * L;
			for (size_t l = 0; l < L; l++) {
				double d2 = fabs(alo[l] - 2.0 * amid[l] + ahi[l]);
				double mx = fmax(alo[l], fmax(amid[l], ahi[l]));
				/* a bend beyond what the nodes' quadrature uncertainty (each a = fine + 2d, fine within
				 * ≈ d of the exact value) can make of the second difference, where the interval is clearly
				 * below 1; near 1 every bend counts (a loose bound there scales the BRDF down for nothing) */
				double qn = 3.0 * (dlo[l] + 2.0 * T.diff[l] + dhi[l]);
				if (!(mx + d2 + qn <= TAB_BELOW))
					qn = 0;
				if (d2 > TAB_CURV_TOL * fmax(mx, 1.0) + qn)
					split = 1;
				bnd[l] = mx + d2;
			}
			int done = !split || depth == TAB_DEPTH;
			albgrid_push(&ng, L, g.th[i], alo, dlo, bnd, done);
			albgrid_push(&ng, L, tmid, amid, T.diff, bnd, done);
			again |= !done;
		}
		albgrid_push(&ng, L, g.th[g.n - 1], g.a + (g.n - 1) * L, g.dq + (g.n - 1) * L, NULL, 1);
		albgrid_free(&g);
		g = ng;
		memset(&ng, 0, sizeof ng);
		if (!again)
			break;
	}
	m->ntab = g.n;
	m->alb_margin = T.margin;
	m->tab_theta = malloc(g.n * sizeof *m->tab_theta);
	m->tab_alb = malloc((g.n - 1) * L * sizeof *m->tab_alb);
	if (!m->tab_theta || !m->tab_alb) {
		acq_errf(err, ACQ_E_NOMEM, "albedo table: out of memory");
		goto out;
	}
	memcpy(m->tab_theta, g.th, g.n * sizeof *g.th);
	memcpy(m->tab_alb, g.b, (g.n - 1) * L * sizeof *g.b);
	rc = 0;
out:
	free(amid);
	free(T.diff);
	albgrid_free(&g);
	albgrid_free(&ng);
	albedo_ws_free(&T.ws);
	return rc;
}

/* ---- fitting ------------------------------------------------------------------------------------------ */

/* Median by quickselect (Hoare partition), O(n); reorders v. */
static double median(double *v, size_t n)
{
	if (n == 0)
		return NAN;
	size_t k = n / 2;
	size_t lo = 0, hi = n - 1;
	while (lo < hi) {
		double pivot = v[lo + (hi - lo) / 2];
		size_t i = lo, j = hi;
		while (i <= j) {
			while (v[i] < pivot)
				i++;
			while (v[j] > pivot)
				j--;
			if (i <= j) {
				double t = v[i];
				v[i] = v[j];
				v[j] = t;
				i++;
				if (j == 0)
					break;
				j--;
			}
		}
		if (k <= j)
			hi = j;
		else if (k >= i)
			lo = i;
		else
			break;
	}
	double m = v[k];
	if (n % 2 == 0) { /* the lower middle is the largest of v[0..k) */
		double lm = v[0];
		for (size_t i = 1; i < k; i++)
			if (v[i] > lm)
				lm = v[i];
		m = 0.5 * (m + lm);
	}
	return m;
}

static double cdist6(const double *a, const double *b)
{
	double s = 0;
	for (int i = 0; i < 6; i++)
		s += (a[i] - b[i]) * (a[i] - b[i]);
	return s;
}

/* Shape grids (chordal units for wendland/gauss, radians for exp/paper). */
static int shape_grid(int kernel, double *g)
{
	static const double wend[] = { 1.2, 1.8, 2.6, 4.0 };
	static const double expo[] = { 0.5, 1.0, 2.0, 4.0 };
	static const double gaus[] = { 0.4, 0.6, 0.9, 1.4 };
	const double *src = kernel == RBF_K_WENDLAND ? wend : kernel == RBF_K_EXP ? expo : gaus;
	memcpy(g, src, 4 * sizeof *g);
	return 4;
}

struct fitctx {
	size_t n, L;
	double *K;     /* n×n kernel matrix for the current shape */
	double *A;     /* work copy */
	double *lam;
	double *G;     /* L×n centred transformed data (channel-major) */
	double max_cond;
};

/* Factor A = K + η diag(lam) into fc->A (lower Cholesky); 0 ok, 1 not PD, 2 too ill-conditioned. */
static int factor(struct fitctx *fc, double eta, double *rcond)
{
	size_t n = fc->n;
	memcpy(fc->A, fc->K, n * n * sizeof *fc->A);
	for (size_t k = 0; k < n; k++)
		fc->A[k * n + k] += eta * fc->lam[k];
	double anorm = LAPACKE_dlansy(LAPACK_COL_MAJOR, '1', 'L', (lapack_int)n, fc->A, (lapack_int)n);
	if (LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', (lapack_int)n, fc->A, (lapack_int)n) != 0)
		return 1;
	double rc = 0;
	if (LAPACKE_dpocon(LAPACK_COL_MAJOR, 'L', (lapack_int)n, fc->A, (lapack_int)n, anorm, &rc) != 0)
		return 1;
	*rcond = rc;
	if (!(rc > 0) || 1.0 / rc > fc->max_cond)
		return 2;
	return 0;
}

/* The diagonal of A⁻¹ from the lower Cholesky factor L of A (column-major, destroyed): A⁻¹ = L⁻ᵀL⁻¹, so
 * (A⁻¹)_kk = Σ_{i≥k} (L⁻¹)_ik², the squared norm of column k of L⁻¹ (dtrtri, n³/3 flops; dpotri would also
 * form the rest of A⁻¹, another n³/3, that no caller reads). (A⁻¹)_kk is left in A[k·n + k]; 0 ok. */
static int diag_inv_chol(double *A, size_t n)
{
	if (LAPACKE_dtrtri(LAPACK_COL_MAJOR, 'L', 'N', (lapack_int)n, A, (lapack_int)n) != 0)
		return -1;
	for (size_t k = 0; k < n; k++) {
		const double *col = A + k * n;
		double s = 0;
		for (size_t i = k; i < n; i++)
			s += col[i] * col[i];
		A[k * n + k] = s; /* column k is not read again */
	}
	return 0;
}

/* Rippa: every leave-one-out residual from one factorisation, e_k = (A⁻¹g)_k / (A⁻¹)_kk, over the channels
 * chan[0..nc) of each candidate data set Gs[0..ncand) (centred, channel-major). fc->A holds the factor on
 * entry and is destroyed. score[g] is candidate g's mean squared residual (INFINITY if the solve failed). */
static void rippa(struct fitctx *fc, const double *const *Gs, int ncand, const size_t *chan, size_t nc, double *rhs,
		  double *score)
{
	size_t n = fc->n;
	for (int g = 0; g < ncand; g++) {
		score[g] = INFINITY;
		for (size_t c = 0; c < nc; c++)
			memcpy(rhs + ((size_t)g * nc + c) * n, Gs[g] + chan[c] * n, n * sizeof *rhs);
	}
	if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)(nc * (size_t)ncand), fc->A,
			   (lapack_int)n, rhs, (lapack_int)n) != 0)
		return;
	if (diag_inv_chol(fc->A, n) != 0)
		return;
	for (int g = 0; g < ncand; g++) {
		double s = 0;
		for (size_t c = 0; c < nc; c++)
			for (size_t k = 0; k < n; k++) {
				double e = rhs[((size_t)g * nc + c) * n + k] / fc->A[k * n + k];
				s += e * e;
			}
		score[g] = s / (double)(n * nc);
	}
}

static void build_K(struct fitctx *fc, int kernel, double shape, const double *ctr, const double *tctr)
{
	size_t n = fc->n;
	for (size_t j = 0; j < n; j++)
		for (size_t i = j; i < n; i++) {
			double v = rbf_kernel(kernel, shape, ctr + 6 * i, ctr + 6 * j, tctr + 6 * j);
			fc->K[j * n + i] = v;
			fc->K[i * n + j] = v;
		}
}

int recon_fit(const struct recon_samples *s, const struct recon_fit_opts *opts, struct recon_model **out,
	      struct acq_err *err)
{
	struct recon_fit_opts o;
	if (opts)
		o = *opts;
	else
		recon_fit_opts_default(&o);
	*out = NULL;
	if (!s || s->n == 0 || s->nwl == 0 || !s->ang || !s->val || !s->wl)
		return acq_errf(err, ACQ_E_INVAL, "fit: no samples");
	if (!rbf_kernel_name(o.kernel))
		return acq_errf(err, ACQ_E_INVAL, "fit: unknown kernel %d", o.kernel);
	if (!recon_transform_name(o.transform))
		return acq_errf(err, ACQ_E_INVAL, "fit: unknown transform %d", o.transform);
	if (o.trend >= RECON_TREND__COUNT || o.trend < -1)
		return acq_errf(err, ACQ_E_INVAL, "fit: unknown trend %d", o.trend);
	if (o.trend == RECON_TREND_GGX && o.transform != RECON_T_LOG)
		return acq_errf(err, ACQ_E_INVAL, "fit: the ggx trend needs the log transform");
	if (!(o.shape >= 0) || !isfinite(o.shape) || !isfinite(o.smoothing) || !(o.max_cond >= 1))
		return acq_errf(err, ACQ_E_INVAL, "fit: shape, smoothing and condition limit must be finite");

	size_t L = s->nwl, n0 = s->n;
	int rc = -1;
	struct recon_model *m = calloc(1, sizeof *m);
	size_t *rep = malloc(n0 * sizeof *rep), *idx = malloc(n0 * sizeof *idx);
	double *c6 = malloc(n0 * 6 * sizeof *c6);
	double *tmp = malloc((n0 > L ? n0 : L) * sizeof *tmp);
	struct fitctx fc = { 0 };
	double *rhs = NULL, *val = NULL, *sig = NULL, *wsum = NULL, *tlog = NULL, *tbas = NULL, *G2 = NULL;
	if (!m || !rep || !idx || !c6 || !tmp) {
		acq_errf(err, ACQ_E_NOMEM, "fit: out of memory");
		goto out;
	}
	m->kernel = o.kernel;
	m->transform = o.transform;
	m->trend = o.trend >= 0 ? o.trend : o.transform == RECON_T_LOG ? RECON_TREND_GGX : RECON_TREND_NONE;

	/* 1. canonical points; rows without any value are dropped; repeated and reciprocal rows merged */
	size_t n = 0, dropped = 0, merged = 0;
	for (size_t k = 0; k < n0; k++) {
		const double *a = s->ang + 4 * k;
		if (!(a[0] >= 0 && a[0] <= M_PI / 2 + 1e-12 && a[2] >= 0 && a[2] <= M_PI / 2 + 1e-12) ||
		    !isfinite(a[1]) || !isfinite(a[3])) {
			acq_errf(err, ACQ_E_RANGE, "fit: sample %zu: angles (%g, %g, %g, %g)° outside θ ∈ [0, 90]°, finite φ",
				 k + 1, a[0] * 180 / M_PI, a[1] * 180 / M_PI, a[2] * 180 / M_PI, a[3] * 180 / M_PI);
			goto out;
		}
		int any = 0;
		for (size_t l = 0; l < L && !any; l++)
			any = isfinite(s->val[k * L + l]);
		if (!any) {
			dropped++;
			rep[k] = SIZE_MAX;
			continue;
		}
		double cc[6];
		rbf_canon(a[0], a[1], a[2], a[3], cc);
		size_t j;
		for (j = 0; j < n; j++)
			if (cdist6(cc, c6 + 6 * j) < MERGE_TOL * MERGE_TOL)
				break;
		if (j == n) {
			memcpy(c6 + 6 * n, cc, sizeof cc);
			idx[n] = k;
			n++;
		} else {
			merged++;
		}
		rep[k] = j;
	}
	if (n == 0) {
		acq_errf(err, ACQ_E_INVAL, "fit: every row is empty (no measured value)");
		goto out;
	}
	if (n > RECON_MAX_N) {
		acq_errf(err, ACQ_E_RANGE, "fit: %zu distinct directions, limit %d", n, RECON_MAX_N);
		goto out;
	}
	m->n = n;
	m->nwl = L;
	m->wl = malloc(L * sizeof *m->wl);
	m->eps = calloc(L, sizeof *m->eps);
	m->mu = calloc(L, sizeof *m->mu);
	m->ang = malloc(n * 4 * sizeof *m->ang);
	m->lam = malloc(n * sizeof *m->lam);
	m->w = malloc(n * L * sizeof *m->w);
	m->g = malloc(n * L * sizeof *m->g);
	m->gsig = malloc(n * L * sizeof *m->gsig);
	val = calloc(n * L, sizeof *val);  /* merged values, channel-major */
	sig = calloc(n * L, sizeof *sig);  /* merged sigma (NAN = none) */
	wsum = calloc(n * L, sizeof *wsum);
	if (!m->wl || !m->eps || !m->mu || !m->ang || !m->lam || !m->w || !m->g || !m->gsig || !val || !sig ||
	    !wsum) {
		acq_errf(err, ACQ_E_NOMEM, "fit: out of memory (%zu directions × %zu wavelengths)", n, L);
		goto out;
	}
	memcpy(m->wl, s->wl, L * sizeof *m->wl);
	for (size_t l = 0; l < L; l++)
		if (!isfinite(m->wl[l]) || !(m->wl[l] > 0) || (l && !(m->wl[l] > m->wl[l - 1]))) {
			acq_errf(err, ACQ_E_INVAL, "fit: wavelengths must be positive and increasing");
			goto out;
		}
	for (size_t j = 0; j < n; j++)
		memcpy(m->ang + 4 * j, s->ang + 4 * idx[j], 4 * sizeof(double));
	/* merge: inverse-variance weights when every merged value has a positive sigma, else equal weights */
	int have_sig = s->sig != NULL;
	for (size_t k = 0; k < n0; k++) {
		if (rep[k] == SIZE_MAX)
			continue;
		size_t j = rep[k];
		for (size_t l = 0; l < L; l++) {
			double v = s->val[k * L + l];
			if (!isfinite(v))
				continue;
			double sg = have_sig ? s->sig[k * L + l] : NAN;
			double wgt = isfinite(sg) && sg > 0 ? 1.0 / (sg * sg) : 1.0;
			if (!(isfinite(sg) && sg > 0))
				sg = NAN;
			size_t at = l * n + j;
			if (wsum[at] == 0) {
				val[at] = v * wgt;
				sig[at] = isfinite(sg) ? wgt : NAN; /* accumulates Σ 1/σ² while merging */
			} else {
				val[at] += v * wgt;
				sig[at] = (isfinite(sig[at]) && isfinite(sg)) ? sig[at] + wgt : NAN;
			}
			wsum[at] += wgt;
		}
	}
	size_t imputed = 0;
	int phi_i_varies = 0; /* recorded: the model treats the material as isotropic regardless */
	for (size_t k = 1; k < n0; k++)
		if (fabs(remainder(s->ang[4 * k + 1] - s->ang[1], 2 * M_PI)) > 1e-9 && s->ang[4 * k] > 0 && s->ang[0] > 0)
			phi_i_varies = 1;
	for (size_t l = 0; l < L; l++) {
		size_t have = 0;
		for (size_t j = 0; j < n; j++) {
			size_t at = l * n + j;
			if (wsum[at] > 0) {
				val[at] /= wsum[at];
				sig[at] = isfinite(sig[at]) ? 1.0 / sqrt(sig[at]) : NAN;
				have++;
			} else {
				val[at] = NAN;
				sig[at] = NAN;
			}
		}
		if (!have) {
			acq_errf(err, ACQ_E_INVAL, "fit: wavelength %g nm has no measured value", m->wl[l]);
			goto out;
		}
	}
	/* 2. missing values: nearest measured direction of the same channel (reciprocal metric), flagged */
	unsigned char *imp = calloc(n * L, 1);
	if (!imp) {
		acq_errf(err, ACQ_E_NOMEM, "fit: out of memory");
		goto out;
	}
	for (size_t l = 0; l < L; l++)
		for (size_t j = 0; j < n; j++) {
			if (isfinite(val[l * n + j]))
				continue;
			double best = INFINITY;
			size_t bj = j;
			double tj[6];
			rbf_tau(c6 + 6 * j, tj);
			for (size_t i = 0; i < n; i++) {
				if (!isfinite(val[l * n + i]) || imp[l * n + i])
					continue;
				double d = fmin(cdist6(c6 + 6 * j, c6 + 6 * i), cdist6(tj, c6 + 6 * i));
				if (d < best) {
					best = d;
					bj = i;
				}
			}
			val[l * n + j] = val[l * n + bj];
			sig[l * n + j] = NAN;
			imp[l * n + j] = 1;
			imputed++;
		}
	/*
	 * 3. Non-negativity by construction: the interpolant is built on g = T(f) and mapped back through a
	 * non-negative T⁻¹, so f̂ ≥ 0 everywhere, not only at the samples (non-negative weights would also do,
	 * but would need an NNLS per channel instead of one factorisation for all).
	 *   log:  g = ln(max(f, 0) + ε), f̂ = max(0, e^g − ε). Multiplicative: suits the orders of magnitude
	 *         between diffuse and specular values. Bias: the interpolant averages in log space, i.e. a
	 *         geometric mean (low by ≈ σ_g²/2 relative where it smooths noise); ε (1 % of the median
	 *         value, or the median σ if larger) keeps noisy near-zero values from pulling g to −∞ and
	 *         lifts values ≪ ε towards ε before the map back removes it again.
	 *   sqrt: g = √max(f, 0), f̂ = g². Additive near 0; bias +σ_g² (the square of the noise).
	 * Negative measurements are clamped to 0 before the transform (noise around a dark value). Transformed
	 * uncertainties come from the delta method, σ_g = σ·|dg/df|.
	 */
	int any_sig = 0;
	for (size_t l = 0; l < L; l++) {
		size_t cnt = 0, cs = 0;
		for (size_t j = 0; j < n; j++)
			tmp[cnt++] = fabs(val[l * n + j]);
		double med = median(tmp, cnt);
		for (size_t j = 0; j < n; j++)
			if (isfinite(sig[l * n + j]))
				tmp[cs++] = sig[l * n + j];
		double meds = cs ? median(tmp, cs) : 0;
		if (cs)
			any_sig = 1;
		double eps = 0;
		if (o.transform == RECON_T_LOG) {
			/* ε: 1 % of the typical value, at least the typical noise, never 0 */
			eps = fmax(0.01 * med, meds);
			if (!(eps > 1e-12))
				eps = 1e-12;
		}
		m->eps[l] = eps;
	}
	/*
	 * 3b. The trend (trend.h): with the log transform the RBF may interpolate ln(f + ε) − ln(T + ε), the data
	 * relative to a Lambertian + GGX lobe fitted to them, so that between samples the BRDF follows a
	 * microfacet lobe instead of the kernel's shape (a 36° azimuth step is wider than a specular lobe).
	 * By default (auto) both readings are candidates and Rippa's leave-one-out score picks one together
	 * with the shape and the smoothing (same factorisation, another right-hand side): a lobe that is not a
	 * microfacet lobe (a Phong lobe about the mirror direction) keeps the plain interpolant.
	 */
	int ncand = 1, cand_ggx = m->trend == RECON_TREND_GGX && o.trend < 0;
	if (cand_ggx)
		ncand = 2; /* candidate 0: none, 1: ggx */
	m->tcoef = calloc(L * TREND_NB, sizeof *m->tcoef);
	if (!m->tcoef) {
		acq_errf(err, ACQ_E_NOMEM, "fit: out of memory");
		goto out;
	}
	/* the channels scored by the trend's roughness search and by the leave-one-out search */
	size_t chan[16], nc = L < 16 ? L : 16;
	for (size_t c = 0; c < nc; c++)
		chan[c] = nc > 1 ? c * (L - 1) / (nc - 1) : 0;
	double trend_rms = 0;
	if (m->trend == RECON_TREND_GGX) {
		if (trend_fit(n, L, val, m->eps, c6, chan, nc, &m->trend_alpha, m->tcoef, &trend_rms, err))
			goto out;
		tlog = malloc(n * L * sizeof *tlog);
		tbas = malloc(n * TREND_NB * sizeof *tbas);
		if (!tlog || !tbas) {
			acq_errf(err, ACQ_E_NOMEM, "fit: out of memory");
			goto out;
		}
		for (size_t j = 0; j < n; j++) /* the basis once per sample, not once per channel */
			trend_at(m, c6 + 6 * j, tbas + j * TREND_NB);
	}
	for (size_t l = 0; l < L; l++) {
		double eps = m->eps[l], sum = 0;
		for (size_t j = 0; j < n; j++) {
			double v = val[l * n + j], sg = sig[l * n + j], pv = v > 0 ? v : 0;
			double g, gs;
			if (o.transform == RECON_T_LOG) {
				g = log(pv + eps);
				if (tlog)
					tlog[l * n + j] = log(trend_val(m, tbas + j * TREND_NB, l) + eps);
				gs = isfinite(sg) ? sg / (pv + eps) : NAN;
			} else {
				g = sqrt(pv);
				gs = isfinite(sg) ? sg / (2.0 * sqrt(pv + sg) + 1e-300) : NAN;
			}
			m->g[l * n + j] = g;
			m->gsig[l * n + j] = gs;
			sum += g;
		}
		m->mu[l] = sum / (double)n;
	}
	/* imputed entries: the largest transformed uncertainty of their channel (or NAN, set after LOO) */
	for (size_t l = 0; l < L; l++) {
		double mx = 0;
		for (size_t j = 0; j < n; j++)
			if (isfinite(m->gsig[l * n + j]) && m->gsig[l * n + j] > mx)
				mx = m->gsig[l * n + j];
		for (size_t j = 0; j < n; j++)
			if (imp[l * n + j])
				m->gsig[l * n + j] = any_sig && mx > 0 ? mx : NAN;
	}
	free(imp);
	/* 4. relative noise pattern r_k: median over channels of σ_g², normalised to mean 1 */
	double rsum = 0;
	for (size_t j = 0; j < n; j++) {
		size_t cnt = 0;
		for (size_t l = 0; l < L; l++)
			if (isfinite(m->gsig[l * n + j]))
				tmp[cnt++] = m->gsig[l * n + j] * m->gsig[l * n + j];
		m->lam[j] = cnt ? median(tmp, cnt) : 1.0;
		rsum += m->lam[j];
	}
	double rmean = rsum / (double)n;
	for (size_t j = 0; j < n; j++) {
		m->lam[j] = rmean > 0 ? m->lam[j] / rmean : 1.0;
		if (!(m->lam[j] > 1e-6))
			m->lam[j] = 1e-6;
	}
	if (recon_model_derive(m, err))
		goto out;

	/* 5. shape and smoothing by Rippa's leave-one-out over a small grid (≤ 16 channels scored) */
	fc.n = n;
	fc.L = L;
	fc.lam = m->lam;
	fc.max_cond = o.max_cond;
	fc.K = malloc(n * n * sizeof *fc.K);
	fc.A = malloc(n * n * sizeof *fc.A);
	fc.G = malloc(n * L * sizeof *fc.G);
	rhs = malloc(n * (L > 32 ? L : 32) * sizeof *rhs);
	if (!fc.K || !fc.A || !fc.G || !rhs) {
		acq_errf(err, ACQ_E_NOMEM, "fit: out of memory for the %zu × %zu system", n, n);
		goto out;
	}
	/* candidate data: the plain transformed values, and (ggx) the values relative to the trend */
	if (tlog) {
		G2 = malloc(n * L * sizeof *G2);
		if (!G2) {
			acq_errf(err, ACQ_E_NOMEM, "fit: out of memory");
			goto out;
		}
		for (size_t l = 0; l < L; l++) {
			double sum = 0;
			for (size_t j = 0; j < n; j++)
				sum += G2[l * n + j] = m->g[l * n + j] - tlog[l * n + j];
			for (size_t j = 0; j < n; j++)
				G2[l * n + j] -= sum / (double)n;
		}
	}
	for (size_t l = 0; l < L; l++)
		for (size_t j = 0; j < n; j++)
			fc.G[l * n + j] = m->g[l * n + j] - m->mu[l];
	if (tlog && !cand_ggx) /* explicit --trend ggx: the only candidate */
		memcpy(fc.G, G2, n * L * sizeof *fc.G);
	const double *Gs[2] = { fc.G, G2 };
	double shapes[8], etas[8];
	int nsh = o.shape > 0 ? 1 : shape_grid(o.kernel, shapes), neta;
	if (o.shape > 0)
		shapes[0] = o.shape;
	static const double eta_grid[] = { 1e-8, 1e-5, 1e-3, 1e-2, 1e-1 };
	/*
	 * --smoothing sigma: Λ straight from the measurement uncertainties, as in a Gaussian-process model
	 * g = s(x) + noise with prior variance α·K: (αK + diag(σ_g²)) w' = g, i.e. η·r_k = σ_g,k²/α with
	 * α = var(g) / mean diag K (the data's spread attributed to the prior). Only the shape is searched.
	 */
	int sigma_mode = o.smoothing == RECON_SMOOTHING_SIGMA;
	double varG = 0;
	if (sigma_mode) {
		if (!any_sig) {
			acq_errf(err, ACQ_E_INVAL, "fit: --smoothing sigma needs sigma_<nm> columns");
			goto out;
		}
		for (size_t l = 0; l < L; l++) {
			double v = 0;
			for (size_t j = 0; j < n; j++)
				v += fc.G[l * n + j] * fc.G[l * n + j];
			varG += v / (double)n / (double)L;
		}
		if (!(varG > 0))
			varG = 1;
		neta = 1;
		etas[0] = 0; /* set per shape below */
	} else if (o.smoothing >= 0) {
		etas[0] = o.smoothing;
		neta = 1;
	} else {
		neta = 5;
		memcpy(etas, eta_grid, sizeof eta_grid);
	}
	double best = INFINITY, bshape = shapes[0], beta = etas[0];
	int bcand = 0;
	int nfail_pd = 0, nfail_cond = 0;
	double worst_rcond = INFINITY;
	for (int a = 0; a < nsh; a++) {
		build_K(&fc, o.kernel, shapes[a], m->ctr, m->tctr);
		if (sigma_mode) {
			double dsum = 0;
			for (size_t k = 0; k < n; k++)
				dsum += fc.K[k * n + k];
			etas[0] = fmax(rmean * (dsum / (double)n) / varG, 1e-12);
		}
		for (int b = 0; b < neta; b++) {
			if (o.progress)
				o.progress(o.progress_ctx, "shape search", (double)(a * neta + b) / (double)(nsh * neta));
			double rcond = 0;
			int f = factor(&fc, etas[b], &rcond);
			if (f == 1) {
				nfail_pd++;
				continue;
			}
			if (f == 2) {
				nfail_cond++;
				if (rcond < worst_rcond)
					worst_rcond = rcond;
				continue;
			}
			double score[2] = { 0, 0 };
			if (nsh * neta * ncand > 1)
				rippa(&fc, Gs, ncand, chan, nc, rhs, score);
			for (int c = 0; c < ncand; c++)
				if (score[c] < best || (best == INFINITY && nsh * neta * ncand == 1)) {
					best = score[c];
					bshape = shapes[a];
					beta = etas[b];
					bcand = c;
				}
		}
	}
	if (best == INFINITY) {
		if (nfail_pd)
			acq_errf(err, ACQ_E_NUMERIC,
				 "fit: the system K + Λ is not positive definite for kernel '%s' on these %zu directions "
				 "(%d of %d settings failed Cholesky)%s", rbf_kernel_name(o.kernel), n, nfail_pd,
				 nsh * neta, o.kernel == RBF_K_PAPER ? "; the paper's kernel is not PD on the sphere: use "
				 "--kernel wendland" : "; increase --smoothing");
		else
			acq_errf(err, ACQ_E_NUMERIC,
				 "fit: K + Λ too ill-conditioned (condition ≈ %.3g > limit %.3g) for every setting tried; "
				 "increase --smoothing or reduce --shape", 1.0 / worst_rcond, o.max_cond);
		goto out;
	}
	m->shape = bshape;
	m->eta = beta;
	if (cand_ggx && bcand == 1)
		memcpy(fc.G, G2, n * L * sizeof *fc.G);
	if (tlog && (!cand_ggx || bcand == 1)) { /* the trend is kept: the model's data are relative to it */
		for (size_t l = 0; l < L; l++) {
			double sum = 0;
			for (size_t j = 0; j < n; j++)
				sum += m->g[l * n + j] -= tlog[l * n + j];
			m->mu[l] = sum / (double)n;
		}
	} else if (m->trend != RECON_TREND_NONE) { /* auto chose the plain interpolant */
		m->trend = RECON_TREND_NONE;
		m->trend_alpha = 0;
		memset(m->tcoef, 0, L * TREND_NB * sizeof *m->tcoef);
	}
	/* 6. the one factorisation; every channel is a right-hand side */
	if (o.progress)
		o.progress(o.progress_ctx, "solve", 0.0);
	build_K(&fc, o.kernel, bshape, m->ctr, m->tctr);
	if (factor(&fc, beta, &m->rcond) != 0) {
		acq_errf(err, ACQ_E_NUMERIC, "fit: final factorisation failed");
		goto out;
	}
	memcpy(m->w, fc.G, n * L * sizeof *m->w);
	if (LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)n, (lapack_int)L, fc.A, (lapack_int)n, m->w,
			   (lapack_int)n) != 0) {
		acq_errf(err, ACQ_E_NUMERIC, "fit: solve failed");
		goto out;
	}
	for (size_t i = 0; i < n * L; i++)
		if (!isfinite(m->w[i])) {
			acq_errf(err, ACQ_E_NUMERIC, "fit: non-finite weights");
			goto out;
		}
	/* leave-one-out residuals of every channel (for the record, and as the noise level without sigmas) */
	if (diag_inv_chol(fc.A, n) != 0) {
		acq_errf(err, ACQ_E_NUMERIC, "fit: inverse failed");
		goto out;
	}
	double tot = 0;
	for (size_t l = 0; l < L; l++) {
		double sc = 0;
		for (size_t k = 0; k < n; k++) {
			double e = m->w[l * n + k] / fc.A[k * n + k];
			sc += e * e;
		}
		tot += sc;
		double rms = n > 1 ? sqrt(sc / (double)n) : 0.0;
		for (size_t k = 0; k < n; k++)
			if (!isfinite(m->gsig[l * n + k]))
				m->gsig[l * n + k] = rms;
	}
	m->loo_rms = sqrt(tot / (double)(n * L));
	/* 7. energy table of the unscaled interpolant */
	if (build_albedo_table(m, err, o.progress, o.progress_ctx))
		goto out;
	char when[32];
	time_t now = time(NULL);
	struct tm tmv;
	gmtime_r(&now, &tmv);
	strftime(when, sizeof when, "%Y-%m-%dT%H:%M:%SZ", &tmv);
	snprintf(m->meta, sizeof m->meta,
		 "software=acquisitiond %s\ncreated=%s\nsource=%s\nrows=%zu\nrows_dropped_empty=%zu\n"
		 "rows_merged=%zu\nvalues_imputed=%zu\nuncertainties=%s\nloo_rms_transformed=%.6g\n"
		 "rcond=%.6g\nalbedo_margin=%.6g\ntrend=%s\ntrend_alpha=%.6g\ntrend_rms_log=%.6g\nsymmetry=isotropic%s\n",
		 ACQ_VERSION, when, o.source ? o.source : "-", n0, dropped, merged, imputed,
		 have_sig ? "given" : "leave-one-out", m->loo_rms, m->rcond, m->alb_margin, trend_name(m->trend),
		 m->trend_alpha, trend_rms,
		 phi_i_varies ? " (phi_i varies in the data: azimuths taken relative to phi_i)" : "");
	for (char *p = m->meta; *p; p++) /* keep metadata printable */
		if ((unsigned char)*p < 0x20 && *p != '\n')
			*p = '?';
	if (o.progress)
		o.progress(o.progress_ctx, "done", 1.0);
	*out = m;
	m = NULL;
	rc = 0;
out:
	recon_model_free(m);
	free(rep);
	free(idx);
	free(c6);
	free(tmp);
	free(fc.K);
	free(fc.A);
	free(fc.G);
	free(rhs);
	free(tlog);
	free(tbas);
	free(G2);
	free(val);
	free(sig);
	free(wsum);
	return rc;
}

/* ---- random numbers (xoshiro256**, seeded by splitmix64) ------------------------------------------------ */

struct rng {
	uint64_t s[4];
};

static uint64_t splitmix(uint64_t *x)
{
	uint64_t z = (*x += 0x9E3779B97F4A7C15ull);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
	return z ^ (z >> 31);
}

static void rng_seed(struct rng *r, uint64_t seed)
{
	for (int i = 0; i < 4; i++)
		r->s[i] = splitmix(&seed);
}

static inline uint64_t rotl(uint64_t x, int k)
{
	return (x << k) | (x >> (64 - k));
}

static uint64_t rng_u64(struct rng *r)
{
	uint64_t *s = r->s, res = rotl(s[1] * 5, 7) * 9, t = s[1] << 17;
	s[2] ^= s[0];
	s[3] ^= s[1];
	s[1] ^= s[2];
	s[0] ^= s[3];
	s[2] ^= t;
	s[3] = rotl(s[3], 45);
	return res;
}

static double rng_unif(struct rng *r)
{
	return (double)(rng_u64(r) >> 11) * 0x1.0p-53;
}

static double rng_normal(struct rng *r)
{
	double u = rng_unif(r), v = rng_unif(r);
	if (u < 1e-300)
		u = 1e-300;
	return sqrt(-2.0 * log(u)) * cos(2.0 * M_PI * v);
}

/* ---- DHR --------------------------------------------------------------------------------------------- */

/* d f̂ / d g at g (the derivative of untransform; 0 where the clamp at 0 is active). */
static inline double untransform_deriv(int transform, double g, double eps, double tf)
{
	if (!(g == g))
		return 0.0;
	if (transform == RECON_T_SQRT)
		return 2.0 * fmin(fmax(g, -1e15), 1e15);
	if (g > G_MAX)
		g = G_MAX;
	double e = exp(g) * tf;
	return e - eps > 0 ? (e < 1e300 ? e : 1e300) : 0.0;
}

/*
 * DHR(θi, λ) = albedo of the final (energy-scaled) model, with the DHR quadrature above.
 * Uncertainty from two estimates of the same error, σ² = max(σ_noise, σ_model)² + σ_quad²:
 *  - σ_noise, the measurement noise: the reconstruction is not linear in the data (the transform that
 *    guarantees f ≥ 0), so the exact formula Var = Σ c_k² σ_k² does not apply. Monte Carlo instead: each
 *    draw perturbs the transformed data by its standard uncertainty (g + σ_g z, z ~ N(0, 1) independent;
 *    σ_g from the given sigmas by the delta method, or the channel's leave-one-out RMS when the file has
 *    none), re-centres, solves with the ONE Cholesky factor of K + Λ (refactored once from the stored
 *    model), and integrates. The energy factor of the nominal model is kept fixed across draws.
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
 */
/* σ_model² of the DHR at one incidence (see recon_dhr_ex): vmod[l] = α_l (c_lᵀ K_QQ c_l − b_lᵀ A⁻¹ b_l) with
 * c = C[q*L + l] (Q nodes c6), b = K_nQ c (Kq[q*n + k]), A the Cholesky factor; scratch KQQ[Q*Q], soaQ[6Q],
 * U[Q*L], Bt[L*n], X[L*n]. */
static int model_variance(const struct recon_model *m, size_t Q, const double *c6, const double *Kq, const double *A,
			  const double *alpha, const double *C, double *KQQ, double *soaQ, double *U, double *Bt,
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
		double v = alpha[l] * (ckc - bab);
		vmod[l] = v > 0 && isfinite(v) ? v : 0.0;
	}
	return 0;
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
	double *Kq = malloc(nth * Q * n * sizeof *Kq), *wt = malloc(Q * sizeof *wt);
	double *c6 = malloc(nth * Q * 6 * sizeof *c6), *scale = malloc(nth * Q * L * sizeof *scale);
	double *A = malloc(n * n * sizeof *A), *Wd = malloc(n * L * sizeof *Wd), *Y = malloc(Q * L * sizeof *Y);
	double *mean = calloc(nth * L, sizeof *mean), *m2 = calloc(nth * L, sizeof *m2);
	double *mud = malloc(L * sizeof *mud);
	double *C = malloc(Q * L * sizeof *C), *KQQ = malloc(Q * Q * sizeof *KQQ), *soaQ = malloc(6 * Q * sizeof *soaQ);
	double *U = malloc(Q * L * sizeof *U), *Bt = malloc(L * n * sizeof *Bt), *X = malloc(L * n * sizeof *X);
	double *Ainv = malloc(n * n * sizeof *Ainv), *alpha = calloc(L, sizeof *alpha);
	double *vmod = calloc(nth * L, sizeof *vmod), *squad = calloc(nth * L, sizeof *squad);
	double *tb = malloc(nth * Q * TREND_NB * sizeof *tb);
	struct albedo_ws ws = { 0 };
	if (!Kq || !wt || !c6 || !scale || !A || !Wd || !Y || !mean || !m2 || !mud || !C || !KQQ || !soaQ || !U ||
	    !Bt || !X || !Ainv || !alpha || !vmod || !squad || !tb) {
		acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory");
		goto out;
	}
	for (size_t t = 0; t < nth; t++) {
		if (hemi_nodes(theta[t], DHR_NMU, DHR_NPHI, 0, c6 + t * Q * 6, wt)) {
			acq_errf(err, ACQ_E_INVAL, "dhr: quadrature");
			goto out;
		}
		rbf_kmatrix_soa(m->kernel, m->shape, Q, c6 + t * Q * 6, n, m->soa, Kq + t * Q * n);
		for (size_t q = 0; q < Q; q++) {
			const double *c = c6 + (t * Q + q) * 6;
			trend_at(m, c, tb + (t * Q + q) * TREND_NB);
			for (size_t l = 0; l < L; l++)
				scale[(t * Q + q) * L + l] = recon_energy_scale(m, theta_of(c), theta_of(c + 3), l) * wt[q];
		}
	}
	/* the one factorisation of K + Λ, and the leave-one-out amplitude α_λ of every channel */
	for (size_t j = 0; j < n; j++)
		for (size_t i = j; i < n; i++) {
			double v = rbf_kernel(m->kernel, m->shape, m->ctr + 6 * i, m->ctr + 6 * j, m->tctr + 6 * j);
			A[j * n + i] = A[i * n + j] = v;
		}
	for (size_t k = 0; k < n; k++)
		A[k * n + k] += m->eta * m->lam[k];
	if (LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', (lapack_int)n, A, (lapack_int)n) != 0) {
		acq_errf(err, ACQ_E_NUMERIC, "dhr: refactorisation of the model's system failed");
		goto out;
	}
	memcpy(Ainv, A, n * n * sizeof *Ainv);
	if (LAPACKE_dpotri(LAPACK_COL_MAJOR, 'L', (lapack_int)n, Ainv, (lapack_int)n) != 0) {
		acq_errf(err, ACQ_E_NUMERIC, "dhr: inverse of the model's system failed");
		goto out;
	}
	for (size_t l = 0; l < L; l++) {
		double acc = 0;
		for (size_t k = 0; k < n; k++)
			acc += m->w[l * n + k] * m->w[l * n + k] / Ainv[k * n + k];
		alpha[l] = acc / (double)n;
	}
	/* draw 0 is the nominal model; draws 1..ndraws are perturbed */
	struct rng r;
	rng_seed(&r, seed);
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
					double v = m->g[l * n + k] + m->gsig[l * n + k] * rng_normal(&r);
					Wd[l * n + k] = v;
					sum += v;
				}
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
			cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)Q, (int)L, (int)n, 1.0, Kq + t * Q * n,
				    (int)n, Wd, (int)n, 0.0, Y, (int)L);
			for (size_t l = 0; l < L; l++) {
				if (d == 0) { /* the nominal value itself comes from the adaptive rule below */
					for (size_t q = 0; q < Q; q++)
						C[q * L + l] = scale[(t * Q + q) * L + l] *
							       untransform_deriv(m->transform, Y[q * L + l] + mud[l], m->eps[l],
										 trend_factor(m, tb + (t * Q + q) * TREND_NB, l));
				} else { /* Welford */
					double acc = 0;
					for (size_t q = 0; q < Q; q++)
						acc += scale[(t * Q + q) * L + l] *
						       untransform(m->transform, Y[q * L + l] + mud[l], m->eps[l],
								   trend_factor(m, tb + (t * Q + q) * TREND_NB, l));
					double delta = acc - mean[t * L + l];
					mean[t * L + l] += delta / d;
					m2[t * L + l] += delta * (acc - mean[t * L + l]);
				}
			}
			if (d == 0 && model_variance(m, Q, c6 + t * Q * 6, Kq + t * Q * n, A, alpha, C, KQQ, soaQ, U, Bt, X,
						     vmod + t * L, err))
				goto out;
		}
	}
	/* the nominal DHR by the adaptive rule (the fixed rule above serves the spread and the model variance):
	 * a lobe narrower than the 32 × 48 rule resolves is refined, per channel, up to 256 × 384. The exact
	 * albedo of the scaled model is ≤ 1 by construction, so an estimate above 1 is quadrature error: it is
	 * clipped (which only moves it towards the exact value) and, with the last refinement step, kept as
	 * the quadrature term of σ. */
	int dmu = DHR_NMU, dphi = DHR_NPHI;
	size_t dq;
	lobe_rule(m, ALB_NMU_MAX, &dmu, &dphi, &dq);
	if (albedo_ws_init(&ws, m, dq, err))
		goto out;
	for (size_t t = 0; t < nth; t++) {
		if (albedo_adaptive(m, theta[t], dmu, dphi, ALB_NMU_MAX, 0, 1, TAB_TOL, DHR_FLOOR, -HUGE_VAL, &ws,
				    dhr + t * L, squad + t * L, err))
			goto out;
		for (size_t l = 0; l < L; l++)
			if (dhr[t * L + l] > 1.0) {
				squad[t * L + l] += dhr[t * L + l] - 1.0;
				dhr[t * L + l] = 1.0;
			}
	}
	for (size_t i = 0; i < nth * L; i++) {
		double sn = ndraws > 1 ? sqrt(m2[i] / (ndraws - 1)) : 0.0, sm = sqrt(vmod[i]);
		double sb = sn > sm ? sn : sm;
		sig[i] = sqrt(sb * sb + squad[i] * squad[i]);
		if (sig_noise)
			sig_noise[i] = sn;
		if (sig_model)
			sig_model[i] = sm;
		if (sig_quad)
			sig_quad[i] = squad[i];
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
	free(A);
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
	free(Ainv);
	free(alpha);
	free(vmod);
	free(squad);
	free(tb);
	albedo_ws_free(&ws);
	return rc;
}

/* ---- check ------------------------------------------------------------------------------------------- */

int recon_check(const struct recon_model *m, size_t npairs, size_t nalb, uint64_t seed,
		struct recon_check_report *rep, recon_progress_fn progress, void *pctx, struct acq_err *err)
{
	memset(rep, 0, sizeof *rep);
	size_t L = m->nwl, B = 1024;
	double *ang = malloc(B * 4 * sizeof *ang), *swp = malloc(B * 4 * sizeof *swp);
	double *f1 = malloc(B * L * sizeof *f1), *f2 = malloc(B * L * sizeof *f2), *alb = malloc(L * sizeof *alb);
	int rc = -1;
	struct albedo_ws ws = { 0 };
	if (!ang || !swp || !f1 || !f2 || !alb) {
		acq_errf(err, ACQ_E_NOMEM, "check: out of memory");
		goto out;
	}
	/* the independent rule (Gauss-Legendre in cos²θo), 48 × 96 refined up to 192 × 384 */
	int cmu = 48, cphi = 96;
	size_t cq;
	lobe_rule(m, ALB_NMU_MAX, &cmu, &cphi, &cq);
	if (albedo_ws_init(&ws, m, cq, err))
		goto out;
	struct rng r;
	rng_seed(&r, seed);
	rep->min_value = INFINITY;
	rep->max_albedo = -INFINITY;
	for (size_t p0 = 0; p0 < npairs; p0 += B) {
		size_t b = npairs - p0 < B ? npairs - p0 : B;
		if (progress)
			progress(pctx, "pairs", (double)p0 / (double)npairs);
		for (size_t i = 0; i < b; i++) {
			/* uniform on the hemisphere: cosθ uniform; φ uniform on [0, 2π) for both directions */
			double *a = ang + 4 * i;
			a[0] = acos(rng_unif(&r));
			a[1] = 2 * M_PI * rng_unif(&r);
			a[2] = acos(rng_unif(&r));
			a[3] = 2 * M_PI * rng_unif(&r);
			double *s = swp + 4 * i;
			s[0] = a[2];
			s[1] = a[3];
			s[2] = a[0];
			s[3] = a[1];
		}
		if (recon_eval(m, b, ang, f1, err) || recon_eval(m, b, swp, f2, err))
			goto out;
		for (size_t i = 0; i < b * L; i++) {
			if (!isfinite(f1[i]) || !isfinite(f2[i])) {
				rep->nonfinite++;
				continue;
			}
			if (f1[i] < rep->min_value)
				rep->min_value = f1[i];
			if (f2[i] < rep->min_value)
				rep->min_value = f2[i];
			double d = fabs(f1[i] - f2[i]), mx = fmax(fabs(f1[i]), fabs(f2[i]));
			if (d > rep->max_recip_abs)
				rep->max_recip_abs = d;
			if (mx > 1e-300 && d / mx > rep->max_recip_rel)
				rep->max_recip_rel = d / mx;
		}
		rep->npairs += b;
	}
	for (size_t t = 0; t < nalb + 2; t++) {
		if (progress)
			progress(pctx, "albedo", (double)t / (double)(nalb + 2));
		double th = t == 0 ? 0.0 : t == 1 ? M_PI / 2 : asin(rng_unif(&r)) ; /* sinθ uniform: more grazing */
		if (albedo_adaptive(m, th, cmu, cphi, ALB_NMU_MAX, 1, 1, TAB_TOL, 1e-300, -HUGE_VAL, &ws, alb, NULL, err))
			goto out;
		for (size_t l = 0; l < L; l++) {
			if (!isfinite(alb[l])) {
				rep->nonfinite++;
				continue;
			}
			if (alb[l] > rep->max_albedo) {
				rep->max_albedo = alb[l];
				rep->max_albedo_theta = th;
				rep->max_albedo_wl = m->wl[l];
			}
		}
		rep->nalb++;
	}
	rc = 0;
out:
	free(ang);
	free(swp);
	free(f1);
	free(f2);
	free(alb);
	albedo_ws_free(&ws);
	return rc;
}
