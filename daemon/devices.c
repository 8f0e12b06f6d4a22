/* devices: opening, reconnecting and reporting the bench's devices; manual move and measure (devices.h). */
#include "daemon/devices.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/executor.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/store.h"
#include "drivers/axis.h"
#include "drivers/laser.h"
#include "drivers/spectro.h"

struct dev_slot {
	bool configured, available;
	char note[512];          /* why unavailable / last error */
	char vendor[64], model[64], serial[64], firmware[64];
};

const struct devices_drv devices_real_drv = {
	axis_open, axis_close, axis_cfg_limits, axis_read_status, axis_move_begin, axis_move_step, axis_stop,
	axis_identity, spectro_open, spectro_close, spectro_info, spectro_start, spectro_fetch, spectro_stop,
	laser_open, laser_close, laser_set_emission, laser_set_power, laser_status, laser_identity, axis_home_begin,
	axis_alarm_reset,
};

struct devices {
	const struct devices_drv *drv;
	struct loop *lp;
	struct store *st;
	const struct conf *c;
	devices_notify_fn notify;
	void *ctx;
	double (*wallclock)(void);
	struct dev_slot slot[CONF_DEV__COUNT];
	struct axis *axis[3];
	struct spectro *spectro;
	struct laser *laser;
	int64_t spectro_id;
	uint64_t retry_timer;
	int retry_next;          /* the slot the next retry starts from */
	/* manual operation in progress */
	uint64_t op_timer;
	devices_done_fn op_done;
	void *op_ctx;
	double op_deadline;
	bool op_axis[3];
	char op_kind[16];
	bool op_laser;           /* the laser was switched on for this measurement: off at its end */
	struct spectro_frame *frame;
};

static void set_identity(struct dev_slot *s, const char *vendor, const char *model, const char *serial,
			 const char *fw)
{
	snprintf(s->vendor, sizeof s->vendor, "%s", vendor);
	snprintf(s->model, sizeof s->model, "%s", model);
	snprintf(s->serial, sizeof s->serial, "%s", serial);
	snprintf(s->firmware, sizeof s->firmware, "%s", fw);
}

/* Try to open slot d; on success record its identity in the store. */
static void try_open(struct devices *dv, enum conf_dev d)
{
	struct dev_slot *s = &dv->slot[d];
	struct acq_err err = { 0 };
	int rc = -1;
	double now = dv->wallclock();
	if (d <= CONF_DEV_DETECTOR_PHI) {
		rc = dv->drv->axis_open(dv->c->axis[d], &dv->axis[d], &err);
		struct axis_identity id = { 0 };
		if (!rc && !dv->drv->axis_identity(dv->axis[d], &id, NULL))
			set_identity(s, id.vendor, id.model, id.serial, id.firmware);
	} else if (d == CONF_DEV_SPECTRO) {
		rc = dv->drv->spectro_open(dv->c->spectro, &dv->spectro, &err);
		if (!rc) {
			const struct spectro_info *in = dv->drv->spectro_info(dv->spectro);
			set_identity(s, "Avantes", in->model, in->serial, in->firmware);
			if (store_spectrometer_put(dv->st, in, now, &dv->spectro_id, &err))
				snprintf(s->note, sizeof s->note, "recording calibration: %s", err.msg);
		}
	} else {
		rc = dv->drv->laser_open(dv->c->laser, &dv->laser, &err);
		if (!rc) {
			const struct laser_identity *li = dv->drv->laser_identity(dv->laser);
			set_identity(s, "", li->model, li->serial, li->firmware);
		}
	}
	if (rc) {
		bool changed = strcmp(s->note, err.msg) != 0;
		snprintf(s->note, sizeof s->note, "%s", err.msg);
		if (changed && dv->notify)
			dv->notify(dv->ctx, d, false, s->note);
		return;
	}
	s->available = true;
	s->note[0] = 0;
	if (d != CONF_DEV_SPECTRO)
		store_device_put(dv->st, conf_dev_name(d), s->vendor, s->model, s->serial, s->firmware, now, NULL, NULL);
	if (dv->notify)
		dv->notify(dv->ctx, d, true, "connected");
}

/* One absent device per tick, in turn: an open is a bounded transaction (up to the link's response
 * timeout), so trying them all at once could hold the loop for several timeouts in a row. */
