/* axis_modbus: the arm-axis driver over Modbus TCP or RTU (libmodbus), driven by a register map from the
 * configuration; bounded transactions, a move state machine stepped by the caller, no sleeps, no logging.
 *
 * Every call does a handful of Modbus transactions and stops at the first failure, so it never blocks for
 * longer than one response timeout per transaction. Recovery is ours, never MODBUS_ERROR_RECOVERY_LINK
 * (which sleeps and retries inside libmodbus): a link error marks the link down and the caller schedules
 * mb_reconnect() with its own backoff (axis_backoff_s()). */
#include <errno.h>
#include <math.h>
#include <modbus.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "drivers/axis.h"
#include "drivers/axis_backend.h"
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
	struct acq_err fail;   /* why the state machine failed */
};

static void mb_close(struct axis_dev *ax);
static int mb_read_status(struct axis_dev *ax, struct axis_status *st, struct acq_err *err);
static int mb_read_bits(struct axis_dev *ax, bool *limit_pos, bool *limit_neg, bool *stall, struct acq_err *err);
static int mb_stop(struct axis_dev *ax, struct acq_err *err);

/* ---- configuration -------------------------------------------------------------------------------- */

static int parse_link(struct yc_node *link, struct axis_link_cfg *l, struct acq_err *err)
{
	static const char *const types[] = { "tcp", "rtu", "fake", NULL };
	static const char *const parities[] = { "none", "even", "odd", NULL };
	if (!link)
		return acq_errf(err, ACQ_E_CONFIG, "arm has no `link`");
	if (yc_expect_map(link, "link", err))
		return -1;
	int type = 0, parity = 0;
	memset(l, 0, sizeof *l);
	if (yc_enum(link, "type", true, types, &type, err))
		return -1;
	l->type = type;
	l->response_timeout_ms = 500;
	l->byte_timeout_ms = 100;
	if (type == AXIS_LINK_FAKE) /* drivers/axis_fake.c: no controller, for tests */
		return yc_check_unknown(link, "link", err);
	long long v;
	if (type == AXIS_LINK_TCP) {
		const char *host = "127.0.0.1";
		long long port = 502;
		if (yc_string(link, "host", false, &host, err) || yc_int(link, "port", true, 0, 65535, &port, err))
			return -1;
		if (strlen(host) >= sizeof l->host)
			return yc_errf(err, yc_get(link, "host"), "host name too long");
		snprintf(l->host, sizeof l->host, "%s", host);
		l->port = (int)port;
	} else {
		const char *dev = NULL;
		long long baud = 115200, data = 8, stop = 1;
		if (yc_string(link, "device", true, &dev, err) || yc_int(link, "baud", false, 300, 4000000, &baud, err) ||
		    yc_enum(link, "parity", false, parities, &parity, err) ||
		    yc_int(link, "data_bits", false, 5, 8, &data, err) ||
		    yc_int(link, "stop_bits", false, 1, 2, &stop, err))
			return -1;
		if (strlen(dev) >= sizeof l->device)
			return yc_errf(err, yc_get(link, "device"), "device path too long");
		snprintf(l->device, sizeof l->device, "%s", dev);
		l->baud = (int)baud;
		l->parity = "NEO"[parity];
		l->data_bits = (int)data;
		l->stop_bits = (int)stop;
	}
	v = l->response_timeout_ms;
	if (yc_int(link, "response_timeout_ms", false, 1, 60000, &v, err))
		return -1;
	l->response_timeout_ms = (int)v;
	v = l->byte_timeout_ms;
	if (yc_int(link, "byte_timeout_ms", false, 1, 60000, &v, err))
		return -1;
	l->byte_timeout_ms = (int)v;
	return yc_check_unknown(link, "link", err);
}

