/* Unit tests for daemon/plan/plan_home.c: the order of an all-axes home on the shipped bench's geometry, checked
 * by an independent model (own vectors, every single-axis segment sampled densely): every axis homed, then parked,
 * the arms never closer than the collision limit; orders that cannot exist are refused. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "config/bench.h"
#include "daemon/plan/plan_home.h"

#define RAD(x) ((x) * 3.14159265358979323846 / 180.0)

/* angle (degrees) between the laser's direction (zenith lt at azimuth lphi) and the detector's (dt, dp) */
static double sep_deg(double lphi, double lt, double dt, double dp)
{
	double a[3] = { sin(RAD(lt)) * cos(RAD(lphi)), sin(RAD(lt)) * sin(RAD(lphi)), cos(RAD(lt)) };
	double b[3] = { sin(RAD(dt)) * cos(RAD(dp)), sin(RAD(dt)) * sin(RAD(dp)), cos(RAD(dt)) };
	double c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
	return acos(c > 1 ? 1 : c < -1 ? -1 : c) * 180 / 3.14159265358979323846;
}

/* The independent check of steps[0..n) from `from`: apart moves (an axis of mask, anywhere within its limits) only
 * before the first home, then each axis of mask homed once then (park) parked once, a single axis per step, every
 * pose on every segment (1000 samples) at least body + body + margin apart, every target within the axis limits;
 * the end pose = the parks. Returns the number of apart moves. */
static int check_sequence(const struct bench_geom *g, const double from[3], const double *park, unsigned mask,
			  const struct plan_home_step *s, int n)
{
	int napart = 0;
	double limit = g->laser_body_halfwidth_deg + g->detector_body_halfwidth_deg + g->safety_margin_deg;
	const struct bench_axis *ax[3] = { &g->laser_theta, &g->detector_theta, &g->detector_phi };
	double p[3] = { from[0], from[1], from[2] };
	int homed[3] = { 0 }, parked[3] = { 0 };
	for (int i = 0; i < n; i++) {
		int a = s[i].axis;
		assert_true(a >= 0 && a < 3 && (mask & (1u << a)));
		if (s[i].apart) {
			assert_true(!s[i].park && napart == i); /* the apart moves first, before any home */
			napart++;
		} else if (s[i].park) {
			assert_non_null(park);
			assert_true(homed[a] && !parked[a]);
			assert_true(s[i].target == park[a]);
			parked[a] = 1;
		} else {
			assert_true(!homed[a] && s[i].target == 0);
			homed[a] = 1;
		}
		assert_true(s[i].target >= ax[a]->min_deg && s[i].target <= ax[a]->max_deg);
		double q[3] = { p[0], p[1], p[2] };
		for (int k = 0; k <= 1000; k++) {
			q[a] = p[a] + (s[i].target - p[a]) * k / 1000.0;
			double d = sep_deg(g->laser_phi_deg, q[0], q[1], q[2]);
			if (d < limit - 1e-9)
				fail_msg("step %d (axis %d to %g): the arms %.3f° apart at (%g, %g, %g), limit %g", i, a,
					 s[i].target, d, q[0], q[1], q[2], limit);
		}
		p[a] = s[i].target;
	}
	for (int a = 0; a < 3; a++)
		if (mask & (1u << a)) {
			assert_true(homed[a]);
			if (park) {
				assert_true(parked[a]);
				assert_true(p[a] == park[a]);
			}
		}
	return napart;
}

/* The shipped benches: from (10, 40, 90) to the parks (30, 30, 180). The order: laser home and park, detector.theta
 * home (the laser away), then detector.phi home and park (to 180 before detector.theta rises: at 0° it would rise
 * into the laser), then detector.theta's park. */
static void test_shipped_bench(void **state)
{
	(void)state;
	struct bench_geom g;
	bench_defaults(&g);
	double from[3] = { 10, 40, 90 }, park[3] = { 30, 30, 180 };
	struct plan_pos f = { from[0], from[1], from[2] };
	struct plan_home_step s[PLAN_HOME_MAX_STEPS];
	int n = plan_home_order(&g, &f, park, 7, s);
	assert_int_equal(n, 6);
	assert_int_equal(check_sequence(&g, from, park, 7, s, n), 0); /* no apart move where none is needed */
	static const int axis[6] = { 0, 0, 1, 2, 2, 1 }, pk[6] = { 0, 1, 0, 0, 1, 1 };
	for (int i = 0; i < 6; i++) {
		assert_int_equal(s[i].axis, axis[i]);
		assert_int_equal(s[i].park, pk[i]);
	}
	/* without parks the homes together, (0, 0, 0), are a collision: no order */
	assert_int_equal(plan_home_order(&g, &f, NULL, 7, s), -1);
	/* a laser parked at 0°: detector.theta can only be homed with the laser away, which it never is from 10° (its
	 * home and park are both at 0°): the laser is moved apart first (to 15°), detector.theta homed, then the rest */
	double low[3] = { 0, 30, 180 };
	n = plan_home_order(&g, &f, low, 7, s);
	assert_int_equal(n, 7);
	assert_int_equal(check_sequence(&g, from, low, 7, s, n), 1);
	assert_true(s[0].axis == 0 && s[0].target > from[0] && s[1].axis == 1 && !s[1].park);
	/* an unknown position: no order */
	struct plan_pos u = { NAN, 40, 90 };
	assert_int_equal(plan_home_order(&g, &u, park, 7, s), -1);
	/* one axis, no park: detector.theta's home with the laser at 0° is refused, with the laser at 30° found */
	struct plan_pos l0 = { 0, 40, 90 }, l30 = { 30, 40, 90 };
	assert_int_equal(plan_home_order(&g, &l0, NULL, 2, s), -1);
	assert_int_equal(plan_home_order(&g, &l30, NULL, 2, s), 1);
	assert_int_equal(s[0].axis, 1);
}