static void retry_cb(struct loop *lp, void *arg)
{
	(void)lp;
	struct devices *dv = arg;
	if (dv->op_timer)
		return;
	for (int k = 0; k < CONF_DEV__COUNT; k++) {
		int d = (dv->retry_next + k) % CONF_DEV__COUNT;
		if (dv->slot[d].configured && !dv->slot[d].available) {
			dv->retry_next = (d + 1) % CONF_DEV__COUNT;
			try_open(dv, (enum conf_dev)d);
			return;
		}
	}
}

static void op_end(struct devices *dv, int rc, const struct acq_err *err, json_t *result);

/* Open every configured device of dv->c (those that fail stay unavailable) and arm the retry timer. */
static void open_all(struct devices *dv)
{
	const struct conf *c = dv->c;
	for (int d = 0; d < CONF_DEV__COUNT; d++) {
		struct dev_slot *s = &dv->slot[d];
		memset(s, 0, sizeof *s);
		s->configured = d <= CONF_DEV_DETECTOR_PHI ? c->axis[d] != NULL
				: d == CONF_DEV_SPECTRO    ? c->spectro != NULL
							   : c->laser != NULL;
		if (!s->configured)
			snprintf(s->note, sizeof s->note, "%s", c->devnote[d][0] ? c->devnote[d] : "not configured");
		else
			try_open(dv, (enum conf_dev)d);
	}
	dv->retry_timer = loop_timer_add(dv->lp, c->d.device_retry_s, c->d.device_retry_s, retry_cb, dv);
}

/* Safe stop and close every handle (the object stays: the executor keeps its pointer). */
static void close_all(struct devices *dv)
{
	devices_safe_stop(dv);
	loop_timer_cancel(dv->lp, dv->retry_timer);
	dv->retry_timer = 0;
	dv->drv->laser_close(dv->laser);
	dv->laser = NULL;
	for (int i = 0; i < 3; i++) {
		dv->drv->axis_close(dv->axis[i]);
		dv->axis[i] = NULL;
	}
	dv->drv->spectro_close(dv->spectro);
	dv->spectro = NULL;
	dv->spectro_id = 0;
}

int devices_init(struct loop *lp, struct store *st, const struct conf *c, const struct devices_drv *drv,
		 devices_notify_fn notify, void *ctx, double (*wallclock)(void), struct devices **out,
		 struct acq_err *err)
{
	struct devices *dv = calloc(1, sizeof *dv);
	if (!dv)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	*dv = (struct devices){ .drv = drv ? drv : &devices_real_drv, .lp = lp, .st = st, .c = c, .notify = notify,
				.ctx = ctx, .wallclock = wallclock };
	open_all(dv);
	*out = dv;
	return 0;
}

int devices_reconfigure(struct devices *dv, const struct conf *c, struct acq_err *err)
{
	if (dv->op_timer)
		return acq_errf(err, ACQ_E_STATE, "a manual move or measurement is running");
	close_all(dv);
	dv->c = c;
	open_all(dv);
	return 0;
}

int devices_safe_stop(struct devices *dv)
{
	int fails = 0;
	if (!dv)
		return 0;
	struct acq_err err = { 0 };
	if (dv->laser && dv->drv->laser_set_emission(dv->laser, false, &err)) {
		log_msg(LOG_ERR, "safe stop: laser emission off not confirmed: %s", err.msg);
		fails++;
	}
	for (int i = 0; i < 3; i++)
		if (dv->axis[i] && dv->drv->axis_stop(dv->axis[i], &err)) {
			log_msg(LOG_ERR, "safe stop: %s: stop not confirmed: %s", conf_dev_name((enum conf_dev)i), err.msg);
			fails++;
		}
	if (dv->spectro)
		dv->drv->spectro_stop(dv->spectro, NULL);
	return fails;
}

void devices_finish(struct devices *dv)
{
	if (!dv)
		return;
	if (dv->op_timer) { /* a manual operation is cut short: its requester gets an answer */
		struct acq_err err = { 0 };
		acq_errf(&err, ACQ_E_STATE, "the daemon is stopping: operation interrupted");
		op_end(dv, -1, &err, NULL);
	}
	close_all(dv);
	free(dv->frame);
	free(dv);
}

