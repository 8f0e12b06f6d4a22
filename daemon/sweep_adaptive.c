/* sweep_adaptive: an adaptive sweep's loop between its batches (see sweep_adaptive.h): the budget, the decision
 * off the loop (recon_select.c), the batch planned from the arms' position and recorded before it is measured,
 * the stop and its reason, and the resume from the recorded decisions. */
#include "daemon/sweep_adaptive.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/devices.h"
#include "daemon/executor.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/recon_select.h"
#include "daemon/store.h"
#include "daemon/store_adaptive.h"

#define ADAPT_TREND 256

struct adapt {
	const struct sweep_env *env;
	struct adapt_ops ops;
	struct rsel *rs;
	int64_t id;                 /* 0: no adaptive sweep loaded */
	const struct plan_spec *spec;
	char *plan_text;            /* the text spec was parsed from (the candidates child parses it again) */
	struct plan_result *plan;   /* the sweep's: seed, then the batches appended */
	int batch;                  /* the last batch decided (0: only the seed) */
	double spent_s;             /* predicted bench seconds of the seed and the batches decided */
	double waited_s;            /* bench seconds the arms waited for decisions */
	double wait_start;          /* loop time the current wait began (NaN: not waiting) */
	char model[4096];           /* the latest decision's model ("" before the first) */
	double trend[ADAPT_TREND];  /* the target's value at each decision */
	int ntrend;
	struct plan_pos *done;      /* scratch: the positions so far, for the candidates child */
	struct plan_pos arms;       /* where the arms were when the decision started */
	int64_t deciding;           /* the sweep the decision under way is for (0: none) */
	struct rsel_res ahead;      /* overlap: a decision that came in while the arms were still measuring */
	bool ahead_ready;
};

struct adapt *adapt_new(const struct sweep_env *env, const struct adapt_ops *ops)
{
	struct adapt *a = calloc(1, sizeof *a);
	if (!a)
		return NULL;
	a->env = env;
	a->ops = *ops;
	a->wait_start = NAN;
	if (!(a->rs = rsel_new(env))) {
		free(a);
		return NULL;
	}
	return a;
}

void adapt_free(struct adapt *a)
{
	if (!a)
		return;
	rsel_free(a->rs);
	if (a->ahead_ready)
		json_decref(a->ahead.out);
	free(a->done);
	free(a->plan_text);
	free(a);
}

void adapt_end(struct adapt *a)
{
	if (!a)
		return;
	if (rsel_busy(a->rs)) { /* its callback must not find a sweep: a fresh decision maker, the old one leaks to
				 * nothing (the child is job_finish()'s, its callback is the old maker's) */
		log_msg(LOG_NOTICE, "sweep %lld: the batch decision under way is abandoned", (long long)a->id);
	}
	a->id = 0;
	a->deciding = 0;
	if (a->ahead_ready)
		json_decref(a->ahead.out);
	a->ahead_ready = false;
	a->spec = NULL;
	free(a->plan_text);
	a->plan_text = NULL;
	a->plan = NULL;
	a->batch = 0;
	a->spent_s = a->waited_s = 0;
	a->wait_start = NAN;
	a->model[0] = '\0';
	a->ntrend = 0;
}

static const char *relpath(const struct adapt *a, const char *path)
{
	size_t n = strlen(a->env->conf->d.state_dir);
	if (!strncmp(path, a->env->conf->d.state_dir, n) && path[n] == '/')
		return path + n + 1;
	return path;
}

static void target_spec(const struct adapt *a, char *buf, size_t len)
{
	plan_adaptive_target_spec(a->spec->adaptive, buf, len);
}

/* The bench seconds the sweep's measurement took so far (store_adaptive_measured × the simulator's time scale), or
 * NaN with err. */
static double measured_raw(const struct adapt *a, struct acq_err *err)
{
	double wall;
	return store_adaptive_measured(a->env->store, a->id, &wall, NULL, err) ? NAN : wall * loop_rate(a->env->loop);
}

