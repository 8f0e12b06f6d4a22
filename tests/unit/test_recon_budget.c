/* Unit tests of recon/budget.c's white-reference-noise component: sigma_refnoise = |DHR| · u_rel(λ), u_rel linear
 * between the table's points and the nearest end outside, added in quadrature to the total; bad tables refused. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon/budget.h"

static void test_refnoise_value_and_total(void **state)
{
	(void)state;
	/* two incidences × five wavelengths; the table covers 500–700 nm only, not on the grid */
	enum { T = 2, L = 5 };
	const double wl[L] = { 400, 500, 550, 650, 800 };
	double dhr[T * L], sig[T * L], rn[T * L], nl[T * L], tot[T * L];
	for (int i = 0; i < T * L; i++) {
		dhr[i] = (i % 3 == 1 ? -1 : 1) * (0.2 + 0.05 * i); /* |DHR|: a negative value counts by its size */
		sig[i] = 1e-4 * (1 + i);
	}
	const double tw[3] = { 500, 600, 700 }, tu[3] = { 0.002, 0.004, 0.001 };
	struct recon_budget_opts o = { .nonlin_rel = 0.001, .refn_wl = tw, .refn_u = tu, .nrefn = 3 };
	struct acq_err err = { 0 };
	assert_int_equal(recon_budget(T, L, wl, dhr, sig, &o, NULL, NULL, NULL, nl, rn, tot, &err), 0);
	/* u_rel at 400 (below: the first row), 500, 550 (halfway 0.002–0.004), 650 (halfway 0.004–0.001), 800 (above) */
	const double want_u[L] = { 0.002, 0.002, 0.003, 0.0025, 0.001 };
	for (int t = 0; t < T; t++)
		for (int l = 0; l < L; l++) {
			int i = t * L + l;
			double want = fabs(dhr[i]) * want_u[l];
			assert_true(fabs(rn[i] - want) <= 1e-15 * fabs(dhr[i]));
			double wt = sqrt(sig[i] * sig[i] + nl[i] * nl[i] + want * want);
			assert_true(fabs(tot[i] - wt) <= 1e-12 * wt);
		}
	/* no table: the component is 0 and the total is the rest */
	struct recon_budget_opts o0 = { .nonlin_rel = 0.001 };
	assert_int_equal(recon_budget(T, L, wl, dhr, sig, &o0, NULL, NULL, NULL, nl, rn, tot, &err), 0);
	for (int i = 0; i < T * L; i++) {
		assert_true(rn[i] == 0.0);
		assert_true(fabs(tot[i] - hypot(sig[i], nl[i])) <= 1e-12 * tot[i]);
	}
	/* one row: that u_rel everywhere */
	struct recon_budget_opts o1 = { .refn_wl = tw, .refn_u = tu + 1, .nrefn = 1 };
	assert_int_equal(recon_budget(T, L, wl, dhr, sig, &o1, NULL, NULL, NULL, NULL, rn, tot, &err), 0);
	for (int i = 0; i < T * L; i++)
		assert_true(fabs(rn[i] - 0.004 * fabs(dhr[i])) <= 1e-15);
}

static void test_refnoise_bad_table(void **state)
{
	(void)state;
	const double wl[1] = { 500 }, dhr[1] = { 0.5 }, sig[1] = { 1e-3 };
	double tot[1], rn[1];
	struct acq_err err = { 0 };
	const double dec[2] = { 600, 500 }, ok_u[2] = { 0.001, 0.001 }, inc[2] = { 500, 600 }, bad_u[2] = { 0.001, 1.5 };
	const double nan_u[2] = { NAN, 0.001 };
	struct recon_budget_opts o = { .refn_wl = dec, .refn_u = ok_u, .nrefn = 2 };
	assert_int_equal(recon_budget(1, 1, wl, dhr, sig, &o, NULL, NULL, NULL, NULL, rn, tot, &err), -1);
	assert_non_null(strstr(err.msg, "reference noise row 2"));
	o.refn_wl = inc;
	o.refn_u = bad_u;
	assert_int_equal(recon_budget(1, 1, wl, dhr, sig, &o, NULL, NULL, NULL, NULL, rn, tot, &err), -1);
	assert_non_null(strstr(err.msg, "reference noise row 2"));
	o.refn_u = nan_u;
	assert_int_equal(recon_budget(1, 1, wl, dhr, sig, &o, NULL, NULL, NULL, NULL, rn, tot, &err), -1);
	assert_non_null(strstr(err.msg, "reference noise row 1"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_refnoise_value_and_total),
		cmocka_unit_test(test_refnoise_bad_table),
	};
	return cmocka_run_group_tests_name("recon_budget", tests, NULL, NULL);
}
