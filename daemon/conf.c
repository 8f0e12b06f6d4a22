/* conf: loading and validating the daemon's configuration file (see conf.h). */
#include "daemon/conf.h"

#include <errno.h>
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <syslog.h>

#include "config/acq_file.h"
#include "drivers/axis.h"
#include "drivers/laser.h"
#include "drivers/spectro.h"

#include "daemon/plan/plan.h"

/* Owned strings built from the file (joined paths); freed with the configuration. */
struct conf_priv {
	struct conf pub;
	char dbpath[4096], recondir[4096];
};

static const char *const dev_names[CONF_DEV__COUNT] = { "laser.theta", "detector.theta", "detector.phi",
							"spectrometer", "laser" };

const char *conf_dev_name(enum conf_dev d)
{
	return (unsigned)d < CONF_DEV__COUNT ? dev_names[d] : "?";
}

/* ---- --sim ports file ------------------------------------------------------------------------------- */

static int sim_port(json_t *root, const char *key, int *out, const char *path, struct acq_err *err)
{
	json_t *o = json_object_get(root, key);
	if (!o)
		return 0;
	json_t *p = json_object_get(o, "port");
	if (!json_is_object(o) || !json_is_integer(p) || json_integer_value(p) < 1 || json_integer_value(p) > 65535)
		return acq_errf(err, ACQ_E_CONFIG, "%s: \"%s\": expected {\"port\": 1..65535}", path, key);
	*out = (int)json_integer_value(p);
	return 0;
}

static int sim_str(json_t *root, const char *key, const char *field, char *out, size_t cap, const char *path,
		   struct acq_err *err)
{
	json_t *o = json_object_get(root, key);
	if (!o)
		return 0;
	json_t *s = json_object_get(o, field);
	if (!json_is_object(o) || !json_is_string(s) || !json_string_length(s) ||
	    json_string_length(s) >= cap || strchr(json_string_value(s), '\n'))
		return acq_errf(err, ACQ_E_CONFIG, "%s: \"%s\": expected {\"%s\": \"path\"}", path, key, field);
	snprintf(out, cap, "%s", json_string_value(s));
	return 0;
}

int conf_sim_read(const char *path, struct conf_sim *sim, struct acq_err *err)
{
	memset(sim, 0, sizeof *sim);
	json_error_t je;
	json_t *root = json_load_file(path, 0, &je);
	if (!root)
		return acq_errf(err, ACQ_E_CONFIG, "%s:%d:%d: %s (expected the simulator's ports file, JSON)", path,
				je.line, je.column, je.text);
	int rc = -1;
	if (!json_is_object(root)) {
		acq_errf(err, ACQ_E_CONFIG, "%s: expected a JSON object", path);
		goto out;
	}
	if (sim_port(root, "laser_arm", &sim->laser_arm_port, path, err) ||
	    sim_port(root, "detector_arm", &sim->detector_arm_port, path, err) ||
	    sim_str(root, "laser", "device", sim->laser_device, sizeof sim->laser_device, path, err) ||
	    sim_str(root, "spectrometer", "socket", sim->spectro_socket, sizeof sim->spectro_socket, path, err) ||
	    sim_str(root, "control", "socket", sim->control_socket, sizeof sim->control_socket, path, err))
		goto out;
	sim->time_scale = 1;
	json_t *ts = json_object_get(root, "time_scale");
	if (ts && (!json_is_number(ts) || !(json_number_value(ts) >= 0.01 && json_number_value(ts) <= 100000))) {
		acq_errf(err, ACQ_E_CONFIG, "%s: \"time_scale\": expected a number in [0.01, 100000]", path);
		goto out;
	}
	if (ts)
		sim->time_scale = json_number_value(ts);
	rc = 0;
out:
	json_decref(root);
	return rc;
}

/* Splice src's keys into dst (both mappings): maps merge recursively, anything else replaces or is added.
 * The spliced nodes stay owned by src's document; only dst's arrays grow (with the allocator yconf uses). */
