/* laser: the supercontinuum source, a const table of functions behind an opaque handle (laser_backend.h): the
 * serial line backend (libserialport; line protocol in drivers/laser_serial.c) or the fake for unit tests
 * (drivers/laser_fake.c). The handle switches emission off on close and on every error path it sees. Libraries
 * do not log. */
#ifndef LASER_H
#define LASER_H

#include <stdbool.h>

#include "config/acq_err.h"
#include "config/yconf.h"

struct laser;
struct laser_cfg;

struct laser_status {
	bool emission;
	double power_pct;    /* 0..100 */
	bool interlock_ok;   /* true when the interlock is closed (emission allowed) */
	bool fault;
	int fault_code;
};

struct laser_identity {
	char model[64], serial[64], firmware[64];
};

/* Parse the `laser` section. Allocates *out. 0 or -1 with file:line:col. */
int laser_cfg_parse(struct yc_node *node, struct laser_cfg **out, struct acq_err *err);
/* Free a parsed configuration. */
void laser_cfg_free(struct laser_cfg *cfg);
/* Set or replace the serial device path (e.g. the pty from acq-sim's ports file). 0 or -1. */
int laser_cfg_set_device(struct laser_cfg *cfg, const char *device, struct acq_err *err);
/* Open the serial line and identify the laser. 0 or -1. */
int laser_open(const struct laser_cfg *cfg, struct laser **out, struct acq_err *err);
/* Emission off (best effort), close, free. NULL is fine. */
void laser_close(struct laser *l);
/* Switch emission on or off. On failure emission is switched off (best effort). 0 or -1. */
int laser_set_emission(struct laser *l, bool on, struct acq_err *err);
/* Set output power in percent. 0 or -1. */
int laser_set_power(struct laser *l, double pct, struct acq_err *err);
/* Query emission, power, interlock, fault. 0 or -1. */
int laser_status(struct laser *l, struct laser_status *st, struct acq_err *err);
/* Refresh the laser's keep-alive (armed at open with keepalive_ms; emission stops if not refreshed within
 * it). Call at least every keepalive_ms / 2. No-op when disarmed. 0 or -1 (emission then switched off). */
int laser_keepalive(struct laser *l, struct acq_err *err);
/* The configuration's keepalive_ms (0: none): the laser switches emission off when not refreshed within it. */
int laser_cfg_keepalive_ms(const struct laser_cfg *cfg);
/* Identity read at open. */
const struct laser_identity *laser_identity(const struct laser *l);

#endif
