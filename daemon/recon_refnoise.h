/* recon_refnoise: the white reference's own noise of a stored sweep, written as reference-noise.csv for
 * brdf-recon dhr --ref-noise (recon_refnoise.c; the recon chain calls it). */
#ifndef RECON_REFNOISE_H
#define RECON_REFNOISE_H

#include <stdint.h>

#include "config/acq_err.h"
#include "daemon/store.h"
#include "daemon/sweep.h"

/* reference-noise.csv of sweep id to path (whole or not at all): u_rel per wavelength of the sweep's grid g (its row
 * as store_export_csv_grid read it) where the stored reference (or direct beam) has light, the detector's full scale
 * from env's open spectrometer when it is the sweep's. 1 written, 0 none (no reference stored, or no bin with light),
 * -1 with err (ACQ_E_STATE: no spectrometer recorded). */
int recon_refnoise_write(const struct sweep_env *env, int64_t id, const struct store_grid *g, const char *path,
			 struct acq_err *err);

#endif