static int map_merge(struct yc_node *dst, struct yc_node *src)
{
	for (size_t i = 0; i < src->n; i++) {
		struct yc_node *k = src->keys[i], *v = src->items[i];
		size_t j = 0;
		for (; j < dst->n; j++)
			if (dst->keys[j]->type == YC_SCALAR && !strcmp(dst->keys[j]->value, k->value))
				break;
		if (j < dst->n) {
			if (dst->items[j]->type == YC_MAP && v->type == YC_MAP) {
				if (map_merge(dst->items[j], v))
					return -1;
			} else {
				dst->items[j] = v;
			}
			continue;
		}
		if (dst->n == dst->cap) {
			size_t c = dst->cap ? dst->cap * 2 : 4;
			struct yc_node **it = realloc(dst->items, c * sizeof *it);
			if (!it)
				return -1;
			dst->items = it;
			struct yc_node **ks = realloc(dst->keys, c * sizeof *ks);
			if (!ks)
				return -1;
			dst->keys = ks;
			bool *u = realloc(dst->used, c * sizeof *u);
			if (!u)
				return -1;
			dst->used = u;
			dst->cap = c;
		}
		dst->keys[dst->n] = k;
		dst->items[dst->n] = v;
		dst->used[dst->n] = false;
		dst->n++;
	}
	return 0;
}

static void yaml_quote(char *out, size_t cap, const char *s)
{
	json_t *js = json_string(s);
	char *j = js ? json_dumps(js, JSON_ENCODE_ANY) : NULL; /* a JSON string is a YAML double-quoted scalar */
	snprintf(out, cap, "%s", j ? j : "\"\"");
	free(j);
	json_decref(js);
}

static bool backend_is(struct yc_node *devs, const char *dev, const char *key, const char *want)
{
	struct yc_node *d = devs ? yc_get(devs, dev) : NULL;
	struct yc_node *b = d && d->type == YC_MAP ? yc_get(d, key) : NULL;
	if (d && d->type == YC_MAP) /* yc_get marked it used; the driver parser will ask again */
		for (size_t i = 0; i < d->n; i++)
			if (d->keys[i]->value && !strcmp(d->keys[i]->value, key))
				d->used[i] = false;
	return b && b->type == YC_SCALAR && !strcmp(b->value, want);
}

static int apply_sim(struct conf *c, struct yc_node *devs, const struct conf_sim *sim, struct acq_err *err)
{
	char text[4096], q[600];
	size_t n = 0;
	text[0] = 0;
	if (sim->laser_arm_port)
		n += (size_t)snprintf(text + n, sizeof text - n,
				      "laser_arm: {link: {host: \"127.0.0.1\", port: %d}}\n", sim->laser_arm_port);
	if (sim->detector_arm_port)
		n += (size_t)snprintf(text + n, sizeof text - n,
				      "detector_arm: {link: {host: \"127.0.0.1\", port: %d}}\n", sim->detector_arm_port);
	if (sim->laser_device[0]) {
		yaml_quote(q, sizeof q, sim->laser_device);
		n += (size_t)snprintf(text + n, sizeof text - n, "laser: {device: %s}\n", q);
	}
	if (sim->spectro_socket[0] && backend_is(devs, "spectrometer", "backend", "sim")) {
		yaml_quote(q, sizeof q, sim->spectro_socket);
		n += (size_t)snprintf(text + n, sizeof text - n, "spectrometer: {socket: %s}\n", q);
	}
	if (!n || !devs || devs->type != YC_MAP) /* not a mapping: parse_devices() reports it */
		return 0;
	if (yc_load_string("--sim ports file", text, n, &c->simdoc, err))
		return -1;
	if (map_merge(devs, yc_root(c->simdoc)))
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	return 0;
}

/* ---- sections ---------------------------------------------------------------------------------------- */

