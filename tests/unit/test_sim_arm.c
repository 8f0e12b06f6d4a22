/* Tests of the simulated arm controllers (sim/sim_arm.c) with clients we did not write: Debian's mbpoll
 * reads the position registers and commands a move whose effect the position registers then show, over
 * TCP and over RTU on a socat pty pair; raw libmodbus clients check several clients at once, exception
 * replies, the ports-file description, dropped connections, and a collision caused by the laser arm. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <modbus.h>

#include "tests/unit/armhost.h"

#define SCALE 20.0
#define MBPOLL "/usr/bin/mbpoll"

struct fix {
	struct armhost h;
	bool started;
	struct yc_doc *maps;
	struct ah_pty pty;
	char *dir;
};

static const char *arms_yaml(char *buf, size_t len, const char *laser_link, const char *det_link)
{
	snprintf(buf, len,
		 "bench:\n"
		 "  laser_theta: {min_deg: -60, max_deg: 90, noise_deg: 0, backlash_deg: 0}\n"
		 "  detector_theta: {noise_deg: 0, backlash_deg: 0}\n"
		 "  detector_phi: {noise_deg: 0, backlash_deg: 0}\n"
		 "devices:\n"
		 "  laser_arm:\n"
		 "    link: %s\n"
		 "    axes: {theta: {unit: 1, map: oriental_az, soft_min_deg: -58, soft_max_deg: 88}}\n"
		 "  detector_arm:\n"
		 "    link: %s\n"
		 "    axes:\n"
		 "      theta: {unit: 1, map: oriental_az, soft_min_deg: -3, soft_max_deg: 88}\n"
		 "      phi: {unit: 2, map: oriental_az, soft_min_deg: -179, soft_max_deg: 359}\n",
		 laser_link, det_link);
	return buf;
}

static int fix_teardown(void **state)
{
	struct fix *f = *state;
	if (!f)
		return 0;
	if (f->started)
		ah_stop(&f->h);
	yc_free(f->maps);
	ah_kill(&f->pty.pid);
	ah_rmrf(f->dir);
	free(f->dir);
	free(f);
	*state = NULL;
	return 0;
}

static struct fix *fix_start(void **state, bool rtu)
{
	struct fix *f = calloc(1, sizeof *f);
	assert_non_null(f);
	*state = f;
	char path[512], yaml[2048], det[512];
	snprintf(path, sizeof path, "%s/config/bench-sim.yaml", ah_src());
	struct acq_err err = { 0 };
	assert_int_equal(yc_load_file(path, &f->maps, &err), 0);
	f->dir = strdup(ah_mkdtemp());
	if (rtu) {
		if (access("/usr/bin/socat", X_OK) != 0) {
			printf("skip: socat is not installed (make deps installs it)\n");
			skip();
		}
		assert_int_equal(ah_pty_start(&f->pty, f->dir), 0); /* socat there: its pty pair must come up */
		snprintf(det, sizeof det, "{type: rtu, device: %s, baud: 115200}", f->pty.b);
	} else {
		snprintf(det, sizeof det, "{type: tcp, port: 0}");
	}
	arms_yaml(yaml, sizeof yaml, "{type: tcp, port: 0}", det);
	f->started = true;
	if (ah_start(&f->h, yaml, yc_get(yc_get(yc_root(f->maps), "devices"), "register_maps"), SCALE, &err))
		fail_msg("%s", err.msg);
	return f;
}

/* Run mbpoll with args (NULL-terminated, after the binary); its stdout into out. Exit status. mbpoll's own
 * response timeout (1 s by default) is raised to ACQ_PEER_TIMEOUT_S (default 5 s): over socat's ptys on a
 * machine whose cores are busy, an answer can take longer than a second; a dead simulator still fails. */
static int mbpoll(char *out, size_t len, const char *const *args)
{
	char cmd[1024] = MBPOLL;
	const char *t = getenv("ACQ_PEER_TIMEOUT_S");
	strncat(cmd, " -o ", sizeof cmd - strlen(cmd) - 1);
	strncat(cmd, t && *t ? t : "5", sizeof cmd - strlen(cmd) - 1);
	for (int i = 0; args[i]; i++) {
		strncat(cmd, " ", sizeof cmd - strlen(cmd) - 1);
		strncat(cmd, args[i], sizeof cmd - strlen(cmd) - 1);
	}
	strncat(cmd, " 2>&1", sizeof cmd - strlen(cmd) - 1);
	FILE *p = popen(cmd, "r");
	if (!p)
		return -1;
	size_t n = fread(out, 1, len - 1, p);
	out[n] = 0;
	int st = pclose(p);
	int rc = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
	if (rc != 0)
		printf("mbpoll exit %d: %s\n%s\n", rc, cmd, out);
	return rc;
}

