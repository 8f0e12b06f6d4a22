/* pool: the one thread-pool helper of librecon. Independent jobs 0..njobs-1 run on up to `threads` workers (the
 * calling thread is one of them), handed out in increasing order through one counter, so a job's result may
 * depend only on the job, never on which worker ran it or how many there were: outputs are bit-identical for
 * any thread count. Used by the MERL writer (merl.c), the MERL table (rgbeval.c) and the render (render.c). */
#ifndef RECON_POOL_H
#define RECON_POOL_H

#include <stddef.h>

#include "config/acq_err.h"

#define POOL_MAX_THREADS 16

/* One job: worker in [0, threads) (index of per-worker scratch), job in [0, njobs). Returns 0, or non-zero with
 * err filled: no further job is started and pool_run returns that error (the first failure in time). */
typedef int (*pool_job_fn)(void *ctx, int worker, size_t job, struct acq_err *err);

/* Progress of a pool run: fn(ctx, stage, done/njobs) after every `every` finished jobs (serialised). */
struct pool_progress {
	void (*fn)(void *ctx, const char *stage, double frac);
	void *ctx;
	const char *stage;
	size_t every; /* 0 = every job */
};

/* Run fn for every job on `threads` (1..POOL_MAX_THREADS) workers; a worker thread that cannot be started is
 * left out (the others take its jobs). progress may be NULL. Returns 0, or -1 with err from the failing job. */
int pool_run(int threads, size_t njobs, pool_job_fn fn, void *ctx, const struct pool_progress *progress,
	     struct acq_err *err);

#endif
