/* sim_laser: the simulated supercontinuum laser on a pseudo-terminal, speaking the line protocol of
 * drivers/laser_serial.c; it writes world->laser_emission / laser_power_pct and obeys the interlock and fault
 * injections (emission forced off, STATUS reports them, EMISSION ON refused).
 *
 * Keep-alive (the laser's own watchdog): "KEEPALIVE <ms>" arms it, and then emission stops when no command
 * has arrived for ms of real time (whatever the bench's time scale: it stands for the laser's firmware
 * timer); any command refreshes it, "KEEPALIVE" alone too. Expiries are counted in `keepalive_expired`.
 *
 * Options (all optional), `sim: {laser: {...}}`: model, serial, firmware (ID? reply tokens). The device's
 * own config mapping (devices.laser) is not read: the pty path is chosen by the system and published by
 * describe() as "laser": {"device": "/dev/pts/N"}. */
#include "sim/sim.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "config/acq_num.h"

#define SL_LINE_MAX 128

struct sim_laser {
	struct sim_service svc;  /* returned to the caller; freed with the rest by destroy */
	struct sim_world *w;
	int master, slave;      /* the slave stays open so the master never sees a hang-up between clients */
	char path[128];
	char model[64], serial[64], firmware[64];
	char line[SL_LINE_MAX + 1];
	size_t len;
	bool overlong;
	char out[4096];
	size_t outlen;
	int keepalive_ms;       /* 0: disarmed */
	double last_cmd;        /* real monotonic seconds of the last command */
	unsigned keepalive_expired;
};

