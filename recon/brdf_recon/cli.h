/* brdf-recon's shared command-line helpers (cli_*, defined in cli.c) and the commands, one per file
 * (recon/brdf_recon/cmd_*.c; the DHR budget dhr and info share: dhr_budget.h). Only the program's own files include this. */
#ifndef RECON_BRDF_RECON_CLI_H
#define RECON_BRDF_RECON_CLI_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "config/acq_err.h"
#include "config/acq_out.h"
#include "recon/recon.h"

/* Progress line on a terminal (stderr), and its erasure. */
void cli_progress(void *ctx, const char *stage, double frac);
void cli_progress_end(void);
/* Print "brdf-recon: message" and return 1. */
int cli_fail(const struct acq_err *e);
/* Print a usage error of a command and return 2. */
int cli_usage_err(const char *cmd, const char *msg);
/* Strict number parsers: 0, or -1 for anything but a whole finite number / unsigned integer. */
int cli_parse_double(const char *s, double *out);
int cli_parse_u64(const char *s, uint64_t *out);


/* An output file: stdout for NULL or "-", else config/acq_out (a temporary file renamed on success; an existing
 * device or FIFO written in place, since renaming over it would replace it; a directory refused). */
struct cli_out {
	FILE *f;
	int std;          /* stdout */
	struct acq_out a; /* the file otherwise */
};
/* Open path for writing (see struct cli_out); 0 or -1 with err set. */
int cli_out_open(struct cli_out *o, const char *path, struct acq_err *err);
/* Finish: on ok, flush and rename the temporary into place; else remove it. 0, or -1 (err set if a write failed). */
int cli_out_close(struct cli_out *o, int ok, struct acq_err *err);

/* The commands: argv[0] is the command's name; exit status. */
int cmd_fit(int argc, char **argv);
int cmd_eval(int argc, char **argv);
int cmd_dhr(int argc, char **argv);
int cmd_check(int argc, char **argv);
int cmd_info(int argc, char **argv);
/* merl and render (cmd is "merl" or "render"). */
int cmd_output(const char *cmd, int argc, char **argv);
int cmd_rgl(int argc, char **argv);
int cmd_select(int argc, char **argv);
int cmd_slices(int argc, char **argv);

#endif