static int principals(struct yc_node *map, const char *key, const char **out, int *n, struct acq_err *err)
{
	struct yc_node *seq = yc_get(map, key);
	if (!seq)
		return 0;
	if (seq->type != YC_SEQ)
		return yc_errf(err, seq, "daemon.%s: expected a sequence of user names or \"@group\" names", key);
	if (seq->n > CONF_MAX_PRINCIPALS)
		return yc_errf(err, seq, "daemon.%s: at most %d entries", key, CONF_MAX_PRINCIPALS);
	*n = 0;
	for (size_t i = 0; i < seq->n; i++) {
		struct yc_node *it = seq->items[i];
		if (it->type != YC_SCALAR || !it->value[0] || !strcmp(it->value, "@"))
			return yc_errf(err, it, "daemon.%s: expected a user name or \"@group\"", key);
		out[(*n)++] = it->value;
	}
	return 0;
}

static int abs_path(struct yc_node *map, const char *key, const char **out, const char *what,
		    struct acq_err *err)
{
	const char *s = NULL;
	if (yc_string(map, key, false, &s, err))
		return -1;
	if (!s)
		return 0;
	if (s[0] != '/' || strlen(s) > 200)
		return yc_errf(err, yc_get(map, key), "%s: expected an absolute path (at most 200 bytes)", what);
	*out = s;
	return 0;
}

static int parse_daemon(struct conf_priv *cp, struct yc_node *node, struct acq_err *err)
{
	struct conf_daemon *d = &cp->pub.d;
	d->state_dir = "/var/lib/acquisitiond";
	d->socket_path = "/run/acquisitiond/acquisitiond.sock";
	d->socket_mode = 0660;
	d->log_level = LOG_INFO;
	d->auto_resume = true;
	d->device_retry_s = 5;
	d->observer_rate = CONF_OBSERVER_RATE;
	d->observer_burst = CONF_OBSERVER_BURST;
	d->plan_cpu_s = CONF_PLAN_CPU_S;
	d->plan_deadline_s = CONF_PLAN_DEADLINE_S;
	const char *db = "acquisition.db";
	if (!node)
		goto paths;
	if (yc_expect_map(node, "daemon", err))
		return -1;
	if (abs_path(node, "state_dir", &d->state_dir, "daemon.state_dir", err) ||
	    yc_string(node, "database", false, &db, err))
		return -1;
	struct yc_node *sock = yc_get(node, "socket");
	if (sock) {
		if (yc_expect_map(sock, "daemon.socket", err) ||
		    abs_path(sock, "path", &d->socket_path, "daemon.socket.path", err) ||
		    yc_string(sock, "group", false, &d->socket_group, err))
			return -1;
		struct yc_node *m = yc_get(sock, "mode");
		if (m) {
			char *end = NULL;
			errno = 0;
			long v = m->type == YC_SCALAR ? strtol(m->value, &end, 8) : -1;
			if (m->type != YC_SCALAR || errno || !end || *end || end == m->value || v < 0 || v > 0777 ||
			    (v & 0600) != 0600)
				return yc_errf(err, m, "daemon.socket.mode: expected an octal mode such as \"0660\" "
						       "(owner read-write required)");
			d->socket_mode = (mode_t)v;
		}
		if (yc_check_unknown(sock, "daemon.socket", err))
			return -1;
	}
	long long port = 0, plan_cpu = d->plan_cpu_s;
	if (yc_int(node, "tcp_port", false, 0, 65535, &port, err))
		return -1;
	d->tcp_port = (int)port;
	if (principals(node, "controllers", d->controllers, &d->ncontrollers, err) ||
	    principals(node, "observers", d->observers, &d->nobservers, err))
		return -1;
	static const char *const levels[] = { "error", "warning", "notice", "info", "debug", NULL };
	int lv = -1;
	if (yc_enum(node, "log_level", false, levels, &lv, err))
		return -1;
	if (lv >= 0)
		d->log_level = LOG_ERR + lv;
	if (yc_bool(node, "auto_resume", false, &d->auto_resume, err) ||
	    yc_double(node, "device_retry_s", false, 0.1, 3600, &d->device_retry_s, err) ||
	    yc_double(node, "watchdog_s", false, 0, 3600, &d->watchdog_s, err) ||
	    yc_double(node, "observer_rate", false, 0, 100000, &d->observer_rate, err) ||
	    yc_double(node, "observer_burst", false, 1, 100000, &d->observer_burst, err) ||
	    yc_int(node, "plan_cpu_s", false, 1, 3600, &plan_cpu, err) ||
	    yc_double(node, "plan_deadline_s", false, 1, 3600, &d->plan_deadline_s, err) ||
	    yc_check_unknown(node, "daemon", err))
		return -1;
	d->plan_cpu_s = (int)plan_cpu;
paths:
	if (strstr(db, "..") || !db[0])
		return yc_errf(err, node ? yc_get(node, "database") : NULL,
			       "daemon.database: expected a file name under state_dir or an absolute path");
	if (db[0] == '/')
		snprintf(cp->dbpath, sizeof cp->dbpath, "%s", db);
	else
		snprintf(cp->dbpath, sizeof cp->dbpath, "%s/%s", d->state_dir, db);
	d->database = cp->dbpath;
	return 0;
}

