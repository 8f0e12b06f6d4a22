/* axis_modbus_int.h: what the Modbus axis backend's files share (internal to drivers/): the parsed axis
 * configuration, the link and the instance, and the link's and the register map's I/O. The files:
 * axis_modbus.c (the backend's table of functions: open/close, status, the move state machine, stop, home,
 * identity, reconnect; the extras of axis_modbus.h), axis_modbus_cfg.c (the configuration parser and its
 * accessors), axis_modbus_link.c (the connection over TCP or RTU: its life and its bounded transactions),
 * axis_modbus_regs.c (the register map's fields and commands on the wire). */
#ifndef AXIS_MODBUS_INT_H
#define AXIS_MODBUS_INT_H

#include <modbus.h>
#include <stdbool.h>
#include <stdint.h>

#include "drivers/axis.h"
#include "drivers/axis_modbus.h"
#include "drivers/regmap.h"

struct axis_cfg {
	char name[64];
	struct axis_link_cfg link;
	int unit;
	struct regmap *map;
	double soft_min, soft_max;
	double wrap;               /* > 0: targets are modulo wrap degrees (azimuth): the nearest equivalent */
	double deadband, backlash;
	int backlash_dir;          /* +1: final approach in the positive direction, -1: negative */
	int retries;
	double speed, accel, decel;
	double settle_s, margin_s, timeout_factor, poll_s, home_timeout_s, start_grace_s;
	double watch_s;            /* a leg's status read at least this often before its predicted end (axis_modbus.c) */
	double response_timeout_s, byte_timeout_s;
};

/* One connection, shared by the axes behind it (an RS-485 bus or one TCP connection per arm). */
struct axis_link {
	int refs;
	modbus_t *ctx;
	bool up;
	bool needs_flush;
	char where[160];
};

enum ax_state { ST_IDLE, ST_MOVE, ST_SETTLE, ST_HOME, ST_DONE, ST_FAILED };

struct axis_dev {
	const struct axis_cfg *cfg;
	struct axis_link *link;
	int state;
	double target;         /* final target */
	double leg;            /* the target of the current leg */
	bool pre_leg;          /* current leg is the backlash take-up leg */
	int retries_left;
	double deadline, next_poll;
	int clear_cmd;         /* level command to clear at the next step, -1 if none */
	bool seen_busy;        /* the controller reported busy since the current leg was sent */
	double leg_start;      /* when the current leg was sent */
	double leg_end;        /* its predicted end: leg_start + the trapezoid of the leg */
	struct acq_err fail;   /* why the state machine failed */
};

/* axis_modbus_link.c: the connection (one per link) and its transactions; each call stops at the first failure
 * and blocks at most one response timeout. */
/* A new link for c's connection (one reference, not connected: mb_link_connect); NULL when out of memory. */
struct axis_link *mb_link_new(const struct axis_cfg *c);
/* One more axis behind l (a shared bus or connection); returns l. */
struct axis_link *mb_link_ref(struct axis_link *l);
/* Drop one reference (NULL: nothing); the last closes the connection and frees the context and l. */
void mb_link_unref(struct axis_link *l);
/* (Re)connect l as c's link says (TCP or RTU, our own error recovery, the configured timeouts). 0 or -1
 * (ACQ_E_INVAL: no context; ACQ_E_DISCONNECTED: no connection). */
int mb_link_connect(struct axis_link *l, const struct axis_cfg *c, struct acq_err *err);
/* Close the connection and mark the link down (the context is kept for a reconnect). */
void mb_link_down(struct axis_link *l);
/* Classify the failed libmodbus call's errno (exception, timeout, bad frame, broken link: then marked down)
 * into err about what at register addr. Always -1. */
int mb_link_fail(struct axis_dev *ax, const char *what, int addr, struct acq_err *err);
/* The link is up (pending garbage flushed) and addresses ax's unit. 0 or -1 (ACQ_E_DISCONNECTED). */
int mb_link_ready(struct axis_dev *ax, struct acq_err *err);
/* Read n registers (input or holding, by space) at addr into regs; what names them in errors. 0 or -1. */
int mb_link_read(struct axis_dev *ax, int space, int addr, int n, uint16_t *regs, const char *what,
		 struct acq_err *err);
/* Write n holding registers at addr (FC6 for one, FC16 for more). 0 or -1. */
int mb_link_write(struct axis_dev *ax, int addr, int n, const uint16_t *regs, const char *what,
		  struct acq_err *err);

/* axis_modbus_regs.c: the register map's fields and commands on the wire. */
/* Read map field id: its scaled value and/or its raw value (either may be NULL). 0 or -1. */
int mb_reg_read_field(struct axis_dev *ax, int id, double *value, double *raw, struct acq_err *err);
/* Send map command id (coil or register); a level command is cleared at once (clear_now) or by the next
 * mb_reg_clear_pending. 0 or -1 (ACQ_E_UNSUPPORTED when the map lacks it). */
int mb_reg_send_cmd(struct axis_dev *ax, int id, bool clear_now, struct acq_err *err);
/* Clear the level command left set by the previous call, if any. 0 or -1. */
int mb_reg_clear_pending(struct axis_dev *ax, struct acq_err *err);
/* Write the move fields for target (one FC16 block or one write per field), then the start command if any. */
int mb_reg_send_move(struct axis_dev *ax, double target, struct acq_err *err);
/* Status bit b of word as the map places it (false when the map does not define it). */
bool mb_reg_bit(const struct regmap *m, uint32_t word, int b);

#endif
