/* sim_refdrift: reference-standard deviation and source drift of the simulated bench (see sim_refdrift.h). */
#include "sim/sim_refdrift.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "sim/material.h"
#include "sim/sim_rng.h"

void refdrift_defaults(struct refdrift_cfg *c)
{
	memset(c, 0, sizeof *c);
	c->ref_corr_nm = 100;
	c->ref_seed = 1;
	c->drift_tilt = 0.5;
	c->drift_period_s = 3600;
	c->drift_seed = 1;
}

int refdrift_parse(struct yc_node *simcfg, struct refdrift_cfg *out, struct acq_err *err)
{
	struct refdrift_cfg c = *out;
	struct yc_node *r = simcfg ? yc_get(simcfg, "reference_standard") : NULL,
		       *d = simcfg ? yc_get(simcfg, "source_drift") : NULL;
	long long seed;
	if (r) {
		seed = (long long)c.ref_seed;
		if (yc_expect_map(r, "sim.reference_standard", err) || yc_double(r, "u", false, 0, 0.1, &c.ref_u, err) ||
		    yc_double(r, "correlation_nm", false, 5, 10000, &c.ref_corr_nm, err) ||
		    yc_int(r, "seed", false, 0, INT64_MAX, &seed, err) || yc_check_unknown(r, "sim.reference_standard", err))
			return -1;
		c.ref_seed = (uint64_t)seed;
	}
	if (d) {
		seed = (long long)c.drift_seed;
		if (yc_expect_map(d, "sim.source_drift", err) || yc_double(d, "amplitude", false, 0, 0.05, &c.drift_amp, err) ||
		    yc_double(d, "tilt", false, 0, 2, &c.drift_tilt, err) ||
		    yc_double(d, "period_s", false, 1, 1e7, &c.drift_period_s, err) ||
		    yc_int(d, "seed", false, 0, INT64_MAX, &seed, err) || yc_check_unknown(d, "sim.source_drift", err))
			return -1;
		c.drift_seed = (uint64_t)seed;
	}
	*out = c;
	return 0;
}

int refdrift_reference(const struct refdrift_cfg *c, int n, const double *wl, double *d, struct acq_err *err)
{
	memset(d, 0, sizeof(double) * (size_t)n);
	if (!(c->ref_u > 0))
		return 0;
	double step = fmin(5.0, c->ref_corr_nm / 8.0);
	int m = (int)ceil((MAT_WL_MAX - MAT_WL_MIN) / step) + 1;
	double *L = calloc((size_t)m * (size_t)m, sizeof(double)), *z = malloc(sizeof(double) * (size_t)m),
	       *v = calloc((size_t)m, sizeof(double));
	if (!L || !z || !v) {
		free(L);
		free(z);
		free(v);
		return acq_errf(err, ACQ_E_NOMEM, "reference standard: out of memory");
	}
	/* Cholesky of the correlation matrix (plus 1e-10 on the diagonal: the kernel is numerically singular at
	 * node spacings far below its length), then v = L z with z standard normal: exactly the process on the
	 * nodes */
	double inv2l2 = 0.5 / (c->ref_corr_nm * c->ref_corr_nm);
	for (int i = 0; i < m; i++)
		for (int j = 0; j <= i; j++) {
			double dl = (i - j) * step, s = exp(-dl * dl * inv2l2) + (i == j ? 1e-10 : 0.0);
			for (int k = 0; k < j; k++)
				s -= L[(size_t)i * m + k] * L[(size_t)j * m + k];
			L[(size_t)i * m + j] = i == j ? sqrt(fmax(s, 0.0)) : (L[(size_t)j * m + j] > 0 ? s / L[(size_t)j * m + j] : 0.0);
		}
	struct sim_rng r;
	sim_rng_seed(&r, c->ref_seed ^ 0x7e5f5a11dull);
	for (int i = 0; i < m; i++)
		z[i] = sim_rng_gauss(&r);
	for (int i = 0; i < m; i++)
		for (int k = 0; k <= i; k++)
			v[i] += L[(size_t)i * m + k] * z[k];
	for (int l = 0; l < n; l++) {
		double x = (fmin(fmax(wl[l], MAT_WL_MIN), MAT_WL_MAX) - MAT_WL_MIN) / step;
		int i = (int)x;
		if (i >= m - 1)
			i = m - 2;
		double t = x - i;
		d[l] = c->ref_u * (v[i] + t * (v[i + 1] - v[i]));
	}
	free(L);
	free(z);
	free(v);
	return 0;
}

/* h_k(t) of sim_refdrift.h for k = 0, 1 from the seed. */
static double drift_h(const struct refdrift_cfg *c, int k, double t)
{
	struct sim_rng r;
	sim_rng_seed(&r, c->drift_seed * 2 + (uint64_t)k + 0x5d41f7ull);
	static const double div[3] = { 1.0, 1.7, 2.9 };
	double cw[3], ph[3], s2 = 0, h = 0;
	for (int j = 0; j < 3; j++) {
		cw[j] = sim_rng_gauss(&r);
		ph[j] = 2 * M_PI * sim_rng_uniform(&r);
		s2 += 0.5 * cw[j] * cw[j];
	}
	double norm = s2 > 0 ? 1.0 / sqrt(s2) : 0.0;
	for (int j = 0; j < 3; j++)
		h += norm * cw[j] * (sin(2 * M_PI * t * div[j] / c->drift_period_s + ph[j]) - sin(ph[j]));
	return h;
}

double refdrift_source(const struct refdrift_cfg *c, double t, double wl)
{
	if (!(c->drift_amp > 0))
		return 1.0;
	double x = (fmin(fmax(wl, MAT_WL_MIN), MAT_WL_MAX) - 775.0) / 325.0;
	/* |h| <= 2 sqrt(6) < 4.9, so with amplitude <= 0.05 and tilt <= 2 (the parser's limits) the factor stays
	 * above 0.27 */
	return 1.0 + c->drift_amp * (drift_h(c, 0, t) + c->drift_tilt * x * drift_h(c, 1, t));
}
