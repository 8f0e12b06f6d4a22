/* dhr_budget: a model's DHR and its uncertainty budget, computed once for brdf-recon dhr and info (dhr_budget.c). */
#ifndef RECON_BRDF_RECON_DHR_BUDGET_H
#define RECON_BRDF_RECON_DHR_BUDGET_H

#include <stddef.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "recon/budget.h"
#include "recon/recon.h"

/* The DHR budget's components, in the order of dhr's CSV columns (dhr_budget_names: the column names). */
enum { DB_NOISE, DB_MODEL, DB_QUAD, DB_MISFIT, DB_RES, DB_CERT, DB_DRIFT, DB_WLCAL, DB_NONLIN, DB_REFNOISE, DB_N };
extern const char *const dhr_budget_names[DB_N];
/* DHR and budget of model m at nth (<= 64) incidences th (degrees) into dhr, sig (total) and part[DB_N][nth*L]
 * (draws Monte Carlo draws from seed; the progress line on a terminal); 0 or -1 with err. */
int dhr_budget(const struct recon_model *m, size_t nth, const double *th, uint64_t draws, uint64_t seed,
	       const struct recon_budget_opts *bo, double *dhr, double *sig, double **part, struct acq_err *err);

#endif
