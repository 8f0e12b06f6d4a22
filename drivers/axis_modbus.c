/* axis_modbus: the arm-axis driver over Modbus TCP or RTU (libmodbus), driven by a register map from the
 * configuration; bounded transactions, a move state machine stepped by the caller, no sleeps, no logging.
 *
 * Every call does a handful of Modbus transactions and stops at the first failure, so it never blocks for
 * longer than one response timeout per transaction. Recovery is ours, never MODBUS_ERROR_RECOVERY_LINK
 * (which sleeps and retries inside libmodbus): a link error marks the link down and the caller schedules
 * mb_reconnect() with its own backoff (axis_backoff_s()). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "drivers/axis_backend.h"
#include "drivers/axis_modbus_int.h"

static void mb_close(struct axis_dev *ax);
static int mb_read_status(struct axis_dev *ax, struct axis_status *st, struct acq_err *err);
static int mb_read_bits(struct axis_dev *ax, bool *limit_pos, bool *limit_neg, bool *stall, struct acq_err *err);
static int mb_stop(struct axis_dev *ax, struct acq_err *err);

double axis_trapezoid_s(double dist, double speed, double accel, double decel)
{
	dist = fabs(dist);
	if (dist == 0)
		return 0;
	/* distance to reach full speed and stop again */
	double dfull = speed * speed / (2 * accel) + speed * speed / (2 * decel);
	if (dist >= dfull)
		return speed / accel + speed / decel + (dist - dfull) / speed;
	/* triangle: peak speed vp with vp²/2a + vp²/2d = dist */
	double vp = sqrt(2 * dist * accel * decel / (accel + decel));
	return vp / accel + vp / decel;
}

double axis_backoff_s(int attempt)
{
	double s = 0.1;
	for (int i = 0; i < attempt && s < 5; i++)
		s *= 2;
	return s > 5 ? 5 : s;
}

/* ---- public operations ------------------------------------------------------------------------------ */

static int open_common(const struct axis_cfg *cfg, struct axis_link *shared, struct axis_dev **out, struct acq_err *err)
{
	struct axis_dev *ax = calloc(1, sizeof *ax);
	if (!ax)
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", cfg->name);
	ax->cfg = cfg;
	ax->clear_cmd = -1;
	ax->state = ST_IDLE;
	if (shared) {
		ax->link = mb_link_ref(shared);
	} else {
		ax->link = mb_link_new(cfg);
		if (!ax->link) {
			free(ax);
			return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", cfg->name);
		}
		if (mb_link_connect(ax->link, cfg, err)) {
			mb_close(ax);
			return -1;
		}
	}
	*out = ax;
	return 0;
}

static int mb_open(const struct axis_cfg *cfg, struct axis_dev **out, struct acq_err *err)
{
	return open_common(cfg, NULL, out, err);
}

static int mb_open_shared(const struct axis_cfg *cfg, struct axis_dev *peer, struct axis_dev **out, struct acq_err *err)
{
	const struct axis_link_cfg *a = &cfg->link, *b = &peer->cfg->link;
	if (a->type != b->type || strcmp(a->host, b->host) || a->port != b->port || strcmp(a->device, b->device))
		return acq_errf(err, ACQ_E_INVAL, "%s: its link differs from %s's, it cannot be shared", cfg->name,
				peer->cfg->name);
	return open_common(cfg, peer->link, out, err);
}

static void mb_close(struct axis_dev *ax)
{
	if (!ax)
		return;
	if (ax->link->up && (ax->state == ST_MOVE || ax->state == ST_HOME))
		mb_stop(ax, NULL);
	mb_link_unref(ax->link);
	free(ax);
}

static bool mb_connected(const struct axis_dev *ax) { return ax->link->up; }
static double mb_next_poll(const struct axis_dev *ax) { return ax->next_poll; }

