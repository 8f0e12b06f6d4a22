/* Unit tests for the HDR preview path: recon/sky.c (importance sampling of a lat-long sky and a sun), the
 * render's multiple importance sampling (white furnace, a sun on a Lambertian sphere against the analytic
 * answer, the highlight of a glossy lobe where the mirror geometry puts it, thread-count independence),
 * recon/exrio.c (bit-exact round trip, refusals) and the sRGB-tagged PNG of recon/pngio.c. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cmocka.h>

#include "recon/exrio.h"
#include "recon/pngio.h"
#include "recon/render.h"
#include "recon/sky.h"

static char dir[512];
static uint64_t seed;

static int lambert(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	(void)wi;
	(void)wo;
	const double *rho = ctx;
	for (int c = 0; c < 3; c++)
		rgb[c] = rho[c] / M_PI;
	return 0;
}

/* GGX microfacet lobe (alpha 0.1) with a constant Fresnel: a sharp highlight. */
static int glossy(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	(void)ctx;
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] }, l = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	double a2 = 0.01, ch = h[2] / l, t = ch * ch * (a2 - 1) + 1, D = a2 / (M_PI * t * t);
	double v = 0.04 * D / (4 * wi[2] * wo[2] + 1e-9) + 0.02;
	for (int c = 0; c < 3; c++)
		rgb[c] = v;
	return 0;
}

static void test_sky_pdf(void **state)
{
	(void)state;
	struct sky_opts so;
	sky_opts_default(&so);
	struct sky *s;
	assert_int_equal(sky_procedural(&so, &s, NULL), 0);
	/* the map pdf integrates to 1 over the sphere (midpoint rule in cos θ × φ) */
	double sum = 0;
	int M = 400;
	for (int a = 0; a < M; a++)
		for (int b = 0; b < 2 * M; b++) {
			double y = 1 - 2 * (a + 0.5) / M, r = sqrt(1 - y * y), p = 2 * M_PI * (b + 0.5) / (2 * M);
			double d[3] = { r * cos(p), y, r * sin(p) };
			sum += sky_pdf_map(s, d) * (2.0 / M) * (2 * M_PI / (2 * M));
		}
	printf("integral of the sky map's pdf over the sphere: %.5f\n", sum);
	assert_true(fabs(sum - 1) < 2e-3);
	/* a sample's pdf is the pdf of its direction; the sun's cone pdf likewise */
	for (int k = 0; k < 1000; k++) {
		double u[2] = { (k + 0.5) / 1000, fmod(k * 0.618034, 1) }, d[3];
		double p = sky_sample_map(s, u, d);
		assert_true(fabs(p - sky_pdf_map(s, d)) <= 1e-6 * p);
		double ps = sky_sample_sun(s, u, d);
		assert_true(ps > 0 && fabs(ps - sky_pdf_sun(s, d)) <= 1e-9 * ps);
	}
	/* the sun disc's irradiance at normal incidence is the asked one: ∫ L cos over the cone */
	double e = 0;
	for (int k = 0; k < 20000; k++) {
		double u[2] = { (k + 0.5) / 20000, fmod(k * 0.618034, 1) }, d[3];
		double p = sky_sample_sun(s, u, d);
		double cs = d[0] * s->sun_dir[0] + d[1] * s->sun_dir[1] + d[2] * s->sun_dir[2];
		e += s->sun_L[1] * cs / p / 20000;
	}
	printf("sun irradiance %.5f (asked %.5f)\n", e, so.sun_rgb[1]);
	assert_true(fabs(e / so.sun_rgb[1] - 1) < 2e-3);
	sky_free(s);
}

static void render_lin(const struct render_opts *o, merl_rgb_fn fn, void *ctx, float *lin)
{
	struct acq_err e = { 0 };
	int rc = render_sphere(o, fn, ctx, NULL, lin, NULL, &e);
	if (rc)
		printf("render: %s\n", e.msg);
	assert_int_equal(rc, 0);
}

