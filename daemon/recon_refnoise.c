/* recon_refnoise: reference-noise.csv beside a sweep's samples: the relative noise u(R_ref)/R_ref of the sweep's
 * stored white reference (or direct beam) per wavelength of its grid, rebuilt from the store as the crash-resume
 * reload does (ex_reference_rate) and binned as every sample's (calib_ref_noise) on the grid row the export read: one spectrum shared by all
 * samples, which dhr must not average away (--ref-noise). The recon chain writes it before its stages. */
#include "daemon/recon_refnoise.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "config/acq_out.h"
#include "daemon/calib.h"
#include "daemon/devices.h"
#include "daemon/executor.h"
#include "daemon/store.h"

int recon_refnoise_write(const struct sweep_env *env, int64_t id, const struct store_grid *g, const char *path,
			 struct acq_err *err)
{
	const struct conf *c = env->conf;
	struct ex_cfg cfg;
	ex_cfg_defaults(&cfg);
	if (ex_cfg_parse(c->sweep.acquisition, c->sweep.calibration, &cfg, err))
		return -1;
	if (!g->nm || g->n <= 0)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld has no wavelength grid (no calibrated sample)", (long long)id);
	if (g->npix < 0)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld has no spectrometer recorded", (long long)id);
	const float *grid = g->nm;
	int n = g->n, npix = g->npix;
	struct spectro_info info = { 0 };
	memcpy(info.wl_coef, g->coef, sizeof info.wl_coef);
	info.npix = npix;
	/* the detector's full scale (saturation as at the measurement) from the spectrometer when it is open */
	const struct spectro_info *live = env->devices ? devices_ex_ops()->spectro_info(env->devices) : NULL;
	if (live && live->npix != npix)
		live = NULL; /* another spectrometer than the sweep's: its pixels say nothing of these */
	double fs = exp_full_scale(live);
	struct calib_cfg *cal = &cfg.cal;
	cal->grid_min_nm = grid[0];
	cal->grid_max_nm = grid[n - 1];
	if (n > 1)
		cal->grid_step_nm = (grid[n - 1] - grid[0]) / (n - 1);
	double *wl = malloc((size_t)(npix > 0 ? npix : 1) * sizeof *wl), *u = malloc((size_t)n * sizeof *u);
	struct exp_rate *ref = malloc(sizeof *ref);
	int rc = -1;
	if (!wl || !u || !ref) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto out;
	}
	if (calib_grid_size(cal) != n) {
		acq_errf(err, ACQ_E_STATE, "sweep %lld: its stored grid (%d values) is not a regular grid",
			 (long long)id, n);
		goto out;
	}
	for (int p = 0; p < npix; p++)
		wl[p] = spectro_wavelength(&info, p);
	rc = ex_reference_rate(env->store, id, &cfg.pol, npix, fs, ref, NULL, err);
	if (rc <= 0)
		goto out;
	exp_mask_black(live, ref); /* as the executor does (the store does not know them) */
	rc = -1;
	if (calib_ref_noise(cal, wl, ref, u, err))
		goto out;
	struct acq_out o;
	if (acq_out_open(&o, path, ACQ_OUT_STDIO, err))
		goto out;
	fprintf(o.f, "# acquisitiond sweep %lld: relative standard uncertainty of its white reference's (or direct "
		"beam's) own noise and dark per wavelength, common to every sample (brdf-recon dhr --ref-noise)\n"
		"wavelength_nm,u_rel\n", (long long)id);
	int rows = 0;
	for (int k = 0; k < n; k++)
		if (isfinite(u[k]) && u[k] >= 0 && u[k] < 1) { /* bins without light: no row (dhr interpolates) */
			fprintf(o.f, "%.7g,%.6g\n", (double)grid[k], u[k]);
			rows++;
		}
	if (rows == 0) {
		acq_out_abort(&o);
		rc = 0;
		goto out;
	}
	rc = acq_out_commit(&o, err) ? -1 : 1;
out:
	free(wl);
	free(u);
	free(ref);
	return rc;
}
