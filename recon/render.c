/* render: sphere preview of an RGB BRDF (directional lights + fixed-sample gradient sky), PNG through cairo. */
#include "recon/render.h"

#include <cairo.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "recon/pngio.h"

static void set3(double d[3], double a, double b, double c)
{
	d[0] = a;
	d[1] = b;
	d[2] = c;
}

void render_opts_default(struct render_opts *o)
{
	memset(o, 0, sizeof(*o));
	o->width = 256;
	o->height = 256;
	o->radius_frac = 0.9;
	o->n_lights = 2;
	set3(o->lights[0].dir, -0.4, 0.55, 0.73); /* key: upper left, in front */
	set3(o->lights[0].rgb, 2.2, 2.2, 2.2);
	set3(o->lights[1].dir, 0.85, 0.05, 0.3); /* fill / rim: right */
	set3(o->lights[1].rgb, 0.5, 0.5, 0.55);
	set3(o->sky_zenith, 0.25, 0.35, 0.55);
	set3(o->sky_horizon, 0.70, 0.72, 0.75);
	set3(o->ground, 0.12, 0.11, 0.10);
	o->sky_samples = 64;
	o->exposure = 1;
	colour_opts_default(&o->tone);
	o->tone.gamut = COLOUR_GAMUT_CLAMP;
	o->tone.range = COLOUR_RANGE_REINHARD;
	o->tone.reinhard_white = 2;
	o->tone.srgb_encode = true;
	set3(o->background, 0.05, 0.05, 0.05);
	o->threads = 1;
}

int render_pixel_normal(const struct render_opts *o, int i, int j, double n[3])
{
	double r = o->radius_frac * (o->width < o->height ? o->width : o->height) / 2.0;
	double x = (i + 0.5 - o->width / 2.0) / r, y = -(j + 0.5 - o->height / 2.0) / r;
	double r2 = x * x + y * y;
	if (!(r2 < 1))
		return 0;
	set3(n, x, y, sqrt(1 - r2));
	return 1;
}

/* Orthonormal basis (b1, b2, n) for unit n (Duff et al. 2017, "Building an orthonormal basis, revisited"). */
static void basis(const double n[3], double b1[3], double b2[3])
{
	double sign = copysign(1.0, n[2]);
	double a = -1.0 / (sign + n[2]);
	double b = n[0] * n[1] * a;
	set3(b1, 1 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]);
	set3(b2, b, sign + n[1] * n[1] * a, -n[1]);
}