static void test_furnace_and_sun(void **state)
{
	(void)state;
	struct sky_opts so;
	sky_opts_default(&so);
	for (int c = 0; c < 3; c++)
		so.zenith[c] = so.horizon[c] = so.ground[c] = 1, so.sun_rgb[c] = 0;
	so.glow = 0;
	struct sky *s;
	assert_int_equal(sky_procedural(&so, &s, NULL), 0);
	struct render_opts o;
	render_opts_default(&o);
	o.width = o.height = 48;
	o.sky = s;
	o.spp = 256;
	o.seed = seed;
	double rho[3] = { 0.8, 0.8, 0.8 };
	float *lin = malloc(48 * 48 * 3 * sizeof *lin);
	assert_non_null(lin);
	render_lin(&o, lambert, rho, lin);
	/* a white furnace: every pixel of a Lambertian sphere in a uniform sky of radiance 1 is ρ */
	double mean = 0, worst = 0, ss = 0;
	int n = 0;
	for (int j = 0; j < 48; j++)
		for (int i = 0; i < 48; i++) {
			double nn[3];
			if (!render_pixel_normal(&o, i, j, nn))
				continue;
			double v = lin[(j * 48 + i) * 3 + 1];
			mean += v;
			ss += (v - 0.8) * (v - 0.8);
			worst = fmax(worst, fabs(v - 0.8));
			n++;
		}
	mean /= n;
	double rms = sqrt(ss / n);
	printf("furnace: mean %.5f (0.8), RMS pixel error %.4f, largest %.4f (256 spp)\n", mean, rms, worst);
	assert_true(fabs(mean - 0.8) < 5 * rms / sqrt(n)); /* unbiased: the mean of ~1800 independent pixels */
	assert_true(rms < 0.06 && worst < 8 * rms);        /* noise, and no outlier (no sampling hole) */
	sky_free(s);
	/* a sun alone on the Lambertian sphere: L = ρ/π · E · max(0, n·s) */
	sky_opts_default(&so);
	for (int c = 0; c < 3; c++)
		so.zenith[c] = so.horizon[c] = so.ground[c] = 0;
	so.glow = 0;
	assert_int_equal(sky_procedural(&so, &s, NULL), 0);
	o.sky = s;
	o.spp = 64;
	render_lin(&o, lambert, rho, lin);
	worst = 0;
	int wi_ = 0, wj_ = 0;
	double wv = 0, we = 0;
	for (int j = 0; j < 48; j++)
		for (int i = 0; i < 48; i++) {
			double nn[3];
			if (!render_pixel_normal(&o, i, j, nn))
				continue;
			/* exact: the disc's radiance times max(0, n·d) over the cone (fine deterministic quadrature, so the
			 * terminator, where part of the disc is below the local horizon, is right too) */
			double ex = 0;
			for (int q = 0; q < 4096; q++) {
				double u[2] = { (q % 64 + 0.5) / 64, (q / 64 + 0.5) / 64 }, d[3];
				double pd = sky_sample_sun(s, u, d);
				ex += 0.8 / M_PI * s->sun_L[0] * fmax(0, nn[0] * d[0] + nn[1] * d[1] + nn[2] * d[2]) / pd / 4096;
			}
			/* 8 sun samples: cos varies by < 0.03 over the 1.5-deg disc (< 1 %), the lit fraction near the
			 * terminator is binomial (measured up to 1.55 % over 8 seeds); 2.5 % of the full irradiance */
			double tol = 0.025 * so.sun_rgb[0] * 0.8 / M_PI;
			if (fabs(lin[(j * 48 + i) * 3] - ex) / tol > worst) {
				worst = fabs(lin[(j * 48 + i) * 3] - ex) / tol;
				wi_ = i;
				wj_ = j;
				wv = lin[(j * 48 + i) * 3];
				we = ex;
			}
		}
	printf("sun on a Lambertian sphere: largest error / tolerance %.3f (pixel %d %d: %.5g, exact %.5g)\n", worst, wi_,
	       wj_, wv, we);
	assert_true(worst <= 1);
	sky_free(s);
	free(lin);
}

