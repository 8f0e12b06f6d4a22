/* Tests of the Modbus axis driver (drivers/axis_modbus.c): ONE suite (status, identity, moves, shared link,
 * soft limits, hard-limit alarm and reset, retries, homing, reconnect) run against four peers: our simulated
 * controller (sim/sim_arm.c) and an independent pymodbus server (tests/integration/az_peer.py), each over TCP
 * and over RTU on a socat pty pair (tests/unit/axis_peer.h); then bad input (dead links, exception replies,
 * malformed frames). The simulator's faults and the Leadshine-like map: test_axis_modbus_sim.c. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "tests/unit/axis_peer.h"

/* ---- the suite ----------------------------------------------------------------------------------------- */

static void s_status_identity(struct peer *p)
{
	struct axis *ax = open_axis(p, 0);
	struct axis_status st;
	struct axis_identity id;
	struct acq_err err = { 0 };
	assert_true(axis_connected(ax));
	assert_string_equal(axis_name(ax), "detector.theta");
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_false(st.alarm);
	assert_false(st.busy);
	assert_true(st.ready);
	assert_true(fabs(st.position_deg - p->init_theta) < 0.011);
	EXPECT(axis_identity(ax, &id, &err), 0);
	assert_string_equal(id.vendor, "Oriental Motor");
	assert_true(id.serial[0] != 0);
	axis_close(ax);
}

static void s_moves(struct peer *p)
{
	struct axis *ax = open_axis(p, 0);
	struct acq_err err = { 0 };
	struct axis_status st;
	const double targets[] = { 30.0, 45.5, 25.25, 70.0 };
	double from = p->init_theta;
	for (size_t i = 0; i < sizeof targets / sizeof targets[0]; i++) {
		double t0 = peer_clock(p);
		int rc = move_to(p, ax, targets[i], &err);
		double dt = peer_clock(p) - t0;
		if (rc != AXIS_MOVE_DONE)
			fprintf(stderr, "%s: %s\n", p->label, err.msg);
		assert_int_equal(rc, AXIS_MOVE_DONE);
		EXPECT(axis_read_status(ax, &st, &err), 0);
		assert_true(fabs(st.position_deg - targets[i]) <= 0.02 + 1e-9);
		assert_false(st.busy);
		/* duration: at least the constant-speed bound; the simulator follows the trapezoid */
		double dist = fabs(targets[i] - from);
		assert_true(dt >= 0.9 * dist / p->speed);
		if (p->kind == PEER_SIM) {
			/* The simulator's profile (bench time, analytic, so independent of load) must be the
			 * trapezoid the driver commanded; the driver must not report the move done before that
			 * profile ends; what the driver adds on top (delivery, polling, settle) must stay within
			 * peer_t() of real time (see there). */
			double T = axis_trapezoid_s(dist, p->speed, p->accel, p->accel);
			double s0, sdur;
			sim_last_profile(p, 0, &s0, &sdur);
			double extra_real = (dt - sdur) / SIM_SCALE;
			printf("%s: move %.2f° took %.3f s bench; sim profile %.3f s (trapezoid %.3f s); driver "
			       "overhead %.1f ms real\n", p->label, dist, dt, sdur, T, extra_real * 1e3);
			assert_true(fabs(sdur - T) <= 1e-6 * (1 + T)); /* closed forms of the same profile */
			assert_true(s0 >= t0);                         /* the profile began after the command */
			assert_true(t0 + dt >= s0 + sdur);            /* done only after the profile's end */
			assert_true(extra_real <= peer_t());
		}
		from = targets[i];
	}
	axis_close(ax);
}

