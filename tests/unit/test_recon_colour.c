/* Unit tests for recon/colour.c and the embedded CIE tables: README check values, white, gamut, range. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "config/yconf.h"
#include "recon/cie_tables.h"
#include "recon/colour.h"

static unsigned seed;

static double urand(void)
{
	seed = seed * 1103515245u + 12345u;
	return ((seed >> 8) & 0xffffff) / (double)0x1000000;
}

#define assert_near(a, b, tol)                                                                        \
	do {                                                                                          \
		double a_ = (a), b_ = (b);                                                            \
		if (!(fabs(a_ - b_) <= (tol)))                                                        \
			fail_msg("%s = %.9g, expected %.9g ± %.3g (seed %u)", #a, a_, b_, (double)(tol), seed); \
	} while (0)

/* Published checks of the CIE README, straight from the embedded tables (5 nm steps for D65). */
static void test_tables_reproduce_readme_checks(void **state)
{
	(void)state;
	double ysum = 0;
	for (int j = 0; j < CIE_CMF_N; j++)
		ysum += cie_cmf_1931_2deg[j][1];
	assert_near(ysum, 106.856917, 1e-6);
	double xyz[3] = { 0, 0, 0 };
	for (int nm = 360; nm <= 830; nm += 5) {
		double e = cie_d65_spd[(nm - CIE_D65_FIRST_NM) / CIE_D65_STEP_NM];
		for (int c = 0; c < 3; c++)
			xyz[c] += e * cie_cmf_1931_2deg[nm - CIE_CMF_FIRST_NM][c];
	}
	double s = xyz[0] + xyz[1] + xyz[2];
	assert_near(xyz[0] / s, 0.312712, 1e-6);
	assert_near(xyz[1] / s, 0.329008, 1e-6);
	assert_near(xyz[0] / xyz[1], 0.950467, 1e-6);
	assert_near(xyz[2] / xyz[1], 1.088969, 1e-6);
	assert_near(cie_d65_spd[(560 - 300) / 5], 100.0, 1e-9); /* D65 is normalised to 100 at 560 nm */
}

/* The chain's own D65 white (5 nm table interpolated to 1 nm) differs from the 5 nm check by ~1.5e-5. */
static void test_chain_d65_white(void **state)
{
	(void)state;
	double w[3];
	colour_illum_white_xyz(COLOUR_ILLUM_D65, w);
	double s = w[0] + w[1] + w[2];
	assert_near(w[1], 1.0, 1e-15);
	assert_near(w[0] / s, 0.312712, 5e-5);
	assert_near(w[1] / s, 0.329008, 5e-5);
	assert_near(w[0], 0.950467, 1e-4);
	assert_near(w[2], 1.088969, 5e-4);
	/* A flat spectrum on the bench grid, EXTENDED below 450 nm, integrates to exactly that white. */
	size_t n = 651;
	double *wl = malloc(n * sizeof(double)), *W = malloc(3 * n * sizeof(double));
	assert_non_null(wl);
	assert_non_null(W);
	for (size_t k = 0; k < n; k++)
		wl[k] = 450 + (double)k;
	double ynorm = 0;
	struct acq_err err = { 0 };
	assert_int_equal(colour_xyz_weights(COLOUR_ILLUM_D65, COLOUR_GAP_EXTEND, wl, n, W, &ynorm, &err), 0);
	for (int c = 0; c < 3; c++) {
		double acc = 0;
		for (size_t k = 0; k < n; k++)
			acc += W[c * n + k];
		assert_near(acc / ynorm, w[c], 1e-12);
	}
	free(wl);
	free(W);
}

