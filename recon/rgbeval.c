/* rgbeval: "model only what the output needs" for RGB outputs (MERL table, preview render). */
#include "recon/rgbeval.h"

#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/*
 * The reconstruction is not linear in the data (the transform that keeps f ≥ 0), so spectra cannot be
 * reduced to three channels before evaluation. What an RGB output needs is still much less than the model:
 *  1. Only wavelengths where the colour weights are non-zero (the CIE observer ends at 830 nm: of 450-1100 nm
 *     only 450-830 count), and of those a 5 nm grid: the colour chain reads the spectrum as piecewise linear
 *     between the kept channels, which for a spectrum as smooth as a reflectance changes RGB by far less
 *     than the measurement noise. The error is measured at construction against the full path.
 *  2. The transformed interpolant at the kept channels is μ_l + Σ_j K(x, x_j) W_jl; the n × nc weight matrix
 *     is replaced by its SVD truncated at singular values below 1e-7 of the largest (an error of that order
 *     relative in the transformed space, i.e. relative in f for the log transform): z = Pᵀ k (n × r), then
 *     g = μ + V z (r × nc), with r far below nc.
 * Per direction pair the cost is n kernel values + n·r + r·nc + nc exponentials + 3·nc, instead of n·L.
 */

#define RGB_STEP_NM 5.0
#define RGB_SVD_TOL 1e-7

struct recon_rgb {
	const struct recon_model *m;
	struct colour_opts co;
	size_t nc, r;
	size_t *chan;   /* [nc] model channel of each kept channel */
	double *P;      /* [r*n] row-major: (U_r diag(S_r))ᵀ, one contiguous row per singular vector */
	double *V;      /* [r*nc] row-major: rows of Vᵀ */
	double *Wrgb;   /* [3*nc] colour weights (stages 1-4) at the kept wavelengths */
	double *Wfull;  /* [3*L] colour weights at every model wavelength (reference path) */
	double red_err;
};

void recon_rgb_free(struct recon_rgb *r)
{
	if (!r)
		return;
	free(r->chan);
	free(r->P);
	free(r->V);
	free(r->Wrgb);
	free(r->Wfull);
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

static void dir_to_angles(const double v[3], double *th, double *ph)
{
	double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
	double z = n > 0 ? v[2] / n : 1;
	*th = z >= 1 ? 0 : z <= 0 ? M_PI / 2 : acos(z);
	*ph = atan2(v[1], v[0]);
}

/* Linear RGB (colour stages 1-4) of the reduced model at one pair; scratch holds n + r + nc doubles. */
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
		g[l] = m->mu[R->chan[l]];
	for (size_t c = 0; c < r; c++) {
		const double *v = R->V + c * nc;
		for (size_t l = 0; l < nc; l++)
			g[l] += z[c] * v[l];
	}
	double cti = acos(fmin(1, fmax(0, c6[2]))), cto = acos(fmin(1, fmax(0, c6[5])));
	lin[0] = lin[1] = lin[2] = 0;
	for (size_t l = 0; l < nc; l++) {
		size_t ch = R->chan[l];
		double f;
		if (m->transform == RECON_T_SQRT) {
			f = g[l] * g[l];
		} else {
			double x = g[l] > 69 ? 69 : g[l];
			f = exp(x) - m->eps[ch];
			if (!(f > 0))
				f = 0;
		}
		f *= recon_energy_scale(m, cti, cto, ch);
		lin[0] += R->Wrgb[l] * f;
		lin[1] += R->Wrgb[nc + l] * f;
		lin[2] += R->Wrgb[2 * nc + l] * f;
	}
}

int recon_rgb_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	const struct recon_rgb *R = ctx;
	double stack[4096], *scratch = stack;
	size_t need = R->m->n + R->r + R->nc;
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

int recon_rgb_new(const struct recon_model *m, const struct colour_opts *co, struct recon_rgb **out,
		  struct acq_err *err)
{
	*out = NULL;
	if (colour_opts_check(co, err))
		return -1;
	size_t n = m->n, L = m->nwl;
	struct recon_rgb *R = calloc(1, sizeof *R);
	double *wsub = NULL, *S = NULL, *U = NULL, *VT = NULL, *wl = NULL, *scratch = NULL;
	int rc = -1;
	if (!R)
		return acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
	R->m = m;
	R->co = *co;
	R->Wfull = malloc(3 * L * sizeof *R->Wfull);
	R->chan = malloc(L * sizeof *R->chan);
	wl = malloc(L * sizeof *wl);
	if (!R->Wfull || !R->chan || !wl) {
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
		if (nc == 0 || l == last || m->wl[l] - m->wl[R->chan[nc - 1]] >= RGB_STEP_NM - 1e-9)
			R->chan[nc++] = l;
	R->nc = nc;
	for (size_t c = 0; c < nc; c++)
		wl[c] = m->wl[R->chan[c]];
	R->Wrgb = malloc(3 * nc * sizeof *R->Wrgb);
	if (!R->Wrgb) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	if (colour_weights(co, wl, nc, R->Wrgb, err))
		goto out;
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
	for (size_t c = 0; c < nc; c++)
		memcpy(wsub + c * n, m->w + R->chan[c] * n, n * sizeof *wsub);
	if (LAPACKE_dgesdd(LAPACK_COL_MAJOR, 'S', (lapack_int)n, (lapack_int)nc, wsub, (lapack_int)n, S, U,
			   (lapack_int)n, VT, (lapack_int)k) != 0) {
		acq_errf(err, ACQ_E_NUMERIC, "rgb: SVD of the weights failed");
		goto out;
	}
	size_t r = 0;
	while (r < k && S[r] > RGB_SVD_TOL * S[0])
		r++;
	if (r == 0)
		r = 1;
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
	scratch = malloc((n + r + nc) * sizeof *scratch);
	if (!scratch) {
		acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
		goto out;
	}
	uint64_t x = 0x9E3779B97F4A7C15ull;
	for (int t = 0; t < 256; t++) {
		double u[4];
		for (int i = 0; i < 4; i++) {
			x ^= x << 13;
			x ^= x >> 7;
			x ^= x << 17;
			u[i] = (double)(x >> 11) * 0x1.0p-53;
		}
		double ci = 0.05 + 0.95 * u[0], co_ = 0.05 + 0.95 * u[2];
		double si = sqrt(1 - ci * ci), so = sqrt(1 - co_ * co_);
		double wi[3] = { si, 0, ci }, wo[3] = { so * cos(2 * M_PI * u[3]), so * sin(2 * M_PI * u[3]), co_ };
		double a[3], b[3];
		reduced_lin(R, wi, wo, a, scratch);
		if (full_lin(R, wi, wo, b)) {
			acq_errf(err, ACQ_E_NOMEM, "rgb: out of memory");
			goto out;
		}
		double mx = fmax(fabs(b[0]), fmax(fabs(b[1]), fabs(b[2])));
		for (int c = 0; c < 3; c++)
			if (mx > 0 && fabs(a[c] - b[c]) / mx > R->red_err)
				R->red_err = fabs(a[c] - b[c]) / mx;
	}
	*out = R;
	R = NULL;
	rc = 0;
out:
	recon_rgb_free(R);
	free(wsub);
	free(S);
	free(U);
	free(VT);
	free(wl);
	free(scratch);
	return rc;
}
