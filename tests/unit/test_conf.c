/* Unit tests for daemon/conf.c: defaults, every section's located errors, unknown keys, --sim overrides,
 * device sections whose driver is missing (a note, not an error), and the shipped example files. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/conf.h"

static char path[] = "/tmp/test_conf.XXXXXX";
static int fdp = -1;

static int load(const char *text, const struct conf_sim *sim, struct conf **c, struct acq_err *err)
{
	if (fdp < 0)
		fdp = mkstemp(path);
	FILE *f = fopen(path, "w");
	fputs(text, f);
	fclose(f);
	*c = NULL;
	acq_err_clear(err);
	return conf_load(path, sim, c, err);
}

static void expect_error(const char *text, const char *where, const char *what)
{
	struct conf *c;
	struct acq_err err = { 0 };
	assert_int_equal(load(text, NULL, &c, &err), -1);
	assert_null(c);
	char loc[300];
	snprintf(loc, sizeof loc, "%s:%s", path, where);
	if (!strstr(err.msg, loc) || !strstr(err.msg, what))
		fail_msg("for %s: got \"%s\", expected \"%s\" and \"%s\"", text, err.msg, loc, what);
}

static void test_defaults_and_values(void **state)
{
	(void)state;
	struct conf *c;
	struct acq_err err = { 0 };
	assert_int_equal(load("daemon:\n  state_dir: /tmp/x\n", NULL, &c, &err), 0);
	assert_string_equal(c->d.database, "/tmp/x/acquisition.db");
	assert_int_equal(c->d.socket_mode, 0660);
	assert_int_equal(c->sweep.averages, 1);
	assert_true(c->d.observer_rate == CONF_OBSERVER_RATE && c->d.observer_burst == CONF_OBSERVER_BURST);
	assert_true(c->d.plan_cpu_s == CONF_PLAN_CPU_S && c->d.plan_deadline_s == CONF_PLAN_DEADLINE_S);
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		assert_true(c->devnote[d][0] != 0);
	conf_free(c);
	assert_int_equal(load("daemon:\n  state_dir: /srv/acq\n  database: /data/a.db\n"
			      "  socket: {path: /run/a.sock, mode: \"0600\"}\n  tcp_port: 4711\n"
			      "  controllers: [alice, \"@ops\"]\n  observers: [bob]\n  log_level: debug\n"
			      "  observer_rate: 0\n  observer_burst: 5\n  plan_cpu_s: 2\n  plan_deadline_s: 7.5\n"
			      "sweep: {averages: 8, dark_every: 5, auto_recon: false}\n"
			      "recon: {program: /opt/brdf-recon, threads: 4, output_dir: out, extra_args: [--fast]}\n"
			      "sim: {anything: [goes, here]}\n",
			      NULL, &c, &err), 0);
	assert_string_equal(c->d.database, "/data/a.db");
	assert_string_equal(c->d.socket_path, "/run/a.sock");
	assert_int_equal(c->d.socket_mode, 0600);
	assert_int_equal(c->d.tcp_port, 4711);
	assert_int_equal(c->d.ncontrollers, 2);
	assert_string_equal(c->d.controllers[1], "@ops");
	assert_int_equal(c->d.nobservers, 1);
	assert_true(c->d.observer_rate == 0 && c->d.observer_burst == 5);
	assert_true(c->d.plan_cpu_s == 2 && c->d.plan_deadline_s == 7.5);
	assert_int_equal(c->sweep.averages, 8);
	assert_false(c->sweep.auto_recon);
	assert_string_equal(c->recon.output_dir, "/srv/acq/out");
	assert_int_equal(c->recon.nextra, 1);
	conf_free(c);
}

static void test_located_errors(void **state)
{
	(void)state;
	expect_error("daemon:\n  colour: red\n", "2:3", "colour");
	expect_error("daemon:\n  state_dir: relative/dir\n", "2:14", "absolute path");
	expect_error("daemon:\n  socket: {mode: \"0999\"}\n", "2:18", "octal mode");
	expect_error("daemon:\n  socket: {mode: \"0066\"}\n", "2:18", "owner read-write");
	expect_error("daemon:\n  tcp_port: 70000\n", "2:13", "65535");
	expect_error("daemon:\n  controllers: alice\n", "2:16", "sequence");
	expect_error("daemon:\n  log_level: loud\n", "2:14", "debug");
	expect_error("daemon:\n  observer_rate: -1\n", "2:18", "observer_rate");
	expect_error("daemon:\n  observer_burst: 0.5\n", "2:19", "observer_burst");
	expect_error("daemon:\n  plan_cpu_s: 0\n", "2:15", "plan_cpu_s");
	expect_error("daemon:\n  plan_deadline_s: 1.5e9\n", "2:20", "plan_deadline_s");
	expect_error("daemon:\n  database: ../escape.db\n", "2:13", "database");
	expect_error("sweep:\n  averages: 0\n", "2:13", "averages");
	expect_error("sweep:\n  min_integration_ms: 50\n  max_integration_ms: 10\n", "2:23", "max_integration_ms");
	expect_error("recon:\n  output_dir: /abs\n", "2:15", "relative");
	expect_error("recon:\n  extra_args: [[1]]\n", "2:16", "string");
	expect_error("bench:\n  laser_radius_mm: -3\n", "2:20", "laser_radius_mm");
	expect_error("devices:\n  toaster: {}\n", "2:3", "toaster");
	expect_error("devices:\n  laser_arm: {axes: {zeta: {}}}\n", "2:22", "zeta");
	expect_error("devices:\n  spectrometer: {backend: ccd}\n", "2:27", "backend");
	expect_error("daemon: {}\nextra_section: 1\n", "2:1", "extra_section");
	expect_error("sim: 3\n", "1:6", "sim");
	expect_error("- a list\n", "1:1", "mapping");
	/* home.park: each value within the soft limits, all three present, the pose clear of collision and blind zones */
	expect_error("home:\n  park: {laser.theta: 95, detector.theta: 30, detector.phi: 180}\n", "2:23",
		     "home.park.laser.theta (soft limits): 95 is outside [-5, 90]");
	expect_error("home:\n  park: {laser.theta: 30, detector.theta: 30}\n", "2:9", "home.park: detector.phi missing");
	expect_error("home:\n  park: {laser.theta: 30, detector.theta: 30, detector.phi: 0}\n", "2:9",
		     "home.park: the pose (30°, 30°, 0°) is a collision");
	/* (the shipped geometry's beam zone lies inside the collision cone: a wider beam puts one outside it) */
	expect_error("bench:\n  beam_halfwidth_deg: 10\nhome:\n  park: {laser.theta: 30, detector.theta: 16, detector.phi: 0}\n",
		     "4:9", "in a blind zone: beam-occluded");
	expect_error("home:\n  park: {laser.theta: 30, detector.theta: 30, detector.phi: 180, x: 1}\n", "2:", "x");
	expect_error("home:\n  parking: {}\n", "2:3", "parking");
}

