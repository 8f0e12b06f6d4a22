/* executor motion: verify positions and home, plan the waypoints to the next target (the planner's own or a
 * fresh collision-free path), move segment by segment, settle and read the positions actually reached. */
#include "daemon/executor_int.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "drivers/axis.h"

/* ---- motion ----------------------------------------------------------------------------------- */

static const struct plan_pos *target_pos(const struct ex *x)
{
	return x->in_reference ? &x->cfg.ref_pose : &x->plan->steps[x->cur].pos;
}

static double axis_val(const struct plan_pos *p, int a)
{
	return a == 0 ? p->laser_theta : a == 1 ? p->det_theta : p->det_phi;
}

static bool near_pos(const struct plan_pos *a, const struct plan_pos *b)
{
	for (int i = 0; i < 3; i++)
		if (fabs(axis_val(a, i) - axis_val(b, i)) > EX_POS_TOL_DEG)
			return false;
	return true;
}

/* Last resort after a move stopped inside the clearance (one axis's alarm while the others went on): the detector
 * straight away from the laser, never closer, then the planner's path (plan_escape). 0, or -1 with no such way. */
static int escape(struct ex *x, const struct plan_pos *t, struct plan_wp w[PLAN_MAX_WP + 1], size_t *n)
{
	*n = 0;
	if (!x->known_valid || plan_escape(&x->geom, &x->known, t, w, n) < 0)
		return -1;
	ex_event(x, "info", NULL,
		 "arms inside the clearance at (%.2f, %.2f, %.2f), ψ %.2f°: moving the detector away from the laser to "
		 "(%.2f, %.2f, %.2f) first", x->known.laser_theta, x->known.det_theta, x->known.det_phi,
		 plan_psi_deg(&x->geom, &x->known), w[0].pos.laser_theta, w[0].pos.det_theta, w[0].pos.det_phi);
	return 0;
}

/* Waypoints to the current target: the planner's own when coming from the previous planned point, else a
 * fresh collision-free path from where the arms are. */
/* φ is periodic: bring a detector azimuth inside the axis's soft limits by whole turns when it is outside. */
static double wrap_phi(const struct ex *x, double phi)
{
	if (!x->ops.limits)
		return phi;
	double lo = -INFINITY, hi = INFINITY;
	x->ops.limits(x->octx, EX_DEV_DETECTOR_PHI, &lo, &hi);
	for (int i = 0; i < 4 && phi > hi; i++)
		phi -= 360.0;
	for (int i = 0; i < 4 && phi < lo; i++)
		phi += 360.0;
	return phi;
}

/* The turn of φ (within the soft limits) nearest to where the detector is. */
static double nearest_phi(const struct ex *x, double phi, double from)
{
	double lo = -INFINITY, hi = INFINITY, best = wrap_phi(x, phi);
	if (x->ops.limits)
		x->ops.limits(x->octx, EX_DEV_DETECTOR_PHI, &lo, &hi);
	for (int k = -2; k <= 2; k++) {
		double c = phi + 360.0 * k;
		if (c >= lo && c <= hi && fabs(c - from) < fabs(best - from))
			best = c;
	}
	return best;
}

/* Recovery when no clear path leads from where the arms are (an alarm stopped one axis mid-segment while the
 * others ran on or decelerated, leaving the arms off the planned path, e.g. closer together than the planner's
 * margin: the demo once stopped at ψ = 10.99° against a 12° limit): back off along the last segment to where it
 * started, a planned position, if on that move the arms never come closer than they are (ψ ≥ min(its collision
 * limit, ψ now), checked at every instant by plan_seg_keeps: sound), then the planner's path from there. Fills
 * x->wps with the back-off and w[*n] with the path after it; 0, or -1 when there is no such way. */
