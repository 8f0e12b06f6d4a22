/* axis_peer: the peers of the Modbus axis driver tests (test_axis_modbus.c, test_axis_modbus_sim.c): our
 * simulated controller (sim/sim_arm.c, hosted in the test process) or an independent pymodbus server
 * (tests/integration/az_peer.py), over TCP or over RTU on a socat pty pair; the driver's configuration for
 * them and the helpers the tests step it with. Header-only (static inline), after cmocka.h. */
#ifndef AXIS_PEER_H
#define AXIS_PEER_H

#include <arpa/inet.h>
#include <math.h>
#include <modbus.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include "tests/unit/armhost.h"

#define PY "/usr/bin/python3"
#define SIM_SCALE 20.0
/* Timing slack is expressed in REAL seconds: the simulator's bench clock runs SIM_SCALE× faster than real
 * time, so 1 bench s of slack is only 50 ms of scheduling, which a loaded CI machine exceeds (measured beside
 * `stress-ng --cpu 4`, load 5-20 on 2 cores: driver overhead per move up to ~0.3 s real, stalls of 7 s, a
 * Python peer > 10 s to start, an RTU answer > 5 s). peer_t() (ACQ_PEER_TIMEOUT_S, default 10 s; the knob
 * test_sim_arm and test_arm_mbpoll.sh use) is that real-time allowance: the driver's response timeout,
 * its move deadline margin, and the upper bound of what it may add to a move's profile (command delivery,
 * polling 0.02 + settle 0.05 bench s ≈ 4 ms real when idle). Lower bounds and the profile itself are exact. */
static inline double peer_t(void)
{
	const char *t = getenv("ACQ_PEER_TIMEOUT_S");
	double s = t && *t ? atof(t) : 10.0;
	return s > 0 && s <= 60 ? s : 10.0;
}

enum { PEER_SIM = 0, PEER_PY = 1 };