static int mb_read_status(struct axis_dev *ax, struct axis_status *st, struct acq_err *err)
{
	const struct regmap *m = ax->cfg->map;
	double word, pos;
	memset(st, 0, sizeof *st);
	if (mb_reg_read_field(ax, RM_STATUS, NULL, &word, err) || mb_reg_read_field(ax, RM_ACTUAL, &pos, NULL, err))
		return -1;
	uint32_t w = (uint32_t)(int64_t)word;
	st->position_deg = pos;
	st->ready = mb_reg_bit(m, w, RM_BIT_READY);
	st->busy = mb_reg_bit(m, w, RM_BIT_BUSY) || mb_reg_bit(m, w, RM_BIT_MOVE);
	st->in_position = mb_reg_bit(m, w, RM_BIT_IN_POS);
	st->alarm = mb_reg_bit(m, w, RM_BIT_ALARM);
	st->homed = mb_reg_bit(m, w, RM_BIT_HOMED);
	if (st->alarm && m->f[RM_ALARM_CODE].present) {
		double code;
		if (mb_reg_read_field(ax, RM_ALARM_CODE, NULL, &code, err))
			return -1;
		st->alarm_code = (int)code;
		if (st->alarm_code == 0)
			st->alarm_code = -1;
	} else if (st->alarm) {
		st->alarm_code = -1; /* in alarm, code unknown */
	}
	return 0;
}

static int mb_read_bits(struct axis_dev *ax, bool *limit_pos, bool *limit_neg, bool *stall, struct acq_err *err)
{
	double word;
	if (mb_reg_read_field(ax, RM_STATUS, NULL, &word, err))
		return -1;
	uint32_t w = (uint32_t)(int64_t)word;
	*limit_pos = mb_reg_bit(ax->cfg->map, w, RM_BIT_LIMIT_POS);
	*limit_neg = mb_reg_bit(ax->cfg->map, w, RM_BIT_LIMIT_NEG);
	*stall = mb_reg_bit(ax->cfg->map, w, RM_BIT_STALL);
	return 0;
}

static int fail_move(struct axis_dev *ax, struct acq_err *err)
{
	ax->state = ST_FAILED;
	ax->fail = *err;
	return AXIS_MOVE_FAILED;
}

/* When to read a running leg's status next (session 14: polled every poll_s from the start, the arms' threads
 * spent 1.57 ms of CPU per point of the paper plan at time scale 35 on a quiet machine, 1.07-1.30 ms with this at
 * load 3; tests/bench/bench_duration.py's debug stall lines): at the leg's predicted end (the trapezoid from its
 * start), but at least every watch_s before it, so an alarm or a stall mid-move, or a move that never ends
 * (the deadline), is seen within watch_s; after the predicted end (the controller behind: the command's delivery
 * on a loaded host, a slower profile) when the distance left would be covered at full speed then decelerating
 * (a lower bound of the time left: an early poll only estimates again), within [poll_s/10, watch_s] (rem_deg NAN:
 * poll_s). A homing has no predicted end: every poll_s. */
static double poll_at(const struct axis_dev *ax, double now, double rem_deg)
{
	const struct axis_cfg *c = ax->cfg;
	if (ax->state != ST_HOME && now < ax->leg_end)
		return now + fmin(ax->leg_end - now, c->watch_s);
	double dec = c->decel > 0 ? c->decel : c->accel, v = c->speed, d = fabs(rem_deg), dt = c->poll_s;
	if (ax->state != ST_HOME && isfinite(d) && dec > 0 && v > 0)
		dt = fmin(fmax(d >= v * v / (2 * dec) ? d / v + v / (2 * dec) : sqrt(2 * d / dec), c->poll_s / 10),
			  c->watch_s);
	return now + dt;
}

