/* rgbeval: "model only what the output needs" for RGB outputs: the reduced evaluator, per pair and in batches
 * (the MERL table it fills: rgbeval_merl.c; the preview render). */
#include "recon/rgbeval.h"
#include "recon/rng.h"

#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/*
 * The reconstruction is not linear in the data (the transform that keeps f ≥ 0), so spectra cannot be
 * reduced to three channels before evaluation. What an RGB output needs is still much less than the model:
 *  1. Only wavelengths where the colour weights are non-zero (the CIE observer ends at 830 nm: of 450-1100 nm
 *     only 450-830 count), binned to 5 nm: each bin is one channel whose transformed weights, mean and
 *     offset (and trend coefficients) are the averages over the bin's model channels (the average of g rather than of f: the
 *     difference is second order in the spread of g within 5 nm, far below the noise, while averaging
 *     keeps the noise of single 1 nm channels out of the colour). The colour chain reads every model channel
 *     back from the bin means as a local quadratic (bin_weights: the colour weights fold onto the bins). The
 *     energy factor uses the largest albedo bound of the bin. The error is measured at construction against
 *     the full path, per channel (R and B are small differences of large lobes: an error relative to the
 *     largest channel does not bound them).
 *  2. The transformed interpolant at the kept channels is μ_l + Σ_j K(x, x_j) W_jl; the n × nc weight matrix
 *     is replaced by its SVD with the trailing components dropped as long as a bound on their total
 *     contribution to g stays below 1e-3 (0.1 % relative in f for the log transform, far below the noise):
 *     z = Pᵀ k (n × r), then g = μ + V z (r × nc), with r below nc.
 * Per direction pair the cost is n kernel values + n·r + r·nc + nc exponentials + 3·nc, instead of n·L.
 */

/*
 * exp of the map-back, vectorised: glibc's libmvec AVX2 variant (_ZGVdN4v_exp, 4 doubles; glibc documents a
 * maximum error of 1 ulp for it, libm-test-ulps "exp_vlen4_avx2", against ≤ 1 ulp for the scalar exp; lanes
 * needing special handling (overflow, underflow, NaN) go through the scalar routine). Elementwise: each value
 * gets the same bits whatever its position in the array, so the per-pair path (reduced_lin) and the batch
 * path agree, and reciprocity (the same arithmetic on the same canonical point) stays bit-exact. Without AVX2
 * the scalar exp. n is padded by the callers to a multiple of 4 (RGB_PAD4).
 */
#define RGB_PAD4(n) (((n) + 3) & ~(size_t)3)
#if defined(__x86_64__)
#include <immintrin.h>
__attribute__((target("avx2"))) extern __m256d _ZGVdN4v_exp(__m256d x);
__attribute__((target("avx2"))) static void vexp_avx2(double *x, size_t n)
{
	for (size_t i = 0; i < n; i += 4)
		_mm256_storeu_pd(x + i, _ZGVdN4v_exp(_mm256_loadu_pd(x + i)));
}
#endif

static void vexp(double *x, size_t n)
{
#if defined(__x86_64__)
	if (__builtin_cpu_supports("avx2")) {
		vexp_avx2(x, RGB_PAD4(n));
		return;
	}
#endif
	for (size_t i = 0; i < n; i++)
		x[i] = exp(x[i]);
}

#define RGB_STEP_NM 5.0
/* A channel below this fraction of the pair's largest channel has its reduction error stated relative to that
 * fraction (a relative error of a channel near 0, e.g. R of a saturated green, would mean nothing). */
#define RGB_REL_FLOOR 1e-2
/*
 * The reduction error is measured against the full path at RGB_RED_PAIRS random pairs, cosθ = u² for both
 * directions (u uniform: weighted toward grazing, where the model's spectra are roughest and the error largest),
 * and stated as RGB_RED_MARGIN times the largest found: a sample's largest is not a bound. Measured (demo model,
 * green-paint, green-paint without trend, metal, narrow-lines, cloth-sheen fitted from acq-sim truth 6x6x8, noise
 * 1 %): the largest per-channel error at 20000 further pairs (cosθ uniform in [0, 1] or [0.01, 1]) was at most
 * 1.12 times the largest of these 1024 (cosθ uniform instead: up to 2.8 times; 256 pairs as before: 2.3 times);
 * at 3000 MERL cells of test_recon_rgb's smooth model, up to 1.25 times (hence 2, not 1.25). Keep
 * RECON_RGB_RED_DEFINITION (rgbeval.h) in step.
 */
