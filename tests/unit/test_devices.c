/* Unit tests for daemon/devices.c on fake drivers and a fake clock: opening and identities recorded in the
 * store, manual moves checked against soft limits and stepped to completion, measurements stored (dark
 * switches the laser off first), a lost device reconnected by the retry timer, safe stop at finish. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/conf.h"
#include "daemon/devices.h"
#include "daemon/loop.h"
#include "daemon/store.h"
#include "drivers/axis.h"
#include "drivers/laser.h"
#include "drivers/spectro.h"

/* ---- fakes ---- */
struct axis {
	double pos, target;
	bool moving;
	int stops;
};
struct spectro {
	struct spectro_info info;
	int fetches;
	bool running;
};
struct laser {
	bool emission;
	struct laser_identity id;
};
static struct axis fake_axes[3];
static struct spectro fake_spec;
static struct laser fake_laser;
static int cfg_token[5];
static bool fail_open[5];

static int slot_of_cfg(const void *cfg)
{
	return (int)((const int *)cfg - cfg_token);
}

static int f_axis_open(const struct axis_cfg *cfg, struct axis **out, struct acq_err *err)
{
	int i = slot_of_cfg(cfg);
	if (fail_open[i])
		return acq_errf(err, ACQ_E_DISCONNECTED, "fake axis %d: no answer", i);
	*out = &fake_axes[i];
	return 0;
}
static void f_axis_close(struct axis *ax)
{
	(void)ax;
}
static void f_axis_cfg_limits(const struct axis_cfg *cfg, double *lo, double *hi)
{
	(void)cfg;
	*lo = -10;
	*hi = 90;
}
static int f_axis_read_status(struct axis *ax, struct axis_status *st, struct acq_err *err)
{
	(void)err;
	*st = (struct axis_status){ .position_deg = ax->pos, .ready = true, .busy = ax->moving, .homed = true };
	return 0;
}
static int f_axis_move_begin(struct axis *ax, double target, double now, struct acq_err *err)
{
	(void)now;
	(void)err;
	ax->target = target;
	ax->moving = true;
	return 0;
}
/* Homing: a move to 0. */
static int f_axis_home_begin(struct axis *ax, double now, struct acq_err *err)
{
	return f_axis_move_begin(ax, 0, now, err);
}
static int f_axis_alarm_reset(struct axis *ax, struct acq_err *err)
{
	(void)ax;
	(void)err;
	return 0;
}
/* Moves 10 degrees per step. */
static int f_axis_move_step(struct axis *ax, double now, struct acq_err *err)
{
	(void)now;
	(void)err;
	double d = ax->target - ax->pos;
	ax->pos += fabs(d) <= 10 ? d : (d > 0 ? 10 : -10);
	ax->moving = ax->pos != ax->target;
	return ax->moving ? AXIS_MOVE_RUNNING : AXIS_MOVE_DONE;
}
static int f_axis_stop(struct axis *ax, struct acq_err *err)
{
	(void)err;
	ax->moving = false;
	ax->stops++;
	return 0;
}
static int f_axis_identity(struct axis *ax, struct axis_identity *id, struct acq_err *err)
{
	(void)err;
	snprintf(id->vendor, sizeof id->vendor, "FakeMotion");
	snprintf(id->model, sizeof id->model, "AX-%d", (int)(ax - fake_axes));
	snprintf(id->serial, sizeof id->serial, "S%d", (int)(ax - fake_axes));
	snprintf(id->firmware, sizeof id->firmware, "1.0");
	return 0;
}
static int f_spectro_open(const struct spectro_cfg *cfg, struct spectro **out, struct acq_err *err)
{
	if (fail_open[slot_of_cfg(cfg)])
		return acq_errf(err, ACQ_E_DISCONNECTED, "fake spectrometer: gone");
	fake_spec.info = (struct spectro_info){ .model = "FakeSpec", .serial = "1234", .firmware = "2", .npix = 16,
						.wl_coef = { 450, 40, 0, 0, 0 }, .max_counts = 65535 };
	*out = &fake_spec;
	return 0;
}
static void f_spectro_close(struct spectro *s)
{
	(void)s;
}
static const struct spectro_info *f_spectro_info(const struct spectro *s)
{
	return &s->info;
}
static int f_spectro_start(struct spectro *s, const struct spectro_meas *m, double now, struct acq_err *err)
{
	(void)m;
	(void)now;
	(void)err;
	s->running = true;
	s->fetches = 0;
	return 0;
}
static int f_spectro_fetch(struct spectro *s, struct spectro_frame *f, double now, struct acq_err *err)
{
	(void)now;
	(void)err;
	if (++s->fetches < 3)
		return 0;
	memset(f, 0, sizeof *f);
	f->npix = 16;
	for (int i = 0; i < 16; i++)
		f->counts[i] = 100.0 * i;
	f->saturated[15] = 1;
	f->nsaturated = 1;
	f->temperature_c = NAN;
	f->meas = (struct spectro_meas){ .integration_ms = 12.5, .averages = 3 };
	s->running = false;
	return 1;
}
static int f_spectro_stop(struct spectro *s, struct acq_err *err)
{
	(void)err;
	s->running = false;
	return 0;
}
static int f_laser_open(const struct laser_cfg *cfg, struct laser **out, struct acq_err *err)
{
	if (fail_open[slot_of_cfg(cfg)])
		return acq_errf(err, ACQ_E_DISCONNECTED, "fake laser: gone");
	*out = &fake_laser;
	return 0;
}
static void f_laser_close(struct laser *l)
{
	l->emission = false;
}
static int f_laser_set_emission(struct laser *l, bool on, struct acq_err *err)
{
	(void)err;
	l->emission = on;
	return 0;
}
static double fake_power;
static int f_laser_set_power(struct laser *l, double pct, struct acq_err *err)
{
	(void)l;
	(void)err;
	fake_power = pct;
	return 0;
}
static int f_laser_status(struct laser *l, struct laser_status *st, struct acq_err *err)
{
	(void)err;
	*st = (struct laser_status){ .emission = l->emission, .interlock_ok = true };
	return 0;
}
static const struct laser_identity *f_laser_identity(const struct laser *l)
{
	return &l->id;
}
static const struct devices_drv fake_drv = {
	f_axis_open, f_axis_close, f_axis_cfg_limits, f_axis_read_status, f_axis_move_begin, f_axis_move_step,
	f_axis_stop, f_axis_identity, f_spectro_open, f_spectro_close, f_spectro_info, f_spectro_start,
	f_spectro_fetch, f_spectro_stop, f_laser_open, f_laser_close, f_laser_set_emission, f_laser_set_power, f_laser_status,
	f_laser_identity, f_axis_home_begin, f_axis_alarm_reset,
};

