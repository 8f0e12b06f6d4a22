/* devices_op: the operator's manual operations on the devices (move, home, measure, stop; devices.h): one at a
 * time, each a chain of requests on the devices' ports whose completions come back through devices_op_done. */
#include "daemon/devices_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/loop.h"
#include "daemon/store.h"
#include "drivers/axis.h"
#include "drivers/laser.h"
#include "drivers/spectro.h"

/* ---- manual operations -------------------------------------------------------------------------------------- */

static void op_finish(struct devices *dv, int rc, const struct acq_err *err, json_t *result)
{
	if (dv->op_laser && dv->slot[CONF_DEV_LASER].available) {
		struct req *r = devices_req_new(dv, CONF_DEV_LASER, R_LASER, OWN_MGR);
		if (r)
			r->on = false;
		devices_req_submit(r);
	}
	dv->op_laser = false;
	dv->op_active = false;
	dv->op_kind[0] = 0;
	devices_done_fn done = dv->op_done;
	dv->op_done = NULL;
	if (done)
		done(dv->op_ctx, rc, err, result);
	else
		json_decref(result);
}

static void measure_stored(struct devices *dv, struct req *r)
{
	struct acq_err err = { 0 };
	struct spectro_frame *f = r->frame;
	int n = f->npix > 0 && f->npix <= SPECTRO_MAX_PIXELS ? f->npix : 0;
	float *counts = malloc((size_t)(n ? n : 1) * sizeof *counts);
	if (!counts || !n) {
		free(counts);
		acq_errf(&err, n ? ACQ_E_NOMEM : ACQ_E_DEVICE, n ? "out of memory" : "spectrometer returned no pixels");
		op_finish(dv, -1, &err, NULL);
		return;
	}
	double peak = 0;
	for (int i = 0; i < n; i++) {
		counts[i] = (float)f->counts[i];
		if (f->counts[i] > peak)
			peak = f->counts[i];
	}
	struct store_spectrum sp = { .kind = dv->op_kind, .spectrometer_id = dv->spectro_id,
				     .integration_ms = f->meas.integration_ms, .averages = (int)f->meas.averages,
				     .npix = n, .counts = counts, .stddev = f->stddev, .saturated_count = f->nsaturated,
				     .saturated = f->saturated, .temperature_c = f->temperature_c,
				     .taken_at = dv->wallclock() };
	int64_t id = 0;
	int rc = store_spectrum_add(dv->st, &sp, &id, &err);
	free(counts);
	if (rc) {
		op_finish(dv, -1, &err, NULL);
		return;
	}
	op_finish(dv, 0, NULL,
		  json_pack("{s:I,s:s,s:i,s:f,s:i,s:f,s:i}", "spectrum_id", (json_int_t)id, "kind", dv->op_kind, "npix", n,
			    "peak", peak, "saturated", f->nsaturated, "integration_ms", f->meas.integration_ms, "averages",
			    (int)f->meas.averages));
}

/* Name the device in a driver's message unless the driver already did. */
static void name_err(struct acq_err *err, int d)
{
	size_t n = strlen(dname(d));
	if (strncmp(err->msg, dname(d), n))
		acq_err_prefix(err, "%s: ", dname(d));
}

