/* spectro: backend selection from config and the common entry points of drivers/spectro.h. */
#include "drivers/spectro.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "drivers/spectro_backend.h"

static const struct spectro_backend *const backends[] = { &spectro_avaspec_backend, &spectro_sim_backend,
							   &spectro_fake_backend, NULL };

struct spectro_cfg {
	const struct spectro_backend *be;
	void *state;
};

struct spectro {
	const struct spectro_cfg *cfg;
	void *dev;
	struct spectro_info info;
};

int spectro_cfg_parse(struct yc_node *node, struct spectro_cfg **out, struct acq_err *err)
{
	*out = NULL;
	if (yc_expect_map(node, "spectrometer", err))
		return -1;
	const char *names[8];
	int n = 0;
	for (; backends[n]; n++)
		names[n] = backends[n]->name;
	names[n] = NULL;
	int which = -1;
	if (yc_enum(node, "backend", true, names, &which, err))
		return -1;
	struct spectro_cfg *cfg = calloc(1, sizeof *cfg);
	if (!cfg)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	cfg->be = backends[which];
	if (cfg->be->cfg_parse(node, &cfg->state, err) || yc_check_unknown(node, "spectrometer", err)) {
		spectro_cfg_free(cfg);
		return -1;
	}
	*out = cfg;
	return 0;
}

void spectro_cfg_free(struct spectro_cfg *cfg)
{
	if (!cfg)
		return;
	if (cfg->state)
		cfg->be->cfg_free(cfg->state);
	free(cfg);
}

int spectro_open(const struct spectro_cfg *cfg, struct spectro **out, struct acq_err *err)
{
	*out = NULL;
	struct spectro *s = calloc(1, sizeof *s);
	if (!s)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	s->cfg = cfg;
	if (cfg->be->open(cfg->state, &s->dev, &s->info, err)) {
		free(s);
		return -1;
	}
	*out = s;
	return 0;
}

void spectro_close(struct spectro *s)
{
	if (!s)
		return;
	s->cfg->be->close(s->dev);
	free(s);
}

const struct spectro_info *spectro_info(const struct spectro *s)
{
	return &s->info;
}

double spectro_wavelength(const struct spectro_info *info, int pixel)
{
	double p = pixel, v = 0;
	for (int i = 4; i >= 0; i--)
		v = v * p + info->wl_coef[i];
	return v;
}

int spectro_start(struct spectro *s, const struct spectro_meas *m, double now, struct acq_err *err)
{
	if (!(m->integration_ms > 0) || m->averages < 1)
		return acq_errf(err, ACQ_E_INVAL, "spectrometer: integration time must be > 0 ms and averages ≥ 1");
	return s->cfg->be->start(s->dev, m, now, err);
}

int spectro_fetch(struct spectro *s, struct spectro_frame *frame, double now, struct acq_err *err)
{
	return s->cfg->be->fetch(s->dev, frame, now, err);
}

int spectro_stop(struct spectro *s, struct acq_err *err)
{
	return s->cfg->be->stop(s->dev, err);
}

int spectro_pollfd(const struct spectro *s)
{
	return s->cfg->be->pollfd ? s->cfg->be->pollfd(s->dev) : -1;
}