static int cfg_parse(struct yc_node *node, struct yc_node *link, struct yc_node *maps, const char *name,
		     int resp_ms, int byte_ms, struct axis_cfg **out, struct acq_err *err)
{
	struct axis_cfg *c = calloc(1, sizeof *c);
	if (!c)
		return acq_errf(err, ACQ_E_NOMEM, "axis %s: out of memory", name);
	snprintf(c->name, sizeof c->name, "%s", name);
	const char *mapname = NULL;
	long long unit = 1, retries = 3;
	static const char *const dirs[] = { "positive", "negative", NULL };
	int dir = 0;
	c->soft_min = -360;
	c->soft_max = 360;
	c->deadband = 0.01;
	c->speed = 10;
	c->accel = 20;
	c->decel = 0;
	c->settle_s = 0;
	c->margin_s = 2;
	c->timeout_factor = 1.5;
	c->poll_s = 0.05;
	c->home_timeout_s = 120;
	c->start_grace_s = 0.2;
	if (yc_expect_map(node, name, err) || parse_link(link, &c->link, err))
		goto fail;
	if (resp_ms > 0 && !yc_get(link, "response_timeout_ms"))
		c->link.response_timeout_ms = resp_ms;
	if (byte_ms > 0 && !yc_get(link, "byte_timeout_ms"))
		c->link.byte_timeout_ms = byte_ms;
	bool fake = c->link.type == AXIS_LINK_FAKE;
	if (yc_int(node, "unit", !fake, 1, 247, &unit, err) || yc_string(node, "map", !fake, &mapname, err) ||
	    yc_double(node, "soft_min_deg", false, -720, 720, &c->soft_min, err) ||
	    yc_double(node, "soft_max_deg", false, -720, 720, &c->soft_max, err) ||
	    yc_double(node, "deadband_deg", false, 0, 10, &c->deadband, err) ||
	    yc_int(node, "retries", false, 0, 100, &retries, err) ||
	    yc_double(node, "backlash_deg", false, 0, 10, &c->backlash, err) ||
	    yc_enum(node, "backlash_approach", false, dirs, &dir, err) ||
	    yc_double(node, "speed_dps", false, 1e-3, 1e4, &c->speed, err) ||
	    yc_double(node, "accel_dps2", false, 1e-3, 1e6, &c->accel, err) ||
	    yc_double(node, "decel_dps2", false, 1e-3, 1e6, &c->decel, err) ||
	    yc_double(node, "settle_s", false, 0, 600, &c->settle_s, err) ||
	    yc_double(node, "timeout_margin_s", false, 0, 3600, &c->margin_s, err) ||
	    yc_double(node, "timeout_factor", false, 1, 100, &c->timeout_factor, err) ||
	    yc_double(node, "poll_s", false, 1e-3, 10, &c->poll_s, err) ||
	    yc_double(node, "home_timeout_s", false, 0.1, 36000, &c->home_timeout_s, err) ||
	    yc_double(node, "start_grace_s", false, 0, 60, &c->start_grace_s, err) ||
	    yc_double(node, "wrap_deg", false, 0, 720, &c->wrap, err))
		goto fail;
	if (c->soft_min >= c->soft_max) {
		yc_errf(err, node, "%s: soft_min_deg (%g) must be below soft_max_deg (%g)", name, c->soft_min,
			c->soft_max);
		goto fail;
	}
	if (c->wrap != 0 && c->wrap < 1) {
		yc_errf(err, yc_get(node, "wrap_deg"), "%s: wrap_deg must be 0 (off) or at least 1", name);
		goto fail;
	}
	if (c->decel == 0)
		c->decel = c->accel;
	c->unit = (int)unit;
	c->retries = (int)retries;
	c->backlash_dir = dir == 0 ? 1 : -1;
	if (!fake && regmap_parse(maps, mapname, yc_get(node, "map"), &c->map, err))
		goto fail;
	if (yc_check_unknown(node, name, err))
		goto fail;
	*out = c;
	return 0;
fail:
	regmap_free(c->map);
	free(c);
	return -1;
}

int axis_cfg_parse(struct yc_node *node, struct yc_node *link, struct yc_node *maps, const char *name,
		   struct axis_cfg **out, struct acq_err *err)
{
	return cfg_parse(node, link, maps, name, 0, 0, out, err);
}

int axis_arm_parse(struct yc_node *arm, struct yc_node *maps, const char *arm_name, struct axis_cfg **out,
		   int max, int *n, struct acq_err *err)
{
	*n = 0;
	if (!arm)
		return acq_errf(err, ACQ_E_CONFIG, "devices: no `%s` section", arm_name);
	if (yc_expect_map(arm, arm_name, err))
		return -1;
	long long resp = 0, byte = 0;
	if (yc_int(arm, "response_timeout_ms", false, 1, 60000, &resp, err) ||
	    yc_int(arm, "byte_timeout_ms", false, 1, 60000, &byte, err))
		return -1;
	struct yc_node *link = yc_get(arm, "link"), *axes = yc_get(arm, "axes");
	if (!link)
		return yc_errf(err, arm, "%s: no `link`", arm_name);
	if (!axes)
		return yc_errf(err, arm, "%s: no `axes`", arm_name);
	if (yc_expect_map(axes, "axes", err))
		return -1;
	if (axes->n == 0)
		return yc_errf(err, axes, "%s: `axes` is empty", arm_name);
	for (size_t i = 0; i < axes->n; i++) {
		if (*n >= max) {
			yc_errf(err, axes->keys[i], "%s: more than %d axes", arm_name, max);
			goto fail;
		}
		char name[64];
		const char *short_name = arm_name;
		if (!strcmp(arm_name, "laser_arm"))
			short_name = "laser";
		else if (!strcmp(arm_name, "detector_arm"))
			short_name = "detector";
		snprintf(name, sizeof name, "%s.%s", short_name, axes->keys[i]->value ? axes->keys[i]->value : "?");
		axes->used[i] = true;
		if (cfg_parse(axes->items[i], link, maps, name, (int)resp, (int)byte, &out[*n], err))
			goto fail;
		(*n)++;
	}
	if (yc_check_unknown(arm, arm_name, err))
		goto fail;
	return 0;
fail:
	for (int i = 0; i < *n; i++)
		axis_cfg_free(out[i]);
	*n = 0;
	return -1;
}

