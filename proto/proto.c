/* proto: framing, request validation and formatting of the JSON-lines protocol (see proto.h). */
#include "proto/proto.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void proto_lines_init(struct proto_lines *pl)
{
	memset(pl, 0, sizeof *pl);
}

void proto_lines_free(struct proto_lines *pl)
{
	free(pl->buf);
	memset(pl, 0, sizeof *pl);
}

static void consume(struct proto_lines *pl, size_t n)
{
	memmove(pl->buf, pl->buf + n, pl->len - n);
	pl->len -= n;
}

int proto_lines_feed(struct proto_lines *pl, const char *data, size_t n)
{
	if (pl->taken) {
		consume(pl, pl->taken);
		pl->taken = 0;
	}
	if (pl->len + n + 1 > pl->cap) {
		size_t c = pl->cap ? pl->cap : 4096;
		while (c < pl->len + n + 1)
			c *= 2;
		char *b = realloc(pl->buf, c);
		if (!b)
			return -1;
		pl->buf = b;
		pl->cap = c;
	}
	memcpy(pl->buf + pl->len, data, n);
	pl->len += n;
	return 0;
}

int proto_lines_next(struct proto_lines *pl, char **line, size_t *len)
{
	if (pl->taken) {
		consume(pl, pl->taken);
		pl->taken = 0;
	}
	size_t max = pl->max ? pl->max : PROTO_MAX_LINE;
	for (;;) {
		char *nl = pl->len ? memchr(pl->buf, '\n', pl->len) : NULL;
		if (pl->discarding) {
			if (!nl) {
				pl->len = 0;
				return PROTO_LINE_NONE;
			}
			consume(pl, (size_t)(nl - pl->buf) + 1);
			pl->discarding = false;
			continue;
		}
		if (!nl) {
			if (pl->len > max) {
				/* Answer as soon as the bound is passed; the rest of the line is dropped as it comes. */
				pl->len = 0;
				pl->discarding = true;
				return PROTO_LINE_TOO_LONG;
			}
			return PROTO_LINE_NONE;
		}
		size_t l = (size_t)(nl - pl->buf);
		if (l > max) {
			consume(pl, l + 1);
			return PROTO_LINE_TOO_LONG;
		}
		pl->buf[l] = 0;
		pl->taken = l + 1;
		if (l && pl->buf[l - 1] == '\r')
			pl->buf[--l] = 0;
		*line = pl->buf;
		*len = l;
		return PROTO_LINE_OK;
	}
}

/* ---- command table ---- */
#define S(n, req, maxlen) { n, PROTO_T_STRING, req, 0, maxlen, NULL }
#define I(n, req, lo, hi) { n, PROTO_T_INT, req, lo, hi, NULL }
#define N(n, req, lo, hi) { n, PROTO_T_NUMBER, req, lo, hi, NULL }
#define B(n, req) { n, PROTO_T_BOOL, req, 0, 0, NULL }
#define NA(n, lo, hi, of) { n, PROTO_T_NUMBER, false, lo, hi, of }
#define ID_MAX 9007199254740991.0

