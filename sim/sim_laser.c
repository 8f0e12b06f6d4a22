/* sim_laser: the simulated supercontinuum laser, speaking the line protocol of drivers/laser_serial.c; it
 * writes world->laser_emission / laser_power_pct and obeys the interlock and fault injections (emission forced
 * off, STATUS reports them, EMISSION ON refused).
 *
 * The link (`sim: {laser: {link: socket|pty}}`, default socket):
 * - socket: a Unix stream socket, as a serial device server (ser2net, a terminal server in raw mode) serves a
 *   serial line; published as "laser": {"device": "unix:PATH"}, which the driver opens with its socket
 *   transport. The latest connection gets the line (an earlier one is closed), as a serial port has no
 *   connections. Bytes written to a socket are in the reader's queue when write() returns.
 * - pty: a pseudo-terminal, published as "laser": {"device": "/dev/pts/N"} (the driver's termios transport,
 *   terminal programs). A pty moves every byte through the kernel's tty flip buffer, pushed by a kernel worker
 *   thread (flush_to_ldisc on the events_unbound workqueue, nice 0): on a CPU-starved machine that worker
 *   waited up to 0.82 s for a CPU before a reply reached the daemon (issue 15's soak stalls; a laser's own
 *   USB-serial adapter goes through the same worker), whatever priority the daemon and the simulator run at.
 *   So the bench's default link is the socket.
 *
 * Keep-alive (the laser's own watchdog): "KEEPALIVE <ms>" arms it, and then emission stops when no command
 * has arrived for ms of real time (whatever the bench's time scale: it stands for the laser's firmware
 * timer); any command refreshes it, "KEEPALIVE" alone too. A command already waiting on the link when the
 * period ends counts as arrived (a UART receives it on arrival; this process may read it late). Expiries are
 * counted in `keepalive_expired`.
 *
 * Delay (the control socket's `laser-delay MS`, a slow serial device): each command is acted on and answered MS
 * real milliseconds after it arrived (in order, by the delay set at the time; the keep-alive counts it at its
 * arrival). At most 64 commands are held: more are lost, as by a receive buffer's overrun.
 *
 * Options (all optional), `sim: {laser: {...}}`: model, serial, firmware (ID? reply tokens), link, socket
 * (the socket's path; default /tmp/acq-sim.<pid>.laser.sock). The device's own config mapping
 * (devices.laser) is not read: the endpoint is published by describe(). */
#include "sim/sim.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "config/acq_num.h"

#define SL_LINE_MAX 128
#define SL_DELAYED_MAX 64 /* commands a slow laser holds; more are lost (a receive buffer overrun) */

struct sim_laser {
	struct sim_service svc;  /* returned to the caller; freed with the rest by destroy */
	struct sim_world *w;
	bool pty;               /* link: pty (else socket) */
	int master, slave;      /* pty: the slave stays open so the master never sees a hang-up between clients */
	int lfd;                /* socket: listening */
	int link;               /* the line's fd: the pty master, or the connected client (-1: none) */
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
	struct sl_delayed {     /* commands received while a delay is set, oldest first */
		char line[SL_LINE_MAX + 1];
		bool overlong;
		double at;      /* real monotonic seconds of its arrival */
	} delayed[SL_DELAYED_MAX];
	int ndelayed;
	unsigned long delayed_lost;
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
	int n = 0;
	if (!s->pty && n < max)
		fds[n++] = (struct pollfd){ .fd = s->lfd, .events = POLLIN };
	if (s->link >= 0 && n < max)
		fds[n++] = (struct pollfd){ .fd = s->link, .events = (short)(POLLIN | (s->outlen ? POLLOUT : 0)) };
	return n;
}

/* socket: the client went away; the laser keeps its state (the keep-alive stops an orphaned emission). */
static void drop_link(struct sim_laser *s)
{
	if (s->pty || s->link < 0)
		return;
	close(s->link);
	s->link = -1;
	s->len = s->outlen = 0;
	s->overlong = false;
}

