/* acqctl: the command-line client of acquisitiond — one subcommand per protocol command, one output per
 * command (human, or one JSON document with --json) whether or not a daemon answers, sysexits exit codes
 * (see ctl.h and acqctl(1)); `plan` runs the local dry run when no daemon answers; `export` copies the stream
 * the daemon passes over the socket; `watch` is a live view on a terminal, JSON lines otherwise. */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "acq_version.h"
#include "daemon/plan/plan_cli.h"
#include "proto/ctl.h"
#include "proto/proto.h"

#define DEFAULT_SOCKET "/run/acquisitiond/acquisitiond.sock"

struct opts {
	const char *sock;
	bool json, points, csv;
	const char *out;       /* -o FILE (export, spectrum --csv) */
	const char *format;    /* export --format csv|nexus */
	const char *bench;     /* plan --config */
	int timeout_ms;
	double wait_s;         /* --wait: keep trying to connect this long */
};

static struct opts O = { .timeout_ms = 30000 };

/* Shortcuts: the positional argument of a command and the key it fills ("@plan": the file's text). */
static const struct {
	const char *cmd, *key;
} positional[] = {
	{ "plan", "@plan" }, { "sweep.start", "@plan" }, { "sweep.show", "sweep" }, { "sweep.resume", "sweep" },
	{ "recon.start", "sweep" }, { "recon.status", "sweep" }, { "export", "sweep" }, { "spectrum", "spectrum" },
	{ "home", "axis" }, { NULL, NULL },
};

static const char *positional_key(const char *cmd)
{
	for (int i = 0; positional[i].cmd; i++)
		if (!strcmp(positional[i].cmd, cmd))
			return positional[i].key;
	return NULL;
}

static void cmd_words(const char *name, char *buf, size_t cap)
{
	proto_cmd_words(name, buf, cap);
}

static void usage_cmd(FILE *f, const struct proto_cmd *c)
{
	char name[64];
	cmd_words(c->name, name, sizeof name);
	const char *pk = positional_key(c->name);
	fprintf(f, "  %-13s", name);
	if (pk)
		fprintf(f, " %s", pk[0] == '@' ? "FILE" : !strcmp(pk, "axis") ? "[AXIS]" : "ID");
	for (int i = 0; i < c->nargs; i++) {
		if ((pk && !strcmp(pk + (pk[0] == '@'), c->args[i].name)) || c->args[i].alias_of)
			continue;
		fprintf(f, " %s%s=…%s", c->args[i].required ? "" : "[", c->args[i].name, c->args[i].required ? "" : "]");
	}
	fprintf(f, "\n      %s%s\n", c->summary, c->role == PROTO_CONTROLLER ? " (controllers)" : "");
}

static void usage(FILE *f)
{
	fprintf(f, "usage: acqctl [-s SOCKET|tcp:PORT] [--json] [-t TIMEOUT_MS] [-o FILE] COMMAND [ARGS] [key=value...]\n"
		   "       acqctl --version | --help | help [COMMAND]\n"
		   "socket: -s, else $ACQ_SOCKET, else " DEFAULT_SOCKET "\n\ncommands:\n");
	for (const struct proto_cmd *c = proto_cmds; c->name; c++)
		usage_cmd(f, c);
	fprintf(f, "  wait STATE [--timeout-s S]\n      wait until the sweep is idle, running, paused or faulted "
		   "(client side)\n");
	fprintf(f, "\n--wait S: keep trying to connect for S seconds (a daemon starting up)\n");
	fprintf(f, "\noptions after the command: --json, --points (plan), --config BENCH.yaml (plan, local dry run),\n"
		   "  -o FILE (export, spectrum --csv: written by acqctl as you), --csv (spectrum),\n"
		   "  --format csv|nexus (export; nexus: the whole sweep as NeXus/HDF5, needs -o FILE or path=NAME)\n"
		   "exit status: 0 ok, 1 refused by the daemon, 64 usage, 65 bad local input, 66 unreadable input,\n"
		   "  69 no daemon answers, 70 internal error, 73 cannot write the output, 75 wait timed out,\n"
		   "  76 protocol error\n"
		   "see acqctl(1); --json replies follow the schemas in\n"
		   "  /usr/share/acquisitiond/acqctl-replies.schema.json\n");
}