/* A perfect white diffuser (BRDF 1/π) gives sRGB (1, 1, 1) relative to white, under D65 and under E. */
static void test_white_reflector_is_white(void **state)
{
	(void)state;
	size_t n = 1301; /* 450..1100 nm every 0.5 nm */
	double *wl = malloc(n * sizeof(double)), *s = malloc(n * sizeof(double));
	assert_non_null(wl);
	assert_non_null(s);
	for (size_t k = 0; k < n; k++) {
		wl[k] = 450 + 0.5 * (double)k;
		s[k] = 1 / M_PI;
	}
	struct colour_opts o;
	struct acq_err err = { 0 };
	double rgb[3];
	for (int illum = 0; illum < 2; illum++) {
		colour_opts_default(&o);
		o.illum = (enum colour_illum)illum;
		assert_int_equal(colour_spectrum_rgb(&o, wl, s, n, rgb, NULL, &err), 0);
		for (int c = 0; c < 3; c++)
			assert_near(rgb[c], 1.0, 1e-4);
		o.srgb_encode = true;
		o.range = COLOUR_RANGE_CLIP;
		assert_int_equal(colour_spectrum_rgb(&o, wl, s, n, rgb, NULL, &err), 0);
		for (int c = 0; c < 3; c++)
			assert_near(rgb[c], 1.0, 1e-4);
	}
	/* Without adaptation D65 is still white to within the matrix's white (0.3127, 0.3290) vs computed. */
	colour_opts_default(&o);
	o.adapt = COLOUR_ADAPT_NONE;
	assert_int_equal(colour_spectrum_rgb(&o, wl, s, n, rgb, NULL, &err), 0);
	for (int c = 0; c < 3; c++)
		assert_near(rgb[c], 1.0, 2e-3);
	/* Under E without adaptation a white reflector is not neutral (red > blue): adaptation matters. */
	o.illum = COLOUR_ILLUM_E;
	assert_int_equal(colour_spectrum_rgb(&o, wl, s, n, rgb, NULL, &err), 0);
	assert_true(rgb[0] > rgb[2] + 0.05);
	/* ABSOLUTE keeps sr⁻¹: Y of the flat spectrum equals its value. */
	colour_opts_default(&o);
	o.norm = COLOUR_NORM_ABSOLUTE;
	assert_int_equal(colour_spectrum_rgb(&o, wl, s, n, rgb, NULL, &err), 0);
	assert_near(colour_luminance(rgb), 1 / M_PI, 1e-4);
	/* The BRDF preset (for MERL and render callbacks) keeps sr⁻¹ and values above 1. */
	colour_opts_brdf(&o);
	for (size_t k = 0; k < n; k++)
		s[k] = 3.0;
	assert_int_equal(colour_spectrum_rgb(&o, wl, s, n, rgb, NULL, &err), 0);
	for (int c = 0; c < 3; c++)
		assert_near(rgb[c], 3.0, 3e-4);
	for (size_t k = 0; k < n; k++)
		s[k] = 1 / M_PI;
	colour_opts_default(&o);
	o.norm = COLOUR_NORM_ABSOLUTE;
	/* MAX_ALBEDO: albedo 0.5 is the largest, mapped to 0.8 → a flat albedo-0.5 BRDF gives 0.8. */
	o.norm = COLOUR_NORM_MAX_ALBEDO;
	o.max_albedo = 0.5;
	o.target = 0.8;
	for (size_t k = 0; k < n; k++)
		s[k] = 0.5 / M_PI;
	assert_int_equal(colour_spectrum_rgb(&o, wl, s, n, rgb, NULL, &err), 0);
	for (int c = 0; c < 3; c++)
		assert_near(rgb[c], 0.8, 1e-4);
	/* Gap ZERO: the flat reflector loses luminance below 450 nm (0.54 % under D65) and blue most. */
	colour_opts_default(&o);
	o.gap = COLOUR_GAP_ZERO;
	for (size_t k = 0; k < n; k++)
		s[k] = 1 / M_PI;
	assert_int_equal(colour_spectrum_rgb(&o, wl, s, n, rgb, NULL, &err), 0);
	assert_near(colour_luminance(rgb), 1 - 0.00543, 1e-3);
	assert_true(rgb[2] < rgb[0] - 0.05);
	free(wl);
	free(s);
}