void devices_op_done(struct devices *dv, struct req *r)
{
	if (!dv->op_active || r->seq != dv->op_gen)
		return; /* the operation ended (stopped) before this completion */
	if (r->op == R_MOVE || r->op == R_HOME) {
		if (r->rc && !dv->op_rc) {
			dv->op_rc = -1;
			dv->op_err = r->err;
			name_err(&dv->op_err, r->d);
			for (int i = 0; i < 3; i++) /* the others stop too */
				if (i != r->d && dv->slot[i].port)
					port_interrupt(dv->slot[i].port);
		}
		if (--dv->op_waiting > 0)
			return;
		if (dv->op_rc) {
			op_finish(dv, -1, &dv->op_err, NULL);
			return;
		}
		json_t *res = json_object();
		for (int i = 0; i < 3; i++)
			if (dv->slot[i].available && dv->slot[i].have_status)
				json_object_set_new(res, dname(i), json_real(dv->slot[i].ast.position_deg));
		op_finish(dv, 0, NULL, res);
		return;
	}
	if (r->op == R_LASER) { /* the laser is as the measurement needs it: measure */
		if (r->rc || (r->on && !(r->lst.emission && r->lst.interlock_ok && !r->lst.fault)) ||
		    (!r->on && r->lst.emission)) {
			struct acq_err err = r->err;
			if (!r->rc)
				acq_errf(&err, ACQ_E_DEVICE, "laser %s", r->on ? "not emitting (interlock open or fault)"
									   : "still emitting");
			acq_err_prefix(&err, "%s: switching the laser %s: ", dv->op_kind, r->on ? "on" : "off");
			op_finish(dv, -1, &err, NULL);
			return;
		}
		struct req *m = devices_req_new(dv, CONF_DEV_SPECTRO, R_MEASURE, OWN_OP);
		if (m) {
			m->meas = r->meas;
			m->frame = malloc(sizeof *m->frame);
		}
		if (devices_req_submit(m)) {
			struct acq_err err = { 0 };
			acq_errf(&err, ACQ_E_NOMEM, "out of memory");
			op_finish(dv, -1, &err, NULL);
		}
		return;
	}
	if (r->op == R_MEASURE) {
		if (r->rc)
			op_finish(dv, -1, &r->err, NULL);
		else
			measure_stored(dv, r);
	}
}

/* Start the manual operation op (R_MOVE, or R_HOME with alarm reset) on the axes whose target is not NaN, each
 * on its thread, ended after timeout_s. 0 or -1. */
