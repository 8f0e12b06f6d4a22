/* axis_modbus: the Modbus axis backend (axis_modbus_backend) and its extras beyond drivers/axis.h: the axis
 * configuration parser (link type tcp|rtu|fake selects the backend), link description, shared links,
 * whole-arm parsing, the trapezoid timing the move timeout uses, and reconnect backoff. */
#ifndef AXIS_MODBUS_H
#define AXIS_MODBUS_H

#include <stdbool.h>

#include "config/acq_err.h"
#include "config/yconf.h"
#include "drivers/axis.h"
#include "drivers/regmap.h"

enum axis_link_type { AXIS_LINK_TCP = 0, AXIS_LINK_RTU = 1, AXIS_LINK_FAKE = 2 /* drivers/axis_fake.c */ };

struct axis_link_cfg {
	int type;                 /* enum axis_link_type */
	char host[128];
	int port;                 /* 0 lets the simulator pick an ephemeral port */
	char device[256];
	int baud, data_bits, stop_bits;
	char parity;              /* 'N', 'E' or 'O' */
	int response_timeout_ms, byte_timeout_ms;
};

/* Parse a whole arm (`link`, `response_timeout_ms`, `byte_timeout_ms`, `axes: {name: {...}}`): up to max
 * axis configs named "<laser|detector>.<axis>" into out[0..*n-1]. 0 or -1 (nothing allocated). */
int axis_arm_parse(struct yc_node *arm, struct yc_node *maps, const char *arm_name, struct axis_cfg **out,
		   int max, int *n, struct acq_err *err);
/* Accessors of a parsed axis configuration. */
const struct axis_link_cfg *axis_cfg_link(const struct axis_cfg *cfg);
int axis_cfg_unit(const struct axis_cfg *cfg);
const struct regmap *axis_cfg_map(const struct axis_cfg *cfg);
const char *axis_cfg_name(const struct axis_cfg *cfg);
/* Point a parsed axis at another endpoint (the port or device acq-sim wrote in its ports file): port for a
 * TCP link, device for RTU. 0 or -1 (ACQ_E_INVAL). */
int axis_cfg_set_endpoint(struct axis_cfg *cfg, int port, const char *device, struct acq_err *err);
/* Open an axis that shares peer's link (same bus or connection; links must match). 0 or -1. */
int axis_open_shared(const struct axis_cfg *cfg, struct axis *peer, struct axis **out, struct acq_err *err);
/* Duration (s) of a trapezoidal move over dist degrees with max speed and accel/decel (triangle if short). */
double axis_trapezoid_s(double dist, double speed, double accel, double decel);
/* Suggested delay before reconnect attempt number attempt (0, 1, ...): 0.1 s doubling, capped at 5 s. */
double axis_backoff_s(int attempt);
/* Limit and stall bits of the status word (false when the map does not define them). 0 or -1. */
int axis_read_bits(struct axis *ax, bool *limit_pos, bool *limit_neg, bool *stall, struct acq_err *err);
/* The angle the current or last move commanded (differs from the request only with wrap_deg). */
double axis_target(const struct axis *ax);
/* Retries the current or last move used. */
int axis_move_retries_used(const struct axis *ax);

#endif
