/* acqctl: the command-line client of acquisitiond — one subcommand per protocol command, human output (or
 * --json), exit status 0 ok / 1 refused or failed / 2 cannot connect; `acqctl plan` runs the local dry run
 * when no daemon is reachable. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "daemon/plan/plan_cli.h"
#include "proto/proto.h"

#define EXIT_REFUSED 1
#define EXIT_NOCONN 2

static bool opt_json;
static int opt_timeout_ms = 30000;

static void usage(FILE *f)
{
	fprintf(f, "usage: acqctl [-s SOCKET|tcp:PORT] [--json] [-t TIMEOUT_MS] COMMAND [ARGS] [key=value...]\n"
		   "socket: -s, else $ACQ_SOCKET, else /run/acquisitiond/acquisitiond.sock\n\ncommands:\n");
	for (const struct proto_cmd *c = proto_cmds; c->name; c++) {
		char name[64];
		snprintf(name, sizeof name, "%s", c->name);
		char *dot = strchr(name, '.');
		if (dot)
			*dot = ' ';
		fprintf(f, "  %-14s %-10s %s", name, c->role == PROTO_CONTROLLER ? "[control]" : "", c->summary);
		if (c->nargs) {
			fputs(" (", f);
			for (int i = 0; i < c->nargs; i++)
				fprintf(f, "%s%s%s", i ? " " : "", c->args[i].name, c->args[i].required ? "" : "?");
			fputs(")", f);
		}
		fputc('\n', f);
	}
	fprintf(f, "\npositional shortcuts: plan FILE, sweep start FILE, sweep show ID, sweep resume ID,\n"
		   "recon start SWEEP, export SWEEP [path=REL]; exit status 0 ok, 1 refused, 2 cannot connect\n"
		   "watch prints progress with ETA (a bar on a terminal); plan runs locally when no daemon answers\n");
}

static char *read_file(const char *path)
{
	FILE *f = strcmp(path, "-") ? fopen(path, "rb") : stdin;
	if (!f) {
		fprintf(stderr, "acqctl: %s: %s\n", path, strerror(errno));
		return NULL;
	}
	size_t cap = 8192, n = 0;
	char *buf = malloc(cap);
	while (buf) {
		n += fread(buf + n, 1, cap - n - 1, f);
		if (n < cap - 1 || cap > (4u << 20))
			break;
		char *nb = realloc(buf, cap *= 2);
		if (!nb) {
			free(buf);
			buf = NULL;
		} else {
			buf = nb;
		}
	}
	if (f != stdin)
		fclose(f);
	if (buf)
		buf[n] = 0;
	return buf;
}

/* key=value with the type the command table gives the key. */
static int set_arg(json_t *req, const struct proto_cmd *def, const char *kv)
{
	const char *eq = strchr(kv, '=');
	if (!eq) {
		fprintf(stderr, "acqctl: %s: expected key=value\n", kv);
		return -1;
	}
	char key[64];
	snprintf(key, sizeof key, "%.*s", (int)(eq - kv), kv);
	const char *v = eq + 1;
	for (int i = 0; i < def->nargs; i++) {
		if (strcmp(def->args[i].name, key))
			continue;
		char *end = NULL;
		switch (def->args[i].type) {
		case PROTO_T_INT: {
			long long x = strtoll(v, &end, 10);
			if (*v && !*end)
				return json_object_set_new(req, key, json_integer(x));
			break;
		}
		case PROTO_T_NUMBER: {
			double x = strtod(v, &end);
			if (*v && !*end && isfinite(x))
				return json_object_set_new(req, key, json_real(x));
			break;
		}
		case PROTO_T_BOOL:
			if (!strcmp(v, "true") || !strcmp(v, "false"))
				return json_object_set_new(req, key, json_boolean(!strcmp(v, "true")));
			break;
		default:
			return json_object_set_new(req, key, json_string(v));
		}
		fprintf(stderr, "acqctl: %s: bad value for %s\n", kv, key);
		return -1;
	}
	fprintf(stderr, "acqctl: %s: unknown argument for %s\n", key, def->name);
	return -1;
}

/* ---- human output ---- */
static void print_value(const char *prefix, json_t *v);

static void print_scalar(const char *prefix, json_t *v)
{
	char *s = json_is_string(v) ? NULL : json_dumps(v, JSON_ENCODE_ANY);
	printf("%s: %s\n", prefix, s ? s : json_string_value(v));
	free(s);
}

