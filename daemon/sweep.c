/* sweep: the daemon's sweep executor behind sweep.h — plans, stores and runs a sweep with daemon/executor.c
 * on the loop over the device handles, resumes interrupted sweeps, and on completion starts the
 * reconstruction chain (recon_chain.c). */
#include "daemon/sweep.h"

#include <math.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/devices.h"
#include "daemon/eta.h"
#include "daemon/executor.h"
#include "daemon/exposure.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/plan/plan.h"
#include "daemon/recon_chain.h"
#include "daemon/store.h"
#include "daemon/sweep_adaptive.h"
#include "daemon/sweep_retime.h"

struct sweep {
	struct sweep_env env;
	struct ex_cfg cfg;
	struct ex *ex;
	struct plan_spec *spec;
	struct plan_result *plan;
	int64_t id;
	uint64_t timer;
	double started_wall;
	struct sweep_progress last;  /* kept after the executor is gone */
	struct eta eta;              /* wall-clock ETA (eta.c), fed by the events and the progress below */
	struct sweep_retime retime;  /* a first auto sweep re-times its plan at each incidence (sweep_retime.h) */
	struct exp_host_cache host;  /* the host's time per point by plan kind, until a sweep completes (exposure.h) */
	char point_text[128];
	/* completion: export + reconstruction chain (recon_chain.c) */
	int64_t done_id;
	uint64_t done_timer;
	struct recon_chain *chain;
	struct adapt *adapt;         /* kind: adaptive: the batches after the seed (sweep_adaptive.c) */
	bool unrecorded_logged;      /* the end of the sweep awaits being recorded (logged once) */
	bool planning;               /* sweep_set_planning(): a plan for sweep_start_planned() is being made */
};

/* ---- events --------------------------------------------------------------------------------------- */

static enum sweep_state map_state(enum ex_state s)
{
	switch (s) {
	case EX_RUNNING:
	case EX_WAITING: return SWEEP_RUNNING; /* between batches: the next is being chosen */
	case EX_PAUSED: return SWEEP_PAUSED;
	case EX_SUSPENDED: return SWEEP_FAULTED;
	default: return SWEEP_IDLE;
	}
}

static void emit(struct sweep *sw, const char *name, json_t *data)
{
	if (sw->env.emit)
		sw->env.emit(sw->env.emit_ctx, name, data);
	else
		json_decref(data);
}

static void on_event(void *ctx, int64_t sweep_id, const char *kind, const char *device, const char *message)
{
	struct sweep *sw = ctx;
	bool bad = !strcmp(kind, "fault") || !strcmp(kind, "failed") || !strcmp(kind, "abort");
	log_msg(bad ? LOG_WARNING : LOG_NOTICE, "sweep %lld: %s%s%s: %s", (long long)sweep_id, kind,
		device ? " " : "", device ? device : "", message);
	if (!strcmp(kind, "fault")) {
		emit(sw, "sweep.fault", json_pack("{s:I,s:s,s:s}", "sweep", (json_int_t)sweep_id, "device",
						  device ? device : "", "message", message));
		return;
	}
	/* The ETA counts running time only. */
	bool run = !strcmp(kind, "start") || !strcmp(kind, "resume") || !strcmp(kind, "recovered");
	if (!strcmp(kind, "start")) {
		eta_reset(&sw->eta);
		/* until its first point, not the previous sweep's last ETA (on_progress writes these) */
		sw->last.eta_s = sw->last.eta_low_s = sw->last.eta_high_s = NAN;
	}
	if (run || !strcmp(kind, "pause") || !strcmp(kind, "abort") || !strcmp(kind, "failed") ||
	    !strcmp(kind, "complete"))
		eta_running(&sw->eta, run, loop_now(sw->env.loop), loop_monotonic(NULL));
	const char *state = !sw->ex ? "idle" : ex_stopping(sw->ex) ? "stopping" : ex_state_name(ex_state(sw->ex));
	emit(sw, "sweep.state", json_pack("{s:I,s:s,s:s,s:s}", "sweep", (json_int_t)sweep_id, "state", state, "kind",
					  kind, "reason", message));
}

/* The bench's own seconds of the first `done` points (eta_work): the shots the executor took, as the planner
 * prices them, and the plan's moves and settling of those steps. NAN without an executor or a plan. */
static double bench_work(const struct sweep *sw, int done)
{
	if (!sw->ex || !sw->plan || done < 0)
		return NAN;
	double s = ex_stats(sw->ex)->shots_s;
	for (size_t i = 0; i < (size_t)done && i < sw->plan->n_steps; i++)
		s += sw->plan->steps[i].move_s + sw->plan->steps[i].settle_s;
	return s;
}

static void retime_bounds(struct sweep *sw);

