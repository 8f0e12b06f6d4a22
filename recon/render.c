/* render: sphere preview of an RGB BRDF (directional lights + fixed-sample gradient sky), PNG through cairo. */
#include "recon/render.h"

#include <cairo.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "recon/pngio.h"
#include "recon/pool.h"
#include "recon/rng.h"

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
	o->spp = 64;
	o->lobe_alpha = 0.3;
	o->seed = 1;
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
	int n_map, n_sun, n_lobe, n_cos; /* samples per strategy (sky path) */
	float *lin;
};

static int bad_pixel(struct acq_err *err, int rc, int i, int j)
{
	if (rc != 0)
		return acq_errf(err, ACQ_E_NUMERIC, "render: BRDF callback failed (%d) at pixel (%d, %d)", rc, i, j);
	return acq_errf(err, ACQ_E_NUMERIC, "render: non-finite radiance at pixel (%d, %d)", i, j);
}

/* Fixed lights and the Fibonacci sky (no sky object). */
static int shade_fixed(const struct scene *s, const double n[3], const double b1[3], const double b2[3],
		       const double wo[3], double L[3], int *cb_rc)
{
	const struct render_opts *o = s->o;
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
			*cb_rc = rc;
			return -1;
		}
		for (int c = 0; c < 3; c++)
			L[c] += f[c] * e[c] * wi[2];
	}
	return 0;
}

static double ggx_d(double a2, double ch)
{
	double t = ch * ch * (a2 - 1) + 1;
	return a2 / (M_PI * t * t);
}

/* n_s·p_s(ωi) of the four strategies (map, sun, lobe, cosine) at ωi, local (wi) and world (d). */
static void mis_pdfs(const struct scene *s, const double wi[3], const double wo[3], const double d[3], double q[4])
{
	const struct render_opts *o = s->o;
	double pc = wi[2] > 0 ? wi[2] / M_PI : 0;
	q[0] = s->n_map * sky_pdf_map(o->sky, d);
	q[1] = s->n_sun * sky_pdf_sun(o->sky, d);
	q[3] = s->n_cos * pc;
	q[2] = 0;
	if (s->n_lobe && o->lobe_alpha > 0) {
		double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] }, l = sqrt(dot(h, h));
		if (l > 0 && wi[2] > 0) {
			for (int c = 0; c < 3; c++)
				h[c] /= l;
			double oh = dot(wo, h);
			if (h[2] > 0 && oh > 0)
				q[2] = s->n_lobe * ggx_d(o->lobe_alpha * o->lobe_alpha, h[2]) * h[2] / (4 * oh);
		}
	} else if (s->n_lobe) {
		q[2] = s->n_lobe * pc;
	}
}

