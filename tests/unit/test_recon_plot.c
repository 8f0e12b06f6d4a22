/* Unit tests for recon/plot.c: the DHR PNG decodes (libpng), has the asked size, curves sit where the data say. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "recon/plot.h"

/* fontconfig (behind cairo's text) keeps process-lifetime caches that LeakSanitizer reports; they are not
 * ours. This hook is read by LSan only in sanitizer builds. */
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void)
{
	return "leak:libfontconfig.so\n";
}

static unsigned seed;
static char dir[512];

static double urand(void)
{
	seed = seed * 1103515245u + 12345u;
	return ((seed >> 8) & 0xffffff) / (double)0x1000000;
}

struct img {
	png_image im;
	unsigned char *px; /* RGB, 3 bytes per pixel */
};

static void load_png(const char *path, struct img *g)
{
	memset(g, 0, sizeof(*g));
	g->im.version = PNG_IMAGE_VERSION;
	assert_true(png_image_begin_read_from_file(&g->im, path));
	g->im.format = PNG_FORMAT_RGB;
	g->px = malloc(PNG_IMAGE_SIZE(g->im));
	assert_non_null(g->px);
	assert_true(png_image_finish_read(&g->im, NULL, g->px, 0, NULL));
}

static int close_to(const unsigned char *p, const double rgb[3], int tol)
{
	for (int c = 0; c < 3; c++)
		if (abs((int)p[c] - (int)lround(rgb[c] * 255)) > tol)
			return 0;
	return 1;
}

/* Is a pixel of colour rgb within ±rows rows of (x, y)? */
static int colour_near(const struct img *g, int x, int y, int rows, const double rgb[3])
{
	for (int dy = -rows; dy <= rows; dy++) {
		int yy = y + dy;
		if (yy < 0 || yy >= (int)g->im.height || x < 0 || x >= (int)g->im.width)
			continue;
		if (close_to(g->px + 3 * ((size_t)yy * g->im.width + (size_t)x), rgb, 8))
			return 1;
	}
	return 0;
}