static int back_off(struct ex *x, const struct plan_pos *t, struct plan_wp w[PLAN_MAX_WP], size_t *n)
{
	*n = 0;
	if (!x->known_valid || !x->seg_from_valid || near_pos(&x->known, &x->seg_from))
		return -1;
	double keep = fmin(plan_collision_deg(&x->geom), plan_psi_deg(&x->geom, &x->known)) - 2 * PLAN_EDGE_DEG;
	if (!plan_seg_keeps(&x->geom, &x->known, &x->seg_from, keep) || plan_move(&x->geom, &x->seg_from, t, w, n) < 0)
		return -1;
	x->wps[x->n_wps].pos = x->seg_from;
	x->wps[x->n_wps].duration_s = plan_seg_time(&x->geom, &x->known, &x->seg_from);
	x->n_wps++;
	ex_event(x, "info", NULL,
		 "no clear path from (%.2f, %.2f, %.2f): backing off along the last segment to (%.2f, %.2f, %.2f)",
		 x->known.laser_theta, x->known.det_theta, x->known.det_phi, x->seg_from.laser_theta,
		 x->seg_from.det_theta, x->seg_from.det_phi);
	return 0;
}

/* Waypoints to the current target: the planner's own when the arms are where the planner left them (the
 * previous step) and its path stays inside the soft limits; else a fresh collision-free path from where the
 * arms are, to the turn of φ nearest to the detector. */
int ex_plan_path(struct ex *x)
{
	struct plan_pos t = *target_pos(x);
	x->n_wps = 0;
	x->wp = 0;
	if (!x->first_move && !x->in_reference && x->cur > 0 && x->known_valid &&
	    near_pos(&x->known, &x->plan->steps[x->cur - 1].pos)) {
		const struct plan_step *s = &x->plan->steps[x->cur];
		bool inside = true;
		for (size_t i = 0; i < s->n_wp && i < PLAN_MAX_WP + 1; i++) {
			x->wps[x->n_wps] = x->plan->wps[s->first_wp + i];
			double p = x->wps[x->n_wps].pos.det_phi;
			inside = inside && wrap_phi(x, p) == p;
			x->n_wps++;
		}
		if (x->n_wps > 0 && inside)
			return 0;
		x->n_wps = 0;
	}
	if (x->known_valid)
		t.det_phi = nearest_phi(x, t.det_phi, x->known.det_phi);
	else
		t.det_phi = wrap_phi(x, t.det_phi);
	if (x->known_valid && near_pos(&x->known, &t))
		return 0;
	size_t n = 0;
	struct plan_wp w[PLAN_MAX_WP + 1];
	if (plan_move(&x->geom, &x->known, &t, w, &n) < 0 && back_off(x, &t, w, &n) && escape(x, &t, w, &n))
		return -1;
	for (size_t i = 0; i < n; i++) {
		if (wrap_phi(x, w[i].pos.det_phi) != w[i].pos.det_phi)
			return -1;
		x->wps[x->n_wps++] = w[i];
	}
	return 0;
}

/* Start every axis of the current segment that has to move. 0, or -1 with the failing axis in *dev. */
static int start_segment(struct ex *x, double now, int *dev, struct acq_err *err)
{
	const struct plan_pos *p = &x->wps[x->wp].pos;
	/* only a position a planned path can start from is a way back: a back-off that starts inside the margin and
	 * is itself stopped by an alarm keeps the safe start it was heading for (test_sweep_full met two alarms in a
	 * row under load and paused) */
	if (!x->known_valid || plan_psi_deg(&x->geom, &x->known) >= plan_clearance_deg(&x->geom)) {
		x->seg_from = x->known;
		x->seg_from_valid = x->known_valid;
	}
	for (int a = 0; a < 3; a++) {
		double tgt = axis_val(p, a);
		x->moving[a] = false;
		if (x->known_valid && fabs(axis_val(&x->known, a) - tgt) <= 1e-9)
			continue;
		if (x->ops.move_begin(x->octx, a, tgt, now, err)) {
			*dev = a;
			return -1;
		}
		x->moving[a] = true;
	}
	return 0;
}

/* Start the first waypoint segment of the current move, or go straight to settling when there is none. */
void ex_begin_waypoints(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	if (x->n_wps == 0) {
		x->phase = PH_SETTLE;
		x->settle_until = now;
		x->wake = now;
		return;
	}
	int dev = 0;
	if (start_segment(x, now, &dev, &err)) {
		ex_fault(x, dev, &err);
		return;
	}
	x->wake = now;
}

/* Read the three axes' positions (the reads run side by side; an axis whose answer is in is not asked again
 * while the others are pending). 0, EX_PENDING, or -1 after a fault. */