/* ---- harness ---- */
static double now_s;
static double fake_clock(void *ctx)
{
	(void)ctx;
	return now_s;
}
static double wall(void)
{
	return 1.7e9 + now_s;
}
static int ups, downs;
static void notify(void *ctx, enum conf_dev d, bool up, const char *why)
{
	(void)ctx;
	(void)d;
	(void)why;
	if (up)
		ups++;
	else
		downs++;
}
static int done_calls, done_rc;
static json_t *done_result;
static struct acq_err done_err;
static void done(void *ctx, int rc, const struct acq_err *err, json_t *result)
{
	(void)ctx;
	done_calls++;
	done_rc = rc;
	if (err)
		done_err = *err;
	json_decref(done_result);
	done_result = result;
}

struct fixture {
	char dir[64];
	struct loop *lp;
	struct store *st;
	struct conf *c;
	struct devices *dv;
};

static void advance(struct fixture *fx, double dt, int steps)
{
	for (int i = 0; i < steps; i++) {
		now_s += dt / steps;
		loop_run_once(fx->lp, 0);
	}
}

static int setup(void **state)
{
	struct fixture *fx = calloc(1, sizeof *fx);
	snprintf(fx->dir, sizeof fx->dir, "/tmp/test_devices.XXXXXX");
	if (!mkdtemp(fx->dir))
		return -1;
	now_s = 100;
	memset(fake_axes, 0, sizeof fake_axes);
	memset(fail_open, 0, sizeof fail_open);
	fake_laser.emission = true;
	ups = downs = done_calls = 0;
	struct loop_clock clk = { .now = fake_clock };
	fx->lp = loop_new(&clk, NULL);
	char text[256], db[128];
	snprintf(text, sizeof text, "daemon: {state_dir: %s, device_retry_s: 1}\nsweep: {move_timeout_s: 5}\n", fx->dir);
	struct acq_err err = { 0 };
	if (conf_load_text("t.yaml", text, strlen(text), NULL, &fx->c, &err))
		return -1;
	/* Fake parsed configurations: only ever passed back to the fake drivers. */
	for (int i = 0; i < 3; i++)
		fx->c->axis[i] = (struct axis_cfg *)&cfg_token[i];
	fx->c->spectro = (struct spectro_cfg *)&cfg_token[CONF_DEV_SPECTRO];
	fx->c->laser = (struct laser_cfg *)&cfg_token[CONF_DEV_LASER];
	snprintf(db, sizeof db, "%s/t.db", fx->dir);
	if (store_open(db, &fx->st, &err))
		return -1;
	*state = fx;
	return 0;
}

