/* slices: the numbers of the in-plane slices of a reconstruction — channel weights, the model's band, the measured
 * in-plane samples — and their CSV; drawn by slices_draw.c. */
#include "recon/slices.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config/acq_out.h"
#include "recon/rbf.h"
#include "recon/recon_int.h"
#include "recon/slices_int.h"

void slices_opts_default(struct slices_opts *o)
{
	memset(o, 0, sizeof *o);
	o->wl_lo = o->wl_hi = NAN;
	o->band_k = 2;
	o->phi_tol_deg = 2;
	o->width = 1000;
	o->height = 640;
	o->npts = 90;
}

int slices_weights(const struct recon_model *m, double lo, double hi, double *wsel, struct acq_err *err)
{
	size_t L = m->nwl;
	if (!(lo <= hi) || !(lo >= m->wl[0] - 1e-9) || !(hi <= m->wl[L - 1] + 1e-9))
		return acq_errf(err, ACQ_E_RANGE, "slices: wavelengths %g..%g nm outside the model's %g..%g nm (or reversed)",
				lo, hi, m->wl[0], m->wl[L - 1]);
	memset(wsel, 0, L * sizeof *wsel);
	if (lo == hi || L == 1) {
		size_t a = 0;
		while (a + 2 < L && m->wl[a + 1] <= lo)
			a++;
		if (L == 1) {
			wsel[0] = 1;
			return 0;
		}
		double t = (lo - m->wl[a]) / (m->wl[a + 1] - m->wl[a]);
		t = t < 0 ? 0 : t > 1 ? 1 : t;
		wsel[a] = 1 - t;
		wsel[a + 1] += t;
		return 0;
	}
	double sum = 0;
	for (size_t l = 0; l < L; l++) {
		if (m->wl[l] < lo - 1e-9 || m->wl[l] > hi + 1e-9)
			continue;
		double a = l ? fmax(lo, 0.5 * (m->wl[l - 1] + m->wl[l])) : lo;
		double b = l + 1 < L ? fmin(hi, 0.5 * (m->wl[l] + m->wl[l + 1])) : hi;
		wsel[l] = b > a ? b - a : 0;
		sum += wsel[l];
	}
	if (!(sum > 0)) { /* a band narrower than the channel spacing: its nearest channel */
		size_t best = 0;
		for (size_t l = 1; l < L; l++)
			if (fabs(m->wl[l] - 0.5 * (lo + hi)) < fabs(m->wl[best] - 0.5 * (lo + hi)))
				best = l;
		wsel[best] = sum = 1;
	}
	for (size_t l = 0; l < L; l++)
		wsel[l] /= sum;
	return 0;
}

/* The model at nq directions ang[q*4..] (θi, φi, θo, φo) reduced by the channel weights wsel (f), and its
 * pointwise band lo..hi: the Gaussian-process posterior σ of the transformed value (variance α_λ (K(x,x) −
 * k_xᵀ A⁻¹ k_x) with A = K + ηΛ and α_λ from the leave-one-out residuals, as the DHR's σ_model), mapped back
 * through the transform at ± k σ, the energy factor applied, channels combined with their weights (fully
 * correlated: conservative). 0, or -1 with err. */
static int slices_band(const struct recon_model *m, size_t nq, const double *ang, const double *wsel, double k,
		       double *f, double *lo, double *hi, struct acq_err *err)
{
	size_t n = m->n, L = m->nwl;
	int rc = -1;
	double *F = malloc(nq * L * sizeof *F), *A = malloc(n * n * sizeof *A), *Ai = malloc(n * n * sizeof *Ai);
	double *c6 = malloc(nq * 6 * sizeof *c6), *Kq = malloc(nq * n * sizeof *Kq), *X = malloc(nq * n * sizeof *X);
	double *alpha = calloc(L, sizeof *alpha), *P = malloc(nq * sizeof *P);
	if (!F || !A || !Ai || !c6 || !Kq || !X || !alpha || !P) {
		acq_errf(err, ACQ_E_NOMEM, "slices: out of memory (%zu samples)", n);
		goto out;
	}
	if (recon_eval(m, nq, ang, F, err))
		goto out;
	/* A = K + ηΛ of the model (its Cholesky factor) and the leave-one-out amplitude α_λ (as for the DHR) */
	if (recon_gp_setup(m, "slices", A, Ai, alpha, err))
		goto out;
	for (size_t q = 0; q < nq; q++)
		rbf_canon(ang[4 * q], ang[4 * q + 1], ang[4 * q + 2], ang[4 * q + 3], c6 + 6 * q);
	rbf_kmatrix_soa(m->kernel, m->shape, nq, c6, n, m->soa, Kq);
	if (recon_gp_postvar(m, A, nq, c6, Kq, X, P, "slices", err))
		goto out;
	for (size_t q = 0; q < nq; q++) {
		double v = P[q];
		f[q] = lo[q] = hi[q] = 0;
		for (size_t l = 0; l < L; l++) {
			if (wsel[l] == 0)
				continue;
			double s = recon_energy_scale(m, ang[4 * q], ang[4 * q + 2], l), fl = F[q * L + l];
			double sg = k * sqrt(alpha[l] * v), fh = s > 0 ? fl / s : 0, l_lo, l_hi;
			if (m->transform == RECON_T_SQRT) {
				double r = sqrt(fh);
				l_hi = s * (r + sg) * (r + sg);
				l_lo = r > sg ? s * (r - sg) * (r - sg) : 0;
			} else {
				double e = m->eps[l];
				l_hi = s * ((fh + e) * exp(fmin(sg, 50)) - e);
				l_lo = fmax(0, s * ((fh + e) * exp(-sg) - e));
			}
			f[q] += wsel[l] * fl;
			lo[q] += wsel[l] * l_lo;
			hi[q] += wsel[l] * l_hi;
		}
		if (!isfinite(f[q]) || !isfinite(lo[q]) || !isfinite(hi[q])) {
			acq_errf(err, ACQ_E_NUMERIC, "slices: non-finite value or band at query %zu", q);
			goto out;
		}
	}
	rc = 0;
out:
	free(F);
	free(A);
	free(Ai);
	free(c6);
	free(Kq);
	free(X);
	free(alpha);
	free(P);
	return rc;
}