void axis_cfg_free(struct axis_cfg *cfg)
{
	if (!cfg)
		return;
	regmap_free(cfg->map);
	free(cfg);
}

void axis_cfg_limits(const struct axis_cfg *cfg, double *min_deg, double *max_deg)
{
	*min_deg = cfg->soft_min;
	*max_deg = cfg->soft_max;
}

const struct axis_link_cfg *axis_cfg_link(const struct axis_cfg *cfg) { return &cfg->link; }

int axis_cfg_set_endpoint(struct axis_cfg *cfg, int port, const char *device, struct acq_err *err)
{
	if (cfg->link.type == AXIS_LINK_TCP) {
		if (port <= 0 || port > 65535)
			return acq_errf(err, ACQ_E_INVAL, "%s: TCP port %d outside [1, 65535]", cfg->name, port);
		cfg->link.port = port;
		return 0;
	}
	if (!device || !device[0] || strlen(device) >= sizeof cfg->link.device)
		return acq_errf(err, ACQ_E_INVAL, "%s: bad serial device path", cfg->name);
	snprintf(cfg->link.device, sizeof cfg->link.device, "%s", device);
	return 0;
}
int axis_cfg_unit(const struct axis_cfg *cfg) { return cfg->unit; }
const struct regmap *axis_cfg_map(const struct axis_cfg *cfg) { return cfg->map; }
const char *axis_cfg_name(const struct axis_cfg *cfg) { return cfg->name; }

double axis_trapezoid_s(double dist, double speed, double accel, double decel)
{
	dist = fabs(dist);
	if (dist == 0)
		return 0;
	/* distance to reach full speed and stop again */
	double dfull = speed * speed / (2 * accel) + speed * speed / (2 * decel);
	if (dist >= dfull)
		return speed / accel + speed / decel + (dist - dfull) / speed;
	/* triangle: peak speed vp with vp²/2a + vp²/2d = dist */
	double vp = sqrt(2 * dist * accel * decel / (accel + decel));
	return vp / accel + vp / decel;
}

double axis_backoff_s(int attempt)
{
	double s = 0.1;
	for (int i = 0; i < attempt && s < 5; i++)
		s *= 2;
	return s > 5 ? 5 : s;
}

/* ---- link ------------------------------------------------------------------------------------------ */

static int link_connect(struct axis_link *l, const struct axis_cfg *c, struct acq_err *err)
{
	if (l->ctx) {
		modbus_close(l->ctx);
		modbus_free(l->ctx);
		l->ctx = NULL;
	}
	l->up = false;
	const struct axis_link_cfg *k = &c->link;
	if (k->type == AXIS_LINK_TCP)
		l->ctx = modbus_new_tcp(k->host, k->port);
	else
		l->ctx = modbus_new_rtu(k->device, k->baud, k->parity, k->data_bits, k->stop_bits);
	if (!l->ctx)
		return acq_errf(err, ACQ_E_INVAL, "%s: %s: cannot create a Modbus context: %s", c->name, l->where,
				modbus_strerror(errno));
	modbus_set_error_recovery(l->ctx, MODBUS_ERROR_RECOVERY_NONE);
	modbus_set_response_timeout(l->ctx, (uint32_t)(k->response_timeout_ms / 1000),
				    (uint32_t)(k->response_timeout_ms % 1000) * 1000);
	modbus_set_byte_timeout(l->ctx, (uint32_t)(k->byte_timeout_ms / 1000),
				(uint32_t)(k->byte_timeout_ms % 1000) * 1000);
	if (modbus_connect(l->ctx) != 0)
		return acq_errf(err, ACQ_E_DISCONNECTED, "%s: cannot connect to %s: %s", c->name, l->where,
				modbus_strerror(errno));
	l->up = true;
	l->needs_flush = false;
	return 0;
}

static void link_down(struct axis_link *l)
{
	if (l->ctx)
		modbus_close(l->ctx);
	l->up = false;
}