static int parse_sweep(struct conf_sweep *s, struct yc_node *node, struct acq_err *err)
{
	*s = (struct conf_sweep){ .move_timeout_s = 60, .move_retries = 2, .extra_settle_s = 0, .target_peak = 0.75,
				  .min_integration_ms = 1, .max_integration_ms = 10000, .averages = 1, .dark_every = 0,
				  .auto_resume_faults = true, .auto_recon = true };
	if (!node)
		return 0;
	long long retries = s->move_retries, avg = s->averages, dark = s->dark_every;
	if (yc_expect_map(node, "sweep", err) ||
	    yc_double(node, "move_timeout_s", false, 0.1, 3600, &s->move_timeout_s, err) ||
	    yc_int(node, "move_retries", false, 0, 10, &retries, err) ||
	    yc_double(node, "extra_settle_s", false, 0, 60, &s->extra_settle_s, err) ||
	    yc_double(node, "target_peak", false, 0.1, 0.95, &s->target_peak, err) ||
	    yc_double(node, "min_integration_ms", false, 0.002, 600000, &s->min_integration_ms, err) ||
	    yc_double(node, "max_integration_ms", false, 0.002, 600000, &s->max_integration_ms, err) ||
	    yc_int(node, "averages", false, 1, 10000, &avg, err) ||
	    yc_int(node, "dark_every", false, -1, 100000, &dark, err) ||
	    yc_bool(node, "auto_resume_faults", false, &s->auto_resume_faults, err) ||
	    yc_bool(node, "auto_recon", false, &s->auto_recon, err))
		return -1;
	s->acquisition = yc_get(node, "acquisition"); /* validated by the sweep executor (sweep_init) */
	s->calibration = yc_get(node, "calibration");
	if (yc_check_unknown(node, "sweep", err))
		return -1;
	if (s->min_integration_ms > s->max_integration_ms)
		return yc_errf(err, yc_get(node, "min_integration_ms"),
			       "sweep.min_integration_ms: expected at most max_integration_ms (%g)",
			       s->max_integration_ms);
	s->move_retries = (int)retries;
	s->averages = (int)avg;
	s->dark_every = (int)dark;
	return 0;
}