static void s_shared_link(struct peer *p)
{
	struct axis *th = open_axis(p, 0), *ph = NULL;
	struct acq_err err = { 0 };
	EXPECT(axis_open_shared(p->cfg[1], th, &ph, &err), 0);
	double now = peer_clock(p);
	EXPECT(axis_move_begin(th, 40, now, &err), 0);
	EXPECT(axis_move_begin(ph, 90, now, &err), 0);
	int a = AXIS_MOVE_RUNNING, b = AXIS_MOVE_RUNNING;
	double limit = ah_mono() + 20;
	while ((a == AXIS_MOVE_RUNNING || b == AXIS_MOVE_RUNNING) && ah_mono() < limit) {
		now = peer_clock(p);
		if (a == AXIS_MOVE_RUNNING)
			a = axis_move_step(th, now, &err);
		if (b == AXIS_MOVE_RUNNING)
			b = axis_move_step(ph, now, &err);
		ah_sleep(0.005);
	}
	assert_int_equal(a, AXIS_MOVE_DONE);
	assert_int_equal(b, AXIS_MOVE_DONE);
	struct axis_status st;
	EXPECT(axis_read_status(th, &st, &err), 0);
	assert_true(fabs(st.position_deg - 40) <= 0.02);
	EXPECT(axis_read_status(ph, &st, &err), 0);
	assert_true(fabs(st.position_deg - 90) <= 0.02);
	axis_close(ph);
	axis_close(th);
}

static void s_soft_limits(struct peer *p)
{
	struct axis *ax = open_axis(p, 0);
	struct acq_err err = { 0 };
	int before = peer_triggers(p, 0);
	EXPECT(axis_move_begin(ax, 100.5, peer_clock(p), &err), -1);
	assert_int_equal(err.code, ACQ_E_RANGE);
	assert_non_null(strstr(err.msg, "detector.theta"));
	assert_non_null(strstr(err.msg, "soft limits"));
	EXPECT(axis_move_begin(ax, -3.5, peer_clock(p), &err), -1);
	EXPECT(axis_move_begin(ax, NAN, peer_clock(p), &err), -1);
	assert_int_equal(err.code, ACQ_E_RANGE);
	assert_int_equal(peer_triggers(p, 0), before); /* nothing reached the controller */
	axis_close(ax);
}

static void s_hard_limit_alarm(struct peer *p)
{
	struct axis *ax = open_axis(p, 0);
	struct acq_err err = { 0 };
	struct axis_status st;
	/* soft limit 100 lies beyond the hard limit at 90: the controller alarms (hardware overtravel) */
	EXPECT(move_to(p, ax, 95, &err), AXIS_MOVE_FAILED);
	assert_int_equal(err.code, ACQ_E_DEVICE);
	assert_int_equal(err.detail, 0x66);
	assert_non_null(strstr(err.msg, "alarm"));
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(st.alarm);
	assert_int_equal(st.alarm_code, 0x66);
	assert_true(fabs(st.position_deg - 90) < 0.02);
	bool lp, ln, stall;
	EXPECT(axis_read_bits(ax, &lp, &ln, &stall, &err), 0);
	assert_true(lp);
	assert_false(ln);
	/* refused while in alarm, with a clear message */
	EXPECT(axis_move_begin(ax, 45, peer_clock(p), &err), -1);
	assert_int_equal(err.code, ACQ_E_DEVICE);
	assert_non_null(strstr(err.msg, "reset"));
	EXPECT(axis_alarm_reset(ax, &err), 0);
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_false(st.alarm);
	EXPECT(move_to(p, ax, 45, &err), AXIS_MOVE_DONE);
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(fabs(st.position_deg - 45) <= 0.02);
	axis_close(ax);
}

static void s_retries(struct peer *p)
{
	struct axis *ax = open_axis(p, 0);
	struct acq_err err = { 0 };
	struct axis_status st;
	/* the first landing is 0.5° off: one retry fixes it */
	int before = peer_triggers(p, 0);
	peer_land_off(p, 0, 1);
	EXPECT(move_to(p, ax, 35, &err), AXIS_MOVE_DONE);
	assert_int_equal(axis_move_retries_used(ax), 1);
	assert_int_equal(peer_triggers(p, 0) - before, 2);
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(fabs(st.position_deg - 35) <= 0.02);
	/* always off: the retries (3) run out, with a message that says so */
	before = peer_triggers(p, 0);
	peer_land_off(p, 0, 100);
	EXPECT(move_to(p, ax, 30, &err), AXIS_MOVE_FAILED);
	assert_int_equal(err.code, ACQ_E_RANGE);
	assert_non_null(strstr(err.msg, "after 3 retries"));
	assert_int_equal(peer_triggers(p, 0) - before, 4);
	peer_land_off(p, 0, 0);
	axis_close(ax);
}