/* Classify a failed libmodbus call (errno) into an error record; a broken link is marked down. */
static int mb_fail(struct axis_dev *ax, const char *what, int addr, struct acq_err *err)
{
	int e = errno;
	const struct axis_cfg *c = ax->cfg;
	const char *msg = modbus_strerror(e);
	int code;
	if (e >= EMBXILFUN && e <= EMBXGTAR) {
		code = ACQ_E_DEVICE; /* the controller answered with an exception */
	} else if (e == ETIMEDOUT) {
		code = ACQ_E_TIMEOUT;
		ax->link->needs_flush = true;
	} else if (e == EMBBADCRC || e == EMBBADDATA || e == EMBBADEXC || e == EMBMDATA || e == EMBBADSLAVE ||
		   e == EMBUNKEXC) {
		code = ACQ_E_PROTO;
		ax->link->needs_flush = true;
	} else {
		code = ACQ_E_DISCONNECTED;
		link_down(ax->link);
	}
	return acq_errf(err, code, "%s (unit %d @ %s): %s at 0x%04x: %s", c->name, c->unit, ax->link->where,
			what, addr, msg);
}

static int link_ready(struct axis_dev *ax, struct acq_err *err)
{
	struct axis_link *l = ax->link;
	if (!l->up || !l->ctx)
		return acq_errf(err, ACQ_E_DISCONNECTED, "%s (unit %d @ %s): link is down", ax->cfg->name,
				ax->cfg->unit, l->where);
	if (l->needs_flush) {
		modbus_flush(l->ctx);
		l->needs_flush = false;
	}
	modbus_set_slave(l->ctx, ax->cfg->unit);
	return 0;
}

static int read_regs(struct axis_dev *ax, int space, int addr, int n, uint16_t *regs, const char *what,
		     struct acq_err *err)
{
	if (link_ready(ax, err))
		return -1;
	int rc = space == REGMAP_INPUT ? modbus_read_input_registers(ax->link->ctx, addr, n, regs)
				       : modbus_read_registers(ax->link->ctx, addr, n, regs);
	if (rc != n) {
		if (rc >= 0) {
			ax->link->needs_flush = true;
			return acq_errf(err, ACQ_E_PROTO, "%s (unit %d): %s at 0x%04x: %d registers instead of %d",
					ax->cfg->name, ax->cfg->unit, what, addr, rc, n);
		}
		return mb_fail(ax, what, addr, err);
	}
	return 0;
}

static int write_regs(struct axis_dev *ax, int addr, int n, const uint16_t *regs, const char *what,
		      struct acq_err *err)
{
	if (link_ready(ax, err))
		return -1;
	int rc = n == 1 ? modbus_write_register(ax->link->ctx, addr, regs[0])
			: modbus_write_registers(ax->link->ctx, addr, n, regs);
	if (rc != (n == 1 ? 1 : n))
		return rc >= 0 ? acq_errf(err, ACQ_E_PROTO, "%s: %s at 0x%04x: short write acknowledge",
					  ax->cfg->name, what, addr)
			       : mb_fail(ax, what, addr, err);
	return 0;
}

static int read_field(struct axis_dev *ax, int id, double *value, double *raw, struct acq_err *err)
{
	const struct regmap_field *f = &ax->cfg->map->f[id];
	uint16_t regs[2];
	if (read_regs(ax, f->space, f->addr, regmap_width(f), regs, regmap_field_name(id), err))
		return -1;
	if (value)
		*value = regmap_decode(f, regs);
	if (raw)
		*raw = regmap_decode_raw(f, regs);
	return 0;
}

static int send_cmd(struct axis_dev *ax, int id, bool clear_now, struct acq_err *err)
{
	const struct regmap_cmd *c = &ax->cfg->map->cmd[id];
	if (!c->present)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: register map '%s' has no `%s` command", ax->cfg->name,
				ax->cfg->map->name, regmap_cmd_name(id));
	for (int pass = 0; pass < (c->level && clear_now ? 2 : 1); pass++) {
		uint16_t v = pass ? 0 : c->value;
		if (c->space == REGMAP_COIL) {
			if (link_ready(ax, err))
				return -1;
			if (modbus_write_bit(ax->link->ctx, c->addr, v ? 1 : 0) != 1)
				return mb_fail(ax, regmap_cmd_name(id), c->addr, err);
		} else if (write_regs(ax, c->addr, 1, &v, regmap_cmd_name(id), err)) {
			return -1;
		}
	}
	if (c->level && !clear_now)
		ax->clear_cmd = id;
	return 0;
}

/* Clear a level-style command bit set by the previous call (the driver owns clearing it). */
static int clear_pending(struct axis_dev *ax, struct acq_err *err)
{
	if (ax->clear_cmd < 0)
		return 0;
	const struct regmap_cmd *c = &ax->cfg->map->cmd[ax->clear_cmd];
	int rc;
	if (link_ready(ax, err))
		return -1;
	if (c->space == REGMAP_COIL)
		rc = modbus_write_bit(ax->link->ctx, c->addr, 0) == 1 ? 0 : mb_fail(ax, "clearing command", c->addr, err);
	else {
		uint16_t z = 0;
		rc = write_regs(ax, c->addr, 1, &z, "clearing command", err);
	}
	if (rc == 0)
		ax->clear_cmd = -1;
	return rc;
}