/* ---- one output per command ---- */

static void print_json(json_t *o)
{
	char *s = json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(10));
	puts(s ? s : "{\"ok\":false}");
	free(s);
	fflush(stdout);
}

/* An error of the client itself (no daemon, bad input): stderr, and the JSON document with --json. */
static int fail(int rc, const char *code, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static int fail(int rc, const char *code, const char *fmt, ...)
{
	char msg[1024];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	fprintf(stderr, "acqctl: %s\n", msg);
	if (O.json) {
		json_t *o = json_pack("{s:b,s:{s:s,s:s}}", "ok", 0, "error", "code", code, "message", msg);
		print_json(o);
		json_decref(o);
	}
	return rc;
}

static char *read_text(const char *path, struct acq_err *err)
{
	FILE *f = strcmp(path, "-") ? fopen(path, "rb") : stdin;
	if (!f) {
		acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(errno));
		return NULL;
	}
	size_t cap = 8192, n = 0;
	char *buf = malloc(cap);
	while (buf) {
		n += fread(buf + n, 1, cap - n - 1, f);
		if (n < cap - 1)
			break;
		if (cap > (2u << 20)) {
			free(buf);
			buf = NULL;
			acq_errf(err, ACQ_E_RANGE, "%s: larger than 2 MiB", path);
			break;
		}
		char *nb = realloc(buf, cap *= 2);
		if (!nb)
			free(buf);
		buf = nb;
	}
	if (f != stdin)
		fclose(f);
	if (buf)
		buf[n] = 0;
	else if (!err->code)
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
	return buf;
}

/* key=value with the type the command table gives the key. 0, or -1 with a message in err. */
static int set_arg(json_t *req, const struct proto_cmd *def, const char *key, const char *v, struct acq_err *err)
{
	for (int i = 0; i < def->nargs; i++) {
		if (strcmp(def->args[i].name, key))
			continue;
		char *end = NULL;
		switch (def->args[i].type) {
		case PROTO_T_INT: {
			long long x = strtoll(v, &end, 10);
			if (*v && !*end)
				return json_object_set_new(req, key, json_integer(x));
			return acq_errf(err, ACQ_E_INVAL, "%s=%s: expected an integer", key, v);
		}
		case PROTO_T_NUMBER: {
			double x = strtod(v, &end);
			if (*v && !*end && isfinite(x))
				return json_object_set_new(req, key, json_real(x));
			return acq_errf(err, ACQ_E_INVAL, "%s=%s: expected a number", key, v);
		}
		case PROTO_T_BOOL:
			if (!strcmp(v, "true") || !strcmp(v, "false"))
				return json_object_set_new(req, key, json_boolean(!strcmp(v, "true")));
			return acq_errf(err, ACQ_E_INVAL, "%s=%s: expected true or false", key, v);
		default:
			return json_object_set_new(req, key, json_string(v));
		}
	}
	char name[64];
	cmd_words(def->name, name, sizeof name);
	return acq_errf(err, ACQ_E_INVAL, "%s: not an argument of %s (acqctl %s --help)", key, name, name);
}

/* ---- talking to the daemon ---- */

struct conn {
	int fd;
	struct proto_lines pl;
	json_t *banner;
};