static void flush_out(struct sim_laser *s)
{
	while (s->outlen && s->link >= 0) {
		ssize_t n = s->pty ? write(s->link, s->out, s->outlen)
				   : send(s->link, s->out, s->outlen, MSG_NOSIGNAL | MSG_DONTWAIT);
		if (n < 0 && !s->pty && errno != EAGAIN && errno != EINTR)
			drop_link(s);
		if (n <= 0)
			return;
		memmove(s->out, s->out + n, s->outlen - (size_t)n);
		s->outlen -= (size_t)n;
	}
}

/* Act on one received line and queue its reply. Faults apply before the command is judged. */
static void run_line(struct sim_laser *s, const char *line, bool overlong)
{
	if (emission_blocked(s))
		s->w->laser_emission = false;
	if (overlong)
		reply(s, "ERR 5 line too long");
	else
		command(s, line);
	if (s->link < 0)
		s->outlen = 0; /* the client that asked has gone: its reply is not for the next one */
}

/* The delayed commands that are due (by the delay set now), in order. */
static void run_delayed(struct sim_laser *s)
{
	double due = real_now() - s->w->faults.laser_delay_ms * 1e-3;
	int k = 0;
	while (k < s->ndelayed && s->delayed[k].at <= due) {
		run_line(s, s->delayed[k].line, s->delayed[k].overlong);
		k++;
	}
	if (k) {
		memmove(s->delayed, s->delayed + k, (size_t)(s->ndelayed - k) * sizeof s->delayed[0]);
		s->ndelayed -= k;
		flush_out(s);
	}
}

/* A line has arrived: act on it now, or after the delay (behind any still delayed). */
static void received(struct sim_laser *s)
{
	s->line[s->len] = '\0';
	s->last_cmd = real_now();
	int delay = s->w->faults.laser_delay_ms;
	if ((delay > 0 || s->ndelayed) && s->ndelayed == SL_DELAYED_MAX) {
		if (!s->delayed_lost++)
			fprintf(stderr, "acq-sim: laser: more than %d commands held by laser-delay: the newest are lost\n",
				SL_DELAYED_MAX);
	} else if (delay > 0 || s->ndelayed) {
		struct sl_delayed *d = &s->delayed[s->ndelayed++];
		memcpy(d->line, s->line, s->len + 1);
		d->overlong = s->overlong;
		d->at = s->last_cmd;
	} else {
		run_line(s, s->line, s->overlong);
	}
	s->len = 0;
	s->overlong = false;
}

/* Bytes wait on the link: the laser has received them (see sl_handle). */
static bool input_waiting(const struct sim_laser *s)
{
	struct pollfd pfd = { .fd = s->link, .events = POLLIN };
	return s->link >= 0 && poll(&pfd, 1, 0) > 0 && (pfd.revents & POLLIN);
}