#define RGB_RED_PAIRS 1024
#define RGB_RED_CMIN 0.0
#define RGB_RED_MARGIN 2.0
#define RGB_G_TOL 1e-3
/*
 * Single precision for the batch GEMM g = K·W (half the time of the MERL table in double: 8 lanes instead of
 * 4). Its error in g is an absolute error in ln f, i.e. a relative error in f: measured at construction
 * (RGB_F32_PAIRS random pairs, the largest |g_single − g_double| over every channel) and used only when it is
 * ≤ RGB_F32_TOL, 1e-4 relative in the BRDF: 40 times below the 5 nm binning's own error (0.4 %) and 100 times
 * below 1 % measurement noise (measured: 4e-6 on the bench's paper-size fit, 1.6e-5 on a noisy Phong fit).
 * A model with large cancelling weights stays in double (measured 1.8e-3 for a nearly interpolating fit,
 * η = 1e-8, rcond 7e-8).
 */
#define RGB_F32_TOL 1e-4
#define RGB_F32_PAIRS 2048

struct recon_rgb {
	const struct recon_model *m;
	struct colour_opts co;
	size_t nc, r;
	size_t *chan;   /* [nc+1] first model channel of each 5 nm bin (chan[nc] = end) */
	double *mu, *eps; /* [nc] bin averages of the transformed mean and offset */
	double *tc;     /* [nc*TREND_NB] bin averages of the trend coefficients */
	double *tab;    /* [(ntab-1)*nc] largest albedo bound over the bin */
	double *P;      /* [r*n] row-major: (U_r diag(S_r))ᵀ, one contiguous row per singular vector */
	double *V;      /* [r*nc] row-major: rows of Vᵀ */
	double *WbT;    /* [n*nc] binned weights, centre-major (batch path when the rank is not reduced; this layout
			 * makes the GEMM K·WbT a plain NoTrans product: less packing than channel-major) */
	double *Wrgb;   /* [3*nc] colour weights (stages 1-4) at the kept wavelengths */
	double *Wfull;  /* [3*L] colour weights at every model wavelength (reference path) */
	float *WbTf;    /* [n*nc] WbT in single precision (the batch GEMM, when f32) */
	float *soaf;    /* [6*n] the centres in single precision (Wendland rows of the f32 path) */
	int f32;        /* batch path multiplies in single precision (recon_rgb_set_f32) */
	double f32_err; /* largest |g(single) − g(double)| measured at construction */
	double red_err;   /* largest of red_err_ch */
	double red_err_ch[3]; /* per channel: largest |reduced − full| / max(|full|, RGB_REL_FLOOR · largest channel) */
};

void recon_rgb_free(struct recon_rgb *r)
{
	if (!r)
		return;
	free(r->chan);
	free(r->mu);
	free(r->eps);
	free(r->tc);
	free(r->tab);
	free(r->P);
	free(r->V);
	free(r->WbT);
	free(r->Wrgb);
	free(r->Wfull);
	free(r->WbTf);
	free(r->soaf);
	free(r);
}

void recon_rgb_sizes(const struct recon_rgb *r, size_t *channels, size_t *rank)
{
	*channels = r->nc;
	*rank = r->r;
}

double recon_rgb_reduction_error(const struct recon_rgb *r)
{
	return r->red_err;
}

void recon_rgb_reduction_error_rgb(const struct recon_rgb *r, double e[3])
{
	for (int c = 0; c < 3; c++)
		e[c] = r->red_err_ch[c];
}

double recon_rgb_f32_error(const struct recon_rgb *r)
{
	return r->f32_err;
}

int recon_rgb_f32(const struct recon_rgb *r)
{
	return r->f32;
}

