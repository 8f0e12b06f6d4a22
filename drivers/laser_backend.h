/* laser_backend: the table of functions a laser backend provides, behind drivers/laser.h (internal to drivers/).
 * Each backend defines its own struct laser_dev; laser.c wraps it in the opaque struct laser. The configuration's
 * `backend:` key chooses (serial, the default, or fake). */
#ifndef LASER_BACKEND_H
#define LASER_BACKEND_H

#include "drivers/laser.h"

struct laser_dev;

struct laser_backend {
	const char *name;  /* value of `backend:` in the laser section */
	int (*open)(const struct laser_cfg *cfg, struct laser_dev **dev, struct acq_err *err);
	void (*close)(struct laser_dev *dev);
	int (*set_emission)(struct laser_dev *dev, bool on, struct acq_err *err);
	int (*set_power)(struct laser_dev *dev, double pct, struct acq_err *err);
	int (*status)(struct laser_dev *dev, struct laser_status *st, struct acq_err *err);
	const struct laser_identity *(*identity)(const struct laser_dev *dev);
	int (*keepalive)(struct laser_dev *dev, struct acq_err *err);  /* NULL: the backend has none */
};

extern const struct laser_backend laser_serial_backend;  /* drivers/laser_serial.c */
extern const struct laser_backend laser_fake_backend;    /* drivers/laser_fake.c */

/* The backend a parsed configuration selects (the configuration is parsed in drivers/laser_serial.c). */
const struct laser_backend *laser_cfg_backend(const struct laser_cfg *cfg);
/* The configuration's max_power_pct. */
double laser_cfg_max_power(const struct laser_cfg *cfg);

#endif