static void on_progress(void *ctx, int64_t sweep_id, int done, int total, double eta, const char *phase)
{
	struct sweep *sw = ctx;
	/* eta (the executor's, loop seconds) is replaced by the wall-clock estimate: the planner's remaining time
	 * refined by the measured rate (eta.c). */
	(void)eta;
	if (sw->env.store && sweep_retime_due(&sw->retime, sw->plan, done)) {
		struct acq_err err = { 0 };
		bool survey_end = sw->retime.survey > 0 && (size_t)done == sw->retime.survey;
		if (survey_end) /* the host's mean time as the ETA measured it over the survey's points (their work as taken) */
			sw->retime.host_hint = eta_host(&sw->eta);
		int rc = sweep_retime_apply(&sw->retime, done, sw->env.store, sweep_id, sw->spec, &sw->env.conf->bench,
					    sw->plan, &err);
		if (rc < 0)
			log_msg(LOG_WARNING, "sweep %lld: re-timing the plan: %s", (long long)sweep_id, err.msg);
		else if (rc > 0) {
			/* the survey's points (long moves, probes at another point's time) say nothing of the route's
			 * excess: the ETA is the re-timed plan's until the route's points are measured */
			if (survey_end)
				eta_forget(&sw->eta);
			else
				eta_replan(&sw->eta, sweep_retime_plan_at, sw->plan);
			retime_bounds(sw);
			log_msg(LOG_DEBUG, "sweep %lld: plan re-timed at point %d from its own exposures: %.1f s",
				(long long)sweep_id, done, sw->plan->predicted_s);
		}
	}
	double plan_at = NAN, plan_total = NAN;
	if (sw->plan && done >= 0) {
		plan_total = sw->plan->predicted_s;
		plan_at = (size_t)done < sw->plan->n_steps ? sw->plan->steps[done].predicted_start_s : plan_total;
	}
	eta_work(&sw->eta, bench_work(sw, done));
	eta = eta_update(&sw->eta, done, total, plan_at, plan_total, loop_now(sw->env.loop), loop_monotonic(NULL));
	sw->last.eta_s = eta;
	/* where the exposures of the rest are unknown, the ETA's interval (sweep_retime_eta) */
	sweep_retime_eta(&sw->retime, sw->plan, done, eta, sw->eta.scale, &sw->last.eta_low_s, &sw->last.eta_high_s);
	json_t *d = json_pack("{s:I,s:s,s:i,s:i,s:s}", "sweep", (json_int_t)sweep_id, "state", "running", "done", done,
			      "total", total, "point", phase);
	if (d && isfinite(eta))
		json_object_set_new(d, "eta_s", json_real(eta));
	if (d && isfinite(sw->last.eta_low_s) && isfinite(sw->last.eta_high_s)) {
		json_object_set_new(d, "eta_low_s", json_real(sw->last.eta_low_s));
		json_object_set_new(d, "eta_high_s", json_real(sw->last.eta_high_s));
	}
	emit(sw, "sweep.progress", d);
}

/* The sweep completed (timer, so it runs outside the executor's step). */
static void on_completed(struct loop *lp, void *arg)
{
	(void)lp;
	struct sweep *sw = arg;
	sw->done_timer = 0;
	struct acq_err err = { 0 };
	if (recon_chain_run(sw->chain, sw->done_id, true, NULL, &err) && err.code != ACQ_E_UNSUPPORTED)
		log_msg(LOG_WARNING, "sweep %lld: completion: %s", (long long)sw->done_id, err.msg);
}

int sweep_recon_start(struct sweep *sw, int64_t sweep_id, int64_t *run_id, struct acq_err *err)
{
	*run_id = 0;
	if (sw->ex)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld is %s: reconstruct when no sweep runs", (long long)sw->id,
				ex_state_name(ex_state(sw->ex)));
	if (recon_chain_busy(sw->chain))
		return acq_errf(err, ACQ_E_STATE, "a reconstruction is still running");
	json_t *js = store_sweep_show(sw->env.store, sweep_id, false, err);
	if (!js)
		return -1;
	json_decref(js);
	return recon_chain_run(sw->chain, sweep_id, false, run_id, err);
}

bool sweep_recon_busy(const struct sweep *sw)
{
	return recon_chain_busy(sw->chain);
}

/* ---- the executor on the loop --------------------------------------------------------------------- */

static void schedule(struct sweep *sw, double when);

static void release(struct sweep *sw)
{
	adapt_end(sw->adapt);
	sweep_retime_end(&sw->retime);
	ex_free(sw->ex, loop_now(sw->env.loop));
	sw->ex = NULL;
	plan_result_free(sw->plan);
	sw->plan = NULL;
	plan_spec_free(sw->spec);
	sw->spec = NULL;
}

