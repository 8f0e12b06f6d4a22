/* sim_control: acq-sim's control socket (fault injection, sample selection, test hooks) and the seeded fault
 * schedule of `sim.faults`.
 *
 * Protocol: a Unix stream socket, one command per line (<= 511 bytes), one reply line per command:
 * "ok[ details]" or "error: <what>". Commands:
 *   help                                   list the commands
 *   status                                 ok t=<bench s> laser.theta= detector.theta= detector.phi= emission=
 *                                          power= sample= temperature= faults=<comma list or none>
 *                                          laser_status_reads=<STATUS? commands the laser answered>
 *                                          lag_s=<real s the main loop's 1 ms waits ended late, summed>
 *   time                                   ok <bench seconds>
 *   sample MATERIAL|none                   what is on the stage (a material of sim/material.h)
 *   temperature <C>                        spectrometer sensor temperature (-40..80)
 *   pose <laser.theta> <detector.theta> <detector.phi>  set the axes' actual positions (degrees; for runs without the
 *                                          arm services: a running arm service overwrites them)
 *   laser on|off [power_pct]               set emission and power (for runs without the laser service)
 *   fault modbus-timeout ARM [on|off]      ARM: the arm controller, laser_arm | detector_arm (the names of
 *   fault drop-connection ARM   (once)     README "Names, one per thing"; the older laser | detector are
 *   fault alarm-mid-move ARM    (next move) still accepted)
 *   fault stall ARM             (next move)
 *   fault spectro-disconnect [offline_s]   the spectrometer vanishes half way through the next exposure and
 *                                          refuses connections for offline_s bench seconds after (default 0)
 *   fault saturation-burst <N>             the next N spectra are saturated
 *   fault laser-interlock on|off
 *   fault laser-fault on|off
 *   fault clear                            clear every fault flag (and the laser's delay)
 *   laser-delay <ms>                       the laser acts on and answers each command ms real milliseconds after
 *                                          it arrives (0: at once; a slow serial device; keep it under the
 *                                          driver's timeout_ms, 500 by default)
 *
 * Schedule (config):  sim.faults: { seed: N (default --seed), schedule: [ {at: S, fault: NAME, arm: laser_arm|
 * detector_arm, duration: S, count: N, offline_s: S}, ... ], random: {rate_per_min: R, faults: [NAME, ...],
 * duration: S (default 5)} }. `at` is bench seconds; `duration` clears an on/off fault after S seconds; random faults
 * arrive as a Poisson process of R per bench minute, kind and arm drawn from the seeded generator. */
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "config/acq_num.h"
#include "sim/material.h"
#include "sim/sim.h"
#include "sim/sim_physics.h"
#include "sim/sim_rng.h"

#define MAX_CLIENTS 8
#define LINE_MAX_LEN 512
#define MAX_EVENTS 256

enum fault_kind {
	F_MODBUS_TIMEOUT, F_DROP_CONNECTION, F_ALARM_MID_MOVE, F_STALL, F_SPECTRO_DISCONNECT, F_SATURATION_BURST,
	F_LASER_INTERLOCK, F_LASER_FAULT, F__COUNT
};

static const char *const fault_names[F__COUNT + 1] = {
	"modbus-timeout", "drop-connection", "alarm-mid-move", "stall", "spectro-disconnect", "saturation-burst",
	"laser-interlock", "laser-fault", NULL
};

struct event {
	double at;
	int kind, arm;
	bool on;
	double duration, offline_s;
	int count;
};

struct client {
	int fd;
	char in[LINE_MAX_LEN];
	size_t nin;
	char *out;
	size_t nout, capout;
	bool closing;
};

struct control {
	struct sim_service svc;  /* what the constructor returns; freed with the rest by ctl_destroy */
	struct sim_world *w;
	char path[108];
	int lfd;
	struct client cl[MAX_CLIENTS];
	struct event ev[MAX_EVENTS];
	int nev;
	struct sim_rng rng;
	double rate_per_s, rand_duration, next_random;
	int rand_kinds[F__COUNT], nrand;
};

static bool arm_fault(int kind)
{
	return kind <= F_STALL;
}