/* Bin means of the piecewise-linear spectrum: a linear spectrum gives the same colour on any grid. */
static void test_grid_independence_and_linearity(void **state)
{
	(void)state;
	struct colour_opts o;
	colour_opts_default(&o);
	struct acq_err err = { 0 };
	size_t na = 300, nb = 2601;
	double *wa = malloc(na * sizeof(double)), *sa = malloc(na * sizeof(double));
	double *wb = malloc(nb * sizeof(double)), *sb = malloc(nb * sizeof(double));
	double *W = malloc(3 * nb * sizeof(double));
	assert_true(wa && sa && wb && sb && W);
	double slope = 0.001 * (urand() - 0.5), icpt = 0.2 + 0.3 * urand();
	double l = 450;
	for (size_t k = 0; k < na; k++) { /* random steps, mean ~2.2 nm, 450 .. ~1100 nm */
		wa[k] = l;
		l += 0.3 + 3.8 * urand();
		sa[k] = icpt + slope * (wa[k] - 450);
	}
	for (size_t k = 0; k < nb; k++) {
		wb[k] = 450 + 0.25 * (double)k;
		sb[k] = icpt + slope * (wb[k] - 450);
	}
	double ra[3], rb[3];
	assert_int_equal(colour_spectrum_rgb(&o, wa, sa, na, ra, NULL, &err), 0);
	assert_int_equal(colour_spectrum_rgb(&o, wb, sb, nb, rb, NULL, &err), 0);
	for (int c = 0; c < 3; c++)
		assert_near(ra[c], rb[c], 1e-9);
	/* W·s equals the whole chain with KEEP/linear, and W is linear: W·(2s) = 2 W·s. */
	assert_int_equal(colour_weights(&o, wb, nb, W, &err), 0);
	double lin[3];
	colour_apply_weights(W, nb, sb, lin);
	for (int c = 0; c < 3; c++)
		assert_near(lin[c], rb[c], 1e-12);
	free(wa);
	free(sa);
	free(wb);
	free(sb);
	free(W);
}

/* A narrow 500 nm spike is outside the sRGB gamut (R < 0): counted, clamped or desaturated. */
static void test_out_of_gamut(void **state)
{
	(void)state;
	double wl[3] = { 499, 500, 501 }, s[3] = { 0, 1, 0 };
	struct colour_opts o;
	colour_opts_default(&o);
	o.gap = COLOUR_GAP_ZERO;
	o.norm = COLOUR_NORM_ABSOLUTE;
	o.exposure = 50;
	struct acq_err err = { 0 };
	double W[9], lin[3], out[3];
	assert_int_equal(colour_weights(&o, wl, 3, W, &err), 0);
	colour_apply_weights(W, 3, s, lin);
	assert_true(lin[0] < 0);
	assert_true(lin[1] > 0);
	struct colour_stats st = { 0 };
	colour_finish(&o, lin, out, &st);
	assert_int_equal(st.out_of_gamut, 1);
	assert_near(out[0], 0, 0);
	assert_near(out[1], lin[1], 0);
	o.gamut = COLOUR_GAMUT_DESATURATE;
	colour_finish(&o, lin, out, &st);
	assert_int_equal(st.out_of_gamut, 2);
	assert_int_equal(st.n, 2);
	assert_near(fmin(out[0], fmin(out[1], out[2])), 0, 1e-12);
	assert_near(colour_luminance(out), colour_luminance(lin), 1e-12);
	/* in-gamut grey: not counted; NaN: zero output, counted as non-finite */
	double grey[3] = { 0.3, 0.3, 0.3 }, nan3[3] = { NAN, 0.1, 0.1 };
	colour_finish(&o, grey, out, &st);
	assert_int_equal(st.out_of_gamut, 2);
	colour_finish(&o, nan3, out, &st);
	assert_int_equal(st.nonfinite, 1);
	for (int c = 0; c < 3; c++)
		assert_true(out[c] == 0);
	/* a random batch: the count equals the number with a negative component */
	struct colour_stats st2 = { 0 };
	size_t expect = 0;
	for (int i = 0; i < 200; i++) {
		double v[3] = { urand() - 0.2, urand() - 0.2, urand() - 0.2 };
		expect += v[0] < 0 || v[1] < 0 || v[2] < 0;
		colour_finish(&o, v, out, &st2);
		assert_true(out[0] >= 0 && out[1] >= 0 && out[2] >= 0);
	}
	assert_int_equal(st2.out_of_gamut, expect);
}