static void snapshot(struct sweep *sw)
{
	struct sweep_progress *p = &sw->last;
	if (!sw->ex)
		return;
	const struct ex_stats *st = ex_stats(sw->ex);
	p->state = ex_stopping(sw->ex) ? SWEEP_STOPPING : map_state(ex_state(sw->ex));
	p->sweep_id = sw->id;
	p->points_done = st->points_done;
	p->points_total = st->points_total;
	p->started_at = sw->started_wall;
	p->pause_pending = ex_pause_pending(sw->ex);
	const char *r = ex_reason(sw->ex);
	snprintf(p->message, sizeof p->message, "%s%s%s", ex_phase(sw->ex), r[0] ? ": " : "", r);
}

static void tick(struct loop *lp, void *arg)
{
	struct sweep *sw = arg;
	sw->timer = 0;
	if (!sw->ex)
		return;
	double now = loop_now(lp);
	bool was_stopping = sw->last.state == SWEEP_STOPPING;
	double next = ex_step(sw->ex, now);
	snapshot(sw);
	enum ex_state s = ex_state(sw->ex);
	if (was_stopping && !ex_stopping(sw->ex))
		emit(sw, "sweep.state", json_pack("{s:I,s:s,s:s,s:s}", "sweep", (json_int_t)sw->id, "state", ex_state_name(s),
						  "kind", "laser-off", "reason", "the laser's emission off is confirmed"));
	if ((s == EX_COMPLETED || s == EX_ABORTED || s == EX_FAILED) && !ex_stopping(sw->ex)) {
		struct acq_err err = { 0 };
		if (ex_has_unrecorded(sw->ex) && ex_flush_unrecorded(sw->ex, &err)) {
			/* The database and the daemon must not disagree on how the sweep ended: the executor stays
			 * loaded (no new sweep) and the records are retried until the database takes them. */
			if (!sw->unrecorded_logged)
				log_msg(LOG_ERR, "sweep %lld %s, but the database refused to record it (%s): retrying every "
					"2 s; no new sweep until then", (long long)sw->id, ex_state_name(s), err.msg);
			sw->unrecorded_logged = true;
			sw->last.state = SWEEP_FAULTED;
			snprintf(sw->last.message, sizeof sw->last.message, "sweep %lld %s (%s); NOT recorded in the "
				 "database yet: %s; retrying", (long long)sw->id, ex_state_name(s), ex_reason(sw->ex), err.msg);
			schedule(sw, now + 2.0 * loop_rate(sw->env.loop)); /* 2 real seconds */
			return;
		}
		if (sw->unrecorded_logged)
			log_msg(LOG_NOTICE, "sweep %lld: its end (%s) is now recorded in the database", (long long)sw->id,
				ex_state_name(s));
		sw->unrecorded_logged = false;
		sw->last.state = SWEEP_IDLE;
		snprintf(sw->last.message, sizeof sw->last.message, "sweep %lld %s%s%s", (long long)sw->id,
			 ex_state_name(s), ex_reason(sw->ex)[0] ? ": " : "", ex_reason(sw->ex));
		if (s == EX_COMPLETED) {
			sw->done_id = sw->id;
			sw->done_timer = loop_timer_add(lp, 0, 0, on_completed, sw);
		}
		release(sw);
		return;
	}
	if (s == EX_WAITING) {
		adapt_waiting(sw->adapt, now); /* may complete or pause it at once: then step again */
		if (sw->ex && ex_state(sw->ex) != EX_WAITING)
			next = now;
	}
	schedule(sw, next);
}

static void schedule(struct sweep *sw, double when)
{
	if (sw->timer)
		loop_timer_cancel(sw->env.loop, sw->timer);
	sw->timer = 0;
	if (!sw->ex || !(when < INFINITY))
		return;
	double d = when - loop_now(sw->env.loop);
	sw->timer = loop_timer_add(sw->env.loop, d > 0 ? d : 0, 0, tick, sw);
}

static void kick(struct sweep *sw)
{
	schedule(sw, loop_now(sw->env.loop));
}

/* A device completion the executor waits for came in: step it now. */
static void on_device(void *ctx)
{
	struct sweep *sw = ctx;
	if (sw->ex)
		kick(sw);
}

/* A committed point the executor waits for is on disk (store_durable_fd): step it now. */
static void on_durable(struct loop *lp, int fd, short revents, void *arg)
{
	(void)lp;
	(void)fd;
	(void)revents;
	struct sweep *sw = arg;
	store_durable_drain(sw->env.store);
	if (sw->ex)
		kick(sw);
}