static double mono(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static int conn_open(struct conn *c, struct acq_err *err)
{
	proto_lines_init(&c->pl);
	c->pl.max = PROTO_MAX_REPLY;
	c->banner = NULL;
	double deadline = mono() + O.wait_s;
	while ((c->fd = proto_client_connect(O.sock, err)) < 0 && mono() < deadline)
		usleep(100000);
	if (c->fd < 0)
		return -1;
	c->banner = proto_client_read(c->fd, &c->pl, O.timeout_ms, err);
	if (!c->banner || json_integer_value(json_object_get(c->banner, "protocol")) != PROTO_VERSION) {
		/* A refusal before the banner ("too many clients", "not authorised") is a one-line error reply. */
		json_t *e = json_object_get(c->banner, "error");
		if (e)
			acq_errf(err, ACQ_E_STATE, "%s", json_string_value(json_object_get(e, "message")));
		else if (c->banner)
			acq_errf(err, ACQ_E_PROTO, "unsupported protocol version");
		return -1;
	}
	return 0;
}

static void conn_close(struct conn *c)
{
	if (c->fd >= 0)
		close(c->fd);
	c->fd = -1;
	proto_lines_free(&c->pl);
	json_decref(c->banner);
	c->banner = NULL;
}

/* Send req (borrowed) and read its reply; passed receives a descriptor sent with it (NULL: none expected). */
static json_t *conn_call(struct conn *c, json_t *req, int *passed, struct acq_err *err)
{
	char *line = json_dumps(req, JSON_COMPACT);
	if (!line) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		return NULL;
	}
	size_t n = strlen(line);
	line[n] = '\n'; /* json_dumps' NUL becomes the newline (the request is sent by length) */
	int rc = proto_write_all(c->fd, line, n + 1, err);
	free(line);
	if (rc) {
		/* The daemon may have refused us and closed: its reason is still to be read. */
		struct acq_err e2 = { 0 };
		json_t *why = proto_client_read_fd(c->fd, &c->pl, 1000, passed, &e2);
		if (why && json_is_false(json_object_get(why, "ok")))
			return why;
		json_decref(why);
		return NULL;
	}
	return proto_client_read_fd(c->fd, &c->pl, O.timeout_ms, passed, err);
}

/* ---- export and spectrum: the data part ---- */

static int open_out(const char *path)
{
	if (!path)
		return 1;
	return open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
}

/* Copy the export stream to the output; the stream must carry the reply's rows (header and comment lines
 * aside), else the daemon stopped early. */
static int copy_export(json_t *rep, int src)
{
	int out = open_out(O.out);
	if (out < 0)
		return fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", O.out, strerror(errno));
	char buf[65536];
	long long bytes = 0, lines = 0;
	ssize_t n;
	int rc = 0;
	while ((n = read(src, buf, sizeof buf)) != 0) {
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0) {
			rc = fail(CTL_EXIT_PROTOCOL, "io", "export stream: %s", strerror(errno));
			break;
		}
		for (ssize_t i = 0; i < n; i++)
			lines += buf[i] == '\n';
		bytes += n;
		struct acq_err err = { 0 };
		if (proto_write_all(out, buf, (size_t)n, &err)) {
			rc = fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", O.out ? O.out : "stdout", err.msg);
			break;
		}
	}
	long long rows = json_integer_value(json_object_get(rep, "rows"));
	long long head = json_integer_value(json_object_get(rep, "header_lines"));
	bool nexus = json_is_string(json_object_get(rep, "format"));
	long long want = json_integer_value(json_object_get(rep, "bytes"));
	if (!rc && nexus && bytes != want)
		rc = fail(CTL_EXIT_PROTOCOL, "io", "NeXus export of sweep %lld: %lld of %lld bytes received",
			  (long long)json_integer_value(json_object_get(rep, "sweep")), bytes, want);
	else if (!rc && !nexus && lines != rows + head)
		rc = fail(CTL_EXIT_PROTOCOL, "io", "export of sweep %lld ended after %lld of %lld rows (see the daemon's log)",
			  (long long)json_integer_value(json_object_get(rep, "sweep")), lines - head, rows);
	if (O.out && close(out) && !rc)
		rc = fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", O.out, strerror(errno));
	if (!rc) {
		json_object_set_new(rep, "bytes", json_integer(bytes));
		json_object_set_new(rep, "output", O.out ? json_string(O.out) : json_null());
		if (O.json)
			print_json(rep);
		else if (O.out && nexus)
			fprintf(stdout, "sweep %lld: NeXus, %lld points, %lld calibrated, %lld bytes written to %s\n",
				(long long)json_integer_value(json_object_get(rep, "sweep")),
				(long long)json_integer_value(json_object_get(rep, "points")),
				(long long)json_integer_value(json_object_get(rep, "calibrated")), bytes, O.out);
		else if (O.out)
			fprintf(stdout, "sweep %lld: %lld rows, %lld bytes written to %s\n",
				(long long)json_integer_value(json_object_get(rep, "sweep")), rows, bytes, O.out);
	}
	return rc;
}