struct axis *devices_axis(struct devices *dv, enum conf_dev d)
{
	return d <= CONF_DEV_DETECTOR_PHI ? dv->axis[d] : NULL;
}

struct spectro *devices_spectro(struct devices *dv)
{
	return dv->spectro;
}

struct laser *devices_laser(struct devices *dv)
{
	return dv->laser;
}

long long devices_spectrometer_id(const struct devices *dv)
{
	return dv->spectro_id;
}

void devices_lost(struct devices *dv, enum conf_dev d, const char *why)
{
	struct dev_slot *s = &dv->slot[d];
	if (d <= CONF_DEV_DETECTOR_PHI) {
		dv->drv->axis_close(dv->axis[d]);
		dv->axis[d] = NULL;
	} else if (d == CONF_DEV_SPECTRO) {
		dv->drv->spectro_close(dv->spectro);
		dv->spectro = NULL;
	} else {
		dv->drv->laser_close(dv->laser);
		dv->laser = NULL;
	}
	bool was = s->available;
	s->available = false;
	snprintf(s->note, sizeof s->note, "%s", why);
	if (was && dv->notify)
		dv->notify(dv->ctx, d, false, why);
}

void devices_positions(struct devices *dv, double pos[3])
{
	for (int i = 0; i < 3; i++) {
		struct axis_status st;
		pos[i] = dv->axis[i] && !dv->drv->axis_read_status(dv->axis[i], &st, NULL) ? st.position_deg : NAN;
	}
}

int devices_available(const struct devices *dv)
{
	int n = 0;
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		n += dv->slot[d].available;
	return n;
}

bool devices_busy(const struct devices *dv)
{
	return dv->op_timer != 0;
}

json_t *devices_json(struct devices *dv)
{
	json_t *arr = json_array();
	for (int d = 0; arr && d < CONF_DEV__COUNT; d++) {
		struct dev_slot *s = &dv->slot[d];
		bool present = s->configured || dv->c->devpresent[d];
		json_t *o = json_pack("{s:s,s:b,s:b,s:s}", "name", conf_dev_name((enum conf_dev)d), "configured",
				      present, "available", s->available, "state",
				      s->available ? "connected" : present ? "unavailable" : "not_configured");
		if (!o)
			continue;
		if (s->note[0])
			json_object_set_new(o, "note", json_string(s->note));
		if (s->available)
			json_object_set_new(o, "identity",
					    json_pack("{s:s,s:s,s:s,s:s}", "vendor", s->vendor, "model", s->model, "serial",
						      s->serial, "firmware", s->firmware));
		if (d <= CONF_DEV_DETECTOR_PHI && dv->c->axis[d]) {
			double lo, hi;
			dv->drv->axis_cfg_limits(dv->c->axis[d], &lo, &hi);
			json_object_set_new(o, "limits_deg", json_pack("[f,f]", lo, hi));
			struct axis_status st;
			if (dv->axis[d] && !dv->drv->axis_read_status(dv->axis[d], &st, NULL))
				json_object_set_new(o, "status",
						    json_pack("{s:f,s:b,s:b,s:b,s:i}", "position_deg", st.position_deg,
							      "busy", st.busy, "homed", st.homed, "alarm", st.alarm,
							      "alarm_code", st.alarm_code));
		}
		if (d == CONF_DEV_LASER && dv->laser) {
			struct laser_status ls;
			if (!dv->drv->laser_status(dv->laser, &ls, NULL))
				json_object_set_new(o, "status",
						    json_pack("{s:b,s:f,s:b,s:b}", "emission", ls.emission, "power_pct",
							      ls.power_pct, "interlock_ok", ls.interlock_ok, "fault",
							      ls.fault));
		}
		json_array_append_new(arr, o);
	}
	return arr;
}

/* ---- manual operations ---- */

/* Name the device in a driver's message unless the driver already did (the log said "x: x: ..."). -1. */
static int name_err(struct acq_err *err, enum conf_dev d)
{
	const char *name = conf_dev_name(d);
	size_t n = strlen(name);
	if (err && strncmp(err->msg, name, n))
		acq_err_prefix(err, "%s: ", name);
	return -1;
}