static void test_sim_overrides(void **state)
{
	(void)state;
	char pj[] = "/tmp/test_conf_ports.XXXXXX";
	int fd = mkstemp(pj);
	assert_true(fd >= 0);
	const char *ports = "{\"laser_arm\": {\"port\": 1502}, \"detector_arm\": {\"port\": 1503},"
			    " \"laser\": {\"device\": \"/dev/pts/7\"}, \"spectrometer\": {\"socket\": \"/tmp/s.sock\"},"
			    " \"control\": {\"socket\": \"/tmp/c.sock\"}}";
	assert_int_equal(write(fd, ports, strlen(ports)), (ssize_t)strlen(ports));
	close(fd);
	struct conf_sim sim;
	struct acq_err err = { 0 };
	assert_int_equal(conf_sim_read(pj, &sim, &err), 0);
	assert_int_equal(sim.laser_arm_port, 1502);
	assert_int_equal(sim.detector_arm_port, 1503);
	assert_string_equal(sim.laser_device, "/dev/pts/7");
	assert_string_equal(sim.spectro_socket, "/tmp/s.sock");
	assert_string_equal(sim.control_socket, "/tmp/c.sock");
	assert_true(sim.time_scale == 1);
	struct conf *c;
	assert_int_equal(load("devices:\n  laser_arm: {link: {host: 10.0.0.5, port: 502}}\n  spectrometer: {backend: sim}\n",
			      &sim, &c, &err), 0);
	assert_true(c->have_sim);
	/* The overrides are spliced into the device tree the drivers parse. */
	conf_free(c);
	FILE *f = fopen(pj, "w");
	fputs("{\"laser_arm\": {\"port\": \"x\"}}", f);
	fclose(f);
	assert_int_equal(conf_sim_read(pj, &sim, &err), -1);
	assert_non_null(strstr(err.msg, "laser_arm"));
	f = fopen(pj, "w");
	fputs("{\"time_scale\": 25, \"laser_arm\": {\"port\": 9}}", f);
	fclose(f);
	assert_int_equal(conf_sim_read(pj, &sim, &err), 0);
	assert_true(sim.time_scale == 25 && sim.laser_arm_port == 9 && sim.detector_arm_port == 0);
	f = fopen(pj, "w");
	fputs("{\"time_scale\": 0}", f);
	fclose(f);
	assert_int_equal(conf_sim_read(pj, &sim, &err), -1);
	assert_non_null(strstr(err.msg, "time_scale"));
	f = fopen(pj, "w");
	fputs("{\"laser_arm\": ", f);
	fclose(f);
	assert_int_equal(conf_sim_read(pj, &sim, &err), -1);
	assert_non_null(strstr(err.msg, pj));
	unlink(pj);
}