static void sl_handle(void *self, const struct pollfd *fds, int n, double now)
{
	(void)now;
	struct sim_laser *s = self;
	int k = 0;
	if (!s->pty && k < n && fds[k++].revents & POLLIN) {
		int fd = accept4(s->lfd, NULL, NULL, SOCK_CLOEXEC | SOCK_NONBLOCK);
		if (fd >= 0) {
			drop_link(s); /* the latest opener gets the line */
			s->link = fd;
			return;
		}
	}
	if (k >= n || s->link < 0 || fds[k].fd != s->link)
		return;
	if (fds[k].revents & (POLLIN | POLLHUP | POLLERR)) {
		char buf[512];
		ssize_t got = read(s->link, buf, sizeof buf);
		if (!s->pty && (got == 0 || (got < 0 && errno != EAGAIN && errno != EINTR))) {
			drop_link(s);
			return;
		}
		for (ssize_t i = 0; i < got; i++) {
			char c = buf[i];
			if (c == '\r')
				continue;
			if (c == '\n') {
				/* The keep-alive is judged by sl_tick() between reads only: a line read now may have
				 * waited on the link while this process was not scheduled (a loaded machine), whereas a
				 * laser's UART receives it on arrival. */
				received(s);
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
	run_delayed(s);
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
	snprintf(buf, len, "\"laser\": {\"device\": \"%s%s\"}", s->pty ? "" : "unix:", s->path);
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
	if (!s->pty && s->link >= 0)
		close(s->link);
	if (s->lfd >= 0) {
		close(s->lfd);
		unlink(s->path);
	}
	free(s);
}

/* link: pty — a pseudo-terminal in raw mode; s->path is its slave's name. 0 or -1. */
static int open_pty(struct sim_laser *s, struct acq_err *err)
{
	s->master = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
	const char *name = NULL;
	if (s->master < 0 || grantpt(s->master) || unlockpt(s->master) || !(name = ptsname(s->master)))
		return acq_errf(err, ACQ_E_IO, "simulated laser: pseudo-terminal: %s", strerror(errno));
	snprintf(s->path, sizeof s->path, "%s", name);
	s->slave = open(s->path, O_RDWR | O_NOCTTY | O_CLOEXEC);
	struct termios t;
	if (s->slave < 0 || tcgetattr(s->slave, &t))
		return acq_errf(err, ACQ_E_IO, "simulated laser: %s: %s", s->path, strerror(errno));
	cfmakeraw(&t); /* no echo, no line editing: the driver sees only our replies */
	if (tcsetattr(s->slave, TCSANOW, &t))
		return acq_errf(err, ACQ_E_IO, "simulated laser: %s: %s", s->path, strerror(errno));
	s->link = s->master;
	return 0;
}

struct sim_service *sim_laser_new(struct sim_world *w, struct yc_node *node, struct yc_node *simcfg,
				  struct acq_err *err)
{
	(void)node;
	struct yc_node *opts = simcfg ? yc_get(simcfg, "laser") : NULL;
	const char *model = "SIM-SC450", *serial = "SIM0001", *firmware = "1.0", *path = NULL;
	static const char *const links[] = { "socket", "pty", NULL };
	int link = 0;
	if (opts && (yc_expect_map(opts, "sim.laser", err) || yc_string(opts, "model", false, &model, err) ||
		     yc_string(opts, "serial", false, &serial, err) || yc_string(opts, "firmware", false, &firmware, err) ||
		     yc_enum(opts, "link", false, links, &link, err) || yc_string(opts, "socket", false, &path, err) ||
		     yc_check_unknown(opts, "sim.laser", err)))
		return NULL;
	if (strpbrk(model, " \t") || strpbrk(serial, " \t") || strpbrk(firmware, " \t") || !*model || !*serial ||
	    !*firmware) {
		yc_errf(err, opts, "sim.laser: model, serial and firmware must be single words");
		return NULL;
	}
	if (path && (link == 1 || !*path || strchr(path, '"') || strchr(path, '\\'))) {
		yc_errf(err, yc_get(opts, "socket"), "sim.laser.socket: %s", link == 1 ? "only with link: socket" :
			"expected a path without quotes or backslashes");
		return NULL;
	}
	struct sim_laser *s = calloc(1, sizeof *s);
	if (!s) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		return NULL;
	}
	s->w = w;
	s->pty = link == 1;
	s->master = s->slave = s->lfd = s->link = -1;
	snprintf(s->model, sizeof s->model, "%s", model);
	snprintf(s->serial, sizeof s->serial, "%s", serial);
	snprintf(s->firmware, sizeof s->firmware, "%s", firmware);
	if (s->pty) {
		if (open_pty(s, err))
			goto fail;
	} else {
		if (path)
			snprintf(s->path, sizeof s->path, "%s", path);
		else
			snprintf(s->path, sizeof s->path, "/tmp/acq-sim.%ld.laser.sock", (long)getpid());
		if ((s->lfd = sim_listen_unix(s->path, err)) < 0) {
			acq_err_prefix(err, "simulated laser: ");
			goto fail;
		}
	}
	w->laser_emission = false;
	s->svc = (struct sim_service){ .name = "laser", .self = s, .pollfds = sl_pollfds, .handle = sl_handle,
				       .tick = sl_tick, .describe = sl_describe, .destroy = sl_destroy };
	return &s->svc;
fail:
	sl_destroy(s);
	return NULL;
}