static void test_dynamic_range(void **state)
{
	(void)state;
	struct colour_opts o;
	colour_opts_default(&o);
	struct colour_stats st = { 0 };
	double two[3] = { 2, 2, 2 }, out[3];
	colour_finish(&o, two, out, &st); /* KEEP */
	assert_near(out[0], 2, 0);
	o.range = COLOUR_RANGE_CLIP;
	colour_finish(&o, two, out, &st);
	assert_near(out[1], 1, 0);
	assert_int_equal(st.clipped, 1);
	o.range = COLOUR_RANGE_REINHARD;
	o.reinhard_white = 4;
	double w4[3] = { 4, 4, 4 }, half[3] = { 0.5, 0.5, 0.5 };
	colour_finish(&o, w4, out, &st); /* Lw maps to 1 */
	assert_near(out[0], 1, 1e-12);
	colour_finish(&o, half, out, &st); /* 0.5·(1 + 0.5/16)/1.5 */
	assert_near(out[2], 0.5 * (1 + 0.5 / 16) / 1.5, 1e-12);
	assert_int_equal(st.clipped, 1);
	o.srgb_encode = true; /* sRGB curve and inverse */
	for (int i = 0; i < 50; i++) {
		double v = urand();
		assert_near(colour_srgb_decode(colour_srgb_encode(v)), v, 1e-12);
	}
	assert_near(colour_srgb_encode(0.0031308), 0.0031308 * 12.92, 1e-12);
	assert_near(colour_srgb_encode(1), 1, 1e-12);
}