int recon_rgb_set_f32(struct recon_rgb *r, int on)
{
	if (on && !(r->f32_err <= RGB_F32_TOL))
		return -1;
	r->f32 = on != 0;
	return 0;
}

/* g = K·W for b canonical points c6 into G (b × nc): in double (kernel rows into K, b·n doubles), or in single
 * precision with scratch Kf (b·n floats) and Gf (b·nc floats). */
static void gemm_kw(const struct recon_rgb *R, int f32, size_t b, const double *c6, double *K, double *G, float *Kf,
		    float *Gf)
{
	const struct recon_model *m = R->m;
	size_t n = m->n, nc = R->nc;
	if (!f32) {
		rbf_kmatrix_soa(m->kernel, m->shape, b, c6, n, m->soa, K);
		cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, (int)b, (int)nc, (int)n, 1.0, K, (int)n, R->WbT,
			    (int)nc, 0.0, G, (int)nc);
		return;
	}
	if (m->kernel == RBF_K_WENDLAND) {
		rbf_kmatrix_wendland_f32(m->shape, b, c6, n, R->soaf, Kf);
	} else {
		rbf_kmatrix_soa(m->kernel, m->shape, b, c6, n, m->soa, K);
		for (size_t i = 0; i < b * n; i++)
			Kf[i] = (float)K[i];
	}
	cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, (int)b, (int)nc, (int)n, 1.0f, Kf, (int)n, R->WbTf, (int)nc,
		    0.0f, Gf, (int)nc);
	for (size_t i = 0; i < b * nc; i++)
		G[i] = (double)Gf[i];
}

/* f32_err: the largest |g_single − g_double| at RGB_F32_PAIRS random pairs (fixed seed: reproducible). */
static int measure_f32(struct recon_rgb *R, struct acq_err *err)
{
	const struct recon_model *m = R->m;
	size_t n = m->n, nc = R->nc, b = RGB_F32_PAIRS;
	double *c6 = malloc(b * 6 * sizeof *c6), *K = malloc(b * n * sizeof *K), *Gd = malloc(b * nc * sizeof *Gd),
	       *Gs = malloc(b * nc * sizeof *Gs);
	float *Kf = malloc(b * n * sizeof *Kf), *Gf = malloc(b * nc * sizeof *Gf);
	int rc = -1;
	if (!c6 || !K || !Gd || !Gs || !Kf || !Gf) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	struct recon_rng x;
	recon_rng_seed(&x, 0x2545F4914F6CDD1Dull);
	for (size_t q = 0; q < b; q++) {
		double u[4];
		for (int i = 0; i < 4; i++)
			u[i] = recon_rng_unif(&x);
		rbf_canon(acos(u[0]), 2 * M_PI * u[1], acos(u[2]), 2 * M_PI * u[3], c6 + 6 * q);
	}
	gemm_kw(R, 0, b, c6, K, Gd, Kf, Gf);
	gemm_kw(R, 1, b, c6, K, Gs, Kf, Gf);
	R->f32_err = 0;
	for (size_t i = 0; i < b * nc; i++) {
		double d = fabs(Gs[i] - Gd[i]);
		if (!(d <= R->f32_err)) /* NaN-safe: a non-finite result disables the path */
			R->f32_err = isfinite(d) ? d : INFINITY;
	}
	rc = 0;
out:
	free(c6);
	free(K);
	free(Gd);
	free(Gs);
	free(Kf);
	free(Gf);
	return rc;
}

/* The trend value of bin l at basis values tb (1 − ε without a trend, so that the map back (T + ε)·e^g − ε is
 * e^g − ε). */
static inline double bin_trend(const struct recon_rgb *R, const double tb[TREND_NB], size_t l)
{
	if (R->m->trend == RECON_TREND_NONE)
		return 1.0 - R->eps[l]; /* factor 1: f = e^g − ε */
	return trend_dot(R->tc + l * TREND_NB, tb);
}

static void dir_to_angles(const double v[3], double *th, double *ph)
{
	double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
	double z = n > 0 ? v[2] / n : 1;
	*th = z >= 1 ? 0 : z <= 0 ? M_PI / 2 : acos(z);
	*ph = atan2(v[1], v[0]);
}

