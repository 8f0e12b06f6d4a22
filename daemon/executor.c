/* executor core: the sweep state machine's states, control (start/pause/resume/abort), faults and retries,
 * configuration; motion in executor_motion.c, acquisition and commits in executor_acq.c. */
#include "daemon/executor_int.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "daemon/store.h"

const char *const ex_dev_names[EX_DEV__COUNT] = { "laser.theta", "detector.theta", "detector.phi",
						  "spectrometer", "laser" };

void ex_cfg_defaults(struct ex_cfg *c)
{
	memset(c, 0, sizeof *c);
	exp_policy_defaults(&c->pol);
	calib_cfg_defaults(&c->cal);
	c->extra_settle_s = 0.0;
	c->poll_s = 0.01;
	c->ladder_ratio = M_SQRT2;
	c->fault_retries = 5;
	c->fault_backoff_s = 0.5;
	c->fault_backoff_max_s = 8.0;
	c->auto_resume_faults = true;
	c->ref_pose = (struct plan_pos){ 0.0, 45.0, 180.0 };
	c->take_reference = true;
	c->pause_after_reference = true;
	c->max_point_attempts = 3;
	c->max_point_faults = 6;
	c->laser_power_pct = 100.0;
	c->max_invalid_frac = 0.005;
}

const char *ex_state_name(enum ex_state s)
{
	switch (s) {
	case EX_IDLE: return "idle";
	case EX_RUNNING: return "running";
	case EX_PAUSED: return "paused";
	case EX_SUSPENDED: return "suspended";
	case EX_COMPLETED: return "completed";
	case EX_ABORTED: return "aborted";
	case EX_FAILED: return "failed";
	case EX_WAITING: return "waiting";
	}
	return "unknown";
}

void ex_pos_angles(const struct bench_geom *g, const struct plan_pos *p, double *ti, double *pi, double *to,
		   double *po)
{
	double a = g->laser_phi_deg + (p->laser_theta < 0 ? 180.0 : 0.0);
	double b = p->det_phi + (p->det_theta < 0 ? 180.0 : 0.0);
	a = fmod(a, 360.0);
	b = fmod(b, 360.0);
	*ti = fabs(p->laser_theta);
	*pi = a < 0 ? a + 360.0 : a;
	*to = fabs(p->det_theta);
	*po = b < 0 ? b + 360.0 : b;
}

