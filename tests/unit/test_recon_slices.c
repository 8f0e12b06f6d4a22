/* Unit tests for recon/slices.c's wavelength selection (slices_weights): one wavelength is the linear blend of
 * its two neighbouring channels, a band the trapezoid weights of the channels inside it (the nearest channel when
 * it is narrower than the spacing), weights sum to 1, and selections outside the model's range are refused.
 * Since session 18: the model beyond the largest measured θo is marked (the drawn pixels, the CSV column, the
 * result), and the CSV is written through config/acq_out (a failed write leaves the old file). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <cmocka.h>
#include <cairo.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include "recon/plot.h"
#include "recon/slices.h"
#include "recon/slices_int.h"
#include "recon_test_util.h"

/* fontconfig (behind cairo's text) keeps process-lifetime caches that LeakSanitizer reports; they are not
 * ours (as test_recon_plot). This hook is read by LSan only in sanitizer builds. */
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void)
{
	return "leak:libfontconfig.so\n";
}

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

/* Colour distance of pixel (x, y) of an RGB24 surface to c (0..1 per channel, largest component difference). */
static double pix_dist(cairo_surface_t *sf, int x, int y, const double c[3])
{
	const unsigned char *d = cairo_image_surface_get_data(sf);
	uint32_t v;
	memcpy(&v, d + (size_t)y * (size_t)cairo_image_surface_get_stride(sf) + 4 * (size_t)x, 4);
	double p[3] = { ((v >> 16) & 255) / 255.0, ((v >> 8) & 255) / 255.0, (v & 255) / 255.0 };
	return fmax(fabs(p[0] - c[0]), fmax(fabs(p[1] - c[1]), fabs(p[2] - c[2])));
}

/* The drawing: a flat model (f = 1, band 0.5..2) whose measured range ends at 60°. Read back from the PNG: inside
 * ±60° every column carries the curve's colour on the curve's row (a solid line); beyond, the dotted line leaves
 * gaps, and the band is paler. Seen failing before the marking (every column beyond 60° had the curve: 196 of 196). */
static void test_draw_beyond_measured(void **state)
{
	(void)state;
	enum { NP = 181 };
	double x[NP], f[NP], lo[NP], hi[NP];
	for (int i = 0; i < NP; i++) {
		x[i] = -90 + i;
		f[i] = 1;
		lo[i] = 0.5;
		hi[i] = 2;
	}
	struct slices_series S = { .theta = 0.5, .np = NP, .x = x, .f = f, .lo = lo, .hi = hi, .xmax = 60 };
	struct slices_opts o;
	slices_opts_default(&o);
	o.wl_lo = o.wl_hi = 600;
	struct slices_frame fr = { 80, 40, o.width - 200.0, o.height - 60.0, -90, 90, -1, 1 };
	char png[] = "/tmp/test_recon_slices_XXXXXX";
	int fd = mkstemp(png);
	assert_true(fd >= 0);
	close(fd);
	struct acq_err e = { 0 };
	assert_int_equal(slices_draw_inplane(&S, 1, &o, &fr, png, &e), 0);
	cairo_surface_t *sf = cairo_image_surface_create_from_png(png);
	unlink(png);
	assert_int_equal(cairo_surface_status(sf), CAIRO_STATUS_SUCCESS);
	double c[3];
	plot_curve_colour(0, c);
	int ycurve = (int)lround(fr.b - 0.5 * (fr.b - fr.t)); /* log10 1 = 0, halfway up [-1, 1] */
	int yband = (int)lround(fr.b - (log10(1.6) + 1) / 2 * (fr.b - fr.t));
	int in_cols = 0, in_hit = 0, out_cols = 0, out_hit = 0;
	double band_in = 0, band_out = 0;
	for (int X = (int)fr.l + 2; X < (int)fr.r - 2; X++) {
		double a = fr.x0 + (X + 0.5 - fr.l) / (fr.r - fr.l) * (fr.x1 - fr.x0);
		if (fabs(fabs(a) - 60) < 2 || fabs(a) > 88 || fmod(fabs(a) + 0.5, 15) < 1.5)
			continue; /* the limit itself, the frame, the 15° grid lines */
		int hit = 0;
		for (int y = ycurve - 1; y <= ycurve + 1; y++)
			hit |= pix_dist(sf, X, y, c) < 0.15;
		if (fabs(a) < 60) {
			in_cols++;
			in_hit += hit;
			band_in += pix_dist(sf, X, yband, (double[]){ 1, 1, 1 });
		} else {
			out_cols++;
			out_hit += hit;
			band_out += pix_dist(sf, X, yband, (double[]){ 1, 1, 1 });
		}
	}
	band_in /= in_cols;
	band_out /= out_cols;
	printf("curve pixels: %d of %d columns inside the measured range, %d of %d beyond; band's distance from white "
	       "%.3f inside, %.3f beyond\n", in_hit, in_cols, out_hit, out_cols, band_in, band_out);
	assert_int_equal(in_hit, in_cols);
	assert_true(out_cols > 20 && out_hit < 0.75 * out_cols);
	assert_true(band_out > 0.01 && band_out < 0.6 * band_in);
	cairo_surface_destroy(sf);
}