/* The one RGB accumulation: linear RGB (colour stages 1-4) of one pair at canonical point c6 from its binned
 * values e[nc] (exp(min(μ + g, 69)) for the log transform, μ + g for sqrt): map back with the bin's trend,
 * energy factor of the bin, colour weights. */
static void bins_to_lin(const struct recon_rgb *R, const double *c6, const double *e, double lin[3])
{
	const struct recon_model *m = R->m;
	size_t nc = R->nc;
	double cti = acos(fmin(1, fmax(0, c6[2]))), cto = acos(fmin(1, fmax(0, c6[5])));
	size_t ji = recon_tab_interval(m, cti), jo = recon_tab_interval(m, cto);
	double tb[TREND_NB];
	trend_eval_basis2(m->trend, m->trend_alpha, m->trend_alpha2, c6, tb);
	lin[0] = lin[1] = lin[2] = 0;
	for (size_t l = 0; l < nc; l++) {
		double x = e[l], f;
		if (m->transform == RECON_T_SQRT) {
			f = x * x;
		} else {
			f = x * (bin_trend(R, tb, l) + R->eps[l]) - R->eps[l];
			if (!(f > 0))
				f = 0;
		}
		double a = R->tab[ji * nc + l], b = R->tab[jo * nc + l], mx = a > b ? a : b;
		if (mx > 1)
			f /= mx;
		lin[0] += R->Wrgb[l] * f;
		lin[1] += R->Wrgb[nc + l] * f;
		lin[2] += R->Wrgb[2 * nc + l] * f;
	}
}

/* Linear RGB (colour stages 1-4) of the reduced model at one pair; scratch holds n + r + RGB_PAD4(nc) doubles. */
static void reduced_lin(const struct recon_rgb *R, const double wi[3], const double wo[3], double lin[3],
			double *scratch)
{
	const struct recon_model *m = R->m;
	size_t n = m->n, r = R->r, nc = R->nc;
	double ti, pi, to, po, c6[6];
	dir_to_angles(wi, &ti, &pi);
	dir_to_angles(wo, &to, &po);
	rbf_canon(ti, pi, to, po, c6);
	double *k = scratch, *z = scratch + n, *g = scratch + n + r;
	rbf_krow(m->kernel, m->shape, c6, n, m->soa, k);
	for (size_t c = 0; c < r; c++)
		z[c] = cblas_ddot((int)n, R->P + c * n, 1, k, 1);
	for (size_t l = 0; l < nc; l++)
		g[l] = R->mu[l];
	for (size_t c = 0; c < r; c++) {
		const double *v = R->V + c * nc;
		for (size_t l = 0; l < nc; l++)
			g[l] += z[c] * v[l];
	}
	if (m->transform != RECON_T_SQRT) {
		for (size_t l = 0; l < nc; l++)
			g[l] = g[l] > 69 ? 69 : g[l];
		for (size_t l = nc; l < RGB_PAD4(nc); l++)
			g[l] = 0;
		vexp(g, nc);
	}
	bins_to_lin(R, c6, g, lin);
}

int recon_rgb_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	const struct recon_rgb *R = ctx;
	double stack[4096], *scratch = stack;
	size_t need = R->m->n + R->r + RGB_PAD4(R->nc);
	if (need > sizeof stack / sizeof stack[0] && !(scratch = malloc(need * sizeof *scratch)))
		return -1;
	double lin[3];
	reduced_lin(R, wi, wo, lin, scratch);
	if (scratch != stack)
		free(scratch);
	colour_finish(&R->co, lin, rgb, NULL);
	return 0;
}

static int full_lin(const struct recon_rgb *R, const double wi[3], const double wo[3], double lin[3])
{
	const struct recon_model *m = R->m;
	double *f = malloc(m->nwl * sizeof *f);
	if (!f)
		return -1;
	if (recon_eval_dirs(m, wi, wo, f, NULL)) {
		free(f);
		return -1;
	}
	colour_apply_weights(R->Wfull, m->nwl, f, lin);
	free(f);
	return 0;
}