static void test_curves_at_data_locations(void **state)
{
	(void)state;
	enum { N = 651, NC = 3 };
	static double wl[N], y[NC][N], s[NC][N], ry[N], rs[N];
	double base[NC], slope[NC];
	for (int c = 0; c < NC; c++) {
		base[c] = 0.15 + 0.2 * c + 0.05 * urand();
		slope[c] = (urand() - 0.5) * 2e-4;
	}
	for (int k = 0; k < N; k++) {
		wl[k] = 450 + k;
		for (int c = 0; c < NC; c++) {
			y[c][k] = base[c] + slope[c] * (wl[k] - 450);
			s[c][k] = 0.01;
		}
		ry[k] = 0.9 + 0.02 * sin(wl[k] / 50);
		rs[k] = 0.015;
	}
	struct plot_curve cv[NC] = {
		{ "\xce\xb8i = 8\xc2\xb0", wl, y[0], s[0], N },
		{ "\xce\xb8i = 30\xc2\xb0", wl, y[1], s[1], N },
		{ "\xce\xb8i = 60\xc2\xb0", wl, y[2], NULL, N },
	};
	struct plot_curve ref = { "spectrophotometer", wl, ry, rs, N };
	struct plot_dhr_opts o;
	plot_dhr_opts_default(&o);
	o.width = 640 + (int)(urand() * 200);
	o.height = 400 + (int)(urand() * 100);
	o.title = "DHR test";
	char p[600];
	snprintf(p, sizeof(p), "%s/dhr.png", dir);
	struct plot_frame f;
	struct acq_err err = { 0 };
	assert_int_equal(plot_dhr_png(p, cv, NC, &ref, &o, &f, &err), 0);
	assert_true(f.x_min == 450 && f.x_max == 1100);
	assert_true(f.y_min == 0 && f.y_max >= 0.9 + 0.02 + 2 * 0.015);

	struct img g;
	load_png(p, &g);
	printf("plot %s: %u x %u, frame [%g %g] x [%g %g] px (%g,%g)-(%g,%g)\n", p, g.im.width, g.im.height, f.x_min,
	       f.x_max, f.y_min, f.y_max, f.px_left, f.px_top, f.px_right, f.px_bottom);
	assert_int_equal(g.im.width, o.width);
	assert_int_equal(g.im.height, o.height);

	/* Along each curve, left 60 % of the plot (the legend is top right): the curve colour sits at the
	 * data → pixel location (±2 rows: line width 2 plus antialiasing), and NOT 20 px above or below. */
	int hits = 0, probes = 0;
	for (int c = 0; c < NC + 1; c++) {
		double col[3];
		if (c < NC)
			plot_curve_colour((size_t)c, col);
		else
			plot_reference_colour(col);
		const double *yy = c < NC ? y[c] : ry;
		for (int k = 20; k < N * 6 / 10; k += 37) {
			int px = (int)floor(plot_x_to_px(&f, wl[k]));
			int py = (int)floor(plot_y_to_px(&f, yy[k]));
			probes++;
			hits += colour_near(&g, px, py, 2, col);
			assert_false(colour_near(&g, px, py - 20, 2, col));
			assert_false(colour_near(&g, px, py + 20, 2, col));
		}
	}
	printf("curve pixels found at %d of %d probes\n", hits, probes);
	assert_int_equal(hits, probes);
	/* The mapping sends the axis range to the plot frame's edges, and the frame is drawn there (black
	 * 1 px lines just inside px_left/px_top/px_right/px_bottom): curves are located relative to the axes. */
	assert_true(fabs(plot_x_to_px(&f, f.x_min) - f.px_left) < 1e-9);
	assert_true(fabs(plot_x_to_px(&f, f.x_max) - f.px_right) < 1e-9);
	assert_true(fabs(plot_y_to_px(&f, f.y_min) - f.px_bottom) < 1e-9);
	assert_true(fabs(plot_y_to_px(&f, f.y_max) - f.px_top) < 1e-9);
	{
		const double black[3] = { 0, 0, 0 };
		int midx = (int)((f.px_left + f.px_right) / 4), midy = (int)((f.px_top + f.px_bottom) / 2);
		assert_true(close_to(g.px + 3 * ((size_t)f.px_top * g.im.width + (size_t)midx), black, 60));
		assert_true(close_to(g.px + 3 * ((size_t)(f.px_bottom - 1) * g.im.width + (size_t)midx), black, 60));
		assert_true(close_to(g.px + 3 * ((size_t)midy * g.im.width + (size_t)f.px_left), black, 60));
		assert_true(close_to(g.px + 3 * ((size_t)midy * g.im.width + (size_t)(f.px_right - 1)), black, 60));
	}
	/* background far from everything is white; the frame's bottom-left corner is black */
	assert_true(close_to(g.px + 3 * 2, (double[3]){ 1, 1, 1 }, 0));
	int fx = (int)f.px_left, fy = (int)f.px_bottom - 1;
	assert_true(close_to(g.px + 3 * ((size_t)fy * g.im.width + (size_t)fx), (double[3]){ 0, 0, 0 }, 60));
	/* Bands (±2σ = ±0.02): rows between the line and the band edge are tinted (fill + hatch) for the
	 * curves with σ, and plain (white or grey grid) for the curve without σ. */
	for (int c = 0; c < NC; c++) {
		int tinted = 0, cols = 0;
		for (int k = 30; k < N / 2; k += 3) {
			int px = (int)floor(plot_x_to_px(&f, wl[k]));
			double py = plot_y_to_px(&f, y[c][k]), half = plot_y_to_px(&f, 0) - plot_y_to_px(&f, 0.02);
			for (int side = -1; side <= 1; side += 2) {
				int yy = (int)floor(py + side * 0.7 * half);
				const unsigned char *q = g.px + 3 * ((size_t)yy * g.im.width + (size_t)px);
				int mx = q[0] > q[1] ? (q[0] > q[2] ? q[0] : q[2]) : (q[1] > q[2] ? q[1] : q[2]);
				int mn = q[0] < q[1] ? (q[0] < q[2] ? q[0] : q[2]) : (q[1] < q[2] ? q[1] : q[2]);
				tinted += mx - mn > 8;
				cols++;
			}
		}
		printf("curve %d: %d of %d band probes tinted\n", c, tinted, cols);
		if (cv[c].sigma)
			assert_true(tinted == cols);
		else
			assert_int_equal(tinted, 0);
	}
	free(g.px);
	unlink(p);
}