static void op_end(struct devices *dv, int rc, const struct acq_err *err, json_t *result)
{
	loop_timer_cancel(dv->lp, dv->op_timer);
	dv->op_timer = 0;
	if (dv->op_laser && dv->laser)
		dv->drv->laser_set_emission(dv->laser, false, NULL);
	dv->op_laser = false;
	devices_done_fn done = dv->op_done;
	dv->op_done = NULL;
	if (done)
		done(dv->op_ctx, rc, err, result);
	else
		json_decref(result);
	dv->op_kind[0] = 0;
}

static void move_step(struct loop *lp, void *arg)
{
	struct devices *dv = arg;
	double now = loop_now(lp);
	struct acq_err err = { 0 };
	bool running = false;
	for (int i = 0; i < 3; i++) {
		if (!dv->op_axis[i])
			continue;
		if (!dv->axis[i]) {
			acq_errf(&err, ACQ_E_DISCONNECTED, "%s: lost during the move", conf_dev_name((enum conf_dev)i));
			goto fail;
		}
		int r = dv->drv->axis_move_step(dv->axis[i], now, &err);
		if (r == AXIS_MOVE_FAILED) {
			name_err(&err, (enum conf_dev)i);
			goto fail;
		}
		if (r == AXIS_MOVE_DONE)
			dv->op_axis[i] = false;
		else
			running = true;
	}
	if (running && now > dv->op_deadline) {
		acq_errf(&err, ACQ_E_TIMEOUT, "move not finished after %g s", dv->c->sweep.move_timeout_s);
		goto fail;
	}
	if (running)
		return;
	json_t *res = json_object();
	for (int i = 0; i < 3; i++) {
		struct axis_status st;
		if (dv->axis[i] && !dv->drv->axis_read_status(dv->axis[i], &st, NULL))
			json_object_set_new(res, conf_dev_name((enum conf_dev)i), json_real(st.position_deg));
	}
	op_end(dv, 0, NULL, res);
	return;
fail:
	for (int i = 0; i < 3; i++)
		if (dv->op_axis[i] && dv->axis[i])
			dv->drv->axis_stop(dv->axis[i], NULL);
	op_end(dv, -1, &err, NULL);
}

#define HOME_TARGET INFINITY  /* begin_axes(): home this axis instead of moving it */

/* Start the manual operation on the axes whose target is not NaN (HOME_TARGET: homing), watched by
 * move_step() until they are done or timeout_s passed. 0, or -1 with every started axis stopped again. */
static int begin_axes(struct devices *dv, const double target[3], double timeout_s, devices_done_fn done, void *ctx,
		      struct acq_err *err)
{
	double now = loop_now(dv->lp);
	for (int i = 0; i < 3; i++) {
		dv->op_axis[i] = false;
		if (isnan(target[i]))
			continue;
		if (isinf(target[i]) ? dv->drv->axis_home_begin(dv->axis[i], now, err)
				     : dv->drv->axis_move_begin(dv->axis[i], target[i], now, err)) {
			for (int j = 0; j < i; j++)
				if (dv->op_axis[j])
					dv->drv->axis_stop(dv->axis[j], NULL);
			return name_err(err, (enum conf_dev)i);
		}
		dv->op_axis[i] = true;
	}
	dv->op_done = done;
	dv->op_ctx = ctx;
	dv->op_deadline = now + timeout_s;
	dv->op_timer = loop_timer_add(dv->lp, 0.05, 0.05, move_step, dv);
	return 0;
}

int devices_move(struct devices *dv, const double target[3], devices_done_fn done, void *ctx, struct acq_err *err)
{
	if (dv->op_timer)
		return acq_errf(err, ACQ_E_STATE, "a manual operation is already running");
	bool any = false;
	for (int i = 0; i < 3; i++) {
		if (isnan(target[i]))
			continue;
		any = true;
		const char *name = conf_dev_name((enum conf_dev)i);
		if (!dv->c->axis[i])
			return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: unavailable (%s)", name, dv->slot[i].note);
		double lo, hi;
		dv->drv->axis_cfg_limits(dv->c->axis[i], &lo, &hi);
		if (!(target[i] >= lo && target[i] <= hi))
			return acq_errf(err, ACQ_E_RANGE, "%s: %g° is outside the soft limits [%g°, %g°]", name, target[i],
					lo, hi);
		if (!dv->axis[i])
			return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: unavailable (%s)", name, dv->slot[i].note);
	}
	if (!any)
		return acq_errf(err, ACQ_E_INVAL, "move: give at least one of laser_theta, detector_theta, detector_phi");
	return begin_axes(dv, target, dv->c->sweep.move_timeout_s, done, ctx, err);
}

