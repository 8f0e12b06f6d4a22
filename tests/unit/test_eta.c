/* Unit tests of eta.c: wall-clock ETA at a time scale, pauses not counted, the measured excess per point taking over
 * and following a drift of the host's time. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdbool.h>
#include <cmocka.h>

#include "daemon/eta.h"

/* Time scale 10 (the loop's clock runs 10 s per real second); a plan of 10 points of 20 bench seconds. */
static void test_scale_and_pause(void **state)
{
	(void)state;
	struct eta e;
	eta_reset(&e);
	double real = 100, loop = 1000;
	eta_running(&e, true, loop, real);
	/* the first point after the start is not measured (it carries the reference): the plan alone */
	real += 5, loop += 50;
	double t = eta_update(&e, 1, 10, 20, 200, loop, real);
	assert_true(fabs(e.scale - 10) < 1e-9);
	assert_true(fabs(t - 18) < 1e-9);
	/* a point as planned (2 s real): ratio 1 */
	real += 2, loop += 20;
	t = eta_update(&e, 2, 10, 40, 200, loop, real);
	assert_true(fabs(t - 16) < 1e-9);
	/* a pause of 500 real seconds is not counted; the first point after the resume is not measured either */
	eta_running(&e, false, loop, real);
	real += 500, loop += 5000;
	eta_running(&e, true, loop, real);
	real += 3, loop += 30;
	t = eta_update(&e, 3, 10, 60, 200, loop, real);
	assert_true(fabs(t - 14) < 1e-9);
	/* the bench turns out 2 real s per point slower than planned: the measured excess takes over */
	for (int d = 4; d <= 9; d++) {
		real += 4, loop += 40;
		t = eta_update(&e, d, 10, 20.0 * d, 200, loop, real);
	}
	/* measured 7 points: 1 as planned (excess 0), then 6 intervals of one point with 2 s more: in the recent
	 * average (memory 10 points, the minimum) the i-th of the 7 intervals weighs (1 - d) d^(7-i), d = exp(-1/10),
	 * normalised by their sum 1 - d^7: the six with the excess 1 - d^6 of it; weight 7/12; one point left, planned
	 * 2 s */
	double d = exp(-0.1), excess = 2 * (1 - pow(d, 6)) / (1 - pow(d, 7)), w = 7.0 / 12.0;
	assert_true(fabs(t - (2.0 + w * excess)) < 1e-9);
	assert_true(eta_update(&e, 10, 10, 200, 200, loop, real) == 0);
}

/* The excess is a time per point: a long move left in the plan is not stretched by it (a ratio would). */
static void test_excess_per_point(void **state)
{
	(void)state;
	struct eta e;
	eta_reset(&e);
	double real = 0;
	eta_running(&e, true, real, real);
	/* plan at scale 1: points of 1 s, the last one 100 s (a long move); 11 points */
	double plan[12];
	plan[0] = 0;
	for (int i = 1; i <= 11; i++)
		plan[i] = plan[i - 1] + (i == 11 ? 100 : 1);
	real += 1;
	eta_update(&e, 1, 11, plan[1], plan[11], real, real); /* skipped: first after the start */
	double t = 0;
	for (int d = 2; d <= 10; d++) {
		real += 1.5; /* 0.5 s per point beyond the plan (host time) */
		t = eta_update(&e, d, 11, plan[d], plan[11], real, real);
	}
	/* 9 measured points, excess 0.5 s each, weight 9/14: 100 s planned + 0.5 * 9/14 */
	assert_true(fabs(t - (100 + 0.5 * 9.0 / 14.0)) < 1e-9);
}

/* A drift of the host's time along a sweep (the machine loaded for the first half, then not, or the reverse): 400
 * points of 1 planned second at time scale 1, 0.5 s per point beyond the plan in one half, none in the other. Well
 * after the change (at 350 points: 150 points = 3 memories of 50 points later) the ETA follows the current rate
 * within 5 %; the mean of the whole past (the estimator before) was 29 % over and 19 % under there. */
