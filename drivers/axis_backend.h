/* axis_backend: the table of functions an axis backend provides, behind drivers/axis.h (internal to drivers/).
 * Each backend defines its own struct axis_dev (the instance); axis.c wraps it in the opaque struct axis. The
 * backend of an axis is chosen by its configuration's link type (axis_cfg_backend). */
#ifndef AXIS_BACKEND_H
#define AXIS_BACKEND_H

#include "drivers/axis.h"

struct axis_dev;

struct axis_backend {
	const char *name;  /* link `type:` of the configuration ("modbus" covers tcp and rtu, "fake") */
	int (*open)(const struct axis_cfg *cfg, struct axis_dev **dev, struct acq_err *err);
	void (*close)(struct axis_dev *dev);
	int (*read_status)(struct axis_dev *dev, struct axis_status *st, struct acq_err *err);
	int (*move_begin)(struct axis_dev *dev, double target_deg, double now, struct acq_err *err);
	int (*move_step)(struct axis_dev *dev, double now, struct acq_err *err);
	double (*next_poll)(const struct axis_dev *dev);
	int (*stop)(struct axis_dev *dev, struct acq_err *err);
	int (*home_begin)(struct axis_dev *dev, double now, struct acq_err *err);
	int (*alarm_reset)(struct axis_dev *dev, struct acq_err *err);
	int (*identity)(struct axis_dev *dev, struct axis_identity *id, struct acq_err *err);
	int (*reconnect)(struct axis_dev *dev, struct acq_err *err);
	bool (*connected)(const struct axis_dev *dev);
};

extern const struct axis_backend axis_modbus_backend;  /* drivers/axis_modbus.c */
extern const struct axis_backend axis_fake_backend;    /* drivers/axis_fake.c */

/* The backend a parsed configuration selects (drivers/axis_modbus_cfg.c, where the configuration is parsed). */
const struct axis_backend *axis_cfg_backend(const struct axis_cfg *cfg);
/* Wrap a backend instance in a handle (for backends that open instances themselves, e.g. a shared link).
 * 0 or -1 (out of memory: dev is closed). */
int axis_wrap(const struct axis_cfg *cfg, const struct axis_backend *be, struct axis_dev *dev, struct axis **out,
	      struct acq_err *err);
/* The instance of ax if it is of backend be, else NULL. */
struct axis_dev *axis_dev_of(const struct axis *ax, const struct axis_backend *be);

#endif