static int cmp_d(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

/* The measured incidences: the distinct θi (0.05° apart) of s's in-plane samples (|sin(φo − φi)| ≤ stol), sorted,
 * into th (SLICES_MAX_THETA at most), their number in *nth; 0 or -1 with err. */
static int measured_theta(const struct recon_samples *s, double stol, double *th, size_t *nth, struct acq_err *err)
{
	if (!s || !s->n)
		return acq_errf(err, ACQ_E_INVAL, "slices: no incidences given and no samples to take them from");
	double *all = malloc(s->n * sizeof *all);
	size_t na = 0, n = 0;
	if (!all)
		return acq_errf(err, ACQ_E_NOMEM, "slices: out of memory");
	for (size_t i = 0; i < s->n; i++)
		if (fabs(sin(s->ang[4 * i + 3] - s->ang[4 * i + 1])) <= stol)
			all[na++] = s->ang[4 * i];
	qsort(all, na, sizeof *all, cmp_d);
	for (size_t i = 0; i < na; i++)
		if (!n || all[i] - th[n - 1] > 0.05 * M_PI / 180) {
			if (n == SLICES_MAX_THETA) {
				free(all);
				return acq_errf(err, ACQ_E_RANGE, "slices: more than %d measured incidences (give --theta-i)",
						SLICES_MAX_THETA);
			}
			th[n++] = all[i];
		}
	free(all);
	*nth = n;
	return 0;
}

/* Sample i of s reduced by the weights wsel over the model's channels (the sample's spectrum read linearly at
 * each channel): its value *v and σ *sg (NAN without σ columns). 0, or -1 when a value it needs is not finite or no
 * weight falls on it. */
static int sample_reduce(const struct recon_model *m, const struct recon_samples *s, size_t i, const double *wsel,
			 double *v, double *sg)
{
	double val = 0, sig = 0, wsum = 0;
	for (size_t l = 0; l < m->nwl; l++) {
		if (wsel[l] == 0)
			continue;
		size_t b = 0;
		while (b + 2 < s->nwl && s->wl[b + 1] <= m->wl[l])
			b++;
		double tt = s->nwl > 1 ? (m->wl[l] - s->wl[b]) / (s->wl[b + 1] - s->wl[b]) : 0;
		tt = tt < 0 ? 0 : tt > 1 ? 1 : tt;
		size_t b1 = s->nwl > 1 ? b + 1 : b;
		double x0 = s->val[i * s->nwl + b], x1 = s->val[i * s->nwl + b1];
		if (!isfinite(x0) || !isfinite(x1))
			return -1;
		val += wsel[l] * ((1 - tt) * x0 + tt * x1);
		if (s->sig) {
			double s0 = s->sig[i * s->nwl + b], s1 = s->sig[i * s->nwl + b1];
			sig += wsel[l] * ((1 - tt) * s0 + tt * s1);
		}
		wsum += wsel[l];
	}
	if (!(wsum > 0))
		return -1;
	*v = val;
	*sg = s->sig && isfinite(sig) ? sig : NAN;
	return 0;
}

/* Range of the plotted values so far: the smallest positive one and the largest upper end. */
struct vrange {
	double min, max;
};

/* One incidence's series q at θi = ti: the model's band over signed θo (np points, ang a scratch of np·4) and the
 * in-plane samples at ti with their ±k σ; widens *vr; 0 or -1 with err. */
static int series_fill(struct slices_series *q, const struct recon_model *m, const struct recon_samples *s, double ti,
		       size_t np, double *ang, const double *wsel, const struct slices_opts *o, double stol,
		       struct vrange *vr, struct acq_err *err)
{
	q->theta = ti;
	q->np = np;
	q->x = malloc(np * sizeof *q->x);
	q->f = malloc(np * sizeof *q->f);
	q->lo = malloc(np * sizeof *q->lo);
	q->hi = malloc(np * sizeof *q->hi);
	size_t cap = s ? s->n : 0;
	q->sx = malloc((cap ? cap : 1) * sizeof *q->sx);
	q->sv = malloc((cap ? cap : 1) * sizeof *q->sv);
	q->ss = malloc((cap ? cap : 1) * sizeof *q->ss);
	if (!q->x || !q->f || !q->lo || !q->hi || !q->sx || !q->sv || !q->ss)
		return acq_errf(err, ACQ_E_NOMEM, "slices: out of memory");
	for (size_t i = 0; i < np; i++) {
		double a = -90 + 180.0 * (double)i / (double)(np - 1); /* signed θo, degrees; ±90 kept just inside */
		a = fmax(-89.5, fmin(89.5, a));
		q->x[i] = a;
		ang[4 * i] = ti;
		ang[4 * i + 1] = 0;
		ang[4 * i + 2] = fabs(a) * M_PI / 180;
		ang[4 * i + 3] = a >= 0 ? M_PI : 0;
	}
	if (slices_band(m, np, ang, wsel, o->band_k, q->f, q->lo, q->hi, err))
		return -1;
	for (size_t i = 0; i < np; i++) {
		if (q->f[i] > 0)
			vr->min = fmin(vr->min, q->f[i]);
		vr->max = fmax(vr->max, q->hi[i]);
	}
	/* the largest measured θo at this incidence (any azimuth; all samples' when none is at it): beyond it the model
	 * extrapolates, and the figure says so */
	q->xmax = NAN;
	double all_max = NAN;
	for (size_t i = 0; s && i < s->n; i++) {
		double to = s->ang[4 * i + 2] * 180 / M_PI;
		all_max = fmax(all_max, to); /* fmax ignores the NaN start */
		if (fabs(s->ang[4 * i] - ti) <= 0.05 * M_PI / 180)
			q->xmax = fmax(q->xmax, to);
	}
	if (q->xmax != q->xmax)
		q->xmax = all_max;
	/* in-plane samples at this incidence, reduced by the same weights (sample spectra read linearly) */
	for (size_t i = 0; s && i < s->n; i++) {
		const double *a = s->ang + 4 * i;
		double dphi = a[3] - a[1], v, sg;
		if (fabs(a[0] - ti) > 0.05 * M_PI / 180 || fabs(sin(dphi)) > stol)
			continue;
		if (sample_reduce(m, s, i, wsel, &v, &sg))
			continue;
		q->sx[q->ns] = (cos(dphi) < 0 ? 1 : -1) * a[2] * 180 / M_PI;
		q->sv[q->ns] = v;
		q->ss[q->ns] = sg;
		if (v > 0)
			vr->min = fmin(vr->min, v);
		vr->max = fmax(vr->max, v + (isfinite(q->ss[q->ns]) ? o->band_k * q->ss[q->ns] : 0));
		q->ns++;
	}
	return 0;
}

/* The plotted numbers to csv (kind,theta_i,theta_o_signed,value,lo,hi,beyond_data: the model's band, beyond_data 1
 * where |θo| exceeds the largest measured θo at that incidence; then the samples ± k σ, beyond_data 0), through
 * config/acq_out (a failed write leaves the old file; a FIFO or device is written in place); 0 or -1 with err. */
static int series_csv(const struct slices_series *S, size_t nth, const struct slices_opts *o, const char *csv,
		      struct acq_err *err)
{
	struct acq_out ao;
	if (acq_out_open(&ao, csv, ACQ_OUT_STDIO, err))
		return acq_err_prefix(err, "slices: ");
	FILE *cf = ao.f;
	fprintf(cf, "kind,theta_i,theta_o_signed,value,lo,hi,beyond_data\n");
	for (size_t t = 0; t < nth; t++) {
		for (size_t i = 0; i < S[t].np; i++)
			fprintf(cf, "model,%.10g,%.10g,%.10g,%.10g,%.10g,%d\n", S[t].theta * 180 / M_PI, S[t].x[i], S[t].f[i],
				S[t].lo[i], S[t].hi[i], slices_beyond(&S[t], S[t].x[i]));
		for (size_t i = 0; i < S[t].ns; i++) {
			double sg = isfinite(S[t].ss[i]) ? o->band_k * S[t].ss[i] : 0;
			fprintf(cf, "sample,%.10g,%.10g,%.10g,%.10g,%.10g,0\n", S[t].theta * 180 / M_PI, S[t].sx[i],
				S[t].sv[i], S[t].sv[i] - sg, S[t].sv[i] + sg);
		}
	}
	if (ferror(cf)) {
		acq_out_abort(&ao);
		return acq_errf(err, ACQ_E_IO, "slices: writing %s failed", csv);
	}
	return acq_out_commit(&ao, err) ? acq_err_prefix(err, "slices: ") : 0;
}

int slices_plot(const struct recon_model *m, const struct recon_samples *s, const double *theta, size_t nth,
		const struct slices_opts *o, const char *png, const char *polar_png_path, const char *csv,
		struct slices_result *res, struct acq_err *err)
{
	if (o->width < 64 || o->width > 8192 || o->height < 64 || o->height > 8192 || o->npts < 4 || o->npts > 4096 ||
	    !(o->band_k > 0) || !(o->phi_tol_deg > 0 && o->phi_tol_deg < 45))
		return acq_errf(err, ACQ_E_INVAL, "slices: size, points, band_k or phi tolerance out of range");
	size_t L = m->nwl;
	double *wsel = malloc(L * sizeof *wsel);
	if (!wsel)
		return acq_errf(err, ACQ_E_NOMEM, "slices: out of memory");
	if (slices_weights(m, o->wl_lo, o->wl_hi, wsel, err)) {
		free(wsel);
		return -1;
	}
	double th[SLICES_MAX_THETA];
	double stol = sin(o->phi_tol_deg * M_PI / 180);
	if (nth > SLICES_MAX_THETA) {
		free(wsel);
		return acq_errf(err, ACQ_E_RANGE, "slices: %zu incidences (at most %d)", nth, SLICES_MAX_THETA);
	}
	if (nth) {
		memcpy(th, theta, nth * sizeof *th); /* theta may be NULL when nth is 0 (memcpy's argument must not be) */
	} else {
		if (measured_theta(s, stol, th, &nth, err)) {
			free(wsel);
			return -1;
		}
		if (!nth) {
			free(wsel);
			return acq_errf(err, ACQ_E_INVAL, "slices: no sample lies in the plane (|sin(phi_o - phi_i)| <= "
					"sin %g deg)", o->phi_tol_deg);
		}
	}
	int rc = -1;
	size_t np = 2 * (size_t)o->npts + 1, nsamp = 0;
	struct slices_series S[SLICES_MAX_THETA];
	memset(S, 0, sizeof S);
	double *ang = malloc(np * 4 * sizeof *ang);
	struct vrange vr = { HUGE_VAL, 0 };
	if (!ang) {
		acq_errf(err, ACQ_E_NOMEM, "slices: out of memory");
		goto out;
	}
	for (size_t t = 0; t < nth; t++) {
		if (series_fill(&S[t], m, s, th[t], np, ang, wsel, o, stol, &vr, err))
			goto out;
		nsamp += S[t].ns;
	}
	if (!(vr.max > 0)) {
		acq_errf(err, ACQ_E_NUMERIC, "slices: the model is 0 on every slice at this wavelength selection");
		goto out;
	}
	if (!(vr.min < HUGE_VAL))
		vr.min = vr.max * 1e-6;
	struct slices_frame fr = { 80, 40, o->width - 200.0, o->height - 60.0, -90, 90, 0, 0 };
	fr.y1 = ceil(log10(vr.max) * 4) / 4;
	fr.y0 = fmax(floor(log10(vr.min) * 4) / 4, fr.y1 - 6);
	if (fr.y1 - fr.y0 < 1)
		fr.y0 = fr.y1 - 1;
	if (slices_draw_inplane(S, nth, o, &fr, png, err) ||
	    (polar_png_path && slices_draw_polar(S, nth, o, &fr, vr.min, polar_png_path, err)) ||
	    (csv && series_csv(S, nth, o, csv, err)))
		goto out;
	if (res) {
		memset(res, 0, sizeof *res);
		res->nth = nth;
		memcpy(res->theta, th, nth * sizeof *th);
		res->nsamples = nsamp;
		for (size_t t = 0; t < nth; t++) {
			res->theta_o_max[t] = S[t].xmax;
			for (size_t i = 0; i < S[t].np; i++)
				res->beyond[t] += (size_t)slices_beyond(&S[t], S[t].x[i]);
		}
		for (size_t l = 0; l < L; l++)
			res->nchannels += wsel[l] != 0;
	}
	rc = 0;
out:
	for (size_t t = 0; t < SLICES_MAX_THETA; t++) {
		free(S[t].x);
		free(S[t].f);
		free(S[t].lo);
		free(S[t].hi);
		free(S[t].sx);
		free(S[t].sv);
		free(S[t].ss);
	}
	free(ang);
	free(wsel);
	return rc;
}