static double drift_eta(double first, double second, double *actual)
{
	struct eta e;
	eta_reset(&e);
	double real = 0, t = 0;
	eta_running(&e, true, real, real);
	real += 1;
	eta_update(&e, 1, 400, 1, 400, real, real); /* skipped: first after the start */
	for (int d = 2; d <= 350; d++) {
		real += 1 + (d <= 200 ? first : second);
		t = eta_update(&e, d, 400, d, 400, real, real);
	}
	*actual = 50 * (1 + second);
	return t;
}

static void test_drift(void **state)
{
	(void)state;
	double actual, t = drift_eta(0.5, 0, &actual);
	assert_true(fabs(t / actual - 1) < 0.05);
	t = drift_eta(0, 0.5, &actual);
	assert_true(fabs(t / actual - 1) < 0.05);
	/* the same excess all along: exactly the plan plus it (weight 349/354) */
	t = drift_eta(0.5, 0.5, &actual);
	assert_true(fabs(t - (50 + 0.5 * 50 * 349.0 / 354.0)) < 1e-9);
}

/* The first points come before the time scale is measured (the loop's and the real clock are compared over half a
 * second; the operator's resume after the reference may follow the start within ms): at time scale 35, points of
 * 2.5 bench seconds taking 2.5 / 35 + 0.01 real seconds. A recent average of the excess taken at the unknown scale
 * (1) would start near -2.4 s per point and drag the ETA to 0 for hundreds of points; averaged apart, the real and
 * plan seconds are compared at the scale known later. */
static void test_scale_measured_late(void **state)
{
	(void)state;
	struct eta e;
	eta_reset(&e);
	double real = 0, step = 2.5 / 35 + 0.01, t = 0;
	eta_running(&e, true, 0, real);
	for (int d = 1; d <= 100; d++) {
		real += step;
		t = eta_update(&e, d, 400, 2.5 * d, 1000, 35 * real, real);
	}
	double want = 300 * (2.5 / 35) + 0.01 * 300 * 99.0 / 104.0;
	assert_true(fabs(t / want - 1) < 0.01);
}

/* A sweep of 400 points at time scale 35 (memory 50 points): each point's bench work 1 bench s (eta_work), planned
 * 1 bench s + the host's 5 ms real (0.175 bench s); the host takes 5 ms real per point but `burst(d)` more at some
 * points. Returns the ETA after `at` points and the real time then left in *actual. */
static double host_run(int at, double (*burst)(int), bool work, double *actual)
{
	struct eta e;
	eta_reset(&e);
	const double scale = 35, host = 0.005, plan_pp = 1 + host * scale;
	double real = 0, t = NAN, left = 0;
	eta_running(&e, true, 0, real);
	for (int d = 1; d <= 400; d++) {
		double pt = 1 / scale + host + burst(d);
		if (d <= at) {
			real += pt;
			if (work)
				eta_work(&e, 1.0 * d);
			t = eta_update(&e, d, 400, plan_pp * d, plan_pp * 400, scale * real, real);
		} else
			left += pt;
	}
	*actual = left;
	return t;
}

static double burst_20(int d)
{
	return d > 200 && d <= 220 ? 0.020 : 0; /* 20 points at 25 ms instead of 5 (session 13's loaded burst) */
}

static double step_up(int d)
{
	return d > 200 ? 0.020 : 0; /* the machine stays loaded */
}

/* One loaded burst does not swing the ETA of the rest: right after 20 points of 25 ms host time per point, the
 * host's part is its median over the last 50 points (5 ms), not the recent average (which rose by 20 ms × (1 -
 * e^(-20/50)) = 6.6 ms per point: +19.5 % on the 34 ms points here, measured so with the split disabled; with
 * it +0.0 %). A load that lasts is followed once it fills half the memory. */
static void test_host_burst_robust(void **state)
{
	(void)state;
	double actual, t = host_run(220, burst_20, true, &actual);
	assert_true(fabs(t / actual - 1) < 0.02);
	/* without the split (no eta_work) the recent average carries the burst into the rest */
	double t_mean = host_run(220, burst_20, false, &actual);
	assert_true(t_mean / actual - 1 > 0.05);
	/* a lasting change: 75 points later (1.5 memories) the ETA follows the new host time within 5 % */
	t = host_run(275, step_up, true, &actual);
	assert_true(fabs(t / actual - 1) < 0.05);
}