static int parse_recon(struct conf_priv *cp, struct yc_node *node, struct acq_err *err)
{
	struct conf_recon *r = &cp->pub.recon;
	*r = (struct conf_recon){ .program = "brdf-recon", .timeout_s = 3600, .threads = 1 };
	const char *outdir = "recon";
	if (node) {
		long long th = r->threads;
		if (yc_expect_map(node, "recon", err) || yc_string(node, "program", false, &r->program, err) ||
		    yc_double(node, "timeout_s", false, 1, 7 * 86400, &r->timeout_s, err) ||
		    yc_int(node, "threads", false, 1, 256, &th, err) ||
		    yc_string(node, "output_dir", false, &outdir, err))
			return -1;
		r->threads = (int)th;
		struct yc_node *args = yc_get(node, "extra_args");
		if (args) {
			if (args->type != YC_SEQ || args->n > 8)
				return yc_errf(err, args, "recon.extra_args: expected a sequence of at most 8 strings");
			for (size_t i = 0; i < args->n; i++) {
				if (args->items[i]->type != YC_SCALAR)
					return yc_errf(err, args->items[i], "recon.extra_args: expected a string");
				r->extra_args[r->nextra++] = args->items[i]->value;
			}
		}
		if (yc_check_unknown(node, "recon", err))
			return -1;
		if (!r->program[0])
			return yc_errf(err, yc_get(node, "program"), "recon.program: expected a program name or path");
		if (outdir[0] == '/' || strstr(outdir, "..") || !outdir[0])
			return yc_errf(err, yc_get(node, "output_dir"),
				       "recon.output_dir: expected a relative directory under daemon.state_dir");
	}
	snprintf(cp->recondir, sizeof cp->recondir, "%s/%s", cp->pub.d.state_dir, outdir);
	r->output_dir = cp->recondir;
	return 0;
}

/* Run one driver parser: ACQ_E_UNSUPPORTED (driver not there yet) is a note, anything else an error. */
static int driver_result(struct conf *c, enum conf_dev d, int rc, struct acq_err *err)
{
	c->devpresent[d] = true;
	if (rc == 0)
		return 0;
	if (err && err->code == ACQ_E_UNSUPPORTED) {
		snprintf(c->devnote[d], sizeof c->devnote[d], "%s", err->msg);
		acq_err_clear(err);
		return 0;
	}
	return -1;
}

#include "drivers/axis_modbus.h"

/* One arm: its axes go to the slots named by axes[] ("theta", "phi"); the Modbus driver parses the whole
 * arm (link, arm-level timeouts, axes, unknown keys). */
static int parse_arm(struct conf *c, struct yc_node *devs, struct yc_node *maps, const char *arm,
		     const char *const *axes, const enum conf_dev *slots, int naxes, struct acq_err *err)
{
	struct yc_node *node = yc_get(devs, arm);
	if (!node) {
		for (int i = 0; i < naxes; i++)
			snprintf(c->devnote[slots[i]], sizeof c->devnote[0], "devices.%s: not configured", arm);
		return 0;
	}
	char what[64];
	snprintf(what, sizeof what, "devices.%s", arm);
	if (yc_expect_map(node, what, err))
		return -1;
	struct yc_node *ax = yc_get(node, "axes");
	if (!ax || (ax->type == YC_MAP && ax->n == 0)) {
		for (int i = 0; i < naxes; i++)
			snprintf(c->devnote[slots[i]], sizeof c->devnote[0], "devices.%s.axes: not configured", arm);
		/* Nothing to drive on this arm: its other keys are not checked (an empty arm is a placeholder). */
		for (size_t i = 0; i < node->n; i++)
			node->used[i] = true;
		return 0;
	}
	snprintf(what, sizeof what, "devices.%s.axes", arm);
	if (yc_expect_map(ax, what, err))
		return -1;
	for (size_t k = 0; k < ax->n; k++) {
		int i = 0;
		while (i < naxes && strcmp(ax->keys[k]->value, axes[i]))
			i++;
		if (i == naxes) {
			ax->used[k] = false;
			return yc_check_unknown(ax, what, err);
		}
	}
	struct axis_cfg *got[4] = { 0 };
	int n = 0;
	if (axis_arm_parse(node, maps, arm, got, 4, &n, err))
		return -1;
	for (int k = 0; k < n; k++) {
		const char *full = axis_cfg_name(got[k]), *dot = full ? strchr(full, '.') : NULL;
		int i = 0;
		while (dot && i < naxes && strcmp(dot + 1, axes[i]))
			i++;
		if (!dot || i == naxes) { /* cannot happen: the names were checked above */
			for (int j = 0; j < n; j++)
				axis_cfg_free(got[j]);
			return yc_errf(err, ax, "%s: unexpected axis '%s'", what, full ? full : "?");
		}
		c->axis[slots[i]] = got[k];
		c->devpresent[slots[i]] = true;
	}
	return 0;
}