/* Start one leg towards `leg`: backlash take-up first when approaching from the wrong side. */
static int start_leg(struct axis_dev *ax, double from, double now, bool allow_pre, struct acq_err *err)
{
	const struct axis_cfg *c = ax->cfg;
	double leg = ax->target;
	ax->pre_leg = false;
	/* Final approach always in backlash_dir: when the move goes the other way, overshoot by the
	 * backlash first (clamped to the soft limits), then come back. */
	if (allow_pre && c->backlash > 0 && (ax->target - from) * c->backlash_dir < 0) {
		leg = ax->target - c->backlash_dir * c->backlash;
		if (leg < c->soft_min)
			leg = c->soft_min;
		if (leg > c->soft_max)
			leg = c->soft_max;
		ax->pre_leg = leg != ax->target;
	}
	if (mb_reg_send_move(ax, leg, err))
		return -1;
	ax->leg = leg;
	ax->leg_start = now;
	ax->seen_busy = false;
	double t = axis_trapezoid_s(leg - from, c->speed, c->accel, c->decel);
	ax->deadline = now + t * c->timeout_factor + c->margin_s;
	ax->leg_end = now + t;
	ax->state = ST_MOVE;
	ax->next_poll = poll_at(ax, now, NAN);
	return 0;
}

/* The target to command: target itself, or with wrap_deg the equivalent angle (target + k·wrap) inside the
 * soft limits nearest to the current position. NAN when none lies inside the limits. */
static double resolve_target(const struct axis_cfg *c, double target, double from)
{
	if (c->wrap <= 0)
		return target >= c->soft_min && target <= c->soft_max ? target : NAN;
	double best = NAN;
	double k0 = floor((c->soft_min - target) / c->wrap);
	for (double k = k0; target + k * c->wrap <= c->soft_max; k += 1) {
		double t = target + k * c->wrap;
		if (t >= c->soft_min && (isnan(best) || fabs(t - from) < fabs(best - from)))
			best = t;
	}
	return best;
}

static int mb_move_begin(struct axis_dev *ax, double target_deg, double now, struct acq_err *err)
{
	const struct axis_cfg *c = ax->cfg;
	if (!isfinite(target_deg) || fabs(target_deg) > 1e6)
		return acq_errf(err, ACQ_E_RANGE, "%s: target is not a finite angle", c->name);
	/* without wrap the soft limits are checked before anything is sent */
	if (c->wrap <= 0 && isnan(resolve_target(c, target_deg, 0)))
		return acq_errf(err, ACQ_E_RANGE, "%s: target %g° outside the soft limits [%g°, %g°]", c->name,
				target_deg, c->soft_min, c->soft_max);
	if (c->wrap > 0 && isnan(resolve_target(c, target_deg, target_deg)))
		return acq_errf(err, ACQ_E_RANGE, "%s: no angle equivalent to %g° (modulo %g°) inside the soft "
				"limits [%g°, %g°]", c->name, target_deg, c->wrap, c->soft_min, c->soft_max);
	if (ax->state == ST_MOVE || ax->state == ST_HOME)
		return acq_errf(err, ACQ_E_STATE, "%s: a move is already running", c->name);
	struct axis_status st;
	if (mb_reg_clear_pending(ax, err) || mb_read_status(ax, &st, err))
		return -1;
	if (st.alarm)
		return acq_errf(err, ACQ_E_DEVICE, "%s: controller in alarm (code 0x%x): reset it first", c->name,
				(unsigned)st.alarm_code);
	ax->target = resolve_target(c, target_deg, st.position_deg);
	ax->retries_left = c->retries;
	if (start_leg(ax, st.position_deg, now, true, err)) {
		ax->state = ST_FAILED;
		ax->fail = *err;
		return -1;
	}
	return 0;
}

static double mb_target(const struct axis_dev *ax)
{
	return ax->target;
}