/* A fitted model and its samples (θo 5..80° at three incidences): the result and the CSV say which model points lie
 * beyond 80°, and the CSV goes through acq_out: with the file size limited (RLIMIT_FSIZE, so the write fails
 * midway) the old file stays whole. Seen failing with fopen: the file was left truncated. */
static void test_fit_beyond_and_csv(void **state)
{
	(void)state;
	struct recon_samples s;
	rt_samples_grid(&s, 3, 4, 4, 5, 0.01, 1.0);
	struct recon_fit_opts fo;
	recon_fit_opts_default(&fo);
	fo.trend = RECON_TREND_NONE;
	struct recon_model *m = NULL;
	struct acq_err e = { 0 };
	assert_int_equal(recon_fit(&s, &fo, &m, &e), 0);
	struct slices_opts o;
	slices_opts_default(&o);
	o.wl_lo = o.wl_hi = 612.5;
	char csv[] = "/tmp/test_recon_slices_csv_XXXXXX";
	int fd = mkstemp(csv);
	assert_true(fd >= 0);
	close(fd);
	struct slices_result r;
	assert_int_equal(slices_plot(m, &s, NULL, 0, &o, "/dev/null", NULL, csv, &r, &e), 0);
	assert_int_equal(r.nth, 3);
	for (size_t t = 0; t < r.nth; t++) {
		assert_true(fabs(r.theta_o_max[t] - 80) < 1e-9);
		assert_int_equal(r.beyond[t], 20); /* |θo| = 81..89, 89.5 on each side */
	}
	FILE *f = fopen(csv, "r");
	assert_non_null(f);
	char line[256];
	size_t rows = 0, marked = 0;
	assert_non_null(fgets(line, sizeof line, f));
	assert_string_equal(line, "kind,theta_i,theta_o_signed,value,lo,hi,beyond_data\n");
	while (fgets(line, sizeof line, f)) {
		char kind[16];
		double ti, to, v, l, h;
		int b;
		assert_int_equal(sscanf(line, "%15[^,],%lf,%lf,%lf,%lf,%lf,%d", kind, &ti, &to, &v, &l, &h, &b), 7);
		assert_int_equal(b, !strcmp(kind, "model") && fabs(to) > 80);
		rows++;
		marked += (size_t)b;
	}
	long size = ftell(f);
	fclose(f);
	assert_true(rows > 3 * 181 && marked == 60 && size > 8192);
	/* a write that fails midway leaves the old file as it was */
	f = fopen(csv, "w");
	assert_non_null(f);
	fputs("old,content\n", f);
	fclose(f);
	struct rlimit old_lim, lim = { 4096, 4096 };
	assert_int_equal(getrlimit(RLIMIT_FSIZE, &old_lim), 0);
	lim.rlim_max = old_lim.rlim_max;
	void (*old_sig)(int) = signal(SIGXFSZ, SIG_IGN);
	assert_int_equal(setrlimit(RLIMIT_FSIZE, &lim), 0);
	int rc = slices_plot(m, &s, NULL, 0, &o, "/dev/null", NULL, csv, &r, &e);
	assert_int_equal(setrlimit(RLIMIT_FSIZE, &old_lim), 0);
	signal(SIGXFSZ, old_sig);
	printf("CSV write under a 4 KiB file-size limit: rc %d (%s)\n", rc, rc ? e.msg : "");
	assert_int_equal(rc, -1);
	f = fopen(csv, "r");
	assert_non_null(f);
	assert_non_null(fgets(line, sizeof line, f));
	assert_string_equal(line, "old,content\n");
	assert_null(fgets(line, sizeof line, f));
	fclose(f);
	unlink(csv);
	/* a directory is refused with its name */
	assert_int_equal(slices_plot(m, &s, NULL, 0, &o, "/dev/null", NULL, "/tmp", &r, &e), -1);
	assert_non_null(strstr(e.msg, "/tmp"));
	recon_model_free(m);
	csvio_samples_free(&s);
}

int main(void)
{
	rt_seed();
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_one_wavelength),
		cmocka_unit_test(test_band),
		cmocka_unit_test(test_draw_beyond_measured),
		cmocka_unit_test(test_fit_beyond_and_csv),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
