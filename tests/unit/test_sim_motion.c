/* Tests of sim/sim_motion.c, the simulated axis kinematics: move durations against the closed-form
 * trapezoid/triangle (tolerance: one integration step, 1 ms), speed and acceleration bounds along the
 * profile, decelerating stops, hard limits, backlash play, positioning noise statistics and reproducibility,
 * scheduled halts, and the arm-separation geometry used for collisions. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "config/bench.h"
#include "sim/sim_motion.h"

#define DT 1e-3

static uint64_t seed = 1;

static struct bench_axis axis_k(double v, double a, double b, double noise)
{
	return (struct bench_axis){ .min_deg = -180, .max_deg = 360, .speed_dps = v, .accel_dps2 = a,
				    .backlash_deg = b, .noise_deg = noise };
}

/* Run a move to completion in DT steps; returns the time the DONE event came. */
static double run(struct simmot *m, double t, int *ev_out)
{
	int ev = SIMMOT_NONE;
	while (ev == SIMMOT_NONE && t < 1e4) {
		t += DT;
		ev = simmot_advance(m, t);
	}
	if (ev_out)
		*ev_out = ev;
	return t;
}

static void test_durations_match_trapezoid(void **state)
{
	(void)state;
	const double v[] = { 10, 20, 30 }, a[] = { 20, 60, 90 };
	for (int i = 0; i < 3; i++) {
		struct bench_axis k = axis_k(v[i], a[i], 0, 0);
		/* distances around the triangle/trapezoid boundary v²/a and far beyond */
		const double dists[] = { 0.01, 0.5 * v[i] * v[i] / a[i], v[i] * v[i] / a[i], 2 * v[i] * v[i] / a[i], 45,
					 170 };
		for (size_t j = 0; j < sizeof dists / sizeof dists[0]; j++) {
			double d = dists[j];
			double expect = d >= v[i] * v[i] / a[i] ? d / v[i] + v[i] / a[i] : 2 * sqrt(d / a[i]);
			assert_true(fabs(simmot_duration(d, 0, v[i], a[i], a[i]) - expect) < 1e-9);
			struct simmot m;
			simmot_init(&m, &k, 0, seed);
			simmot_start(&m, d, 0, 0, 0, 0);
			int ev;
			double t = run(&m, 0, &ev);
			assert_int_equal(ev, SIMMOT_DONE);
			assert_true(fabs(t - expect) <= DT + 1e-9);
			assert_true(fabs(m.motor - d) < 1e-9);
			/* a negative move takes as long */
			simmot_start(&m, 0, t, 0, 0, 0);
			double t2 = run(&m, t, &ev) - t;
			assert_true(fabs(t2 - expect) <= DT + 1e-9);
		}
	}
}

static void test_profile_bounds(void **state)
{
	(void)state;
	struct bench_axis k = axis_k(20, 60, 0, 0);
	struct simmot m;
	simmot_init(&m, &k, 10, seed);
	simmot_start(&m, 70, 0, 0, 0, 0);
	double prev_p = 10, prev_v = 0;
	for (double t = DT; m.moving; t += DT) {
		simmot_advance(&m, t);
		double vel = m.moving ? simmot_speed(&m, t) : 0;
		assert_true(m.motor >= prev_p - 1e-12);             /* monotonic */
		assert_true(fabs(vel) <= 20 + 1e-9);                 /* speed bound */
		assert_true(fabs(vel - prev_v) <= 60 * DT + 1e-6);   /* acceleration bound */
		prev_p = m.motor;
		prev_v = vel;
	}
	assert_true(fabs(m.motor - 70) < 1e-9);
	/* a commanded speed below the axis's maximum is honoured; above it is clipped */
	simmot_start(&m, 10, 0, 5, 0, 0);
	double t = run(&m, 0, NULL);
	assert_true(fabs(t - (60 / 5.0 + 5 / 60.0)) <= DT + 1e-9);
	simmot_start(&m, 70, 0, 500, 0, 0);
	t = run(&m, 0, NULL);
	assert_true(fabs(t - (60 / 20.0 + 20 / 60.0)) <= DT + 1e-9);
}