/* Write the move fields (one FC16 block or one write per field), then the start command if any. */
static int send_move(struct axis_dev *ax, double target, struct acq_err *err)
{
	const struct axis_cfg *c = ax->cfg;
	const struct regmap *m = c->map;
	double values[RM_MOVE_FIELDS_END] = { [RM_TARGET] = target, [RM_SPEED] = c->speed, [RM_ACCEL] = c->accel,
					      [RM_DECEL] = c->decel };
	uint16_t block[128] = { 0 };
	for (int i = 0; i < RM_MOVE_FIELDS_END; i++) {
		const struct regmap_field *f = &m->f[i];
		if (!f->present)
			continue;
		uint16_t regs[2];
		int rc = f->has_value ? regmap_encode_raw(f, f->value, regs, err) : regmap_encode(f, values[i], regs, err);
		if (rc)
			return acq_err_prefix(err, "%s: %s: ", c->name, regmap_field_name(i));
		if (m->block) {
			memcpy(block + (f->addr - m->block_start), regs, sizeof(uint16_t) * (size_t)regmap_width(f));
		} else if (i != RM_TRIGGER && write_regs(ax, f->addr, regmap_width(f), regs, regmap_field_name(i), err)) {
			return -1;
		}
	}
	if (m->block) {
		if (write_regs(ax, m->block_start, m->block_count, block, "move block", err))
			return -1;
	} else if (m->f[RM_TRIGGER].present) {
		const struct regmap_field *f = &m->f[RM_TRIGGER];
		uint16_t regs[2];
		if (regmap_encode_raw(f, f->value, regs, err) ||
		    write_regs(ax, f->addr, regmap_width(f), regs, "trigger", err))
			return -1;
	}
	if (m->cmd[RM_CMD_START].present)
		return send_cmd(ax, RM_CMD_START, false, err);
	return 0;
}

/* ---- public operations ------------------------------------------------------------------------------ */

static int open_common(const struct axis_cfg *cfg, struct axis_link *shared, struct axis_dev **out, struct acq_err *err)
{
	struct axis_dev *ax = calloc(1, sizeof *ax);
	if (!ax)
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", cfg->name);
	ax->cfg = cfg;
	ax->clear_cmd = -1;
	ax->state = ST_IDLE;
	if (shared) {
		ax->link = shared;
		shared->refs++;
	} else {
		ax->link = calloc(1, sizeof *ax->link);
		if (!ax->link) {
			free(ax);
			return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", cfg->name);
		}
		ax->link->refs = 1;
		if (cfg->link.type == AXIS_LINK_TCP)
			snprintf(ax->link->where, sizeof ax->link->where, "%s:%d", cfg->link.host, cfg->link.port);
		else
			snprintf(ax->link->where, sizeof ax->link->where, "%s", cfg->link.device);
		if (link_connect(ax->link, cfg, err)) {
			mb_close(ax);
			return -1;
		}
	}
	*out = ax;
	return 0;
}

static int mb_open(const struct axis_cfg *cfg, struct axis_dev **out, struct acq_err *err)
{
	return open_common(cfg, NULL, out, err);
}

static int mb_open_shared(const struct axis_cfg *cfg, struct axis_dev *peer, struct axis_dev **out, struct acq_err *err)
{
	const struct axis_link_cfg *a = &cfg->link, *b = &peer->cfg->link;
	if (a->type != b->type || strcmp(a->host, b->host) || a->port != b->port || strcmp(a->device, b->device))
		return acq_errf(err, ACQ_E_INVAL, "%s: its link differs from %s's, it cannot be shared", cfg->name,
				peer->cfg->name);
	return open_common(cfg, peer->link, out, err);
}

static void mb_close(struct axis_dev *ax)
{
	if (!ax)
		return;
	if (ax->link->up && (ax->state == ST_MOVE || ax->state == ST_HOME))
		mb_stop(ax, NULL);
	if (--ax->link->refs == 0) {
		if (ax->link->ctx) {
			modbus_close(ax->link->ctx);
			modbus_free(ax->link->ctx);
		}
		free(ax->link);
	}
	free(ax);
}

static bool mb_connected(const struct axis_dev *ax) { return ax->link->up; }
static double mb_next_poll(const struct axis_dev *ax) { return ax->next_poll; }

static bool bit(const struct regmap *m, uint32_t word, int b)
{
	return m->bit[b] >= 0 && (word >> m->bit[b]) & 1u;
}

