/* sim_sphere: simulated d/8 integrating-sphere spectrophotometer measurement of a truth's DHR (see sim_sphere.h). */
#include "sim/sim_sphere.h"

#include <math.h>
#include <stdlib.h>

#include "sim/sim_refdrift.h"
#include "sim/sim_rng.h"

/* The noise part's standard deviation at wavelength wl for a value v. */
static double sphere_noise_sd(double wl, double v)
{
	return wl < SPHERE_DETECTOR_CHANGE_NM ? 0.001 * fabs(v) + 1e-4 : 0.002 * fabs(v) + 2e-4;
}

int sphere_apply(int nwl, const double *wl, const double *dhr8, uint64_t seed, double *val, double *sigma,
		 struct acq_err *err)
{
	double *cal = malloc(sizeof(double) * (size_t)nwl);
	if (!cal)
		return acq_errf(err, ACQ_E_NOMEM, "spectrophotometer: out of memory");
	struct refdrift_cfg c;
	refdrift_defaults(&c);
	c.ref_u = SPHERE_U_CAL;
	c.ref_corr_nm = SPHERE_CORR_NM;
	c.ref_seed = seed ^ 0x59be7e0ull;
	if (refdrift_reference(&c, nwl, wl, cal, err)) {
		free(cal);
		return -1;
	}
	struct sim_rng r;
	sim_rng_seed(&r, seed ^ 0x5f1e7e5ull);
	for (int l = 0; l < nwl; l++) {
		double truth = dhr8[l], sd = sphere_noise_sd(wl[l], truth);
		val[l] = truth * (1.0 + cal[l]) + sd * sim_rng_gauss(&r);
		double u = SPHERE_U_CAL * fabs(val[l]);
		sigma[l] = sqrt(u * u + sd * sd);
	}
	free(cal);
	return 0;
}

int sphere_measure(const struct mat *m, int nwl, const double *wl, uint64_t seed, double *val, double *sigma,
		   struct acq_err *err)
{
	double *qs = malloc(sizeof(double) * (size_t)nwl);
	if (!qs)
		return acq_errf(err, ACQ_E_NOMEM, "spectrophotometer: out of memory");
	int rc = mat_dhr(m, SPHERE_THETA_DEG * M_PI / 180, 2, val, qs, err) ||
		 sphere_apply(nwl, wl, val, seed, val, sigma, err) ? -1 : 0;
	free(qs);
	return rc;
}
