/* axis_modbus_cfg: the axis configuration (a link of type tcp|rtu|fake, the unit, the register map, limits,
 * backlash, timing) parsed from YAML, its accessors, and the backend its link type selects. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "drivers/axis_backend.h"
#include "drivers/axis_modbus_int.h"

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
	c->watch_s = 0.5;
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
	    yc_double(node, "watch_s", false, 1e-3, 60, &c->watch_s, err) ||
	    yc_double(node, "home_timeout_s", false, 0.1, 36000, &c->home_timeout_s, err) ||
	    yc_double(node, "start_grace_s", false, 0, 60, &c->start_grace_s, err) ||
	    yc_double(node, "wrap_deg", false, 0, 720, &c->wrap, err))
		goto fail;
	if (c->watch_s < c->poll_s)
		c->watch_s = c->poll_s; /* never polled more often than poll_s asks */
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

const struct axis_backend *axis_cfg_backend(const struct axis_cfg *cfg)
{
	return cfg->link.type == AXIS_LINK_FAKE ? &axis_fake_backend : &axis_modbus_backend;
}
