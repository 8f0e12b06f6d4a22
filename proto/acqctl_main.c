/* acqctl: the command-line client of acquisitiond — one subcommand per protocol command, one output per
 * command (human, or one JSON document with --json) whether or not a daemon answers, sysexits exit codes
 * (see ctl.h and acqctl(1)); `plan` runs the local dry run when no daemon answers; `export` copies the stream
 * the daemon passes over the socket; `watch` is a live view on a terminal, JSON lines otherwise. This file is the
 * command line (options, the command and its arguments, the request, the reply's output); the connection, the
 * outputs and watch/wait are in proto/acqctl/ (acqctl.h). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "acq_version.h"
#include "config/acq_file.h"
#include "config/yconf.h"
#include "daemon/plan/plan_cli.h"
#include "proto/acqctl/acqctl.h"
#include "proto/ctl.h"
#include "proto/proto.h"

#define DEFAULT_SOCKET "/run/acquisitiond/acquisitiond.sock"

struct acqctl_opts acqctl_o = { .timeout_ms = 30000 };

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
	if (pk) { /* the positional argument, in brackets when it may be left out (sweep resume [ID], home [AXIS]) */
		bool required = true;
		for (int i = 0; i < c->nargs; i++)
			if (!strcmp(c->args[i].name, pk + (pk[0] == '@')))
				required = c->args[i].required;
		const char *w = pk[0] == '@' ? "FILE" : !strcmp(pk, "axis") ? "AXIS" : "ID";
		fprintf(f, required ? " %s" : " [%s]", w);
	}
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
		   "  " ACQ_DATADIR "/acqctl-replies.schema.json\n");
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
			errno = 0;
			long long x = strtoll(v, &end, 10);
			if (*v && !*end && errno != ERANGE) /* not a saturated 2^63 - 1 */
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

