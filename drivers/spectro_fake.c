/* spectro_fake: the spectrometer backend without hardware (spectro_fake.h). */
#include "drivers/spectro_fake.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "drivers/spectro_backend.h"

#define FAKE_NPIX 600
#define FAKE_DARK 1000.0

static struct spectro_fake fake = { .level = 20000 };
static pthread_mutex_t fake_lock = PTHREAD_MUTEX_INITIALIZER;

struct fake_dev {
	bool running;
	struct spectro_meas meas;
	double done_at;
};

struct spectro_fake *spectro_fake_state(void)
{
	return &fake;
}

void spectro_fake_reset(void)
{
	pthread_mutex_lock(&fake_lock);
	memset(&fake, 0, sizeof fake);
	fake.level = 20000;
	pthread_mutex_unlock(&fake_lock);
}

static int fk_parse(struct yc_node *node, void **state, struct acq_err *err)
{
	(void)node;
	(void)err;
	*state = NULL;
	return 0;
}

static void fk_cfg_free(void *state)
{
	(void)state;
}

static int fk_open(const void *state, void **dev, struct spectro_info *info, struct acq_err *err)
{
	(void)state;
	pthread_mutex_lock(&fake_lock);
	int rc = fake.fail_open ? acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer (fake): no answer (injected)") : 0;
	if (!rc)
		fake.opens++;
	pthread_mutex_unlock(&fake_lock);
	if (rc)
		return -1;
	struct fake_dev *d = calloc(1, sizeof *d);
	if (!d)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	memset(info, 0, sizeof *info);
	snprintf(info->model, sizeof info->model, "fake");
	snprintf(info->serial, sizeof info->serial, "FAKE0001");
	snprintf(info->firmware, sizeof info->firmware, "1");
	info->npix = FAKE_NPIX;
	info->wl_coef[0] = 350.0;
	info->wl_coef[1] = 1.0;
	info->ndark_pixels = 2;
	info->dark_pixels[0] = 0;
	info->dark_pixels[1] = 1;
	info->max_counts = 65535;
	*dev = d;
	return 0;
}

static void fk_close(void *dev)
{
	free(dev);
}

static int fk_start(void *dev, const struct spectro_meas *m, double now, struct acq_err *err)
{
	struct fake_dev *d = dev;
	pthread_mutex_lock(&fake_lock);
	int code = fake.fail_io;
	if (!code)
		fake.starts++;
	pthread_mutex_unlock(&fake_lock);
	if (code)
		return acq_errf(err, code, "spectrometer (fake): start failed (injected %s)", acq_errname(code));
	d->meas = *m;
	d->running = true;
	d->done_at = now + m->integration_ms * 1e-3 * m->averages;
	return 0;
}

static int fk_fetch(void *dev, struct spectro_frame *f, double now, struct acq_err *err)
{
	struct fake_dev *d = dev;
	pthread_mutex_lock(&fake_lock);
	int code = fake.fail_io;
	double level = fake.level;
	fake.fetches++;
	pthread_mutex_unlock(&fake_lock);
	if (code)
		return acq_errf(err, code, "spectrometer (fake): fetch failed (injected %s)", acq_errname(code));
	if (!d->running)
		return acq_errf(err, ACQ_E_STATE, "spectrometer (fake): no measurement running");
	if (now + 1e-12 < d->done_at)
		return 0;
	d->running = false;
	memset(f, 0, sizeof *f);
	f->npix = FAKE_NPIX;
	for (int p = 0; p < FAKE_NPIX; p++)
		f->counts[p] = FAKE_DARK + (p < 2 ? 0 : level);
	f->temperature_c = NAN;
	f->meas = d->meas;
	return 1;
}

static int fk_stop(void *dev, struct acq_err *err)
{
	(void)err;
	((struct fake_dev *)dev)->running = false;
	pthread_mutex_lock(&fake_lock);
	fake.stops++;
	pthread_mutex_unlock(&fake_lock);
	return 0;
}

const struct spectro_backend spectro_fake_backend = {
	.name = "fake", .cfg_parse = fk_parse, .cfg_free = fk_cfg_free, .open = fk_open, .close = fk_close,
	.start = fk_start, .fetch = fk_fetch, .stop = fk_stop,
};