/* Environment lighting by multiple importance sampling (render.h). */
static int shade_sky(const struct scene *s, size_t pixel, const double n[3], const double b1[3],
		     const double b2[3], const double wo[3], double L[3], int *cb_rc)
{
	const struct render_opts *o = s->o;
	struct recon_rng r;
	recon_rng_seed(&r, o->seed * 0x9E3779B97F4A7C15ull + pixel);
	int total = s->n_map + s->n_sun + s->n_lobe + s->n_cos;
	for (int k = 0; k < total; k++) {
		double u[2] = { recon_rng_unif(&r), recon_rng_unif(&r) }, d[3], wi[3];
		if (k < s->n_map + s->n_sun) {
			if (k < s->n_map)
				sky_sample_map(o->sky, u, d);
			else
				sky_sample_sun(o->sky, u, d);
			wi[0] = dot(d, b1);
			wi[1] = dot(d, b2);
			wi[2] = dot(d, n);
		} else {
			if (k < s->n_map + s->n_sun + s->n_lobe && o->lobe_alpha > 0) {
				double a = o->lobe_alpha, t2 = a * a * u[0] / fmax(1e-12, 1 - u[0]);
				double ct = 1 / sqrt(1 + t2), st = sqrt(fmax(0, 1 - ct * ct)), p = 2 * M_PI * u[1];
				double h[3] = { st * cos(p), st * sin(p), ct }, oh = dot(wo, h);
				for (int c = 0; c < 3; c++)
					wi[c] = 2 * oh * h[c] - wo[c];
			} else {
				double rr = sqrt(u[0]), p = 2 * M_PI * u[1];
				set3(wi, rr * cos(p), rr * sin(p), sqrt(fmax(0, 1 - u[0])));
			}
			for (int c = 0; c < 3; c++)
				d[c] = wi[0] * b1[c] + wi[1] * b2[c] + wi[2] * n[c];
		}
		if (!(wi[2] > 0))
			continue;
		/* power heuristic (β = 2): a sample weighs (n_s p_s)² / Σ (n_k p_k)², divided by n_s p_s; a rare lobe
		 * or cosine sample landing in the small, bright sun adds almost nothing (no fireflies) */
		int strat = k < s->n_map ? 0 : k < s->n_map + s->n_sun ? 1 : k < s->n_map + s->n_sun + s->n_lobe ? 2 : 3;
		double q[4], sq = 0;
		mis_pdfs(s, wi, wo, d, q);
		for (int t = 0; t < 4; t++)
			sq += q[t] * q[t];
		if (!(q[strat] > 0) || !(sq > 0))
			continue;
		double den = sq / q[strat];
		double f[3] = { 0, 0, 0 }, Le[3];
		int rc = s->fn(s->ctx, wi, wo, f);
		if (rc != 0 || !finite3(f)) {
			*cb_rc = rc;
			return -1;
		}
		sky_radiance(o->sky, d, Le);
		for (int c = 0; c < 3; c++)
			L[c] += f[c] * Le[c] * wi[2] / den;
	}
	return 0;
}

/* One image row (a pool job). */
static int render_row(void *ctx, int worker, size_t job, struct acq_err *err)
{
	(void)worker;
	const struct scene *s = ctx;
	const struct render_opts *o = s->o;
	int j = (int)job;
	for (int i = 0; i < o->width; i++) {
		size_t pixel = (size_t)j * (size_t)o->width + (size_t)i;
		float *out = s->lin + 3 * pixel;
		double n[3], b1[3], b2[3], L[3] = { 0, 0, 0 };
		if (!render_pixel_normal(o, i, j, n)) {
			for (int c = 0; c < 3; c++)
				out[c] = (float)(o->background[c] * o->exposure);
			continue;
		}
		basis(n, b1, b2);
		const double view[3] = { 0, 0, 1 };
		double wo[3] = { dot(view, b1), dot(view, b2), dot(view, n) };
		int cb_rc = 0;
		if ((o->sky ? shade_sky(s, pixel, n, b1, b2, wo, L, &cb_rc) : shade_fixed(s, n, b1, b2, wo, L, &cb_rc)))
			return bad_pixel(err, cb_rc, i, j);
		for (int c = 0; c < 3; c++) {
			double v = L[c] * o->exposure;
			if (!isfinite(v) || fabs(v) > 3e38)
				return bad_pixel(err, 0, i, j);
			out[c] = (float)v;
		}
	}
	return 0;
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
	if (o->sky && (o->spp < 8 || o->spp > 4096))
		return acq_errf(err, ACQ_E_INVAL, "render: spp %d outside 8..4096", o->spp);
	if (o->sky && !(o->lobe_alpha == 0 || (o->lobe_alpha >= 0.01 && o->lobe_alpha <= 1)))
		return acq_errf(err, ACQ_E_INVAL, "render: lobe_alpha %g (0 or 0.01..1)", o->lobe_alpha);
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

	if (o->sky) {
		int n8 = o->spp / 8 ? o->spp / 8 : 1;
		s.n_sun = o->sky->has_sun ? n8 : 0;
		s.n_cos = n8;
		s.n_lobe = 3 * n8;
		s.n_map = o->spp - s.n_sun - s.n_cos - s.n_lobe;
	}
	if (pool_run(o->threads, (size_t)o->height, render_row, &s, NULL, err))
		goto out;

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
