/* Unit tests of eta.c: wall-clock ETA at a time scale, pauses not counted, the measured rate taking over. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <cmocka.h>

#include "daemon/eta.h"

/* Time scale 10: the loop's clock runs 10 s per real second. */
static void test_scale_and_pause(void **state)
{
	(void)state;
	struct eta e;
	eta_reset(&e);
	double real = 100, loop = 1000;
	eta_running(&e, true, 0, loop, real);
	/* the planner says 200 bench seconds for 10 points: 20 wall seconds at scale 10 */
	real += 2, loop += 20;
	double t = eta_update(&e, 1, 10, 180, loop, real);
	assert_true(fabs(e.scale - 10) < 1e-9);
	/* one point measured (2 s real each): blend of plan 18 s and measured 18 s */
	assert_true(fabs(t - 18) < 1e-9);
	/* a pause of 500 real seconds is not counted */
	eta_running(&e, false, 1, loop, real);
	real += 500, loop += 5000;
	eta_running(&e, true, 1, loop, real);
	real += 2, loop += 20;
	t = eta_update(&e, 2, 10, 160, loop, real);
	assert_true(fabs(t - 16) < 1e-9);
	/* the bench turns out slower than planned (4 s per point): the measurement takes over */
	for (int d = 3; d <= 9; d++) {
		real += 4, loop += 40;
		t = eta_update(&e, d, 10, 20.0 * (10 - d), loop, real);
	}
	/* 9 points in 2+2+7*4 = 32 s: 3.56 s per point measured, plan 2 s: weight 9/14 on the measurement */
	double meas = 32.0 / 9, plan = 2.0, w = 9.0 / 14.0;
	assert_true(fabs(t - ((1 - w) * plan + w * meas)) < 1e-9);
	assert_true(eta_update(&e, 10, 10, 0, loop, real) == 0);
}

static void test_no_plan(void **state)
{
	(void)state;
	struct eta e;
	eta_reset(&e);
	assert_true(isnan(eta_update(&e, 0, 5, NAN, 0, 0)));
	eta_running(&e, true, 0, 0, 0);
	assert_true(fabs(eta_update(&e, 1, 5, NAN, 3, 3) - 12) < 1e-9);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_scale_and_pause),
		cmocka_unit_test(test_no_plan),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
