/* brdf-recon's shared command-line helpers (defined in brdf_recon_main.c) and the commands kept in their own
 * files (recon/brdf_recon/cmd_*.c). Only the program's own files include this. */
#ifndef RECON_BRDF_RECON_CLI_H
#define RECON_BRDF_RECON_CLI_H

#include <stdint.h>

#include "config/acq_err.h"

/* Progress line on a terminal (stderr), and its erasure. */
void progress(void *ctx, const char *stage, double frac);
void progress_end(void);
/* Print "brdf-recon: message" and return 1. */
int fail(const struct acq_err *e);
/* Print a usage error of a command and return 2. */
int usage_err(const char *cmd, const char *msg);
/* Strict number parsers: 0, or -1 for anything but a whole finite number / unsigned integer. */
int parse_double(const char *s, double *out);
int parse_u64(const char *s, uint64_t *out);

/* The commands: argv[0] is the command's name; exit status. */
int cmd_rgl(int argc, char **argv);
int cmd_slices(int argc, char **argv);

#endif