static int load_cfg(const struct conf *c, struct ex_cfg *cfg, struct acq_err *err)
{
	ex_cfg_defaults(cfg);
	cfg->pol.target_frac = c->sweep.target_peak;
	cfg->pol.min_ms = c->sweep.min_integration_ms;
	cfg->pol.max_ms = c->sweep.max_integration_ms;
	if (cfg->pol.probe_ms < cfg->pol.min_ms)
		cfg->pol.probe_ms = cfg->pol.min_ms;
	if (cfg->pol.probe_ms > cfg->pol.max_ms)
		cfg->pol.probe_ms = cfg->pol.max_ms;
	cfg->pol.averages = (unsigned)c->sweep.averages;
	cfg->extra_settle_s = c->sweep.extra_settle_s;
	cfg->dark_every = c->sweep.dark_every;
	cfg->auto_resume_faults = c->sweep.auto_resume_faults;
	if (ex_cfg_parse(c->sweep.acquisition, c->sweep.calibration, cfg, err))
		return -1;
	return exp_policy_check(&cfg->pol, err);
}

/* ---- the adaptive loop's requests (sweep_adaptive.h) ----------------------------------------------- */

static void adapt_extend(void *ctx)
{
	struct sweep *sw = ctx;
	struct acq_err err = { 0 };
	if (!sw->ex)
		return;
	if (ex_extend(sw->ex, sw->plan, loop_now(sw->env.loop), &err))
		log_msg(LOG_ERR, "sweep %lld: the next batch: %s", (long long)sw->id, err.msg);
	snapshot(sw);
	kick(sw);
}

static void adapt_finish(void *ctx, const char *why)
{
	struct sweep *sw = ctx;
	struct acq_err err = { 0 };
	if (!sw->ex)
		return;
	if (ex_finish(sw->ex, why, &err))
		log_msg(LOG_ERR, "sweep %lld: completing: %s", (long long)sw->id, err.msg);
	kick(sw); /* the tick sees it completed: recorded, released, the reconstruction chain */
}

static void adapt_pause(void *ctx, const char *why)
{
	struct sweep *sw = ctx;
	struct acq_err err = { 0 };
	if (!sw->ex)
		return;
	if (ex_pause(sw->ex, loop_now(sw->env.loop), &err))
		log_msg(LOG_ERR, "sweep %lld: pausing (%s): %s", (long long)sw->id, why, err.msg);
	else
		store_event(sw->env.store, sw->id, "info", NULL, why, sw->env.wallclock(), NULL);
	snapshot(sw);
	if (ex_state(sw->ex) == EX_PAUSED)
		snprintf(sw->last.message, sizeof sw->last.message, "paused: %s", why);
	kick(sw);
}

static void adapt_timing(void *ctx, struct plan_timing *t)
{
	sweep_plan_timing(ctx, t);
}

