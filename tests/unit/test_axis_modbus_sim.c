/* Tests of the Modbus axis driver (drivers/axis_modbus.c) against the simulator's faults (stall, alarm half
 * way, timeout, collision), its backlash compensation and azimuth wrap, and the Leadshine-like register map
 * (peers: tests/unit/axis_peer.h; the common suite and bad input: test_axis_modbus.c). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "tests/unit/axis_peer.h"

static void test_sim_stall_times_out(void **state)
{
	struct peer *pp = new_peer(state);
	/* the deadline's margin: 1 s real, not peer_t() (10 s of waiting): a stalled move fails whatever the load,
	 * and what is measured is the deadline itself */
	pp->margin_real_s = 1.0;
	start_sim(pp, false);
	struct axis *ax = open_axis(pp, 0);
	struct acq_err err = { 0 };
	struct axis_status st;
	ah_lock(&pp->host);
	pp->host.w.faults.stall[SIM_ARM_DETECTOR] = true;
	ah_unlock(&pp->host);
	double t0 = peer_clock(pp);
	EXPECT(move_to(pp, ax, 30, &err), AXIS_MOVE_FAILED);
	double dt = peer_clock(pp) - t0;
	double expect = axis_trapezoid_s(30, 20, 60, 60) * 1.5 + move_margin_s(pp); /* factor × trapezoid + margin */
	printf("stall: failed after %.2f s bench (deadline %.2f s): %s\n", dt, expect, err.msg);
	assert_int_equal(err.code, ACQ_E_TIMEOUT);
	/* not before the deadline; after it, within the real-time slack of a loaded machine (see peer_t(): bench
	 * seconds are SIM_SCALE× shorter than real ones) */
	assert_true(dt >= expect && (dt - expect) / SIM_SCALE < peer_t());
	ah_lock(&pp->host);
	assert_false(pp->host.w.faults.stall[SIM_ARM_DETECTOR]); /* consumed */
	ah_unlock(&pp->host);
	/* the driver sent a stop: the controller is no longer busy, short of the target */
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_false(st.busy);
	assert_true(fabs(st.position_deg - (60 - 0.6 * 30)) < 0.05);
	axis_close(ax);
}

/* A move's status is read at its predicted end, not every poll_s from its start (session 14): a 28° move of the
 * detector's zenith (60° to 88°, 1.73 s bench) reads the status at most ceil(T / watch_s) + 6 times (the watch
 * reads, the end, the settle's confirmation, a backlash leg, a re-read if the controller is behind); measured 6.
 * Polled every poll_s (0.02 s here) from the start it read 76 times: the test failed. At every step the next read
 * is at most watch_s ahead: an alarm, a stall or a move that never ends is seen within watch_s of bench time
 * (test_sim_alarm_mid_move, test_sim_stall_times_out). */
static void test_sim_polls_at_end(void **state)
{
	struct peer *pp = new_peer(state);
	start_sim(pp, false);
	struct axis *ax = open_axis(pp, 0);
	struct acq_err err = { 0 };
	const double watch = 0.5; /* drivers/axis_modbus_cfg.c's watch_s default: the peers' configurations leave it */
	double T = axis_trapezoid_s(28, 20, 60, 60);
	EXPECT(axis_move_begin(ax, 88, peer_clock(pp), &err), 0);
	int polls = 0, rc = AXIS_MOVE_RUNNING;
	double limit = ah_mono() + 4 * peer_t();
	while (rc == AXIS_MOVE_RUNNING && ah_mono() < limit) {
		double now = peer_clock(pp);
		if (now >= axis_next_poll(ax))
			polls++; /* the driver reads the status at this step (axis.h: next_poll) */
		rc = axis_move_step(ax, now, &err);
		if (rc != AXIS_MOVE_RUNNING)
			break;
		assert_true(axis_next_poll(ax) - now <= watch + 1e-9);
		double dt = (axis_next_poll(ax) - peer_clock(pp)) / peer_scale(pp);
		ah_sleep(dt < 0.001 ? 0.001 : dt);
	}
	EXPECT(rc, AXIS_MOVE_DONE);
	printf("a %.2f s move: %d status reads\n", T, polls);
	assert_true(polls >= 1 && polls <= (int)ceil(T / watch) + 6);
	axis_close(ax);
}

static void test_sim_alarm_mid_move(void **state)
{
	struct peer *pp = new_peer(state);
	start_sim(pp, false);
	struct axis *ax = open_axis(pp, 0);
	struct acq_err err = { 0 };
	ah_lock(&pp->host);
	pp->host.w.faults.alarm_mid_move[SIM_ARM_DETECTOR] = true;
	ah_unlock(&pp->host);
	EXPECT(move_to(pp, ax, 80, &err), AXIS_MOVE_FAILED);
	assert_int_equal(err.code, ACQ_E_DEVICE);
	assert_int_equal(err.detail, 0x30);
	struct axis_status st;
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(st.alarm);
	assert_true(fabs(st.position_deg - 70) < 0.05); /* half way from 60 to 80 */
	EXPECT(axis_alarm_reset(ax, &err), 0);
	EXPECT(move_to(pp, ax, 80, &err), AXIS_MOVE_DONE);
	axis_close(ax);
}