static int parse_devices(struct conf *c, struct yc_node *devs, struct acq_err *err)
{
	if (!devs) {
		for (int d = 0; d < CONF_DEV__COUNT; d++)
			snprintf(c->devnote[d], sizeof c->devnote[d], "devices: not configured");
		return 0;
	}
	if (yc_expect_map(devs, "devices", err))
		return -1;
	struct yc_node *maps = yc_get(devs, "register_maps");
	if (maps && yc_expect_map(maps, "devices.register_maps", err))
		return -1;
	static const char *const la[] = { "theta" }, *const da[] = { "theta", "phi" };
	static const enum conf_dev ls[] = { CONF_DEV_LASER_THETA },
				   ds[] = { CONF_DEV_DETECTOR_THETA, CONF_DEV_DETECTOR_PHI };
	if (parse_arm(c, devs, maps, "laser_arm", la, ls, 1, err) ||
	    parse_arm(c, devs, maps, "detector_arm", da, ds, 2, err))
		return -1;
	struct yc_node *sp = yc_get(devs, "spectrometer"), *ls_ = yc_get(devs, "laser");
	if (!sp)
		snprintf(c->devnote[CONF_DEV_SPECTRO], sizeof c->devnote[0], "devices.spectrometer: not configured");
	else if (driver_result(c, CONF_DEV_SPECTRO, spectro_cfg_parse(sp, &c->spectro, err), err))
		return -1;
	if (!ls_)
		snprintf(c->devnote[CONF_DEV_LASER], sizeof c->devnote[0], "devices.laser: not configured");
	else if (driver_result(c, CONF_DEV_LASER, laser_cfg_parse(ls_, &c->laser, err), err))
		return -1;
	/* register_maps belong to the axis driver (it reads them through axis_cfg_parse). */
	if (maps)
		for (size_t i = 0; i < devs->n; i++)
			if (!strcmp(devs->keys[i]->value, "register_maps"))
				devs->used[i] = true;
	return yc_check_unknown(devs, "devices", err);
}

/* home.park: where `acqctl home` (all axes) leaves each axis after referencing it. Each value within the bench's
 * axis limits and the controller's soft limits; the three together a pose with the arms clear of each other,
 * the beam and the view. Absent: no parks (c->have_park false). */
static int parse_home(struct conf *c, struct yc_node *node, struct acq_err *err)
{
	c->have_park = false;
	if (!node)
		return 0;
	struct yc_node *park = yc_get(node, "park");
	if (yc_expect_map(node, "home", err) || (park && yc_expect_map(park, "home.park", err)))
		return -1;
	if (park) {
		const struct bench_axis *ba[3] = { &c->bench.laser_theta, &c->bench.detector_theta,
						   &c->bench.detector_phi };
		for (int a = 0; a < 3; a++) {
			const char *name = conf_dev_name((enum conf_dev)a);
			double lo = ba[a]->min_deg, hi = ba[a]->max_deg;
			if (c->axis[a]) {
				double smin, smax;
				axis_cfg_limits(c->axis[a], &smin, &smax);
				lo = smin > lo ? smin : lo;
				hi = smax < hi ? smax : hi;
			}
			if (!yc_get(park, name))
				return yc_errf(err, park, "home.park: %s missing (expected a park for each of laser.theta, "
					       "detector.theta, detector.phi)", name);
			char what[64];
			snprintf(what, sizeof what, "home.park.%s (soft limits)", name);
			if (yc_node_double(yc_get(park, name), what, lo, hi, &c->park[a], err))
				return -1;
		}
		struct plan_pos p = { c->park[0], c->park[1], c->park[2] };
		unsigned blind = plan_blind(&c->bench, &p);
		if (blind)
			return yc_errf(err, park, "home.park: the pose (%g°, %g°, %g°) is %s%s; expected a pose with the "
				       "arms clear of each other, the beam and the view", p.laser_theta, p.det_theta,
				       p.det_phi, blind & PLAN_R_COLLISION ? "a collision of the arms" : "in a blind zone: ",
				       blind & PLAN_R_COLLISION ? "" : plan_reason_name(blind));
		if (yc_check_unknown(park, "home.park", err))
			return -1;
		c->have_park = true;
	}
	return yc_check_unknown(node, "home", err);
}

