/* devices_ex: the sweep executor's device operations (executor.h) over the devices' ports (devices.c).
 * Commands (move, home, stop, alarm reset, laser, power, spectrometer start/stop) are queued and return at once;
 * their outcome comes through the polls (move_step, spectro_fetch) or the next read. Reads (position, laser
 * state, reconnect) return EX_PENDING until their completion has kicked the executor, then the result; a laser
 * state read right after a laser switch is the switch's own read-back (R_LASER reads the laser after switching). */
#include "daemon/devices_int.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/executor.h"
#include "daemon/loop.h"

/* A result the executor has not taken within this many real seconds is stale (it was abandoned). */
#define EX_STALE_REAL_S 1.0
/* While an executor request runs, the executor is stepped again at the latest after this (clock seconds);
 * the completion kicks it sooner. */
#define EX_RECHECK_S 0.5

static double real_now(void)
{
	return loop_monotonic(NULL);
}

void devices_ex_done(struct devices *dv, struct req *r)
{
	struct xview *x = &dv->slot[r->d].x;
	bool kick = false;
	if ((r->op == R_MOVE || r->op == R_HOME) && x->move == XW_RUNNING && r->seq == x->move_seq) {
		x->move = r->rc ? XW_FAILED : XW_READY;
		x->move_err = r->err;
		kick = true;
	} else if (r->op == R_STATUS && x->read == XW_RUNNING && r->seq == x->read_seq) {
		x->read = XW_READY;
		x->read_rc = r->rc;
		x->read_err = r->err;
		x->ast = r->ast;
		x->lst = r->lst;
		x->read_real = real_now();
		kick = true;
	} else if (r->op == R_MEASURE && x->meas == XW_RUNNING && r->seq == x->meas_seq) {
		x->meas = r->rc ? XW_FAILED : XW_READY;
		x->meas_err = r->err;
		if (!r->rc) {
			free(x->frame);
			x->frame = r->frame;
			r->frame = NULL;
		}
		kick = true;
	} else if ((r->op == R_LASER || r->op == R_POWER || r->op == R_ALARM_RESET) && r->rc && !x->sticky) {
		x->sticky = true; /* reported by the next read of this device */
		x->sticky_err = r->err;
		kick = true;
	}
	if (r->op == R_LASER) {
		if (r->seq == x->lcmd_seq)
			x->lcmd_seq = 0;
		/* ex_read waits for this read-back (also when a later command made it stale: ex_read then reads again) */
		if (x->read == XW_RUNNING && r->seq == x->read_seq) {
			x->read = XW_READY;
			x->read_rc = r->have_lst ? 0 : -1; /* without one the switch failed: sticky says why */
			x->read_err = r->err;
			x->lst = r->lst;
			x->read_real = real_now();
			kick = true;
		}
	}
	if (kick && dv->kick)
		dv->kick(dv->kick_ctx);
}

static struct dev_slot *ex_slot(struct devices *dv, int d, struct acq_err *err)
{
	struct dev_slot *s = &dv->slot[d];
	if (!s->available || !s->port) {
		acq_errf(err, ACQ_E_DISCONNECTED, "%s unavailable", dname(d));
		return NULL;
	}
	return s;
}

/* Queue an executor command on slot d; its failure (if any) is reported by the next read. */
static int ex_command(struct devices *dv, int d, enum rop op, double target, bool on, double pct,
		      struct acq_err *err)
{
	struct dev_slot *s = ex_slot(dv, d, err);
	if (!s)
		return -1;
	struct req *r = devices_req_new(dv, d, op, OWN_EX);
	if (!r)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	r->seq = s->x.cmd_seq = ++s->x.seq;
	if (op == R_LASER)
		s->x.lcmd_seq = r->seq;
	r->target = target;
	r->on = on;
	r->pct = pct;
	if (op == R_MOVE || op == R_HOME) {
		s->x.move = XW_RUNNING;
		s->x.move_seq = r->seq;
	}
	return devices_req_submit(r) ? acq_errf(err, ACQ_E_NOMEM, "out of memory") : 0;
}