static void print_value(const char *prefix, json_t *v)
{
	const char *k;
	json_t *x;
	size_t i;
	char p[256];
	if (json_is_object(v)) {
		json_object_foreach(v, k, x) {
			snprintf(p, sizeof p, "%s%s%s", prefix, *prefix ? "." : "", k);
			print_value(p, x);
		}
	} else if (json_is_array(v) && json_array_size(v) && json_is_object(json_array_get(v, 0))) {
		json_array_foreach(v, i, x) {
			snprintf(p, sizeof p, "%s[%zu]", prefix, i);
			print_value(p, x);
		}
	} else {
		print_scalar(prefix, v);
	}
}

static void print_table(json_t *rows, const char *const *cols)
{
	for (int c = 0; cols[c]; c++)
		printf("%-*s", c ? 16 : 6, cols[c]);
	putchar('\n');
	size_t i;
	json_t *r;
	json_array_foreach(rows, i, r) {
		for (int c = 0; cols[c]; c++) {
			json_t *v = json_object_get(r, cols[c]);
			char *s = !v || json_is_null(v) ? strdup("-") : json_is_string(v) ? strdup(json_string_value(v))
											    : json_dumps(v, JSON_ENCODE_ANY);
			printf("%-*s", c ? 16 : 6, s ? s : "");
			free(s);
		}
		putchar('\n');
	}
}

static void print_human(const char *cmd, json_t *rep)
{
	json_object_del(rep, "id");
	json_object_del(rep, "ok");
	if (!strcmp(cmd, "sweep.list")) {
		static const char *const cols[] = { "id", "state", "name", "points_done", "points_total", NULL };
		print_table(json_object_get(rep, "sweeps"), cols);
	} else if (!strcmp(cmd, "devices")) {
		static const char *const cols[] = { "name", "state", "note", NULL };
		json_t *d = json_object_get(rep, "devices");
		size_t i;
		json_t *r;
		json_array_foreach(d, i, r)
			printf("%-16s %-15s %s\n", json_string_value(json_object_get(r, "name")),
			       json_string_value(json_object_get(r, "state")),
			       json_is_string(json_object_get(r, "note")) ? json_string_value(json_object_get(r, "note")) : "");
		(void)cols;
	} else if (!strcmp(cmd, "export") && json_is_string(json_object_get(rep, "csv"))) {
		fputs(json_string_value(json_object_get(rep, "csv")), stdout);
	} else if (!strcmp(cmd, "config") && json_is_string(json_object_get(json_object_get(rep, "config"), "text"))) {
		fputs(json_string_value(json_object_get(json_object_get(rep, "config"), "text")), stdout);
	} else {
		print_value("", rep);
	}
}

/* ---- watch ---- */
static void show_event(json_t *ev, bool tty, bool *bar_shown)
{
	const char *name = json_string_value(json_object_get(ev, "event"));
	if (opt_json) {
		char *s = json_dumps(ev, JSON_COMPACT);
		puts(s ? s : "{}");
		free(s);
		fflush(stdout);
		return;
	}
	char line[256];
	if (proto_progress_line(ev, tty, line, sizeof line)) {
		fputs(line, stdout);
		if (!tty)
			putchar('\n');
		*bar_shown = tty;
		fflush(stdout);
		return;
	}
	if (*bar_shown) {
		putchar('\n');
		*bar_shown = false;
	}
	char ename[64];
	snprintf(ename, sizeof ename, "%s", name ? name : "?");
	json_object_del(ev, "event"); /* frees name */
	char *s = json_dumps(ev, JSON_COMPACT);
	printf("%s %s\n", ename, s ? s : "");
	free(s);
	fflush(stdout);
}