static void s_home(struct peer *p)
{
	struct axis *ax = open_axis(p, 1); /* phi: homing theta to 0 would hit the laser arm in the simulator */
	struct acq_err err = { 0 };
	struct axis_status st;
	EXPECT(move_to(p, ax, 20, &err), AXIS_MOVE_DONE);
	EXPECT(axis_home_begin(ax, peer_clock(p), &err), 0);
	EXPECT(ah_wait_move(ax, peer_clock, p, peer_scale(p), &err), AXIS_MOVE_DONE);
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(st.homed);
	assert_true(fabs(st.position_deg) < 0.011);
	axis_close(ax);
}

/* The response timeout of the dead-link step: a dead RTU peer is only noticed when it runs out, and the suite's
 * peer_t() (10 s) made each RTU suite wait that long (two of test_axis_modbus's 47 s). The reads of the reconnect
 * loop may run out under load too: the loop retries them; the move after it uses the suite's timeout again. */
#define RECONNECT_RESP_MS 1500

static void s_reconnect(struct peer *p)
{
	struct acq_err err = { 0 };
	int suite_ms = p->resp_ms;
	p->resp_ms = RECONNECT_RESP_MS;
	EXPECT(peer_load_cfg(p, "oriental_az", &err), 0);
	struct axis *ax = open_axis(p, 0);
	struct axis_status st;
	peer_drop(p);
	double t0 = ah_mono();
	EXPECT(axis_read_status(ax, &st, &err), -1);
	double dt = ah_mono() - t0;
	printf("%s: dead link reported in %.3f s: %s\n", p->label, dt, err.msg);
	assert_true(err.code == ACQ_E_DISCONNECTED || err.code == ACQ_E_TIMEOUT);
	assert_non_null(strstr(err.msg, "detector.theta"));
	/* at most one response timeout + byte timeout, with peer_t() of slack for a loaded machine */
	assert_true(dt < peer_resp_ms(p) / 1000.0 + peer_t());
	/* while it is down, a reconnect attempt fails within one response timeout or succeeds at once */
	peer_restore(p);
	int attempt = 0;
	bool ok = false;
	double limit = ah_mono() + 15;
	while (ah_mono() < limit) {
		t0 = ah_mono();
		if (axis_reconnect(ax, &err) == 0 && axis_read_status(ax, &st, &err) == 0) {
			ok = true;
			break;
		}
		assert_true(ah_mono() - t0 < peer_resp_ms(p) / 1000.0 + peer_t());
		ah_sleep(axis_backoff_s(attempt++));
	}
	assert_true(ok);
	assert_true(axis_connected(ax));
	assert_false(st.alarm);
	axis_close(ax);
	p->resp_ms = suite_ms;
	EXPECT(peer_load_cfg(p, "oriental_az", &err), 0);
	ax = open_axis(p, 0);
	EXPECT(move_to(p, ax, st.position_deg + 5, &err), AXIS_MOVE_DONE);
	axis_close(ax);
}

static void run_suite(void **state, int kind, bool rtu, const char *label)
{
	struct peer *p = new_peer(state);
	p->kind = kind;
	p->rtu = rtu;
	p->label = label;
	int rc = peer_start(p, "oriental_az");
	if (rc == 1)
		skip();
	assert_int_equal(rc, 0);
	printf("[ %s ] seed %llu\n", label, ah_seed());
	s_status_identity(p);
	s_moves(p);
	s_shared_link(p);
	s_soft_limits(p);
	s_hard_limit_alarm(p);
	s_retries(p);
	s_home(p);
	s_reconnect(p);
}

static void test_suite_sim_tcp(void **state) { run_suite(state, PEER_SIM, false, "sim/tcp"); }
static void test_suite_sim_rtu(void **state) { run_suite(state, PEER_SIM, true, "sim/rtu"); }
static void test_suite_pymodbus_tcp(void **state) { run_suite(state, PEER_PY, false, "pymodbus/tcp"); }
static void test_suite_pymodbus_rtu(void **state) { run_suite(state, PEER_PY, true, "pymodbus/rtu"); }

/* ---- bad input ------------------------------------------------------------------------------------------ */