static int local_plan(const char *file)
{
	struct acq_err err = { 0 };
	json_t *p = plan_cli_json(file, acqctl_o.bench, acqctl_o.points, &err);
	if (!p)
		return out_fail(err.code == ACQ_E_NOTFOUND || err.code == ACQ_E_IO ? CTL_EXIT_NOINPUT : CTL_EXIT_REFUSED,
			    err.code == ACQ_E_NOTFOUND || err.code == ACQ_E_IO ? "not_found" : "invalid", "plan: %s",
			    err.msg);
	json_t *rep = json_pack("{s:b,s:o,s:s}", "ok", 1, "plan", p, "source", "local");
	if (acqctl_o.json)
		out_json(rep);
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
			acqctl_o.json = true;
		else if (!strcmp(a, "--help") || !strcmp(a, "-h"))
			*help = true;
		else if (!strcmp(a, "--version") || !strcmp(a, "-V")) {
			printf("acqctl %s (protocol %d)\n", ACQ_VERSION, PROTO_VERSION);
			return 0;
		} else if (!strcmp(a, "--points"))
			acqctl_o.points = true;
		else if (!strcmp(a, "--csv"))
			acqctl_o.csv = true;
		else if (TAKES("-s", "--socket")) {
			if (!(acqctl_o.sock = val) || !*val)
				return out_fail(CTL_EXIT_USAGE, "usage", "%s needs a socket path or tcp:PORT (acqctl --help)", a);
		} else if (TAKES("-t", "--timeout")) {
			char *end = NULL;
			errno = 0;
			long ms = val ? strtol(val, &end, 10) : 0;
			if (!val || !*val || *end || errno || ms <= 0 || ms > 86400000L)
				return out_fail(CTL_EXIT_USAGE, "usage", "-t: expected milliseconds in [1, 86400000], got '%s'",
						val ? val : "");
			acqctl_o.timeout_ms = (int)ms;
		} else if (TAKES("-w", "--wait") || TAKES("-T", "--timeout-s")) {
			char *end;
			double x = val ? strtod(val, &end) : -1;
			if (!val || *end || !(x >= 0 && x <= 1e6))
				return out_fail(CTL_EXIT_USAGE, "usage", "%s: expected seconds", a);
			if (a[1] == 'w' || !strcmp(a, "--wait"))
				acqctl_o.wait_s = x;
			else
				*wait_timeout = x;
		} else if (TAKES("-f", "--format")) {
			if (!(acqctl_o.format = val) || (strcmp(val, "csv") && strcmp(val, "nexus")))
				return out_fail(CTL_EXIT_USAGE, "usage", "--format: expected csv or nexus");
		} else if (TAKES("-o", "--output")) {
			if (!(acqctl_o.out = val) || !*val)
				return out_fail(CTL_EXIT_USAGE, "usage", "-o needs a file name");
		} else if (TAKES("-c", "--config")) {
			if (!(acqctl_o.bench = val) || !*val)
				return out_fail(CTL_EXIT_USAGE, "usage", "--config needs a file name");
		} else if (a[0] == '-' && a[1] && strcmp(a, "-"))
			return out_fail(CTL_EXIT_USAGE, "usage", "unknown option %s (acqctl --help)", a);
		else if (*nw < 64)
			words[(*nw)++] = argv[i];
		else /* not dropped unsaid */
			return out_fail(CTL_EXIT_USAGE, "usage", "more than 64 words: '%s' and after (acqctl --help)", a);
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
				char *text;
				size_t len;
				if (acq_file_read(*plan_file, (size_t)2 << 20, ACQ_FILE_STDIN, &text, &len, &err)) {
					bool unread = err.code == ACQ_E_IO || err.code == ACQ_E_NOTFOUND;
					return out_fail(unread ? CTL_EXIT_NOINPUT : CTL_EXIT_DATAERR,
							unread ? "not_found" : "invalid", "%s", err.msg);
				}
				/* a NUL byte or a byte that is not UTF-8 would cut the text short or drop it (JSON) */
				int bad = yc_check_text(!strcmp(*plan_file, "-") ? "standard input" : *plan_file, text, len,
							&err);
				if (!bad)
					json_object_set_new(req, pk + 1, json_stringn(text, len));
				free(text);
				if (bad)
					return out_fail(CTL_EXIT_DATAERR, "invalid", "%s", err.msg);
			} else if (set_arg(req, def, pk, words[wi], &err)) {
				return out_fail(CTL_EXIT_USAGE, "usage", "%s", err.msg);
			}
			pk = NULL;
			continue;
		}
		if (!eq)
			return out_fail(CTL_EXIT_USAGE, "usage", "%s: expected key=value (acqctl %s --help)", words[wi], words[0]);
		*eq = 0;
		const char *key = words[wi];
		for (int i = 0; i < def->nargs; i++) /* an old name (laser_theta=) is sent as the one name (laser.theta=) */
			if (def->args[i].alias_of && !strcmp(key, def->args[i].name))
				key = def->args[i].alias_of;
		if (json_object_get(req, key))
			return out_fail(CTL_EXIT_USAGE, "usage", "%s given twice%s%s%s", key, strcmp(key, words[wi]) ? " (as " : "",
				    strcmp(key, words[wi]) ? words[wi] : "", strcmp(key, words[wi]) ? " too)" : "");
		if (set_arg(req, def, key, eq + 1, &err))
			return out_fail(CTL_EXIT_USAGE, "usage", "%s", err.msg);
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
			return out_fail(CTL_EXIT_USAGE, "usage", "%s: missing %s (acqctl %s --help)", name, def->args[i].name,
				    name);
		}
	if ((!strcmp(cmd, "plan") || !strcmp(cmd, "sweep.show")) && acqctl_o.points)
		json_object_set_new(req, "points", json_true());
	if (acqctl_o.format && strcmp(cmd, "export"))
		return out_fail(CTL_EXIT_USAGE, "usage", "--format is an option of export");
	if (acqctl_o.format)
		json_object_set_new(req, "format", json_string(acqctl_o.format));
	if (!strcmp(cmd, "export") && !acqctl_o.out && !json_object_get(req, "path") &&
	    json_is_string(json_object_get(req, "format")) &&
	    !strcmp(json_string_value(json_object_get(req, "format")), "nexus") && isatty(1))
		return out_fail(CTL_EXIT_USAGE, "usage", "export --format nexus writes a binary HDF5 file: give -o FILE (or "
			    "redirect the output)");
	if (!strcmp(cmd, "export") && acqctl_o.json && !acqctl_o.out && !json_object_get(req, "path"))
		return out_fail(CTL_EXIT_USAGE, "usage", "export --json prints the summary: give -o FILE for the CSV");
	return CTL_EXIT_OK;
}