static int mb_read_status(struct axis_dev *ax, struct axis_status *st, struct acq_err *err)
{
	const struct regmap *m = ax->cfg->map;
	double word, pos;
	memset(st, 0, sizeof *st);
	if (read_field(ax, RM_STATUS, NULL, &word, err) || read_field(ax, RM_ACTUAL, &pos, NULL, err))
		return -1;
	uint32_t w = (uint32_t)(int64_t)word;
	st->position_deg = pos;
	st->ready = bit(m, w, RM_BIT_READY);
	st->busy = bit(m, w, RM_BIT_BUSY) || bit(m, w, RM_BIT_MOVE);
	st->in_position = bit(m, w, RM_BIT_IN_POS);
	st->alarm = bit(m, w, RM_BIT_ALARM);
	st->homed = bit(m, w, RM_BIT_HOMED);
	if (st->alarm && m->f[RM_ALARM_CODE].present) {
		double code;
		if (read_field(ax, RM_ALARM_CODE, NULL, &code, err))
			return -1;
		st->alarm_code = (int)code;
		if (st->alarm_code == 0)
			st->alarm_code = -1;
	} else if (st->alarm) {
		st->alarm_code = -1; /* in alarm, code unknown */
	}
	return 0;
}

static int mb_read_bits(struct axis_dev *ax, bool *limit_pos, bool *limit_neg, bool *stall, struct acq_err *err)
{
	double word;
	if (read_field(ax, RM_STATUS, NULL, &word, err))
		return -1;
	uint32_t w = (uint32_t)(int64_t)word;
	*limit_pos = bit(ax->cfg->map, w, RM_BIT_LIMIT_POS);
	*limit_neg = bit(ax->cfg->map, w, RM_BIT_LIMIT_NEG);
	*stall = bit(ax->cfg->map, w, RM_BIT_STALL);
	return 0;
}

static int fail_move(struct axis_dev *ax, struct acq_err *err)
{
	ax->state = ST_FAILED;
	ax->fail = *err;
	return AXIS_MOVE_FAILED;
}

/* Start one leg towards `leg`: backlash take-up first when approaching from the wrong side. */
static int start_leg(struct axis_dev *ax, double from, double now, bool allow_pre, struct acq_err *err)
{
	const struct axis_cfg *c = ax->cfg;
	double leg = ax->target;
	ax->pre_leg = false;
	/* Final approach always in backlash_dir: when the move goes the other way, overshoot by the
	 * backlash first (clamped to the soft limits), then come back. */
	if (allow_pre && c->backlash > 0 && (ax->target - from) * c->backlash_dir < 0) {
		leg = ax->target - c->backlash_dir * c->backlash;
		if (leg < c->soft_min)
			leg = c->soft_min;
		if (leg > c->soft_max)
			leg = c->soft_max;
		ax->pre_leg = leg != ax->target;
	}
	if (send_move(ax, leg, err))
		return -1;
	ax->leg = leg;
	ax->leg_start = now;
	ax->seen_busy = false;
	double t = axis_trapezoid_s(leg - from, c->speed, c->accel, c->decel);
	ax->deadline = now + t * c->timeout_factor + c->margin_s;
	ax->next_poll = now + c->poll_s;
	ax->state = ST_MOVE;
	return 0;
}

/* The target to command: target itself, or with wrap_deg the equivalent angle (target + k·wrap) inside the
 * soft limits nearest to the current position. NAN when none lies inside the limits. */
static double resolve_target(const struct axis_cfg *c, double target, double from)
{
	if (c->wrap <= 0)
		return target >= c->soft_min && target <= c->soft_max ? target : NAN;
	double best = NAN;
	double k0 = floor((c->soft_min - target) / c->wrap);
	for (double k = k0; target + k * c->wrap <= c->soft_max; k += 1) {
		double t = target + k * c->wrap;
		if (t >= c->soft_min && (isnan(best) || fabs(t - from) < fabs(best - from)))
			best = t;
	}
	return best;
}

static int mb_move_begin(struct axis_dev *ax, double target_deg, double now, struct acq_err *err)
{
	const struct axis_cfg *c = ax->cfg;
	if (!isfinite(target_deg) || fabs(target_deg) > 1e6)
		return acq_errf(err, ACQ_E_RANGE, "%s: target is not a finite angle", c->name);
	/* without wrap the soft limits are checked before anything is sent */
	if (c->wrap <= 0 && isnan(resolve_target(c, target_deg, 0)))
		return acq_errf(err, ACQ_E_RANGE, "%s: target %g° outside the soft limits [%g°, %g°]", c->name,
				target_deg, c->soft_min, c->soft_max);
	if (c->wrap > 0 && isnan(resolve_target(c, target_deg, target_deg)))
		return acq_errf(err, ACQ_E_RANGE, "%s: no angle equivalent to %g° (modulo %g°) inside the soft "
				"limits [%g°, %g°]", c->name, target_deg, c->wrap, c->soft_min, c->soft_max);
	if (ax->state == ST_MOVE || ax->state == ST_HOME)
		return acq_errf(err, ACQ_E_STATE, "%s: a move is already running", c->name);
	struct axis_status st;
	if (clear_pending(ax, err) || mb_read_status(ax, &st, err))
		return -1;
	if (st.alarm)
		return acq_errf(err, ACQ_E_DEVICE, "%s: controller in alarm (code 0x%x): reset it first", c->name,
				(unsigned)st.alarm_code);
	ax->target = resolve_target(c, target_deg, st.position_deg);
	ax->retries_left = c->retries;
	if (start_leg(ax, st.position_deg, now, true, err)) {
		ax->state = ST_FAILED;
		ax->fail = *err;
		return -1;
	}
	return 0;
}

