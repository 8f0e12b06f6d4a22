/* axis_fake: the axis backend without hardware (axis_fake.h): moves take move_s on the caller's clock, then the
 * position is the target; failures are injected through the per-name state. */
#include "drivers/axis_fake.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "drivers/axis_backend.h"
#include "drivers/axis_modbus.h"

enum { FAKE_MAX = 8 };
enum fake_state { FK_IDLE, FK_MOVE, FK_HOME, FK_FAILED };

static struct axis_fake fakes[FAKE_MAX];
static int nfakes;
static pthread_mutex_t fake_lock = PTHREAD_MUTEX_INITIALIZER;

struct axis_dev {
	const struct axis_cfg *cfg;
	struct axis_fake *f;
	enum fake_state state;
	double target, t_end;
	struct acq_err fail;
};

struct axis_fake *axis_fake_get(const char *name)
{
	struct axis_fake *f = NULL;
	pthread_mutex_lock(&fake_lock);
	for (int i = 0; i < nfakes && !f; i++)
		if (!strcmp(fakes[i].name, name))
			f = &fakes[i];
	if (!f && nfakes < FAKE_MAX) {
		f = &fakes[nfakes++];
		memset(f, 0, sizeof *f);
		snprintf(f->name, sizeof f->name, "%s", name);
		f->homed = true;
	}
	pthread_mutex_unlock(&fake_lock);
	return f;
}

void axis_fake_reset(void)
{
	pthread_mutex_lock(&fake_lock);
	memset(fakes, 0, sizeof fakes);
	nfakes = 0;
	pthread_mutex_unlock(&fake_lock);
}

/* An injected slow answer: block the caller (outside the lock). */
static void answer_late(const struct axis_dev *d)
{
	double s = d->f->delay_s;
	if (s > 0) {
		struct timespec ts = { (time_t)s, (long)((s - floor(s)) * 1e9) };
		nanosleep(&ts, NULL);
	}
}

/* Injected I/O failure: -1 with the fake's code, else 0. Called with the lock held. */
static int io_fail(const struct axis_dev *d, const char *what, struct acq_err *err)
{
	if (!d->f->fail_io)
		return 0;
	return acq_errf(err, d->f->fail_io, "%s (fake): %s failed (injected %s)", d->f->name, what,
			acq_errname(d->f->fail_io));
}

static int fk_open(const struct axis_cfg *cfg, struct axis_dev **out, struct acq_err *err)
{
	struct axis_fake *f = axis_fake_get(axis_cfg_name(cfg));
	if (!f)
		return acq_errf(err, ACQ_E_NOMEM, "%s (fake): too many fake axes", axis_cfg_name(cfg));
	pthread_mutex_lock(&fake_lock);
	int rc = f->fail_open ? acq_errf(err, ACQ_E_DISCONNECTED, "%s (fake): no answer (injected)", f->name) : 0;
	if (!rc)
		f->opens++;
	pthread_mutex_unlock(&fake_lock);
	if (rc)
		return -1;
	struct axis_dev *d = calloc(1, sizeof *d);
	if (!d)
		return acq_errf(err, ACQ_E_NOMEM, "%s (fake): out of memory", f->name);
	d->cfg = cfg;
	d->f = f;
	*out = d;
	return 0;
}

static void fk_close(struct axis_dev *d)
{
	free(d);
}

