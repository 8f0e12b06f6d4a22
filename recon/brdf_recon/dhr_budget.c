/* dhr_budget: a model's DHR with its whole uncertainty budget (recon_dhr_parts, then recon_budget), as brdf-recon
 * dhr writes it and info summarises it. */
#include "recon/brdf_recon/dhr_budget.h"

#include <math.h>
#include <stdlib.h>

#include "recon/brdf_recon/cli.h"

const char *const dhr_budget_names[DB_N] = { "sigma_noise", "sigma_model",  "sigma_quad",  "sigma_misfit", "sigma_res",
					    "sigma_cert",  "sigma_drift", "sigma_wlcal", "sigma_nonlin", "sigma_refnoise" };

int dhr_budget(const struct recon_model *m, size_t nth, const double *th, uint64_t draws, uint64_t seed,
	       const struct recon_budget_opts *bo, double *dhr, double *sig, double **part, struct acq_err *err)
{
	double thr[64];
	for (size_t t = 0; t < nth; t++)
		thr[t] = th[t] * M_PI / 180.0;
	struct recon_dhr_parts parts = { .noise = part[DB_NOISE], .model = part[DB_MODEL], .quad = part[DB_QUAD],
					 .misfit = part[DB_MISFIT], .res = part[DB_RES] };
	double *srec = malloc(nth * m->nwl * sizeof *srec);
	int rc = !srec ? acq_errf(err, ACQ_E_NOMEM, "dhr: out of memory")
		 : recon_dhr_parts(m, nth, thr, (int)draws, seed, dhr, srec, &parts, cli_progress, NULL, err) ||
			 recon_budget(nth, m->nwl, m->wl, dhr, srec, bo, part[DB_CERT], part[DB_DRIFT], part[DB_WLCAL],
				      part[DB_NONLIN], part[DB_REFNOISE], sig, err)
		 ? -1
		 : 0;
	free(srec);
	return rc;
}
