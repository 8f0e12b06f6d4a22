/* Unit tests for recon/warp2d.c: sample and invert are inverses, the pdf integrates to 1, sampled points follow
 * the bilinear density (histogram against the exact cell masses), and bad tables are refused. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "recon/warp2d.h"

static uint64_t rng_state;

static double urand(void)
{
	rng_state ^= rng_state << 13;
	rng_state ^= rng_state >> 7;
	rng_state ^= rng_state << 17;
	return (double)(rng_state >> 11) / 9007199254740992.0;
}

/* A lumpy table with a zero row and a zero column (empty cells must be skipped, not landed in). */
static void table(double *d, size_t w, size_t h)
{
	for (size_t j = 0; j < h; j++)
		for (size_t i = 0; i < w; i++) {
			double x = (double)i / (double)(w - 1), y = (double)j / (double)(h - 1);
			d[j * w + i] = (j == 2 || i == 0) ? 0 : exp(-20 * ((x - 0.7) * (x - 0.7) + (y - 0.3) * (y - 0.3))) + 0.05 * y;
		}
}

static void test_roundtrip(void **state)
{
	(void)state;
	size_t w = 17, h = 9;
	double d[17 * 9];
	table(d, w, h);
	struct warp2d wp;
	assert_int_equal(warp2d_init(&wp, d, w, h, NULL), 0);
	double worst = 0;
	for (int k = 0; k < 20000; k++) {
		double s[2] = { urand(), urand() }, u[2], s2[2], pdf;
		warp2d_sample(&wp, s, u, &pdf);
		assert_true(u[0] >= 0 && u[0] <= 1 && u[1] >= 0 && u[1] <= 1);
		assert_true(pdf > 0); /* never lands where the density is 0 */
		warp2d_invert(&wp, u, s2);
		double e = fmax(fabs(s2[0] - s[0]), fabs(s2[1] - s[1]));
		worst = e > worst ? e : worst;
	}
	printf("sample/invert round trip: max |s' - s| = %.3g (tolerance 1e-9: closed forms, double)\n", worst);
	assert_true(worst < 1e-9);
	warp2d_free(&wp);
}

static void test_pdf_and_histogram(void **state)
{
	(void)state;
	size_t w = 9, h = 7;
	double d[9 * 7];
	table(d, w, h);
	struct warp2d wp;
	assert_int_equal(warp2d_init(&wp, d, w, h, NULL), 0);
	/* the pdf integrates to 1 (midpoint rule on a fine grid; bilinear pieces: error ~ 1e-6) */
	double sum = 0;
	int M = 800;
	for (int a = 0; a < M; a++)
		for (int b = 0; b < M; b++) {
			double u[2] = { (a + 0.5) / M, (b + 0.5) / M };
			sum += warp2d_pdf(&wp, u) / ((double)M * M);
		}
	printf("integral of the pdf = %.8f\n", sum);
	assert_true(fabs(sum - 1) < 1e-4);
	/* histogram over the table's cells against each cell's exact mass (mean of its 4 corners × area) */
	size_t nc = (w - 1) * (h - 1), n = 200000;
	size_t *cnt = calloc(nc, sizeof *cnt);
	assert_non_null(cnt);
	for (size_t k = 0; k < n; k++) {
		double s[2] = { urand(), urand() }, u[2];
		warp2d_sample(&wp, s, u, NULL);
		size_t i = (size_t)fmin(u[0] * (double)(w - 1), (double)(w - 2));
		size_t j = (size_t)fmin(u[1] * (double)(h - 1), (double)(h - 2));
		cnt[j * (w - 1) + i]++;
	}
	double chi2 = 0;
	size_t dof = 0;
	for (size_t j = 0; j + 1 < h; j++)
		for (size_t i = 0; i + 1 < w; i++) {
			double mass = 0.25 * (d[j * w + i] + d[j * w + i + 1] + d[(j + 1) * w + i] + d[(j + 1) * w + i + 1]) /
				      ((double)(w - 1) * (double)(h - 1)) / wp.total;
			double ex = mass * (double)n, o = (double)cnt[j * (w - 1) + i];
			if (ex == 0) {
				assert_true(o == 0);
				continue;
			}
			chi2 += (o - ex) * (o - ex) / ex;
			dof++;
		}
	/* 48 cells, ~47 degrees of freedom: 110 is beyond the 1 - 1e-6 quantile (a broken warp gives thousands) */
	printf("histogram chi-square %.1f over %zu cells\n", chi2, dof);
	assert_true(chi2 < 110);
	free(cnt);
	warp2d_free(&wp);
}

static void test_refused(void **state)
{
	(void)state;
	struct warp2d wp;
	struct acq_err e = { 0 };
	double z[4] = { 0, 0, 0, 0 }, bad[4] = { 1, NAN, 1, 1 }, neg[4] = { 1, -1, 1, 1 };
	assert_int_equal(warp2d_init(&wp, z, 2, 2, &e), -1);
	assert_non_null(strstr(e.msg, "no mass"));
	assert_int_equal(warp2d_init(&wp, bad, 2, 2, &e), -1);
	assert_non_null(strstr(e.msg, "node 1"));
	assert_int_equal(warp2d_init(&wp, neg, 2, 2, &e), -1);
	assert_int_equal(warp2d_init(&wp, z, 1, 4, &e), -1);
	warp2d_free(&wp);
}

int main(void)
{
	const char *s = getenv("ACQ_SEED");
	rng_state = (s ? strtoull(s, NULL, 10) : 1) * 2654435761u + 88172645463325252ull;
	printf("ACQ_SEED=%s\n", s ? s : "1");
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_roundtrip),
		cmocka_unit_test(test_pdf_and_histogram),
		cmocka_unit_test(test_refused),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