const struct proto_cmd proto_cmds[] = {
	{ "version", PROTO_OBSERVER, "daemon and protocol version", { { 0 } }, 0 },
	{ "status", PROTO_OBSERVER, "daemon, sweep and device summary", { { 0 } }, 0 },
	{ "devices", PROTO_OBSERVER, "each device: configured, connected, state, identity", { { 0 } }, 0 },
	{ "config", PROTO_OBSERVER, "the running configuration (daemon, sweep, recon; text with text=true)",
	  { B("text", false) }, 1 },
	{ "plan", PROTO_OBSERVER, "dry run of a plan (YAML text): points, blind zones, duration (steps with points)",
	  { S("plan", true, 1 << 20), B("points", false) }, 2 },
	{ "sweep.start", PROTO_CONTROLLER, "start a sweep from a plan (YAML text)",
	  { S("plan", true, 1 << 20), S("name", false, 200) }, 2 },
	{ "sweep.pause", PROTO_CONTROLLER, "pause the running sweep after the current spectrum", { { 0 } }, 0 },
	{ "sweep.resume", PROTO_CONTROLLER, "resume a paused or interrupted sweep", { I("sweep", false, 1, ID_MAX) }, 1 },
	{ "sweep.abort", PROTO_CONTROLLER, "abort the current sweep (laser off, arms stopped)", { { 0 } }, 0 },
	{ "sweep.list", PROTO_OBSERVER, "recent sweeps from the database", { I("limit", false, 1, 10000) }, 1 },
	{ "sweep.show", PROTO_OBSERVER, "one sweep: state, counts, events (points with points=true)",
	  { I("sweep", true, 1, ID_MAX), B("points", false) }, 2 },
	{ "move", PROTO_CONTROLLER, "move arms to absolute angles (degrees), checked against soft limits",
	  { N("laser.theta", false, -360, 360), N("detector.theta", false, -360, 360),
	    N("detector.phi", false, -720, 720), NA("laser_theta", -360, 360, "laser.theta"),
	    NA("detector_theta", -360, 360, "detector.theta"), NA("detector_phi", -720, 720, "detector.phi") }, 6 },
	{ "home", PROTO_CONTROLLER, "home the arms (all axes, or the one named by axis: laser.theta, detector.theta, "
	  "detector.phi)", { S("axis", false, 32) }, 1 },
	{ "stop", PROTO_CONTROLLER, "stop a running manual move, homing or measurement (arms decelerate, laser off)",
	  { { 0 } }, 0 },
	{ "laser.off", PROTO_CONTROLLER, "switch the laser emission off now (refused while a sweep is loaded)",
	  { { 0 } }, 0 },
	{ "measure", PROTO_CONTROLLER, "take one sample spectrum (laser on for it, at power_pct if given)",
	  { N("integration_ms", false, 0.002, 600000), I("averages", false, 1, 10000), N("power_pct", false, 0, 100) },
	  3 },
	{ "dark", PROTO_CONTROLLER, "take one dark spectrum (laser off)",
	  { N("integration_ms", false, 0.002, 600000), I("averages", false, 1, 10000) }, 2 },
	{ "reference", PROTO_CONTROLLER, "take one reference (white standard) spectrum (laser on, power_pct)",
	  { N("integration_ms", false, 0.002, 600000), I("averages", false, 1, 10000), N("power_pct", false, 0, 100) },
	  3 },
	{ "recon.start", PROTO_CONTROLLER, "start the reconstruction of a sweep in a child process",
	  { I("sweep", true, 1, ID_MAX) }, 1 },
	{ "recon.status", PROTO_OBSERVER, "state of a reconstruction run (latest of a sweep, or by run id)",
	  { I("sweep", false, 1, ID_MAX), I("run", false, 1, ID_MAX) }, 2 },
	{ "export", PROTO_OBSERVER, "a sweep's calibrated samples as CSV, or format=nexus: the whole sweep as NeXus/HDF5 "
	  "(a stream passed to the client, or a new file NAME in the daemon's export folder)",
	  { I("sweep", true, 1, ID_MAX), S("path", false, 255), S("format", false, 16) }, 3 },
	{ "spectrum", PROTO_OBSERVER, "one stored spectrum: kind, settings, wavelengths and counts",
	  { I("spectrum", true, 1, ID_MAX) }, 1 },
	{ "watch", PROTO_OBSERVER, "stream events (progress with ETA, device state, faults, recon)", { { 0 } }, 0 },
	{ "reload", PROTO_CONTROLLER, "reload the configuration file (refused while a sweep runs)", { { 0 } }, 0 },
	{ NULL, 0, NULL, { { 0 } }, 0 },
};

char *proto_cmd_words(const char *cmd, char *buf, size_t cap)
{
	snprintf(buf, cap, "%s", cmd);
	for (char *p = buf; *p; p++)
		if (*p == '.')
			*p = ' ';
	return buf;
}

const struct proto_cmd *proto_cmd_find(const char *name)
{
	for (const struct proto_cmd *c = proto_cmds; c->name; c++)
		if (!strcmp(c->name, name))
			return c;
	return NULL;
}

static const char *type_name(enum proto_argtype t)
{
	switch (t) {
	case PROTO_T_STRING: return "a string";
	case PROTO_T_INT: return "an integer";
	case PROTO_T_NUMBER: return "a number";
	default: return "true or false";
	}
}