double ex_wall_now(struct ex *x)
{
	if (x->ops.wall)
		return x->ops.wall(x->octx);
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* The sweep's state was stored (rc 0: the latest stored) or refused (rc -1: kept for ex_flush_unrecorded). */
static void keep_state(struct ex *x, const char *state, double at, int rc)
{
	if (rc) {
		snprintf(x->lost_state, sizeof x->lost_state, "%s", state);
		x->lost_state_at = at;
	} else {
		x->lost_state[0] = 0;
	}
}

/* Store the sweep's state (NULL: none) and an event at one time, in one transaction (both or neither: a full disk
 * cannot keep a halt's state without its event), and tell the sink. What the store refuses is kept for
 * ex_flush_unrecorded(): a failure must not go unrecorded because recording failed; not fatal otherwise. */
static void record(struct ex *x, const char *state, const char *kind, const char *device, const char *msg)
{
	double at = ex_wall_now(x);
	if (x->st) {
		struct acq_err err = { 0 };
		bool group = state && store_group_begin(x->st, &err) == 0;
		int rs = state ? store_sweep_set_state(x->st, x->sweep_id, state, at, &err) : 0;
		int re = store_event(x->st, x->sweep_id, kind, device, msg, at, &err);
		if (group && store_group_end(x->st, rs || re, NULL))
			rs = re = -1; /* rolled back together */
		if (state)
			keep_state(x, state, at, rs);
		if (re) {
			if (x->nlost_ev == 4) {
				memmove(&x->lost_ev[0], &x->lost_ev[1], 3 * sizeof x->lost_ev[0]);
				x->nlost_ev = 3;
			}
			struct ex_lost_event *e = &x->lost_ev[x->nlost_ev++];
			snprintf(e->kind, sizeof e->kind, "%s", kind);
			snprintf(e->device, sizeof e->device, "%s", device ? device : "");
			snprintf(e->msg, sizeof e->msg, "%s", msg);
			e->at = at;
		}
	}
	if (x->sink.event)
		x->sink.event(x->sink.ctx, x->sweep_id, kind, device, msg);
}

static void __attribute__((format(printf, 5, 0))) vrecord(struct ex *x, const char *state, const char *kind,
							  const char *device, const char *fmt, va_list ap)
{
	char msg[768];
	vsnprintf(msg, sizeof msg, fmt, ap);
	record(x, state, kind, device, msg);
}

void ex_event(struct ex *x, const char *kind, const char *device, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vrecord(x, NULL, kind, device, fmt, ap);
	va_end(ap);
}

void ex_state_event(struct ex *x, const char *state, const char *kind, const char *device, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vrecord(x, state, kind, device, fmt, ap);
	va_end(ap);
}

void ex_set_db_state(struct ex *x, const char *state)
{
	struct acq_err err = { 0 };
	double at = ex_wall_now(x);
	if (x->st)
		keep_state(x, state, at, store_sweep_set_state(x->st, x->sweep_id, state, at, &err));
}

bool ex_has_unrecorded(const struct ex *x)
{
	return x->lost_state[0] || x->nlost_ev;
}

int ex_flush_unrecorded(struct ex *x, struct acq_err *err)
{
	/* One transaction, as they were meant to be stored: all of them or none. */
	if (store_group_begin(x->st, err))
		return -1;
	int rc = 0;
	for (int i = 0; i < x->nlost_ev && !rc; i++) {
		struct ex_lost_event *e = &x->lost_ev[i];
		rc = store_event(x->st, x->sweep_id, e->kind, e->device[0] ? e->device : NULL, e->msg, e->at, err);
	}
	if (!rc && x->lost_state[0])
		rc = store_sweep_set_state(x->st, x->sweep_id, x->lost_state, x->lost_state_at, err);
	if (store_group_end(x->st, rc, rc ? NULL : err) || rc)
		return -1;
	x->nlost_ev = 0;
	x->lost_state[0] = 0;
	return 0;
}

void ex_clear_pending(struct ex *x)
{
	for (int i = 0; i < x->npend; i++)
		free(x->pend[i].frame);
	x->npend = 0;
}

int ex_laser_off(struct ex *x, struct acq_err *err)
{
	if (!x->ops.laser_set)
		return 0;
	/* Emission may be on (commanded, a command in flight, or unknown after a restart): the off is queued to the
	 * laser's thread, so it is confirmed by a read before anything relies on it (laser_confirm; a halt reports
	 * `stopping` until then, ex_stopping). */
	bool maybe_on = x->stats.laser_on || x->laser_confirm || x->laser_unknown;
	int rc = x->ops.laser_set(x->octx, false, err);
	if (rc == 0)
		x->stats.laser_on = false;
	if (maybe_on && x->ops.laser_state) {
		x->laser_confirm = true;
		x->off_tries = 0;
	}
	return rc;
}

/* Best effort: stop the spectrometer and the arms, laser off. */
void ex_safe_stop(struct ex *x)
{
	memset(x->pos_got, 0, sizeof x->pos_got);
	struct acq_err err = { 0 };
	if (x->shot_in_flight && x->ops.spectro_stop)
		x->ops.spectro_stop(x->octx, &err);
	x->shot_in_flight = false;
	for (int a = 0; a < 3; a++) {
		if ((x->moving[a] || x->homing[a]) && x->ops.stop)
			x->ops.stop(x->octx, a, &err);
		x->moving[a] = x->homing[a] = false;
	}
	ex_laser_off(x, &err);
	x->stats.laser_on = false; /* the driver switches emission off on its own error paths too */
}

void ex_set_phase_text(struct ex *x, const char *s)
{
	snprintf(x->phase_text, sizeof x->phase_text, "%s", s);
}

/* The sweep stops moving and measuring for the reason fmt/ap (x->reason) and enters state (failed, paused). */
static void __attribute__((format(printf, 3, 0))) halt(struct ex *x, enum ex_state state, const char *fmt, va_list ap)
{
	vsnprintf(x->reason, sizeof x->reason, fmt, ap);
	ex_safe_stop(x);
	ex_reset_acq(x);
	x->state = state;
	x->phase = PH_NONE;
}

void ex_failed(struct ex *x, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	halt(x, EX_FAILED, fmt, ap);
	va_end(ap);
	ex_set_phase_text(x, "failed");
	ex_state_event(x, "failed", "failed", NULL, "%s", x->reason);
}

void ex_pause_now(struct ex *x, bool by_fault, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	halt(x, EX_PAUSED, fmt, ap);
	va_end(ap);
	x->paused_by_fault = by_fault;
	x->pause_requested = false;
	ex_set_phase_text(x, "paused");
	ex_state_event(x, "paused", "pause", by_fault ? ex_dev_names[x->fault_dev] : NULL, "%s", x->reason);
}

/* A device error: the sweep suspends, and retries the device with backoff (or pauses at once). */
void ex_fault(struct ex *x, int dev, const struct acq_err *err)
{
	x->stats.faults++;
	memset(x->pos_got, 0, sizeof x->pos_got);
	/* the device's name once (the event's device, the log's prefix): drivers may put it in front of their
	 * message already ("detector.theta: ...", "detector.theta (unit 1 @ host): link is down") */
	const char *msg = err && err->msg[0] ? err->msg : "device error", *nm = ex_dev_names[dev];
	size_t nl = strlen(nm);
	if (!strncmp(msg, nm, nl) && (msg[nl] == ':' || msg[nl] == ' ') && msg[nl + 1])
		msg += nl + (msg[nl] == ':' ? 2 : 1);
	snprintf(x->fault_msg, sizeof x->fault_msg, "%s", msg);
	x->fault_dev = dev;
	if (x->ops.lost)
		x->ops.lost(x->octx, dev, err);
	ex_safe_stop(x);
	ex_reset_acq(x);
	if (dev == EX_DEV_SPECTRO)
		exp_darks_clear(x->darks); /* a reconnected spectrometer starts afresh */
	if (dev <= EX_DEV_DETECTOR_PHI)
		x->known_valid = false;
	if (dev == EX_DEV_LASER)
		x->power_set = false;
	ex_event(x, "fault", nm, "%s (%s)", x->fault_msg, acq_errname(err ? err->code : ACQ_E_DEVICE));
	if (err && (err->code == ACQ_E_RANGE || err->code == ACQ_E_INVAL || err->code == ACQ_E_UNSUPPORTED)) {
		/* Not a device that went away: retrying cannot help. */
		ex_pause_now(x, true, "%s refused the operation at point %d: %s; fix the plan or the limits, then resume",
			  ex_dev_names[dev], x->cur, x->fault_msg);
		return;
	}
	if (++x->point_faults > x->cfg.max_point_faults) {
		ex_pause_now(x, true, "%d faults at point %d (last on %s: %s): paused for the operator", x->point_faults - 1,
			  x->cur, ex_dev_names[dev], x->fault_msg);
		x->point_faults = 0;
		return;
	}
	if (!x->cfg.auto_resume_faults) {
		ex_pause_now(x, true, "fault on %s: %s; resume when it is fixed", ex_dev_names[dev], x->fault_msg);
		return;
	}
	x->state = EX_SUSPENDED;
	x->phase = PH_NONE;
	x->fault_attempts = 0;
	x->reconnecting = false;
	x->backoff = x->cfg.fault_backoff_s;
	snprintf(x->phase_text, sizeof x->phase_text, "suspended: %s", ex_dev_names[dev]);
	x->retry_at = -1;
}

struct ex *ex_new(const struct ex_cfg *cfg, const struct ex_ops *ops, void *ops_ctx, const struct ex_sink *sink,
		  struct store *st, int64_t sweep_id, int64_t spectrometer_id, const struct bench_geom *geom,
		  const struct plan_result *plan, struct acq_err *err)
{
	struct acq_err perr = { 0 };
	if (exp_policy_check(&cfg->pol, &perr))
		return acq_errf(err, ACQ_E_CONFIG, "sweep: %s", perr.msg), NULL;
	if (calib_grid_size(&cfg->cal) <= 0)
		return acq_errf(err, ACQ_E_CONFIG, "sweep: bad calibration grid"), NULL;
	if (!plan || !ops || !geom)
		return acq_errf(err, ACQ_E_INVAL, "sweep: missing plan, devices or geometry"), NULL;
	struct ex *x = calloc(1, sizeof *x);
	if (!x)
		return acq_errf(err, ACQ_E_NOMEM, "sweep: out of memory"), NULL;
	x->cfg = *cfg;
	x->ops = *ops;
	x->octx = ops_ctx;
	if (sink)
		x->sink = *sink;
	x->st = st;
	x->sweep_id = sweep_id;
	x->spectro_id = spectrometer_id;
	x->geom = *geom;
	x->plan = plan;
	x->nsteps = (int)plan->n_steps;
	x->frame = malloc(sizeof *x->frame);
	x->probe = malloc(sizeof *x->probe);
	x->merged = malloc(sizeof *x->merged);
	x->ref_rate = malloc(sizeof *x->ref_rate);
	x->darks = calloc(1, sizeof *x->darks);
	x->cal = malloc(sizeof *x->cal);
	x->avg = malloc(sizeof *x->avg);
	bool ok = x->frame && x->probe && x->merged && x->ref_rate && x->darks && x->cal && x->avg;
	for (int i = 0; i < EX_MAX_TIMES && ok; i++)
		ok = (x->rates[i] = malloc(sizeof(struct exp_rate))) != NULL;
	if (!ok) {
		ex_free(x, 0);
		return acq_errf(err, ACQ_E_NOMEM, "sweep: out of memory"), NULL;
	}
	x->stats.points_total = x->nsteps;
	x->t_last = cfg->pol.probe_ms;
	x->temperature = NAN;
	x->state = EX_IDLE;
	ex_set_phase_text(x, "idle");
	return x;
}

void ex_free(struct ex *x, double now)
{
	(void)now;
	if (!x)
		return;
	if (x->state == EX_RUNNING || x->state == EX_SUSPENDED)
		ex_safe_stop(x);
	ex_clear_pending(x);
	for (int i = 0; i < EX_MAX_TIMES; i++)
		free(x->rates[i]);
	free(x->frame);
	free(x->probe);
	free(x->merged);
	free(x->ref_rate);
	free(x->darks);
	free(x->cal);
	free(x->avg);
	free(x);
}

enum ex_state ex_state(const struct ex *x)
{
	return x->state;
}

const char *ex_phase(const struct ex *x)
{
	return x->phase_text;
}

const struct ex_stats *ex_stats(const struct ex *x)
{
	return &x->stats;
}

const char *ex_reason(const struct ex *x)
{
	return x->reason;
}

int ex_current_step(const struct ex *x)
{
	return x->cur;
}

/* ---- control ---------------------------------------------------------------------------------- */

void ex_io_wait(struct ex *x, double now)
{
	x->wake = now + EX_IO_RECHECK_S;
}

void ex_begin_segment(struct ex *x, double now)
{
	memset(x->alarm_reset_sent, 0, sizeof x->alarm_reset_sent);
	memset(x->pos_got, 0, sizeof x->pos_got);
	x->laser_unknown = true;
	x->phase = PH_VERIFY;
	x->first_move = true;
	x->wake = now;
}

int ex_start(struct ex *x, int first_step, bool resumed, double now, struct acq_err *err)
{
	if (x->state != EX_IDLE)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld is %s", (long long)x->sweep_id, ex_state_name(x->state));
	if (first_step < 0 || first_step > x->nsteps)
		return acq_errf(err, ACQ_E_RANGE, "sweep: first step %d outside [0, %d]", first_step, x->nsteps);
	if (x->cfg.take_reference && x->cfg.cal.method == CALIB_RELATIVE) {
		unsigned why = plan_blind(&x->geom, &x->cfg.ref_pose);
		if (why)
			return acq_errf(err, ACQ_E_CONFIG, "sweep.acquisition.reference_pose (%g, %g, %g): %s",
					x->cfg.ref_pose.laser_theta, x->cfg.ref_pose.det_theta, x->cfg.ref_pose.det_phi,
					plan_reason_name(why));
	}
	x->cur = first_step;
	x->stats.points_done = first_step;
	if (x->st) {
		float *grid = x->scratch;
		int n = calib_grid_size(&x->cfg.cal);
		for (int k = 0; k < n; k++)
			grid[k] = (float)(x->cfg.cal.grid_min_nm + k * x->cfg.cal.grid_step_nm);
		if (store_sweep_set_grid(x->st, x->sweep_id, grid, n, err))
			return -1;
	}
	x->state = EX_RUNNING;
	x->point_avg_s = NAN;
	ex_stall_reset(x);
	ex_set_db_state(x, "running");
	if (resumed) {
		struct acq_err lerr = { 0 };
		int r = ex_load_reference(x, &lerr);
		x->have_ref = r == 1;
		ex_event(x, "resume", NULL, "resuming after point %d of %d (%s)", first_step, x->nsteps,
		      x->have_ref ? "reference reloaded from the database"
				  : r < 0 ? lerr.msg : "no complete reference stored: measuring it again");
	} else {
		ex_event(x, "start", NULL, "sweep of %d points started", x->nsteps);
	}
	x->in_reference = x->cfg.take_reference && !x->have_ref;
	if (x->cfg.cal.method == CALIB_RELATIVE && !x->cfg.take_reference && !x->have_ref)
		ex_event(x, "info", NULL, "no reference will be measured: calibrated values need one (take_reference)");
	if (x->cfg.hold_at_end && first_step >= x->nsteps) { /* resumed between batches: the next is decided first */
		x->in_reference = false;
		ex_wait_batch(x);
		return 0;
	}
	ex_begin_segment(x, now);
	ex_set_phase_text(x, "verifying positions");
	/* The reference → sample swap is one durable state: resumed with the reference stored and no point
	 * committed, nothing proves the sample was placed (a crash may have come between the reference and its
	 * pause, or between the operator's resume and the first point), so the operator is asked again; the white
	 * standard is never measured as the sample. */
	if (resumed && x->have_ref && first_step == 0 && x->nsteps > 0 && x->cfg.take_reference &&
	    x->cfg.pause_after_reference)
		ex_pause_now(x, false, "%s measured before the restart: place the sample on the stage (if not done yet), "
			     "then resume", x->cfg.cal.method == CALIB_ABSOLUTE ? "direct beam" : "reference");
	return 0;
}

int ex_pause(struct ex *x, double now, struct acq_err *err)
{
	(void)now;
	if (x->state == EX_SUSPENDED) {
		ex_pause_now(x, true, "paused by the operator while %s was faulted", ex_dev_names[x->fault_dev]);
		return 0;
	}
	if (x->state == EX_WAITING) {
		ex_pause_now(x, false, "paused by the operator after point %d (between batches)", x->cur);
		return 0;
	}
	if (x->state != EX_RUNNING)
		return acq_errf(err, ACQ_E_STATE, "sweep is %s, not running", ex_state_name(x->state));
	x->pause_requested = true;
	return 0;
}

bool ex_pause_pending(const struct ex *x)
{
	return x->state == EX_RUNNING && x->pause_requested;
}

int ex_resume(struct ex *x, double now, struct acq_err *err)
{
	if (x->state == EX_SUSPENDED) {
		x->retry_at = now; /* try the device now */
		return 0;
	}
	if (x->state != EX_PAUSED)
		return acq_errf(err, ACQ_E_STATE, "sweep is %s, not paused", ex_state_name(x->state));
	x->reason[0] = '\0';
	ex_set_db_state(x, "running");
	if (x->cfg.hold_at_end && x->cur >= x->nsteps && !x->paused_by_fault) {
		ex_event(x, "resume", NULL, "resumed after point %d: waiting for the next batch", x->cur);
		ex_wait_batch(x);
		return 0;
	}
	if (x->paused_by_fault) {
		x->state = EX_SUSPENDED;
		x->fault_attempts = 0;
		x->reconnecting = false;
		x->backoff = x->cfg.fault_backoff_s;
		x->retry_at = now;
		ex_event(x, "resume", ex_dev_names[x->fault_dev], "resumed by the operator: trying %s again",
		      ex_dev_names[x->fault_dev]);
		return 0;
	}
	x->state = EX_RUNNING;
	ex_event(x, "resume", NULL, "resumed at point %d of %d", x->cur, x->nsteps);
	ex_begin_segment(x, now);
	return 0;
}

int ex_abort(struct ex *x, const char *why, double now, struct acq_err *err)
{
	(void)now;
	if (x->state == EX_COMPLETED || x->state == EX_ABORTED || x->state == EX_FAILED)
		return acq_errf(err, ACQ_E_STATE, "sweep already %s", ex_state_name(x->state));
	ex_safe_stop(x);
	ex_reset_acq(x);
	snprintf(x->reason, sizeof x->reason, "%s", why && *why ? why : "aborted by the operator");
	x->state = EX_ABORTED;
	x->phase = PH_NONE;
	ex_set_phase_text(x, "aborted");
	ex_state_event(x, "aborted", "abort", NULL, "aborted at point %d of %d: %s (laser off, arms stopped)", x->cur,
		       x->nsteps, x->reason);
	return 0;
}

/* ---- a halt's laser off ------------------------------------------------------------------------ */

bool ex_stopping(const struct ex *x)
{
	return x->laser_confirm && x->state != EX_RUNNING && x->state != EX_WAITING && x->state != EX_IDLE;
}

/* A halt queued the laser's emission-off: read the laser until it says off. True while the read is on its way
 * (the sweep reports `stopping`); false once confirmed, or after an event saying why it could not be (the laser
 * does not answer, or still emits after EX_OFF_TRIES commands): the halt is never held up by the laser. */
static bool halt_laser_confirm(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	bool emission = false, ready = false;
	int rc = x->ops.laser_state(x->octx, &emission, &ready, &err);
	if (rc == EX_PENDING) {
		ex_io_wait(x, now);
		return true;
	}
	x->laser_confirm = false;
	if (rc == 0 && !emission)
		return false;
	if (rc == 0 && ++x->off_tries < EX_OFF_TRIES) {
		int tries = x->off_tries;
		x->stats.laser_on = true; /* so that ex_laser_off asks for a confirmation again */
		if (ex_laser_off(x, &err) == 0) {
			x->off_tries = tries;
			x->wake = now;
			return true;
		}
		rc = -1;
	}
	if (rc == 0)
		acq_errf(&err, ACQ_E_DEVICE, "still emitting after %d emission-off commands", EX_OFF_TRIES);
	x->stats.laser_on = false;
	ex_event(x, "info", ex_dev_names[EX_DEV_LASER], "the sweep %s, but the laser's emission off is NOT confirmed: "
		 "%s; check the laser (its keep-alive stops emission when the daemon stops refreshing it)",
		 ex_state_name(x->state), err.msg[0] ? err.msg : "no answer");
	return false;
}

/* ---- faults ----------------------------------------------------------------------------------- */

static void run_suspended(struct ex *x, double now)
{
	if (x->retry_at < 0)
		x->retry_at = now + x->backoff;
	if (!x->reconnecting) {
		if (now + 1e-12 < x->retry_at) {
			x->wake = x->retry_at;
			return;
		}
		x->fault_attempts++;
		x->stats.retries++;
		x->reconnecting = true;
		x->recon_stage = 0;
	}
	struct acq_err err = { 0 };
	int dev = x->fault_dev;
	int rc = 0;
	if (x->recon_stage == 0) {
		rc = x->ops.reconnect(x->octx, dev, &err);
		if (rc == EX_PENDING) {
			ex_io_wait(x, now);
			return;
		}
		if (rc == 0 && dev == EX_DEV_LASER)
			x->recon_stage = 1;
	}
	if (rc == 0 && x->recon_stage == 1) {
		bool emission = false, ready = false;
		rc = x->ops.laser_state(x->octx, &emission, &ready, &err);
		if (rc == EX_PENDING) {
			ex_io_wait(x, now);
			return;
		}
		if (rc == 0 && !ready)
			rc = acq_errf(&err, ACQ_E_DEVICE, "laser not ready (interlock open or fault)");
	}
	x->reconnecting = false;
	if (rc == 0 && dev == EX_DEV_SPECTRO) {
		x->info = NULL;
		if (!ex_want_wl(x))
			rc = acq_errf(&err, ACQ_E_DISCONNECTED, "spectrometer information unavailable");
	}
	if (rc == 0) {
		x->stats.recoveries++;
		x->state = EX_RUNNING;
		ex_event(x, "recovered", ex_dev_names[dev], "%s answers again after %d attempt%s: point %d restarts", ex_dev_names[dev],
		      x->fault_attempts, x->fault_attempts == 1 ? "" : "s", x->cur);
		ex_begin_segment(x, now);
		return;
	}
	if (x->fault_attempts >= x->cfg.fault_retries) {
		ex_pause_now(x, true, "%s did not come back after %d attempts (%s): paused for the operator", ex_dev_names[dev],
			  x->fault_attempts, err.msg);
		return;
	}
	x->backoff = fmin(x->backoff * 2, x->cfg.fault_backoff_max_s);
	x->retry_at = now + x->backoff;
	x->wake = x->retry_at;
}

double ex_step_run(struct ex *x, double now)
{
	/* A point committed while the sweep went on: announced as soon as it is on disk, whatever the state. */
	if (x->ack_pending)
		ex_ack_step(x);
	/* Bounded work per call: a few transitions, then hand back to the loop. */
	for (int guard = 0; guard < 16; guard++) {
		x->wake = INFINITY;
		if (ex_stopping(x)) {
			if (halt_laser_confirm(x, now))
				return x->wake > now ? x->wake : now;
			continue;
		}
		if (x->state == EX_SUSPENDED) {
			run_suspended(x, now);
		} else if (x->state == EX_RUNNING) {
			switch (x->phase) {
			case PH_VERIFY: ex_run_verify(x, now); break;
			case PH_HOMING: ex_run_homing(x, now); break;
			case PH_MOVE: ex_run_move(x, now); break;
			case PH_SETTLE: ex_run_settle(x, now); break;
			case PH_ACQ: ex_run_acq(x, now); break;
			case PH_LASER_OFF: ex_run_laser_off(x, now); break;
			case PH_DURABLE: ex_run_durable(x, now); break;
			case PH_NONE: break;
			}
		} else {
			return INFINITY;
		}
		/* A transition that scheduled nothing (e.g. into suspended, or a halt whose emission-off is still to be
		 * confirmed: a sweep failed while storing a point) runs the new state at once. */
		if (x->wake == INFINITY && (x->state == EX_RUNNING || x->state == EX_SUSPENDED || ex_stopping(x)))
			continue;
		if (x->wake > now)
			return x->wake;
	}
	return now;
}

/* ---- configuration and shutdown ---------------------------------------------------------------- */

int ex_cfg_parse(struct yc_node *acq, struct yc_node *cal, struct ex_cfg *c, struct acq_err *err)
{
	struct ex_cfg q = *c;
	if (acq) {
		if (exp_policy_parse(acq, &q.pol, err))
			return -1;
		long long retries = q.fault_retries, attempts = q.max_point_attempts;
		struct yc_node *pose = yc_get(acq, "reference_pose");
		if (yc_bool(acq, "take_reference", false, &q.take_reference, err) ||
		    yc_bool(acq, "pause_after_reference", false, &q.pause_after_reference, err) ||
		    yc_int(acq, "fault_retries", false, 0, 1000, &retries, err) ||
		    yc_double(acq, "fault_backoff_s", false, 0.001, 3600, &q.fault_backoff_s, err) ||
		    yc_double(acq, "fault_backoff_max_s", false, 0.001, 86400, &q.fault_backoff_max_s, err) ||
		    yc_double(acq, "ladder_ratio", false, 1.01, 10, &q.ladder_ratio, err) ||
		    yc_double(acq, "poll_s", false, 1e-4, 10, &q.poll_s, err) ||
		    yc_int(acq, "max_point_attempts", false, 1, 20, &attempts, err) ||
		    yc_double(acq, "max_invalid_frac", false, 0, 1, &q.max_invalid_frac, err) ||
		    yc_bool(acq, "home_unhomed", false, &q.home_unhomed, err) ||
		    yc_double(acq, "laser_power_pct", false, 0, 100, &q.laser_power_pct, err))
			return -1;
		struct yc_node *home = yc_get(acq, "home_deg");
		if (home) {
			if (yc_expect_seq(home, "sweep.acquisition.home_deg", err))
				return -1;
			if (home->n != 3)
				return yc_errf(err, home, "home_deg: expected [laser.theta, detector.theta, detector.phi]");
			for (int i = 0; i < 3; i++)
				if (yc_node_double(home->items[i], "home_deg angle", -360, 720, &q.home_deg[i], err))
					return -1;
		}
		if (pose && plan_pose_parse(pose, "sweep.acquisition.reference_pose", &q.ref_pose, err))
			return -1;
		if (yc_check_unknown(acq, "sweep.acquisition", err))
			return -1;
		q.fault_retries = (int)retries;
		q.max_point_attempts = (int)attempts;
	}
	if (cal && calib_cfg_parse(cal, &q.cal, err))
		return -1;
	*c = q;
	return 0;
}

void ex_shutdown(struct ex *x, const char *why)
{
	if (!x || !(x->state == EX_RUNNING || x->state == EX_SUSPENDED || x->state == EX_PAUSED || x->state == EX_WAITING))
		return;
	if (x->state == EX_PAUSED) { /* already paused (and why is in the log): it stays so after the restart */
		ex_safe_stop(x);
		return;
	}
	ex_safe_stop(x);
	ex_reset_acq(x);
	x->state = EX_PAUSED;
	ex_state_event(x, "paused", "stop", NULL, "%s: the sweep stays resumable after point %d of %d",
		       why && *why ? why : "daemon stopping", x->cur, x->nsteps);
}

void ex_hold(struct ex *x, const char *why)
{
	if (!x || (x->state != EX_RUNNING && x->state != EX_WAITING))
		return;
	ex_pause_now(x, false, "still paused after a restart: %s", why && *why ? why : "paused by the operator");
}