int sweep_init(const struct sweep_env *env, struct sweep **out, struct acq_err *err)
{
	struct sweep *sw = calloc(1, sizeof *sw);
	if (!sw)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	sw->env = *env;
	eta_reset(&sw->eta);
	if (load_cfg(env->conf, &sw->cfg, err)) {
		free(sw);
		return -1;
	}
	struct adapt_ops aops = { adapt_extend, adapt_finish, adapt_pause, adapt_timing, sw };
	if (!(sw->chain = recon_chain_new(&sw->env)) || !(sw->adapt = adapt_new(&sw->env, &aops))) {
		recon_chain_free(sw->chain);
		free(sw);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	if (env->devices)
		devices_set_kick(env->devices, on_device, sw);
	/* The points' fsyncs run on the store's thread; its completions step the executor (else it waits in its step). */
	int dfd = env->store ? store_durable_fd(env->store) : -1;
	if (dfd >= 0 && loop_fd_add(env->loop, dfd, POLLIN, on_durable, sw, NULL) == 0) {
		loop_fd_urgent(env->loop, dfd);
		sw->cfg.durable_async = true;
	}
	sw->last.eta_s = sw->last.eta_low_s = sw->last.eta_high_s = NAN;
	*out = sw;
	return 0;
}

void sweep_finish(struct sweep *sw)
{
	if (!sw)
		return;
	if (sw->timer)
		loop_timer_cancel(sw->env.loop, sw->timer);
	if (sw->done_timer)
		loop_timer_cancel(sw->env.loop, sw->done_timer);
	if (sw->ex)
		ex_shutdown(sw->ex, "daemon stopping");
	recon_chain_free(sw->chain);
	if (sw->env.devices)
		devices_set_kick(sw->env.devices, NULL, NULL);
	if (sw->cfg.durable_async)
		loop_fd_del(sw->env.loop, store_durable_fd(sw->env.store));
	release(sw);
	adapt_free(sw->adapt);
	free(sw);
}

void sweep_plan_timing(const struct sweep *sw, struct plan_timing *t)
{
	plan_timing_defaults(t);
	t->extra_settle_s = sw->cfg.extra_settle_s;
	t->probe_ms = sw->cfg.pol.probe_ms;
	t->min_ms = sw->cfg.pol.min_ms;
	t->ladder_ratio = sw->cfg.ladder_ratio;
	t->exposure_overhead_s = sw->cfg.poll_s / 2;
	t->dark_averages = (int)sw->cfg.pol.dark_averages;
	t->dark_every = sw->cfg.dark_every;
	t->dark_max_age_s = sw->cfg.pol.dark_max_age_s;
	t->max_exposures = sw->cfg.pol.max_exposures;
	t->hdr_ratio = sw->cfg.pol.hdr_ratio;
	t->reference = sw->cfg.take_reference;
	t->ref_pose = sw->cfg.ref_pose;
	if (sw->env.conf->have_sim && sw->env.conf->sim.time_scale > 0)
		t->time_scale = sw->env.conf->sim.time_scale;
	double pos[3] = { NAN, NAN, NAN };
	if (sw->env.devices)
		devices_positions(sw->env.devices, pos);
	if (!isnan(pos[0]) && !isnan(pos[1]) && !isnan(pos[2])) {
		t->have_start = true;
		t->start = (struct plan_pos){ pos[0], pos[1], pos[2] };
	}
}

void sweep_plan_prior(struct sweep *sw, const struct plan_spec *spec, int64_t exclude, struct plan_timing *t)
{
	if (spec)
		sweep_plan_prior_of(sw, spec->integ_mode == PLAN_INTEG_AUTO ? spec->sample : "", exclude, t);
	else
		sweep_plan_prior_of(sw, NULL, exclude, t);
}

void sweep_plan_prior_of(struct sweep *sw, const char *sample, int64_t exclude, struct plan_timing *t)
{
	memset(&t->prior, 0, sizeof t->prior);
	t->host_sweep = 0;
	t->n_host_kind = 0;
	if (!sample || !sw->env.store)
		return;
	struct acq_err err = { 0 };
	if (sample[0] && exp_prior_load(sw->env.store, sample, exclude, &sw->env.conf->bench, t, &t->prior, &err)) {
		log_msg(LOG_WARNING, "exposure prior of sample '%s': %s (timed from the plan's estimate)", sample, err.msg);
		memset(&t->prior, 0, sizeof t->prior);
	}
	/* without the sample's own host figure, the host's time per point as this host's latest sweep of the plan's
	 * kind (else of any kind) measured it; kept until a sweep completes */
	if (!(t->prior.sweep > 0 && t->prior.host_points > 0) &&
	    exp_host_cached(&sw->host, sw->env.store, exclude, &sw->env.conf->bench, t, &err))
		log_msg(LOG_WARNING, "the host's time per point from the latest sweep: %s (the default)", err.msg);
}

static int plan_cfg(struct sweep *sw, struct ex_cfg *cfg, struct acq_err *err);

/* The interval of the sweep's time where its exposures are unknown (sweep_retime_bounds), for the ETA's. */
static void retime_bounds(struct sweep *sw)
{
	struct acq_err err = { 0 };
	if (sweep_retime_bounds(&sw->retime, sw->spec, &sw->env.conf->bench, sw->plan, &err))
		log_msg(LOG_WARNING, "sweep %lld: %s (no interval for the ETA)", (long long)sw->id, err.msg);
}

/* Whether the sweep in sw re-times its plan as it goes (sweep_retime.h): the timing its plan was made with. */
static void retime_begin(struct sweep *sw)
{
	struct plan_timing tm;
	sweep_plan_timing(sw, &tm);
	sweep_plan_prior(sw, sw->spec, sw->id, &tm);
	sweep_retime_setup(&sw->retime, sw->spec, &tm);
	sweep_retime_survey(&sw->retime, sw->spec, sw->plan);
	retime_bounds(sw);
}

/* Plan the text against the bench; the spec's integration settings override the configuration's. */
static int make_plan(struct sweep *sw, const char *text, const char *name, struct ex_cfg *cfg, struct acq_err *err)
{
	if (!text)
		return acq_errf(err, ACQ_E_INVAL, "no plan text");
	if (plan_load_string(name && *name ? name : "plan", text, &sw->spec, err))
		return -1;
	if (plan_make(sw->spec, &sw->env.conf->bench, &sw->plan, err))
		return -1;
	struct plan_timing tm;
	sweep_plan_timing(sw, &tm);
	sweep_plan_prior(sw, sw->spec, sw->id, &tm);
	/* a first auto sweep measures its survey first (plan_survey_apply; as the planning child does) */
	if (plan_survey_apply(sw->spec, &sw->env.conf->bench, &tm, sw->plan, err))
		return -1;
	plan_time_apply(sw->spec, &sw->env.conf->bench, &tm, sw->plan); /* the ETA's plan figure */
	return plan_cfg(sw, cfg, err);
}

/* The executor's settings for the plan in sw: the configuration's, with the spec's integration settings. */
static int plan_cfg(struct sweep *sw, struct ex_cfg *cfg, struct acq_err *err)
{
	if (sw->plan->n_steps == 0)
		return acq_errf(err, ACQ_E_INVAL, "the plan has no visible point");
	*cfg = sw->cfg;
	cfg->hold_at_end = sw->spec->adaptive != NULL;
	if (sw->spec->averages > 0)
		cfg->pol.averages = (unsigned)sw->spec->averages;
	if (sw->spec->integ_mode == PLAN_INTEG_FIXED) {
		cfg->fixed_integration = true;
		cfg->fixed_ms = sw->spec->integ_ms;
	} else {
		if (sw->spec->target_peak > 0 && sw->spec->target_peak < cfg->pol.sat_frac)
			cfg->pol.target_frac = sw->spec->target_peak;
		if (sw->spec->max_integ_ms > 0 && sw->spec->max_integ_ms < cfg->pol.max_ms)
			cfg->pol.max_ms = fmax(sw->spec->max_integ_ms, cfg->pol.min_ms);
		if (sw->spec->integ_ms > 0)
			cfg->pol.probe_ms = fmin(fmax(sw->spec->integ_ms, cfg->pol.min_ms), cfg->pol.max_ms);
	}
	return exp_policy_check(&cfg->pol, err);
}

/* Provenance: the devices (arm controllers, laser) the sweep runs with, in sweep_devices. 0 or -1. */
static int record_devices(struct sweep *sw, int64_t id, struct acq_err *err)
{
	for (int d = 0; d < CONF_DEV__COUNT; d++) {
		int64_t dev = devices_device_id(sw->env.devices, (enum conf_dev)d);
		if (dev > 0 && store_sweep_device(sw->env.store, id, dev, err))
			return -1;
	}
	return 0;
}

static struct ex_sink sink_of(struct sweep *sw)
{
	return (struct ex_sink){ .event = on_event, .progress = on_progress, .ctx = sw };
}

int sweep_start_check(const struct sweep *sw, struct acq_err *err)
{
	if (sw->ex)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld is %s", (long long)sw->id, ex_state_name(ex_state(sw->ex)));
	if (sw->planning)
		return acq_errf(err, ACQ_E_STATE, "a sweep is being planned");
	char missing[256] = "";
	for (int d = 0; d < CONF_DEV__COUNT; d++) {
		if (!devices_up(sw->env.devices, (enum conf_dev)d))
			snprintf(missing + strlen(missing), sizeof missing - strlen(missing), "%s%s", missing[0] ? ", " : "",
				 conf_dev_name((enum conf_dev)d));
	}
	if (missing[0])
		return acq_errf(err, ACQ_E_DISCONNECTED, "cannot start a sweep: unavailable: %s", missing);
	return 0;
}

void sweep_set_planning(struct sweep *sw, bool planning)
{
	sw->planning = planning;
}

static int start_planned(struct sweep *sw, const char *plan_text, const char *name, int64_t *id,
			 struct acq_err *err);

int sweep_start_planned(struct sweep *sw, const char *plan_text, const char *name, struct plan_spec *spec,
			struct plan_result *plan, int64_t *id, struct acq_err *err)
{
	*id = 0;
	if (sweep_start_check(sw, err)) { /* the devices may have gone while it was planned */
		plan_spec_free(spec);
		plan_result_free(plan);
		return -1;
	}
	sw->spec = spec;
	sw->plan = plan;
	return start_planned(sw, plan_text, name, id, err);
}

/* A start from the plan in sw (sw->spec, sw->plan, released on failure). */
static int start_planned(struct sweep *sw, const char *plan_text, const char *name, int64_t *id,
			 struct acq_err *err)
{
	struct ex_cfg cfg;
	if (plan_cfg(sw, &cfg, err))
		goto fail;
	size_t n = sw->plan->n_steps;
	struct store_point_new *pts = calloc(n, sizeof *pts);
	if (!pts) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto fail;
	}
	for (size_t i = 0; i < n; i++) {
		pts[i].order_index = (int)i;
		ex_pos_angles(&sw->env.conf->bench, &sw->plan->steps[i].pos, &pts[i].theta_i, &pts[i].phi_i,
			      &pts[i].theta_o, &pts[i].phi_o);
	}
	char method[128];
	snprintf(method, sizeof method, "%s-v1", calib_method_name(cfg.cal.method));
	char kind[PLAN_KIND_MAX];
	struct store_sweep_new nw = {
		.name = name && *name ? name : sw->spec->name,
		.plan_text = plan_text,
		.config_snapshot = sw->env.conf->text ? sw->env.conf->text : "",
		.software_version = sw->env.software_version,
		.calibration_method = method,
		.spectrometer_id = devices_spectrometer_id(sw->env.devices),
		.created_at = sw->env.wallclock(),
		.sample = sw->spec->sample,
		.auto_exposure = sw->spec->integ_mode == PLAN_INTEG_AUTO,
		.plan_kind = plan_kind_of(sw->spec, kind),
	};
	int rc = store_sweep_create(sw->env.store, &nw, pts, (int)n, &sw->id, err);
	free(pts);
	if (rc || record_devices(sw, sw->id, err))
		goto fail;
	if (sw->spec->adaptive && adapt_begin(sw->adapt, sw->id, sw->spec, plan_text, sw->plan, err))
		goto fail;
	struct ex_sink sk = sink_of(sw);
	sw->ex = ex_new(&cfg, devices_ex_ops(), sw->env.devices, &sk, sw->env.store, sw->id, nw.spectrometer_id, &sw->env.conf->bench,
			sw->plan, err);
	if (!sw->ex)
		goto fail;
	sw->started_wall = sw->env.wallclock();
	retime_begin(sw);
	if (ex_start(sw->ex, 0, false, loop_now(sw->env.loop), err))
		goto fail;
	*id = sw->id;
	snapshot(sw);
	kick(sw);
	return 0;
fail:
	release(sw);
	return -1;
}