static void test_highlight_and_threads(void **state)
{
	(void)state;
	struct sky_opts so;
	sky_opts_default(&so);
	struct sky *s;
	assert_int_equal(sky_procedural(&so, &s, NULL), 0);
	struct render_opts o;
	render_opts_default(&o);
	o.width = o.height = 96;
	o.sky = s;
	o.spp = 64;
	o.lobe_alpha = 0.1;
	o.seed = seed;
	float *a = malloc(96 * 96 * 3 * sizeof *a), *b = malloc(96 * 96 * 3 * sizeof *b);
	assert_non_null(a);
	assert_non_null(b);
	render_lin(&o, glossy, NULL, a);
	o.threads = 3;
	render_lin(&o, glossy, NULL, b);
	assert_memory_equal(a, b, 96 * 96 * 3 * sizeof *a);
	/* the brightest pixel is where the normal halves the sun and the view direction */
	double h[3] = { s->sun_dir[0], s->sun_dir[1], s->sun_dir[2] + 1 }, l = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	double best = -1, bn[3] = { 0, 0, 0 };
	for (int j = 0; j < 96; j++)
		for (int i = 0; i < 96; i++) {
			double nn[3];
			if (render_pixel_normal(&o, i, j, nn) && a[(j * 96 + i) * 3 + 1] > best) {
				best = a[(j * 96 + i) * 3 + 1];
				memcpy(bn, nn, sizeof bn);
			}
		}
	double ang = acos(fmin(1, (bn[0] * h[0] + bn[1] * h[1] + bn[2] * h[2]) / l)) * 180 / M_PI;
	printf("highlight: brightest pixel %.3g at %.2f deg from the mirror normal\n", best, ang);
	assert_true(ang < 3); /* two pixels of a 96-pixel sphere are ~2.6 deg near the centre */
	/* and it is a highlight: far brighter than the sphere's median pixel */
	float *v = malloc(96 * 96 * sizeof *v);
	assert_non_null(v);
	int nv = 0;
	for (int j = 0; j < 96; j++)
		for (int i = 0; i < 96; i++) {
			double nn[3];
			if (render_pixel_normal(&o, i, j, nn))
				v[nv++] = a[(j * 96 + i) * 3 + 1];
		}
	int lt = 0;
	for (int k = 0; k < nv; k++)
		lt += v[k] < 0.1 * best;
	printf("highlight: %d of %d sphere pixels are below 10 %% of it\n", lt, nv);
	assert_true(lt > nv * 3 / 4);
	free(v);
	free(a);
	free(b);
	sky_free(s);
}

static void test_exr_roundtrip(void **state)
{
	(void)state;
	char p[600], q[600];
	snprintf(p, sizeof p, "%s/a.exr", dir);
	int w = 37, h = 21;
	float *img = malloc((size_t)w * h * 3 * sizeof *img), *back = NULL;
	assert_non_null(img);
	for (int k = 0; k < w * h * 3; k++)
		img[k] = (float)(exp((k % 97) * 0.3 - 10) * (1 + (k % 3)));
	struct acq_err e = { 0 };
	assert_int_equal(exrio_write_rgb(p, img, w, h, "test", &e), 0);
	int w2, h2;
	assert_int_equal(exrio_read_rgb(p, &back, &w2, &h2, &e), 0);
	assert_int_equal(w2, w);
	assert_int_equal(h2, h);
	assert_memory_equal(img, back, (size_t)w * h * 3 * sizeof *img); /* float, lossless ZIP: bit-exact */
	free(back);
	/* an environment map from it: pdf integrates to 1 there too */
	struct sky *s;
	assert_int_equal(sky_envmap(p, 2.0, NULL, &s, &e), 0);
	assert_false(s->has_sun);
	assert_true(fabs(s->map[5] - 2 * img[5]) <= 1e-6 * img[5]);
	sky_free(s);
	/* refusals: non-finite pixel, missing file, not an EXR */
	img[7] = NAN;
	assert_int_equal(exrio_write_rgb(p, img, w, h, NULL, &e), -1);
	assert_non_null(strstr(e.msg, "not finite"));
	snprintf(q, sizeof q, "%s/missing.exr", dir);
	assert_int_equal(exrio_read_rgb(q, &back, &w2, &h2, &e), -1);
	assert_non_null(strstr(e.msg, "missing.exr"));
	snprintf(q, sizeof q, "%s/bad.exr", dir);
	FILE *f = fopen(q, "w");
	assert_non_null(f);
	fputs("not an exr at all", f);
	fclose(f);
	assert_int_equal(exrio_read_rgb(q, &back, &w2, &h2, &e), -1);
	assert_int_equal(sky_envmap(q, 1, NULL, &s, &e), -1);
	unlink(p);
	unlink(q);
	free(img);
}

/* An EXR written to a FIFO goes through it and leaves it a FIFO. The library's own temporary file + rename
 * replaced the FIFO by a regular file (seen: S_ISFIFO false and no byte through the pipe before the fix) and
 * would have replaced /dev/null as root. The read end is opened first (non-blocking), so the small image
 * (< the pipe's 64 KiB) is written without a second process and the test cannot hang. */