/* The "sweep.adaptive" event for watchers (and the log). */
static void emit_state(struct adapt *a, double value, int met, double waited, const char *stop)
{
	const struct plan_adaptive *ad = a->spec->adaptive;
	char spec[256];
	target_spec(a, spec, sizeof spec);
	json_t *trend = json_array();
	for (int i = 0; i < a->ntrend; i++)
		json_array_append_new(trend, json_real(a->trend[i]));
	json_t *d = json_pack("{s:I,s:i,s:s,s:f,s:o,s:I,s:f,s:f}", "sweep", (json_int_t)a->id, "batch", a->batch,
			      "target", spec, "threshold", plan_adaptive_threshold(ad), "trend", trend, "points",
			      (json_int_t)a->plan->n_steps,
			      "predicted_s", a->spent_s, "waited_total_s", a->waited_s);
	if (!d)
		return;
	struct acq_err err = { 0 };
	double m = measured_raw(a, &err);
	json_object_set_new(d, "spent_s", isfinite(m) ? json_real(m) : json_null()); /* measured bench seconds */
	json_object_set_new(d, "value", isfinite(value) ? json_real(value) : json_null());
	json_object_set_new(d, "met", met < 0 ? json_null() : json_boolean(met));
	json_object_set_new(d, "waited_s", isfinite(waited) ? json_real(waited) : json_null());
	json_object_set_new(d, "budget_s", ad->budget_s > 0 ? json_real(ad->budget_s) : json_null());
	json_object_set_new(d, "budget_points", ad->budget_points ? json_integer((json_int_t)ad->budget_points) : json_null());
	json_object_set_new(d, "stop", stop ? json_string(stop) : json_null());
	if (a->env->emit)
		a->env->emit(a->env->emit_ctx, "sweep.adaptive", d);
	else
		json_decref(d);
}