static void test_decelerating_stop(void **state)
{
	(void)state;
	struct bench_axis k = axis_k(20, 60, 0, 0);
	struct simmot m;
	simmot_init(&m, &k, 0, seed);
	simmot_start(&m, 100, 0, 0, 0, 0);
	double t = 0;
	for (; t < 2.0; t += DT) /* well into the cruise */
		simmot_advance(&m, t);
	double p_stop = m.motor, v = simmot_speed(&m, t);
	assert_true(fabs(v - 20) < 1e-9);
	simmot_stop(&m, t);
	int ev;
	double t_end = run(&m, t, &ev);
	assert_int_equal(ev, SIMMOT_DONE);
	assert_true(fabs(m.motor - (p_stop + v * v / (2 * 60))) < 1e-6); /* stopping distance v²/2a */
	assert_true(fabs((t_end - t) - v / 60) <= DT + 1e-9);
}

static void test_hard_limits(void **state)
{
	(void)state;
	struct bench_axis k = axis_k(20, 60, 0, 0);
	k.min_deg = -5;
	k.max_deg = 90;
	struct simmot m;
	simmot_init(&m, &k, 80, seed);
	simmot_start(&m, 95, 0, 0, 0, 0);
	int ev;
	run(&m, 0, &ev);
	assert_int_equal(ev, SIMMOT_LIMIT_POS);
	assert_true(m.motor == 90);
	assert_false(m.moving);
	simmot_start(&m, -10, 10, 0, 0, 0);
	run(&m, 10, &ev);
	assert_int_equal(ev, SIMMOT_LIMIT_NEG);
	assert_true(m.motor == -5);
}

static void test_backlash_play(void **state)
{
	(void)state;
	const double b = 0.3;
	struct bench_axis k = axis_k(20, 60, b, 0);
	struct simmot m;
	simmot_init(&m, &k, 0, seed);
	/* from below: the load trails the motor by b/2; from above: leads by b/2 */
	simmot_start(&m, 10, 0, 0, 0, 0);
	double t = run(&m, 0, NULL);
	assert_true(fabs(m.motor - 10) < 1e-12);
	double from_below = m.load;
	simmot_start(&m, 20, t, 0, 0, 0);
	t = run(&m, t, NULL);
	simmot_start(&m, 10, t, 0, 0, 0);
	t = run(&m, t, NULL);
	double from_above = m.load;
	assert_true(fabs(m.motor - 10) < 1e-12);
	assert_true(fabs((from_above - from_below) - b) < 1e-9);
	assert_true(fabs(from_below - (10 - b / 2)) < 1e-9);
	/* a reversal smaller than the play does not move the load */
	double before = m.load;
	simmot_start(&m, 10 + b / 2, t, 0, 0, 0);
	run(&m, t, NULL);
	assert_true(fabs(m.load - before) < 1e-9);
}

static void test_noise_statistics_and_seed(void **state)
{
	(void)state;
	const double sigma = 0.01;
	const int n = 2000;
	struct bench_axis k = axis_k(1000, 1e5, 0, sigma);
	struct simmot m, m2;
	simmot_init(&m, &k, 0, seed);
	simmot_init(&m2, &k, 0, seed);
	double sum = 0, sum2 = 0, t = 0, t2 = 0;
	for (int i = 0; i < n; i++) {
		double target = (i % 2) ? 10 : 20;
		simmot_start(&m, target, t, 0, 0, 0);
		t = run(&m, t, NULL);
		simmot_start(&m2, target, t2, 0, 0, 0);
		t2 = run(&m2, t2, NULL);
		assert_true(m.motor == m2.motor); /* same seed, same noise */
		double e = m.motor - target;
		sum += e;
		sum2 += e * e;
	}
	double mean = sum / n, sd = sqrt(sum2 / n - mean * mean);
	printf("noise: sigma %.4f configured, %.4f measured over %d moves, mean %.5f\n", sigma, sd, n, mean);
	assert_true(fabs(mean) < 4 * sigma / sqrt(n));
	assert_true(fabs(sd - sigma) < 0.1 * sigma);
	/* another seed gives another sequence */
	simmot_init(&m2, &k, 0, seed + 1);
	simmot_init(&m, &k, 0, seed);
	simmot_start(&m, 5, 0, 0, 0, 0);
	simmot_start(&m2, 5, 0, 0, 0, 0);
	run(&m, 0, NULL);
	run(&m2, 0, NULL);
	assert_true(m.motor != m2.motor);
}