int sweep_pause(struct sweep *sw, struct acq_err *err)
{
	if (!sw->ex)
		return acq_errf(err, ACQ_E_STATE, "no sweep is running");
	if (ex_pause(sw->ex, loop_now(sw->env.loop), err))
		return -1;
	snapshot(sw);
	kick(sw);
	return 0;
}

/* The stored sweep id if it can be resumed (running or paused in the store), else NULL with err. */
static json_t *recover_load(struct sweep *sw, int64_t id, struct acq_err *err)
{
	json_t *js = store_sweep_show(sw->env.store, id, false, err);
	if (!js)
		return NULL;
	const char *state = json_string_value(json_object_get(js, "state"));
	if (!state || (strcmp(state, "running") && strcmp(state, "paused"))) {
		acq_errf(err, ACQ_E_STATE, "sweep %lld is %s: only a running or paused sweep can be resumed",
			 (long long)id, state ? state : "?");
		json_decref(js);
		return NULL;
	}
	return js;
}

static int recover_planned(struct sweep *sw, int64_t id, json_t *js, bool hold, struct acq_err *err);

/* Resume interrupted sweep id from the store: re-plan its stored plan text (deterministic), check it matches
 * the stored points, discard a partial point and start after the last committed one. */
static int recover_id(struct sweep *sw, int64_t id, bool hold, struct acq_err *err)
{
	json_t *js = recover_load(sw, id, err);
	if (!js)
		return -1;
	const char *text = json_string_value(json_object_get(js, "plan_text"));
	const char *name = json_string_value(json_object_get(js, "name"));
	struct ex_cfg cfg;
	if (make_plan(sw, text, name, &cfg, err)) {
		json_decref(js);
		release(sw);
		return -1;
	}
	return recover_planned(sw, id, js, hold, err);
}

