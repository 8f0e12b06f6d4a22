/* sim_ctlcli: `acq-sim ctl`, the client of the simulator's control socket (sim_control.c): put the white
 * standard or a sample on the stage, inject or clear faults, read the simulator's truth (true pose, emission,
 * sample, active faults) — what a person at the real bench would do or see. */
#include <errno.h>
#include <jansson.h>
#include <poll.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "sim/sim.h"

#define EX_USAGE_ 64
#define EX_UNAVAILABLE_ 69

static void usage(FILE *f)
{
	fprintf(f,
		"usage: acq-sim ctl [--control SOCKET | --ports-file FILE] [--json] COMMAND [ARGS]\n"
		"  the control socket: --control, else $ACQ_SIM_CONTROL, else the \"control\" entry of the ports file\n"
		"  (--ports-file, else $ACQ_SIM_PORTS, else ./ports.json)\n"
		"commands:\n"
		"  truth | status           the simulator's true state: pose, emission, power, sample, temperature, faults\n"
		"  reference                put the white standard on the stage (sample white)\n"
		"  sample NAME              put NAME on the stage: green-paint | white | metal | clear-coat |\n"
		"                           rough-backscatter | cloth-sheen | sharp-lobe | narrow-lines |\n"
		"                           merl (the table of sim.merl_file) | none\n"
		"  fault NAME [ARGS]        inject a fault (acq-sim ctl help lists them); fault clear ends all\n"
		"  pose LT DT DP | laser on|off [PCT] | temperature C | time | help   (as the control socket has them)\n"
		"exit status: 0 ok, 1 refused by the simulator, 64 usage (an unknown command, a missing argument),\n"
		"  69 no simulator answers\n");
}

/* The control socket from the ports file's {"control": {"socket": PATH}}. */
static int from_ports(const char *ports, char *out, size_t cap)
{
	json_error_t je;
	json_t *root = json_load_file(ports, 0, &je);
	const char *s = json_string_value(json_object_get(json_object_get(root, "control"), "socket"));
	int rc = -1;
	if (s && strlen(s) < cap) {
		snprintf(out, cap, "%s", s);
		rc = 0;
	} else if (!root) {
		fprintf(stderr, "acq-sim ctl: %s: %s (give --control SOCKET or --ports-file FILE)\n", ports, je.text);
	} else {
		fprintf(stderr, "acq-sim ctl: %s: no control socket in the ports file\n", ports);
	}
	json_decref(root);
	return rc;
}

/* One line to the control socket, its one-line reply into buf. 0, or -1 with a message printed. */
static int exchange(const char *path, const char *line, char *buf, size_t cap)
{
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	if (strlen(path) >= sizeof sa.sun_path) {
		fprintf(stderr, "acq-sim ctl: %s: path too long\n", path);
		return -1;
	}
	strcpy(sa.sun_path, path);
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0 || connect(fd, (struct sockaddr *)&sa, sizeof sa) < 0) {
		fprintf(stderr, "acq-sim ctl: cannot connect to %s: %s (is acq-sim running?)\n", path, strerror(errno));
		if (fd >= 0)
			close(fd);
		return -1;
	}
	size_t n = strlen(line), off = 0;
	while (off < n) {
		ssize_t w = send(fd, line + off, n - off, MSG_NOSIGNAL);
		if (w < 0 && errno == EINTR)
			continue;
		if (w < 0) {
			fprintf(stderr, "acq-sim ctl: %s: %s\n", path, strerror(errno));
			close(fd);
			return -1;
		}
		off += (size_t)w;
	}
	size_t len = 0;
	while (len + 1 < cap) {
		struct pollfd p = { .fd = fd, .events = POLLIN };
		if (poll(&p, 1, 10000) <= 0) {
			fprintf(stderr, "acq-sim ctl: %s: no reply within 10 s\n", path);
			close(fd);
			return -1;
		}
		ssize_t r = read(fd, buf + len, cap - 1 - len);
		if (r < 0 && errno == EINTR)
			continue;
		if (r <= 0)
			break;
		len += (size_t)r;
		if (memchr(buf, '\n', len))
			break;
	}
	close(fd);
	buf[len] = 0;
	char *nl = strchr(buf, '\n');
	if (nl)
		*nl = 0;
	if (!len) {
		fprintf(stderr, "acq-sim ctl: %s: closed without a reply\n", path);
		return -1;
	}
	return 0;
}

/* "ok k=v k=v ..." as a JSON object (numbers where they parse), with "ok": true; a reply without k=v pairs
 * (time, help) as "t" (time's number) or "reply". */
