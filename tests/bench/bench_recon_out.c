/* bench_recon_out: timings and sample outputs of the recon output side (colour, MERL, DHR plot, render). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "recon/colour.h"
#include "recon/merl.h"
#include "recon/plot.h"
#include "recon/render.h"

static double now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* Green-paint-like analytic RGB BRDF (sr⁻¹): Lambert + Schlick-Fresnel Blinn-Phong. */
static int glossy(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	(void)ctx;
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] };
	double l = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	double hz = h[2] / l, ih = (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) / l;
	double lobe = 42 / (8 * M_PI) * pow(hz, 40) * (0.04 + 0.96 * pow(1 - ih, 5));
	static const double kd[3] = { 0.05, 0.30, 0.07 };
	for (int c = 0; c < 3; c++)
		rgb[c] = kd[c] / M_PI + 0.7 * lobe;
	return 0;
}

static int fail(const char *what, const struct acq_err *e)
{
	fprintf(stderr, "bench_recon_out: %s: %s\n", what, e->msg);
	return 1;
}

int main(void)
{
	const char *out = getenv("ACQ_BENCH_OUT");
	if (!out)
		out = "build/bench";
	char p[1024];
	struct acq_err err = { 0 };

	/* colour: weights for a 0.5 nm grid 450–1100 nm */
	size_t n = 1301;
	double *wl = malloc(n * sizeof(double)), *W = malloc(3 * n * sizeof(double)), *s = malloc(n * sizeof(double));
	if (!wl || !W || !s)
		return 1;
	for (size_t k = 0; k < n; k++) {
		wl[k] = 450 + 0.5 * (double)k;
		s[k] = (0.05 + 0.4 * exp(-pow((wl[k] - 540) / 40, 2)) + 0.35 / (1 + exp(-(wl[k] - 700) / 20))) / M_PI;
	}
	struct colour_opts co;
	colour_opts_default(&co);
	co.srgb_encode = true;
	co.range = COLOUR_RANGE_CLIP;
	double t0 = now();
	int reps = 200;
	for (int r = 0; r < reps; r++)
		if (colour_weights(&co, wl, n, W, &err) != 0)
			return fail("colour_weights", &err);
	double t_w = (now() - t0) / reps;
	double lin[3], rgb[3];
	struct colour_stats st = { 0 };
	colour_apply_weights(W, n, s, lin);
	colour_finish(&co, lin, rgb, &st);
	char meta[1024];
	colour_opts_json(&co, &st, meta, sizeof(meta));
	printf("colour_weights (%zu wavelengths): %.3f ms; green-paint-like reflectance → sRGB %.3f %.3f %.3f\n", n,
	       1e3 * t_w, rgb[0], rgb[1], rgb[2]);
	printf("metadata: %s\n", meta);

	/* MERL: write with 1 and 2 threads, read, look up */
	snprintf(p, sizeof(p), "%s/recon_out_glossy.binary", out);
	struct merl_write_opts mo;
	merl_write_opts_default(&mo);
	for (int th = 1; th <= 2; th++) {
		mo.threads = th;
		t0 = now();
		if (merl_write_ex(p, glossy, NULL, &mo, &err) != 0)
			return fail("merl_write", &err);
		printf("merl_write, %d thread(s): %.3f s (%s)\n", th, now() - t0, p);
	}
	struct merl_table t;
	t0 = now();
	if (merl_read(p, &t, &err) != 0)
		return fail("merl_read", &err);
	printf("merl_read: %.3f s\n", now() - t0);

	/* render: analytic and from the table */
	struct render_opts ro;
	render_opts_default(&ro);
	snprintf(p, sizeof(p), "%s/recon_out_sphere.png", out);
	t0 = now();
	if (render_sphere(&ro, glossy, NULL, p, NULL, NULL, &err) != 0)
		return fail("render", &err);
	printf("render %d×%d, %d lights + %d sky directions: %.3f s (%s)\n", ro.width, ro.height, ro.n_lights,
	       ro.sky_samples, now() - t0, p);
	snprintf(p, sizeof(p), "%s/recon_out_sphere_merl.png", out);
	t0 = now();
	if (render_sphere(&ro, merl_table_fn, &t, p, NULL, NULL, &err) != 0)
		return fail("render (MERL)", &err);
	printf("render from the MERL table: %.3f s (%s)\n", now() - t0, p);
	merl_free(&t);

	/* DHR plot: three incidences with ±2σ bands and a reference */
	enum { NP = 651 };
	static double pw[NP], py[3][NP], ps[3][NP], ry[NP], rs[NP];
	for (int k = 0; k < NP; k++) {
		pw[k] = 450 + k;
		for (int c = 0; c < 3; c++) {
			py[c][k] = (1 - 0.05 * c) * M_PI * (0.05 + 0.4 * exp(-pow((pw[k] - 540) / 40, 2)) +
							    0.35 / (1 + exp(-(pw[k] - 700) / 20))) / M_PI;
			ps[c][k] = 0.006 * (1 + c);
		}
		ry[k] = py[0][k] * 1.01;
		rs[k] = 0.01;
	}
	struct plot_curve cv[3] = {
		{ "\xce\xb8i = 8\xc2\xb0", pw, py[0], ps[0], NP },
		{ "\xce\xb8i = 30\xc2\xb0", pw, py[1], ps[1], NP },
		{ "\xce\xb8i = 60\xc2\xb0", pw, py[2], ps[2], NP },
	};
	struct plot_curve ref = { "spectrophotometer", pw, ry, rs, NP };
	struct plot_dhr_opts po;
	plot_dhr_opts_default(&po);
	po.title = "DHR (synthetic)";
	snprintf(p, sizeof(p), "%s/recon_out_dhr.png", out);
	t0 = now();
	if (plot_dhr_png(p, cv, 3, &ref, &po, NULL, &err) != 0)
		return fail("plot", &err);
	printf("plot_dhr_png %d×%d: %.3f s (%s)\n", po.width, po.height, now() - t0, p);
	free(wl);
	free(W);
	free(s);
	return 0;
}