int recon_rgb_full_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	const struct recon_rgb *R = ctx;
	double lin[3];
	if (full_lin(R, wi, wo, lin))
		return -1;
	colour_finish(&R->co, lin, rgb, NULL);
	return 0;
}

/*
 * Colour weights of the bins. A bin's value v_b stands for the mean of the spectrum over the bin's model channels
 * (exp of the mean of g: the geometric mean, measured 4e-5 below the arithmetic one at 1.8 % channel-to-channel
 * roughness). Model channel l is read back from the bins around it as the quadratic whose bin means are their
 * values (reconstruction from cell averages: exact for quadratics, error O(h³)), and the full path's weights at
 * the model wavelengths (gap rule included) fold onto the bins: Wrgb = Wfull · S, S (L × nc) the reconstruction,
 * 3 bins per channel. Linear in the bin values, so the per-pair cost is unchanged.
 * Why not the colour weights at the bin centres (sessions ≤ 17): that reads the spectrum as linear between
 * centres 5 nm apart, an O(h²) error of ≈ 0.2 % of the spectrum, which is 5 % of R and 2.7 % of B for the green
 * paint (R and B are small differences of large positive and negative lobes of the sRGB weights: the error is
 * amplified ~20×). Measured, demo model, θ ≤ 70° (median error against the full path R / G / B): old +5.2 /
 * −0.2 / +2.7 %; quadratic +0.22 / −0.01 / +0.29 %; cubic (4 bins) similar on smooth spectra but 1 % in B on
 * narrow-lines (overshoot at 2.5-6 nm lines); piecewise constant +4.1 / −0.2 / +2.6 %. What remains is the
 * model's own channel-to-channel roughness, which no reconstruction from 5 nm means can follow (sub-sampling
 * one channel per bin instead of the mean doubles it); --bin-nm 1 is exact.
 */
#define RGB_REC_ORDER 3
static void bin_weights(const struct recon_model *m, const size_t *chan, size_t nc, const double *Wfull, double *Wrgb)
{
	size_t L = m->nwl, first = chan[0], end = chan[nc];
	int ord = nc < RGB_REC_ORDER ? (int)nc : RGB_REC_ORDER;
	memset(Wrgb, 0, 3 * nc * sizeof *Wrgb);
	for (size_t l = first; l < end; l++) {
		/* the bin holding l, then a window of ord bins centred on it (shifted inside at the ends) */
		size_t b = 0;
		while (b + 1 < nc && chan[b + 1] <= l)
			b++;
		double lc = m->wl[l], c0 = 0.5 * (m->wl[chan[b]] + m->wl[chan[b + 1] - 1]);
		long sb = (long)b - (ord % 2 ? (ord - 1) / 2 : ord / 2 - (lc > c0));
		if (sb < 0)
			sb = 0;
		if (sb + ord > (long)nc)
			sb = (long)nc - ord;
		size_t b0 = (size_t)sb;
		double A[4][4], h = m->wl[chan[b0 + (size_t)ord] - 1] - m->wl[chan[b0]];
		if (!(h > 0))
			h = 1;
		for (int i = 0; i < ord; i++) {
			size_t lo = chan[b0 + (size_t)i], hi = chan[b0 + (size_t)i + 1];
				for (int k = 0; k < ord; k++) {
				double acc = 0;
				for (size_t j = lo; j < hi; j++)
					acc += pow((m->wl[j] - lc) / h, k);
				A[i][k] = acc / (double)(hi - lo);
			}
		}
		/* s = e0ᵀ A⁻¹: solve Aᵀ s = e0 (Gaussian elimination with partial pivoting, ord ≤ 4) */
		double T[4][5];
		for (int i = 0; i < ord; i++) {
			for (int k = 0; k < ord; k++)
				T[i][k] = A[k][i];
			T[i][ord] = i == 0;
		}
		for (int c = 0; c < ord; c++) {
			int p = c;
			for (int i = c + 1; i < ord; i++)
				if (fabs(T[i][c]) > fabs(T[p][c]))
					p = i;
			for (int k = 0; k <= ord; k++) {
				double t = T[c][k];
				T[c][k] = T[p][k];
				T[p][k] = t;
			}
			for (int i = 0; i < ord; i++)
				if (i != c) {
					double f = T[i][c] / T[c][c];
					for (int k = c; k <= ord; k++)
						T[i][k] -= f * T[c][k];
				}
		}
		for (int i = 0; i < ord; i++) {
			double s = T[i][ord] / T[i][i];
			for (int c = 0; c < 3; c++)
				Wrgb[(size_t)c * nc + b0 + (size_t)i] += Wfull[(size_t)c * L + l] * s;
		}
	}
}