/* assert_int_equal that also prints the driver's last error message (err must be in scope) */
#define EXPECT(expr, want)                                                                                  \
	do {                                                                                                \
		long long got_ = (long long)(expr);                                                         \
		if (got_ != (long long)(want))                                                              \
			fprintf(stderr, "%s:%d: %s = %lld, want %lld; last error: %s\n", __FILE__, __LINE__,    \
				#expr, got_, (long long)(want), err.msg);                                   \
		assert_int_equal(got_, (want));                                                             \
	} while (0)

struct peer {
	int kind;
	bool rtu;
	const char *label;
	struct armhost host;
	bool host_started;
	pid_t py;
	struct ah_pty pty;
	char *dir;
	int port;
	double speed, accel;      /* what the driver commands (the sim clips to its bench kinematics) */
	double init_theta, init_phi;
	struct yc_doc *maps_doc;  /* config/bench-sim.yaml: the shipped AZ map */
	struct yc_doc *doc;       /* the driver's config */
	struct axis_cfg *cfg[2];
	int ncfg;
	int retries;
	int resp_ms;              /* driver's response timeout; 0: suite_resp_ms() */
	double margin_real_s;     /* move deadline margin in real seconds; 0: peer_t() */
};

/* The driver's response timeout for the suite (ms): peer_t(). A Python peer behind socat on a busy machine was
 * measured to miss a 300 ms timeout during homing; a dead peer still fails, only later. Tests of the timeout
 * itself set resp_ms. */
static inline int suite_resp_ms(void)
{
	return (int)(peer_t() * 1000);
}

static inline int peer_resp_ms(const struct peer *p)
{
	return p->resp_ms > 0 ? p->resp_ms : suite_resp_ms();
}

static inline struct yc_doc *load_file(const char *rel)
{
	char path[512];
	struct acq_err err = { 0 };
	struct yc_doc *doc = NULL;
	snprintf(path, sizeof path, "%s/%s", ah_src(), rel);
	if (yc_load_file(path, &doc, &err)) {
		fprintf(stderr, "%s\n", err.msg);
		return NULL;
	}
	return doc;
}

static inline struct yc_node *maps_of(struct yc_doc *doc)
{
	return yc_get(yc_get(yc_root(doc), "devices"), "register_maps");
}

static inline double peer_clock(void *p)
{
	struct peer *pe = p;
	return pe->kind == PEER_SIM ? ah_now(&pe->host) : ah_mono();
}

static inline double peer_scale(const struct peer *p)
{
	return p->kind == PEER_SIM ? SIM_SCALE : 1.0;
}

/* The driver's move deadline margin (timeout_margin_s, peer clock seconds): peer_t() of real time. It was
 * 1 bench s = 50 ms real, which a loaded machine exceeded (a landing retry failed by time-out). */
static inline double move_margin_s(const struct peer *p)
{
	return (p->margin_real_s > 0 ? p->margin_real_s : peer_t()) * peer_scale(p);
}

static inline void arm_yaml(char *buf, size_t len, const struct peer *p, const char *link, int retries,
			    const char *map)
{
	snprintf(buf, len,
		 "bench:\n"
		 "  detector_theta: {noise_deg: 0, backlash_deg: 0}\n"
		 "  detector_phi: {noise_deg: 0, backlash_deg: 0}\n"
		 "devices:\n"
		 "  detector_arm:\n"
		 "    link: %s\n"
		 "    response_timeout_ms: %d\n"
		 "    byte_timeout_ms: 50\n"
		 "    axes:\n"
		 "      theta: {unit: 1, map: %s, soft_min_deg: -3, soft_max_deg: 100, deadband_deg: 0.02,\n"
		 "              retries: %d, speed_dps: %g, accel_dps2: %g, settle_s: 0.05, poll_s: 0.02,\n"
		 "              timeout_margin_s: %g}\n"
		 "      phi: {unit: 2, map: %s, soft_min_deg: -179, soft_max_deg: 359, deadband_deg: 0.02,\n"
		 "            retries: %d, speed_dps: %g, accel_dps2: %g, settle_s: 0.05, poll_s: 0.02,\n"
		 "            timeout_margin_s: %g}\n",
		 link, peer_resp_ms(p), map, retries, p->speed, p->accel, move_margin_s(p), map, retries, p->speed,
		 p->accel, move_margin_s(p));
}

static inline int peer_load_cfg(struct peer *p, const char *map, struct acq_err *err)
{
	char link[512], yaml[4096];
	if (p->rtu)
		snprintf(link, sizeof link, "{type: rtu, device: %s, baud: 115200, parity: none, data_bits: 8, "
			 "stop_bits: 1}", p->pty.a);
	else
		snprintf(link, sizeof link, "{type: tcp, host: 127.0.0.1, port: %d}", p->port);
	arm_yaml(yaml, sizeof yaml, p, link, p->retries, map);
	for (int i = 0; i < p->ncfg; i++)
		axis_cfg_free(p->cfg[i]);
	p->ncfg = 0;
	yc_free(p->doc);
	p->doc = NULL;
	if (yc_load_string("driver.yaml", yaml, strlen(yaml), &p->doc, err))
		return -1;
	return axis_arm_parse(yc_get(yc_get(yc_root(p->doc), "devices"), "detector_arm"), maps_of(p->maps_doc),
			      "detector_arm", p->cfg, 2, &p->ncfg, err);
}

static inline int py_start(struct peer *p, int port)
{
	char script[512], portarg[32], pf[300], seed[32], log[300];
	snprintf(script, sizeof script, "%s/tests/integration/az_peer.py", ah_src());
	snprintf(pf, sizeof pf, "%s/py.port", p->dir);
	snprintf(log, sizeof log, "%s/py.log", p->dir);
	snprintf(portarg, sizeof portarg, "%d", port);
	snprintf(seed, sizeof seed, "%llu", ah_seed());
	unlink(pf);
	if (p->rtu) {
		char *argv[] = { PY, script, "--rtu", p->pty.b, "--ports-file", pf, "--seed", seed, NULL };
		p->py = ah_spawn(argv, log);
		return ah_wait_file(pf, 60) ? 0 : -1; /* written once the serial port is served */
	}
	char *argv[] = { PY, script, "--tcp", portarg, "--ports-file", pf, "--seed", seed, NULL };
	p->py = ah_spawn(argv, log);
	if (!ah_wait_file(pf, 60)) /* a deadline, not a delay: Python took > 10 s to start on a loaded machine */
		return -1;
	FILE *f = fopen(pf, "r");
	if (!f || fscanf(f, "%d", &p->port) != 1) {
		if (f)
			fclose(f);
		return -1;
	}
	fclose(f);
	return 0;
}

static inline bool have_python_peer(void)
{
	return access(PY, X_OK) == 0 && system(PY " -c 'import pymodbus.server.async_io, serial_asyncio' "
					       ">/dev/null 2>&1") == 0;
}

/* Start a peer; returns 0, or 1 to skip (a tool not installed, the reason printed), or -1. */
static inline int peer_start(struct peer *p, const char *map)
{
	struct acq_err err = { 0 };
	p->dir = strdup(ah_mkdtemp());
	p->maps_doc = load_file(strstr(map, "leadshine") ? "config/bench-real.yaml" : "config/bench-sim.yaml");
	if (!p->dir || !p->maps_doc)
		return -1;
	if (p->retries == 0)
		p->retries = 3;
	if (p->rtu && access("/usr/bin/socat", X_OK) != 0) {
		printf("skip: socat is not installed (make deps installs it)\n");
		return 1;
	}
	if (p->rtu && ah_pty_start(&p->pty, p->dir)) {
		fprintf(stderr, "socat did not make its pty pair in 5 s (log in %s)\n", p->dir);
		return -1;
	}
	if (p->kind == PEER_SIM) {
		p->speed = 20;
		p->accel = 60;
		p->init_theta = 60;
		p->init_phi = 180;
		char link[512], yaml[4096];
		if (p->rtu)
			snprintf(link, sizeof link, "{type: rtu, device: %s, baud: 115200}", p->pty.b);
		else
			snprintf(link, sizeof link, "{type: tcp, host: 127.0.0.1, port: 0}");
		arm_yaml(yaml, sizeof yaml, p, link, p->retries, map);
		p->host_started = true;
		if (ah_start(&p->host, yaml, maps_of(p->maps_doc), SIM_SCALE, &err)) {
			fprintf(stderr, "sim: %s\n", err.msg);
			return -1;
		}
		p->port = simarm_port(p->host.svc[0]);
	} else {
		if (!have_python_peer()) {
			printf("skip: pymodbus or serial_asyncio missing for " PY " (make deps installs python3-pymodbus)\n");
			return 1;
		}
		p->speed = 200;
		p->accel = 2000;
		p->init_theta = 0;
		p->init_phi = 0;
		if (py_start(p, 0))
			return -1;
	}
	if (peer_load_cfg(p, map, &err)) {
		fprintf(stderr, "driver config: %s\n", err.msg);
		return -1;
	}
	return 0;
}

static inline void peer_stop(struct peer *p)
{
	if (p->kind == PEER_SIM && p->host_started)
		ah_stop(&p->host);
	p->host_started = false;
	for (int i = 0; i < p->ncfg; i++)
		axis_cfg_free(p->cfg[i]);
	p->ncfg = 0;
	yc_free(p->doc);
	yc_free(p->maps_doc);
	p->doc = p->maps_doc = NULL;
	ah_kill(&p->py);
	ah_kill(&p->pty.pid);
	ah_rmrf(p->dir);
	free(p->dir);
	p->dir = NULL;
}

/* A raw libmodbus client to the peer (not the driver): to observe what the driver did or did not send. */
static inline modbus_t *raw_client(const struct peer *p, int unit)
{
	modbus_t *c = p->rtu ? modbus_new_rtu(p->pty.a, 115200, 'N', 8, 1) : modbus_new_tcp("127.0.0.1", p->port);
	if (!c)
		return NULL;
	modbus_set_response_timeout(c, 1, 0);
	modbus_set_slave(c, unit);
	if (modbus_connect(c)) {
		modbus_free(c);
		return NULL;
	}
	return c;
}

/* Move triggers the peer received on axis i. */
static inline int peer_triggers(struct peer *p, int axis)
{
	if (p->kind == PEER_SIM) {
		ah_lock(&p->host);
		int n = simarm_moves(p->host.svc[0], axis);
		ah_unlock(&p->host);
		return n;
	}
	modbus_t *c = raw_client(p, axis + 1);
	uint16_t v = 0xFFFF;
	assert_non_null(c);
	assert_int_equal(modbus_read_registers(c, 0x402, 1, &v), 1);
	modbus_close(c);
	modbus_free(c);
	return v;
}

/* The next n moves of axis i end 0.5° past their target. */
static inline void peer_land_off(struct peer *p, int axis, int n)
{
	if (p->kind == PEER_SIM) {
		ah_lock(&p->host);
		struct simmot *m = simarm_motion(p->host.svc[0], axis);
		m->bias_moves = n;
		m->bias_deg = 0.5;
		ah_unlock(&p->host);
		return;
	}
	modbus_t *c = raw_client(p, axis + 1);
	assert_non_null(c);
	assert_int_equal(modbus_write_register(c, 0x401, (uint16_t)n), 1);
	modbus_close(c);
	modbus_free(c);
}

/* Make the peer unreachable / reachable again. */
static inline void peer_drop(struct peer *p)
{
	if (p->kind == PEER_SIM) {
		ah_lock(&p->host);
		if (p->rtu)
			p->host.w.faults.modbus_timeout[SIM_ARM_DETECTOR] = true;
		else
			p->host.w.faults.drop_connection[SIM_ARM_DETECTOR] = true;
		ah_unlock(&p->host);
		/* TCP: the simulator clears the flag once it has closed the connection; wait for that */
		double limit = ah_mono() + 10;
		bool pending = !p->rtu;
		while (pending && ah_mono() < limit) {
			ah_sleep(0.002);
			ah_lock(&p->host);
			pending = p->host.w.faults.drop_connection[SIM_ARM_DETECTOR];
			ah_unlock(&p->host);
		}
		assert_false(pending);
	} else {
		ah_kill(&p->py);
	}
}

static inline void peer_restore(struct peer *p)
{
	if (p->kind == PEER_SIM) {
		ah_lock(&p->host);
		p->host.w.faults.modbus_timeout[SIM_ARM_DETECTOR] = false;
		ah_unlock(&p->host);
	} else {
		assert_int_equal(py_start(p, p->port), 0);
		if (p->rtu)
			p->init_theta = p->init_phi = 0;
	}
}

static inline struct axis *open_axis(struct peer *p, int i)
{
	struct axis *ax = NULL;
	struct acq_err err = { 0 };
	/* RTU peers start without a readiness signal: the first status read may time out once. */
	if (axis_open(p->cfg[i], &ax, &err)) {
		fprintf(stderr, "%s: open: %s\n", p->label, err.msg);
		fail();
	}
	struct axis_status st;
	double limit = ah_mono() + 20;
	while (axis_read_status(ax, &st, &err) && ah_mono() < limit)
		ah_sleep(0.01);
	return ax;
}

static inline int move_to(struct peer *p, struct axis *ax, double target, struct acq_err *err)
{
	if (axis_move_begin(ax, target, peer_clock(p), err))
		return AXIS_MOVE_FAILED;
	return ah_wait_move(ax, peer_clock, p, peer_scale(p), err);
}

/* Start (bench s) and duration of the simulator's last motion profile of axis i. */
static inline void sim_last_profile(struct peer *p, int axis, double *start, double *dur)
{
	ah_lock(&p->host);
	const struct simmot *m = simarm_motion(p->host.svc[0], axis);
	*start = m->t0;
	*dur = m->ta + m->tc + m->td;
	ah_unlock(&p->host);
}

/* Each test owns a heap peer in *state; the teardown stops it even when an assertion failed. */
static inline struct peer *new_peer(void **state)
{
	struct peer *p = calloc(1, sizeof *p);
	assert_non_null(p);
	*state = p;
	return p;
}

static inline int peer_teardown(void **state)
{
	struct peer *p = *state;
	if (p) {
		peer_stop(p);
		free(p);
	}
	*state = NULL;
	return 0;
}

static inline void start_sim(struct peer *p, bool rtu)
{
	p->kind = PEER_SIM;
	p->rtu = rtu;
	p->label = "sim";
	int rc = peer_start(p, "oriental_az");
	if (rc == 1)
		skip();
	assert_int_equal(rc, 0);
}

#endif