static void test_scheduled_halts(void **state)
{
	(void)state;
	struct bench_axis k = axis_k(20, 60, 0, 0);
	struct simmot m;
	simmot_init(&m, &k, 60, seed);
	simmot_start(&m, 80, 0, 0, 0, 0);
	simmot_schedule_halt(&m, SIMMOT_HALT_ALARM, 0.5);
	int ev;
	run(&m, 0, &ev);
	assert_int_equal(ev, SIMMOT_ALARMED);
	assert_true(fabs(m.motor - 70) < 1e-9);
	simmot_start(&m, 30, 10, 0, 0, 0);
	simmot_schedule_halt(&m, SIMMOT_HALT_STALL, 0.6);
	run(&m, 10, &ev);
	assert_int_equal(ev, SIMMOT_STALL);
	assert_true(fabs(m.motor - (70 - 0.6 * 40)) < 1e-9);
}

static void test_arm_separation(void **state)
{
	(void)state;
	/* same direction */
	assert_true(fabs(simmot_arm_separation(30, 0, 30, 0)) < 1e-6);
	/* negative laser zenith means the opposite azimuth */
	assert_true(fabs(simmot_arm_separation(-30, 0, 30, 180)) < 1e-6);
	assert_true(fabs(simmot_arm_separation(-30, 0, 30, 0) - 60) < 1e-9);
	/* laser at the zenith: separation is the detector's zenith angle whatever its azimuth */
	for (int phi = -180; phi <= 360; phi += 45)
		assert_true(fabs(simmot_arm_separation(0, 0, 25, phi) - 25) < 1e-9);
	/* across the zenith in one plane: θL + θD */
	assert_true(fabs(simmot_arm_separation(40, 0, 35, 180) - 75) < 1e-9);
	/* perpendicular azimuths at the horizon: 90° */
	assert_true(fabs(simmot_arm_separation(90, 0, 90, 90) - 90) < 1e-9);
	/* spherical law of cosines at a generic point, computed with vectors */
	double tl = 50, pl = 10, td = 35, pd = 70, r = M_PI / 180;
	double a[3] = { sin(tl * r) * cos(pl * r), sin(tl * r) * sin(pl * r), cos(tl * r) };
	double b[3] = { sin(td * r) * cos(pd * r), sin(td * r) * sin(pd * r), cos(td * r) };
	double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
	assert_true(fabs(simmot_arm_separation(tl, pl, td, pd) - acos(dot) / r) < 1e-9);
}

int main(void)
{
	const char *s = getenv("ACQ_SEED");
	seed = s ? strtoull(s, NULL, 10) : 1;
	printf("test_sim_motion: seed %llu\n", (unsigned long long)seed);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_durations_match_trapezoid),
		cmocka_unit_test(test_profile_bounds),
		cmocka_unit_test(test_decelerating_stop),
		cmocka_unit_test(test_hard_limits),
		cmocka_unit_test(test_backlash_play),
		cmocka_unit_test(test_noise_statistics_and_seed),
		cmocka_unit_test(test_scheduled_halts),
		cmocka_unit_test(test_arm_separation),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