/* Apply one fault to the world. */
static void apply(struct control *c, const struct event *e, double now)
{
	struct sim_faults *f = &c->w->faults;
	switch (e->kind) {
	case F_MODBUS_TIMEOUT: f->modbus_timeout[e->arm] = e->on; break;
	case F_DROP_CONNECTION: f->drop_connection[e->arm] = true; break;
	case F_ALARM_MID_MOVE: f->alarm_mid_move[e->arm] = true; break;
	case F_STALL: f->stall[e->arm] = true; break;
	case F_SPECTRO_DISCONNECT:
		f->spectro_disconnect = e->on;
		c->w->spectro_offline_until = e->on && e->offline_s > 0 ? now + e->offline_s : 0;
		break;
	case F_SATURATION_BURST: f->saturation_burst = e->on ? e->count : 0; break;
	case F_LASER_INTERLOCK: f->laser_interlock_open = e->on; break;
	case F_LASER_FAULT: f->laser_fault = e->on; break;
	default: break;
	}
}

static int add_event(struct control *c, const struct event *e)
{
	if (c->nev >= MAX_EVENTS)
		return -1;
	c->ev[c->nev++] = *e;
	return 0;
}

static int reply(struct client *k, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Queue one reply line; always 0 (so command() can `return reply(...)`). */
static int reply(struct client *k, const char *fmt, ...)
{
	char line[1024];
	va_list ap;
	va_start(ap, fmt);
	int n = vsnprintf(line, sizeof line - 1, fmt, ap);
	va_end(ap);
	if (n < 0)
		return 0;
	if ((size_t)n > sizeof line - 2)
		n = (int)sizeof line - 2;
	line[n++] = '\n';
	if (k->nout + (size_t)n > k->capout) {
		size_t cap = k->capout ? k->capout * 2 : 2048;
		while (cap < k->nout + (size_t)n)
			cap *= 2;
		char *b = realloc(k->out, cap);
		if (!b) {
			k->closing = true;
			return 0;
		}
		k->out = b;
		k->capout = cap;
	}
	memcpy(k->out + k->nout, line, (size_t)n);
	k->nout += (size_t)n;
	return 0;
}

static int parse_onoff(const char *s, bool *on)
{
	if (!s || !strcmp(s, "on")) {
		*on = true;
		return 0;
	}
	if (!strcmp(s, "off")) {
		*on = false;
		return 0;
	}
	return -1;
}

/* The arm controllers by name (index % 2: 0 the laser's, 1 the detector's): laser_arm, detector_arm as everywhere
 * else; laser, detector are the older spellings, still accepted. */
static const char *const arm_names[] = { "laser_arm", "detector_arm", "laser", "detector", NULL };

static void faults_list(const struct sim_world *w, char *buf, size_t len)
{
	const struct sim_faults *f = &w->faults;
	static const char *const arms[2] = { "laser_arm", "detector_arm" };
	size_t n = 0;
	buf[0] = 0;
#define ADD(...) do { if (n < len) n += (size_t)snprintf(buf + n, len - n, "%s", n ? "," : ""); \
		      if (n < len) n += (size_t)snprintf(buf + n, len - n, __VA_ARGS__); } while (0)
	for (int a = 0; a < 2; a++) {
		if (f->modbus_timeout[a]) ADD("modbus-timeout:%s", arms[a]);
		if (f->drop_connection[a]) ADD("drop-connection:%s", arms[a]);
		if (f->alarm_mid_move[a]) ADD("alarm-mid-move:%s", arms[a]);
		if (f->stall[a]) ADD("stall:%s", arms[a]);
	}
	if (f->spectro_disconnect) ADD("spectro-disconnect");
	if (f->saturation_burst > 0) ADD("saturation-burst:%d", f->saturation_burst);
	if (f->laser_interlock_open) ADD("laser-interlock");
	if (f->laser_fault) ADD("laser-fault");
	if (f->laser_delay_ms > 0) ADD("laser-delay:%d", f->laser_delay_ms);
#undef ADD
	if (!buf[0])
		snprintf(buf, len, "none");
}

static int find_name(const char *const *names, const char *s)
{
	for (int i = 0; s && names[i]; i++)
		if (!strcmp(names[i], s))
			return i;
	return -1;
}