static int read_positions(struct ex *x, double now, double pos[3], bool homed[3], bool alarm[3])
{
	struct acq_err err = { 0 };
	int pending = 0;
	for (int a = 0; a < 3; a++) {
		if (x->pos_got[a])
			continue;
		x->pos_homed[a] = true;
		x->pos_alarm[a] = false;
		int rc = x->ops.position(x->octx, a, &x->pos_val[a], &x->pos_homed[a], &x->pos_alarm[a], &err);
		if (rc == EX_PENDING) {
			pending++;
		} else if (rc) {
			ex_fault(x, a, &err);
			return -1;
		} else {
			x->pos_got[a] = true;
		}
	}
	if (pending) {
		ex_io_wait(x, now);
		return EX_PENDING;
	}
	for (int a = 0; a < 3; a++) {
		pos[a] = x->pos_val[a];
		homed[a] = x->pos_homed[a];
		alarm[a] = x->pos_alarm[a];
	}
	memset(x->pos_got, 0, sizeof x->pos_got);
	return 0;
}

void ex_run_verify(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	ex_set_phase_text(x, "verifying positions");
	double pos[3];
	bool homed[3], alarm[3];
	if (read_positions(x, now, pos, homed, alarm))
		return;
	/* An axis in alarm is reset once, then read again: still in alarm is a fault. */
	bool reset = false;
	for (int a = 0; a < 3; a++) {
		if (!alarm[a])
			continue;
		if (x->alarm_reset_sent[a]) {
			acq_errf(&err, ACQ_E_DEVICE, "%s still in alarm after an alarm reset", ex_dev_names[a]);
			ex_fault(x, a, &err);
			return;
		}
		if (x->ops.alarm_reset(x->octx, a, &err)) {
			ex_fault(x, a, &err);
			return;
		}
		x->alarm_reset_sent[a] = true;
		reset = true;
		ex_event(x, "info", ex_dev_names[a], "alarm cleared on %s before moving", ex_dev_names[a]);
	}
	if (reset) {
		x->wake = now;
		return;
	}
	memset(x->alarm_reset_sent, 0, sizeof x->alarm_reset_sent);
	/* Homing, when configured: one axis at a time, only when its way home is collision-free. */
	for (int a = 0; a < 3 && x->cfg.home_unhomed; a++) {
		if (homed[a])
			continue;
		struct plan_pos from = { pos[0], pos[1], pos[2] }, to = from;
		if (a == 0)
			to.laser_theta = x->cfg.home_deg[0];
		else if (a == 1)
			to.det_theta = x->cfg.home_deg[1];
		else
			to.det_phi = x->cfg.home_deg[2];
		if (!plan_seg_safe(&x->geom, &from, &to)) {
			ex_pause_now(x, false, "%s is not homed and homing it from (%.2f, %.2f, %.2f) could collide: home it by "
				  "hand and resume", ex_dev_names[a], pos[0], pos[1], pos[2]);
			return;
		}
		if (x->ops.home_begin(x->octx, a, now, &err)) {
			ex_fault(x, a, &err);
			return;
		}
		x->homing[a] = true;
		ex_event(x, "info", ex_dev_names[a], "%s not homed: homing", ex_dev_names[a]);
		x->phase = PH_HOMING;
		ex_set_phase_text(x, "homing");
		x->wake = now;
		return;
	}
	x->known = (struct plan_pos){ pos[0], pos[1], pos[2] };
	x->known_valid = true;
	/* Laser off before any motion (also when a crashed predecessor may have left it on). */
	if (x->stats.laser_on || x->laser_unknown) {
		if (ex_laser_off(x, &err)) {
			ex_fault(x, EX_DEV_LASER, &err);
			return;
		}
		x->laser_confirm = true;
	}
	x->laser_unknown = false;
	x->move_from_verify = true;
	x->phase = PH_LASER_OFF;
	x->wake = now;
}

