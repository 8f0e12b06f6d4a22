/* plan_worker: a sweep's plan made off the loop. plan_make() grows fast with the points (1000 × 10 Fibonacci
 * points took 31 s and 2000 × 10 320 MB): `sweep.start` plans in a child of the job helper (job.h: nice +10, bounded
 * address space, a deadline), which sends the result back whole through its output pipe, so no plan holds the
 * loop, its clients or the watchdog. */
#ifndef DAEMON_PLAN_WORKER_H
#define DAEMON_PLAN_WORKER_H

#include <stddef.h>

#include "config/acq_err.h"
#include "daemon/job.h"
#include "daemon/plan/plan.h"

struct plan_worker;

/* On the loop, once: rc 0 with the plan (the callee's to free), or -1 with err (a planning error, the deadline,
 * the memory bound, or abort). */
typedef void (*plan_worker_done_fn)(void *ctx, int rc, const struct acq_err *err, struct plan_result *plan);

/* Parse text (named name in messages), plan it against g and apply the executor's timing tm (plan_load_string +
 * plan_make + plan_time_apply) in a child of the job helper (job_fork_msg) killed after deadline_s of the loop's
 * clock (real_deadline_s, the real seconds it stands for, only for the message), its address space limited to
 * mem_bytes; a lost helper fails it with "retry". *out (may be NULL) is the running worker, valid until done().
 * 0 or -1. */
int plan_worker_start(const char *name, const char *text, const struct bench_geom *g, const struct plan_timing *tm,
		      size_t mem_bytes, double deadline_s, double real_deadline_s, plan_worker_done_fn done, void *ctx,
		      struct plan_worker **out, struct acq_err *err);
/* The worker's child, run by the job helper (it must be in the program's table of job kinds, job_kinds_main). */
extern const struct job_kind plan_worker_kind;
/* Stop a running worker: its done() gets -1 with ACQ_E_STATE "aborted". */
void plan_worker_abort(struct plan_worker *w);

/* The result's binary form, as the child sends it (exported for the tests): plan_worker_encode() writes r to
 * fd (0 or -1); plan_worker_decode() checks the bytes (sizes, indices) and rebuilds a result. 0 or -1. */
int plan_worker_encode(const struct plan_result *r, int fd);
int plan_worker_decode(const char *buf, size_t len, struct plan_result **out, struct acq_err *err);

#endif