/* Is a pixel within ±rows rows of (x, y) dark (every channel < 90: the residual line, 0.1 grey 1.5 px wide with its
 * antialiasing; the panel's 0 line is 0.4 grey = 102, its ±2 lines red)? */
static int dark_near(const struct img *g, int x, int y, int rows)
{
	for (int yy = y - rows; yy <= y + rows; yy++) {
		if (yy < 0 || yy >= (int)g->im.height)
			continue;
		const unsigned char *q = g->px + 3 * ((size_t)yy * g->im.width + (size_t)x);
		if (q[0] < 90 && q[1] < 90 && q[2] < 90)
			return 1;
	}
	return 0;
}

/*
 * The paper's Fig. 4 as `brdf-recon dhr --reference --plot` draws it (issue 13 item 7): the reference's filled
 * ±2σ band, and a residual panel below the axes with (model − reference)/σ, lines at 0 and ±2. Located from the
 * image alone (the panel's own mapping is not exported): the ±2 lines (red) and the 0 line (grey) are found below
 * the DHR axes, they must be evenly spaced (one σ scale), and the residual curve (dark grey) must sit where its
 * value says on that scale (±2 rows), above the 0 line for positive residuals, and not 15 rows off.
 */
static void test_reference_band_and_residual_panel(void **state)
{
	(void)state;
	enum { N = 651 };
	static double wl[N], y[N], s[N], ry[N], rs[N], rz[N];
	double ph = 6.28 * urand();
	for (int k = 0; k < N; k++) {
		wl[k] = 450 + k;
		y[k] = 0.2 + 1e-4 * k; /* clear of the reference band */
		s[k] = 0.005;
		ry[k] = 0.45 + 0.01 * sin(wl[k] / 50);
		rs[k] = 0.02;
		rz[k] = 2.5 * sin(wl[k] / 40 + ph); /* within ±3: the panel's range stays ±3 */
	}
	struct plot_curve cv = { "\xce\xb8i = 8\xc2\xb0", wl, y, s, N }, ref = { "reference", wl, ry, rs, N };
	struct plot_curve res = { "(model \xe2\x88\x92 ref) / \xcf\x83", wl, rz, NULL, N };
	struct plot_dhr_opts o;
	plot_dhr_opts_default(&o);
	o.width = 800 + (int)(urand() * 100);
	o.height = 700 + (int)(urand() * 60);
	o.residual = &res;
	char p[600];
	snprintf(p, sizeof(p), "%s/dhr-ref.png", dir);
	struct plot_frame f;
	struct acq_err err = { 0 };
	assert_int_equal(plot_dhr_png(p, &cv, 1, &ref, &o, &f, &err), 0);
	struct img g;
	load_png(p, &g);
	assert_int_equal(g.im.height, o.height);

	/* the reference's band: rows between its line and ±2σ are tinted (the filled green) */
	int tinted = 0, cols = 0;
	for (int k = 30; k < N / 2; k += 7) {
		int px = (int)floor(plot_x_to_px(&f, wl[k]));
		double py = plot_y_to_px(&f, ry[k]), half = plot_y_to_px(&f, 0) - plot_y_to_px(&f, 2 * rs[k]);
		for (int side = -1; side <= 1; side += 2) {
			const unsigned char *q = g.px + 3 * ((size_t)floor(py + side * 0.6 * half) * g.im.width + (size_t)px);
			tinted += q[1] > q[0] + 8 && q[1] > q[2] + 8; /* green dominates */
			cols++;
		}
	}
	printf("reference band: %d of %d probes tinted green\n", tinted, cols);
	assert_int_equal(tinted, cols);

	/* the panel's lines at +2, 0, −2 below the DHR axes: the rows red (grey for 0) across most of the width */
	const double red[3] = { 0.75, 0.3, 0.3 }, grey[3] = { 0.4, 0.4, 0.4 };
	double r_plus = -1, r_minus = -1, r_zero = -1;
	int x0 = (int)f.px_left + 5, x1 = (int)f.px_right - 5, best = 0;
	for (int yy = (int)f.px_bottom + 2; yy < (int)g.im.height; yy++) {
		int nr = 0, ng = 0;
		for (int x = x0; x < x1; x++) {
			nr += close_to(g.px + 3 * ((size_t)yy * g.im.width + (size_t)x), red, 10);
			ng += close_to(g.px + 3 * ((size_t)yy * g.im.width + (size_t)x), grey, 10);
		}
		if (nr > (x1 - x0) / 2) {
			if (r_plus < 0)
				r_plus = yy;
			r_minus = yy;
		}
		if (ng > (x1 - x0) / 2 && ng > best) {
			best = ng;
			r_zero = yy;
		}
	}
	printf("residual panel: rows +2 %.1f, 0 %.1f, -2 %.1f (DHR axes end at %.0f)\n", r_plus, r_zero, r_minus,
	       f.px_bottom);
	assert_true(r_plus > f.px_bottom && r_zero > r_plus && r_minus > r_zero);
	double step = (r_minus - r_plus) / 4; /* pixels per σ */
	assert_true(fabs((r_zero - r_plus) - 2 * step) < 1.5 && step > 5);
	int hits = 0, probes = 0;
	for (int k = 25; k < N * 45 / 100; k += 13) {
		int px = (int)floor(plot_x_to_px(&f, wl[k]));
		int py = (int)floor(r_zero - rz[k] * step);
		probes++;
		hits += dark_near(&g, px, py, 2);
		for (int off = -15; off <= 15; off += 30) /* not 15 rows off (inside the panel's frame, ±2.8σ) */
			if (fabs(py + off - r_zero) < 2.8 * step)
				assert_false(dark_near(&g, px, py + off, 1));
	}
	printf("residual curve found at %d of %d probes\n", hits, probes);
	assert_int_equal(hits, probes);
	free(g.px);
	unlink(p);
}