/* recover_id() once sw->spec and sw->plan are made (both released on failure); consumes js. */
static int recover_planned(struct sweep *sw, int64_t id, json_t *js, bool hold, struct acq_err *err)
{
	const char *state = json_string_value(json_object_get(js, "state"));
	json_int_t total = json_integer_value(json_object_get(js, "points_total"));
	int rc = -1;
	struct ex_cfg cfg;
	if (plan_cfg(sw, &cfg, err))
		goto out;
	char stopped[1024] = "";
	if (sw->spec->adaptive && adapt_resume(sw->adapt, id, sw->spec, json_string_value(json_object_get(js, "plan_text")),
					      sw->plan, stopped, sizeof stopped, err))
		goto out;
	if ((json_int_t)sw->plan->n_steps != total) {
		acq_errf(err, ACQ_E_STATE, "sweep %lld: its plan now gives %zu points, %lld were stored (bench changed?)",
			 (long long)id, sw->plan->n_steps, (long long)total);
		goto out;
	}
	int oi = -1;
	int64_t pid = 0;
	if (store_sweep_next_point(sw->env.store, id, &oi, &pid, err))
		goto out;
	if (oi < 0)
		oi = (int)sw->plan->n_steps; /* everything committed: completes at once */
	else if (store_point_discard_partial(sw->env.store, pid, err))
		goto out;
	sw->id = id;
	if (record_devices(sw, id, err)) /* after a restart the controllers may be others */
		goto out;
	struct ex_sink sk = sink_of(sw);
	sw->ex = ex_new(&cfg, devices_ex_ops(), sw->env.devices, &sk, sw->env.store, id, devices_spectrometer_id(sw->env.devices),
			&sw->env.conf->bench, sw->plan, err);
	if (!sw->ex)
		goto out;
	sw->started_wall = sw->env.wallclock();
	retime_begin(sw);
	if (ex_start(sw->ex, oi, true, loop_now(sw->env.loop), err))
		goto out;
	if (stopped[0] && ex_state(sw->ex) == EX_WAITING) { /* it had stopped: only its completion was lost */
		if (ex_finish(sw->ex, stopped, err))
			goto out;
	} else if (hold && !strcmp(state, "paused")) {
		/* Paused for the operator (sample swap, fault, pause command) before the restart: stays paused. */
		json_t *evs = json_object_get(js, "events");
		for (size_t i = 0; i < json_array_size(evs); i++) {
			json_t *e = json_array_get(evs, i);
			const char *k = json_string_value(json_object_get(e, "kind"));
			if (!k || (strcmp(k, "pause") && strcmp(k, "resume") && strcmp(k, "start") && strcmp(k, "stop")))
				continue;
			if (!strcmp(k, "pause"))
				ex_hold(sw->ex, json_string_value(json_object_get(e, "message")));
			break;
		}
	}
	snapshot(sw);
	kick(sw);
	rc = 0;
out:
	json_decref(js);
	if (rc)
		release(sw);
	return rc;
}