static void test_sim_timeout_fault(void **state)
{
	struct peer *pp = new_peer(state);
	pp->resp_ms = 300; /* this test measures the response timeout itself */
	start_sim(pp, false);
	struct axis *ax = open_axis(pp, 0);
	struct acq_err err = { 0 };
	struct axis_status st;
	ah_lock(&pp->host);
	pp->host.w.faults.modbus_timeout[SIM_ARM_DETECTOR] = true;
	ah_unlock(&pp->host);
	double t0 = ah_mono();
	EXPECT(axis_read_status(ax, &st, &err), -1);
	double dt = ah_mono() - t0;
	assert_int_equal(err.code, ACQ_E_TIMEOUT);
	assert_true(dt >= 0.29 && dt < 0.3 + peer_t()); /* one response timeout (300 ms) + a loaded machine's slack */
	ah_lock(&pp->host);
	pp->host.w.faults.modbus_timeout[SIM_ARM_DETECTOR] = false;
	ah_unlock(&pp->host);
	/* the link was kept: the next transaction works (a late answer would have been flushed) */
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(fabs(st.position_deg - 60) < 0.011);
	axis_close(ax);
}

static void test_sim_collision(void **state)
{
	struct peer *pp = new_peer(state);
	start_sim(pp, false);
	struct axis *ax = open_axis(pp, 0);
	struct acq_err err = { 0 };
	/* laser arm at θL = 0: the detector reaches it when θD < 6° + 5° */
	EXPECT(move_to(pp, ax, 5, &err), AXIS_MOVE_FAILED);
	assert_int_equal(err.code, ACQ_E_DEVICE);
	assert_int_equal(err.detail, 0xE0);
	ah_lock(&pp->host);
	assert_true(pp->host.w.collision);
	double th = pp->host.w.detector_theta_deg;
	double sep = simmot_arm_separation(pp->host.w.laser_theta_deg, 0, th, pp->host.w.detector_phi_deg);
	ah_unlock(&pp->host);
	assert_true(sep < 11.0 && sep > 10.9); /* stopped within one 0.05° step of contact */
	/* after a reset the arm can move away, and the collision clears */
	EXPECT(axis_alarm_reset(ax, &err), 0);
	EXPECT(move_to(pp, ax, 30, &err), AXIS_MOVE_DONE);
	ah_lock(&pp->host);
	assert_false(pp->host.w.collision);
	ah_unlock(&pp->host);
	axis_close(ax);
}

static void test_sim_backlash_compensation(void **state)
{
	/* backlash 0.5° in the simulator's mechanics; the driver approaches from below by 0.6° */
	struct peer *pp = new_peer(state);
	pp->kind = PEER_SIM;
	struct armhost *hp = &pp->host;
	struct acq_err err = { 0 };
	struct yc_doc *maps = pp->maps_doc = load_file("config/bench-sim.yaml");
	assert_non_null(maps);
	const char *sim_yaml =
		"bench:\n  detector_theta: {noise_deg: 0, backlash_deg: 0.5}\n"
		"devices:\n  detector_arm:\n    link: {type: tcp, port: 0}\n    axes:\n"
		"      theta: {unit: 1, map: oriental_az, soft_max_deg: 89}\n";
	pp->host_started = true;
	assert_int_equal(ah_start(hp, sim_yaml, maps_of(maps), SIM_SCALE, &err), 0);
	char yaml[1024];
	snprintf(yaml, sizeof yaml,
		 "link: {type: tcp, port: %d}\naxes:\n  theta: {unit: 1, map: oriental_az, soft_max_deg: 89, "
		 "backlash_deg: 0.6, speed_dps: 20, accel_dps2: 60, poll_s: 0.02}\n", simarm_port(hp->svc[0]));
	struct yc_doc *doc = NULL;
	assert_int_equal(yc_load_string("d.yaml", yaml, strlen(yaml), &doc, &err), 0);
	struct axis_cfg *cfg[2];
	int n = 0;
	EXPECT(axis_arm_parse(yc_root(doc), maps_of(maps), "detector_arm", cfg, 2, &n, &err), 0);
	struct axis *ax = NULL;
	EXPECT(axis_open(cfg[0], &ax, &err), 0);
	/* approach 40° from above (60 → 40) and from below (20 → 40): the load ends at the same place */
	double load[2];
	const double from[2] = { 60, 20 };
	for (int i = 0; i < 2; i++) {
		EXPECT(axis_move_begin(ax, from[i], ah_now(hp), &err), 0);
		EXPECT(ah_wait_move(ax, peer_clock, pp, SIM_SCALE, &err), AXIS_MOVE_DONE);
		EXPECT(axis_move_begin(ax, 40, ah_now(hp), &err), 0);
		EXPECT(ah_wait_move(ax, peer_clock, pp, SIM_SCALE, &err), AXIS_MOVE_DONE);
		ah_lock(hp);
		load[i] = hp->w.detector_theta_deg;
		ah_unlock(hp);
	}
	printf("backlash: load after approach from above %.4f, from below %.4f\n", load[0], load[1]);
	assert_true(fabs(load[0] - load[1]) < 1e-6);
	assert_true(fabs(load[0] - (40 - 0.25)) < 1e-6); /* taken up on the positive side: motor - b/2 */
	axis_close(ax);
	axis_cfg_free(cfg[0]);
	yc_free(doc);
}