static double dot(const double a[3], const double b[3])
{
	return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static int finite3(const double v[3])
{
	return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

struct scene {
	const struct render_opts *o;
	merl_rgb_fn fn;
	void *ctx;
	double (*sky_dir)[3]; /* K unit directions (world) */
	double (*sky_rad)[3]; /* their radiance · 4π/K */
	double light_dir[RENDER_MAX_LIGHTS][3];
	float *lin;
	atomic_int *stop;
};

struct worker {
	struct scene *s;
	int thread, nthreads;
	int failed; /* 0, 1 = callback error, 2 = non-finite */
	int rc, px, py;
};

static void *render_rows(void *arg)
{
	struct worker *w = arg;
	const struct scene *s = w->s;
	const struct render_opts *o = s->o;
	for (int j = w->thread; j < o->height; j += w->nthreads) {
		if (atomic_load(s->stop))
			return NULL;
		for (int i = 0; i < o->width; i++) {
			float *out = s->lin + 3 * ((size_t)j * (size_t)o->width + (size_t)i);
			double n[3], b1[3], b2[3], L[3] = { 0, 0, 0 };
			if (!render_pixel_normal(o, i, j, n)) {
				for (int c = 0; c < 3; c++)
					out[c] = (float)(o->background[c] * o->exposure);
				continue;
			}
			basis(n, b1, b2);
			const double view[3] = { 0, 0, 1 };
			double wo[3] = { dot(view, b1), dot(view, b2), dot(view, n) };
			int nl = o->n_lights, ns = o->sky_samples;
			for (int k = 0; k < nl + ns; k++) {
				const double *d = k < nl ? s->light_dir[k] : s->sky_dir[k - nl];
				const double *e = k < nl ? o->lights[k].rgb : s->sky_rad[k - nl];
				double wi[3] = { dot(d, b1), dot(d, b2), dot(d, n) };
				if (!(wi[2] > 0))
					continue;
				double f[3] = { 0, 0, 0 };
				int rc = s->fn(s->ctx, wi, wo, f);
				if (rc != 0 || !finite3(f)) {
					w->failed = rc != 0 ? 1 : 2;
					w->rc = rc;
					w->px = i;
					w->py = j;
					atomic_store(s->stop, 1);
					return NULL;
				}
				for (int c = 0; c < 3; c++)
					L[c] += f[c] * e[c] * wi[2];
			}
			for (int c = 0; c < 3; c++) {
				double v = L[c] * o->exposure;
				if (!isfinite(v) || fabs(v) > 3e38) {
					w->failed = 2;
					w->px = i;
					w->py = j;
					atomic_store(s->stop, 1);
					return NULL;
				}
				out[c] = (float)v;
			}
		}
	}
	return NULL;
}

static int check_opts(const struct render_opts *o, struct acq_err *err)
{
	if (o->width < 8 || o->width > 4096 || o->height < 8 || o->height > 4096)
		return acq_errf(err, ACQ_E_INVAL, "render: image size %d × %d outside 8..4096", o->width, o->height);
	if (!(o->radius_frac > 0 && o->radius_frac <= 1))
		return acq_errf(err, ACQ_E_INVAL, "render: radius_frac must be in (0, 1] (got %g)", o->radius_frac);
	if (o->n_lights < 0 || o->n_lights > RENDER_MAX_LIGHTS)
		return acq_errf(err, ACQ_E_INVAL, "render: %d lights (0..%d)", o->n_lights, RENDER_MAX_LIGHTS);
	if (o->sky_samples < 0 || o->sky_samples > 4096)
		return acq_errf(err, ACQ_E_INVAL, "render: sky_samples %d outside 0..4096", o->sky_samples);
	if (o->threads < 1 || o->threads > 16)
		return acq_errf(err, ACQ_E_INVAL, "render: threads %d outside 1..16", o->threads);
	if (!(o->exposure > 0) || !isfinite(o->exposure))
		return acq_errf(err, ACQ_E_INVAL, "render: exposure must be finite and > 0 (got %g)", o->exposure);
	for (int k = 0; k < o->n_lights; k++) {
		const double *d = o->lights[k].dir;
		if (!finite3(d) || !(dot(d, d) > 0) || !finite3(o->lights[k].rgb))
			return acq_errf(err, ACQ_E_INVAL, "render: light %d has a zero or non-finite direction or colour", k);
	}
	if (!finite3(o->sky_zenith) || !finite3(o->sky_horizon) || !finite3(o->ground) || !finite3(o->background))
		return acq_errf(err, ACQ_E_INVAL, "render: non-finite sky, ground or background colour");
	return colour_opts_check(&o->tone, err) != 0 ? acq_err_prefix(err, "render: tone: ") : 0;
}

int render_sphere(const struct render_opts *o, merl_rgb_fn fn, void *ctx, const char *png_path, float *linear,
		  struct colour_stats *stats, struct acq_err *err)
{
	if (!o || !fn)
		return acq_errf(err, ACQ_E_INVAL, "render: no options or no BRDF callback");
	if (check_opts(o, err) != 0)
		return -1;
	int rc = -1;
	size_t npx = (size_t)o->width * (size_t)o->height;
	struct scene s = { .o = o, .fn = fn, .ctx = ctx };
	atomic_int stop = 0;
	s.stop = &stop;
	float *own = NULL;
	cairo_surface_t *surf = NULL;
	s.lin = linear ? linear : (own = malloc(npx * 3 * sizeof(float)));
	size_t K = (size_t)o->sky_samples;
	s.sky_dir = malloc((K ? K : 1) * sizeof(*s.sky_dir));
	s.sky_rad = malloc((K ? K : 1) * sizeof(*s.sky_rad));
	if (!s.lin || !s.sky_dir || !s.sky_rad) {
		acq_errf(err, ACQ_E_NOMEM, "render: out of memory for %d × %d", o->width, o->height);
		goto out;
	}
	for (int k = 0; k < o->n_lights; k++) {
		const double *d = o->lights[k].dir;
		double l = sqrt(dot(d, d));
		set3(s.light_dir[k], d[0] / l, d[1] / l, d[2] / l);
	}
	/* Fibonacci set: y uniform in (−1, 1), golden-angle azimuth; each direction carries 4π/K sr. */
	const double golden = M_PI * (3 - sqrt(5.0));
	for (size_t k = 0; k < K; k++) {
		double y = 1 - (2.0 * (double)k + 1) / (double)K, r = sqrt(fmax(0, 1 - y * y)), p = golden * (double)k;
		set3(s.sky_dir[k], r * cos(p), y, r * sin(p));
		for (int c = 0; c < 3; c++) {
			double rad = y > 0 ? o->sky_horizon[c] + (o->sky_zenith[c] - o->sky_horizon[c]) * y : o->ground[c];
			s.sky_rad[k][c] = rad * 4 * M_PI / (double)K;
		}
	}

	struct worker w[16];
	pthread_t tid[16];
	int started = 0;
	for (int t = 0; t < o->threads; t++)
		w[t] = (struct worker){ .s = &s, .thread = t, .nthreads = o->threads };
	for (int t = 1; t < o->threads; t++) {
		if (pthread_create(&tid[t], NULL, render_rows, &w[t]) != 0) {
			atomic_store(&stop, 1);
			break;
		}
		started = t;
	}
	if (!atomic_load(&stop))
		render_rows(&w[0]);
	for (int t = 1; t <= started; t++)
		pthread_join(tid[t], NULL);
	if (started + 1 < o->threads) {
		acq_errf(err, ACQ_E_NOMEM, "render: cannot start %d threads", o->threads);
		goto out;
	}
	for (int t = 0; t < o->threads; t++) {
		if (!w[t].failed)
			continue;
		if (w[t].failed == 1)
			acq_errf(err, ACQ_E_NUMERIC, "render: BRDF callback failed (%d) at pixel (%d, %d)", w[t].rc, w[t].px,
				 w[t].py);
		else
			acq_errf(err, ACQ_E_NUMERIC, "render: non-finite radiance at pixel (%d, %d)", w[t].px, w[t].py);
		goto out;
	}

	/* Tone stages and 8-bit sRGB into a cairo image (RGB24: 0x00RRGGBB per pixel). */
	surf = cairo_image_surface_create(CAIRO_FORMAT_RGB24, o->width, o->height);
	if (cairo_surface_status(surf) != CAIRO_STATUS_SUCCESS) {
		acq_errf(err, ACQ_E_NOMEM, "render: cannot create the image");
		goto out;
	}
	cairo_surface_flush(surf);
	unsigned char *data = cairo_image_surface_get_data(surf);
	int stride = cairo_image_surface_get_stride(surf);
	for (int j = 0; j < o->height; j++) {
		uint32_t *row = (uint32_t *)(void *)(data + (size_t)j * (size_t)stride);
		for (int i = 0; i < o->width; i++) {
			const float *l = s.lin + 3 * ((size_t)j * (size_t)o->width + (size_t)i);
			double in[3] = { l[0], l[1], l[2] }, v[3];
			colour_finish(&o->tone, in, v, stats);
			uint32_t px = 0;
			for (int c = 0; c < 3; c++)
				px = px << 8 | (uint32_t)lround(fmin(1, fmax(0, v[c])) * 255);
			row[i] = px;
		}
	}
	cairo_surface_mark_dirty(surf);
	if (png_path && pngio_write_surface(surf, png_path, err) != 0)
		goto out;
	rc = 0;
out:
	if (surf)
		cairo_surface_destroy(surf);
	free(own);
	free(s.sky_dir);
	free(s.sky_rad);
	return rc;
}
