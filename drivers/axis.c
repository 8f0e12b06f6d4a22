/* axis: the common entry points of drivers/axis.h over the backend the configuration selects (axis_backend.h). */
#include "drivers/axis.h"

#include <stdlib.h>

#include "drivers/axis_backend.h"
#include "drivers/axis_modbus.h"

struct axis {
	const struct axis_backend *be;
	struct axis_dev *dev;
	const struct axis_cfg *cfg;
};

int axis_wrap(const struct axis_cfg *cfg, const struct axis_backend *be, struct axis_dev *dev, struct axis **out,
	      struct acq_err *err)
{
	struct axis *ax = calloc(1, sizeof *ax);
	if (!ax) {
		be->close(dev);
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", axis_cfg_name(cfg));
	}
	*ax = (struct axis){ be, dev, cfg };
	*out = ax;
	return 0;
}

struct axis_dev *axis_dev_of(const struct axis *ax, const struct axis_backend *be)
{
	return ax && ax->be == be ? ax->dev : NULL;
}

int axis_open(const struct axis_cfg *cfg, struct axis **out, struct acq_err *err)
{
	*out = NULL;
	const struct axis_backend *be = axis_cfg_backend(cfg);
	struct axis_dev *dev = NULL;
	if (be->open(cfg, &dev, err))
		return -1;
	return axis_wrap(cfg, be, dev, out, err);
}

void axis_close(struct axis *ax)
{
	if (!ax)
		return;
	ax->be->close(ax->dev);
	free(ax);
}

const char *axis_name(const struct axis *ax)
{
	return axis_cfg_name(ax->cfg);
}

int axis_read_status(struct axis *ax, struct axis_status *st, struct acq_err *err)
{
	return ax->be->read_status(ax->dev, st, err);
}

int axis_move_begin(struct axis *ax, double target_deg, double now, struct acq_err *err)
{
	return ax->be->move_begin(ax->dev, target_deg, now, err);
}

int axis_move_step(struct axis *ax, double now, struct acq_err *err)
{
	return ax->be->move_step(ax->dev, now, err);
}

double axis_next_poll(const struct axis *ax)
{
	return ax->be->next_poll(ax->dev);
}

int axis_stop(struct axis *ax, struct acq_err *err)
{
	return ax->be->stop(ax->dev, err);
}

int axis_home_begin(struct axis *ax, double now, struct acq_err *err)
{
	return ax->be->home_begin(ax->dev, now, err);
}

int axis_alarm_reset(struct axis *ax, struct acq_err *err)
{
	return ax->be->alarm_reset(ax->dev, err);
}

int axis_identity(struct axis *ax, struct axis_identity *id, struct acq_err *err)
{
	return ax->be->identity(ax->dev, id, err);
}

int axis_reconnect(struct axis *ax, struct acq_err *err)
{
	return ax->be->reconnect(ax->dev, err);
}

bool axis_connected(const struct axis *ax)
{
	return ax->be->connected(ax->dev);
}