static int mb_move_step(struct axis_dev *ax, double now, struct acq_err *err)
{
	const struct axis_cfg *c = ax->cfg;
	switch (ax->state) {
	case ST_IDLE:
	case ST_DONE:
		return AXIS_MOVE_DONE;
	case ST_FAILED:
		if (err)
			*err = ax->fail;
		return AXIS_MOVE_FAILED;
	default:
		break;
	}
	if (now < ax->next_poll)
		return AXIS_MOVE_RUNNING;
	struct axis_status st;
	if (mb_reg_clear_pending(ax, err) || mb_read_status(ax, &st, err))
		return fail_move(ax, err);
	if (st.alarm) {
		acq_errf(err, ACQ_E_DEVICE, "%s: controller alarm (code 0x%x) at %.4f° during %s", c->name,
			 (unsigned)st.alarm_code, st.position_deg, ax->state == ST_HOME ? "homing" : "a move");
		err->detail = st.alarm_code;
		return fail_move(ax, err);
	}
	if (st.busy)
		ax->seen_busy = true;
	if (st.busy || (!ax->seen_busy && now < ax->leg_start + c->start_grace_s &&
			fabs(st.position_deg - ax->leg) > c->deadband)) {
		/* moving, or not yet seen moving (a controller may take a moment to raise busy) */
		if (now > ax->deadline) {
			struct acq_err e2;
			bool lp = false, ln = false, stall = false;
			mb_read_bits(ax, &lp, &ln, &stall, &e2);
			mb_stop(ax, &e2);
			acq_errf(err, ACQ_E_TIMEOUT, "%s: %s did not complete in time (at %.4f°, target %.4f°%s); stopped",
				 c->name, ax->state == ST_HOME ? "homing" : "move", st.position_deg, ax->leg,
				 stall ? ", the controller reports a stall" : "");
			return fail_move(ax, err);
		}
		ax->next_poll = poll_at(ax, now, st.position_deg - ax->leg);
		return AXIS_MOVE_RUNNING;
	}
	if (ax->state == ST_HOME) {
		if (c->map->bit[RM_BIT_HOMED] >= 0 && !st.homed) {
			acq_errf(err, ACQ_E_DEVICE, "%s: homing ended without the homed bit (at %.4f°)", c->name,
				 st.position_deg);
			return fail_move(ax, err);
		}
		ax->state = ST_DONE;
		return AXIS_MOVE_DONE;
	}
	if (ax->pre_leg) { /* take-up leg done: final approach */
		if (start_leg(ax, st.position_deg, now, false, err))
			return fail_move(ax, err);
		return AXIS_MOVE_RUNNING;
	}
	double e = st.position_deg - ax->target;
	if (fabs(e) <= c->deadband) {
		/* in position: settle, then confirm it stayed there (a second read after settle_s) */
		if (ax->state == ST_SETTLE || c->settle_s <= 0) {
			ax->state = ST_DONE;
			return AXIS_MOVE_DONE;
		}
		ax->state = ST_SETTLE;
		ax->next_poll = now + c->settle_s;
		return AXIS_MOVE_RUNNING;
	}
	if (ax->retries_left > 0) {
		ax->retries_left--;
		if (start_leg(ax, st.position_deg, now, true, err))
			return fail_move(ax, err);
		return AXIS_MOVE_RUNNING;
	}
	acq_errf(err, ACQ_E_RANGE, "%s: not in position after %d retries: at %.4f°, target %.4f°, deadband %g°",
		 c->name, c->retries, st.position_deg, ax->target, c->deadband);
	return fail_move(ax, err);
}

static int mb_move_retries_used(const struct axis_dev *ax)
{
	return ax->cfg->retries - ax->retries_left;
}

static int mb_stop(struct axis_dev *ax, struct acq_err *err)
{
	struct acq_err local;
	if (!err)
		err = &local;
	if (mb_reg_clear_pending(ax, err) && !ax->link->up)
		return -1;
	int rc = mb_reg_send_cmd(ax, RM_CMD_STOP, true, err);
	if (ax->state == ST_MOVE || ax->state == ST_HOME || ax->state == ST_SETTLE) {
		ax->state = ST_FAILED;
		acq_errf(&ax->fail, ACQ_E_STATE, "%s: move stopped by request", ax->cfg->name);
	}
	return rc;
}