static void pause_for(struct adapt *a, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void pause_for(struct adapt *a, const char *fmt, ...)
{
	char why[1200];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(why, sizeof why, fmt, ap);
	va_end(ap);
	log_msg(LOG_WARNING, "sweep %lld: %s", (long long)a->id, why);
	a->wait_start = NAN; /* a pause is the operator's time, not the arms' wait */
	a->ops.pause(a->ops.ctx, why);
}

/* Record the stop and complete the sweep. */
static void stop(struct adapt *a, double value, int met, const char *fmt, ...) __attribute__((format(printf, 4, 5)));
static void stop(struct adapt *a, double value, int met, const char *fmt, ...)
{
	char why[1024], spec[256];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(why, sizeof why, fmt, ap);
	va_end(ap);
	target_spec(a, spec, sizeof spec);
	double waited = isfinite(a->wait_start) ? loop_now(a->env->loop) - a->wait_start : NAN;
	struct store_batch b = {
		.batch = a->batch + 1, .decided_at = a->env->wallclock(), .first_order_index = (int)a->plan->n_steps,
		.n_points = 0, .target_spec = spec, .target_value = value, .target_met = met, .predicted_value = NAN,
		.model = a->model[0] ? relpath(a, a->model) : NULL, .warm = -1, .candidates = -1, .predicted_s = 0,
		.waited_s = waited, .stop_reason = why,
	};
	struct acq_err err = { 0 };
	if (store_adaptive_batch(a->env->store, a->id, &b, NULL, 0, NULL, 0, &err))
		return pause_for(a, "recording why the adaptive sweep stops (%s) failed: %s; resume to try again", why,
				 err.msg);
	if (isfinite(waited))
		a->waited_s += waited;
	a->wait_start = NAN;
	char msg[1400];
	struct acq_err merr = { 0 };
	snprintf(msg, sizeof msg, "adaptive sweep stopped after %d batches, %zu points, %.0f s of %s bench time "
		 "measured (%.0f s predicted; the arms waited %.1f s for decisions): %s", a->batch, a->plan->n_steps,
		 measured_raw(a, &merr), a->spec->adaptive->budget_s > 0 ? "the budgeted" : "unbudgeted", a->spent_s,
		 a->waited_s, why);
	emit_state(a, value, met, waited, why);
	a->ops.finish(a->ops.ctx, msg);
}

static double num_or(json_t *o, const char *k, double dflt)
{
	json_t *v = json_object_get(o, k);
	return json_is_number(v) ? json_number_value(v) : dflt;
}

static void decided(void *ctx, const struct rsel_res *r);
static void apply(struct adapt *a, const struct rsel_res *r);

/* The arms read within this of the last planned point on every axis (degrees) are at it: the positioning noise and
 * backlash (0.005 + 0.02° on the simulated bench) must not make the next batch's candidates at the same incidence
 * look like a new one (the executor compares planned positions: same laser position, no new darks). Read from the
 * devices, the costs were up to 9.2 % above the offline study's, which starts from the planned point (issue 17,
 * session 9): a laser read 0.01° off (batches 1, 2 and 8 of the validation sweep) charged every same-incidence
 * candidate a dark and the laser's settling. */
#define ARMS_AT_PLANNED_DEG 0.1

/* Where the arms are (the last planned point when the devices do not say, or say they are there). */
static struct plan_pos arms_now(const struct adapt *a)
{
	double pos[3] = { NAN, NAN, NAN };
	struct plan_pos last = a->plan->n_steps ? a->plan->steps[a->plan->n_steps - 1].pos : (struct plan_pos){ 0, 0, 0 };
	if (a->env->devices)
		devices_positions(a->env->devices, pos);
	if (isnan(pos[0]) || isnan(pos[1]) || isnan(pos[2]))
		return last;
	if (a->plan->n_steps && fabs(pos[0] - last.laser_theta) <= ARMS_AT_PLANNED_DEG &&
	    fabs(pos[1] - last.det_theta) <= ARMS_AT_PLANNED_DEG && fabs(pos[2] - last.det_phi) <= ARMS_AT_PLANNED_DEG)
		return last;
	return (struct plan_pos){ pos[0], pos[1], pos[2] };
}

/* measured_raw, or -1 after pausing the sweep if the store cannot say. */
static double measured_s(struct adapt *a)
{
	struct acq_err err = { 0 };
	double m = measured_raw(a, &err);
	if (isnan(m)) {
		pause_for(a, "the budget: %s; resume to try again", err.msg);
		return -1;
	}
	return m;
}

/* The budget is spent, counting the bench seconds measured so far plus ahead_s predicted for a batch still being
 * measured: why into buf (true), else false; *meas (may be NULL): the measured seconds (-1: the store failed and
 * the sweep is paused: true). */
static bool budget_spent(struct adapt *a, double ahead_s, char *buf, size_t len, double *meas)
{
	const struct plan_adaptive *ad = a->spec->adaptive;
	double m = ad->budget_s > 0 ? measured_s(a) : 0;
	if (meas)
		*meas = m;
	if (m < 0)
		return snprintf(buf, len, "the budget could not be read"), true;
	if (ad->budget_points && a->plan->n_steps >= ad->budget_points)
		return snprintf(buf, len, "budget spent: %zu of %zu points measured", a->plan->n_steps, ad->budget_points), true;
	if (ad->budget_s > 0 && m + ahead_s >= ad->budget_s)
		return snprintf(buf, len, "budget spent: %.1f of %.0f bench seconds measured", m, ad->budget_s), true;
	return false;
}

/* Start choosing the next batch: from the arms (ahead: from the last planned point, where the arms will be when
 * the batch being measured ends). 0, or -1 after pausing the sweep with the reason. */
static int start_decision(struct adapt *a, bool ahead)
{
	struct plan_pos *d = realloc(a->done, (a->plan->n_steps + 1) * sizeof *d);
	if (!d)
		return pause_for(a, "choosing batch %d: out of memory; resume to try again", a->batch + 1), -1;
	a->done = d;
	for (size_t i = 0; i < a->plan->n_steps; i++)
		d[i] = a->plan->steps[i].pos;
	a->arms = ahead && a->plan->n_steps ? a->plan->steps[a->plan->n_steps - 1].pos : arms_now(a);
	struct rsel_req q = {
		.sweep_id = a->id, .batch = a->batch + 1, .spec = a->spec, .plan_text = a->plan_text, .from = a->arms, .done = d,
		.n_done = a->plan->n_steps, .prev_model = a->model, .batch_size = a->spec->adaptive->batch,
	};
	a->ops.timing(a->ops.ctx, &q.timing);
	struct acq_err err = { 0 };
	if (rsel_start(a->rs, &q, decided, a, &err))
		return pause_for(a, "choosing batch %d: %s; resume to try again", a->batch + 1, err.msg), -1;
	a->deciding = a->id;
	log_msg(LOG_NOTICE, "sweep %lld: choosing batch %d (fit, then brdf-recon select)%s", (long long)a->id,
		a->batch + 1, ahead ? ", overlapping the measurement of the batch before it" : "");
	return 0;
}

void adapt_waiting(struct adapt *a, double now)
{
	if (!a->id)
		return;
	if (!isfinite(a->wait_start))
		a->wait_start = now;
	if (a->ahead_ready) { /* chosen while the arms were measuring: at once */
		struct rsel_res r = a->ahead;
		a->ahead_ready = false;
		apply(a, &r);
		json_decref(r.out);
		return;
	}
	if (rsel_busy(a->rs)) /* under way (overlap): applied when it comes */
		return;
	char why[256];
	double m;
	if (budget_spent(a, 0, why, sizeof why, &m)) {
		if (m >= 0)
			stop(a, a->ntrend ? a->trend[a->ntrend - 1] : NAN, -1, "%s", why);
		return;
	}
	start_decision(a, false);
}

/* The picks that fit the budget (the bench seconds measured so far, measured, plus the batch's predicted time, its
 * worst case), planned from the arms' position into *out; their count (0: none fits, *need = the bench seconds
 * select's first pick alone would take: its cost, or its planned time). */
static size_t plan_batch(struct adapt *a, json_t *picks, const struct plan_pos *pos, size_t n, double measured,
			 size_t *keep, struct plan_result **out, double *need, struct acq_err *err)
{
	const struct plan_adaptive *ad = a->spec->adaptive;
	const struct bench_geom *g = &a->env->conf->bench;
	double left_s = ad->budget_s > 0 ? ad->budget_s - measured : INFINITY;
	size_t left_pts = ad->budget_points ? ad->budget_points - a->plan->n_steps : n;
	double *cost = malloc((n ? n : 1) * sizeof *cost);
	struct plan_pos *kp = malloc((n ? n : 1) * sizeof *kp);
	*out = NULL;
	*need = INFINITY;
	if (!cost || !kp) {
		free(cost);
		free(kp);
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		return 0;
	}
	for (size_t i = 0; i < n; i++) {
		cost[i] = num_or(json_array_get(picks, i), "cost_s", 0);
		*need = fmin(*need, cost[i]);
	}
	/* select's picks in order, a dearer one skipped while a cheaper later one fits what is left */
	size_t k = plan_adaptive_fit_picks(cost, n, left_s, left_pts, keep);
	for (size_t i = 0; i < k; i++)
		kp[i] = pos[keep[i]];
	struct plan_timing tm;
	a->ops.timing(a->ops.ctx, &tm);
	tm.reference = false;
	tm.have_start = false; /* the batch's first step moves from the arms' position itself */
	if (a->plan->n_steps) /* the dark cache as the sweep's points left it (kept at the same incidence) */
		plan_timing_continue(&tm, &a->plan->steps[0].pos, a->plan->n_steps, sizeof *a->plan->steps);
	for (; k > 0; k--) {
		if (plan_make_points(a->spec, g, kp, k, &a->arms, out, err)) {
			k = 0;
			break;
		}
		plan_time_apply(a->spec, g, &tm, *out);
		if ((*out)->predicted_s <= left_s || !isfinite(left_s))
			break;
		if (k == 1)
			*need = (*out)->predicted_s;
		plan_result_free(*out);
		*out = NULL;
	}
	free(cost);
	free(kp);
	return k;
}

static void decided(void *ctx, const struct rsel_res *r)
{
	struct adapt *a = ctx;
	if (!a->id || a->deciding != a->id) { /* for a sweep no longer loaded: a waiting one asks again */
		a->deciding = 0;
		if (a->id && isfinite(a->wait_start))
			adapt_waiting(a, loop_now(a->env->loop));
		return;
	}
	a->deciding = 0;
	if (!isfinite(a->wait_start)) { /* overlap: the arms are still measuring; applied when they wait */
		a->ahead = *r;
		json_incref(a->ahead.out);
		a->ahead_ready = true;
		return;
	}
	apply(a, r);
}

/* Record and start the batch decision r chose (or stop, or pause with why it failed). */
static void apply(struct adapt *a, const struct rsel_res *r)
{
	int next = a->batch + 1;
	a->arms = arms_now(a);
	if (!r->ok)
		return pause_for(a, "choosing batch %d: %s; resume to try again", next, r->msg);
	json_t *t = json_object_get(r->out, "target"), *picks = json_object_get(r->out, "picks");
	double value = num_or(t, "value", NAN);
	int met = json_is_boolean(json_object_get(t, "met")) ? json_is_true(json_object_get(t, "met"))
							     : value <= plan_adaptive_threshold(a->spec->adaptive);
	snprintf(a->model, sizeof a->model, "%s", r->model);
	if (a->ntrend < ADAPT_TREND)
		a->trend[a->ntrend++] = value;
	char spec[256];
	target_spec(a, spec, sizeof spec);
	if (met)
		return stop(a, value, 1, "target met: %s value %.6g <= %.6g with %zu points", spec, value,
			    plan_adaptive_threshold(a->spec->adaptive), a->plan->n_steps);
	if (r->n_candidates == 0)
		return stop(a, value, 0, "nothing reachable left: no visible, reachable candidate is unmeasured (%s value "
			    "%.6g)", spec, value);
	size_t n = json_array_size(picks);
	if (n == 0)
		return stop(a, value, 0, "nothing reachable left worth measuring: select picked none of %zu candidates "
			    "(%s value %.6g)", r->n_candidates, spec, value);
	struct plan_pos *pos = calloc(n, sizeof *pos);
	struct store_pick *sp = calloc(n, sizeof *sp);
	struct store_point_new *pts = calloc(n, sizeof *pts);
	size_t *keep = calloc(n, sizeof *keep);
	struct plan_result *b = NULL;
	struct acq_err err = { 0 };
	if (!pos || !sp || !pts || !keep) {
		pause_for(a, "choosing batch %d: out of memory; resume to try again", next);
		goto out;
	}
	for (size_t i = 0; i < n; i++) {
		json_t *p = json_array_get(picks, i), *id = json_object_get(p, "id");
		if (!json_is_integer(id) || json_integer_value(id) < 0 ||
		    plan_adaptive_cand_pos(a->spec, &a->env->conf->bench, (size_t)json_integer_value(id), &pos[i])) {
			pause_for(a, "batch %d: select's pick %zu names no candidate of %s; resume to try again", next, i,
				  r->dir);
			goto out;
		}
		sp[i] = (struct store_pick){ .rank = (int)i, .candidate_id = json_integer_value(id), .order_index = -1,
					     .laser_theta = pos[i].laser_theta, .detector_theta = pos[i].det_theta,
					     .detector_phi = pos[i].det_phi, .gain = num_or(p, "gain", NAN),
					     .cost_s = num_or(p, "cost_s", NAN),
					     .predicted_value_after = num_or(p, "predicted_value_after", NAN) };
	}
	double measured = a->spec->adaptive->budget_s > 0 ? measured_s(a) : 0;
	if (measured < 0)
		goto out;
	double need = 0;
	size_t k = plan_batch(a, picks, pos, n, measured, keep, &b, &need, &err);
	if (k == 0 && err.code) {
		pause_for(a, "planning batch %d: %s; resume to try again", next, err.msg);
		goto out;
	}
	if (k == 0 || !b || b->n_steps == 0) {
		if (k == 0 && a->spec->adaptive->budget_s > 0 && !(a->spec->adaptive->budget_points &&
								    a->plan->n_steps >= a->spec->adaptive->budget_points))
			stop(a, value, 0, "budget spent: %.1f of %.0f bench seconds measured, not one more pick fits what is "
			     "left (the cheapest of select's %zu picks needs %.1f s; %s value %.6g)", measured,
			     a->spec->adaptive->budget_s, n, need, spec, value);
		else
			stop(a, value, 0, "%s (%s value %.6g)", k == 0 ? "budget spent: not one more pick fits what is left of "
			     "it" : "nothing reachable left: the planner found no safe path to the picks", spec, value);
		goto out;
	}
	size_t first = a->plan->n_steps;
	for (size_t s = 0; s < b->n_steps; s++) {
		size_t pick = keep[b->steps[s].req];
		pts[s].order_index = (int)(first + s);
		ex_pos_angles(&a->env->conf->bench, &b->steps[s].pos, &pts[s].theta_i, &pts[s].phi_i, &pts[s].theta_o,
			      &pts[s].phi_o);
		sp[pick].order_index = (int)(first + s);
		sp[pick].laser_theta = b->steps[s].pos.laser_theta;
		sp[pick].detector_theta = b->steps[s].pos.det_theta;
		sp[pick].detector_phi = b->steps[s].pos.det_phi;
	}
	double now = loop_now(a->env->loop);
	double waited = isfinite(a->wait_start) ? now - a->wait_start : NAN;
	json_t *last = json_array_get(picks, keep[k - 1]);
	struct store_batch rec = {
		.batch = next, .decided_at = a->env->wallclock(), .first_order_index = (int)first,
		.n_points = (int)b->n_steps, .target_spec = spec, .target_value = value, .target_met = 0,
		.predicted_value = num_or(last, "predicted_value_after", NAN), .model = relpath(a, r->model),
		.criterion = json_string_value(json_object_get(r->out, "criterion")), .warm = r->warm,
		.candidates = (int)r->n_candidates, .predicted_s = b->predicted_s, .waited_s = waited,
	};
	if (store_adaptive_batch(a->env->store, a->id, &rec, sp, (int)n, pts, (int)b->n_steps, &err)) {
		pause_for(a, "recording batch %d failed: %s; resume to try again", next, err.msg);
		goto out;
	}
	if (plan_result_append(a->plan, b, &err)) { /* recorded: a restart resumes it; this daemon cannot go on */
		pause_for(a, "batch %d: %s; restart the daemon to resume", next, err.msg);
		goto out;
	}
	a->batch = next;
	a->spent_s += b->predicted_s;
	if (isfinite(waited))
		a->waited_s += waited;
	a->wait_start = NAN;
	log_msg(LOG_NOTICE, "sweep %lld: batch %d: %zu points (%zu picked of %zu candidates), %s value %.6g, predicted "
		"%.1f s; the arms waited %.1f s (fit %.1f s%s, select %.1f s)", (long long)a->id, next, b->n_steps, n,
		r->n_candidates, spec, value, b->predicted_s, isfinite(waited) ? waited : 0, r->fit_s,
		r->warm ? ", warm" : "", r->select_s);
	emit_state(a, value, 0, waited, NULL);
	a->ops.extend(a->ops.ctx);
	char why[256];
	if (a->id && a->spec->adaptive->overlap && !budget_spent(a, b->predicted_s, why, sizeof why, NULL))
		start_decision(a, true); /* the next batch is chosen while this one is measured */
out:
	plan_result_free(b);
	free(pos);
	free(sp);
	free(pts);
	free(keep);
}

/* Keep a copy of the plan's text for the decisions' candidates children. 0 or -1 with err. */
static int keep_text(struct adapt *a, const char *plan_text, struct acq_err *err)
{
	if (!plan_text)
		return acq_errf(err, ACQ_E_INVAL, "an adaptive sweep without its plan text");
	if (!(a->plan_text = strdup(plan_text)))
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	return 0;
}

int adapt_begin(struct adapt *a, int64_t id, const struct plan_spec *spec, const char *plan_text,
		struct plan_result *plan, struct acq_err *err)
{
	adapt_end(a);
	if (keep_text(a, plan_text, err))
		return -1;
	char tspec[256];
	plan_adaptive_target_spec(spec->adaptive, tspec, sizeof tspec);
	struct store_batch b = {
		.batch = 0, .decided_at = a->env->wallclock(), .first_order_index = 0, .n_points = (int)plan->n_steps,
		.target_spec = tspec, .target_value = NAN, .target_met = -1, .predicted_value = NAN, .warm = -1,
		.candidates = -1, .predicted_s = plan->predicted_s, .waited_s = NAN,
	};
	if (store_adaptive_batch(a->env->store, id, &b, NULL, 0, NULL, 0, err))
		return -1;
	a->id = id;
	a->spec = spec;
	a->plan = plan;
	a->spent_s = plan->predicted_s;
	return 0;
}

int adapt_resume(struct adapt *a, int64_t id, const struct plan_spec *spec, const char *plan_text,
		 struct plan_result *plan, char *stopr, size_t stop_len, struct acq_err *err)
{
	adapt_end(a);
	stopr[0] = '\0';
	if (keep_text(a, plan_text, err))
		return -1;
	json_t *rows = store_adaptive_show(a->env->store, id, err);
	if (!rows)
		return -1;
	int rc = -1;
	struct plan_pos *pts = NULL;
	struct plan_timing tm;
	a->ops.timing(a->ops.ctx, &tm);
	tm.reference = false;
	tm.have_start = false;
	a->spent_s = plan->predicted_s;
	size_t i;
	json_t *row;
	bool have_seed = false;
	json_array_foreach(rows, i, row) {
		int batch = (int)json_integer_value(json_object_get(row, "batch"));
		json_t *sr = json_object_get(row, "stop_reason"), *tv = json_object_get(row, "target_value");
		if (batch == 0) {
			have_seed = true;
			if (json_integer_value(json_object_get(row, "n_points")) != (json_int_t)plan->n_steps) {
				acq_errf(err, ACQ_E_STATE, "sweep %lld: its seed plan now gives %zu points, %lld were recorded",
					 (long long)id, plan->n_steps, (long long)json_integer_value(json_object_get(row, "n_points")));
				goto out;
			}
			continue;
		}
		if (json_is_number(tv) && a->ntrend < ADAPT_TREND)
			a->trend[a->ntrend++] = json_number_value(tv);
		const char *model = json_string_value(json_object_get(row, "model"));
		if (model)
			snprintf(a->model, sizeof a->model, "%s%s%s", model[0] == '/' ? "" : a->env->conf->d.state_dir,
				 model[0] == '/' ? "" : "/", model);
		a->waited_s += json_is_number(json_object_get(row, "waited_s"))
				       ? json_number_value(json_object_get(row, "waited_s")) : 0;
		a->batch = batch;
		if (json_is_string(sr)) {
			snprintf(stopr, stop_len, "%s", json_string_value(sr));
			continue;
		}
		json_int_t first = json_integer_value(json_object_get(row, "first_order_index"));
		if (first != (json_int_t)plan->n_steps) {
			acq_errf(err, ACQ_E_STATE, "sweep %lld: batch %d starts at point %lld, the plan has %zu before it",
				 (long long)id, batch, (long long)first, plan->n_steps);
			goto out;
		}
		/* the batch's points in their recorded order, each at its recorded arm angles */
		json_t *picks = json_object_get(row, "picks"), *p;
		size_t np = (size_t)json_integer_value(json_object_get(row, "n_points")), j;
		free(pts);
		if (!(pts = calloc(np ? np : 1, sizeof *pts))) {
			acq_errf(err, ACQ_E_NOMEM, "out of memory");
			goto out;
		}
		size_t got = 0;
		json_array_foreach(picks, j, p) {
			json_t *oi = json_object_get(p, "order_index");
			if (!json_is_integer(oi))
				continue;
			json_int_t k = json_integer_value(oi) - first;
			if (k < 0 || (size_t)k >= np) {
				acq_errf(err, ACQ_E_STATE, "sweep %lld: batch %d: a pick at point %lld outside the batch",
					 (long long)id, batch, (long long)json_integer_value(oi));
				goto out;
			}
			pts[k] = (struct plan_pos){ num_or(p, "laser_theta", NAN), num_or(p, "detector_theta", NAN),
						    num_or(p, "detector_phi", NAN) };
			got++;
		}
		if (got != np) {
			acq_errf(err, ACQ_E_STATE, "sweep %lld: batch %d records %zu points and %zu picks measuring them",
				 (long long)id, batch, np, got);
			goto out;
		}
		struct plan_result *b = NULL;
		const struct plan_pos *from = plan->n_steps ? &plan->steps[plan->n_steps - 1].pos : NULL;
		if (plan_make_fixed(spec, &a->env->conf->bench, pts, np, from, &b, err))
			goto out;
		plan_time_apply(spec, &a->env->conf->bench, &tm, b);
		int arc = plan_result_append(plan, b, err);
		a->spent_s += json_is_number(json_object_get(row, "predicted_s"))
				      ? json_number_value(json_object_get(row, "predicted_s")) : b->predicted_s;
		plan_result_free(b);
		if (arc)
			goto out;
	}
	a->id = id;
	a->spec = spec;
	a->plan = plan;
	if (!have_seed) { /* the daemon died between creating the sweep and recording its seed */
		char tspec[256];
		plan_adaptive_target_spec(spec->adaptive, tspec, sizeof tspec);
		struct store_batch b = {
			.batch = 0, .decided_at = a->env->wallclock(), .n_points = (int)plan->n_steps, .target_spec = tspec,
			.target_value = NAN, .target_met = -1, .predicted_value = NAN, .warm = -1, .candidates = -1,
			.predicted_s = plan->predicted_s, .waited_s = NAN,
		};
		if (store_adaptive_batch(a->env->store, id, &b, NULL, 0, NULL, 0, err)) {
			a->id = 0;
			goto out;
		}
	}
	rc = 0;
out:
	free(pts);
	json_decref(rows);
	if (rc)
		adapt_end(a);
	return rc;
}
