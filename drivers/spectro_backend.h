/* spectro_backend: the table of functions a spectrometer backend provides (internal to drivers/). */
#ifndef SPECTRO_BACKEND_H
#define SPECTRO_BACKEND_H

#include "drivers/spectro.h"

struct spectro_backend {
	const char *name;  /* value of `backend:` in the config */
	/* Parse the backend's own keys of the `spectrometer` mapping; *state is the backend's config. */
	int (*cfg_parse)(struct yc_node *node, void **state, struct acq_err *err);
	void (*cfg_free)(void *state);
	/* Open the device; *dev is the backend's instance; fill info. */
	int (*open)(const void *state, void **dev, struct spectro_info *info, struct acq_err *err);
	void (*close)(void *dev);
	int (*start)(void *dev, const struct spectro_meas *m, double now, struct acq_err *err);
	int (*fetch)(void *dev, struct spectro_frame *frame, double now, struct acq_err *err);
	int (*stop)(void *dev, struct acq_err *err);
	int (*pollfd)(const void *dev); /* readable when fetch may progress (the port thread waits on it); NULL: none */
};

extern const struct spectro_backend spectro_avaspec_backend;  /* drivers/avaspec.c */
extern const struct spectro_backend spectro_sim_backend;      /* drivers/spectro_sim.c */
extern const struct spectro_backend spectro_fake_backend;     /* drivers/spectro_fake.c (unit tests) */

#endif
