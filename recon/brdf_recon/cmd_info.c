/* brdf-recon info: a model's parameters, metadata and DHR budget at 8 degrees. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon/brdf_recon/cli.h"
#include "recon/brdf_recon/dhr_budget.h"
#include "recon/budget.h"
#include "recon/recon.h"

/* ---- info ---- */
static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

int cmd_info(int argc, char **argv)
{
	int budget = 1;
	if (argc == 3 && !strcmp(argv[2], "--no-budget")) {
		budget = 0;
		argc--;
	}
	if (argc == 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
		puts("usage: brdf-recon info MODEL [--no-budget]\nPrint a model's parameters and metadata (warnings of the "
		     "fit included), and the DHR uncertainty budget at theta_i = 8 deg (16 draws; the median and largest\n"
		     "standard uncertainty of each component over the wavelengths; brdf-recon dhr --help names them; the\n"
		     "instrument's systematic components are 0 there, brdf-recon dhr takes them as options).");
		return 0;
	}
	if (argc != 2)
		return cli_usage_err("info", "one MODEL expected");
	struct acq_err err = { 0 };
	struct recon_model *m;
	if (recon_model_load(argv[1], &m, &err))
		return cli_fail(&err);
	printf("directions=%zu\nwavelengths=%zu (%g..%g nm)\nkernel=%s\nshape=%.6g\ntransform=%s\nsmoothing=%.6g\n%s",
	       m->n, m->nwl, m->wl[0], m->wl[m->nwl - 1], rbf_kernel_name(m->kernel), m->shape,
	       recon_transform_name(m->transform), m->eta, m->meta);
	int ok = 1;
	if (budget) {
		size_t L = m->nwl;
		double th = 8, *buf = malloc((DB_N + 3) * L * sizeof *buf), *part[DB_N];
		struct recon_budget_opts bo = { 0 };
		ok = buf != NULL;
		if (!ok)
			acq_errf(&err, ACQ_E_NOMEM, "info: out of memory");
		for (int k = 0; ok && k < DB_N; k++)
			part[k] = buf + (size_t)k * L;
		if (ok && dhr_budget(m, 1, &th, 16, 1, &bo, buf + DB_N * L, buf + (DB_N + 1) * L, part, &err))
			ok = 0;
		cli_progress_end();
		if (ok) {
			double *tmp = buf + (DB_N + 2) * L;
			printf("budget at theta_i=8 deg (standard uncertainty over %zu wavelengths: median, max):\n", L);
			for (int k = -2; k < DB_N; k++) {
				memcpy(tmp, k == -2 ? buf + DB_N * L : k == -1 ? buf + (DB_N + 1) * L : part[k], L * sizeof *tmp);
				qsort(tmp, L, sizeof *tmp, cmp_double);
				printf("  %-14s %.3g  %.3g\n", k == -2 ? "dhr" : k == -1 ? "sigma" : dhr_budget_names[k], tmp[L / 2],
				       tmp[L - 1]);
			}
		}
		free(buf);
	}
	recon_model_free(m);
	return ok ? 0 : cli_fail(&err);
}