/* The largest configuration file read (acq_file_read refuses a larger one). */
#define CONF_MAX_BYTES ((size_t)16 << 20)

int conf_load(const char *path, const struct conf_sim *sim, struct conf **out, struct acq_err *err)
{
	*out = NULL;
	char *text;
	size_t len;
	if (acq_file_read(path, CONF_MAX_BYTES, 0, &text, &len, err))
		return -1;
	int rc = conf_load_text(path, text, len, sim, out, err); /* len: a NUL byte in the file is an error */
	free(text);
	return rc;
}

int conf_load_text(const char *name, const char *text, size_t len, const struct conf_sim *sim, struct conf **out,
		   struct acq_err *err)
{
	*out = NULL;
	struct conf_priv *cp = calloc(1, sizeof *cp);
	if (!cp)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	struct conf *c = &cp->pub;
	if (!(c->path = strdup(name)) || !(c->text = malloc(len + 1))) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto fail;
	}
	memcpy(c->text, text, len);
	c->text[len] = 0;
	if (yc_load_string(name, c->text, len, &c->doc, err))
		goto fail;
	struct yc_node *root = yc_root(c->doc);
	if (!root) {
		yc_errf(err, NULL, "%s: empty configuration: expected a mapping with bench, devices, daemon", name);
		goto fail;
	}
	if (yc_expect_map(root, "the configuration", err))
		goto fail;
	bench_defaults(&c->bench);
	struct yc_node *bench = yc_get(root, "bench");
	if (bench && bench_parse(bench, &c->bench, err))
		goto fail;
	struct yc_node *devs = yc_get(root, "devices");
	if (sim) {
		c->sim = *sim;
		c->have_sim = true;
		if (apply_sim(c, devs, sim, err))
			goto fail;
	}
	if (parse_devices(c, devs, err))
		goto fail;
	struct yc_node *simsec = yc_get(root, "sim"); /* acq-sim's section: accepted, not interpreted here */
	if (simsec && simsec->type != YC_MAP) {
		yc_errf(err, simsec, "sim: expected a mapping (the simulator's section)");
		goto fail;
	}
	if (parse_daemon(cp, yc_get(root, "daemon"), err) || parse_sweep(&c->sweep, yc_get(root, "sweep"), err) ||
	    parse_recon(cp, yc_get(root, "recon"), err) || parse_home(c, yc_get(root, "home"), err) ||
	    yc_check_unknown(root, "the configuration", err))
		goto fail;
	*out = c;
	return 0;
fail:
	conf_free(c);
	return -1;
}

void conf_free(struct conf *c)
{
	if (!c)
		return;
	for (int i = 0; i < 3; i++)
		axis_cfg_free(c->axis[i]);
	spectro_cfg_free(c->spectro);
	laser_cfg_free(c->laser);
	yc_free(c->doc);
	yc_free(c->simdoc);
	free(c->text);
	free(c->path);
	free((struct conf_priv *)c);
}
