/* axis: one motorised rotation axis of a goniometer arm (laser zenith, detector zenith, detector azimuth).
 *
 * A driver is a const table of functions behind an opaque handle (style habit 1, drivers/axis_backend.h): the
 * real backend is Modbus (drivers/axis_modbus.c, register map from config: drivers/regmap.h; acq-sim serves the
 * same Modbus maps, so the daemon drives the simulated bench through the real driver); drivers/axis_fake.c is
 * the fake for unit tests (link type fake). drivers/axis.c dispatches.
 *
 * Every operation is a bounded transaction (at most the configured response timeout, plus retries) and
 * never sleeps. Waiting for a move is a state machine stepped by the caller's event loop with its own
 * clock (`now`, monotonic seconds): axis_move_begin(), then axis_move_step() at axis_next_poll() times.
 * Libraries do not log: every failure fills struct acq_err. */
#ifndef AXIS_H
#define AXIS_H

#include <stdbool.h>

#include "config/acq_err.h"
#include "config/yconf.h"

struct axis;      /* opaque instance */
struct axis_cfg;  /* opaque parsed configuration (link, unit, register map, motion policy) */

struct axis_status {
	double position_deg;   /* feedback (actual) position, degrees */
	bool ready, busy, in_position, alarm, homed;
	int alarm_code;        /* controller's alarm code, 0 if none */
};

struct axis_identity {
	char vendor[64], model[64], serial[64], firmware[64];
};

/* Outcome of axis_move_step(). */
enum axis_move_state {
	AXIS_MOVE_RUNNING = 0, /* still moving/settling: call again at axis_next_poll() */
	AXIS_MOVE_DONE = 1,    /* in position within the deadband */
	AXIS_MOVE_FAILED = -1, /* timeout, alarm, retries exhausted, link lost: see err */
};

/* Parse one axis's configuration (node: the axis mapping; maps: the `register_maps` mapping or NULL;
 * link: the arm's `link` mapping). Allocates *out. 0 or -1 with a file:line:col message. */
int axis_cfg_parse(struct yc_node *node, struct yc_node *link, struct yc_node *maps, const char *name,
		   struct axis_cfg **out, struct acq_err *err);
/* Free a parsed axis configuration. */
void axis_cfg_free(struct axis_cfg *cfg);
/* Soft limits of the axis in degrees, from its configuration. */
void axis_cfg_limits(const struct axis_cfg *cfg, double *min_deg, double *max_deg);

/* Connect to the controller described by cfg (which must outlive the axis). 0 or -1. */
int axis_open(const struct axis_cfg *cfg, struct axis **out, struct acq_err *err);
/* Stop motion if possible, disconnect, free. NULL is fine. */
void axis_close(struct axis *ax);
/* Axis name from the configuration ("laser.theta", "detector.phi"). */
const char *axis_name(const struct axis *ax);

/* Read position and status once. 0 or -1. */
int axis_read_status(struct axis *ax, struct axis_status *st, struct acq_err *err);
/* Start an absolute move (soft limits are checked before anything is sent; backlash approach and retry
 * policy from config). 0 or -1 (ACQ_E_RANGE for a limit). */
int axis_move_begin(struct axis *ax, double target_deg, double now, struct acq_err *err);
/* Advance the move state machine; see enum axis_move_state. */
int axis_move_step(struct axis *ax, double now, struct acq_err *err);
/* When the caller should call axis_move_step() next (monotonic seconds). */
double axis_next_poll(const struct axis *ax);
/* Stop now (deceleration stop). 0 or -1. */
int axis_stop(struct axis *ax, struct acq_err *err);
/* Start homing; completion is observed with axis_move_step(). 0 or -1. */
int axis_home_begin(struct axis *ax, double now, struct acq_err *err);
/* Clear a controller alarm. 0 or -1. */
int axis_alarm_reset(struct axis *ax, struct acq_err *err);
/* Device identity for provenance (fields empty if the controller cannot say). 0 or -1. */
int axis_identity(struct axis *ax, struct axis_identity *id, struct acq_err *err);
/* Try to re-establish a lost link (bounded by the response timeout; the caller schedules backoff). 0 or -1. */
int axis_reconnect(struct axis *ax, struct acq_err *err);
/* True when the link is believed up. */
bool axis_connected(const struct axis *ax);

#endif