/* The value mbpoll printed for reference ref ("[204]: \t1000"). */
static bool mbpoll_value(const char *out, int ref, long *v)
{
	char key[32];
	snprintf(key, sizeof key, "[%d]:", ref);
	const char *p = strstr(out, key);
	return p && sscanf(p + strlen(key), "%ld", v) == 1;
}

static double world_pos(struct fix *f, double *where)
{
	ah_lock(&f->h);
	double v = *where;
	ah_unlock(&f->h);
	return v;
}

/* Read the detector theta position (0xCC, int32 big-endian) with mbpoll; move it with one FC16 block
 * (0x58: op data, op type 1, target, speed, accel, decel, current, trigger 1); read until it shows. */
static void mbpoll_read_move(struct fix *f, const char *const *link)
{
	char out[4096], port[16];
	long v;
	const char *conn[16];
	int nc = 0;
	for (int i = 0; link[i] && nc < 16; i++)
		conn[nc++] = link[i];
	snprintf(port, sizeof port, "%d", simarm_port(f->h.svc[1]));
	for (int i = 0; i < nc; i++)
		if (!strcmp(conn[i], "@PORT"))
			conn[i] = port;
	/* read: mbpoll -a 1 -0 -r 204 -t 4:int -B -c 1 -1 <conn...> */
	const char *rd[24] = { "-a", "1", "-0", "-r", "204", "-t", "4:int", "-B", "-c", "1", "-1" };
	int n = 11;
	for (int i = 0; i < nc; i++)
		rd[n++] = conn[i];
	rd[n] = NULL;
	assert_int_equal(mbpoll(out, sizeof out, rd), 0);
	assert_true(mbpoll_value(out, 204, &v));
	double before = world_pos(f, &f->h.w.detector_theta_deg);
	assert_int_equal(v, lround(before * 100));
	/* move to 42.37° at 20°/s */
	const char *wr[40] = { "-a", "1", "-0", "-r", "88", "-t", "4:int", "-B" };
	n = 8;
	for (int i = 0; i < nc; i++)
		wr[n++] = conn[i];
	const char *vals[] = { "0", "1", "4237", "2000", "6000", "6000", "1000", "1" };
	for (int i = 0; i < 8; i++)
		wr[n++] = vals[i];
	wr[n] = NULL;
	assert_int_equal(mbpoll(out, sizeof out, wr), 0);
	assert_non_null(strstr(out, "Written 8 references"));
	double limit = ah_mono() + 10;
	bool seen = false, moving_seen = false;
	while (ah_mono() < limit) {
		if (mbpoll(out, sizeof out, rd) == 0 && mbpoll_value(out, 204, &v)) {
			if (v != 4237 && v != lround(before * 100))
				moving_seen = true; /* an intermediate position: the profile is visible */
			if (v == 4237) {
				seen = true;
				break;
			}
		}
		ah_sleep(0.02);
	}
	assert_true(seen);
	printf("mbpoll saw the move end at 42.37 (intermediate positions seen: %s)\n", moving_seen ? "yes" : "no");
	assert_true(fabs(world_pos(f, &f->h.w.detector_theta_deg) - 42.37) < 1e-9);
	/* the status word (0x7F) says ready + in position (bits 5, 14), no alarm (bit 7) */
	const char *st[24] = { "-a", "1", "-0", "-r", "127", "-t", "4", "-c", "1", "-1" };
	n = 10;
	for (int i = 0; i < nc; i++)
		st[n++] = conn[i];
	st[n] = NULL;
	assert_int_equal(mbpoll(out, sizeof out, st), 0);
	assert_true(mbpoll_value(out, 127, &v));
	assert_true(v & (1 << 5));
	assert_true(v & (1 << 14));
	assert_false(v & (1 << 7));
}

static void test_mbpoll_tcp(void **state)
{
	if (access(MBPOLL, X_OK) != 0) {
		printf("skip: " MBPOLL " is not installed (make deps installs mbpoll)\n");
		skip();
	}
	struct fix *f = fix_start(state, false);
	const char *link[] = { "-m", "tcp", "-p", "@PORT", "127.0.0.1", NULL };
	mbpoll_read_move(f, link);
}

static void test_mbpoll_rtu(void **state)
{
	if (access(MBPOLL, X_OK) != 0) {
		printf("skip: " MBPOLL " is not installed (make deps installs mbpoll)\n");
		skip();
	}
	struct fix *f = fix_start(state, true);
	const char *link[] = { "-m", "rtu", "-b", "115200", "-P", "none", "-d", "8", "-s", "1", f->pty.a, NULL };
	mbpoll_read_move(f, link);
	/* unit 2 (phi) on the same bus answers too */
	char out[4096];
	long v;
	const char *rd[] = { "-m", "rtu", "-b", "115200", "-P", "none", "-a", "2", "-0", "-r", "204", "-t", "4:int",
			     "-B", "-c", "1", "-1", f->pty.a, NULL };
	assert_int_equal(mbpoll(out, sizeof out, rd), 0);
	assert_true(mbpoll_value(out, 204, &v));
	assert_int_equal(v, lround(world_pos(f, &f->h.w.detector_phi_deg) * 100));
}