/* A read of slot d: the result when one is in (0 or -1), else EX_PENDING (a read is queued or running). */
static int ex_read(struct devices *dv, int d, struct acq_err *err)
{
	struct dev_slot *s = ex_slot(dv, d, err);
	if (!s)
		return -1;
	struct xview *x = &s->x;
	if (x->read == XW_READY && real_now() - x->read_real > EX_STALE_REAL_S)
		x->read = XW_IDLE; /* nobody took it in time: read again */
	if (x->read == XW_READY && (int)(x->cmd_seq - x->read_seq) > 0)
		x->read = XW_IDLE; /* queued before the latest command (e.g. emission off): it cannot tell its outcome */
	if (x->read == XW_READY) {
		x->read = XW_IDLE;
		if (x->sticky) {
			x->sticky = false;
			if (err)
				*err = x->sticky_err;
			return -1;
		}
		if (x->read_rc && err)
			*err = x->read_err;
		return x->read_rc ? -1 : 0;
	}
	if (x->read == XW_IDLE && x->lcmd_seq && x->lcmd_seq == x->cmd_seq) {
		x->read_seq = x->lcmd_seq; /* the laser switch in flight reads the laser back after it: take that */
		x->read = XW_RUNNING;
	}
	if (x->read == XW_IDLE) {
		struct req *r = devices_req_new(dv, d, R_STATUS, OWN_EX);
		if (!r)
			return acq_errf(err, ACQ_E_NOMEM, "out of memory");
		r->seq = x->read_seq = ++x->seq;
		x->read = XW_RUNNING;
		if (devices_req_submit(r)) {
			x->read = XW_IDLE;
			return acq_errf(err, ACQ_E_NOMEM, "out of memory");
		}
	}
	return EX_PENDING;
}

static int o_move_begin(void *ctx, int a, double target, double now, struct acq_err *err)
{
	(void)now;
	return ex_command(ctx, a, R_MOVE, target, false, NAN, err);
}

static int o_home_begin(void *ctx, int a, double now, struct acq_err *err)
{
	(void)now;
	return ex_command(ctx, a, R_HOME, 0, false, NAN, err);
}

static int o_move_step(void *ctx, int a, double now, struct acq_err *err)
{
	(void)now;
	struct devices *dv = ctx;
	struct dev_slot *s = ex_slot(dv, a, err);
	if (!s)
		return AXIS_MOVE_FAILED;
	switch (s->x.move) {
	case XW_RUNNING: return AXIS_MOVE_RUNNING;
	case XW_FAILED:
		s->x.move = XW_IDLE;
		if (err)
			*err = s->x.move_err;
		return AXIS_MOVE_FAILED;
	default: s->x.move = XW_IDLE; return AXIS_MOVE_DONE;
	}
}

static double o_next_poll(void *ctx, int a)
{
	struct devices *dv = ctx;
	/* Running: look again a little later (the completion kicks sooner); else the result is in: now. */
	return dv->slot[a].available && dv->slot[a].x.move == XW_RUNNING ? loop_now(dv->lp) + EX_RECHECK_S : -INFINITY;
}

static int o_stop(void *ctx, int a, struct acq_err *err)
{
	struct devices *dv = ctx;
	struct dev_slot *s = ex_slot(dv, a, err);
	if (!s)
		return -1;
	port_interrupt(s->port);
	s->x.move = XW_IDLE;
	s->x.seq++;
	struct req *r = devices_req_new(dv, a, R_STOP, OWN_MGR);
	return devices_req_submit(r) ? acq_errf(err, ACQ_E_NOMEM, "out of memory") : 0;
}

static int o_position(void *ctx, int a, double *deg, bool *homed, bool *alarm, struct acq_err *err)
{
	struct devices *dv = ctx;
	int rc = ex_read(dv, a, err);
	if (rc == 0) {
		const struct axis_status *st = &dv->slot[a].x.ast;
		*deg = st->position_deg;
		*homed = st->homed;
		*alarm = st->alarm;
	}
	return rc;
}

static int o_alarm_reset(void *ctx, int a, struct acq_err *err)
{
	return ex_command(ctx, a, R_ALARM_RESET, 0, false, NAN, err);
}