/* A refusal of the plan sent from plan_file names it as the daemon read it, "plan:LINE:COL: ...": the message
 * in e is made to name the file instead ("quick.yaml:9:11: averages: ..."), in the human and the --json output. */
static void name_plan_file(json_t *e, const char *plan_file)
{
	const char *msg = json_string_value(json_object_get(e, "message"));
	if (!plan_file || !msg || strncmp(msg, "plan:", 5) || msg[5] < '0' || msg[5] > '9')
		return;
	char buf[2048];
	snprintf(buf, sizeof buf, "%s:%s", strcmp(plan_file, "-") ? plan_file : "standard input", msg + 5);
	json_object_set_new(e, "message", json_string(buf));
}

/* The daemon's reply to cmd: a refusal on stderr (commands named as typed), an export's stream or inline CSV, a
 * spectrum's CSV, else JSON or the human view. Returns the exit status. */
static int show_reply(const char *cmd, json_t *rep, int passed, const char *plan_file)
{
	if (!json_is_true(json_object_get(rep, "ok"))) {
		json_t *e = json_object_get(rep, "error");
		name_plan_file(e, plan_file);
		char words2[64];
		cmd_words(cmd, words2, sizeof words2);
		/* the daemon's message names commands as the protocol does ("sweep.abort"): say them as typed */
		const char *msg = json_string_value(json_object_get(e, "message"));
		char said[1024];
		snprintf(said, sizeof said, "%s", msg ? msg : "");
		char *hit = strstr(said, cmd);
		if (hit && strchr(cmd, '.'))
			hit[strchr(cmd, '.') - cmd] = ' ';
		/* a message that starts with the command ("move: \"laser.theta\": ...") is not prefixed twice */
		size_t wl = strlen(words2);
		const char *body = !strncmp(said, words2, wl) && !strncmp(said + wl, ": ", 2) ? said + wl + 2 : said;
		fprintf(stderr, "acqctl: %s: %s (%s)\n", words2, body, json_string_value(json_object_get(e, "code")));
		if (acqctl_o.json)
			out_json(rep);
		return CTL_EXIT_REFUSED;
	}
	if (!strcmp(cmd, "export") && json_is_true(json_object_get(rep, "stream"))) {
		if (passed < 0)
			return out_fail(CTL_EXIT_PROTOCOL, "protocol", "export: the daemon sent no stream (over TCP? use the Unix "
				    "socket)");
		return out_export(rep, passed);
	}
	if (!strcmp(cmd, "export") && json_is_string(json_object_get(rep, "csv")))
		return out_inline(rep);
	if (!strcmp(cmd, "spectrum") && acqctl_o.csv)
		return out_spectrum_csv(rep);
	if (acqctl_o.json)
		out_json(rep);
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
		return out_fail(CTL_EXIT_UNAVAILABLE, "unavailable", "cannot connect to acquisitiond: %s (socket: -s or "
			    "$ACQ_SOCKET)", err.msg);
	}
	/* a request longer than the daemon reads in one line would be refused as "too_long" without saying whose */
	json_int_t max_line = json_integer_value(json_object_get(c.banner, "max_line"));
	char *line = max_line > 0 ? json_dumps(req, JSON_COMPACT) : NULL;
	size_t len = line ? strlen(line) + 1 : 0;
	free(line);
	if (max_line > 0 && len > (size_t)max_line) {
		conn_close(&c);
		char words2[64];
		cmd_words(cmd, words2, sizeof words2);
		return out_fail(CTL_EXIT_DATAERR, "too_long", "%s%s%s: the request is %zu bytes, more than the daemon reads "
				"in one line (%lld bytes)%s", words2, plan_file ? " " : "", plan_file ? plan_file : "", len,
				(long long)max_line, plan_file ? ": shorten the plan (a range {from, to, step} instead of a "
				"long list)" : "");
	}
	int passed = -1;
	json_t *rep = conn_call(&c, req, !strcmp(cmd, "export") ? &passed : NULL, &err);
	conn_close(&c);
	if (!rep)
		return out_fail(err.code == ACQ_E_PROTO ? CTL_EXIT_PROTOCOL : CTL_EXIT_UNAVAILABLE,
			    err.code == ACQ_E_PROTO ? "protocol" : "unavailable", "%s: %s", acqctl_o.sock, err.msg);
	json_object_del(rep, "id");
	int rc = show_reply(cmd, rep, passed, plan_file);
	if (passed >= 0)
		close(passed);
	json_decref(rep);
	return rc;
}