static int command(struct control *c, struct client *k, char *line, double now)
{
	struct sim_world *w = c->w;
	char *argv[8];
	int argc = 0;
	for (char *save = NULL, *t = strtok_r(line, " \t\r", &save); t && argc < 8; t = strtok_r(NULL, " \t\r", &save))
		argv[argc++] = t;
	if (argc == 0)
		return reply(k, "error: empty command (try help)");
	const char *cmd = argv[0];
	if (!strcmp(cmd, "help")) {
		return reply(k, "ok commands: help | status | time | sample MATERIAL|none | temperature C"
				" | pose LASER.THETA DETECTOR.THETA DETECTOR.PHI | laser on|off [POWER_PCT] | fault NAME [ARGS] | fault clear;"
				" faults: modbus-timeout ARM [on|off], drop-connection ARM, alarm-mid-move ARM, stall ARM,"
				" spectro-disconnect [OFFLINE_S], saturation-burst N, laser-interlock on|off, laser-fault on|off;"
				" ARM: laser_arm|detector_arm | laser-delay MS");
	}
	if (!strcmp(cmd, "status")) {
		char fl[512];
		faults_list(w, fl, sizeof fl);
		return reply(k, "ok t=%.6f laser.theta=%.4f detector.theta=%.4f detector.phi=%.4f emission=%d power=%.2f"
				" sample=%s temperature=%.2f faults=%s laser_status_reads=%lu lag_s=%.6f collisions=%lu",
			     now, w->laser_theta_deg, w->detector_theta_deg, w->detector_phi_deg, w->laser_emission ? 1 : 0,
			     w->laser_power_pct, phys_sample_name(w->sample), w->sensor_temp_c, fl, w->laser_status_reads,
			     w->lag_s, w->collisions);
	}
	if (!strcmp(cmd, "time"))
		return reply(k, "ok %.6f", now);
	if (!strcmp(cmd, "sample")) {
		int s = argc == 2 ? phys_sample_from_name(argv[1]) : -1;
		if (s < 0)
			return reply(k, "error: sample: expected one of %s, none", mat_names_list());
		w->sample = s;
		return reply(k, "ok sample=%s", phys_sample_name(s));
	}
	if (!strcmp(cmd, "temperature")) {
		double t;
		if (argc != 2 || acq_num_parse(argv[1], -40, 80, &t))
			return reply(k, "error: temperature: expected degrees Celsius in [-40, 80]");
		w->sensor_temp_c = t;
		return reply(k, "ok temperature=%.2f", t);
	}
	if (!strcmp(cmd, "pose")) {
		double a, b, d;
		if (argc != 4 || acq_num_parse(argv[1], -360, 360, &a) || acq_num_parse(argv[2], -360, 360, &b) ||
		    acq_num_parse(argv[3], -720, 720, &d))
			return reply(k, "error: pose: expected LASER.THETA DETECTOR.THETA DETECTOR.PHI in degrees");
		w->laser_theta_deg = a;
		w->detector_theta_deg = b;
		w->detector_phi_deg = d;
		return reply(k, "ok pose %.4f %.4f %.4f", a, b, d);
	}
	if (!strcmp(cmd, "laser")) {
		bool on;
		double p = w->laser_power_pct;
		if (argc < 2 || argc > 3 || parse_onoff(argv[1], &on) || (argc == 3 && acq_num_parse(argv[2], 0, 100, &p)))
			return reply(k, "error: laser: expected on|off [POWER_PCT in 0..100]");
		w->laser_emission = on;
		w->laser_power_pct = p;
		return reply(k, "ok emission=%d power=%.2f", on ? 1 : 0, p);
	}
	if (!strcmp(cmd, "laser-delay")) {
		double ms;
		if (argc != 2 || acq_num_parse(argv[1], 0, 60000, &ms) || ms != floor(ms))
			return reply(k, "error: laser-delay: expected whole milliseconds in [0, 60000]");
		w->faults.laser_delay_ms = (int)ms;
		return reply(k, "ok laser-delay=%d", (int)ms);
	}
	if (!strcmp(cmd, "fault")) {
		if (argc == 2 && !strcmp(argv[1], "clear")) {
			memset(&w->faults, 0, sizeof w->faults);
			w->spectro_offline_until = 0;
			return reply(k, "ok faults=none");
		}
		int kind = argc >= 2 ? find_name(fault_names, argv[1]) : -1;
		if (kind < 0)
			return reply(k, "error: fault: unknown fault '%s' (try help)", argc >= 2 ? argv[1] : "");
		struct event e = { .at = now, .kind = kind, .on = true };
		int next = 2;
		if (arm_fault(kind)) {
			e.arm = argc > 2 ? find_name(arm_names, argv[2]) : -1;
			if (e.arm < 0)
				return reply(k, "error: fault %s: expected the arm: laser_arm|detector_arm", argv[1]);
			e.arm %= 2;
			next = 3;
		}
		if (kind == F_SATURATION_BURST) {
			double n;
			if (argc != 3 || acq_num_parse(argv[2], 0, 1e6, &n) || n != floor(n))
				return reply(k, "error: fault saturation-burst: expected a count N >= 0");
			e.count = (int)n;
			e.on = n > 0;
		} else if (kind == F_SPECTRO_DISCONNECT) {
			if (argc > 3 || (argc == 3 && acq_num_parse(argv[2], 0, 1e6, &e.offline_s)))
				return reply(k, "error: fault spectro-disconnect: expected [OFFLINE_SECONDS >= 0]");
		} else if (kind == F_MODBUS_TIMEOUT || kind == F_LASER_INTERLOCK || kind == F_LASER_FAULT) {
			if (argc > next + 1 || parse_onoff(argc > next ? argv[next] : NULL, &e.on) ||
			    (!arm_fault(kind) && argc != 3))
				return reply(k, "error: fault %s: expected %son|off", argv[1], arm_fault(kind) ? "ARM " : "");
		} else if (argc != next) {
			return reply(k, "error: fault %s: unexpected argument '%s'", argv[1], argv[next]);
		}
		apply(c, &e, now);
		char fl[512];
		faults_list(w, fl, sizeof fl);
		return reply(k, "ok faults=%s", fl);
	}
	return reply(k, "error: unknown command '%s' (try help)", cmd);
}