int devices_home(struct devices *dv, unsigned mask, devices_done_fn done, void *ctx, struct acq_err *err)
{
	if (dv->op_timer)
		return acq_errf(err, ACQ_E_STATE, "a manual operation is already running");
	for (int i = 0; i < 3; i++)
		if ((mask & (1u << i)) && !dv->axis[i])
			return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: unavailable (%s)", conf_dev_name((enum conf_dev)i),
					dv->slot[i].note[0] ? dv->slot[i].note : "not configured");
	if (!(mask & 7u))
		return acq_errf(err, ACQ_E_INVAL, "home: no axis selected");
	double t[3];
	for (int i = 0; i < 3; i++) {
		t[i] = mask & (1u << i) ? HOME_TARGET : NAN;
		struct axis_status st;
		if ((mask & (1u << i)) && !dv->drv->axis_read_status(dv->axis[i], &st, NULL) && st.alarm &&
		    dv->drv->axis_alarm_reset(dv->axis[i], err))
			return acq_err_prefix(err, "%s: resetting its alarm: ", conf_dev_name((enum conf_dev)i));
	}
	/* a homing run is slower than a move */
	return begin_axes(dv, t, 4 * dv->c->sweep.move_timeout_s, done, ctx, err);
}

int devices_stop(struct devices *dv, bool *stopped, struct acq_err *err)
{
	*stopped = dv->op_timer != 0;
	int rc = 0;
	for (int i = 0; i < 3; i++) /* every axis, moving or not: whatever moves stops */
		if (dv->axis[i] && dv->drv->axis_stop(dv->axis[i], err))
			rc = name_err(err, (enum conf_dev)i);
	if (*stopped && dv->op_kind[0] && dv->spectro)
		dv->drv->spectro_stop(dv->spectro, NULL);
	if (*stopped) {
		struct acq_err e = { 0 };
		acq_errf(&e, ACQ_E_STATE, "stopped by the operator");
		for (int i = 0; i < 3; i++)
			dv->op_axis[i] = false;
		op_end(dv, -1, &e, NULL); /* also switches off a laser it switched on */
	}
	return rc;
}

int devices_laser_off(struct devices *dv, struct acq_err *err)
{
	if (!dv->laser)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "laser: unavailable (%s)",
				dv->slot[CONF_DEV_LASER].note[0] ? dv->slot[CONF_DEV_LASER].note : "not configured");
	if (dv->drv->laser_set_emission(dv->laser, false, err))
		return acq_err_prefix(err, "laser: ");
	struct laser_status ls;
	if (dv->drv->laser_status(dv->laser, &ls, err))
		return acq_err_prefix(err, "laser: ");
	if (ls.emission)
		return acq_errf(err, ACQ_E_DEVICE, "laser: emission still reported on after switching it off");
	return 0;
}

static void measure_step(struct loop *lp, void *arg)
{
	struct devices *dv = arg;
	struct acq_err err = { 0 };
	if (!dv->spectro) {
		acq_errf(&err, ACQ_E_DISCONNECTED, "spectrometer lost during the measurement");
		op_end(dv, -1, &err, NULL);
		return;
	}
	int r = dv->drv->spectro_fetch(dv->spectro, dv->frame, loop_now(lp), &err);
	if (r == 0)
		return;
	if (r < 0) {
		op_end(dv, -1, &err, NULL);
		return;
	}
	struct spectro_frame *f = dv->frame;
	int n = f->npix > 0 && f->npix <= SPECTRO_MAX_PIXELS ? f->npix : 0;
	float *counts = malloc((size_t)(n ? n : 1) * sizeof *counts);
	if (!counts || !n) {
		free(counts);
		acq_errf(&err, n ? ACQ_E_NOMEM : ACQ_E_DEVICE, n ? "out of memory" : "spectrometer returned no pixels");
		op_end(dv, -1, &err, NULL);
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
		op_end(dv, -1, &err, NULL);
		return;
	}
	op_end(dv, 0, NULL,
	       json_pack("{s:I,s:s,s:i,s:f,s:i,s:f,s:i}", "spectrum_id", (json_int_t)id, "kind", dv->op_kind, "npix", n,
			 "peak", peak, "saturated", f->nsaturated, "integration_ms", f->meas.integration_ms, "averages",
			 (int)f->meas.averages));
}