static int check_arg(const struct proto_arg *a, json_t *v, const char **code, struct acq_err *err)
{
	*code = PROTO_E_INVALID;
	bool ok = (a->type == PROTO_T_STRING && json_is_string(v)) || (a->type == PROTO_T_INT && json_is_integer(v)) ||
		  (a->type == PROTO_T_NUMBER && json_is_number(v)) || (a->type == PROTO_T_BOOL && json_is_boolean(v));
	if (!ok)
		return acq_errf(err, ACQ_E_INVAL, "\"%s\": expected %s", a->name, type_name(a->type));
	if (a->type == PROTO_T_STRING) {
		if (a->max > 0 && (double)json_string_length(v) > a->max)
			return acq_errf(err, ACQ_E_INVAL, "\"%s\": longer than %.0f bytes", a->name, a->max);
		if (strlen(json_string_value(v)) != json_string_length(v))
			return acq_errf(err, ACQ_E_INVAL, "\"%s\": contains a NUL character", a->name);
		/* a one-line argument (a name, a path; not a plan's text) goes into replies, logs and tables as is: a
		 * newline or a terminal escape there would forge a log line or reach an operator's terminal */
		const unsigned char *t = (const unsigned char *)json_string_value(v);
		for (size_t i = 0; a->max > 0 && a->max <= 4096 && t[i]; i++)
			if (t[i] < 0x20 || t[i] == 0x7f)
				return acq_errf(err, ACQ_E_INVAL, "\"%s\": a control character (0x%02x) at position %zu",
						a->name, t[i], i + 1);
	} else if (a->type != PROTO_T_BOOL && (a->min != 0 || a->max != 0)) {
		double d = json_number_value(v);
		if (!(d >= a->min && d <= a->max) && a->max >= ID_MAX) /* an id: no upper bound worth saying (2^53) */
			return acq_errf(err, ACQ_E_INVAL, "\"%s\": expected %s >= %g", a->name, type_name(a->type), a->min);
		if (!(d >= a->min && d <= a->max))
			return acq_errf(err, ACQ_E_INVAL, "\"%s\": expected %s in [%g, %g]", a->name, type_name(a->type),
					a->min, a->max);
	}
	return 0;
}

int proto_req_parse(const char *line, size_t len, struct proto_req *req, const char **code, struct acq_err *err)
{
	memset(req, 0, sizeof *req);
	*code = PROTO_E_PARSE;
	json_error_t je;
	/* JSON_REJECT_DUPLICATES: {"cmd":"status","cmd":"move"} is ambiguous, so it is an error. */
	req->root = json_loadb(line, len, JSON_REJECT_DUPLICATES | JSON_DECODE_ANY, &je);
	if (!req->root) {
		/* jansson names its own flag ("\\u0000 is not allowed without JSON_ALLOW_NUL"): say what was sent */
		if (strstr(je.text, "JSON_ALLOW_NUL"))
			return acq_errf(err, ACQ_E_PROTO, "a NUL character (\\u0000) is not allowed in a request, at "
					"column %d", je.column);
		return acq_errf(err, ACQ_E_PROTO, "not JSON: %s at column %d", je.text, je.column);
	}
	*code = PROTO_E_INVALID;
	if (!json_is_object(req->root))
		return acq_errf(err, ACQ_E_PROTO, "expected a JSON object {\"cmd\": ..., \"id\": ...}");
	json_t *id = json_object_get(req->root, "id");
	if (id) {
		if (!json_is_integer(id) && !json_is_string(id) && !json_is_null(id))
			return acq_errf(err, ACQ_E_PROTO, "\"id\": expected an integer or a string");
		if (json_is_string(id) && json_string_length(id) > 256)
			return acq_errf(err, ACQ_E_PROTO, "\"id\": longer than 256 bytes");
		req->id = id;
	}
	json_t *cmd = json_object_get(req->root, "cmd");
	if (!cmd)
		return acq_errf(err, ACQ_E_PROTO, "missing \"cmd\"");
	if (!json_is_string(cmd) || strlen(json_string_value(cmd)) != json_string_length(cmd))
		return acq_errf(err, ACQ_E_PROTO, "\"cmd\": expected a string (without NUL characters)");
	req->cmd = json_string_value(cmd);
	if (!(req->def = proto_cmd_find(req->cmd))) {
		*code = PROTO_E_UNKNOWN;
		return acq_errf(err, ACQ_E_PROTO, "unknown command \"%.64s\" (see acqctl help)", req->cmd);
	}
	char words[64];
	proto_cmd_words(req->cmd, words, sizeof words);
	const char *key;
	json_t *v;
	json_object_foreach(req->root, key, v) {
		if (!strcmp(key, "cmd") || !strcmp(key, "id"))
			continue;
		int i = 0;
		for (; i < req->def->nargs; i++)
			if (!strcmp(req->def->args[i].name, key))
				break;
		if (i == req->def->nargs)
			return acq_errf(err, ACQ_E_PROTO, "%s: unknown argument \"%.64s\"", words, key);
		if (req->def->args[i].alias_of && json_object_get(req->root, req->def->args[i].alias_of))
			return acq_errf(err, ACQ_E_PROTO, "%s: \"%s\" and its old name \"%s\" both given", words,
					req->def->args[i].alias_of, key);
		if (check_arg(&req->def->args[i], v, code, err))
			return acq_err_prefix(err, "%s: ", words);
	}
	for (int i = 0; i < req->def->nargs; i++)
		if (req->def->args[i].required && !json_object_get(req->root, req->def->args[i].name))
			return acq_errf(err, ACQ_E_PROTO, "%s: missing \"%s\" (%s)", words, req->def->args[i].name,
					type_name(req->def->args[i].type));
	*code = NULL;
	return 0;
}