static void test_exr_to_fifo(void **state)
{
	(void)state;
	char p[600];
	snprintf(p, sizeof p, "%s/pipe.exr", dir);
	unlink(p);
	assert_int_equal(mkfifo(p, 0600), 0);
	int rd = open(p, O_RDONLY | O_NONBLOCK);
	assert_true(rd >= 0);
	int w = 9, h = 5;
	float img[9 * 5 * 3];
	for (int k = 0; k < w * h * 3; k++)
		img[k] = (float)(0.01 * k);
	struct acq_err e = { 0 };
	assert_int_equal(exrio_write_rgb(p, img, w, h, NULL, &e), 0);
	struct stat sb;
	assert_int_equal(stat(p, &sb), 0);
	assert_true(S_ISFIFO(sb.st_mode));
	unsigned char buf[65536];
	size_t n = 0;
	ssize_t r;
	while (n < sizeof buf && (r = read(rd, buf + n, sizeof buf - n)) > 0)
		n += (size_t)r;
	close(rd);
	unlink(p);
	assert_true(n > 4 && buf[0] == 0x76 && buf[1] == 0x2f && buf[2] == 0x31 && buf[3] == 0x01); /* EXR magic */
	/* the bytes through the pipe are the image */
	char q[600];
	snprintf(q, sizeof q, "%s/copy.exr", dir);
	FILE *f = fopen(q, "wb");
	assert_non_null(f);
	assert_int_equal(fwrite(buf, 1, n, f), n);
	assert_int_equal(fclose(f), 0);
	float *back = NULL;
	int w2, h2;
	assert_int_equal(exrio_read_rgb(q, &back, &w2, &h2, &e), 0);
	assert_true(w2 == w && h2 == h);
	assert_memory_equal(img, back, sizeof img);
	free(back);
	unlink(q);
	/* a directory is refused, a missing folder named */
	assert_int_equal(exrio_write_rgb(dir, img, w, h, NULL, &e), -1);
	assert_non_null(strstr(e.msg, "directory"));
	snprintf(q, sizeof q, "%s/no/such/x.exr", dir);
	assert_int_equal(exrio_write_rgb(q, img, w, h, NULL, &e), -1);
	assert_non_null(strstr(e.msg, "no/such/x.exr"));
}

static void test_png_chunks(void **state)
{
	(void)state;
	char p[600];
	snprintf(p, sizeof p, "%s/a.png", dir);
	unsigned char px[4 * 3 * 3];
	for (int k = 0; k < 36; k++)
		px[k] = (unsigned char)(k * 7);
	assert_int_equal(pngio_write_rgb8(p, px, 4, 3, NULL), 0);
	FILE *f = fopen(p, "rb");
	assert_non_null(f);
	png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
	png_infop info = png_create_info_struct(png);
	assert_int_equal(setjmp(png_jmpbuf(png)), 0);
	png_init_io(png, f);
	png_read_info(png, info);
	int intent = -1;
	double gamma = 0, wx, wy, rx, ry, gx, gy, bx, by;
	assert_true(png_get_sRGB(png, info, &intent) != 0);
	assert_int_equal(intent, PNG_sRGB_INTENT_PERCEPTUAL);
	assert_true(png_get_gAMA(png, info, &gamma) != 0);
	assert_true(fabs(gamma - 1 / 2.2) < 1e-4);
	assert_true(png_get_cHRM(png, info, &wx, &wy, &rx, &ry, &gx, &gy, &bx, &by) != 0);
	assert_true(fabs(wx - 0.3127) < 1e-4 && fabs(ry - 0.33) < 1e-4 && fabs(bx - 0.15) < 1e-4);
	png_destroy_read_struct(&png, &info, NULL);
	fclose(f);
	unlink(p);
}

int main(void)
{
	const char *s = getenv("ACQ_SEED");
	seed = s ? strtoull(s, NULL, 10) : 1;
	printf("test_recon_sky: ACQ_SEED=%llu\n", (unsigned long long)seed);
	const char *tmp = getenv("TMPDIR");
	snprintf(dir, sizeof dir, "%s/test_recon_sky.XXXXXX", tmp ? tmp : "/tmp");
	if (!mkdtemp(dir))
		return 1;
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sky_pdf),
		cmocka_unit_test(test_furnace_and_sun),
		cmocka_unit_test(test_highlight_and_threads),
		cmocka_unit_test(test_exr_roundtrip),
		cmocka_unit_test(test_exr_to_fifo),
		cmocka_unit_test(test_png_chunks),
	};
	int rc = cmocka_run_group_tests(tests, NULL, NULL);
	rmdir(dir);
	return rc;
}
