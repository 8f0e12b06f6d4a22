/* cli: what brdf-recon's commands share: the progress line, error and usage reports, strict number parsers,
 * output files (recon/brdf_recon/cli.h). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "recon/brdf_recon/cli.h"

static const char *prog = "brdf-recon";

void cli_progress(void *ctx, const char *stage, double frac)
{
	(void)ctx;
	if (!isatty(2))
		return;
	fprintf(stderr, "\r  %-14s %3d%%%s", stage, (int)(100 * frac + 0.5), frac >= 1.0 ? "\n" : "");
	fflush(stderr);
}

void cli_progress_end(void)
{
	if (isatty(2))
		fprintf(stderr, "\r%40s\r", "");
}

int cli_fail(const struct acq_err *e)
{
	cli_progress_end();
	fprintf(stderr, "%s: %s\n", prog, e->msg[0] ? e->msg : "error");
	return 1;
}

int cli_usage_err(const char *cmd, const char *msg)
{
	fprintf(stderr, "%s %s: %s (see %s %s --help)\n", prog, cmd, msg, prog, cmd);
	return 2;
}

int cli_parse_double(const char *s, double *out)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end || errno || !isfinite(v))
		return -1;
	*out = v;
	return 0;
}

int cli_parse_u64(const char *s, uint64_t *out)
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

int cli_out_open(struct cli_out *o, const char *path, struct acq_err *err)
{
	o->std = !path || !strcmp(path, "-");
	o->f = stdout;
	if (o->std)
		return 0;
	if (acq_out_open(&o->a, path, ACQ_OUT_STDIO, err))
		return -1;
	o->f = o->a.f;
	return 0;
}

int cli_out_close(struct cli_out *o, int ok, struct acq_err *err)
{
	if (o->std) {
		fflush(stdout);
		return ok ? 0 : -1;
	}
	if (!ok) {
		acq_out_abort(&o->a);
		return -1;
	}
	return acq_out_commit(&o->a, err);
}
