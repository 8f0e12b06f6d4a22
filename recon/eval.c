/* eval: the final BRDF at query points: kernel rows, one GEMM per block, the map back through the transform and
 * the trend, the energy factor from the albedo table. */
#include <cblas.h>
#include <math.h>
#include <stdlib.h>

#include "recon/recon_int.h"

size_t recon_eval_work_size(const struct recon_model *m)
{
	return (size_t)RECON_EVAL_BLOCK * m->n;
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

/* (recon_int.h)
 * One block of b ≤ RECON_EVAL_BLOCK queries for nch channels: chan[k] names the model channel of output
 * column k (chan NULL: every channel in order) and wsub holds those channels' weights, channel-major
 * (nch × n; m->w itself when chan is NULL). out is b × nch, row-major.
 */
void recon_eval_block(const struct recon_model *m, size_t b, const double *c6, int scaled, size_t nch,
		      const size_t *chan, const double *wsub, double *out, double *work)
{
	recon_eval_block_part(m, b, c6, scaled, RECON_PART_ALL, nch, chan, wsub, out, work);
}

void recon_eval_block_part(const struct recon_model *m, size_t b, const double *c6, int scaled, int part, size_t nch,
			   const size_t *chan, const double *wsub, double *out, double *work)
{
	size_t n = m->n;
	const int lf = trend_lobe_first(m->trend);
	rbf_kmatrix_soa(m->kernel, m->shape, b, c6, n, m->soa, work);
	/* out (b × nch) = K (b × n) · Wᵀ */
	cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)b, (int)nch, (int)n, 1.0, work, (int)n, wsub,
		    (int)n, 0.0, out, (int)nch);
	for (size_t q = 0; q < b; q++) {
		const double *c = c6 + 6 * q;
		const double *ai = m->tab_alb, *ao = m->tab_alb;
		double tb[TREND_NB];
		trend_at(m, c, tb);
		if (part == RECON_PART_LOBE || part == RECON_PART_NOLOBE) /* split at the lobe terms: [0, lf) and [lf, TREND_NB) */
			for (int j = 0; j < TREND_NB; j++)
				if ((j >= lf) == (part == RECON_PART_NOLOBE))
					tb[j] = 0;
		if (part == RECON_PART_SMOOTH || part == RECON_PART_BASE) /* [0, j0) and [j0, lf), j0 = 1 for two lobes */
			for (int j = 0, j0 = trend_two_lobes(m->trend) ? 1 : lf; j < TREND_NB; j++)
				if (j >= lf || (j >= j0) == (part == RECON_PART_SMOOTH))
					tb[j] = 0;
		if (scaled && m->ntab >= 2) {
			ai += recon_tab_interval(m, theta_of(c)) * m->nwl;
			ao += recon_tab_interval(m, theta_of(c + 3)) * m->nwl;
		}
		for (size_t k = 0; k < nch; k++) {
			size_t l = chan ? chan[k] : k;
			double f;
			if (recon_part_hv(part)) { /* T_lobe·e^g (T_base·e^g): ≥ 0, no offset */
				double g = out[q * nch + k] + m->mu[l];
				f = trend_val(m, tb, l) * exp(g < G_MAX ? g : G_MAX);
				f = f < 1e300 ? f : 1e300;
			} else if (part == RECON_PART_REST) { /* f̂ − T_lobe·e^g, the lobe part as above */
				double g = out[q * nch + k] + m->mu[l], tl = 0;
				for (int j = lf; j < TREND_NB; j++)
					tl += m->tcoef[l * TREND_NB + j] * tb[j];
				f = untransform(m->transform, g, m->eps[l], trend_factor(m, tb, l)) -
				    fmin(tl * exp(g < G_MAX ? g : G_MAX), 1e300);
			} else {
				f = untransform(m->transform, out[q * nch + k] + m->mu[l], m->eps[l], trend_factor(m, tb, l));
			}
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
		recon_eval_block(m, b, c6 + 6 * q0, scaled, m->nwl, NULL, m->w, out + q0 * m->nwl, work);
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

double recon_nearest_centre(const struct recon_model *m, const double *c6, size_t *kmin)
{
	double best = INFINITY;
	size_t bk = 0;
	for (size_t k = 0; k < m->n; k++) {
		double d = rbf_canon_dist2(c6, m->ctr + 6 * k, m->tctr + 6 * k);
		if (d < best) {
			best = d;
			bk = k;
		}
	}
	if (kmin)
		*kmin = bk;
	return sqrt(best);
}

double recon_trend_width(const struct recon_model *m, int specular)
{
	double a = m->trend_alpha;
	if (!(a > 0))
		return specular ? RECON_PRIOR_LOBE_NONE : 0.0;
	double hv = trend_hv_alpha(m->trend, a);
	if (hv > 0)
		return 2.0 * hv;
	if (specular)
		return INFINITY;
	if (m->trend == RECON_TREND_ROUGH)
		return a;
	if (m->trend == RECON_TREND_SHEEN)
		return sqrt(2.0 * log(4.0) * a);
	return specular ? INFINITY : 0.0;
}

double recon_mirror_unseen(const struct recon_model *m, const double mir[6], double w)
{
	double best = 1.0;
	for (size_t k = 0; k < m->n && best > 0; k++)
		best = fmin(best, recon_mirror_term(mir, m->ctr + 6 * k, m->tctr + 6 * k, w));
	return best;
}

/*
 * The data the final model does not honour: at each sample, the measured value (from the stored transformed
 * data g, relative to the trend) against the final (smoothed, energy-scaled) model. Smoothing and the energy
 * factor may both pull the model away from a sample: a lobe narrower than the kernel allows cannot keep its
 * peak under the albedo bound.
 */
long recon_misfit(const struct recon_model *m, double zlim, double rmin, double *df, double *ratio,
		  struct recon_misfit_worst *worst, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl;
	double *wk = malloc(recon_eval_work_size(m) * sizeof *wk);
	if (!wk)
		return acq_errf(err, ACQ_E_NOMEM, "misfit: out of memory");
	recon_eval_canon(m, n, m->ctr, 1, df, wk); /* df[k*L + l] = f̂ at the samples */
	free(wk);
	long count = 0;
	double wr = 0;
	for (size_t k = 0; k < n; k++) {
		double tb[TREND_NB];
		trend_at(m, m->ctr + 6 * k, tb);
		for (size_t l = 0; l < L; l++) {
			double g = m->g[l * n + k], sg = m->gsig[l * n + k], fh = df[k * L + l], tf = trend_factor(m, tb, l);
			double ghat = m->transform == RECON_T_SQRT ? sqrt(fh) : log((fh + m->eps[l]) / tf);
			double r = fabs(g - ghat), d = 0, q = 1.0;
			if (isfinite(r) && r > rmin && isfinite(sg) && r > zlim * sg) {
				double fd = untransform(m->transform, g, m->eps[l], tf);
				d = fd - fh;
				q = (fd + m->eps[l]) / (fh + m->eps[l]);
				count++;
				if (worst && fabs(d) > wr) {
					wr = fabs(d);
					worst->k = k;
					worst->l = l;
					worst->data = fd;
					worst->model = fh;
				}
			}
			df[k * L + l] = isfinite(d) ? d : 0.0;
			if (ratio)
				ratio[k * L + l] = isfinite(q) && isfinite(d) ? q : 1.0;
		}
	}
	return count;
}