/* From (10, 10, 90) every home closes the arms in (each axis's home is within 12° of the other arm): the arms are
 * moved apart first, by one move of the smallest size (5°-steps, laser first), then homed and parked. */
static void test_apart_first(void **state)
{
	(void)state;
	struct bench_geom g;
	bench_defaults(&g);
	double from[3] = { 10, 10, 90 }, park[3] = { 30, 30, 180 };
	struct plan_pos f = { from[0], from[1], from[2] };
	struct plan_home_step s[PLAN_HOME_MAX_STEPS];
	int n = plan_home_order(&g, &f, park, 7, s);
	assert_int_equal(n, 7);
	assert_int_equal(check_sequence(&g, from, park, 7, s, n), 1);
	assert_true(s[0].apart && s[0].axis == 0);
	/* no smaller single move opens an order: the first axis moved by 5° less (or any axis by less) has none */
	double size = fabs(s[0].target - from[0]);
	for (int a = 0; a < 3; a++)
		for (double d = -size + 5; d <= size - 5 + 1e-9; d += 5) {
			if (d == 0)
				continue;
			struct plan_pos q = f;
			double *v = a == 0 ? &q.laser_theta : a == 1 ? &q.det_theta : &q.det_phi;
			*v += d;
			struct plan_home_step t[PLAN_HOME_MAX_STEPS];
			if (plan_home_move_ok(&g, &f, &q) && plan_home_order(&g, &q, park, 7, t) >= 0)
				assert_true(t[0].apart); /* only with another apart move of its own */
		}
	/* home of one axis never moves another: detector.theta's home with the laser at 0° stays refused */
	struct plan_pos l0 = { 0, 40, 90 };
	assert_int_equal(plan_home_order(&g, &l0, NULL, 2, s), -1);
}

/* A bench with bulkier arms (half-widths 10° and 9°: the arms at least 20° apart): from (17.5, 22.5, 61) no order
 * exists at once, and the smallest apart move that opens one by itself, the laser down to 12.5°, closes the arms in:
 * the rule (plan_home_move_ok) refuses it, and detector.theta moves up to 27.5° first instead. An apart move that
 * skipped the rule would be the laser's, and the independent model fails that order. */
static void test_apart_move_checked(void **state)
{
	(void)state;
	struct bench_geom g;
	bench_defaults(&g);
	g.laser_body_halfwidth_deg = 10;
	g.detector_body_halfwidth_deg = 9;
	double from[3] = { 17.5, 22.5, 61 }, park[3] = { 30, 30, 180 };
	struct plan_pos f = { from[0], from[1], from[2] };
	assert_false(plan_blind(&g, &f) & (PLAN_R_COLLISION | PLAN_R_LIMITS));
	struct plan_home_step s[PLAN_HOME_MAX_STEPS], t[PLAN_HOME_MAX_STEPS];
	int n = plan_home_order(&g, &f, park, 7, s);
	assert_int_equal(n, 7);
	assert_int_equal(check_sequence(&g, from, park, 7, s, n), 1);
	assert_true(s[0].apart && s[0].axis == 1 && fabs(s[0].target - 27.5) < 1e-9);
	/* the laser's move to 12.5° is refused by the rule, though from there the homes have an order */
	struct plan_pos l = f;
	l.laser_theta = 12.5;
	assert_false(plan_home_move_ok(&g, &f, &l));
	assert_true(plan_home_order(&g, &l, park, 7, t) >= 0);
}

/* Start poses over the bench (clear of collision): from every one an order exists (with apart moves first where
 * the arms are low and close), and the independent model agrees with each. */
static void test_start_poses(void **state)
{
	(void)state;
	struct bench_geom g;
	bench_defaults(&g);
	double park[3] = { 30, 30, 180 };
	int tried = 0, found = 0, apart = 0;
	for (double lt = -5; lt <= 90; lt += 7.5)
		for (double dt = -5; dt <= 90; dt += 7.5)
			for (double dp = -179; dp <= 359; dp += 31) {
				struct plan_pos f = { lt, dt, dp };
				if (plan_blind(&g, &f) & (PLAN_R_COLLISION | PLAN_R_LIMITS))
					continue;
				tried++;
				struct plan_home_step s[PLAN_HOME_MAX_STEPS];
				int n = plan_home_order(&g, &f, park, 7, s);
				if (n < 0)
					continue;
				found++;
				double from[3] = { lt, dt, dp };
				int napart = check_sequence(&g, from, park, 7, s, n);
				assert_int_equal(n, 6 + napart);
				apart += napart > 0;
			}
	printf("# %d of %d clear start poses have an order, %d of them with apart moves first\n", found, tried, apart);
	assert_true(tried > 1000);
	assert_int_equal(found, tried);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_shipped_bench),
		cmocka_unit_test(test_apart_first),
		cmocka_unit_test(test_apart_move_checked),
		cmocka_unit_test(test_start_poses),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
