/* Unit test of sim/sim_sphere.c, the simulated integrating-sphere spectrophotometer: over 300 instrument seeds
 * its errors against the truth's DHR at 8 deg are described by its stated sigma (z mean ~ 0, z standard
 * deviation in [0.85, 1.15]: fails if sigma were scaled by 3 or 1/3, or the calibration part left out of it),
 * the calibration part is correlated across wavelengths and the noise is not, and the same seed gives the same
 * measurement. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "sim/sim_sphere.h"

#define NW 131

static void test_sphere_statistics(void **state)
{
	(void)state;
	double wl[NW], truth[NW], qs[NW], v[NW], s[NW];
	for (int l = 0; l < NW; l++)
		wl[l] = 450 + 5 * l;
	struct acq_err err = { 0 };
	static const enum mat_id ids[] = { MAT_GREEN_PAINT, MAT_NARROW_LINES, MAT_CLEAR_COAT };
	for (size_t k = 0; k < sizeof ids / sizeof ids[0]; k++) {
		struct mat *m = mat_new(ids[k], NW, wl, &err);
		assert_non_null(m);
		assert_int_equal(mat_dhr(m, 8 * M_PI / 180, 2, truth, qs, &err), 0);
		double sz = 0, sz2 = 0, sab = 0, sa = 0, sb = 0, sa2 = 0, sb2 = 0, within = 0;
		int n = 300, cnt = 0;
		for (int seed = 1; seed <= n; seed++) {
			assert_int_equal(sphere_apply(NW, wl, truth, (uint64_t)seed, v, s, &err), 0);
			for (int l = 0; l < NW; l++) {
				assert_true(isfinite(v[l]) && s[l] > 0);
				double z = (v[l] - truth[l]) / s[l];
				sz += z, sz2 += z * z, within += fabs(z) < 2, cnt++;
			}
			/* relative errors at 600 and 625 nm (30 and 35): the calibration part correlates them */
			double a = v[30] / truth[30] - 1, b = v[35] / truth[35] - 1;
			sa += a, sb += b, sa2 += a * a, sb2 += b * b, sab += a * b;
		}
		double mz = sz / cnt, sdz = sqrt(sz2 / cnt - mz * mz);
		double ma = sa / n, mb = sb / n, r = (sab / n - ma * mb) / sqrt((sa2 / n - ma * ma) * (sb2 / n - mb * mb));
		printf("%s: z over %d seeds x %d wavelengths: mean %.3f, sd %.3f, |z| < 2 for %.1f %%; correlation of the "
		       "relative errors at 600 and 625 nm %.2f\n", mat_name(ids[k]), n, NW, mz, sdz, 100 * within / cnt, r);
		assert_true(fabs(mz) < 0.25); /* the correlated part makes the mean over wavelengths move per seed */
		assert_true(sdz > 0.85 && sdz < 1.15);
		assert_true(r > 0.5);
		double v2[NW], s2[NW];
		assert_int_equal(sphere_measure(m, NW, wl, 7, v, s, &err), 0);
		sphere_apply(NW, wl, truth, 7, v2, s2, &err);
		assert_memory_equal(v, v2, sizeof v); /* the same seed, the same measurement */
		mat_free(m);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(test_sphere_statistics) };
	return cmocka_run_group_tests(tests, NULL, NULL);
}
