/* brdf-recon: command-line front end of the reconstruction library: the command table and the helpers the
 * commands share (recon/brdf_recon/cli.h). Only the program's files print. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <sys/stat.h>
#include <stdlib.h>
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

void progress(void *ctx, const char *stage, double frac)
{
	(void)ctx;
	if (!isatty(2))
		return;
	fprintf(stderr, "\r  %-14s %3d%%%s", stage, (int)(100 * frac + 0.5), frac >= 1.0 ? "\n" : "");
	fflush(stderr);
}

void progress_end(void)
{
	if (isatty(2))
		fprintf(stderr, "\r%40s\r", "");
}

int fail(const struct acq_err *e)
{
	progress_end();
	fprintf(stderr, "%s: %s\n", prog, e->msg[0] ? e->msg : "error");
	return 1;
}

int usage_err(const char *cmd, const char *msg)
{
	fprintf(stderr, "%s %s: %s (see %s %s --help)\n", prog, cmd, msg, prog, cmd);
	return 2;
}

int parse_double(const char *s, double *out)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end || errno || !isfinite(v))
		return -1;
	*out = v;
	return 0;
}

int parse_u64(const char *s, uint64_t *out)
{
	char *end;
	errno = 0;
	if (!*s || *s == '-')
		return -1;
	unsigned long long v = strtoull(s, &end, 10);
	if (*end || errno)
		return -1;
	*out = v;
	return 0;
}

int out_open(struct out *o, const char *path, struct acq_err *err)
{
	o->path = path;
	o->direct = 0;
	if (!path || !strcmp(path, "-")) {
		o->f = stdout;
		o->path = NULL;
		return 0;
	}
	struct stat st;
	if (stat(path, &st) == 0 && !S_ISREG(st.st_mode)) {
		if (S_ISDIR(st.st_mode))
			return acq_errf(err, ACQ_E_IO, "%s: is a directory", path);
		o->direct = 1;
		o->f = fopen(path, "w");
		return o->f ? 0 : acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(errno));
	}
	snprintf(o->tmp, sizeof o->tmp, "%s.tmp.%ld", path, (long)getpid());
	o->f = fopen(o->tmp, "w");
	if (!o->f)
		return acq_errf(err, ACQ_E_IO, "%s: %s", o->tmp, strerror(errno));
	return 0;
}

int out_close(struct out *o, int ok, struct acq_err *err)
{
	if (!o->path) {
		fflush(stdout);
		return ok ? 0 : -1;
	}
	int bad = fclose(o->f) != 0;
	if (o->direct)
		return !ok ? -1 : bad ? acq_errf(err, ACQ_E_IO, "%s: write failed", o->path) : 0;
	if (!ok || bad) {
		unlink(o->tmp);
		return ok ? acq_errf(err, ACQ_E_IO, "%s: write failed", o->path) : -1;
	}
	if (rename(o->tmp, o->path)) {
		unlink(o->tmp);
		return acq_errf(err, ACQ_E_IO, "%s: %s", o->path, strerror(errno));
	}
	return 0;
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

