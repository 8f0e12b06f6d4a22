/* laser: the common entry points of drivers/laser.h over the backend the configuration selects
 * (laser_backend.h). */
#include "drivers/laser.h"

#include <stdlib.h>

#include "drivers/laser_backend.h"

struct laser {
	const struct laser_backend *be;
	struct laser_dev *dev;
};

int laser_open(const struct laser_cfg *cfg, struct laser **out, struct acq_err *err)
{
	*out = NULL;
	struct laser *l = calloc(1, sizeof *l);
	if (!l)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	l->be = laser_cfg_backend(cfg);
	if (l->be->open(cfg, &l->dev, err)) {
		free(l);
		return -1;
	}
	*out = l;
	return 0;
}

void laser_close(struct laser *l)
{
	if (!l)
		return;
	l->be->close(l->dev);
	free(l);
}

int laser_set_emission(struct laser *l, bool on, struct acq_err *err)
{
	return l->be->set_emission(l->dev, on, err);
}

int laser_set_power(struct laser *l, double pct, struct acq_err *err)
{
	return l->be->set_power(l->dev, pct, err);
}

int laser_status(struct laser *l, struct laser_status *st, struct acq_err *err)
{
	return l->be->status(l->dev, st, err);
}

const struct laser_identity *laser_identity(const struct laser *l)
{
	return l->be->identity(l->dev);
}

int laser_keepalive(struct laser *l, struct acq_err *err)
{
	return l->be->keepalive ? l->be->keepalive(l->dev, err) : 0;
}