static int mb_home_begin(struct axis_dev *ax, double now, struct acq_err *err)
{
	if (ax->state == ST_MOVE || ax->state == ST_HOME)
		return acq_errf(err, ACQ_E_STATE, "%s: a move is already running", ax->cfg->name);
	if (mb_reg_clear_pending(ax, err) || mb_reg_send_cmd(ax, RM_CMD_HOME, false, err))
		return -1;
	ax->state = ST_HOME;
	ax->leg = 0;
	ax->leg_start = now;
	ax->seen_busy = false;
	ax->deadline = now + ax->cfg->home_timeout_s;
	ax->leg_end = now;
	ax->next_poll = now + ax->cfg->poll_s;
	return 0;
}

static int mb_alarm_reset(struct axis_dev *ax, struct acq_err *err)
{
	if (mb_reg_clear_pending(ax, err) || mb_reg_send_cmd(ax, RM_CMD_ALARM_RESET, true, err))
		return -1;
	if (ax->state == ST_FAILED)
		ax->state = ST_IDLE;
	return 0;
}

static int mb_identity(struct axis_dev *ax, struct axis_identity *id, struct acq_err *err)
{
	const struct regmap *m = ax->cfg->map;
	memset(id, 0, sizeof *id);
	snprintf(id->vendor, sizeof id->vendor, "%s", m->vendor);
	snprintf(id->model, sizeof id->model, "%s", m->model);
	double v;
	if (m->f[RM_SERIAL].present) {
		if (mb_reg_read_field(ax, RM_SERIAL, NULL, &v, err))
			return -1;
		snprintf(id->serial, sizeof id->serial, "%.0f", v);
	}
	if (m->f[RM_FIRMWARE].present) {
		if (mb_reg_read_field(ax, RM_FIRMWARE, NULL, &v, err))
			return -1;
		snprintf(id->firmware, sizeof id->firmware, "%.0f", v);
	}
	return 0;
}

static int mb_reconnect(struct axis_dev *ax, struct acq_err *err)
{
	if (mb_link_connect(ax->link, ax->cfg, err))
		return -1;
	if (ax->state == ST_MOVE || ax->state == ST_HOME || ax->state == ST_SETTLE) {
		ax->state = ST_FAILED;
		acq_errf(&ax->fail, ACQ_E_DISCONNECTED, "%s: link was lost during the move", ax->cfg->name);
	}
	ax->clear_cmd = -1;
	return 0;
}

const struct axis_backend axis_modbus_backend = {
	.name = "modbus", .open = mb_open, .close = mb_close, .read_status = mb_read_status,
	.move_begin = mb_move_begin, .move_step = mb_move_step, .next_poll = mb_next_poll, .stop = mb_stop,
	.home_begin = mb_home_begin, .alarm_reset = mb_alarm_reset, .identity = mb_identity,
	.reconnect = mb_reconnect, .connected = mb_connected,
};

/* ---- extras of the Modbus backend (axis_modbus.h) ---------------------------------------------------- */

static struct axis_dev *mb_of(const struct axis *ax)
{
	return axis_dev_of(ax, &axis_modbus_backend);
}

int axis_open_shared(const struct axis_cfg *cfg, struct axis *peer, struct axis **out, struct acq_err *err)
{
	struct axis_dev *p = mb_of(peer), *d = NULL;
	if (!p || cfg->link.type == AXIS_LINK_FAKE)
		return acq_errf(err, ACQ_E_INVAL, "%s: only Modbus links can be shared", cfg->name);
	if (mb_open_shared(cfg, p, &d, err))
		return -1;
	return axis_wrap(cfg, &axis_modbus_backend, d, out, err);
}

int axis_read_bits(struct axis *ax, bool *limit_pos, bool *limit_neg, bool *stall, struct acq_err *err)
{
	struct axis_dev *d = mb_of(ax);
	if (!d)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "axis: limit and stall bits need a Modbus axis");
	return mb_read_bits(d, limit_pos, limit_neg, stall, err);
}

double axis_target(const struct axis *ax)
{
	const struct axis_dev *d = mb_of(ax);
	return d ? mb_target(d) : NAN;
}

int axis_move_retries_used(const struct axis *ax)
{
	const struct axis_dev *d = mb_of(ax);
	return d ? mb_move_retries_used(d) : 0;
}