static void drop(struct client *k)
{
	if (k->fd >= 0)
		close(k->fd);
	free(k->out);
	memset(k, 0, sizeof *k);
	k->fd = -1;
}

static void flush_client(struct client *k)
{
	while (k->fd >= 0 && k->nout) {
		ssize_t n = send(k->fd, k->out, k->nout, MSG_NOSIGNAL | MSG_DONTWAIT);
		if (n < 0) {
			if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)
				drop(k);
			return;
		}
		memmove(k->out, k->out + n, k->nout - (size_t)n);
		k->nout -= (size_t)n;
	}
	if (k->fd >= 0 && k->closing && !k->nout)
		drop(k);
}

static void read_lines(struct control *c, struct client *k, double now)
{
	for (;;) {
		if (k->closing)
			return;
		ssize_t n = recv(k->fd, k->in + k->nin, sizeof k->in - k->nin, MSG_DONTWAIT);
		if (n == 0) {
			/* peer done: answer what is buffered, then close */
			k->closing = true;
			return;
		}
		if (n < 0) {
			if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)
				drop(k);
			return;
		}
		k->nin += (size_t)n;
		char *nl;
		while ((nl = memchr(k->in, '\n', k->nin))) {
			*nl = 0;
			size_t used = (size_t)(nl - k->in) + 1;
			if (memchr(k->in, 0, used - 1))
				reply(k, "error: NUL byte in command");
			else
				command(c, k, k->in, now);
			memmove(k->in, k->in + used, k->nin - used);
			k->nin -= used;
		}
		if (k->nin == sizeof k->in) {
			reply(k, "error: command line longer than %d bytes", LINE_MAX_LEN - 1);
			k->closing = true;
			return;
		}
	}
}