static double real_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static void reply(struct sim_laser *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

static void reply(struct sim_laser *s, const char *fmt, ...)
{
	char buf[256];
	va_list ap;
	va_start(ap, fmt);
	int n = vsnprintf(buf, sizeof buf - 1, fmt, ap);
	va_end(ap);
	if (n < 0)
		return;
	if ((size_t)n > sizeof buf - 2)
		n = (int)sizeof buf - 2;
	buf[n++] = '\n';
	if (s->outlen + (size_t)n > sizeof s->out)
		return; /* nobody reads: drop rather than grow */
	memcpy(s->out + s->outlen, buf, (size_t)n);
	s->outlen += (size_t)n;
}

static bool emission_blocked(const struct sim_laser *s)
{
	return s->w->faults.laser_interlock_open || s->w->faults.laser_fault;
}

static void command(struct sim_laser *s, const char *cmd)
{
	struct sim_world *w = s->w;
	if (!strcmp(cmd, "ID?")) {
		reply(s, "ID %s %s %s", s->model, s->serial, s->firmware);
	} else if (!strcmp(cmd, "EMISSION ON")) {
		if (w->faults.laser_fault)
			reply(s, "ERR 4 fault active");
		else if (w->faults.laser_interlock_open)
			reply(s, "ERR 3 interlock open");
		else {
			w->laser_emission = true;
			reply(s, "OK");
		}
	} else if (!strcmp(cmd, "EMISSION OFF")) {
		w->laser_emission = false;
		reply(s, "OK");
	} else if (!strcmp(cmd, "EMISSION?")) {
		reply(s, "EMISSION %d", w->laser_emission);
	} else if (!strncmp(cmd, "POWER ", 6)) {
		double v;
		if (acq_num_parse(cmd + 6, 0, 100, &v))
			reply(s, "ERR 2 power must be a number in [0, 100]");
		else {
			w->laser_power_pct = v;
			reply(s, "OK");
		}
	} else if (!strcmp(cmd, "POWER?")) {
		reply(s, "POWER %.1f", w->laser_power_pct);
	} else if (!strcmp(cmd, "KEEPALIVE")) {
		reply(s, "OK");
	} else if (!strncmp(cmd, "KEEPALIVE ", 10)) {
		char *end;
		long v = strtol(cmd + 10, &end, 10);
		if (end == cmd + 10 || *end || v < 0 || v > 600000)
			reply(s, "ERR 2 keep-alive must be an integer in [0, 600000] ms");
		else {
			s->keepalive_ms = (int)v;
			reply(s, "OK");
		}
	} else if (!strcmp(cmd, "STATUS?")) {
		w->laser_status_reads++;
		reply(s, "STATUS emission=%d interlock=%d fault=%d", w->laser_emission, !w->faults.laser_interlock_open,
		      w->faults.laser_fault ? 1 : 0);
	} else {
		reply(s, "ERR 1 unknown command");
	}
}

static int sl_pollfds(void *self, struct pollfd *fds, int max)
{
	struct sim_laser *s = self;
	if (max < 1)
		return 0;
	fds[0] = (struct pollfd){ .fd = s->master, .events = (short)(POLLIN | (s->outlen ? POLLOUT : 0)) };
	return 1;
}

static void flush_out(struct sim_laser *s)
{
	while (s->outlen) {
		ssize_t n = write(s->master, s->out, s->outlen);
		if (n <= 0)
			return;
		memmove(s->out, s->out + n, s->outlen - (size_t)n);
		s->outlen -= (size_t)n;
	}
}

static void sl_tick(void *self, double now);

/* Bytes wait in the pty: the laser has received them (see sl_handle). */
static bool input_waiting(const struct sim_laser *s)
{
	struct pollfd pfd = { .fd = s->master, .events = POLLIN };
	return poll(&pfd, 1, 0) > 0 && (pfd.revents & POLLIN);
}

static void sl_handle(void *self, const struct pollfd *fds, int n, double now)
{
	(void)now;
	struct sim_laser *s = self;
	if (n < 1)
		return;
	if (fds[0].revents & POLLIN) {
		char buf[512];
		ssize_t got = read(s->master, buf, sizeof buf);
		for (ssize_t i = 0; i < got; i++) {
			char c = buf[i];
			if (c == '\r')
				continue;
			if (c == '\n') {
				s->line[s->len] = '\0';
				/* Faults apply before the command is judged. The keep-alive is judged by sl_tick() between
				 * reads only: a line read now may have waited in the pty while this process was not scheduled
				 * (a loaded machine), whereas a laser's UART receives it on arrival. */
				if (emission_blocked(s))
					s->w->laser_emission = false;
				s->last_cmd = real_now();
				if (s->overlong)
					reply(s, "ERR 5 line too long");
				else
					command(s, s->line);
				s->len = 0;
				s->overlong = false;
				continue;
			}
			if (s->len >= SL_LINE_MAX)
				s->overlong = true;
			else
				s->line[s->len++] = c;
		}
	}
	flush_out(s);
}

static void sl_tick(void *self, double now)
{
	(void)now;
	struct sim_laser *s = self;
	if (emission_blocked(s))
		s->w->laser_emission = false;
	if (s->keepalive_ms && s->w->laser_emission && real_now() - s->last_cmd > s->keepalive_ms * 1e-3 &&
	    !input_waiting(s)) {
		s->w->laser_emission = false;
		s->keepalive_expired++;
		fprintf(stderr, "acq-sim: laser: no command for %d ms: keep-alive expired, emission off\n", s->keepalive_ms);
	}
}

static void sl_describe(void *self, char *buf, size_t len)
{
	struct sim_laser *s = self;
	snprintf(buf, len, "\"laser\": {\"device\": \"%s\"}", s->path);
}

static void sl_destroy(void *self)
{
	struct sim_laser *s = self;
	if (!s)
		return;
	s->w->laser_emission = false;
	if (s->slave >= 0)
		close(s->slave);
	if (s->master >= 0)
		close(s->master);
	free(s);
}

struct sim_service *sim_laser_new(struct sim_world *w, struct yc_node *node, struct yc_node *simcfg,
				  struct acq_err *err)
{
	(void)node;
	struct yc_node *opts = simcfg ? yc_get(simcfg, "laser") : NULL;
	const char *model = "SIM-SC450", *serial = "SIM0001", *firmware = "1.0";
	if (opts && (yc_expect_map(opts, "sim.laser", err) || yc_string(opts, "model", false, &model, err) ||
		     yc_string(opts, "serial", false, &serial, err) || yc_string(opts, "firmware", false, &firmware, err) ||
		     yc_check_unknown(opts, "sim.laser", err)))
		return NULL;
	if (strpbrk(model, " \t") || strpbrk(serial, " \t") || strpbrk(firmware, " \t") || !*model || !*serial ||
	    !*firmware) {
		yc_errf(err, opts, "sim.laser: model, serial and firmware must be single words");
		return NULL;
	}
	struct sim_laser *s = calloc(1, sizeof *s);
	if (!s) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		return NULL;
	}
	s->w = w;
	s->slave = -1;
	snprintf(s->model, sizeof s->model, "%s", model);
	snprintf(s->serial, sizeof s->serial, "%s", serial);
	snprintf(s->firmware, sizeof s->firmware, "%s", firmware);
	s->master = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
	const char *name = NULL;
	if (s->master < 0 || grantpt(s->master) || unlockpt(s->master) || !(name = ptsname(s->master))) {
		acq_errf(err, ACQ_E_IO, "simulated laser: pseudo-terminal: %s", strerror(errno));
		goto fail;
	}
	snprintf(s->path, sizeof s->path, "%s", name);
	s->slave = open(s->path, O_RDWR | O_NOCTTY | O_CLOEXEC);
	struct termios t;
	if (s->slave < 0 || tcgetattr(s->slave, &t)) {
		acq_errf(err, ACQ_E_IO, "simulated laser: %s: %s", s->path, strerror(errno));
		goto fail;
	}
	cfmakeraw(&t); /* no echo, no line editing: the driver sees only our replies */
	if (tcsetattr(s->slave, TCSANOW, &t)) {
		acq_errf(err, ACQ_E_IO, "simulated laser: %s: %s", s->path, strerror(errno));
		goto fail;
	}
	w->laser_emission = false;
	s->svc = (struct sim_service){ .name = "laser", .self = s, .pollfds = sl_pollfds, .handle = sl_handle,
				       .tick = sl_tick, .describe = sl_describe, .destroy = sl_destroy };
	return &s->svc;
fail:
	sl_destroy(s);
	return NULL;
}
