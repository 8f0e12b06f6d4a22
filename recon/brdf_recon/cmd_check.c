/* brdf-recon check: non-negativity, reciprocity and energy conservation of a model. */
#include <getopt.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>

#include "recon/brdf_recon/cli.h"
#include "recon/recon.h"

/* ---- check ---- */
static const char check_help[] =
	"usage: brdf-recon check MODEL [--pairs N] [--thetas N] [--seed S]\n"
	"Verify the three physical properties of the evaluated model: non-negativity and reciprocity at N random\n"
	"direction pairs (default 100000), energy conservation (albedo <= 1 at every wavelength) at N random\n"
	"incidences plus 0 and 90 degrees (default 16) with an independent quadrature (adaptive cubature over cells\n"
	"of cos(theta_o) x azimuth, to 1e-3 relative). Prints the worst violation of each; exit 1 if any property\n"
	"fails.\n";

int cmd_check(int argc, char **argv)
{
	static const struct option lo[] = {
		{ "pairs", required_argument, 0, 'p' }, { "thetas", required_argument, 0, 't' },
		{ "seed", required_argument, 0, 's' }, { "help", no_argument, 0, 'h' }, { 0, 0, 0, 0 } };
	uint64_t pairs = 100000, thetas = 16, seed = 1;
	int c;
	while ((c = getopt_long(argc, argv, "h", lo, NULL)) != -1) {
		switch (c) {
		case 'p':
			if (cli_parse_u64(optarg, &pairs) || pairs > 100000000)
				return cli_usage_err("check", "--pairs needs a count");
			break;
		case 't':
			if (cli_parse_u64(optarg, &thetas) || thetas > 100000)
				return cli_usage_err("check", "--thetas needs a count");
			break;
		case 's':
			if (cli_parse_u64(optarg, &seed))
				return cli_usage_err("check", "--seed needs an unsigned integer");
			break;
		case 'h': fputs(check_help, stdout); return 0;
		default: return cli_usage_err("check", "bad option");
		}
	}
	if (optind != argc - 1)
		return cli_usage_err("check", "one MODEL expected");
	struct acq_err err = { 0 };
	struct recon_model *m;
	if (recon_model_load(argv[optind], &m, &err))
		return cli_fail(&err);
	struct recon_check_report r;
	int rc = recon_check(m, pairs, thetas, seed, &r, cli_progress, NULL, &err);
	cli_progress_end();
	recon_model_free(m);
	if (rc)
		return cli_fail(&err);
	int nonneg = r.min_value >= 0 && r.nonfinite == 0, recip = r.max_recip_abs == 0.0,
	    energy = r.energy_excess <= 0;
	printf("check: %zu random pairs, %zu incidences (seed %llu)\n", r.npairs, r.nalb, (unsigned long long)seed);
	printf("non-negativity:  %s  min f = %.6g sr^-1, non-finite values: %zu\n", nonneg ? "ok  " : "FAIL",
	       r.min_value, r.nonfinite);
	printf("reciprocity:     %s  max |f(wi,wo) - f(wo,wi)| = %.3g (relative %.3g)\n", recip ? "ok  " : "FAIL",
	       r.max_recip_abs, r.max_recip_rel);
	printf("energy:          %s  max albedo = %.6f +- %.2g (the check's quadrature) at theta_i = %.2f deg, %g nm "
	       "(violation beyond it %.3g)\n",
	       energy ? "ok  " : "FAIL", r.max_albedo, r.max_albedo_qerr, r.max_albedo_theta * 180 / M_PI, r.max_albedo_wl,
	       r.energy_excess > 0 ? r.energy_excess : 0.0);
	if (r.alb_unresolved)
		printf("                 %zu albedo(s) not resolved to 1e-3 by the check's cubature (its estimate is used)\n",
		       r.alb_unresolved);
	return nonneg && recip && energy ? 0 : 1;
}