static void test_dead_links(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct yc_doc *maps = load_file("config/bench-sim.yaml");
	assert_non_null(maps);
	/* a port nobody listens on: bind one, close it */
	int s = socket(AF_INET, SOCK_STREAM, 0);
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	socklen_t sl = sizeof sa;
	assert_int_equal(bind(s, (struct sockaddr *)&sa, sizeof sa), 0);
	assert_int_equal(getsockname(s, (struct sockaddr *)&sa, &sl), 0);
	int port = ntohs(sa.sin_port);
	close(s);
	char yaml[512];
	snprintf(yaml, sizeof yaml, "link: {type: tcp, port: %d}\naxes:\n  theta: {unit: 1, map: oriental_az}\n", port);
	struct yc_doc *doc = NULL;
	struct axis_cfg *cfg[2];
	int n;
	assert_int_equal(yc_load_string("d.yaml", yaml, strlen(yaml), &doc, &err), 0);
	EXPECT(axis_arm_parse(yc_root(doc), maps_of(maps), "laser_arm", cfg, 2, &n, &err), 0);
	struct axis *ax = NULL;
	double t0 = ah_mono();
	EXPECT(axis_open(cfg[0], &ax, &err), -1);
	assert_true(ah_mono() - t0 < 1.0);
	assert_int_equal(err.code, ACQ_E_DISCONNECTED);
	char where[64];
	snprintf(where, sizeof where, "127.0.0.1:%d", port);
	assert_non_null(strstr(err.msg, where));
	assert_non_null(strstr(err.msg, "laser.theta"));
	axis_cfg_free(cfg[0]);
	yc_free(doc);
	/* a serial device that does not exist */
	const char *y2 = "link: {type: rtu, device: /nonexistent/ttyX}\naxes:\n  theta: {unit: 1, map: oriental_az}\n";
	assert_int_equal(yc_load_string("d.yaml", y2, strlen(y2), &doc, &err), 0);
	EXPECT(axis_arm_parse(yc_root(doc), maps_of(maps), "laser_arm", cfg, 2, &n, &err), 0);
	EXPECT(axis_open(cfg[0], &ax, &err), -1);
	assert_non_null(strstr(err.msg, "/nonexistent/ttyX"));
	axis_cfg_free(cfg[0]);
	yc_free(doc);
	yc_free(maps);
}

/* A hostile TCP "controller": answers each request with the next canned frame (or nothing). */
struct evil {
	int lfd, port;
	pthread_t th;
	int mode;
};

static void *evil_loop(void *p)
{
	struct evil *e = p;
	int c = accept(e->lfd, NULL, NULL);
	if (c < 0)
		return NULL;
	uint8_t req[260];
	for (;;) {
		ssize_t n = recv(c, req, sizeof req, 0);
		if (n < 8)
			break;
		uint8_t rsp[260];
		size_t len = 0;
		memcpy(rsp, req, 4); /* transaction + protocol id */
		switch (e->mode) {
		case 0: /* exception: illegal data address */
			rsp[4] = 0; rsp[5] = 3; rsp[6] = req[6]; rsp[7] = (uint8_t)(req[7] | 0x80); rsp[8] = 2; len = 9;
			break;
		case 1: /* MBAP length says 7 but the frame is cut short, then the peer closes */
			rsp[4] = 0; rsp[5] = 7; rsp[6] = req[6]; rsp[7] = req[7]; rsp[8] = 4; len = 9;
			break;
		case 2: /* wrong byte count: one register instead of the two asked */
			rsp[4] = 0; rsp[5] = 5; rsp[6] = req[6]; rsp[7] = req[7]; rsp[8] = 2; rsp[9] = 0; rsp[10] = 1;
			len = 11;
			break;
		case 3: /* wrong function code in the answer */
			rsp[4] = 0; rsp[5] = 5; rsp[6] = req[6]; rsp[7] = 0x11; rsp[8] = 2; rsp[9] = 0; rsp[10] = 1;
			len = 11;
			break;
		case 4: /* wrong transaction id */
			rsp[0] ^= 0x55;
			rsp[4] = 0; rsp[5] = 5; rsp[6] = req[6]; rsp[7] = req[7]; rsp[8] = 2; rsp[9] = 0; rsp[10] = 1;
			len = 11;
			break;
		}
		if (send(c, rsp, len, MSG_NOSIGNAL) < 0 || e->mode == 1)
			break;
	}
	close(c);
	return NULL;
}