static int fk_read_status(struct axis_dev *d, struct axis_status *st, struct acq_err *err)
{
	answer_late(d);
	memset(st, 0, sizeof *st);
	pthread_mutex_lock(&fake_lock);
	int rc = io_fail(d, "reading the status", err);
	st->position_deg = d->f->pos;
	st->homed = d->f->homed;
	st->alarm = d->f->alarm;
	st->alarm_code = d->f->alarm ? d->f->alarm_code : 0;
	st->busy = d->state == FK_MOVE || d->state == FK_HOME;
	st->ready = !st->busy && !st->alarm;
	st->in_position = !st->busy;
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static int fk_move_begin(struct axis_dev *d, double target, double now, struct acq_err *err)
{
	answer_late(d);
	double lo, hi;
	axis_cfg_limits(d->cfg, &lo, &hi);
	if (!(target >= lo && target <= hi))
		return acq_errf(err, ACQ_E_RANGE, "%s (fake): target %g° outside the soft limits [%g°, %g°]", d->f->name,
				target, lo, hi);
	pthread_mutex_lock(&fake_lock);
	int rc = io_fail(d, "starting a move", err);
	if (!rc && d->f->alarm)
		rc = acq_errf(err, ACQ_E_DEVICE, "%s (fake): in alarm: reset it first", d->f->name);
	if (!rc) {
		d->f->moves++;
		d->state = FK_MOVE;
		d->target = target;
		d->t_end = now + d->f->move_s;
	}
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static int fk_move_step(struct axis_dev *d, double now, struct acq_err *err)
{
	int r = AXIS_MOVE_DONE;
	pthread_mutex_lock(&fake_lock);
	if (d->state == FK_FAILED) {
		if (err)
			*err = d->fail;
		r = AXIS_MOVE_FAILED;
	} else if (d->state == FK_MOVE || d->state == FK_HOME) {
		if (io_fail(d, d->state == FK_HOME ? "homing" : "a move", &d->fail)) {
			d->state = FK_FAILED;
			if (err)
				*err = d->fail;
			r = AXIS_MOVE_FAILED;
		} else if (now + 1e-12 < d->t_end) {
			r = AXIS_MOVE_RUNNING;
		} else {
			d->f->pos = d->target;
			if (d->state == FK_HOME)
				d->f->homed = true;
			d->state = FK_IDLE;
		}
	}
	pthread_mutex_unlock(&fake_lock);
	return r;
}

static double fk_next_poll(const struct axis_dev *d)
{
	return d->t_end;
}

static int fk_stop(struct axis_dev *d, struct acq_err *err)
{
	answer_late(d);
	pthread_mutex_lock(&fake_lock);
	d->f->stops++;
	if (d->state == FK_MOVE || d->state == FK_HOME) {
		d->state = FK_FAILED;
		acq_errf(&d->fail, ACQ_E_STATE, "%s (fake): move stopped by request", d->f->name);
	}
	int rc = io_fail(d, "stop", err);
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static int fk_home_begin(struct axis_dev *d, double now, struct acq_err *err)
{
	answer_late(d);
	pthread_mutex_lock(&fake_lock);
	int rc = io_fail(d, "homing", err);
	if (!rc) {
		d->f->homings++;
		d->state = FK_HOME;
		d->target = 0;
		d->t_end = now + d->f->move_s;
	}
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static int fk_alarm_reset(struct axis_dev *d, struct acq_err *err)
{
	answer_late(d);
	pthread_mutex_lock(&fake_lock);
	int rc = io_fail(d, "alarm reset", err);
	if (!rc) {
		d->f->resets++;
		d->f->alarm = false;
		if (d->state == FK_FAILED)
			d->state = FK_IDLE;
	}
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static int fk_identity(struct axis_dev *d, struct axis_identity *id, struct acq_err *err)
{
	memset(id, 0, sizeof *id);
	pthread_mutex_lock(&fake_lock);
	int rc = io_fail(d, "identity", err);
	pthread_mutex_unlock(&fake_lock);
	snprintf(id->vendor, sizeof id->vendor, "fake");
	snprintf(id->model, sizeof id->model, "axis");
	snprintf(id->serial, sizeof id->serial, "%s", d->f->name);
	snprintf(id->firmware, sizeof id->firmware, "1");
	return rc;
}

static int fk_reconnect(struct axis_dev *d, struct acq_err *err)
{
	answer_late(d);
	pthread_mutex_lock(&fake_lock);
	int rc = io_fail(d, "reconnect", err);
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static bool fk_connected(const struct axis_dev *d)
{
	return !d->f->fail_io;
}

const struct axis_backend axis_fake_backend = {
	.name = "fake", .open = fk_open, .close = fk_close, .read_status = fk_read_status, .move_begin = fk_move_begin,
	.move_step = fk_move_step, .next_poll = fk_next_poll, .stop = fk_stop, .home_begin = fk_home_begin,
	.alarm_reset = fk_alarm_reset, .identity = fk_identity, .reconnect = fk_reconnect, .connected = fk_connected,
};