static json_t *kv_json(const char *cmd, const char *text)
{
	json_t *o = json_pack("{s:b}", "ok", 1);
	text += strspn(text, " ");
	if (*text && !strchr(text, '=')) {
		char *end;
		double v = strtod(text, &end);
		if (!strcmp(cmd, "time") && !*end)
			json_object_set_new(o, "t", json_real(v));
		else
			json_object_set_new(o, "reply", json_string(text));
		return o;
	}
	char *copy = strdup(text), *save = NULL;
	for (char *t = copy ? strtok_r(copy, " ", &save) : NULL; t; t = strtok_r(NULL, " ", &save)) {
		char *eq = strchr(t, '=');
		if (!eq)
			continue;
		*eq = 0;
		char *end, *iend;
		double v = strtod(eq + 1, &end);
		long long iv = strtoll(eq + 1, &iend, 10); /* "0", "252": integers, not 0.0 and 252.0 */
		json_object_set_new(o, t, *end || end == eq + 1 ? json_string(eq + 1)
					  : !*iend && !strchr(eq + 1, '.') ? json_integer(iv) : json_real(v));
	}
	free(copy);
	return o;
}

int simctl_main(int argc, char **argv)
{
	const char *control = getenv("ACQ_SIM_CONTROL"), *ports = getenv("ACQ_SIM_PORTS");
	bool json = false;
	int i = 1;
	for (; i < argc && argv[i][0] == '-'; i++) {
		if (!strcmp(argv[i], "--json"))
			json = true;
		else if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
			usage(stdout);
			return 0;
		} else if ((!strcmp(argv[i], "--control") || !strcmp(argv[i], "--ports-file")) && i + 1 < argc) {
			if (argv[i][2] == 'c') {
				control = argv[++i];
			} else {
				ports = argv[++i];
				control = NULL;
			}
		} else {
			fprintf(stderr, "acq-sim ctl: unknown option %s\n", argv[i]);
			usage(stderr);
			return EX_USAGE_;
		}
	}
	if (i >= argc) {
		usage(stderr);
		return EX_USAGE_;
	}
	char path[108];
	if (!control || !*control) {
		if (from_ports(ports && *ports ? ports : "ports.json", path, sizeof path))
			return EX_UNAVAILABLE_;
		control = path;
	}
	/* the commands that take arguments, said before asking the simulator (a usage error, 64) */
	static const struct {
		const char *cmd, *args;
		int min;
	} need[] = { { "sample", "NAME", 1 }, { "fault", "NAME [ARGS] (acq-sim ctl help lists them)", 1 },
		     { "pose", "LASER.THETA DETECTOR.THETA DETECTOR.PHI", 3 }, { "temperature", "C", 1 },
		     { "laser", "on|off [PCT]", 1 } };
	for (size_t k = 0; k < sizeof need / sizeof need[0]; k++)
		if (!strcmp(argv[i], need[k].cmd) && argc - i - 1 < need[k].min) {
			fprintf(stderr, "acq-sim ctl: %s needs %s (acq-sim ctl --help)\n", need[k].cmd, need[k].args);
			return EX_USAGE_;
		}
	char line[1024];
	size_t n = 0;
	const char *cmd = argv[i];
	if (!strcmp(cmd, "truth"))
		cmd = "status";
	if (!strcmp(cmd, "reference")) {
		if (i + 1 != argc) {
			fprintf(stderr, "acq-sim ctl: reference takes no argument\n");
			return EX_USAGE_;
		}
		n = (size_t)snprintf(line, sizeof line, "sample white");
	} else {
		n = (size_t)snprintf(line, sizeof line, "%s", cmd);
		for (int k = i + 1; k < argc && n < sizeof line; k++)
			n += (size_t)snprintf(line + n, sizeof line - n, " %s", argv[k]);
	}
	if (n + 2 >= sizeof line) {
		fprintf(stderr, "acq-sim ctl: command too long\n");
		return EX_USAGE_;
	}
	line[n++] = '\n';
	line[n] = 0;
	char reply[4096];
	if (exchange(control, line, reply, sizeof reply))
		return EX_UNAVAILABLE_;
	bool ok = !strncmp(reply, "ok", 2);
	if (json) {
		json_t *o = ok ? kv_json(cmd, reply + 2) : json_pack("{s:b,s:s}", "ok", 0, "error", reply);
		char *s = json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(12)); /* 74.3259, not 74.325900000000004 */
		puts(s ? s : "{}");
		free(s);
		json_decref(o);
	} else if (ok) {
		/* one "key: value" per line for status/truth, else the reply as is */
		const char *body = reply[2] == ' ' ? reply + 3 : reply + 2;
		if (!strcmp(cmd, "status")) {
			char *copy = strdup(body), *save = NULL;
			for (char *t = copy ? strtok_r(copy, " ", &save) : NULL; t; t = strtok_r(NULL, " ", &save)) {
				char *eq = strchr(t, '=');
				if (eq)
					*eq = 0;
				printf("%-15s %s\n", t, eq ? eq + 1 : "");
			}
			free(copy);
		} else {
			puts(*body ? body : "ok");
		}
	} else {
		fprintf(stderr, "acq-sim ctl: %s\n", reply);
	}
	/* a command the simulator does not know is a usage error, like acqctl's */
	return ok ? 0 : strstr(reply, "error: unknown command") == reply ? EX_USAGE_ : 1;
}