static int teardown(void **state)
{
	struct fixture *fx = *state;
	devices_finish(fx->dv);
	for (int i = 0; i < 3; i++)
		fx->c->axis[i] = NULL;
	fx->c->spectro = NULL;
	fx->c->laser = NULL;
	conf_free(fx->c);
	store_close(fx->st);
	loop_free(fx->lp);
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf %s", fx->dir);
	int rc = system(cmd);
	json_decref(done_result);
	done_result = NULL;
	free(fx);
	return rc == 0 ? 0 : -1;
}

static void test_open_and_identities(void **state)
{
	struct fixture *fx = *state;
	struct acq_err err = { 0 };
	assert_int_equal(devices_init(fx->lp, fx->st, fx->c, &fake_drv, notify, NULL, wall, &fx->dv, &err), 0);
	assert_int_equal(devices_available(fx->dv), 5);
	assert_int_equal(ups, 5);
	assert_true(devices_spectrometer_id(fx->dv) > 0);
	json_t *j = devices_json(fx->dv);
	assert_int_equal(json_array_size(j), 5);
	json_t *a0 = json_array_get(j, 0);
	assert_string_equal(json_string_value(json_object_get(a0, "state")), "connected");
	assert_string_equal(json_string_value(json_object_get(json_object_get(a0, "identity"), "model")), "AX-0");
	assert_true(json_is_array(json_object_get(a0, "limits_deg")));
	json_decref(j);
	/* A reload reopens everything on the same object (the executor keeps its pointer); the laser goes off. */
	struct devices *before = fx->dv;
	fake_laser.emission = true;
	assert_int_equal(devices_reconfigure(fx->dv, fx->c, &err), 0);
	assert_ptr_equal(fx->dv, before);
	assert_false(fake_laser.emission);
	assert_int_equal(ups, 10);
	assert_int_equal(devices_available(fx->dv), 5);
	fake_laser.emission = true;
	/* Finish: laser off, every arm stopped. */
	assert_true(fake_laser.emission);
	devices_finish(fx->dv);
	fx->dv = NULL;
	assert_false(fake_laser.emission);
	for (int i = 0; i < 3; i++)
		assert_true(fake_axes[i].stops >= 1);
}