int main(int argc, char **argv)
{
	acqctl_o.sock = getenv("ACQ_SOCKET");
	if (!acqctl_o.sock || !*acqctl_o.sock)
		acqctl_o.sock = DEFAULT_SOCKET;
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
			return out_fail(CTL_EXIT_USAGE, "usage", "wait: expected one state (acqctl wait --help)");
		return watch_wait(words[wi + 1], wait_timeout);
	}
	char cmd[64];
	const struct proto_cmd *def = find_command(words, nw, &wi, cmd, sizeof cmd);
	if (!def) { /* "sweep" alone (or "sweep frob"): the word of a group, so say its sub-commands */
		char subs[256] = "";
		size_t wl = strlen(words[help_cmd]);
		for (const struct proto_cmd *c = proto_cmds; c->name; c++)
			if (!strncmp(c->name, words[help_cmd], wl) && c->name[wl] == '.')
				snprintf(subs + strlen(subs), sizeof subs - strlen(subs), "%s%s", subs[0] ? ", " : "",
					 c->name + wl + 1);
		if (subs[0])
			return out_fail(CTL_EXIT_USAGE, "usage", "%s: expected one of %s (acqctl help)", words[help_cmd], subs);
		return out_fail(CTL_EXIT_USAGE, "usage", "unknown command '%s' (acqctl help)", words[help_cmd]);
	}
	if (help || help_cmd) {
		printf("usage: acqctl [options] ");
		usage_cmd(stdout, def);
		return 0;
	}
	if (!strcmp(cmd, "watch")) {
		if (wi < nw)
			return out_fail(CTL_EXIT_USAGE, "usage", "watch takes no arguments");
		return watch_run();
	}
	/* The request, checked before anything is sent. */
	json_t *req = json_pack("{s:s,s:i}", "cmd", cmd, "id", 1);
	const char *plan_file = NULL;
	rc = fill_args(req, def, cmd, words, wi, nw, &plan_file);
	if (rc == CTL_EXIT_OK)
		rc = check_request(req, def, cmd);
	if (rc == CTL_EXIT_OK && !strcmp(cmd, "export")) /* -o checked before the daemon streams anything */
		rc = out_prepare();
	if (rc == CTL_EXIT_OK)
		rc = !strcmp(cmd, "plan") && acqctl_o.bench ? local_plan(plan_file) : send_request(req, cmd, plan_file);
	out_abandon();
	json_decref(req);
	/* a write that failed earlier (out_json flushes as it goes) leaves the error flag, not a failing fflush */
	if ((fflush(stdout) || ferror(stdout)) && !rc) {
		fputs("acqctl: cannot write the output (standard output)\n", stderr);
		rc = CTL_EXIT_CANTCREAT;
	}
	return rc;
}