static int o_laser_set(void *ctx, bool on, struct acq_err *err)
{
	struct devices *dv = ctx;
	if (!dv->slot[CONF_DEV_LASER].available)
		return on ? acq_errf(err, ACQ_E_DISCONNECTED, "laser unavailable") : 0; /* absent = dark */
	return ex_command(dv, CONF_DEV_LASER, R_LASER, 0, on, NAN, err);
}

static int o_laser_power(void *ctx, double pct, struct acq_err *err)
{
	return ex_command(ctx, CONF_DEV_LASER, R_POWER, 0, false, pct, err);
}

static int o_laser_state(void *ctx, bool *emission, bool *ready, struct acq_err *err)
{
	struct devices *dv = ctx;
	int rc = ex_read(dv, CONF_DEV_LASER, err);
	if (rc == 0) {
		const struct laser_status *st = &dv->slot[CONF_DEV_LASER].x.lst;
		*emission = st->emission;
		*ready = st->interlock_ok && !st->fault;
	}
	return rc;
}

/* The device manager reconnects on its own thread; here: is the device back and answering? */
static int o_reconnect(void *ctx, int dev, struct acq_err *err)
{
	struct devices *dv = ctx;
	if (dev == EX_DEV_SPECTRO)
		return ex_slot(dv, dev, err) && dv->slot[dev].info.npix > 0 ? 0 : -1;
	return ex_read(dv, dev, err);
}

static int o_spectro_start(void *ctx, const struct spectro_meas *m, double now, struct acq_err *err)
{
	(void)now;
	struct devices *dv = ctx;
	struct dev_slot *s = ex_slot(dv, CONF_DEV_SPECTRO, err);
	if (!s)
		return -1;
	struct req *r = devices_req_new(dv, CONF_DEV_SPECTRO, R_MEASURE, OWN_EX);
	if (r) {
		r->meas = *m;
		r->frame = malloc(sizeof *r->frame);
		r->seq = s->x.meas_seq = ++s->x.seq;
	}
	s->x.meas = XW_RUNNING;
	if (devices_req_submit(r)) {
		s->x.meas = XW_IDLE;
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	return 0;
}

static int o_spectro_fetch(void *ctx, struct spectro_frame *f, double now, struct acq_err *err)
{
	(void)now;
	struct devices *dv = ctx;
	struct dev_slot *s = ex_slot(dv, CONF_DEV_SPECTRO, err);
	if (!s)
		return -1;
	switch (s->x.meas) {
	case XW_RUNNING: return 0;
	case XW_READY:
		s->x.meas = XW_IDLE;
		memcpy(f, s->x.frame, sizeof *f);
		return 1;
	case XW_FAILED:
		s->x.meas = XW_IDLE;
		if (err)
			*err = s->x.meas_err;
		return -1;
	default: return acq_errf(err, ACQ_E_STATE, "spectrometer: no measurement running");
	}
}

static int o_spectro_stop(void *ctx, struct acq_err *err)
{
	(void)err;
	struct devices *dv = ctx;
	struct dev_slot *s = &dv->slot[CONF_DEV_SPECTRO];
	if (!s->available || !s->port || s->x.meas != XW_RUNNING)
		return 0;
	s->x.meas = XW_IDLE;
	s->x.seq++;
	port_interrupt(s->port);
	return 0;
}

static const struct spectro_info *o_spectro_info(void *ctx)
{
	struct devices *dv = ctx;
	const struct dev_slot *s = &dv->slot[CONF_DEV_SPECTRO];
	return s->available && s->info.npix > 0 ? &s->info : NULL;
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
		if (dev != EX_DEV_SPECTRO || dv->slot[dev].available)
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
	.laser_set = o_laser_set, .laser_power = o_laser_power, .laser_state = o_laser_state,
	.spectro_start = o_spectro_start, .spectro_fetch = o_spectro_fetch, .spectro_stop = o_spectro_stop,
	.spectro_info = o_spectro_info, .wall = o_wall, .lost = o_lost, .limits = o_limits,
};

const struct ex_ops *devices_ex_ops(void)
{
	return &ex_dev_ops;
}