static int ctl_pollfds(void *self, struct pollfd *fds, int max)
{
	struct control *c = self;
	if (max < 1 + MAX_CLIENTS)
		return 0;
	fds[0] = (struct pollfd){ .fd = c->lfd, .events = POLLIN };
	for (int i = 0; i < MAX_CLIENTS; i++)
		fds[1 + i] = (struct pollfd){ .fd = c->cl[i].fd, .events = (short)(POLLIN | (c->cl[i].nout ? POLLOUT : 0)) };
	return 1 + MAX_CLIENTS;
}

static void ctl_handle(void *self, const struct pollfd *fds, int n, double now)
{
	struct control *c = self;
	if (n < 1 + MAX_CLIENTS)
		return;
	for (int i = 0; i < MAX_CLIENTS; i++) {
		struct client *k = &c->cl[i];
		if (k->fd < 0 || fds[1 + i].fd != k->fd)
			continue;
		if (fds[1 + i].revents & (POLLIN | POLLHUP | POLLERR))
			read_lines(c, k, now);
		flush_client(k);
	}
	if (fds[0].revents & POLLIN) {
		int fd = accept4(c->lfd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
		if (fd < 0)
			return;
		for (int i = 0; i < MAX_CLIENTS; i++)
			if (c->cl[i].fd < 0) {
				c->cl[i].fd = fd;
				return;
			}
		const char *m = "error: too many control clients\n";
		if (send(fd, m, strlen(m), MSG_NOSIGNAL | MSG_DONTWAIT) < 0) {
			/* closed either way */
		}
		close(fd);
	}
}

static void ctl_tick(void *self, double now)
{
	struct control *c = self;
	for (int i = 0; i < c->nev;) {
		if (c->ev[i].at > now) {
			i++;
			continue;
		}
		struct event e = c->ev[i];
		c->ev[i] = c->ev[--c->nev];
		apply(c, &e, now);
		if (e.on && e.duration > 0 && (e.kind == F_MODBUS_TIMEOUT || e.kind == F_LASER_INTERLOCK || e.kind == F_LASER_FAULT)) {
			struct event off = e;
			off.on = false;
			off.at = e.at + e.duration;
			off.duration = 0;
			add_event(c, &off);
		}
	}
	if (c->rate_per_s > 0 && c->nrand > 0) {
		if (c->next_random < 0)
			c->next_random = now - log(1.0 - sim_rng_uniform(&c->rng)) / c->rate_per_s;
		while (now >= c->next_random) {
			struct event e = { .at = c->next_random, .on = true, .duration = c->rand_duration, .count = 3 };
			e.kind = c->rand_kinds[sim_rng_next(&c->rng) % (uint64_t)c->nrand];
			e.arm = (int)(sim_rng_next(&c->rng) & 1);
			add_event(c, &e);
			c->next_random += -log(1.0 - sim_rng_uniform(&c->rng)) / c->rate_per_s;
		}
	}
	for (int i = 0; i < MAX_CLIENTS; i++)
		if (c->cl[i].fd >= 0)
			flush_client(&c->cl[i]);
}

static void ctl_describe(void *self, char *buf, size_t len)
{
	struct control *c = self;
	char esc[256];
	size_t j = 0;
	for (size_t i = 0; c->path[i] && j + 3 < sizeof esc; i++) {
		if (c->path[i] == '"' || c->path[i] == '\\')
			esc[j++] = '\\';
		esc[j++] = c->path[i];
	}
	esc[j] = 0;
	snprintf(buf, len, "\"control\": {\"socket\": \"%s\"}", esc);
}

static void ctl_destroy(void *self)
{
	struct control *c = self;
	if (!c)
		return;
	for (int i = 0; i < MAX_CLIENTS; i++)
		drop(&c->cl[i]);
	if (c->lfd >= 0) {
		close(c->lfd);
		unlink(c->path);
	}
	free(c);
}

static int parse_faults(struct control *c, struct yc_node *fn, struct acq_err *err)
{
	if (yc_expect_map(fn, "sim.faults", err))
		return -1;
	long long seed = (long long)(c->w->seed & 0x7fffffffffffffffull);
	if (yc_int(fn, "seed", false, 0, INT64_MAX, &seed, err))
		return -1;
	sim_rng_seed(&c->rng, (uint64_t)seed ^ 0xfa17ull);
	struct yc_node *sched = yc_get(fn, "schedule");
	if (sched) {
		if (yc_expect_seq(sched, "sim.faults.schedule", err))
			return -1;
		for (size_t i = 0; i < sched->n; i++) {
			struct yc_node *it = sched->items[i];
			struct event e = { .on = true };
			int arm = -1;
			long long count = 1;
			if (yc_expect_map(it, "a fault schedule entry", err) ||
			    yc_double(it, "at", true, 0, 1e9, &e.at, err) || yc_enum(it, "fault", true, fault_names, &e.kind, err) ||
			    yc_enum(it, "arm", false, arm_names, &arm, err) || yc_double(it, "duration", false, 0, 1e9, &e.duration, err) ||
			    yc_int(it, "count", false, 0, 1000000, &count, err) ||
			    yc_double(it, "offline_s", false, 0, 1e9, &e.offline_s, err))
				return -1;
			if (arm_fault(e.kind) && arm < 0)
				return yc_errf(err, it, "fault %s needs `arm: laser_arm|detector_arm`", fault_names[e.kind]);
			e.arm = arm < 0 ? 0 : arm % 2;
			e.count = (int)count;
			if (yc_check_unknown(it, "a fault schedule entry", err))
				return -1;
			if (add_event(c, &e))
				return yc_errf(err, it, "more than %d scheduled faults", MAX_EVENTS / 2);
		}
	}
	struct yc_node *rn = yc_get(fn, "random");
	if (rn) {
		double rate = 0;
		struct yc_node *kinds;
		if (yc_expect_map(rn, "sim.faults.random", err) || yc_double(rn, "rate_per_min", true, 0, 1e4, &rate, err) ||
		    yc_double(rn, "duration", false, 0, 1e9, &c->rand_duration, err))
			return -1;
		if (!(kinds = yc_get(rn, "faults")))
			return yc_errf(err, rn, "sim.faults.random: missing key 'faults' (a list of fault names)");
		if (yc_expect_seq(kinds, "sim.faults.random.faults", err))
			return -1;
		for (size_t i = 0; i < kinds->n && c->nrand < F__COUNT; i++) {
			int k = kinds->items[i]->type == YC_SCALAR ? find_name(fault_names, kinds->items[i]->value) : -1;
			if (k < 0)
				return yc_errf(err, kinds->items[i], "unknown fault name (expected one of modbus-timeout, "
					       "drop-connection, alarm-mid-move, stall, spectro-disconnect, saturation-burst, "
					       "laser-interlock, laser-fault)");
			c->rand_kinds[c->nrand++] = k;
		}
		c->rate_per_s = rate / 60.0;
		if (yc_check_unknown(rn, "sim.faults.random", err))
			return -1;
	}
	return yc_check_unknown(fn, "sim.faults", err);
}

struct sim_service *sim_control_new(struct sim_world *w, struct yc_node *simcfg, const char *socket_path,
				    struct acq_err *err)
{
	struct control *c = calloc(1, sizeof *c);
	if (!c) {
		acq_errf(err, ACQ_E_NOMEM, "control: out of memory");
		return NULL;
	}
	c->w = w;
	c->lfd = -1;
	c->next_random = -1;
	c->rand_duration = 5.0;
	for (int i = 0; i < MAX_CLIENTS; i++)
		c->cl[i].fd = -1;
	sim_rng_seed(&c->rng, w->seed ^ 0xfa17ull);
	struct yc_node *fn = simcfg ? yc_get(simcfg, "faults") : NULL;
	if (fn && parse_faults(c, fn, err))
		goto fail;
	if (socket_path)
		snprintf(c->path, sizeof c->path, "%s", socket_path);
	else
		snprintf(c->path, sizeof c->path, "/tmp/acq-sim.%ld.control.sock", (long)getpid());
	if ((c->lfd = sim_listen_unix(c->path, err)) < 0) {
		acq_err_prefix(err, "control socket: ");
		goto fail;
	}
	c->svc = (struct sim_service){ .name = "control", .self = c, .pollfds = ctl_pollfds, .handle = ctl_handle,
				     .tick = ctl_tick, .describe = ctl_describe, .destroy = ctl_destroy };
	return &c->svc;
fail:
	ctl_destroy(c);
	return NULL;
}
