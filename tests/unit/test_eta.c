/* Unit tests of eta.c: wall-clock ETA at a time scale, pauses not counted, the measured rate taking over. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
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
	/* the bench turns out twice as slow as planned: the measurement takes over */
	for (int d = 4; d <= 9; d++) {
		real += 4, loop += 40;
		t = eta_update(&e, d, 10, 20.0 * d, 200, loop, real);
	}
	/* measured 7 points: 1 at ratio 1, 6 at ratio 2: 26 s real for 14 s planned; weight 7/12 */
	double ratio = 26.0 / 14.0, w = 7.0 / 12.0;
	assert_true(fabs(t - 2.0 * ((1 - w) + w * ratio)) < 1e-9);
	assert_true(eta_update(&e, 10, 10, 200, 200, loop, real) == 0);
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

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_scale_and_pause),
		cmocka_unit_test(test_no_plan),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
