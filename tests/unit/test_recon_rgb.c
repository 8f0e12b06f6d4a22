/* Unit tests of recon/rgbeval.c: the reduced RGB evaluator against the full-spectrum path, the batch path
 * against the per-pair callback, and the half-table MERL (mirror cells copied) against evaluating every cell;
 * twice: a model without trend and one with the GGX trend (binned trend coefficients). */
#include <setjmp.h>
#include <unistd.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "recon/rgbeval.h"
#include "recon_test_util.h"

static struct recon_model *M;
static struct recon_rgb *R;
static int TREND; /* the group's trend */

static int setup(void **state)
{
	(void)state;
	struct recon_samples s;
	/* 5 × 5 × 6 directions, 261 wavelengths over 450-1100 nm (2.5 nm apart), smooth data, no noise */
	rt_samples_grid(&s, 5, 5, 6, 261, 0.0, 1.0);
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	o.shape = 2.0;
	o.trend = TREND;
	o.smoothing = 1e-4;
	struct acq_err err = { 0 };
	int rc = recon_fit(&s, &o, &M, &err);
	csvio_samples_free(&s);
	if (rc) {
		printf("%s\n", err.msg);
		return -1;
	}
	struct colour_opts co;
	colour_opts_brdf(&co);
	if (recon_rgb_new(M, &co, 0, &R, &err))
		return -1;
	return recon_rgb_set_f32(R, 0); /* the exact checks below compare double paths; single: its own test */
}

static int teardown(void **state)
{
	(void)state;
	recon_rgb_free(R);
	recon_model_free(M);
	return 0;
}

static void random_dirs(double wi[3], double wo[3])
{
	double a[4];
	rt_random_pair(a);
	wi[0] = sin(a[0]) * cos(a[1]);
	wi[1] = sin(a[0]) * sin(a[1]);
	wi[2] = cos(a[0]);
	wo[0] = sin(a[2]) * cos(a[3]);
	wo[1] = sin(a[2]) * sin(a[3]);
	wo[2] = cos(a[2]);
}

/* The reduction (visible channels in 5 nm bins, low rank) changes RGB by < 1 % on smooth spectra, and the
 * batch path equals the per-pair path. The expected error is that of reading the spectrum as linear between
 * bin centres 5 nm apart: h²/8 · f''/f ≈ 25/(8σ²) for a spectral feature of width σ: 0.3 % for the 60 nm
 * Gaussian of the test material (measured 0.4 %); without binning the two paths agree to 1e-13. */
static void test_reduced_matches_full_and_batch(void **state)
{
	(void)state;
	size_t nc, rank;
	recon_rgb_sizes(R, &nc, &rank);
	printf("channels %zu (of %zu), rank %zu, reduction error %.3g\n", nc, M->nwl, rank,
	       recon_rgb_reduction_error(R));
	assert_true(nc < M->nwl && rank <= nc);
	assert_true(recon_rgb_reduction_error(R) < 1e-2);
	enum { NQ = 300 };
	double wi[3 * NQ], wo[3 * NQ], rb[3 * NQ];
	for (int q = 0; q < NQ; q++)
		random_dirs(wi + 3 * q, wo + 3 * q);
	struct acq_err err = { 0 };
	assert_int_equal(recon_rgb_batch(R, NQ, wi, wo, rb, NULL, &err), 0);
	for (int q = 0; q < NQ; q++) {
		double a[3], f[3];
		assert_int_equal(recon_rgb_fn(R, wi + 3 * q, wo + 3 * q, a), 0);
		assert_int_equal(recon_rgb_full_fn(R, wi + 3 * q, wo + 3 * q, f), 0);
		double mx = fmax(f[0], fmax(f[1], f[2]));
		for (int c = 0; c < 3; c++) {
			assert_true(fabs(a[c] - rb[3 * q + c]) <= 1e-12 * fmax(fabs(a[c]), 1e-300));
			assert_true(fabs(a[c] - f[c]) <= 1e-2 * mx);
			assert_true(isfinite(a[c]) && a[c] >= 0);
		}
		double r2[3]; /* reciprocity survives the reduction */
		assert_int_equal(recon_rgb_fn(R, wo + 3 * q, wi + 3 * q, r2), 0);
		for (int c = 0; c < 3; c++)
			assert_true(r2[c] == a[c]);
	}
}