static double mb_target(const struct axis_dev *ax)
{
	return ax->target;
}

static int mb_move_step(struct axis_dev *ax, double now, struct acq_err *err)
{
	const struct axis_cfg *c = ax->cfg;
	switch (ax->state) {
	case ST_IDLE:
	case ST_DONE:
		return AXIS_MOVE_DONE;
	case ST_FAILED:
		if (err)
			*err = ax->fail;
		return AXIS_MOVE_FAILED;
	default:
		break;
	}
	if (now < ax->next_poll)
		return AXIS_MOVE_RUNNING;
	struct axis_status st;
	if (clear_pending(ax, err) || mb_read_status(ax, &st, err))
		return fail_move(ax, err);
	if (st.alarm) {
		acq_errf(err, ACQ_E_DEVICE, "%s: controller alarm (code 0x%x) at %.4f° during %s", c->name,
			 (unsigned)st.alarm_code, st.position_deg, ax->state == ST_HOME ? "homing" : "a move");
		err->detail = st.alarm_code;
		return fail_move(ax, err);
	}
	if (st.busy)
		ax->seen_busy = true;
	if (st.busy || (!ax->seen_busy && now < ax->leg_start + c->start_grace_s &&
			fabs(st.position_deg - ax->leg) > c->deadband)) {
		/* moving, or not yet seen moving (a controller may take a moment to raise busy) */
		if (now > ax->deadline) {
			struct acq_err e2;
			bool lp = false, ln = false, stall = false;
			mb_read_bits(ax, &lp, &ln, &stall, &e2);
			mb_stop(ax, &e2);
			acq_errf(err, ACQ_E_TIMEOUT, "%s: %s did not complete in time (at %.4f°, target %.4f°%s); stopped",
				 c->name, ax->state == ST_HOME ? "homing" : "move", st.position_deg, ax->leg,
				 stall ? ", the controller reports a stall" : "");
			return fail_move(ax, err);
		}
		ax->next_poll = now + c->poll_s;
		return AXIS_MOVE_RUNNING;
	}
	if (ax->state == ST_HOME) {
		if (c->map->bit[RM_BIT_HOMED] >= 0 && !st.homed) {
			acq_errf(err, ACQ_E_DEVICE, "%s: homing ended without the homed bit (at %.4f°)", c->name,
				 st.position_deg);
			return fail_move(ax, err);
		}
		ax->state = ST_DONE;
		return AXIS_MOVE_DONE;
	}
	if (ax->pre_leg) { /* take-up leg done: final approach */
		if (start_leg(ax, st.position_deg, now, false, err))
			return fail_move(ax, err);
		return AXIS_MOVE_RUNNING;
	}
	double e = st.position_deg - ax->target;
	if (fabs(e) <= c->deadband) {
		/* in position: settle, then confirm it stayed there (a second read after settle_s) */
		if (ax->state == ST_SETTLE || c->settle_s <= 0) {
			ax->state = ST_DONE;
			return AXIS_MOVE_DONE;
		}
		ax->state = ST_SETTLE;
		ax->next_poll = now + c->settle_s;
		return AXIS_MOVE_RUNNING;
	}
	if (ax->retries_left > 0) {
		ax->retries_left--;
		if (start_leg(ax, st.position_deg, now, true, err))
			return fail_move(ax, err);
		return AXIS_MOVE_RUNNING;
	}
	acq_errf(err, ACQ_E_RANGE, "%s: not in position after %d retries: at %.4f°, target %.4f°, deadband %g°",
		 c->name, c->retries, st.position_deg, ax->target, c->deadband);
	return fail_move(ax, err);
}

static int mb_move_retries_used(const struct axis_dev *ax)
{
	return ax->cfg->retries - ax->retries_left;
}

