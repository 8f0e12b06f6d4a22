/* quad: hemisphere quadrature of the albedo, adaptive per channel, with the starting rule sized from the
 * narrowest lobe the model can make. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/recon_int.h"

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
int recon_hemi_nodes(double theta_i, int nmu, int nphi, int square_rule, double *c6, double *wt)
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

void recon_albedo_ws_free(struct albedo_ws *ws)
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

int recon_albedo_ws_init(struct albedo_ws *ws, const struct recon_model *m, size_t qmax, struct acq_err *err)
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
		recon_albedo_ws_free(ws);
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
	if (Q > ws->qmax || (ws->part == RECON_PART_LOBE ? recon_hv_nodes(theta_i, trend_hv_alpha(m->trend, m->trend_alpha), nmu, nphi, ws->c6, ws->wt)
						       : recon_hemi_nodes(theta_i, nmu, nphi, square_rule, ws->c6, ws->wt)))
		return acq_errf(err, ACQ_E_INVAL, "albedo: quadrature size %d × %d out of range", nmu, nphi);
	for (size_t k = 0; k < nch; k++)
		acc[k] = 0;
	for (size_t q0 = 0; q0 < Q; q0 += RECON_EVAL_BLOCK) {
		size_t b = Q - q0 < RECON_EVAL_BLOCK ? Q - q0 : RECON_EVAL_BLOCK;
		recon_eval_block_part(m, b, ws->c6 + 6 * q0, scaled, ws->part, nch, ws->chan, ws->wsub, ws->vals, ws->work);
		ws->evals += (double)b * (double)m->n * (1.0 + (double)nch / 64.0);
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
void recon_lobe_rule(const struct recon_model *m, int nmu_max, int no_trend_lobe, int *nmu, int *nphi, size_t *qmax)
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
	if (m->trend != RECON_TREND_NONE && !no_trend_lobe) {
		double lobe = 0;
		for (size_t l = 0; l < m->nwl; l++) {
			double sum = 0; /* the lobe terms' albedo is ≤ the sum of their coefficients */
			for (int j = TREND_LOBE; j < TREND_NB; j++)
				sum += m->tcoef[l * TREND_NB + j];
			lobe = fmax(lobe, sum);
		}
		if (lobe >= 1e-4)
			s = fmin(s, m->trend == RECON_TREND_GGX ? TREND_RULE_SPACING * m->trend_alpha
							       : trend_rule_step(m->trend, m->trend_alpha));
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
 * compares its bound, fine + 2·|fine − coarse|, with 1: a value clearly below needs no more digits; with
 * ws->offset the rest of a split albedo is added to the comparison; −∞ turns
 * this off). out[l] is the finest value; diff[l] (may be NULL) the last |fine − coarse|, or 0 when no
 * doubling fits under nmu_max.
 */
int recon_albedo_adaptive(const struct recon_model *m, double theta_i, int nmu, int nphi, int nmu_max,
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
			double off = ws->offset ? ws->offset[l] : 0.0; /* the rest of a split albedo (fine + 4d) */
			if (!(d <= tol * ref) && !(ws->fine[k] + 4.0 * d + off <= below && d <= TAB_BELOW_DIFF)) {
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

int recon_hv_nodes(double theta_i, double alpha, int nu, int nphi, double *c6, double *wt)
{
	double x[256], w[256];
	if (nu > 256 || rbf_gauss_legendre01(nu, x, w) || !(alpha > 0))
		return -1;
	double si = sin(theta_i), ci = cos(theta_i), wi[3] = { si, 0, ci }, a2 = alpha * alpha;
	size_t k = 0;
	for (int i = 0; i < nu; i++) {
		/* tan²θh = α² u/(1 − u); dωh = sinθh dθh dφ = (α² + t²)² / (2α²(1 + t²)^{3/2}) du dφ, t = tanθh */
		double u = x[i], t2 = a2 * u / (1 - u), t = sqrt(t2), ch = 1 / sqrt(1 + t2), sh = t * ch;
		double jac = (a2 + t2) * (a2 + t2) / (2 * a2 * (1 + t2) * sqrt(1 + t2));
		for (int j = 0; j < nphi; j++) {
			double p = (j + 0.5) * M_PI / nphi;
			double h[3] = { sh * cos(p), sh * sin(p), ch }; /* about the normal, the specular half vector */
			double d = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2];
			double wo[3] = { 2 * d * h[0] - wi[0], 2 * d * h[1] - wi[1], 2 * d * h[2] - wi[2] };
			double weight = 0;
			if (d > 0 && wo[2] > 1e-12) {
				weight = w[i] * jac * (2.0 * M_PI / nphi) * 4 * d * wo[2];
			} else {
				wo[0] = -wi[0];
				wo[1] = 0;
				wo[2] = wi[2] > 1e-12 ? wi[2] : 1e-12; /* any valid point; weight 0 */
			}
			double to = acos(fmin(1, fmax(0, wo[2] / sqrt(wo[0] * wo[0] + wo[1] * wo[1] + wo[2] * wo[2]))));
			double po = atan2(wo[1], wo[0]);
			rbf_canon(theta_i, 0.0, to, po, c6 + 6 * k);
			wt[k] = weight;
			k++;
		}
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
	if (recon_albedo_ws_init(&ws, m, (size_t)top * (size_t)tphi, err))
		return -1;
	int rc = recon_albedo_adaptive(m, theta_i, nmu, nphi, ALB_NMU_MAX, 0, scaled, TAB_TOL, 1e-300, -HUGE_VAL, &ws, out, NULL,
				 err);
	recon_albedo_ws_free(&ws);
	return rc;
}