void proto_req_free(struct proto_req *req)
{
	json_decref(req->root);
	memset(req, 0, sizeof *req);
}

static char *dump_line(json_t *o)
{
	if (!o)
		return NULL;
	char *s = json_dumps(o, JSON_COMPACT | JSON_ENSURE_ASCII);
	json_decref(o);
	if (!s)
		return NULL;
	size_t n = strlen(s);
	char *l = realloc(s, n + 2);
	if (!l) {
		free(s);
		return NULL;
	}
	l[n] = '\n';
	l[n + 1] = 0;
	return l;
}

char *proto_reply_ok(json_t *id, json_t *data)
{
	json_t *o = json_object();
	if (!o) {
		json_decref(data);
		return NULL;
	}
	json_object_set_new(o, "id", id ? json_incref(id) : json_null());
	json_object_set_new(o, "ok", json_true());
	if (json_is_object(data))
		json_object_update_missing(o, data);
	json_decref(data);
	return dump_line(o);
}

char *proto_reply_err(json_t *id, const char *code, const char *msg)
{
	return dump_line(json_pack("{s:O?,s:b,s:{s:s,s:s}}", "id", id, "ok", 0, "error", "code", code, "message",
				   msg ? msg : ""));
}

char *proto_event(const char *name, json_t *data)
{
	json_t *o = json_pack("{s:s}", "event", name);
	if (o && json_is_object(data))
		json_object_update_missing(o, data);
	json_decref(data);
	return dump_line(o);
}

char *proto_banner(const char *version)
{
	return dump_line(json_pack("{s:s,s:i,s:s,s:i}", "version", version, "protocol", PROTO_VERSION, "server",
				   "acquisitiond", "max_line", PROTO_MAX_LINE));
}

const char *proto_code_of(const struct acq_err *err)
{
	switch (err ? err->code : ACQ_E_IO) {
	case ACQ_E_INVAL:
	case ACQ_E_CONFIG:
	case ACQ_E_PROTO: return PROTO_E_INVALID;
	case ACQ_E_RANGE: return PROTO_E_RANGE;
	case ACQ_E_STATE: return PROTO_E_STATE;
	case ACQ_E_NOTFOUND: return PROTO_E_NOT_FOUND;
	case ACQ_E_UNSUPPORTED:
	case ACQ_E_DISCONNECTED:
	case ACQ_E_TIMEOUT:
	case ACQ_E_DEVICE: return PROTO_E_UNAVAILABLE;
	case ACQ_E_IO: return PROTO_E_IO;
	default: return PROTO_E_INTERNAL;
	}
}