static int cmp_dbl(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

/* The stated reduction error is a per-channel bound: at 3000 random MERL cells (the table's own pairs, through
 * the batch path that fills it) every channel's error against an independent spectral → RGB evaluation (the
 * model's full spectrum by recon_eval_dirs, then colour_spectrum_rgb: no code of rgbeval.c) stays within the
 * figure stated for that channel, relative to the channel itself (or 1 % of the largest channel when smaller:
 * the definition in rgbeval.h). The test material is green (a 60 nm Gaussian at 550 nm over a grey base), so
 * linear R and B are small differences of the sRGB weights' positive and negative lobes. Before session 18
 * the bins' colour weights read the spectrum as linear between bin centres and one figure was stated, relative
 * to the largest channel: seen failing here (seed 1: B 0.92 % at the cells, 0.40 % stated). The medians must
 * also stay at the G channel's level (≤ 1e-3; measured ≤ 2e-4 here, seeds 1-5; the demo's green paint, 5 nm
 * bins of 1 nm channels: R / G / B 0.22 / 0.01 / 0.29 % at θ ≤ 70°). */
static void test_reduction_bound_per_channel(void **state)
{
	(void)state;
	enum { NQ = 3000 };
	static double wi[3 * NQ], wo[3 * NQ], rb[3 * NQ], rel[3][NQ];
	int q = 0;
	while (q < NQ) {
		int ith = (int)(rt_unif() * MERL_N_THETA_H), itd = (int)(rt_unif() * MERL_N_THETA_D);
		int ipd = (int)(rt_unif() * MERL_N_PHI_D);
		if (merl_cell_dirs(ith < MERL_N_THETA_H ? ith : 0, itd < MERL_N_THETA_D ? itd : 0,
				   ipd < MERL_N_PHI_D ? ipd : 0, wi + 3 * q, wo + 3 * q) == 1)
			q++;
	}
	struct acq_err err = { 0 };
	assert_int_equal(recon_rgb_batch(R, NQ, wi, wo, rb, NULL, &err), 0);
	struct colour_opts co;
	colour_opts_brdf(&co);
	double stated[3], worst[3] = { 0 }, *f = malloc(M->nwl * sizeof *f);
	assert_non_null(f);
	recon_rgb_reduction_error_rgb(R, stated);
	for (q = 0; q < NQ; q++) {
		double ind[3];
		assert_int_equal(recon_eval_dirs(M, wi + 3 * q, wo + 3 * q, f, NULL), 0);
		assert_int_equal(colour_spectrum_rgb(&co, M->wl, f, M->nwl, ind, NULL, &err), 0);
		double mx = fmax(fabs(ind[0]), fmax(fabs(ind[1]), fabs(ind[2])));
		for (int c = 0; c < 3; c++) {
			double den = fmax(fabs(ind[c]), 1e-2 * mx);
			rel[c][q] = den > 0 ? fabs(rb[3 * q + c] - ind[c]) / den : 0;
			worst[c] = fmax(worst[c], rel[c][q]);
		}
	}
	free(f);
	for (int c = 0; c < 3; c++) {
		qsort(rel[c], NQ, sizeof rel[c][0], cmp_dbl);
		printf("channel %c: stated %.3g, largest at %d MERL cells %.3g, median %.3g\n", "RGB"[c], stated[c], NQ,
		       worst[c], rel[c][NQ / 2]);
	}
	assert_true(recon_rgb_reduction_error(R) == fmax(stated[0], fmax(stated[1], stated[2])));
	for (int c = 0; c < 3; c++) {
		assert_true(worst[c] <= stated[c]);
		assert_true(rel[c][NQ / 2] <= 1e-3);
	}
}

/* Evaluating half of the φd cells and copying the mirror cells gives the table of every cell. */
static void test_merl_half_table_exact(void **state)
{
	(void)state;
	struct merl_table half = { NULL }, all = { NULL };
	struct acq_err err = { 0 };
	struct merl_table two = { NULL };
	struct colour_stats s1 = { 0 }, s2 = { 0 };
	/* one worker: the table recon_rgb_merl_table makes (its tone statistics kept for the two-worker check) */
	assert_int_equal(recon_rgb_merl_table_ex(R, &half, 0, 1, &s1, NULL, NULL, &err), 0);
	assert_int_equal(recon_rgb_merl_table(R, &all, 1, NULL, NULL, NULL, &err), 0);
	size_t nodata = 0;
	double worst = 0;
	for (size_t i = 0; i < 3 * (size_t)MERL_N_CELLS; i++) {
		if (all.data[i] == MERL_NO_DATA) {
			assert_true(half.data[i] == MERL_NO_DATA);
			nodata++;
			continue;
		}
		double d = fabs(half.data[i] - all.data[i]) / fmax(fabs(all.data[i]), 1e-300);
		if (d > worst)
			worst = d;
	}
	printf("no-data values %zu, worst relative difference %.3g\n", nodata, worst);
	assert_int_equal(nodata, 3 * (size_t)(MERL_N_CELLS - 1096216));
	assert_true(worst < 1e-10);
	/* two workers give the same table bit for bit, and the same tone statistics */
	assert_int_equal(recon_rgb_merl_table_ex(R, &two, 0, 2, &s2, NULL, NULL, &err), 0);
	assert_memory_equal(half.data, two.data, 3 * (size_t)MERL_N_CELLS * sizeof *two.data);
	assert_true(s1.n == s2.n && s1.n > 0 && s1.clipped == s2.clipped && s1.out_of_gamut == s2.out_of_gamut);
	assert_int_equal(recon_rgb_merl_table_ex(R, &two, 0, 0, NULL, NULL, NULL, &err), -1);
	/* writing the table as it is gives the file the writer makes through the reference lookup, to rounding */
	char pa[] = "/tmp/test_recon_rgb_a_XXXXXX", pb[] = "/tmp/test_recon_rgb_b_XXXXXX";
	int fa = mkstemp(pa), fb = mkstemp(pb);
	assert_true(fa >= 0 && fb >= 0);
	close(fa);
	close(fb);
	assert_int_equal(merl_write_table(pa, &half, &err), 0);
	assert_int_equal(merl_write_ex(pb, merl_table_fn, &half, NULL, &err), 0);
	struct merl_table ra = { NULL }, rb = { NULL };
	assert_int_equal(merl_read(pa, &ra, &err), 0);
	assert_int_equal(merl_read(pb, &rb, &err), 0);
	double wdiff = 0;
	for (size_t i = 0; i < 3 * (size_t)MERL_N_CELLS; i++) {
		assert_true((ra.data[i] == MERL_NO_DATA) == (rb.data[i] == MERL_NO_DATA));
		assert_true(ra.data[i] == half.data[i]);
		if (rb.data[i] != MERL_NO_DATA)
			wdiff = fmax(wdiff, fabs(ra.data[i] - rb.data[i]) / fmax(fabs(rb.data[i]), 1e-300));
	}
	printf("direct table write vs lookup write: worst relative difference %.3g\n", wdiff);
	assert_true(wdiff <= 4e-16);
	merl_free(&ra);
	merl_free(&rb);
	half.data[12345] = NAN; /* a bad value is refused, nothing left at the path */
	unlink(pa);
	assert_int_equal(merl_write_table(pa, &half, &err), -1);
	assert_int_equal(access(pa, F_OK), -1);
	unlink(pb);
	merl_free(&two);
	merl_free(&half);
	merl_free(&all);
}

/* The single-precision batch GEMM. A nearly interpolating fit of noise-free data (η = 1e-8, shape 4: large
 * cancelling weights) measures ≈ 2e-3 in ln f, above the 1e-4 limit: single precision is refused and the batch
 * path stays in double. A default fit of noisy data (the usual case; 6 × 6 × 8 directions) measures ≈ 1.5e-5
 * (7e-6 to 1.7e-5 over seeds 1-3 and both trends; the paper's 10 × 10 × 10 grid: 1.5e-5): there the whole MERL
 * table changes by no more than that error allows (|Δ ln f| ≤ e gives |Δf|/f ≤ e^e − 1; the colour chain is
 * linear in f before clamping; 2× for the sampling of the measurement, which sees 2048 of 1.1 M cells). */
static void test_single_precision_table(void **state)
{
	(void)state;
	struct recon_samples s;
	struct recon_fit_opts o;
	struct recon_model *m = NULL;
	struct recon_rgb *r = NULL;
	struct acq_err err = { 0 };
	struct colour_opts co;
	colour_opts_brdf(&co);
	rt_samples_grid(&s, 5, 5, 6, 261, 0.0, 1.0);
	recon_fit_opts_default(&o);
	o.shape = 4;
	o.smoothing = 1e-8;
	o.trend = TREND;
	assert_int_equal(recon_fit(&s, &o, &m, &err), 0);
	csvio_samples_free(&s);
	assert_int_equal(recon_rgb_new(m, &co, 0, &r, &err), 0);
	double e = recon_rgb_f32_error(r);
	printf("nearly interpolating fit: single-precision error in ln f %.3g\n", e);
	assert_true(e > 1e-4);
	assert_int_equal(recon_rgb_f32(r), 0);
	assert_int_equal(recon_rgb_set_f32(r, 1), -1);
	recon_rgb_free(r);
	recon_model_free(m);

	rt_samples_grid(&s, 6, 6, 8, 131, 0.02, 1.0); /* 288 samples: the table's cost grows with the centres */
	recon_fit_opts_default(&o);
	o.trend = TREND;
	assert_int_equal(recon_fit(&s, &o, &m, &err), 0);
	csvio_samples_free(&s);
	assert_int_equal(recon_rgb_new(m, &co, 0, &r, &err), 0);
	e = recon_rgb_f32_error(r);
	printf("noisy default fit: single-precision error in ln f %.3g\n", e);
	assert_true(e > 0 && e <= 1e-4);
	assert_int_equal(recon_rgb_f32(r), 1); /* the default when within the limit */
	struct merl_table d = { NULL }, f = { NULL };
	assert_int_equal(recon_rgb_merl_table(r, &f, 0, NULL, NULL, NULL, &err), 0);
	assert_int_equal(recon_rgb_set_f32(r, 0), 0);
	assert_int_equal(recon_rgb_merl_table(r, &d, 0, NULL, NULL, NULL, &err), 0);
	double worst = 0;
	size_t differ = 0;
	for (size_t i = 0; i < 3 * (size_t)MERL_N_CELLS; i++) {
		assert_true((d.data[i] == MERL_NO_DATA) == (f.data[i] == MERL_NO_DATA));
		if (d.data[i] == MERL_NO_DATA || !(d.data[i] > 1e-9))
			continue;
		double rel = fabs(f.data[i] - d.data[i]) / d.data[i];
		differ += rel > 0;
		worst = fmax(worst, rel);
	}
	printf("single vs double table: worst relative difference %.3g (%zu values differ)\n", worst, differ);
	assert_true(differ > 0); /* the two paths are really different */
	assert_true(worst <= 2.0 * expm1(e) + 1e-12);
	merl_free(&d);
	merl_free(&f);
	recon_rgb_free(r);
	recon_model_free(m);
}

int main(void)
{
	rt_seed();
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_reduced_matches_full_and_batch),
		cmocka_unit_test(test_reduction_bound_per_channel),
		cmocka_unit_test(test_merl_half_table_exact),
		cmocka_unit_test(test_single_precision_table),
	};
	TREND = RECON_TREND_NONE;
	int rc = cmocka_run_group_tests_name("recon_rgb (no trend)", tests, setup, teardown);
	TREND = RECON_TREND_GGX;
	return rc + cmocka_run_group_tests_name("recon_rgb (ggx trend)", tests, setup, teardown);
}