static void test_options_and_metadata(void **state)
{
	(void)state;
	struct colour_opts o;
	colour_opts_default(&o);
	struct acq_err err = { 0 };
	assert_int_equal(colour_opts_set(&o, "illum", "E", &err), 0);
	assert_int_equal(o.illum, COLOUR_ILLUM_E);
	assert_int_equal(colour_opts_set(&o, "range", "reinhard", &err), 0);
	assert_int_equal(colour_opts_set(&o, "white", "1", &err), 0);
	assert_int_equal(colour_opts_set(&o, "srgb_encode", "true", &err), 0);
	assert_true(o.srgb_encode);
	assert_int_equal(colour_opts_set(&o, "range", "wild", &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
	assert_int_equal(colour_opts_set(&o, "exposure", "-1", &err), -1);
	assert_int_equal(colour_opts_set(&o, "exposure", "nan", &err), -1);
	assert_int_equal(colour_opts_set(&o, "nosuch", "1", &err), -1);
	struct colour_stats st = { .n = 7, .out_of_gamut = 3 };
	char buf[1024];
	int len = colour_opts_json(&o, &st, buf, sizeof(buf));
	assert_true(len > 0 && (size_t)len < sizeof(buf));
	assert_non_null(strstr(buf, "\"illuminant\":\"E\""));
	assert_non_null(strstr(buf, "\"dynamic_range\":\"reinhard\""));
	assert_non_null(strstr(buf, "\"gap\":\"extend\""));
	assert_non_null(strstr(buf, "\"out_of_gamut\":3"));
	assert_true(buf[0] == '{' && buf[len - 1] == '}');
	o.exposure = NAN; /* JSON has no NaN: written as null */
	len = colour_opts_json(&o, NULL, buf, sizeof(buf));
	assert_non_null(strstr(buf, "\"exposure\":null"));
	assert_null(strstr(buf, ":nan"));
	assert_null(strstr(buf, ":-nan"));
	/* bad grids and bad options are errors, not crashes */
	double wl[3] = { 500, 500, 510 }, W[9];
	colour_opts_default(&o);
	assert_int_equal(colour_weights(&o, wl, 3, W, &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
	wl[1] = NAN;
	assert_int_equal(colour_weights(&o, wl, 3, W, &err), -1);
	assert_int_equal(colour_weights(&o, wl, 0, W, &err), -1);
	o.white = 0;
	wl[1] = 505;
	assert_int_equal(colour_weights(&o, wl, 3, W, &err), -1);
	o.white = 1;
	o.gamut = (enum colour_gamut)42;
	assert_int_equal(colour_weights(&o, wl, 3, W, &err), -1);
}

static void test_yaml_options(void **state)
{
	(void)state;
	static const char text[] = "colour:\n  illum: E\n  gap: zero\n  norm: max_albedo\n  max_albedo: 0.6\n"
				   "  range: reinhard\n  srgb_encode: true\n";
	struct acq_err err = { 0 };
	struct yc_doc *doc = NULL;
	assert_int_equal(yc_load_string("c.yaml", text, strlen(text), &doc, &err), 0);
	struct colour_opts o;
	colour_opts_default(&o);
	assert_int_equal(colour_opts_from_yaml(yc_get(yc_root(doc), "colour"), &o, &err), 0);
	assert_int_equal(o.illum, COLOUR_ILLUM_E);
	assert_int_equal(o.gap, COLOUR_GAP_ZERO);
	assert_int_equal(o.norm, COLOUR_NORM_MAX_ALBEDO);
	assert_near(o.max_albedo, 0.6, 0);
	assert_int_equal(o.range, COLOUR_RANGE_REINHARD);
	assert_true(o.srgb_encode);
	assert_int_equal(o.adapt, COLOUR_ADAPT_BRADFORD); /* untouched default */
	yc_free(doc);
	static const char bad[] = "colour:\n  illum: D65\n  gamut: squash\n";
	assert_int_equal(yc_load_string("b.yaml", bad, strlen(bad), &doc, &err), 0);
	assert_int_equal(colour_opts_from_yaml(yc_get(yc_root(doc), "colour"), &o, &err), -1);
	assert_non_null(strstr(err.msg, "b.yaml:3:"));
	assert_non_null(strstr(err.msg, "squash"));
	yc_free(doc);
	static const char unknown[] = "colour:\n  illuminant: D65\n";
	assert_int_equal(yc_load_string("u.yaml", unknown, strlen(unknown), &doc, &err), 0);
	assert_int_equal(colour_opts_from_yaml(yc_get(yc_root(doc), "colour"), &o, &err), -1);
	assert_non_null(strstr(err.msg, "illuminant"));
	yc_free(doc);
	static const char neg[] = "colour:\n  exposure: -2\n";
	assert_int_equal(yc_load_string("n.yaml", neg, strlen(neg), &doc, &err), 0);
	assert_int_equal(colour_opts_from_yaml(yc_get(yc_root(doc), "colour"), &o, &err), -1);
	assert_non_null(strstr(err.msg, "n.yaml:2:"));
	yc_free(doc);
}

int main(void)
{
	const char *s = getenv("ACQ_SEED");
	seed = s ? (unsigned)strtoul(s, NULL, 10) : 1u;
	printf("test_recon_colour: ACQ_SEED=%u\n", seed);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_tables_reproduce_readme_checks),
		cmocka_unit_test(test_chain_d65_white),
		cmocka_unit_test(test_white_reflector_is_white),
		cmocka_unit_test(test_grid_independence_and_linearity),
		cmocka_unit_test(test_out_of_gamut),
		cmocka_unit_test(test_dynamic_range),
		cmocka_unit_test(test_options_and_metadata),
		cmocka_unit_test(test_yaml_options),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