static int mb_stop(struct axis_dev *ax, struct acq_err *err)
{
	struct acq_err local;
	if (!err)
		err = &local;
	if (clear_pending(ax, err) && !ax->link->up)
		return -1;
	int rc = send_cmd(ax, RM_CMD_STOP, true, err);
	if (ax->state == ST_MOVE || ax->state == ST_HOME || ax->state == ST_SETTLE) {
		ax->state = ST_FAILED;
		acq_errf(&ax->fail, ACQ_E_STATE, "%s: move stopped by request", ax->cfg->name);
	}
	return rc;
}

static int mb_home_begin(struct axis_dev *ax, double now, struct acq_err *err)
{
	if (ax->state == ST_MOVE || ax->state == ST_HOME)
		return acq_errf(err, ACQ_E_STATE, "%s: a move is already running", ax->cfg->name);
	if (clear_pending(ax, err) || send_cmd(ax, RM_CMD_HOME, false, err))
		return -1;
	ax->state = ST_HOME;
	ax->leg = 0;
	ax->leg_start = now;
	ax->seen_busy = false;
	ax->deadline = now + ax->cfg->home_timeout_s;
	ax->next_poll = now + ax->cfg->poll_s;
	return 0;
}

static int mb_alarm_reset(struct axis_dev *ax, struct acq_err *err)
{
	if (clear_pending(ax, err) || send_cmd(ax, RM_CMD_ALARM_RESET, true, err))
		return -1;
	if (ax->state == ST_FAILED)
		ax->state = ST_IDLE;
	return 0;
}

static int mb_identity(struct axis_dev *ax, struct axis_identity *id, struct acq_err *err)
{
	const struct regmap *m = ax->cfg->map;
	memset(id, 0, sizeof *id);
	snprintf(id->vendor, sizeof id->vendor, "%s", m->vendor);
	snprintf(id->model, sizeof id->model, "%s", m->model);
	double v;
	if (m->f[RM_SERIAL].present) {
		if (read_field(ax, RM_SERIAL, NULL, &v, err))
			return -1;
		snprintf(id->serial, sizeof id->serial, "%.0f", v);
	}
	if (m->f[RM_FIRMWARE].present) {
		if (read_field(ax, RM_FIRMWARE, NULL, &v, err))
			return -1;
		snprintf(id->firmware, sizeof id->firmware, "%.0f", v);
	}
	return 0;
}

static int mb_reconnect(struct axis_dev *ax, struct acq_err *err)
{
	if (link_connect(ax->link, ax->cfg, err))
		return -1;
	if (ax->state == ST_MOVE || ax->state == ST_HOME || ax->state == ST_SETTLE) {
		ax->state = ST_FAILED;
		acq_errf(&ax->fail, ACQ_E_DISCONNECTED, "%s: link was lost during the move", ax->cfg->name);
	}
	ax->clear_cmd = -1;
	return 0;
}

const struct axis_backend axis_modbus_backend = {
	.name = "modbus", .open = mb_open, .close = mb_close, .read_status = mb_read_status,
	.move_begin = mb_move_begin, .move_step = mb_move_step, .next_poll = mb_next_poll, .stop = mb_stop,
	.home_begin = mb_home_begin, .alarm_reset = mb_alarm_reset, .identity = mb_identity,
	.reconnect = mb_reconnect, .connected = mb_connected,
};

const struct axis_backend *axis_cfg_backend(const struct axis_cfg *cfg)
{
	return cfg->link.type == AXIS_LINK_FAKE ? &axis_fake_backend : &axis_modbus_backend;
}

/* ---- extras of the Modbus backend (axis_modbus.h) ---------------------------------------------------- */

static struct axis_dev *mb_of(const struct axis *ax)
{
	return axis_dev_of(ax, &axis_modbus_backend);
}

int axis_open_shared(const struct axis_cfg *cfg, struct axis *peer, struct axis **out, struct acq_err *err)
{
	struct axis_dev *p = mb_of(peer), *d = NULL;
	if (!p || cfg->link.type == AXIS_LINK_FAKE)
		return acq_errf(err, ACQ_E_INVAL, "%s: only Modbus links can be shared", cfg->name);
	if (mb_open_shared(cfg, p, &d, err))
		return -1;
	return axis_wrap(cfg, &axis_modbus_backend, d, out, err);
}

int axis_read_bits(struct axis *ax, bool *limit_pos, bool *limit_neg, bool *stall, struct acq_err *err)
{
	struct axis_dev *d = mb_of(ax);
	if (!d)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "axis: limit and stall bits need a Modbus axis");
	return mb_read_bits(d, limit_pos, limit_neg, stall, err);
}

double axis_target(const struct axis *ax)
{
	const struct axis_dev *d = mb_of(ax);
	return d ? mb_target(d) : NAN;
}

int axis_move_retries_used(const struct axis *ax)
{
	const struct axis_dev *d = mb_of(ax);
	return d ? mb_move_retries_used(d) : 0;
}