int sweep_resume(struct sweep *sw, int64_t id, struct acq_err *err)
{
	if (sw->ex) {
		if (id && id != sw->id)
			return acq_errf(err, ACQ_E_STATE, "sweep %lld is loaded; finish or abort it first", (long long)sw->id);
		if (ex_resume(sw->ex, loop_now(sw->env.loop), err))
			return -1;
		snapshot(sw);
		kick(sw);
		return 0;
	}
	if (!id && store_sweep_interrupted(sw->env.store, &id, err))
		return -1;
	if (!id)
		return acq_errf(err, ACQ_E_NOTFOUND, "no paused or interrupted sweep to resume");
	return recover_id(sw, id, false, err);
}

int sweep_resume_plan_text(struct sweep *sw, int64_t id, int64_t *found, char **text, char **name,
			   struct acq_err *err)
{
	*found = 0;
	*text = *name = NULL;
	if (sw->ex)
		return 1;
	if (sw->planning)
		return acq_errf(err, ACQ_E_STATE, "a sweep is being planned");
	if (!id && store_sweep_interrupted(sw->env.store, &id, err))
		return -1;
	if (!id)
		return acq_errf(err, ACQ_E_NOTFOUND, "no paused or interrupted sweep to resume");
	json_t *js = recover_load(sw, id, err);
	if (!js)
		return -1;
	const char *t = json_string_value(json_object_get(js, "plan_text"));
	const char *n = json_string_value(json_object_get(js, "name"));
	*text = strdup(t ? t : "");
	*name = n ? strdup(n) : NULL;
	json_decref(js);
	if (!*text || (n && !*name)) {
		free(*text);
		free(*name);
		*text = *name = NULL;
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	*found = id;
	return 0;
}

int sweep_resume_planned(struct sweep *sw, int64_t id, struct plan_spec *spec, struct plan_result *plan, bool hold,
			 struct acq_err *err)
{
	json_t *js = NULL;
	if (sw->ex || sw->planning) {
		acq_errf(err, ACQ_E_STATE, "a sweep is loaded or being planned");
	} else if ((js = recover_load(sw, id, err))) { /* the row may have changed while it was planned */
		sw->spec = spec;
		sw->plan = plan;
		return recover_planned(sw, id, js, hold, err);
	}
	plan_spec_free(spec);
	plan_result_free(plan);
	return -1;
}

int sweep_abort(struct sweep *sw, struct acq_err *err)
{
	if (!sw->ex)
		return acq_errf(err, ACQ_E_STATE, "no sweep is running");
	if (ex_abort(sw->ex, "aborted by the operator", loop_now(sw->env.loop), err))
		return -1;
	kick(sw); /* the tick releases it */
	return 0;
}

void sweep_device_back(struct sweep *sw, enum conf_dev dev)
{
	(void)dev;
	if (sw->ex && ex_state(sw->ex) == EX_SUSPENDED) {
		ex_resume(sw->ex, loop_now(sw->env.loop), NULL); /* retry now */
		kick(sw);
	}
}

void sweep_conf_changed(struct sweep *sw, const struct conf *c)
{
	struct ex_cfg cfg;
	struct acq_err err = { 0 };
	sw->env.conf = c;
	exp_host_cache_drop(&sw->host); /* priced with the bench's figures: read again with the new ones */
	if (load_cfg(c, &cfg, &err))
		log_msg(LOG_ERR, "sweep configuration after reload: %s (keeping the previous one)", err.msg);
	else
		sw->cfg = cfg;
}

void sweep_get_progress(const struct sweep *sw, struct sweep_progress *p)
{
	*p = sw->last;
	if (!sw->ex) {
		p->state = SWEEP_IDLE;
		p->eta_s = p->eta_low_s = p->eta_high_s = NAN;
		p->pause_pending = false;
	}
}

bool sweep_busy(const struct sweep *sw)
{
	return sw->ex != NULL || sw->planning;
}

const char *sweep_state_name(enum sweep_state s)
{
	static const char *const names[] = { "idle", "running", "paused", "faulted", "stopping" };
	return (unsigned)s < 5 ? names[s] : "?";
}
