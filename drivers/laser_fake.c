/* laser_fake: the laser backend without hardware (laser_fake.h). Like the serial driver, every failed call
 * switches emission off, and the interlock or a fault refuses emission. */
#include "drivers/laser_fake.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "drivers/laser_backend.h"

static struct laser_fake fake = { .power_pct = 100 };
static pthread_mutex_t fake_lock = PTHREAD_MUTEX_INITIALIZER;

struct laser_dev {
	const struct laser_cfg *cfg;
	struct laser_identity id;
};

struct laser_fake *laser_fake_state(void)
{
	return &fake;
}

void laser_fake_reset(void)
{
	pthread_mutex_lock(&fake_lock);
	memset(&fake, 0, sizeof fake);
	fake.power_pct = 100;
	pthread_mutex_unlock(&fake_lock);
}

static double mono_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* A command arrives: take delay_s (without the lock), then, with the lock held on return, apply the keep-alive
 * of cfg (emission off if the previous command is older than keepalive_ms) and refresh it. */
static void command_in(const struct laser_cfg *cfg)
{
	pthread_mutex_lock(&fake_lock);
	double delay = fake.delay_s;
	pthread_mutex_unlock(&fake_lock);
	if (delay > 0) {
		struct timespec ts = { (time_t)delay, (long)((delay - (double)(time_t)delay) * 1e9) };
		nanosleep(&ts, NULL);
	}
	pthread_mutex_lock(&fake_lock);
	double now = mono_now();
	int ka = cfg ? laser_cfg_keepalive_ms(cfg) : 0;
	if (fake.last_refresh > 0) {
		double gap = now - fake.last_refresh;
		if (gap > fake.max_gap)
			fake.max_gap = gap;
		if (ka && gap > ka * 1e-3 && fake.emission) {
			fake.emission = false;
			fake.expired++;
		}
	}
	fake.last_refresh = now;
}

/* Injected failure: emission off, -1 with the fake's code; else 0. Called with the lock held. */
static int io_fail(const char *what, struct acq_err *err)
{
	if (!fake.fail_io)
		return 0;
	fake.emission = false;
	return acq_errf(err, fake.fail_io, "laser (fake): %s failed (injected %s)", what, acq_errname(fake.fail_io));
}

static int lf_open(const struct laser_cfg *cfg, struct laser_dev **out, struct acq_err *err)
{
	pthread_mutex_lock(&fake_lock);
	int rc = fake.fail_open ? acq_errf(err, ACQ_E_DISCONNECTED, "laser (fake): no answer (injected)") : 0;
	if (!rc) {
		fake.opens++;
		fake.emission = false;
		fake.last_refresh = mono_now(); /* open arms the keep-alive */
	}
	pthread_mutex_unlock(&fake_lock);
	if (rc)
		return -1;
	struct laser_dev *d = calloc(1, sizeof *d);
	if (!d)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	d->cfg = cfg;
	strcpy(d->id.model, "fake-laser");
	strcpy(d->id.serial, "F1");
	strcpy(d->id.firmware, "1");
	*out = d;
	return 0;
}

static void lf_close(struct laser_dev *d)
{
	pthread_mutex_lock(&fake_lock);
	fake.emission = false;
	pthread_mutex_unlock(&fake_lock);
	free(d);
}

static int lf_set_emission(struct laser_dev *d, bool on, struct acq_err *err)
{
	command_in(d->cfg);
	int rc = io_fail(on ? "EMISSION ON" : "EMISSION OFF", err);
	if (!rc && on && (fake.interlock_open || fake.fault_code)) {
		fake.emission = false;
		rc = acq_errf(err, ACQ_E_DEVICE, "laser (fake): emission refused: %s",
			      fake.interlock_open ? "interlock open" : "fault active");
		err->detail = fake.interlock_open ? 3 : 4;
	}
	if (!rc) {
		fake.emission = on;
		if (on)
			fake.sets_on++;
		else
			fake.sets_off++;
	}
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static int lf_set_power(struct laser_dev *d, double pct, struct acq_err *err)
{
	double maxp = laser_cfg_max_power(d->cfg);
	command_in(d->cfg);
	int rc = io_fail("POWER", err);
	if (!rc && (!isfinite(pct) || pct < 0 || pct > maxp)) {
		fake.emission = false;
		rc = acq_errf(err, ACQ_E_RANGE, "laser (fake): power %g%% outside [0, %g]", pct, maxp);
	}
	if (!rc) {
		fake.power_pct = pct;
		fake.power_sets++;
	}
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static int lf_status(struct laser_dev *d, struct laser_status *st, struct acq_err *err)
{
	memset(st, 0, sizeof *st);
	command_in(d->cfg);
	int rc = io_fail("STATUS?", err);
	if (fake.interlock_open || fake.fault_code)
		fake.emission = false;
	fake.status_reads++;
	fake.reads_since_keepalive++;
	st->emission = fake.emission;
	st->power_pct = fake.power_pct;
	st->interlock_ok = !fake.interlock_open;
	st->fault = fake.fault_code != 0;
	st->fault_code = fake.fault_code;
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static int lf_keepalive(struct laser_dev *d, struct acq_err *err)
{
	if (!laser_cfg_keepalive_ms(d->cfg))
		return 0;
	command_in(d->cfg);
	int rc = io_fail("KEEPALIVE", err);
	fake.keepalives++;
	if (fake.last_keepalive > 0 && fake.last_refresh - fake.last_keepalive > fake.max_keepalive_gap)
		fake.max_keepalive_gap = fake.last_refresh - fake.last_keepalive;
	fake.last_keepalive = fake.last_refresh;
	if (fake.reads_since_keepalive > fake.max_reads_between)
		fake.max_reads_between = fake.reads_since_keepalive;
	fake.reads_since_keepalive = 0;
	pthread_mutex_unlock(&fake_lock);
	return rc;
}

static const struct laser_identity *lf_identity(const struct laser_dev *d)
{
	return &d->id;
}

const struct laser_backend laser_fake_backend = {
	.name = "fake", .open = lf_open, .close = lf_close, .set_emission = lf_set_emission,
	.set_power = lf_set_power, .status = lf_status, .identity = lf_identity, .keepalive = lf_keepalive,
};