int main(int argc, char **argv)
{
	static const struct option opts[] = { { "socket", required_argument, NULL, 's' },
					      { "json", no_argument, NULL, 'j' },
					      { "timeout", required_argument, NULL, 't' },
					      { "help", no_argument, NULL, 'h' },
					      { NULL, 0, NULL, 0 } };
	const char *sock = getenv("ACQ_SOCKET");
	if (!sock || !*sock)
		sock = "/run/acquisitiond/acquisitiond.sock";
	/* "+": options stop at the command, so `acqctl plan FILE --json` keeps its own options. */
	int o;
	while ((o = getopt_long(argc, argv, "+s:jt:h", opts, NULL)) != -1) {
		switch (o) {
		case 's': sock = optarg; break;
		case 'j': opt_json = true; break;
		case 't': opt_timeout_ms = atoi(optarg); break;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return EXIT_REFUSED;
		}
	}
	if (optind >= argc) {
		usage(stderr);
		return EXIT_REFUSED;
	}
	char cmd[64];
	int ai = optind;
	snprintf(cmd, sizeof cmd, "%s", argv[ai++]);
	if ((!strcmp(cmd, "sweep") || !strcmp(cmd, "recon")) && ai < argc) {
		snprintf(cmd + strlen(cmd), sizeof cmd - strlen(cmd), ".%s", argv[ai++]);
	}
	if (!strcmp(cmd, "help")) {
		usage(stdout);
		return 0;
	}
	struct acq_err err = { 0 };
	int fd = proto_client_connect(sock, &err);
	if (!strcmp(cmd, "plan") && fd < 0)
		return plan_cli_main(argc - optind, argv + optind);
	const struct proto_cmd *def = proto_cmd_find(cmd);
	if (!def) {
		fprintf(stderr, "acqctl: unknown command '%s' (acqctl help)\n", cmd);
		if (fd >= 0)
			close(fd);
		return EXIT_REFUSED;
	}
	if (fd < 0) {
		fprintf(stderr, "acqctl: cannot connect: %s\n", err.msg);
		return EXIT_NOCONN;
	}
	json_t *req = json_pack("{s:s,s:i}", "cmd", cmd, "id", 1);
	char *line = NULL;
	json_t *banner = NULL;
	struct proto_lines pl;
	proto_lines_init(&pl);
	int rc = EXIT_REFUSED;
	/* Positional shortcuts. */
	if ((!strcmp(cmd, "plan") || !strcmp(cmd, "sweep.start")) && ai < argc && !strchr(argv[ai], '=')) {
		char *text = read_file(argv[ai++]);
		if (!text)
			goto out;
		json_object_set_new(req, "plan", json_string(text));
		free(text);
		if (!strcmp(cmd, "plan"))
			while (ai < argc && argv[ai][0] == '-') /* local dry-run options do not apply to the daemon */
				ai++;
	} else if ((!strcmp(cmd, "sweep.show") || !strcmp(cmd, "sweep.resume") || !strcmp(cmd, "recon.start") ||
		    !strcmp(cmd, "export")) && ai < argc && !strchr(argv[ai], '=')) {
		char kv[64];
		snprintf(kv, sizeof kv, "sweep=%s", argv[ai++]);
		if (set_arg(req, def, kv))
			goto out;
	}
	for (; ai < argc; ai++)
		if (set_arg(req, def, argv[ai]))
			goto out;
	line = json_dumps(req, JSON_COMPACT);
	banner = proto_client_read(fd, &pl, opt_timeout_ms, &err);
	if (!banner || json_integer_value(json_object_get(banner, "protocol")) != PROTO_VERSION) {
		fprintf(stderr, "acqctl: %s: %s\n", sock, banner ? "unsupported protocol version" : err.msg);
		rc = EXIT_NOCONN;
		goto out;
	}
	if (!line) {
		fprintf(stderr, "acqctl: out of memory\n");
		goto out;
	}
	size_t n = strlen(line);
	line[n] = '\n'; /* json_dumps' NUL becomes the newline (the request is sent by length) */
	if (proto_write_all(fd, line, n + 1, &err)) {
		fprintf(stderr, "acqctl: %s\n", err.msg);
		rc = EXIT_NOCONN;
		goto out;
	}
	json_t *rep = proto_client_read(fd, &pl, opt_timeout_ms, &err);
	if (!rep) {
		fprintf(stderr, "acqctl: %s\n", err.msg);
		rc = EXIT_NOCONN;
		goto out;
	}
	bool ok = json_is_true(json_object_get(rep, "ok"));
	if (opt_json) {
		char *s = json_dumps(rep, JSON_COMPACT);
		puts(s ? s : "{}");
		free(s);
	} else if (ok) {
		print_human(cmd, rep);
	} else {
		json_t *e = json_object_get(rep, "error");
		fprintf(stderr, "acqctl: %s: %s (%s)\n", cmd, json_string_value(json_object_get(e, "message")),
			json_string_value(json_object_get(e, "code")));
	}
	rc = ok ? 0 : EXIT_REFUSED;
	if (ok && !strcmp(cmd, "watch")) {
		bool tty = isatty(1), bar = false;
		fflush(stdout);
		json_t *ev;
		while ((ev = proto_client_read(fd, &pl, -1, &err))) {
			show_event(ev, tty, &bar);
			json_decref(ev);
		}
		if (bar)
			putchar('\n');
		fprintf(stderr, "acqctl: watch ended: %s\n", err.msg);
		rc = EXIT_NOCONN;
	}
	json_decref(rep);
out:
	json_decref(req);
	json_decref(banner);
	free(line);
	proto_lines_free(&pl);
	close(fd);
	return rc;
}
