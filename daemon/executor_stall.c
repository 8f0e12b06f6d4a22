/* executor stall report: where the real time between two committed points went — what the executor waited for
 * between its steps (by phase), its own steps, and the loop's and the ports' totals (stall.h) — logged at debug
 * level after each point, so a slow point in a soak explains itself. */
#include "daemon/executor_int.h"

#include <stdio.h>

#include "daemon/cputime.h"
#include "daemon/log.h"
#include "daemon/stall.h"
#include "daemon/store.h"

static int bucket(const struct ex *x)
{
	if (x->state == EX_SUSPENDED)
		return EX_STALL_RETRY;
	if (x->state != EX_RUNNING)
		return EX_STALL_OTHER;
	switch (x->phase) {
	case PH_LASER_OFF: return EX_STALL_LASER_OFF;
	case PH_VERIFY: return EX_STALL_VERIFY;
	case PH_HOMING: return EX_STALL_HOMING;
	case PH_MOVE: return EX_STALL_MOVE;
	case PH_SETTLE: return EX_STALL_SETTLE;
	case PH_ACQ:
		if (x->shot_in_flight)
			return x->shot == SHOT_DARK ? EX_STALL_DARK : EX_STALL_EXPOSURE;
		return EX_STALL_ACQ;
	case PH_DURABLE: return EX_STALL_DURABLE;
	case PH_NONE: break;
	}
	return EX_STALL_OTHER;
}

static double loop_cpu_wait(void)
{
	struct cputime c;
	return cputime_thread(&c) ? c.waiting : 0;
}

void ex_stall_reset(struct ex *x)
{
	struct stall_acc drop;
	stall_take(&drop);
	for (int i = 0; i < EX_STALL__COUNT; i++)
		x->stall_in[i] = 0;
	x->stall_stale = false;
	x->stall_from = x->stall_last = stall_now();
	x->stall_cpu_wait0 = loop_cpu_wait();
	x->stall_bucket = bucket(x);
	double max_s;
	x->stall_ck_runs = 0;
	x->stall_ck_s = 0;
	if (x->st) /* the checkpoints from here on (the store's totals run since the daemon started) */
		store_ckpt_stats(x->st, &x->stall_ck_runs, &x->stall_ck_s, &max_s);
}

double ex_step(struct ex *x, double now)
{
	double t0 = stall_now();
	if (x->stall_last > 0)
		x->stall_in[x->stall_bucket] += t0 - x->stall_last;
	double next = ex_step_run(x, now);
	x->stall_last = stall_now();
	x->stall_bucket = bucket(x);
	stall_executor(x->stall_last - t0);
	return next;
}

void ex_stall_report(struct ex *x, int point)
{
	/* Gathered only for the debug line: without it, no /proc read, no totals, no text on the loop per point;
	 * the interval restarts (and a debug level turned on later starts from a fresh baseline). */
	stall_cpu_on(log_enabled(LOG_DEBUG));
	if (!log_enabled(LOG_DEBUG)) {
		struct stall_acc drop;
		stall_take(&drop);
		for (int i = 0; i < EX_STALL__COUNT; i++)
			x->stall_in[i] = 0;
		x->stall_stale = true;
		return;
	}
	if (x->stall_stale) {
		ex_stall_reset(x);
		return;
	}
	double t = stall_now(), w = loop_cpu_wait();
	struct stall_acc a;
	stall_take(&a);
	unsigned long ck_runs = 0;
	double ck_s = 0, ck_max = 0;
	if (x->st)
		store_ckpt_stats(x->st, &ck_runs, &ck_s, &ck_max);
	char ports[1024];
	stall_ports_text(&a, ports, sizeof ports);
	const double *in = x->stall_in;
	log_msg(LOG_DEBUG,
		"stall: sweep %lld point %d: %.1f ms since the last commit (monotonic %.3f-%.3f); waited, ms: "
		"laser_off=%.1f verify=%.1f homing=%.1f move=%.1f settle=%.1f dark=%.1f exposure=%.1f acq=%.1f "
		"retry=%.1f durable=%.1f other=%.1f; executor steps=%.1f store=%.1f store_max=%.1f checkpoints=%lu "
		"checkpoint=%.1f (off the loop); loop callbacks=%.1f callback_max=%.1f callback_max_on_cpu=%.1f callback_max_at=0x%lx callback_cpu_max=%.1f callback_cpu_max_at=0x%lx completions=%.1f loop_other=%.1f "
		"timers_late=%.1f timer_late_max=%.1f loop_cpu_wait=%.1f; ports: %s",
		(long long)x->sweep_id, point, 1e3 * (t - x->stall_from), x->stall_from, t, 1e3 * in[EX_STALL_LASER_OFF],
		1e3 * in[EX_STALL_VERIFY], 1e3 * in[EX_STALL_HOMING], 1e3 * in[EX_STALL_MOVE], 1e3 * in[EX_STALL_SETTLE],
		1e3 * in[EX_STALL_DARK], 1e3 * in[EX_STALL_EXPOSURE], 1e3 * in[EX_STALL_ACQ], 1e3 * in[EX_STALL_RETRY],
		1e3 * in[EX_STALL_DURABLE], 1e3 * in[EX_STALL_OTHER], 1e3 * a.executor, 1e3 * a.store, 1e3 * a.max_store,
		ck_runs - x->stall_ck_runs, 1e3 * (ck_s - x->stall_ck_s), 1e3 * a.callbacks, 1e3 * a.max_callback,
		1e3 * a.max_callback_cpu, (unsigned long)stall_fn_offset(a.max_callback_fn), 1e3 * a.max_cpu,
		(unsigned long)stall_fn_offset(a.max_cpu_fn), 1e3 * a.devices,
		1e3 * (a.callbacks - a.devices - a.executor), 1e3 * a.timer_late, 1e3 * a.max_timer_late,
		1e3 * (w - x->stall_cpu_wait0), ports);
	for (int i = 0; i < EX_STALL__COUNT; i++)
		x->stall_in[i] = 0;
	x->stall_from = t;
	x->stall_cpu_wait0 = w;
	x->stall_ck_runs = ck_runs;
	x->stall_ck_s = ck_s;
}