int recon_rgb_new(const struct recon_model *m, const struct colour_opts *co, double bin_nm, struct recon_rgb **out,
		  struct acq_err *err)
{
	*out = NULL;
	if (colour_opts_check(co, err))
		return -1;
	if (bin_nm == 0)
		bin_nm = RGB_STEP_NM;
	if (!(bin_nm >= 0.5 && bin_nm <= 50))
		return acq_errf(err, ACQ_E_INVAL, "rgb: spectral bin %g nm outside [0.5, 50]", bin_nm);
	size_t n = m->n, L = m->nwl;
	struct recon_rgb *R = calloc(1, sizeof *R);
	double *wsub = NULL, *S = NULL, *U = NULL, *VT = NULL, *scratch = NULL;
	int rc = -1;
	if (!R)
		return acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
	R->m = m;
	R->co = *co;
	R->Wfull = malloc(3 * L * sizeof *R->Wfull);
	R->chan = malloc((L + 1) * sizeof *R->chan);
	if (!R->Wfull || !R->chan) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	if (colour_weights(co, m->wl, L, R->Wfull, err))
		goto out;
	/* 1. channels that carry colour weight, thinned to a 5 nm grid (first and last kept) */
	size_t first = L, last = 0;
	for (size_t l = 0; l < L; l++)
		if (R->Wfull[l] != 0 || R->Wfull[L + l] != 0 || R->Wfull[2 * L + l] != 0) {
			if (first == L)
				first = l;
			last = l;
		}
	if (first == L) {
		acq_errf(err, ACQ_E_INVAL, "rgb: the model's wavelengths (%g-%g nm) are outside the visible range",
			 m->wl[0], m->wl[L - 1]);
		goto out;
	}
	size_t nc = 0;
	for (size_t l = first; l <= last; l++)
		if (nc == 0 || m->wl[l] - m->wl[R->chan[nc - 1]] >= bin_nm - 1e-9)
			R->chan[nc++] = l;
	R->chan[nc] = last + 1;
	R->nc = nc;
	R->mu = calloc(nc, sizeof *R->mu);
	R->eps = calloc(nc, sizeof *R->eps);
	R->tc = calloc(nc * TREND_NB, sizeof *R->tc);
	R->tab = calloc((m->ntab - 1) * nc, sizeof *R->tab);
	R->Wrgb = malloc(3 * nc * sizeof *R->Wrgb);
	if (!R->mu || !R->eps || !R->tc || !R->tab || !R->Wrgb) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	for (size_t c = 0; c < nc; c++) {
		size_t lo = R->chan[c], hi = R->chan[c + 1];
		for (size_t l = lo; l < hi; l++) {
			R->mu[c] += m->mu[l];
			R->eps[c] += m->eps[l];
			for (int j = 0; j < TREND_NB; j++)
				R->tc[c * TREND_NB + j] += m->tcoef[l * TREND_NB + j];
			for (size_t t = 0; t + 1 < m->ntab; t++)
				if (m->tab_alb[t * L + l] > R->tab[t * nc + c])
					R->tab[t * nc + c] = m->tab_alb[t * L + l];
		}
		R->mu[c] /= (double)(hi - lo);
		R->eps[c] /= (double)(hi - lo);
		for (int j = 0; j < TREND_NB; j++)
			R->tc[c * TREND_NB + j] /= (double)(hi - lo);
	}
	bin_weights(m, R->chan, nc, R->Wfull, R->Wrgb);
	/* 2. truncated SVD of the kept weights */
	size_t k = n < nc ? n : nc;
	wsub = malloc(n * nc * sizeof *wsub);
	S = malloc(k * sizeof *S);
	U = malloc(n * k * sizeof *U);
	VT = malloc(k * nc * sizeof *VT);
	if (!wsub || !S || !U || !VT) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	for (size_t c = 0; c < nc; c++) {
		size_t lo = R->chan[c], hi = R->chan[c + 1];
		for (size_t j = 0; j < n; j++) {
			double acc = 0;
			for (size_t l = lo; l < hi; l++)
				acc += m->w[l * n + j];
			wsub[c * n + j] = acc / (double)(hi - lo);
		}
	}
	R->WbT = malloc(n * nc * sizeof *R->WbT);
	R->WbTf = malloc(n * nc * sizeof *R->WbTf);
	R->soaf = malloc(6 * n * sizeof *R->soaf);
	if (!R->WbT || !R->WbTf || !R->soaf) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	for (size_t c = 0; c < nc; c++)
		for (size_t j = 0; j < n; j++)
			R->WbTf[j * nc + c] = (float)(R->WbT[j * nc + c] = wsub[c * n + j]);
	rbf_soa_f32(n, m->ctr, R->soaf);
	if (LAPACKE_dgesdd(LAPACK_COL_MAJOR, 'S', (lapack_int)n, (lapack_int)nc, wsub, (lapack_int)n, S, U,
			   (lapack_int)n, VT, (lapack_int)k) != 0) {
		acq_errf(err, ACQ_E_NUMERIC, "rgb: SVD of the weights failed");
		goto out;
	}
	/* drop trailing components while the bound on what they add to g stays below RGB_G_TOL:
	 * |Σ_c k·u_c S_c v_cl| ≤ Σ_c ‖k‖₂ S_c (‖u_c‖ = 1, |v_cl| ≤ 1), ‖k‖₂ ≤ 2√n (kernel values ≤ 2) */
	double kb = 2.0 * sqrt((double)n), dropped = 0;
	size_t r = k;
	while (r > 1 && dropped + kb * S[r - 1] <= RGB_G_TOL) {
		dropped += kb * S[r - 1];
		r--;
	}
	R->r = r;
	R->P = malloc(n * r * sizeof *R->P);
	R->V = malloc(r * nc * sizeof *R->V);
	if (!R->P || !R->V) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	for (size_t j = 0; j < n; j++)
		for (size_t c = 0; c < r; c++)
			R->P[c * n + j] = U[c * n + j] * S[c];
	for (size_t c = 0; c < r; c++)
		for (size_t l = 0; l < nc; l++)
			R->V[c * nc + l] = VT[l * k + c];
	/* 3. measure the reduction against the full path at random pairs (fixed seed: reproducible) */
	scratch = malloc((n + r + RGB_PAD4(nc)) * sizeof *scratch);
	if (!scratch) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	struct recon_rng x;
	recon_rng_seed(&x, 0x9E3779B97F4A7C15ull);
	for (int t = 0; t < RGB_RED_PAIRS; t++) {
		double u[4];
		for (int i = 0; i < 4; i++)
			u[i] = recon_rng_unif(&x);
		double ci = RGB_RED_CMIN + (1 - RGB_RED_CMIN) * u[0] * u[0], co_ = RGB_RED_CMIN + (1 - RGB_RED_CMIN) * u[2] * u[2];
		double si = sqrt(1 - ci * ci), so = sqrt(1 - co_ * co_);
		double wi[3] = { si, 0, ci }, wo[3] = { so * cos(2 * M_PI * u[3]), so * sin(2 * M_PI * u[3]), co_ };
		double a[3], b[3];
		reduced_lin(R, wi, wo, a, scratch);
		if (full_lin(R, wi, wo, b)) {
			acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
			goto out;
		}
		double mx = fmax(fabs(b[0]), fmax(fabs(b[1]), fabs(b[2])));
		for (int c = 0; c < 3; c++) {
			double den = fmax(fabs(b[c]), RGB_REL_FLOOR * mx);
			if (den > 0 && fabs(a[c] - b[c]) / den > R->red_err_ch[c])
				R->red_err_ch[c] = fabs(a[c] - b[c]) / den;
		}
	}
	for (int c = 0; c < 3; c++) {
		R->red_err_ch[c] *= RGB_RED_MARGIN;
		R->red_err = fmax(R->red_err, R->red_err_ch[c]);
	}
	/* 4. the single-precision GEMM of the batch path, measured against double at the same pairs' kind */
	if (measure_f32(R, err))
		goto out;
	R->f32 = R->f32_err <= RGB_F32_TOL;
	*out = R;
	R = NULL;
	rc = 0;
out:
	recon_rgb_free(R);
	free(wsub);
	free(S);
	free(U);
	free(VT);
	free(scratch);
	return rc;
}

