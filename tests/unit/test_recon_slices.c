/* Unit tests for recon/slices.c's wavelength selection (slices_weights): one wavelength is the linear blend of
 * its two neighbouring channels, a band the trapezoid weights of the channels inside it (the nearest channel when
 * it is narrower than the spacing), weights sum to 1, and selections outside the model's range are refused. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <cmocka.h>

#include "recon/slices.h"

/* A model holding only its wavelengths: five channels at 400, 500, …, 800 nm (in wl, 5 entries). */
static void five_channels(struct recon_model *m, double *wl)
{
	for (int l = 0; l < 5; l++)
		wl[l] = 400 + 100 * l;
	memset(m, 0, sizeof *m);
	m->wl = wl;
	m->nwl = 5;
}

static void test_one_wavelength(void **state)
{
	(void)state;
	double wl[5], w[5];
	struct recon_model m;
	five_channels(&m, wl);
	assert_int_equal(slices_weights(&m, 550, 550, w, NULL), 0);
	assert_true(fabs(w[1] - 0.5) < 1e-12 && fabs(w[2] - 0.5) < 1e-12 && w[0] == 0 && w[3] == 0);
	assert_int_equal(slices_weights(&m, 800, 800, w, NULL), 0); /* the last channel itself */
	assert_true(fabs(w[4] - 1) < 1e-12 && fabs(w[3]) < 1e-12);
	assert_int_equal(slices_weights(&m, 400, 400, w, NULL), 0);
	assert_true(fabs(w[0] - 1) < 1e-12);
	struct acq_err e = { 0 };
	assert_int_equal(slices_weights(&m, 399, 399, w, &e), -1);
	assert_non_null(strstr(e.msg, "outside"));
	assert_int_equal(slices_weights(&m, 700, 600, w, &e), -1);
}

static void test_band(void **state)
{
	(void)state;
	double wl[5], w[5];
	struct recon_model m;
	five_channels(&m, wl);
	/* 450..650: channel 500 covers 450..550 (100), 600 covers 550..650 (100) */
	assert_int_equal(slices_weights(&m, 450, 650, w, NULL), 0);
	assert_true(fabs(w[1] - 0.5) < 1e-12 && fabs(w[2] - 0.5) < 1e-12 && w[0] == 0 && w[3] == 0);
	/* the whole range: the ends carry half cells */
	assert_int_equal(slices_weights(&m, 400, 800, w, NULL), 0);
	double sum = 0;
	for (int l = 0; l < 5; l++)
		sum += w[l];
	assert_true(fabs(sum - 1) < 1e-12 && fabs(w[0] - 0.125) < 1e-12 && fabs(w[2] - 0.25) < 1e-12);
	/* narrower than the spacing, between channels: the nearest one */
	assert_int_equal(slices_weights(&m, 610, 640, w, NULL), 0);
	assert_true(fabs(w[2] - 1) < 1e-12);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_one_wavelength),
		cmocka_unit_test(test_band),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