static modbus_t *client(int port, int unit)
{
	modbus_t *c = modbus_new_tcp("127.0.0.1", port);
	assert_non_null(c);
	modbus_set_slave(c, unit);
	modbus_set_response_timeout(c, 1, 0);
	assert_int_equal(modbus_connect(c), 0);
	return c;
}

static void test_many_clients_and_exceptions(void **state)
{
	struct fix *f = fix_start(state, false);
	int port = simarm_port(f->h.svc[1]);
	modbus_t *c[6];
	for (int i = 0; i < 6; i++)
		c[i] = client(port, 1 + i % 2);
	for (int round = 0; round < 5; round++)
		for (int i = 0; i < 6; i++) {
			uint16_t r[2];
			assert_int_equal(modbus_read_registers(c[i], 0xCC, 2, r), 2);
			double expect = i % 2 ? f->h.w.detector_phi_deg : f->h.w.detector_theta_deg;
			assert_int_equal((int32_t)((uint32_t)r[0] << 16 | r[1]), lround(expect * 100));
		}
	/* a register outside the map: illegal data address; an unknown unit: gateway target failed */
	uint16_t r[4];
	assert_int_equal(modbus_read_registers(c[0], 0x0500, 1, r), -1);
	assert_int_equal(errno, EMBXILADD);
	assert_int_equal(modbus_read_registers(c[0], 0x007E, 2, r), -1); /* 0x7E is not in this map */
	assert_int_equal(errno, EMBXILADD);
	assert_int_equal(modbus_read_input_registers(c[0], 0xCC, 2, r), -1);
	assert_int_equal(errno, EMBXILADD);
	modbus_set_slave(c[0], 9);
	assert_int_equal(modbus_read_registers(c[0], 0xCC, 2, r), -1);
	assert_int_equal(errno, EMBXGTAR);
	/* the ports-file description names the arm and its port */
	char buf[128], want[64];
	f->h.svc[1]->describe(f->h.svc[1]->self, buf, sizeof buf);
	snprintf(want, sizeof want, "\"detector_arm\": {\"port\": %d}", port);
	assert_string_equal(buf, want);
	/* drop_connection closes every client once; new connections work */
	ah_lock(&f->h);
	f->h.w.faults.drop_connection[SIM_ARM_DETECTOR] = true;
	ah_unlock(&f->h);
	ah_sleep(0.05);
	assert_int_equal(modbus_read_registers(c[1], 0xCC, 2, r), -1);
	assert_false(f->h.w.faults.drop_connection[SIM_ARM_DETECTOR]);
	modbus_t *again = client(port, 1);
	assert_int_equal(modbus_read_registers(again, 0xCC, 2, r), 2);
	modbus_close(again);
	modbus_free(again);
	for (int i = 0; i < 6; i++) {
		modbus_close(c[i]);
		modbus_free(c[i]);
	}
}

static void az_move(modbus_t *c, double deg)
{
	int32_t t = (int32_t)lround(deg * 100);
	uint16_t blk[16] = { 0, 0, 0, 1, (uint16_t)((uint32_t)t >> 16), (uint16_t)t, 0, 2000, 0, 6000, 0, 6000,
			     0, 1000, 0, 1 };
	assert_int_equal(modbus_write_registers(c, 0x58, 16, blk), 16);
}