/* A small export sent inline (over TCP, where no descriptor can be passed). */
static int write_inline(json_t *rep)
{
	const char *csv = json_string_value(json_object_get(rep, "csv"));
	int out = open_out(O.out);
	struct acq_err err = { 0 };
	if (out < 0 || proto_write_all(out, csv, strlen(csv), &err) || (O.out && close(out)))
		return fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", O.out ? O.out : "stdout", out < 0 ? strerror(errno) : err.msg);
	json_int_t len = (json_int_t)strlen(csv);
	json_object_del(rep, "csv");
	json_object_set_new(rep, "bytes", json_integer(len));
	json_object_set_new(rep, "output", O.out ? json_string(O.out) : json_null());
	if (O.json)
		print_json(rep);
	return 0;
}

static int spectrum_csv(json_t *rep)
{
	json_t *s = json_object_get(rep, "spectrum");
	json_t *wl = json_object_get(s, "wavelength_nm"), *ct = json_object_get(s, "counts");
	json_t *sd = json_object_get(s, "stddev");
	if (!json_is_array(wl) || !json_is_array(ct) || json_array_size(wl) != json_array_size(ct))
		return fail(CTL_EXIT_PROTOCOL, "protocol", "spectrum reply without matching wavelength_nm and counts");
	FILE *f = O.out ? fopen(O.out, "w") : stdout;
	if (!f)
		return fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", O.out, strerror(errno));
	fprintf(f, "# acquisitiond spectrum %lld (%s)\nwavelength_nm,counts%s\n",
		(long long)json_integer_value(json_object_get(s, "id")), json_string_value(json_object_get(s, "kind")),
		json_is_array(sd) ? ",stddev" : "");
	for (size_t i = 0; i < json_array_size(wl); i++) {
		fprintf(f, "%.6g,%.9g", json_number_value(json_array_get(wl, i)), json_number_value(json_array_get(ct, i)));
		if (json_is_array(sd))
			fprintf(f, ",%.6g", json_number_value(json_array_get(sd, i)));
		fputc('\n', f);
	}
	if ((O.out ? fclose(f) : fflush(f)) != 0)
		return fail(CTL_EXIT_CANTCREAT, "io", "%s: %s", O.out ? O.out : "stdout", strerror(errno));
	if (O.out)
		printf("spectrum %lld: %zu rows written to %s\n", (long long)json_integer_value(json_object_get(s, "id")),
		       json_array_size(wl), O.out);
	return 0;
}

/* ---- watch ---- */

static volatile sig_atomic_t stop_watch;
static void on_signal(int sig)
{
	(void)sig;
	stop_watch = 1;
}