/* Transformed values → linear RGB → colour chain, for one pair (e as in bins_to_lin). */
static void finish_pair(const struct recon_rgb *R, const double *c6, const double *e, double rgb[3],
			struct colour_stats *stats)
{
	double lin[3];
	bins_to_lin(R, c6, e, lin);
	colour_finish(&R->co, lin, rgb, stats);
}

#define BATCH 512

int recon_rgb_batch(const struct recon_rgb *R, size_t nq, const double *wi, const double *wo, double *rgb,
		    struct colour_stats *stats, struct acq_err *err)
{
	const struct recon_model *m = R->m;
	size_t n = m->n, nc = R->nc, r = R->r;
	int reduced = r < nc;
	double *c6 = malloc(BATCH * 6 * sizeof *c6), *K = malloc(BATCH * n * sizeof *K);
	double *Z = malloc(BATCH * r * sizeof *Z), *G = malloc(RGB_PAD4(BATCH * nc) * sizeof *G);
	int f32 = R->f32 && !reduced;
	float *Kf = f32 ? malloc(BATCH * n * sizeof *Kf) : NULL, *Gf = f32 ? malloc(BATCH * nc * sizeof *Gf) : NULL;
	int rc = 0;
	if (!c6 || !K || !Z || !G || (f32 && (!Kf || !Gf))) {
		rc = acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	for (size_t q0 = 0; q0 < nq; q0 += BATCH) {
		size_t b = nq - q0 < BATCH ? nq - q0 : BATCH;
		for (size_t q = 0; q < b; q++) {
			double ti, pi, to, po;
			dir_to_angles(wi + 3 * (q0 + q), &ti, &pi);
			dir_to_angles(wo + 3 * (q0 + q), &to, &po);
			rbf_canon(ti, pi, to, po, c6 + 6 * q);
		}
		if (reduced) {
			rbf_kmatrix_soa(m->kernel, m->shape, b, c6, n, m->soa, K);
			cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasTrans, (int)b, (int)r, (int)n, 1.0, K, (int)n, R->P,
				    (int)n, 0.0, Z, (int)r);
			cblas_dgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, (int)b, (int)nc, (int)r, 1.0, Z, (int)r, R->V,
				    (int)nc, 0.0, G, (int)nc);
		} else {
			gemm_kw(R, f32, b, c6, K, G, Kf, Gf);
		}
		/* μ + g (the same sum as reduced_lin's), then exp over the whole block at once */
		for (size_t q = 0; q < b; q++) {
			double *gq = G + q * nc;
			for (size_t l = 0; l < nc; l++) {
				double x = gq[l] + R->mu[l];
				gq[l] = m->transform != RECON_T_SQRT && x > 69 ? 69 : x;
			}
		}
		if (m->transform != RECON_T_SQRT) {
			for (size_t i = b * nc; i < RGB_PAD4(b * nc); i++)
				G[i] = 0;
			vexp(G, b * nc);
		}
		for (size_t q = 0; q < b; q++)
			finish_pair(R, c6 + 6 * q, G + q * nc, rgb + 3 * (q0 + q), stats);
	}
out:
	free(c6);
	free(K);
	free(Z);
	free(G);
	free(Kf);
	free(Gf);
	return rc;
}