static void test_collision_by_laser_arm(void **state)
{
	struct fix *f = fix_start(state, false);
	modbus_t *laser = client(simarm_port(f->h.svc[0]), 1);
	/* detector at (60°, 180°); the laser swings to θL = -55° (azimuth 180°): 5° apart < 6° + 5° */
	az_move(laser, -55);
	double limit = ah_mono() + 10;
	uint16_t st = 0;
	while (ah_mono() < limit) {
		assert_int_equal(modbus_read_registers(laser, 0x7F, 1, &st), 1);
		if (!(st & (1 << 8)))
			break;
		ah_sleep(0.01);
	}
	assert_true(st & (1 << 7)); /* alarm */
	uint16_t code[2];
	assert_int_equal(modbus_read_registers(laser, 0x80, 2, code), 2);
	assert_int_equal(code[1], 0xE0);
	ah_lock(&f->h);
	bool coll = f->h.w.collision;
	double th = f->h.w.laser_theta_deg;
	int det_alarm = simarm_alarm(f->h.svc[1], 0), det_phi_alarm = simarm_alarm(f->h.svc[1], 1);
	double sep = simmot_arm_separation(th, 0, f->h.w.detector_theta_deg, f->h.w.detector_phi_deg);
	ah_unlock(&f->h);
	assert_true(coll);
	assert_int_equal(det_alarm, 0xE0); /* both controllers stop and raise the alarm */
	assert_int_equal(det_phi_alarm, 0xE0);
	printf("collision: laser stopped at %.3f°, separation %.3f° (limit 11°)\n", th, sep);
	assert_true(sep < 11.0 && sep > 10.9); /* stopped within one 0.05° step of contact */
	/* a move while in alarm is ignored; after ALM-RST (level bit, cleared by us) the arm moves away */
	az_move(laser, 0);
	ah_sleep(0.05);
	ah_lock(&f->h);
	assert_true(fabs(f->h.w.laser_theta_deg - th) < 1e-9);
	ah_unlock(&f->h);
	assert_int_equal(modbus_write_register(laser, 0x7D, 0x80), 1);
	assert_int_equal(modbus_write_register(laser, 0x7D, 0), 1);
	az_move(laser, 0);
	limit = ah_mono() + 10;
	while (ah_mono() < limit && fabs(world_pos(f, &f->h.w.laser_theta_deg)) > 1e-9)
		ah_sleep(0.01);
	assert_true(fabs(world_pos(f, &f->h.w.laser_theta_deg)) < 1e-9);
	ah_lock(&f->h);
	assert_false(f->h.w.collision);
	ah_unlock(&f->h);
	modbus_close(laser);
	modbus_free(laser);
}

static void test_controller_soft_limit_and_op_type(void **state)
{
	struct fix *f = fix_start(state, false);
	modbus_t *c = client(simarm_port(f->h.svc[1]), 1);
	/* outside the soft limits (the same limits the driver checks; a raw client bypasses the driver) */
	az_move(c, 89);
	uint16_t code[2];
	assert_int_equal(modbus_read_registers(c, 0x80, 2, code), 2);
	assert_int_equal(code[1], 0x67);
	assert_int_equal(modbus_write_register(c, 0x7D, 0x80), 1);
	assert_int_equal(modbus_write_register(c, 0x7D, 0), 1);
	assert_int_equal(modbus_read_registers(c, 0x80, 2, code), 2);
	assert_int_equal(code[1], 0);
	/* an operation type the simulator does not support */
	uint16_t blk[16] = { 0, 0, 0, 16, 0, 3000, 0, 2000, 0, 6000, 0, 6000, 0, 1000, 0, 1 };
	assert_int_equal(modbus_write_registers(c, 0x58, 16, blk), 16);
	assert_int_equal(modbus_read_registers(c, 0x80, 2, code), 2);
	assert_int_equal(code[1], 0x70);
	modbus_close(c);
	modbus_free(c);
}

static void test_bad_config(void **state)
{
	(void)state;
	struct sim_world w = { .scale = 1 };
	bench_defaults(&w.geom);
	struct acq_err err = { 0 };
	const char *y = "arm:\n  link: {type: tcp, port: 0}\n  axes: {roll: {unit: 1, map: m}}\nmaps:\n  m:\n"
			"    fields: {target: {addr: 0}, actual: {addr: 2}, status: {addr: 4}}\n"
			"    status_bits: {busy: 0, alarm: 1}\n"
			"    commands: {start: {addr: 6, value: 1}, stop: {addr: 6, value: 2}}\n";
	struct yc_doc *doc = NULL;
	assert_int_equal(yc_load_string("s.yaml", y, strlen(y), &doc, &err), 0);
	struct yc_node *root = yc_root(doc);
	assert_null(sim_arm_new(&w, SIM_ARM_LASER, yc_get(root, "arm"), yc_get(root, "maps"), NULL, &err));
	assert_non_null(strstr(err.msg, "roll"));
	assert_null(sim_arm_new(&w, SIM_ARM_LASER, NULL, yc_get(root, "maps"), NULL, &err));
	assert_non_null(strstr(err.msg, "laser_arm"));
	yc_free(doc);
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	printf("test_sim_arm: seed %llu\n", ah_seed());
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_teardown(test_mbpoll_tcp, fix_teardown),
		cmocka_unit_test_teardown(test_mbpoll_rtu, fix_teardown),
		cmocka_unit_test_teardown(test_many_clients_and_exceptions, fix_teardown),
		cmocka_unit_test_teardown(test_collision_by_laser_arm, fix_teardown),
		cmocka_unit_test_teardown(test_controller_soft_limit_and_op_type, fix_teardown),
		cmocka_unit_test(test_bad_config),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