static double wall(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void json_line_event(const char *name, const char *msg)
{
	json_t *o = json_pack("{s:s,s:s,s:f}", "event", name, "message", msg, "at", wall());
	print_json(o);
	json_decref(o);
}

/* Follow the daemon's events until interrupted, reconnecting (every second) when it goes away. */
static int run_watch(void)
{
	bool tty = !O.json && isatty(STDOUT_FILENO);
	struct ctl_view *view = tty ? ctl_view_new(stdout, O.sock) : NULL;
	struct sigaction sa = { .sa_handler = on_signal };
	sigaction(SIGINT, &sa, NULL);
	sigaction(SIGTERM, &sa, NULL);
	bool ever = false;
	char last_err[512] = "";
	while (!stop_watch) {
		struct conn c;
		struct acq_err err = { 0 };
		json_t *req = NULL, *st = NULL, *dv = NULL, *rep = NULL;
		if (conn_open(&c, &err))
			goto lost;
		if (view) {
			req = json_pack("{s:s,s:i}", "cmd", "status", "id", 1);
			st = conn_call(&c, req, NULL, &err);
			json_decref(req);
			req = json_pack("{s:s,s:i}", "cmd", "devices", "id", 2);
			dv = st ? conn_call(&c, req, NULL, &err) : NULL;
			json_decref(req);
			if (!dv)
				goto lost;
			ctl_view_status(view, st, dv);
		}
		req = json_pack("{s:s,s:i}", "cmd", "watch", "id", 3);
		rep = conn_call(&c, req, NULL, &err);
		json_decref(req);
		if (!rep)
			goto lost;
		if (!json_is_true(json_object_get(rep, "ok"))) {
			json_t *e = json_object_get(rep, "error");
			int rc = fail(CTL_EXIT_REFUSED, json_string_value(json_object_get(e, "code")), "watch: %s",
				      json_string_value(json_object_get(e, "message")));
			json_decref(rep);
			conn_close(&c);
			ctl_view_free(view);
			return rc;
		}
		json_decref(rep);
		if (view)
			ctl_view_link(view, "connected");
		else if (ever)
			json_line_event("acqctl.reconnected", O.sock);
		ever = true;
		last_err[0] = 0;
		while (!stop_watch) {
			if (view)
				ctl_view_draw(view, wall());
			json_t *ev = proto_client_read(c.fd, &c.pl, 1000, &err);
			if (!ev && err.code == ACQ_E_TIMEOUT)
				continue;
			if (!ev)
				break;
			if (view)
				ctl_view_event(view, ev);
			else
				print_json(ev);
			json_decref(ev);
		}
	lost:
		json_decref(st);
		json_decref(dv);
		conn_close(&c);
		if (stop_watch)
			break;
		if (strcmp(last_err, err.msg)) {
			snprintf(last_err, sizeof last_err, "%s", err.msg);
			char text[600];
			snprintf(text, sizeof text, "reconnecting: %s", err.msg);
			if (view)
				ctl_view_link(view, text);
			else
				json_line_event("acqctl.disconnected", err.msg);
		}
		if (view)
			ctl_view_draw(view, wall());
		sleep(1);
	}
	if (view)
		fputc('\n', stdout);
	ctl_view_free(view);
	return 0;
}

/* ---- wait: until the sweep is in a state (client side, by polling status) ---- */
static int run_wait(const char *want, double timeout_s)
{
	static const char *const states[] = { "idle", "running", "paused", "faulted", NULL };
	bool known = false;
	for (int i = 0; states[i]; i++)
		known |= !strcmp(want, states[i]);
	if (!known)
		return fail(CTL_EXIT_USAGE, "usage", "wait: expected idle, running, paused or faulted, got '%s'", want);
	struct conn c;
	struct acq_err err = { 0 };
	if (conn_open(&c, &err)) {
		conn_close(&c);
		return fail(CTL_EXIT_UNAVAILABLE, "unavailable", "cannot connect to acquisitiond: %s", err.msg);
	}
	double deadline = mono() + timeout_s;
	json_t *req = json_pack("{s:s,s:i}", "cmd", "status", "id", 1);
	int rc = -1;
	while (rc < 0) {
		json_t *rep = conn_call(&c, req, NULL, &err);
		json_t *p = json_object_get(rep, "sweep");
		if (!rep)
			rc = fail(CTL_EXIT_UNAVAILABLE, "unavailable", "%s: %s", O.sock, err.msg);
		else if (!strcmp(json_string_value(json_object_get(p, "state")) ?: "", want)) {
			json_object_del(rep, "id");
			if (O.json)
				print_json(rep);
			else
				ctl_print_human(stdout, "status", rep);
			rc = 0;
		} else if (mono() > deadline)
			rc = fail(75, "state", "wait: the sweep is still %s after %g s (wanted %s)",
				  json_string_value(json_object_get(p, "state")), timeout_s, want);
		else
			usleep(250000);
		json_decref(rep);
	}
	json_decref(req);
	conn_close(&c);
	return rc;
}

/* ---- plan without a daemon ---- */
static int local_plan(const char *file)
{
	struct acq_err err = { 0 };
	json_t *p = plan_cli_json(file, O.bench, O.points, &err);
	if (!p)
		return fail(err.code == ACQ_E_NOTFOUND || err.code == ACQ_E_IO ? CTL_EXIT_NOINPUT : CTL_EXIT_REFUSED,
			    err.code == ACQ_E_NOTFOUND || err.code == ACQ_E_IO ? "not_found" : "invalid", "plan: %s",
			    err.msg);
	json_t *rep = json_pack("{s:b,s:o,s:s}", "ok", 1, "plan", p, "source", "local");
	if (O.json)
		print_json(rep);
	else
		ctl_print_plan(stdout, p);
	json_decref(rep);
	return 0;
}

/* The command line: options anywhere (into O, *wait_timeout and *help); words that are not options form the command
 * and its arguments (words, at most 64, *nw). -1 to go on, or the exit status (--version: 0, a usage error). */
static int parse_options(int argc, char **argv, char **words, int *nw, double *wait_timeout, bool *help)
{
	for (int i = 1; i < argc; i++) {
		const char *a = argv[i];
		const char *val = NULL;
#define TAKES(s, l) ((!strcmp(a, s) || !strcmp(a, l)) && (val = i + 1 < argc ? argv[++i] : NULL, 1))
		if (!strcmp(a, "--json") || !strcmp(a, "-j"))
			O.json = true;
		else if (!strcmp(a, "--help") || !strcmp(a, "-h"))
			*help = true;
		else if (!strcmp(a, "--version") || !strcmp(a, "-V")) {
			printf("acqctl %s (protocol %d)\n", ACQ_VERSION, PROTO_VERSION);
			return 0;
		} else if (!strcmp(a, "--points"))
			O.points = true;
		else if (!strcmp(a, "--csv"))
			O.csv = true;
		else if (TAKES("-s", "--socket")) {
			if (!(O.sock = val))
				return fail(CTL_EXIT_USAGE, "usage", "%s needs a value (acqctl --help)", a);
		} else if (TAKES("-t", "--timeout")) {
			char *end;
			O.timeout_ms = val ? (int)strtol(val, &end, 10) : 0;
			if (!val || *end || O.timeout_ms <= 0)
				return fail(CTL_EXIT_USAGE, "usage", "-t: expected milliseconds > 0");
		} else if (TAKES("-w", "--wait") || TAKES("-T", "--timeout-s")) {
			char *end;
			double x = val ? strtod(val, &end) : -1;
			if (!val || *end || !(x >= 0 && x <= 1e6))
				return fail(CTL_EXIT_USAGE, "usage", "%s: expected seconds", a);
			if (a[1] == 'w' || !strcmp(a, "--wait"))
				O.wait_s = x;
			else
				*wait_timeout = x;
		} else if (TAKES("-f", "--format")) {
			if (!(O.format = val) || (strcmp(val, "csv") && strcmp(val, "nexus")))
				return fail(CTL_EXIT_USAGE, "usage", "--format: expected csv or nexus");
		} else if (TAKES("-o", "--output")) {
			if (!(O.out = val))
				return fail(CTL_EXIT_USAGE, "usage", "-o needs a file name");
		} else if (TAKES("-c", "--config")) {
			if (!(O.bench = val))
				return fail(CTL_EXIT_USAGE, "usage", "--config needs a file name");
		} else if (a[0] == '-' && a[1] && strcmp(a, "-"))
			return fail(CTL_EXIT_USAGE, "usage", "unknown option %s (acqctl --help)", a);
		else if (*nw < 64)
			words[(*nw)++] = argv[i];
#undef TAKES
	}
	return -1;
}

/* The protocol command the words from *wi name: two words ("sweep start", "laser off") when they name one, else
 * one; its name in cmd, *wi past it. NULL when none does. */
static const struct proto_cmd *find_command(char **words, int nw, int *wi, char *cmd, size_t cap)
{
	const struct proto_cmd *def = NULL;
	if (*wi + 1 < nw) {
		snprintf(cmd, cap, "%s.%s", words[*wi], words[*wi + 1]);
		if ((def = proto_cmd_find(cmd)))
			*wi += 2;
	}
	if (!def) {
		snprintf(cmd, cap, "%s", words[*wi]);
		if ((def = proto_cmd_find(cmd)))
			(*wi)++;
	}
	return def;
}

/* The command's arguments into req: the positional one (a plan file's text for "@" keys, its name in *plan_file),
 * then key=value (old names sent as the one name, each key once), typed by the command table. 0, or the exit
 * status of the usage or input error (reported). */
static int fill_args(json_t *req, const struct proto_cmd *def, const char *cmd, char **words, int wi, int nw,
		     const char **plan_file)
{
	struct acq_err err = { 0 };
	const char *pk = positional_key(cmd);
	for (; wi < nw; wi++) {
		char *eq = strchr(words[wi], '=');
		if (!eq && pk) {
			if (pk[0] == '@') {
				*plan_file = words[wi];
				char *text = read_text(*plan_file, &err);
				if (!text)
					return fail(err.code == ACQ_E_IO ? CTL_EXIT_NOINPUT : CTL_EXIT_DATAERR, "not_found", "%s",
						    err.msg);
				json_object_set_new(req, pk + 1, json_string(text));
				free(text);
			} else if (set_arg(req, def, pk, words[wi], &err)) {
				return fail(CTL_EXIT_USAGE, "usage", "%s", err.msg);
			}
			pk = NULL;
			continue;
		}
		if (!eq)
			return fail(CTL_EXIT_USAGE, "usage", "%s: expected key=value (acqctl %s --help)", words[wi], words[0]);
		*eq = 0;
		const char *key = words[wi];
		for (int i = 0; i < def->nargs; i++) /* an old name (laser_theta=) is sent as the one name (laser.theta=) */
			if (def->args[i].alias_of && !strcmp(key, def->args[i].name))
				key = def->args[i].alias_of;
		if (json_object_get(req, key))
			return fail(CTL_EXIT_USAGE, "usage", "%s given twice%s%s%s", key, strcmp(key, words[wi]) ? " (as " : "",
				    strcmp(key, words[wi]) ? words[wi] : "", strcmp(key, words[wi]) ? " too)" : "");
		if (set_arg(req, def, key, eq + 1, &err))
			return fail(CTL_EXIT_USAGE, "usage", "%s", err.msg);
	}
	return CTL_EXIT_OK;
}

/* The request checked before anything is sent: required arguments, then the options that go with the command
 * (--points, --format, export's output). 0, or the usage error's status (reported). */
static int check_request(json_t *req, const struct proto_cmd *def, const char *cmd)
{
	for (int i = 0; i < def->nargs; i++)
		if (def->args[i].required && !json_object_get(req, def->args[i].name)) {
			char name[64];
			cmd_words(def->name, name, sizeof name);
			return fail(CTL_EXIT_USAGE, "usage", "%s: missing %s (acqctl %s --help)", name, def->args[i].name,
				    name);
		}
	if ((!strcmp(cmd, "plan") || !strcmp(cmd, "sweep.show")) && O.points)
		json_object_set_new(req, "points", json_true());
	if (O.format && strcmp(cmd, "export"))
		return fail(CTL_EXIT_USAGE, "usage", "--format is an option of export");
	if (O.format)
		json_object_set_new(req, "format", json_string(O.format));
	if (!strcmp(cmd, "export") && !O.out && !json_object_get(req, "path") &&
	    json_is_string(json_object_get(req, "format")) &&
	    !strcmp(json_string_value(json_object_get(req, "format")), "nexus") && isatty(1))
		return fail(CTL_EXIT_USAGE, "usage", "export --format nexus writes a binary HDF5 file: give -o FILE (or "
			    "redirect the output)");
	if (!strcmp(cmd, "export") && O.json && !O.out && !json_object_get(req, "path"))
		return fail(CTL_EXIT_USAGE, "usage", "export --json prints the summary: give -o FILE for the CSV");
	return CTL_EXIT_OK;
}

/* The daemon's reply to cmd: a refusal on stderr (commands named as typed), an export's stream or inline CSV, a
 * spectrum's CSV, else JSON or the human view. Returns the exit status. */
static int show_reply(const char *cmd, json_t *rep, int passed)
{
	if (!json_is_true(json_object_get(rep, "ok"))) {
		json_t *e = json_object_get(rep, "error");
		char words2[64];
		cmd_words(cmd, words2, sizeof words2);
		/* the daemon's message names commands as the protocol does ("sweep.abort"): say them as typed */
		const char *msg = json_string_value(json_object_get(e, "message"));
		char said[1024];
		snprintf(said, sizeof said, "%s", msg ? msg : "");
		char *hit = strstr(said, cmd);
		if (hit && strchr(cmd, '.'))
			hit[strchr(cmd, '.') - cmd] = ' ';
		fprintf(stderr, "acqctl: %s: %s (%s)\n", words2, said, json_string_value(json_object_get(e, "code")));
		if (O.json)
			print_json(rep);
		return CTL_EXIT_REFUSED;
	}
	if (!strcmp(cmd, "export") && json_is_true(json_object_get(rep, "stream"))) {
		if (passed < 0)
			return fail(CTL_EXIT_PROTOCOL, "protocol", "export: the daemon sent no stream (over TCP? use the Unix "
				    "socket)");
		return copy_export(rep, passed);
	}
	if (!strcmp(cmd, "export") && json_is_string(json_object_get(rep, "csv")))
		return write_inline(rep);
	if (!strcmp(cmd, "spectrum") && O.csv)
		return spectrum_csv(rep);
	if (O.json)
		print_json(rep);
	else
		ctl_print_human(stdout, cmd, rep);
	return CTL_EXIT_OK;
}

/* The request sent and its reply shown (plan falls back to the local dry run when no daemon answers). Returns the
 * exit status. */
static int send_request(json_t *req, const char *cmd, const char *plan_file)
{
	struct acq_err err = { 0 };
	struct conn c;
	if (conn_open(&c, &err)) {
		conn_close(&c);
		if (!strcmp(cmd, "plan") && err.code != ACQ_E_STATE)
			return local_plan(plan_file);
		return fail(CTL_EXIT_UNAVAILABLE, "unavailable", "cannot connect to acquisitiond: %s (socket: -s or "
			    "$ACQ_SOCKET)", err.msg);
	}
	int passed = -1;
	json_t *rep = conn_call(&c, req, !strcmp(cmd, "export") ? &passed : NULL, &err);
	conn_close(&c);
	if (!rep)
		return fail(err.code == ACQ_E_PROTO ? CTL_EXIT_PROTOCOL : CTL_EXIT_UNAVAILABLE,
			    err.code == ACQ_E_PROTO ? "protocol" : "unavailable", "%s: %s", O.sock, err.msg);
	json_object_del(rep, "id");
	int rc = show_reply(cmd, rep, passed);
	if (passed >= 0)
		close(passed);
	json_decref(rep);
	return rc;
}

int main(int argc, char **argv)
{
	O.sock = getenv("ACQ_SOCKET");
	if (!O.sock || !*O.sock)
		O.sock = DEFAULT_SOCKET;
	char *words[64];
	int nw = 0;
	double wait_timeout = 3600;
	bool help = false;
	int rc = parse_options(argc, argv, words, &nw, &wait_timeout, &help);
	if (rc >= 0)
		return rc;
	if (nw == 0) {
		if (help) {
			usage(stdout);
			return 0;
		}
		usage(stderr);
		return CTL_EXIT_USAGE;
	}
	int wi = 0;
	bool help_cmd = !strcmp(words[0], "help");
	if (help_cmd) {
		if (nw == 1) {
			usage(stdout);
			return 0;
		}
		wi = 1;
	}
	if (!strcmp(words[wi], "wait")) {
		if (help || help_cmd) {
			printf("usage: acqctl [options] wait idle|running|paused|faulted [--timeout-s S]\n"
			       "      wait until the sweep is in that state (polls status); exit 75 after the timeout "
			       "(default 3600 s)\n");
			return 0;
		}
		if (nw != wi + 2)
			return fail(CTL_EXIT_USAGE, "usage", "wait: expected one state (acqctl wait --help)");
		return run_wait(words[wi + 1], wait_timeout);
	}
	char cmd[64];
	const struct proto_cmd *def = find_command(words, nw, &wi, cmd, sizeof cmd);
	if (!def)
		return fail(CTL_EXIT_USAGE, "usage", "unknown command '%s' (acqctl help)", words[help_cmd]);
	if (help || help_cmd) {
		printf("usage: acqctl [options] ");
		usage_cmd(stdout, def);
		return 0;
	}
	if (!strcmp(cmd, "watch")) {
		if (wi < nw)
			return fail(CTL_EXIT_USAGE, "usage", "watch takes no arguments");
		return run_watch();
	}
	/* The request, checked before anything is sent. */
	json_t *req = json_pack("{s:s,s:i}", "cmd", cmd, "id", 1);
	const char *plan_file = NULL;
	rc = fill_args(req, def, cmd, words, wi, nw, &plan_file);
	if (rc == CTL_EXIT_OK)
		rc = check_request(req, def, cmd);
	if (rc == CTL_EXIT_OK)
		rc = !strcmp(cmd, "plan") && O.bench ? local_plan(plan_file) : send_request(req, cmd, plan_file);
	json_decref(req);
	if (fflush(stdout) && !rc)
		rc = CTL_EXIT_CANTCREAT;
	return rc;
}
