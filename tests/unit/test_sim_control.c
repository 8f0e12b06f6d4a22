/* Unit tests of sim/sim_control.c's fault schedule, driven by tick() at chosen bench times: scheduled faults
 * fire at their time and clear after their duration; the random schedule is a seeded Poisson process of the
 * configured rate and kinds (same seed, same faults); configuration errors are located. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "sim/sim.h"

static struct sim_service *make(struct sim_world *w, const char *yaml, struct yc_doc **doc, char *dir,
				 struct acq_err *err)
{
	char path[128];
	snprintf(dir, 64, "/tmp/acq-test-ctl.XXXXXX");
	assert_non_null(mkdtemp(dir));
	snprintf(path, sizeof path, "%s/ctl.sock", dir);
	assert_int_equal(yc_load_string("t.yaml", yaml, strlen(yaml), doc, err), 0);
	return sim_control_new(w, yc_root(*doc), path, err);
}

static void done(struct sim_service *s, struct yc_doc *doc, char *dir)
{
	if (s) {
		s->destroy(s->self); /* frees the service too */
	}
	yc_free(doc);
	rmdir(dir);
}

static void test_schedule(void **state)
{
	(void)state;
	struct sim_world w = { .scale = 1, .seed = 3 };
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	char dir[64];
	struct sim_service *s = make(&w,
				     "faults:\n  schedule:\n"
				     "    - {at: 1, fault: modbus-timeout, arm: detector, duration: 2}\n"
				     "    - {at: 5, fault: spectro-disconnect, offline_s: 3}\n"
				     "    - {at: 6, fault: saturation-burst, count: 4}\n"
				     "    - {at: 7, fault: stall, arm: laser_arm}\n",
				     &doc, dir, &err);
	if (!s)
		fail_msg("%s", err.msg);
	s->tick(s->self, 0.5);
	assert_false(w.faults.modbus_timeout[1]);
	s->tick(s->self, 1.0);
	assert_true(w.faults.modbus_timeout[1]);
	assert_false(w.faults.modbus_timeout[0]);
	s->tick(s->self, 2.9);
	assert_true(w.faults.modbus_timeout[1]);
	s->tick(s->self, 3.1);
	assert_false(w.faults.modbus_timeout[1]);
	s->tick(s->self, 5.2);
	assert_true(w.faults.spectro_disconnect);
	assert_true(fabs(w.spectro_offline_until - 8.2) < 1e-9);
	s->tick(s->self, 7.0);
	assert_int_equal(w.faults.saturation_burst, 4);
	assert_true(w.faults.stall[0] && !w.faults.stall[1]);
	char buf[256] = "";
	s->describe(s->self, buf, sizeof buf);
	assert_non_null(strstr(buf, "\"control\": {\"socket\": \""));
	done(s, doc, dir);
}

/* Count how often the random schedule raises stall / saturation-burst over 600 bench seconds. */
static int random_run(uint64_t seed, int *stalls, int *bursts)
{
	struct sim_world w = { .scale = 1, .seed = seed };
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	char dir[64];
	struct sim_service *s = make(&w, "faults:\n  random: {rate_per_min: 60, faults: [stall, saturation-burst]}\n", &doc,
				     dir, &err);
	if (!s)
		fail_msg("%s", err.msg);
	*stalls = *bursts = 0;
	for (int t = 1; t <= 6000; t++) {
		s->tick(s->self, t * 0.1);
		for (int a = 0; a < 2; a++)
			if (w.faults.stall[a]) {
				(*stalls)++;
				w.faults.stall[a] = false;
			}
		if (w.faults.saturation_burst) {
			(*bursts)++;
			w.faults.saturation_burst = 0;
		}
	}
	done(s, doc, dir);
	return *stalls + *bursts;
}

static void test_random_schedule(void **state)
{
	(void)state;
	const char *e = getenv("ACQ_SEED");
	uint64_t seed = e ? strtoull(e, NULL, 10) : 1;
	printf("ACQ_SEED=%llu\n", (unsigned long long)seed);
	int st, bu, st2, bu2;
	int n = random_run(seed, &st, &bu);
	printf("random faults at 60/min over 600 s: %d (stall %d, saturation-burst %d)\n", n, st, bu);
	assert_true(n > 500 && n < 700); /* Poisson mean 600, sigma 24.5: ±4 sigma (650 was only 2 sigma above) */
	assert_true(st > 150 && bu > 150);
	random_run(seed, &st2, &bu2);
	assert_true(st2 == st && bu2 == bu);
}

static void test_bad_schedule(void **state)
{
	(void)state;
	static const char *const bad[][2] = {
		{ "faults:\n  schedule:\n    - {at: 1, fault: stall}\n", "t.yaml:3" },
		{ "faults:\n  schedule:\n    - {at: -1, fault: laser-fault}\n", "t.yaml:3" },
		{ "faults:\n  schedule:\n    - {at: 1, fault: meteor}\n", "meteor" },
		{ "faults:\n  schedule:\n    - {at: 1, fault: stall, arm: left}\n", "left" },
		{ "faults:\n  schedule:\n    - {at: 1, fault: laser-fault, colour: red}\n", "colour" },
		{ "faults:\n  random: {faults: [stall]}\n", "rate_per_min" },
		{ "faults:\n  random: {rate_per_min: 1}\n", "faults" },
		{ "faults:\n  seed: -4\n", "t.yaml:2" },
		{ "faults:\n  sched: []\n", "sched" },
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		struct sim_world w = { .scale = 1 };
		struct yc_doc *doc = NULL;
		struct acq_err err = { 0 };
		char dir[64];
		struct sim_service *s = make(&w, bad[i][0], &doc, dir, &err);
		printf("%s", bad[i][0]);
		printf("  -> %s\n", err.msg);
		assert_null(s);
		assert_non_null(strstr(err.msg, bad[i][1]));
		done(NULL, doc, dir);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_schedule),
		cmocka_unit_test(test_random_schedule),
		cmocka_unit_test(test_bad_schedule),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