static void test_bad_input_is_an_error(void **state)
{
	(void)state;
	char p[600];
	snprintf(p, sizeof(p), "%s/bad.png", dir);
	double wl[3] = { 500, 600, 700 }, y[3] = { NAN, INFINITY, 0.5 }, s[3] = { -1, NAN, 0.1 };
	struct plot_curve c = { "x", wl, y, s, 3 };
	struct acq_err err = { 0 };
	struct plot_dhr_opts o;
	plot_dhr_opts_default(&o);
	/* non-finite points are skipped, not fatal */
	assert_int_equal(plot_dhr_png(p, &c, 1, NULL, &o, NULL, &err), 0);
	assert_int_equal(access(p, F_OK), 0);
	unlink(p);
	assert_int_equal(plot_dhr_png(p, NULL, 0, NULL, &o, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
	o.width = 10;
	assert_int_equal(plot_dhr_png(p, &c, 1, NULL, &o, NULL, &err), -1);
	plot_dhr_opts_default(&o);
	o.y_min = 1;
	o.y_max = 1;
	assert_int_equal(plot_dhr_png(p, &c, 1, NULL, &o, NULL, &err), -1);
	o.y_min = NAN;
	o.y_max = NAN;
	o.band_k = 0;
	assert_int_equal(plot_dhr_png(p, &c, 1, NULL, &o, NULL, &err), -1);
	struct plot_curve empty = { "e", wl, y, s, 0 };
	plot_dhr_opts_default(&o);
	assert_int_equal(plot_dhr_png(p, &empty, 1, NULL, &o, NULL, &err), -1);
	assert_int_equal(plot_dhr_png("/nonexistent-dir/x.png", &c, 1, NULL, &o, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_IO);
	assert_int_equal(access(p, F_OK), -1);
}

int main(void)
{
	const char *s = getenv("ACQ_SEED");
	seed = s ? (unsigned)strtoul(s, NULL, 10) : 1u;
	printf("test_recon_plot: ACQ_SEED=%u\n", seed);
	const char *tmp = getenv("TMPDIR");
	snprintf(dir, sizeof(dir), "%s/test_recon_plot.XXXXXX", tmp && *tmp ? tmp : "/tmp");
	if (!mkdtemp(dir)) {
		perror("mkdtemp");
		return 1;
	}
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_curves_at_data_locations),
		cmocka_unit_test(test_reference_band_and_residual_panel),
		cmocka_unit_test(test_bad_input_is_an_error),
	};
	int rc = cmocka_run_group_tests(tests, NULL, NULL);
	rmdir(dir);
	return rc;
}