static void test_bad_replies(void **state)
{
	(void)state;
	struct yc_doc *maps = load_file("config/bench-sim.yaml");
	assert_non_null(maps);
	static const int expect[] = { ACQ_E_DEVICE, -1, ACQ_E_PROTO, ACQ_E_PROTO, ACQ_E_PROTO };
	for (int mode = 0; mode < 5; mode++) {
		struct evil e = { .mode = mode };
		e.lfd = socket(AF_INET, SOCK_STREAM, 0);
		struct sockaddr_in sa = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
		socklen_t sl = sizeof sa;
		assert_int_equal(bind(e.lfd, (struct sockaddr *)&sa, sizeof sa), 0);
		assert_int_equal(listen(e.lfd, 1), 0);
		assert_int_equal(getsockname(e.lfd, (struct sockaddr *)&sa, &sl), 0);
		e.port = ntohs(sa.sin_port);
		assert_int_equal(pthread_create(&e.th, NULL, evil_loop, &e), 0);
		char yaml[512];
		snprintf(yaml, sizeof yaml, "link: {type: tcp, port: %d, response_timeout_ms: 2000}\naxes:\n"
			 "  theta: {unit: 1, map: oriental_az}\n", e.port);
		struct yc_doc *doc = NULL;
		struct axis_cfg *cfg[2];
		int n;
		struct acq_err err = { 0 };
		assert_int_equal(yc_load_string("d.yaml", yaml, strlen(yaml), &doc, &err), 0);
		EXPECT(axis_arm_parse(yc_root(doc), maps_of(maps), "laser_arm", cfg, 2, &n, &err), 0);
		struct axis *ax = NULL;
		EXPECT(axis_open(cfg[0], &ax, &err), 0);
		struct axis_status st;
		EXPECT(axis_read_status(ax, &st, &err), -1);
		printf("bad reply %d: %s: %s\n", mode, acq_errname(err.code), err.msg);
		if (expect[mode] >= 0)
			assert_int_equal(err.code, expect[mode]);
		else
			assert_true(err.code == ACQ_E_TIMEOUT || err.code == ACQ_E_DISCONNECTED ||
				    err.code == ACQ_E_PROTO);
		assert_non_null(strstr(err.msg, "laser.theta"));
		/* a move after a bad reply fails cleanly too */
		EXPECT(axis_move_begin(ax, 10, 0, &err), -1);
		axis_close(ax);
		shutdown(e.lfd, SHUT_RDWR);
		close(e.lfd);
		pthread_join(e.th, NULL);
		axis_cfg_free(cfg[0]);
		yc_free(doc);
	}
	yc_free(maps);
}

static void test_trapezoid_and_backoff(void **state)
{
	(void)state;
	/* long move: accel + cruise + decel; short move: triangle with peak speed sqrt(d·a) */
	double v = 20, a = 60;
	double d_full = v * v / a; /* distance of the ramps */
	assert_true(fabs(axis_trapezoid_s(30, v, a, a) - (30 / v + v / a)) < 1e-12);
	assert_true(fabs(axis_trapezoid_s(-30, v, a, a) - (30 / v + v / a)) < 1e-12);
	assert_true(fabs(axis_trapezoid_s(d_full / 4, v, a, a) - 2 * sqrt(d_full / 4 / a)) < 1e-12);
	assert_true(axis_trapezoid_s(0, v, a, a) == 0);
	double prev = 0;
	for (int i = 0; i < 20; i++) {
		double b = axis_backoff_s(i);
		assert_true(b >= prev && b <= 5.0);
		prev = b;
	}
	assert_true(axis_backoff_s(0) == 0.1 && axis_backoff_s(100) == 5.0);
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	printf("test_axis_modbus: seed %llu\n", ah_seed());
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_trapezoid_and_backoff),
		cmocka_unit_test_teardown(test_suite_sim_tcp, peer_teardown),
		cmocka_unit_test_teardown(test_suite_sim_rtu, peer_teardown),
		cmocka_unit_test_teardown(test_suite_pymodbus_tcp, peer_teardown),
		cmocka_unit_test_teardown(test_suite_pymodbus_rtu, peer_teardown),
		cmocka_unit_test(test_dead_links),
		cmocka_unit_test(test_bad_replies),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
