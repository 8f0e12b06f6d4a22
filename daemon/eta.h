/* eta: a sweep's remaining time in wall-clock seconds at any time scale — the planner's prediction of the rest,
 * plus the time per point the sweep has taken beyond the prediction recently (paused or faulted time does not
 * count). */
#ifndef ETA_H
#define ETA_H

#include <stdbool.h>

#define ETA_HISTORY 1024
#define ETA_HOST_WINDOW 120 /* the recent memory's largest span in points (eta.c ETA_MEMORY_MAX) */

struct eta {
	double t0_loop, t0_real;   /* first sample of the two clocks (the loop's may run time-scale faster) */
	double scale;              /* loop seconds per real second, measured; 1 until known */
	double last_real;          /* real time of the last running sample; NAN when not running */
	double last_plan;          /* the plan's time at the last sample (bench seconds from the sweep's start) */
	int last_done;
	bool skip;                 /* the first interval after a (re)start carries the reference, re-checks */
	double run_real;           /* real seconds spent running over the measured intervals */
	double run_plan;           /* the plan's bench seconds for the same points */
	int measured;              /* points completed in those intervals */
	double recent_real;        /* real s per point, recent average (eta.c); NAN until measured */
	double recent_plan;        /* the plan's bench s per point over the same points, with the same weights */
	double recent_w;           /* the weights' sum (each interval's 1 - exp(-k / memory), the older decayed) */
	/* the last measured intervals (steps from..to), oldest first from hist_n - ETA_HISTORY: a re-timed plan's
	 * recent_plan is replayed over them (eta_replan); older ones weigh under exp(-ETA_HISTORY / 120) = 2e-4 */
	struct { int from, to; } hist[ETA_HISTORY];
	long hist_n;               /* intervals recorded since the reset */
	/* the host's time per point is an interval's real seconds less its bench work (eta_work) at the scale:
	 * the last ETA_HOST_WINDOW points' real and bench seconds, oldest first from host_n - ETA_HOST_WINDOW (kept
	 * apart, compared at the current scale as recent_real and recent_plan are), and the recent average of the
	 * bench work per point with recent_real's weights (recent_work; NAN: not measured) */
	struct { float real, work; } host[ETA_HOST_WINDOW];
	long host_n;
	double recent_work, work_w;
	double work_now, work_last; /* eta_work's cumulative bench work: now, at the last update (NAN: unknown) */
	int total;                 /* the sweep's points at the last update */
};

/* A new sweep (or a resumed one): nothing measured yet. */
void eta_reset(struct eta *e);
/* The sweep runs (true) or stops running (pause, fault: false) at these clock readings. */
void eta_running(struct eta *e, bool running, double loop_now, double real_now);
/* The plan was re-timed (sweep_retime.c): its time at step i is now plan_at(ctx, i) (bench s). The plan's side of
 * the recent average is replayed over the remembered intervals in the new plan, so the excess measured so far is
 * kept, against the new plan; the interval under way (its two ends in different plans) is not measured. */
void eta_replan(struct eta *e, double (*plan_at)(const void *ctx, int step), const void *ctx);
/* Forget what the sweep has measured beyond the plan (the recent averages, their history; the clocks' scale and the
 * host's window kept): the points measured so far are not like the rest (a survey's, plan_survey_apply, whose long
 * moves and probes at another point's time the rest does not repeat); the ETA is the plan's until the next points
 * are measured. */
void eta_forget(struct eta *e);
/* The host's real seconds per point: the mean over the recent memory of each point's real time less its bench work
 * at the scale (eta_update takes their median for the excess); NAN before any point is measured with its work. */
double eta_host(const struct eta *e);
/* The bench's own seconds (the counted points' exposures as the planner prices them, their planned moves and
 * settling) of the points done so far, cumulative; given before the eta_update that counts them (NAN: unknown,
 * the excess is then the plain recent average). */
void eta_work(struct eta *e, double work_s);
/* After a point: wall seconds left. plan_at_s: the plan's predicted time (bench s from the sweep's start) at
 * which step `done` starts; plan_total_s: the plan's whole predicted time (NAN: no plan). */
double eta_update(struct eta *e, int done, int total, double plan_at_s, double plan_total_s, double loop_now,
		  double real_now);

#endif