void ex_run_laser_off(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	if (x->laser_confirm && x->ops.laser_state) {
		bool emission = false, ready = false;
		int rc = x->ops.laser_state(x->octx, &emission, &ready, &err);
		if (rc == EX_PENDING) {
			ex_io_wait(x, now);
			return;
		}
		if (rc == 0 && emission)
			rc = acq_errf(&err, ACQ_E_DEVICE, "laser still emitting after emission off");
		if (rc) {
			ex_fault(x, EX_DEV_LASER, &err);
			return;
		}
	}
	x->laser_confirm = false;
	if (ex_plan_path(x)) {
		if (x->move_from_verify)
			ex_pause_now(x, false, "no collision-free path from (%.2f, %.2f, %.2f) to the next point: move the "
				     "arms and resume", x->known.laser_theta, x->known.det_theta, x->known.det_phi);
		else
			ex_pause_now(x, false, "no collision-free path to point %d: move the arms and resume", x->cur);
		return;
	}
	x->first_move = false;
	x->phase = PH_MOVE;
	if (x->move_from_verify)
		x->point_started = now;
	ex_set_phase_text(x, x->in_reference && x->move_from_verify ? "moving to the reference pose" : "moving");
	ex_begin_waypoints(x, now);
}

/* Step every axis flagged in active[] (a move or a homing): clears the flag of an axis that arrived and
 * lowers *wake to the earliest next poll. 1 while any is still busy, 0 when all arrived, -1 after a fault
 * (already reported through ex_fault()). */
static int step_axes(struct ex *x, bool active[3], double now, double *wake)
{
	struct acq_err err = { 0 };
	int busy = 0;
	for (int a = 0; a < 3; a++) {
		if (!active[a])
			continue;
		double np = x->ops.next_poll(x->octx, a);
		if (now + 1e-12 < np) {
			busy = 1;
			*wake = fmin(*wake, np);
			continue;
		}
		int r = x->ops.move_step(x->octx, a, now, &err);
		if (r == AXIS_MOVE_FAILED) {
			ex_fault(x, a, &err);
			return -1;
		}
		if (r == AXIS_MOVE_DONE) {
			active[a] = false;
			continue;
		}
		busy = 1;
		*wake = fmin(*wake, x->ops.next_poll(x->octx, a));
	}
	return busy;
}

void ex_run_homing(struct ex *x, double now)
{
	double wake = INFINITY;
	int busy = step_axes(x, x->homing, now, &wake);
	if (busy < 0)
		return;
	if (!busy) {
		x->phase = PH_VERIFY;
		x->wake = now;
		return;
	}
	x->wake = fmax(now, wake);
}

void ex_run_move(struct ex *x, double now)
{
	struct acq_err err = { 0 };
	if (x->stats.laser_on)
		x->stats.laser_on_while_moving++;
	double wake = INFINITY;
	int busy = step_axes(x, x->moving, now, &wake);
	if (busy < 0)
		return;
	if (busy) {
		x->wake = fmax(now, wake);
		return;
	}
	x->known = x->wps[x->wp].pos;
	x->known_valid = true;
	if (++x->wp < x->n_wps) {
		int dev = 0;
		if (start_segment(x, now, &dev, &err)) {
			ex_fault(x, dev, &err);
			return;
		}
		x->wake = now;
		return;
	}
	x->phase = PH_SETTLE;
	x->settle_until = now + x->cfg.extra_settle_s;
	ex_set_phase_text(x, "settling");
	x->wake = x->settle_until;
}

void ex_run_settle(struct ex *x, double now)
{
	if (now + 1e-12 < x->settle_until) {
		x->wake = x->settle_until;
		return;
	}
	struct acq_err err = { 0 };
	double pos[3];
	bool homed[3], alarm[3];
	if (read_positions(x, now, pos, homed, alarm))
		return;
	for (int a = 0; a < 3; a++) {
		if (alarm[a]) {
			acq_errf(&err, ACQ_E_DEVICE, "%s in alarm after the move", ex_dev_names[a]);
			ex_fault(x, a, &err);
			return;
		}
	}
	x->actual = (struct plan_pos){ pos[0], pos[1], pos[2] };
	if (!ex_want_wl(x)) {
		acq_errf(&err, ACQ_E_DISCONNECTED, "spectrometer information unavailable");
		ex_fault(x, EX_DEV_SPECTRO, &err);
		return;
	}
	x->phase = PH_ACQ;
	ex_reset_acq(x);
	x->attempts = 0;
	ex_set_phase_text(x, x->in_reference ? "reference" : "acquiring");
	x->wake = now;
}
