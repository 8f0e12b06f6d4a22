/* recon_chain: what the daemon does when a sweep completes (or on `recon.start`): export the sweep's
 * calibrated samples as CSV into <recon.output_dir>/sweep-<id>/, then run brdf-recon fit, merl, dhr --plot and
 * render there in child processes (job.h), one after the other; runs, outputs and every step go to the store. */
#ifndef RECON_CHAIN_H
#define RECON_CHAIN_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "daemon/sweep.h"

struct recon_chain;

/* A chain over env (borrowed: the sweep's own, whose conf follows reloads). NULL when out of memory. */
struct recon_chain *recon_chain_new(const struct sweep_env *env);
/* Free; a stage still running is recorded as cancelled (the body's job_finish() kills it). NULL is fine. */
void recon_chain_free(struct recon_chain *ch);
/* The chain for sweep id: export, then the stages when wanted (automatic: only with sweep.auto_recon) and
 * brdf-recon is found. *run_id (may be NULL): the recon_runs row. ACQ_E_STATE while a stage runs,
 * ACQ_E_UNSUPPORTED without brdf-recon. 0 or -1. */
int recon_chain_run(struct recon_chain *ch, int64_t id, bool automatic, int64_t *run_id, struct acq_err *err);
/* The program prog (brdf-recon) as an absolute path, next to acquisitiond, or in PATH into out. 0 or -1. */
int recon_find_program(const char *prog, char *out, size_t cap);
/* True while a stage's child process runs. */
bool recon_chain_busy(const struct recon_chain *ch);

#endif