static void test_examples_valid(void **state)
{
	(void)state;
	const char *src = getenv("ACQ_SRC");
	char p[1024];
	const char *files[] = { "config/bench-sim.yaml", "config/bench-real.yaml" };
	for (int i = 0; i < 2; i++) {
		snprintf(p, sizeof p, "%s/%s", src ? src : ".", files[i]);
		struct conf *c = NULL;
		struct acq_err err = { 0 };
		if (conf_load(p, NULL, &c, &err))
			fail_msg("%s: %s", p, err.msg);
		conf_free(c);
	}
}

/* home.park against the controller's soft limits: bench-sim.yaml's bench allows laser.theta up to 90°, its
 * laser_arm controller only to 88°: a park at 89° is refused naming the key, the file and the line. */
static void test_park_soft_limits(void **state)
{
	(void)state;
	const char *src = getenv("ACQ_SRC");
	char p[1024];
	snprintf(p, sizeof p, "%s/config/bench-sim.yaml", src ? src : ".");
	FILE *f = fopen(p, "r");
	assert_non_null(f);
	static char text[1 << 16];
	size_t n = fread(text, 1, sizeof text - 1, f);
	fclose(f);
	text[n] = 0;
	char *at = strstr(text, "park: {laser.theta: 30,");
	assert_non_null(at);
	memcpy(at + strlen("park: {laser.theta: "), "89", 2);
	int line = 1;
	for (const char *q = text; q < at; q++)
		line += *q == '\n';
	struct conf *c;
	struct acq_err err = { 0 };
	assert_int_equal(load(text, NULL, &c, &err), -1);
	char want[300];
	snprintf(want, sizeof want, "%s:%d:", path, line);
	if (!strstr(err.msg, want) || !strstr(err.msg, "home.park.laser.theta (soft limits): 89 is outside [-3, 88]"))
		fail_msg("got \"%s\", expected \"%s\" and the soft limits [-3, 88]", err.msg, want);
}

static int cleanup(void **state)
{
	(void)state;
	unlink(path);
	return 0;
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_defaults_and_values),
		cmocka_unit_test(test_located_errors),
		cmocka_unit_test(test_sim_overrides),
		cmocka_unit_test(test_examples_valid),
		cmocka_unit_test(test_park_soft_limits),
	};
	return cmocka_run_group_tests(tests, NULL, cleanup);
}
