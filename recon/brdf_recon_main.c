/* brdf-recon: command-line front end of the reconstruction library: the command table (the commands, one per
 * file, and the helpers they share: recon/brdf_recon/cli.h, cli.c). Only the program's files print. */
#include <getopt.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "acq_version.h"
#include "recon/recon.h"
#include "recon/brdf_recon/cli.h"

static const char *prog = "brdf-recon";

/* fontconfig (behind cairo's text in dhr --plot) keeps process-lifetime caches that LeakSanitizer reports;
 * they are not ours. This hook is read by LSan only in sanitizer builds. */
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void)
{
	return "leak:libfontconfig.so\n";
}

static const char main_help[] =
	"usage: brdf-recon COMMAND [options]   (brdf-recon COMMAND --help for each)\n"
	"Reconstruct a complete spectral BRDF from sparse samples with radial basis functions on the product of\n"
	"two hemispheres: non-negative, reciprocal and energy conserving by construction.\n"
	"commands:\n"
	"  fit     SAMPLES.csv -o MODEL     fit a model (or --db FILE --sweep ID)\n"
	"  eval    MODEL QUERIES.csv        evaluate at given directions (CSV)\n"
	"  dhr     MODEL                    DHR(theta_i, lambda) with uncertainty; compare with a reference\n"
	"  check   MODEL                    verify non-negativity, reciprocity, energy conservation\n"
	"  info    MODEL                    print parameters and metadata\n"
	"  merl    MODEL -o FILE.binary     MERL table (RGB)\n"
	"  render  MODEL -o OUT.png         preview render of a sphere\n"
	"  rgl     MODEL -o FILE.bsdf       spectral RGL tabulated BRDF (Mitsuba 3, pbrt-v4)\n"
	"  slices  MODEL -o OUT.png         in-plane slices and polar plots with samples and uncertainty\n"
	"  select  MODEL --candidates CAND.csv --target SPEC   next measurements of an adaptive sweep (JSON)\n";

int main(int argc, char **argv)
{
	if (argc < 2) {
		fputs(main_help, stderr);
		return 2;
	}
	const char *cmd = argv[1];
	if (!strcmp(cmd, "--help") || !strcmp(cmd, "-h") || !strcmp(cmd, "help")) {
		fputs(main_help, stdout);
		return 0;
	}
	if (!strcmp(cmd, "--version")) {
		printf("brdf-recon %s\n", ACQ_VERSION);
		return 0;
	}
	argc--;
	argv++;
	if (!strcmp(cmd, "fit"))
		return cmd_fit(argc, argv);
	if (!strcmp(cmd, "eval"))
		return cmd_eval(argc, argv);
	if (!strcmp(cmd, "dhr"))
		return cmd_dhr(argc, argv);
	if (!strcmp(cmd, "check"))
		return cmd_check(argc, argv);
	if (!strcmp(cmd, "info"))
		return cmd_info(argc, argv);
	if (!strcmp(cmd, "rgl"))
		return cmd_rgl(argc, argv);
	if (!strcmp(cmd, "select"))
		return cmd_select(argc, argv);
	if (!strcmp(cmd, "slices"))
		return cmd_slices(argc, argv);
	if (!strcmp(cmd, "merl") || !strcmp(cmd, "render"))
		return cmd_output(cmd, argc, argv);
	fprintf(stderr, "%s: unknown command '%s'\n%s", prog, cmd, main_help);
	return 2;
}