/* wrap_deg: the azimuth takes the equivalent angle nearest to where it is, inside the soft limits. */
static void test_sim_wrap(void **state)
{
	struct peer *pp = new_peer(state);
	pp->kind = PEER_SIM;
	struct acq_err err = { 0 };
	struct yc_doc *maps = pp->maps_doc = load_file("config/bench-sim.yaml");
	assert_non_null(maps);
	const char *sim_yaml = "bench:\n  detector_phi: {noise_deg: 0, backlash_deg: 0}\n"
			       "devices:\n  detector_arm:\n    link: {type: tcp, port: 0}\n    axes:\n"
			       "      phi: {unit: 2, map: oriental_az, soft_min_deg: -179, soft_max_deg: 359}\n";
	pp->host_started = true;
	assert_int_equal(ah_start(&pp->host, sim_yaml, maps_of(maps), SIM_SCALE, &err), 0);
	char yaml[1024];
	snprintf(yaml, sizeof yaml,
		 "link: {type: tcp, port: %d}\naxes:\n  phi: {unit: 2, map: oriental_az, soft_min_deg: -179, "
		 "soft_max_deg: 359, wrap_deg: 360, speed_dps: 30, accel_dps2: 90, poll_s: 0.02}\n",
		 simarm_port(pp->host.svc[0]));
	assert_int_equal(yc_load_string("d.yaml", yaml, strlen(yaml), &pp->doc, &err), 0);
	EXPECT(axis_arm_parse(yc_root(pp->doc), maps_of(maps), "detector_arm", pp->cfg, 2, &pp->ncfg, &err), 0);
	struct axis *ax = open_axis(pp, 0);
	struct axis_status st;
	/* from 180: -20 is commanded as 340 (160° away instead of 200°) */
	EXPECT(move_to(pp, ax, -20, &err), AXIS_MOVE_DONE);
	assert_true(axis_target(ax) == 340);
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(fabs(st.position_deg - 340) <= 0.01);
	/* from 340: 10 would be 370, outside the soft limits: it goes the long way to 10 */
	EXPECT(move_to(pp, ax, 10, &err), AXIS_MOVE_DONE);
	assert_true(axis_target(ax) == 10);
	/* 725 ≡ 5 */
	EXPECT(move_to(pp, ax, 725, &err), AXIS_MOVE_DONE);
	assert_true(axis_target(ax) == 5);
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(fabs(st.position_deg - 5) <= 0.01);
	axis_close(ax);
}

/* The Leadshine-like map (single writes, pulse-style trigger register) against the same simulator. */
static void test_leadshine_map_on_sim(void **state)
{
	struct peer *pp = new_peer(state);
	pp->kind = PEER_SIM;
	pp->label = "sim/leadshine";
	assert_int_equal(peer_start(pp, "leadshine_like"), 0);
	struct axis *ax = open_axis(pp, 0);
	struct acq_err err = { 0 };
	struct axis_status st;
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(fabs(st.position_deg - 60) < 0.01);
	EXPECT(move_to(pp, ax, 33.3, &err), AXIS_MOVE_DONE);
	EXPECT(axis_read_status(ax, &st, &err), 0);
	assert_true(fabs(st.position_deg - 33.3) <= 0.02);
	EXPECT(move_to(pp, ax, 95, &err), AXIS_MOVE_FAILED);
	assert_int_equal(err.code, ACQ_E_DEVICE);
	EXPECT(axis_alarm_reset(ax, &err), 0);
	EXPECT(move_to(pp, ax, 50, &err), AXIS_MOVE_DONE);
	struct axis_identity id;
	EXPECT(axis_identity(ax, &id, &err), 0);
	assert_string_equal(id.vendor, "Leadshine");
	axis_close(ax);
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	printf("test_axis_modbus_sim: seed %llu\n", ah_seed());
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_teardown(test_sim_stall_times_out, peer_teardown),
		cmocka_unit_test_teardown(test_sim_polls_at_end, peer_teardown),
		cmocka_unit_test_teardown(test_sim_alarm_mid_move, peer_teardown),
		cmocka_unit_test_teardown(test_sim_timeout_fault, peer_teardown),
		cmocka_unit_test_teardown(test_sim_collision, peer_teardown),
		cmocka_unit_test_teardown(test_sim_backlash_compensation, peer_teardown),
		cmocka_unit_test_teardown(test_sim_wrap, peer_teardown),
		cmocka_unit_test_teardown(test_leadshine_map_on_sim, peer_teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