int devices_measure(struct devices *dv, const char *kind, double integration_ms, int averages, double power_pct,
		    devices_done_fn done, void *ctx, struct acq_err *err)
{
	if (dv->op_timer)
		return acq_errf(err, ACQ_E_STATE, "a manual operation is already running");
	if (!dv->spectro)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "spectrometer: unavailable (%s)", dv->slot[CONF_DEV_SPECTRO].note);
	/* A dark needs the laser off (and known to be off); a sample or reference needs the beam, switched on for
	 * the measurement only. */
	bool dark = !strcmp(kind, "dark");
	if (!dv->laser && (!dark || dv->slot[CONF_DEV_LASER].configured || dv->c->devpresent[CONF_DEV_LASER]))
		return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: the laser is unavailable (%s)", kind,
				dv->slot[CONF_DEV_LASER].note);
	if (!dark && dv->laser && !isnan(power_pct) && dv->drv->laser_set_power(dv->laser, power_pct, err))
		return acq_err_prefix(err, "%s: setting the laser power: ", kind);
	if (dv->laser && dv->drv->laser_set_emission(dv->laser, !dark, err))
		return acq_err_prefix(err, "%s: switching the laser %s: ", kind, dark ? "off" : "on");
	if (!dv->frame && !(dv->frame = malloc(sizeof *dv->frame)))
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	struct spectro_meas m = { .integration_ms = integration_ms, .averages = (unsigned)averages,
				  .saturation_detection = true };
	if (dv->drv->spectro_start(dv->spectro, &m, loop_now(dv->lp), err)) {
		if (!dark && dv->laser)
			dv->drv->laser_set_emission(dv->laser, false, NULL);
		return -1;
	}
	dv->op_laser = !dark && dv->laser;
	snprintf(dv->op_kind, sizeof dv->op_kind, "%s", kind);
	dv->op_done = done;
	dv->op_ctx = ctx;
	/* Polled by timer: a measurement takes milliseconds to seconds, 10 ms granularity is plenty. */
	dv->op_timer = loop_timer_add(dv->lp, 0.01, 0.01, measure_step, dv);
	return 0;
}

/* ---- the sweep executor's device operations over these handles (executor.h) ------------------------- */

static struct axis *ax_of(struct devices *dv, int a, struct acq_err *err)
{
	struct axis *ax = devices_axis(dv, (enum conf_dev)a);
	if (!ax)
		acq_errf(err, ACQ_E_DISCONNECTED, "%s unavailable", conf_dev_name((enum conf_dev)a));
	return ax;
}

static int o_move_begin(void *ctx, int a, double target, double now, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_move_begin(ax, target, now, err) : -1;
}

static int o_move_step(void *ctx, int a, double now, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_move_step(ax, now, err) : AXIS_MOVE_FAILED;
}

static double o_next_poll(void *ctx, int a)
{
	struct devices *dv = ctx;
	struct axis *ax = devices_axis(dv, (enum conf_dev)a);
	return ax ? axis_next_poll(ax) : loop_now(dv->lp);
}

static int o_stop(void *ctx, int a, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_stop(ax, err) : -1;
}

static int o_position(void *ctx, int a, double *deg, bool *homed, bool *alarm, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	struct axis_status st;
	if (!ax || axis_read_status(ax, &st, err))
		return -1;
	*deg = st.position_deg;
	*homed = st.homed;
	*alarm = st.alarm;
	return 0;
}

static int o_home_begin(void *ctx, int a, double now, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_home_begin(ax, now, err) : -1;
}

static int o_alarm_reset(void *ctx, int a, struct acq_err *err)
{
	struct axis *ax = ax_of(ctx, a, err);
	return ax ? axis_alarm_reset(ax, err) : -1;
}

static int o_laser_set(void *ctx, bool on, struct acq_err *err)
{
	struct devices *dv = ctx;
	struct laser *l = devices_laser(dv);
	if (!l)
		return on ? acq_errf(err, ACQ_E_DISCONNECTED, "laser unavailable") : 0; /* absent = dark */
	return laser_set_emission(l, on, err);
}

