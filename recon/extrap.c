/* extrap: the DHR's extrapolation term beyond the plan's last observation zenith and the size of the last ring's
 * misfit that switches it on (recon/reconstruction.md, sessions 12 and 13). */
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "recon/recon_int.h"

double recon_last_zenith(const struct recon_model *m)
{
	double te = 0;
	for (size_t k = 0; k < m->n; k++) /* the canonical point's second direction is the larger zenith */
		te = fmax(te, theta_of(m->ctr + 6 * k + 3));
	return te;
}

/* The canonical point c with both zeniths clamped to at most te, the relative azimuth kept (rbf_canon splits
 * it as ai = −Δ·sinθo/s, ao = Δ·sinθi/s, so Δ = ao − ai). */
static void canon_clamp(const double *c, double te, double *out)
{
	double ts = theta_of(c), tl = theta_of(c + 3), d = 0;
	if (c[0] != 0 || c[1] != 0)
		d -= atan2(c[1], c[0]);
	if (c[3] != 0 || c[4] != 0)
		d += atan2(c[4], c[3]);
	rbf_canon(fmin(ts, te), 0.0, fmin(tl, te), fmin(fabs(d), M_PI), out);
}

double recon_edge_size(const struct recon_model *m, const double *Ainv, const double *alpha)
{
	size_t n = m->n, L = m->nwl, nb = 0;
	double te = recon_last_zenith(m), a2 = 0;
	size_t *B = malloc(n * sizeof *B), used = 0;
	double *S = NULL, *r = NULL, *one = NULL;
	if (!B)
		return -1;
	for (size_t k = 0; k < n; k++)
		if (theta_of(m->ctr + 6 * k + 3) >= te - RECON_EDGE_RING)
			B[nb++] = k;
	if (nb < RECON_EDGE_MIN || n - nb < RECON_EDGE_MIN) {
		free(B);
		return 0; /* no ring to hold out, or nothing left to predict it from */
	}
	S = malloc(nb * nb * sizeof *S);
	r = malloc(nb * L * sizeof *r);
	one = malloc(nb * sizeof *one);
	if (!S || !r || !one) {
		a2 = -1;
		goto out;
	}
	for (size_t i = 0; i < nb; i++) {
		for (size_t j = 0; j < nb; j++) /* Ainv: column-major, its lower triangle (recon_gp_setup) */
			S[j * nb + i] = Ainv[(B[i] < B[j] ? B[i] : B[j]) * n + (B[i] < B[j] ? B[j] : B[i])];
		one[i] = 1;
		for (size_t l = 0; l < L; l++)
			r[l * nb + i] = m->w[l * n + B[i]];
	}
	if (LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', (lapack_int)nb, S, (lapack_int)nb) != 0 ||
	    LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)nb, (lapack_int)L, S, (lapack_int)nb, r, (lapack_int)nb) != 0 ||
	    LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', (lapack_int)nb, 1, S, (lapack_int)nb, one, (lapack_int)nb) != 0)
		goto out; /* 0: no verdict */
	double s1 = 0;
	for (size_t i = 0; i < nb; i++)
		s1 += one[i];
	for (size_t l = 0; l < L; l++) {
		/* the ring's mean held-out residual (ln f), its noise variance α·1ᵀS⁻¹1/nb² taken off (a size, not a
		 * significance), in units of the kriging amplitude √α */
		double mean = 0, var = alpha[l] * s1 / ((double)nb * (double)nb);
		for (size_t i = 0; i < nb; i++)
			mean += r[l * nb + i];
		mean /= (double)nb;
		if (alpha[l] > 0 && isfinite(var) && isfinite(mean)) {
			a2 += fmax(mean * mean - var, 0) / alpha[l];
			used++;
		}
	}
	a2 = used ? a2 / (double)used : 0;
out:
	free(B);
	free(S);
	free(r);
	free(one);
	return a2 < 0 ? -1 : sqrt(a2);
}

int recon_extrap_sd(const struct recon_model *m, size_t Q, const double *c6, const double *wt, double gate, double *xs,
		    struct acq_err *err)
{
	size_t L = m->nwl, nb = 0;
	double te = recon_last_zenith(m);
	for (size_t l = 0; l < L; l++)
		xs[l] = 0;
	if (!(gate > 0))
		return 0;
	for (size_t q = 0; q < Q; q++)
		nb += theta_of(c6 + 6 * q + 3) > te;
	if (nb == 0)
		return 0;
	double *cb = malloc(2 * nb * 6 * sizeof *cb), *w = malloc(nb * sizeof *w), *f = malloc(2 * nb * L * sizeof *f);
	double *work = malloc(recon_eval_work_size(m) * sizeof *work);
	if (!cb || !w || !f || !work) {
		free(cb);
		free(w);
		free(f);
		free(work);
		return acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory (extrapolation term)");
	}
	size_t j = 0;
	for (size_t q = 0; q < Q; q++)
		if (theta_of(c6 + 6 * q + 3) > te) {
			memcpy(cb + 6 * j, c6 + 6 * q, 6 * sizeof *cb);
			canon_clamp(c6 + 6 * q, te, cb + 6 * (nb + j));
			w[j++] = wt[q];
		}
	recon_eval_canon(m, 2 * nb, cb, 1, f, work);
	for (size_t q = 0; q < nb; q++)
		for (size_t l = 0; l < L; l++)
			xs[l] += w[q] * fabs(f[q * L + l] - f[(nb + q) * L + l]);
	for (size_t l = 0; l < L; l++)
		xs[l] *= gate * RECON_EXTRAP_K;
	free(cb);
	free(w);
	free(f);
	free(work);
	return 0;
}
