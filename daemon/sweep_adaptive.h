/* sweep_adaptive: the loop of an adaptive sweep (kind: adaptive) beside the executor. The seed plan is measured
 * like any plan; whenever the executor has measured every planned point (EX_WAITING), the next batch is chosen
 * off the loop (recon_select.h: fit, then brdf-recon select among reachable candidates), cut to the budget,
 * ordered by the planner from where the arms are, recorded (store_adaptive.h: decision, picks, points in one
 * transaction) and appended to the sweep's plan; or the sweep completes, saying why: the target met, the budget
 * spent, or nothing reachable left. Every decision is in the database, so a restarted daemon resumes where the
 * last one stopped. Watchers get "sweep.adaptive" events: {sweep, batch, target, value, threshold, met, trend,
 * points, spent_s, budget_s, budget_points, waited_s, waited_total_s, stop}. */
#ifndef SWEEP_ADAPTIVE_H
#define SWEEP_ADAPTIVE_H

#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "daemon/plan/plan.h"
#include "daemon/sweep.h"

struct adapt;

/* What the loop asks of the sweep (sweep.c): go on with the plan's new steps, complete (why), or pause (why). */
struct adapt_ops {
	void (*extend)(void *ctx);
	void (*finish)(void *ctx, const char *why);
	void (*pause)(void *ctx, const char *why);
	void (*timing)(void *ctx, struct plan_timing *t); /* this daemon's executor timing (sweep_plan_timing) */
	void *ctx;
};

/* A loop over env (borrowed: the sweep's). NULL when out of memory. */
struct adapt *adapt_new(const struct sweep_env *env, const struct adapt_ops *ops);
/* Free (a decision under way is abandoned: its child is job_finish()'s). NULL is fine. */
void adapt_free(struct adapt *a);
/* A new adaptive sweep id whose plan (the sweep's, extended in place by later batches; borrowed with spec until
 * adapt_end) holds the seed; spec was parsed from plan_text (copied: each decision's candidates child parses it);
 * the seed's decision row is recorded. 0 or -1. */
int adapt_begin(struct adapt *a, int64_t id, const struct plan_spec *spec, const char *plan_text,
		struct plan_result *plan, struct acq_err *err);
/* Resume sweep id: plan holds the seed as planned again from plan_text (spec, parsed from it); the stored batches
 * are appended in their stored order and their figures reloaded. *stop: the stored stop reason ("" when it goes
 * on). 0 or -1. */
int adapt_resume(struct adapt *a, int64_t id, const struct plan_spec *spec, const char *plan_text,
		 struct plan_result *plan, char *stop, size_t stop_len, struct acq_err *err);
/* The executor has measured every planned point and waits (now: loop seconds): choose the next batch or stop. */
void adapt_waiting(struct adapt *a, double now);
/* The sweep is released: forget it (a decision under way is abandoned). */
void adapt_end(struct adapt *a);

#endif
