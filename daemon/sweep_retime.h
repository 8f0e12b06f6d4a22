/* sweep_retime: a first auto sweep of a sample re-times the rest of its plan from what it has measured itself.
 * Without an exposure prior (no earlier sweep of the sample) the plan times every auto exposure from a band around
 * the plan's estimate (plan_time.c), which can be far from the sample (quick plan on the simulated green paint: a
 * 20 ms estimate, 57.9 ms chosen); the live ETA's measured excess (eta.c) follows such an error only slowly, and
 * not at all for what comes later at another incidence (its darks at other ladder times, longer exposures). At each
 * new incidence the sweep's own done points so far become its exposure prior (exp_prior_load_sweep: per incidence
 * the times, darks and HDR exposures it chose, and the host's time per point), the plan is timed again with it
 * (plan_time_apply: each incidence by the nearest one measured) and the ETA's measured excess is re-expressed
 * against it (eta_replan).
 * A sweep that has a prior from an earlier sweep of its sample keeps it (its exposures are the sample's already),
 * as do fixed integration and adaptive sweeps (their batches are timed as they are chosen).
 * Before the sweep nothing measures the sample: the plan's reply gives the estimate's prediction with the same
 * model's times for half and twice the estimate (plan_json.c). Measured in session 15 (README, "How long a sweep
 * takes") and not done: a probe when the plan is made (the white standard is on the stage then), a re-timing from
 * the first sample point alone (one direction: the paper plan's first point needs 41 ms of the green paint's
 * median 57.9, −9 %), a probe at the reference pose when the sample is placed (its unrounded time matched the
 * paper plan's unrounded median on the green paint and the cloth-sheen, not on the metal: 163 against 299 ms).
 * Even at the sample's median the band model errs −12.7…+8.4 % on those three, and this re-timing takes the nearest
 * measured incidence's times for the next, which the metal's (quick plan: ETA +35 / +44 % at 50 / 75 %) and the
 * cloth-sheen's towards grazing are not (README, "How long a sweep takes"). Session 16: with darks kept across
 * incidences (sweep.dark_every -1) the next incidence pays only the darks of rungs not taken yet (plan_time.c):
 * metal quick +4.2 / +12.1 %, cloth-sheen within ±2 %; what is left is the exposure times' change with the
 * incidence. Re-timing after every point instead (eta_replan re-expressing the interval under way) was measured
 * worse on the metal's quick plan (−8.1 / +39.8 / +17.4 % at 25 / 50 / 75 %) and not kept. Session 17: the plan's
 * interval where the exposures are unknown (plan_time_interval) is kept per step and moves the ETA's two ends
 * (sweep_retime_bounds, sweep_retime_eta; sweep.progress eta_low_s, eta_high_s). Session 18: the survey
 * (plan_survey_apply) measures a few points of every incidence first, so that after it every incidence is re-timed
 * from its own exposures (README "How long a sweep takes"); its rows, six points each, are smoothed across
 * incidences (sweep_retime_smooth) until the route reaches them. */
#ifndef SWEEP_RETIME_H
#define SWEEP_RETIME_H

#include <stdbool.h>
#include <stddef.h>

#include "config/acq_err.h"
#include "daemon/exposure.h"
#include "daemon/plan/plan.h"

struct store;

struct sweep_retime {
	bool on;                    /* this sweep re-times its plan */
	struct plan_timing tm;      /* the timing its plan was made with (the prior replaced at each re-timing) */
	int retimed;                /* re-timings done */
	int at;                     /* the step the last one was due at */
	struct exp_prior_rows rows; /* the sweep's exposures read so far (each re-timing reads only the new points) */
	/* the interval where the exposures are unknown (plan_time_interval): each step's predicted start at its low and
	 * high end (n_at = the plan's steps + 1, the last the total), set by sweep_retime_bounds */
	enum plan_interval iv;
	double *lo_at, *hi_at;
	size_t n_at;
	size_t survey;              /* the plan's survey points (plan_survey_apply; 0: none): steps [0, survey) */
	double host_hint;           /* the host's real s per point as the live ETA measured it (eta_host; NAN: none):
				     * the re-timing at the survey's end takes it (sweep_retime_apply) */
};

/* Whether the sweep planned with spec and tm (its exposure prior in tm->prior) re-times its plan: auto
 * integration, not adaptive, no prior from an earlier sweep. Keeps a copy of tm; r is zero-initialised or was set
 * up before (its rows are dropped: a recovered sweep reads its points again). */
void sweep_retime_setup(struct sweep_retime *r, const struct plan_spec *spec, const struct plan_timing *tm);
/* The sweep's plan measures a survey first (plan->n_survey > 0, an auto plan that is not adaptive): r re-times it
 * (even with a prior from an earlier sweep that lacks some incidence: the survey's rows replace it), the survey's
 * rows' pooled share taken as the route's (sweep_retime_apply). Call after sweep_retime_setup. */
void sweep_retime_survey(struct sweep_retime *r, const struct plan_spec *spec, const struct plan_result *plan);
/* The rows of pr flagged in only (pr->n_inc flags: the survey's rows without route points) smoothed across
 * incidences: each one's mean and median first exposure scaled to the Gaussian-kernel mean (12° in zenith) of every
 * row's mean, each row weighted by 1 / (its ln-times' variance / points + 0.4); the other rows unchanged. */
void sweep_retime_smooth(struct plan_prior *pr, const bool *only);
/* The sweep has ended: r's rows freed (r is then set up for nothing). */
void sweep_retime_end(struct sweep_retime *r);
/* Whether step done (the next to be measured) of plan starts a new incidence after at least one measured point, or
 * ends the survey (done = r->survey; within the survey never: its points jump between incidences), when r re-times
 * and has not re-timed there yet. */
bool sweep_retime_due(const struct sweep_retime *r, const struct plan_result *plan, int done);
/* At step done, time plan (sweep sweep_id's, from spec, on bench g) again with the sweep's own exposures so far
 * from st as its prior (exp_prior_update: only the points committed since the last re-timing are read). With a
 * survey, the host's time per point is measured over the route's points only (the survey's long moves and probes at
 * another point's time are not the route's), r->host_hint until ten of them are done. 1 when re-timed, 0 when there was nothing to time it with (no done point), -1 with err (the plan is then
 * unchanged). */
int sweep_retime_apply(struct sweep_retime *r, int done, struct store *st, long long sweep_id,
		       const struct plan_spec *spec, const struct bench_geom *g, struct plan_result *plan,
		       struct acq_err *err);
/* The interval of plan's time (auto, not adaptive: plan_time_interval with r's timing, on a copy of plan) kept in
 * r for sweep_retime_eta; at the start of a sweep and after each re-timing. -1 with err when out of memory (r then
 * has none). */
int sweep_retime_bounds(struct sweep_retime *r, const struct plan_spec *spec, const struct bench_geom *g,
			const struct plan_result *plan, struct acq_err *err);
/* The ETA's interval at step done: eta (wall s) moved by the rest's time at the interval's two ends less the plan's
 * rest (bench s / scale, scale the bench seconds per wall second), *lo <= eta <= *hi; both NAN without an interval. */
void sweep_retime_eta(const struct sweep_retime *r, const struct plan_result *plan, int done, double eta,
		      double scale, double *lo, double *hi);
/* For eta_replan: plan (a struct plan_result) predicted start of step i, bench s (its end for i = n_steps). */
double sweep_retime_plan_at(const void *plan, int i);

#endif