static int begin_axes(struct devices *dv, const double target[3], enum rop op, double timeout_s, devices_done_fn done,
		      void *ctx, struct acq_err *err)
{
	double deadline = loop_now(dv->lp) + timeout_s;
	dv->op_active = true;
	dv->op_gen++;
	dv->op_done = done;
	dv->op_ctx = ctx;
	dv->op_rc = 0;
	dv->op_waiting = 0;
	for (int i = 0; i < 3; i++) {
		if (isnan(target[i]))
			continue;
		struct req *r = devices_req_new(dv, i, op, OWN_OP);
		if (r) {
			r->target = target[i];
			r->on = op == R_HOME;
			r->deadline = deadline;
		}
		if (devices_req_submit(r) == 0)
			dv->op_waiting++;
	}
	if (!dv->op_waiting) {
		dv->op_active = false;
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	return 0;
}

int devices_move(struct devices *dv, const double target[3], devices_done_fn done, void *ctx, struct acq_err *err)
{
	if (dv->op_active)
		return acq_errf(err, ACQ_E_STATE, "a manual operation is already running");
	bool any = false;
	for (int i = 0; i < 3; i++) {
		if (isnan(target[i]))
			continue;
		any = true;
		const char *name = dname(i);
		if (!dv->c->axis[i])
			return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: unavailable (%s)", name, dv->slot[i].note);
		double lo, hi;
		axis_cfg_limits(dv->c->axis[i], &lo, &hi);
		if (!(target[i] >= lo && target[i] <= hi))
			return acq_errf(err, ACQ_E_RANGE, "%s: %g° is outside the soft limits [%g°, %g°]", name, target[i],
					lo, hi);
		if (!dv->slot[i].available)
			return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: unavailable (%s)", name, dv->slot[i].note);
	}
	if (!any)
		return acq_errf(err, ACQ_E_INVAL, "move: give at least one of laser_theta, detector_theta, detector_phi");
	return begin_axes(dv, target, R_MOVE, dv->c->sweep.move_timeout_s, done, ctx, err);
}

int devices_measure(struct devices *dv, const char *kind, double integration_ms, int averages, double power_pct,
		    devices_done_fn done, void *ctx, struct acq_err *err)
{
	if (dv->op_active)
		return acq_errf(err, ACQ_E_STATE, "a manual operation is already running");
	if (!dv->slot[CONF_DEV_SPECTRO].available)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "spectrometer: unavailable (%s)", dv->slot[CONF_DEV_SPECTRO].note);
	/* A dark needs the laser off (and known to be off); a sample or reference needs the beam, switched on for
	 * the measurement only. */
	bool dark = !strcmp(kind, "dark");
	const struct dev_slot *ls = &dv->slot[CONF_DEV_LASER];
	if (!ls->available && (!dark || ls->configured || dv->c->devpresent[CONF_DEV_LASER]))
		return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: the laser is unavailable (%s)", kind, ls->note);
	struct spectro_meas m = { .integration_ms = integration_ms, .averages = (unsigned)averages,
				  .saturation_detection = true };
	if (!(m.integration_ms > 0) || m.averages < 1)
		return acq_errf(err, ACQ_E_INVAL, "spectrometer: integration time must be > 0 ms and averages ≥ 1");
	snprintf(dv->op_kind, sizeof dv->op_kind, "%s", kind);
	dv->op_active = true;
	dv->op_gen++;
	dv->op_done = done;
	dv->op_ctx = ctx;
	dv->op_laser = !dark && ls->available;
	struct req *r;
	if (ls->available) {
		r = devices_req_new(dv, CONF_DEV_LASER, R_LASER, OWN_OP);
		if (r) {
			r->on = !dark;
			r->pct = dark ? NAN : power_pct;
			r->meas = m;
		}
	} else { /* no laser at all: a dark straight away */
		r = devices_req_new(dv, CONF_DEV_SPECTRO, R_MEASURE, OWN_OP);
		if (r) {
			r->meas = m;
			r->frame = malloc(sizeof *r->frame);
		}
	}
	if (devices_req_submit(r)) {
		dv->op_active = false;
		dv->op_laser = false;
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	return 0;
}

int devices_home(struct devices *dv, unsigned mask, devices_done_fn done, void *ctx, struct acq_err *err)
{
	if (dv->op_active)
		return acq_errf(err, ACQ_E_STATE, "a manual operation is already running");
	for (int i = 0; i < 3; i++)
		if ((mask & (1u << i)) && !dv->slot[i].available)
			return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: unavailable (%s)", dname(i),
					dv->slot[i].note[0] ? dv->slot[i].note : "not configured");
	if (!(mask & 7u))
		return acq_errf(err, ACQ_E_INVAL, "home: no axis selected");
	double t[3];
	for (int i = 0; i < 3; i++)
		t[i] = mask & (1u << i) ? 0 : NAN;
	/* a homing run is slower than a move */
	return begin_axes(dv, t, R_HOME, 4 * dv->c->sweep.move_timeout_s, done, ctx, err);
}

int devices_stop(struct devices *dv, bool *stopped, struct acq_err *err)
{
	(void)err;
	*stopped = dv->op_active;
	for (int i = 0; i < 3; i++) { /* every axis, moving or not: whatever moves stops */
		if (!dv->slot[i].available || !dv->slot[i].port)
			continue;
		port_interrupt(dv->slot[i].port);
		devices_req_submit(devices_req_new(dv, i, R_STOP, OWN_MGR));
	}
	if (*stopped) {
		struct dev_slot *sp = &dv->slot[CONF_DEV_SPECTRO];
		if (dv->op_kind[0] && sp->available && sp->port) {
			port_interrupt(sp->port);
			devices_req_submit(devices_req_new(dv, CONF_DEV_SPECTRO, R_SPECTRO_STOP, OWN_MGR));
		}
		struct acq_err e = { 0 };
		acq_errf(&e, ACQ_E_STATE, "stopped by the operator");
		op_finish(dv, -1, &e, NULL); /* also switches off a laser it switched on */
	}
	return 0;
}