/* Lumpy exposures (a dark of 2 bench s every 10th point, which the plan prices by expectation, 0.2 s per point) do
 * not bias the ETA: with a constant host time the split changes nothing (the median of the host's time equals its
 * average), whereas a median of the excess itself would price every point at its dark-less excess (-0.2 bench s). */
static void test_host_split_unbiased(void **state)
{
	(void)state;
	double t[2];
	for (int w = 0; w < 2; w++) {
		struct eta e;
		eta_reset(&e);
		const double scale = 35, host = 0.005, plan_pp = 1.2 + host * scale;
		double real = 0, work = 0;
		eta_running(&e, true, 0, real);
		for (int d = 1; d <= 300; d++) {
			double b = d % 10 == 0 ? 3.0 : 1.0; /* bench s of the point: exposures, a dark every 10th */
			work += b;
			real += b / scale + host;
			if (w)
				eta_work(&e, work);
			t[w] = eta_update(&e, d, 400, plan_pp * d, plan_pp * 400, scale * real, real);
		}
	}
	assert_true(fabs(t[1] - t[0]) < 1e-6);
	/* and the ETA is the plan's rest within 5 % (the recent average of a lumpy excess) */
	assert_true(fabs(t[1] / (100 * (1.2 / 35 + 0.005)) - 1) < 0.05);
}

static void test_no_plan(void **state)
{
	(void)state;
	struct eta e;
	eta_reset(&e);
	assert_true(isnan(eta_update(&e, 0, 5, NAN, NAN, 0, 0)));
	eta_running(&e, true, 0, 0);
	assert_true(isnan(eta_update(&e, 1, 5, NAN, NAN, 3, 3)));  /* the first interval is skipped */
	assert_true(fabs(eta_update(&e, 2, 5, NAN, NAN, 6, 6) - 9) < 1e-9);
}

/* eta_forget (a survey's end): the excess measured so far is dropped, the ETA is the plan's again (the scale kept),
 * and the next points' own excess takes over; eta_host is the host's mean over the points measured with their work. */
static void test_forget(void **state)
{
	(void)state;
	struct eta e;
	eta_reset(&e);
	double real = 100, loop = 1000;
	eta_running(&e, true, loop, real);
	real += 2, loop += 20;
	eta_update(&e, 1, 20, 20, 400, loop, real); /* the first interval: not measured */
	assert_true(isnan(eta_host(&e)));
	for (int d = 2; d <= 10; d++) { /* 5 real s a point for 20 bench s planned, of which 18 bench s of work; the
					 * last one 0.9 s longer (a burst) */
		real += d == 10 ? 5.9 : 5, loop += d == 10 ? 59 : 50; /* the clocks' ratio stays 10 */
		eta_work(&e, 18.0 * d);
		eta_update(&e, d, 20, 20.0 * d, 400, loop, real);
	}
	/* the host: 5 - 18 / 10 = 3.2 s per point, and the burst in the mean (8 points with their work: + 0.9 / 8), not
	 * in a median */
	assert_true(fabs(eta_host(&e) - (3.2 + 0.9 / 8)) < 1e-6); /* the window keeps floats */
	double before = eta_update(&e, 10, 20, 200, 400, loop, real);
	assert_true(before > 10 * 2 + 5); /* the plan's 2 s a point and most of the 3 s excess */
	eta_forget(&e);
	assert_true(fabs(e.scale - 10) < 1e-9);
	double t = eta_update(&e, 10, 20, 200, 400, loop, real);
	assert_true(fabs(t - 20) < 1e-9); /* the plan's rest at the scale, nothing more */
	/* the route's points as planned: the ETA stays the plan's */
	for (int d = 11; d <= 14; d++) {
		real += 2, loop += 20;
		t = eta_update(&e, d, 20, 20.0 * d, 400, loop, real);
		assert_true(fabs(t - 2.0 * (20 - d)) < 1e-6);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_scale_and_pause),
		cmocka_unit_test(test_excess_per_point),
		cmocka_unit_test(test_drift),
		cmocka_unit_test(test_scale_measured_late),
		cmocka_unit_test(test_no_plan),
		cmocka_unit_test(test_host_burst_robust),
		cmocka_unit_test(test_host_split_unbiased),
		cmocka_unit_test(test_forget),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