static void test_move_limits_and_completion(void **state)
{
	struct fixture *fx = *state;
	struct acq_err err = { 0 };
	assert_int_equal(devices_init(fx->lp, fx->st, fx->c, &fake_drv, notify, NULL, wall, &fx->dv, &err), 0);
	double out_of_range[3] = { 95, NAN, NAN };
	assert_int_equal(devices_move(fx->dv, out_of_range, done, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_RANGE);
	assert_non_null(strstr(err.msg, "laser.theta"));
	assert_false(fake_axes[0].moving);
	double none[3] = { NAN, NAN, NAN };
	assert_int_equal(devices_move(fx->dv, none, done, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
	double t[3] = { 45, NAN, -5 };
	assert_int_equal(devices_move(fx->dv, t, done, NULL, &err), 0);
	assert_true(devices_busy(fx->dv));
	assert_int_equal(devices_move(fx->dv, t, done, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_STATE);
	advance(fx, 1.0, 40);
	assert_int_equal(done_calls, 1);
	assert_int_equal(done_rc, 0);
	assert_false(devices_busy(fx->dv));
	assert_true(fake_axes[0].pos == 45 && fake_axes[2].pos == -5 && fake_axes[1].pos == 0);
	assert_true(json_real_value(json_object_get(done_result, "laser.theta")) == 45);
	/* A lost axis: the move is refused as unavailable, and the retry timer brings it back. */
	devices_lost(fx->dv, CONF_DEV_DETECTOR_THETA, "fake: cable pulled");
	assert_int_equal(downs, 1);
	assert_null(devices_axis(fx->dv, CONF_DEV_DETECTOR_THETA));
	double t2[3] = { NAN, 30, NAN };
	assert_int_equal(devices_move(fx->dv, t2, done, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_UNSUPPORTED);
	assert_non_null(strstr(err.msg, "cable pulled"));
	advance(fx, 1.5, 3);
	assert_non_null(devices_axis(fx->dv, CONF_DEV_DETECTOR_THETA));
	assert_int_equal(ups, 6);
}

static void test_measure_and_dark(void **state)
{
	struct fixture *fx = *state;
	struct acq_err err = { 0 };
	fail_open[CONF_DEV_LASER] = true;
	assert_int_equal(devices_init(fx->lp, fx->st, fx->c, &fake_drv, notify, NULL, wall, &fx->dv, &err), 0);
	assert_int_equal(devices_available(fx->dv), 4);
	/* Without the laser a dark cannot be guaranteed dark. */
	assert_int_equal(devices_measure(fx->dv, "dark", 10, 1, NAN, done, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_UNSUPPORTED);
	fail_open[CONF_DEV_LASER] = false;
	advance(fx, 1.2, 3);
	assert_non_null(devices_laser(fx->dv));
	fake_laser.emission = true;
	assert_int_equal(devices_measure(fx->dv, "dark", 12.5, 3, 50, done, NULL, &err), 0);
	assert_false(fake_laser.emission);
	advance(fx, 0.1, 10);
	assert_int_equal(done_calls, 1);
	assert_int_equal(done_rc, 0);
	assert_string_equal(json_string_value(json_object_get(done_result, "kind")), "dark");
	assert_int_equal(json_integer_value(json_object_get(done_result, "npix")), 16);
	assert_int_equal(json_integer_value(json_object_get(done_result, "saturated")), 1);
	assert_true(json_real_value(json_object_get(done_result, "peak")) == 1500);
	assert_int_equal(store_spectrum_count(fx->st, 0, &err), 1);
	assert_true(fake_power == 0); /* a dark does not touch the power */
	assert_int_equal(devices_measure(fx->dv, "sample", 12.5, 3, 40, done, NULL, &err), 0);
	assert_true(fake_laser.emission); /* on for the sample */
	assert_true(fake_power == 40);
	advance(fx, 0.1, 10);
	assert_false(fake_laser.emission); /* and off again */
	assert_int_equal(done_calls, 2);
	assert_int_equal(store_spectrum_count(fx->st, 0, &err), 2);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(test_open_and_identities, setup, teardown),
		cmocka_unit_test_setup_teardown(test_move_limits_and_completion, setup, teardown),
		cmocka_unit_test_setup_teardown(test_measure_and_dark, setup, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