static int o_laser_power(void *ctx, double pct, struct acq_err *err)
{
	struct devices *dv = ctx;
	struct laser *l = devices_laser(dv);
	if (!l)
		return acq_errf(err, ACQ_E_DISCONNECTED, "laser unavailable");
	return laser_set_power(l, pct, err);
}

static int o_laser_state(void *ctx, bool *emission, bool *ready, struct acq_err *err)
{
	struct devices *dv = ctx;
	struct laser *l = devices_laser(dv);
	struct laser_status st;
	if (!l)
		return acq_errf(err, ACQ_E_DISCONNECTED, "laser unavailable");
	if (laser_status(l, &st, err))
		return -1;
	*emission = st.emission;
	*ready = st.interlock_ok && !st.fault;
	return 0;
}

/* The daemon's device manager reconnects on its own timer; here: is the device back and answering? */
static int o_reconnect(void *ctx, int dev, struct acq_err *err)
{
	struct devices *dv = ctx;
	if (dev <= EX_DEV_DETECTOR_PHI) {
		bool homed, alarm;
		double d;
		return o_position(ctx, dev, &d, &homed, &alarm, err);
	}
	if (dev == EX_DEV_SPECTRO) {
		struct spectro *s = devices_spectro(dv);
		return s && spectro_info(s) ? 0 : acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer unavailable");
	}
	bool e, r;
	return o_laser_state(ctx, &e, &r, err);
}

static int o_spectro_start(void *ctx, const struct spectro_meas *m, double now, struct acq_err *err)
{
	struct devices *dv = ctx;
	struct spectro *s = devices_spectro(dv);
	if (!s)
		return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer unavailable");
	return spectro_start(s, m, now, err);
}

static int o_spectro_fetch(void *ctx, struct spectro_frame *f, double now, struct acq_err *err)
{
	struct devices *dv = ctx;
	struct spectro *s = devices_spectro(dv);
	if (!s)
		return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer unavailable");
	return spectro_fetch(s, f, now, err);
}

static int o_spectro_stop(void *ctx, struct acq_err *err)
{
	struct devices *dv = ctx;
	struct spectro *s = devices_spectro(dv);
	return s ? spectro_stop(s, err) : 0;
}

static const struct spectro_info *o_spectro_info(void *ctx)
{
	struct devices *dv = ctx;
	struct spectro *s = devices_spectro(dv);
	return s ? spectro_info(s) : NULL;
}

static double o_wall(void *ctx)
{
	struct devices *dv = ctx;
	return dv->wallclock();
}

/* A link-level failure hands the device back to the manager (close, reconnect on its timer); a device that
 * answered with an error (alarm, interlock) keeps its handle. */
static void o_lost(void *ctx, int dev, const struct acq_err *err)
{
	struct devices *dv = ctx;
	int code = err ? err->code : ACQ_E_DEVICE;
	if (code == ACQ_E_TIMEOUT || code == ACQ_E_DISCONNECTED || code == ACQ_E_IO || code == ACQ_E_PROTO)
		if (dev != EX_DEV_SPECTRO || devices_spectro(dv))
			devices_lost(dv, (enum conf_dev)dev, err ? err->msg : "device error");
}

static void o_limits(void *ctx, int a, double *lo, double *hi)
{
	struct devices *dv = ctx;
	const struct axis_cfg *c = a >= 0 && a < 3 ? dv->c->axis[a] : NULL;
	if (c)
		axis_cfg_limits(c, lo, hi);
}

static const struct ex_ops ex_dev_ops = {
	.move_begin = o_move_begin, .move_step = o_move_step, .next_poll = o_next_poll, .stop = o_stop,
	.position = o_position, .home_begin = o_home_begin, .alarm_reset = o_alarm_reset, .reconnect = o_reconnect,
	.laser_set = o_laser_set, .laser_power = o_laser_power, .laser_state = o_laser_state, .spectro_start = o_spectro_start,
	.spectro_fetch = o_spectro_fetch, .spectro_stop = o_spectro_stop, .spectro_info = o_spectro_info,
	.wall = o_wall, .lost = o_lost, .limits = o_limits,
};

const struct ex_ops *devices_ex_ops(void)
{
	return &ex_dev_ops;
}
