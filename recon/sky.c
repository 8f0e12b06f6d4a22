/* sky: lat-long environment (procedural or EXR) with importance sampling, and a sun disc. */
#include "recon/sky.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "recon/exrio.h"

static void set3(double d[3], double a, double b, double c)
{
	d[0] = a;
	d[1] = b;
	d[2] = c;
}

void sky_opts_default(struct sky_opts *o)
{
	memset(o, 0, sizeof *o);
	set3(o->zenith, 0.20, 0.32, 0.60);
	set3(o->horizon, 0.75, 0.78, 0.82);
	set3(o->ground, 0.14, 0.12, 0.10);
	o->glow = 0.4;
	set3(o->sun_dir, -0.45, 0.65, 0.62);
	set3(o->sun_rgb, 2.5, 2.4, 2.2);
	o->sun_radius_deg = 1.5;
	o->width = 256;
	o->height = 128;
}

static double lum(const double c[3])
{
	return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
}

static void dir_of_uv(double u, double v, double d[3])
{
	double ph = 2 * M_PI * u - M_PI, th = M_PI * v;
	set3(d, sin(th) * sin(ph), cos(th), -sin(th) * cos(ph));
}

static void uv_of_dir(const double d[3], double *u, double *v)
{
	double y = d[1] < -1 ? -1 : d[1] > 1 ? 1 : d[1];
	*u = (atan2(d[0], -d[2]) + M_PI) / (2 * M_PI);
	*v = acos(y) / M_PI;
	if (*u >= 1)
		*u -= 1;
}

static void map_lookup(const struct sky *s, double u, double v, double L[3])
{
	double x = u * s->w - 0.5, y = v * s->h - 0.5;
	double fx = floor(x), fy = floor(y);
	double tx = x - fx, ty = y - fy;
	int i0 = ((int)fx % s->w + s->w) % s->w, i1 = (i0 + 1) % s->w;
	int j0 = (int)fy, j1 = j0 + 1;
	j0 = j0 < 0 ? 0 : j0 >= s->h ? s->h - 1 : j0;
	j1 = j1 < 0 ? 0 : j1 >= s->h ? s->h - 1 : j1;
	for (int c = 0; c < 3; c++) {
		double a = s->map[((size_t)j0 * s->w + i0) * 3 + c], b = s->map[((size_t)j0 * s->w + i1) * 3 + c];
		double e = s->map[((size_t)j1 * s->w + i0) * 3 + c], f = s->map[((size_t)j1 * s->w + i1) * 3 + c];
		L[c] = (1 - ty) * ((1 - tx) * a + tx * b) + ty * ((1 - tx) * e + tx * f);
	}
}

static int set_sun(struct sky *s, const struct sky_opts *o, struct acq_err *err)
{
	if (!o || (o->sun_rgb[0] == 0 && o->sun_rgb[1] == 0 && o->sun_rgb[2] == 0))
		return 0;
	double n = sqrt(o->sun_dir[0] * o->sun_dir[0] + o->sun_dir[1] * o->sun_dir[1] + o->sun_dir[2] * o->sun_dir[2]);
	if (!(n > 0) || !isfinite(n) || !(o->sun_radius_deg >= 0.05 && o->sun_radius_deg <= 10))
		return acq_errf(err, ACQ_E_INVAL, "sky: sun direction must be non-zero and its radius 0.05..10 deg (got %g)",
				o->sun_radius_deg);
	for (int c = 0; c < 3; c++)
		if (!(o->sun_rgb[c] >= 0) || !isfinite(o->sun_rgb[c]))
			return acq_errf(err, ACQ_E_INVAL, "sky: sun irradiance must be finite and >= 0");
	double r = o->sun_radius_deg * M_PI / 180;
	s->has_sun = 1;
	set3(s->sun_dir, o->sun_dir[0] / n, o->sun_dir[1] / n, o->sun_dir[2] / n);
	s->sun_cos = cos(r);
	/* a disc of uniform radiance L: irradiance at normal incidence ∫cos dω = π sin²r */
	for (int c = 0; c < 3; c++)
		s->sun_L[c] = o->sun_rgb[c] / (M_PI * sin(r) * sin(r));
	return 0;
}

/* The importance table: map luminance·sinθ at the cell corners, plus a floor so every direction can be drawn. */
static int build_warp(struct sky *s, struct acq_err *err)
{
	size_t W = (size_t)s->w + 1, H = (size_t)s->h + 1;
	double *d = malloc(W * H * sizeof *d), sum = 0;
	if (!d)
		return acq_errf(err, ACQ_E_NOMEM, "sky: out of memory");
	for (size_t j = 0; j < H; j++)
		for (size_t i = 0; i < W; i++) {
			double u = (double)i / (double)s->w, v = (double)j / (double)s->h, L[3];
			map_lookup(s, u, v, L);
			d[j * W + i] = lum(L) * sin(M_PI * v);
			if (!(d[j * W + i] > 0))
				d[j * W + i] = 0;
			sum += d[j * W + i];
		}
	double floor_v = 1e-3 * (sum > 0 ? sum / (double)(W * H) : 1);
	for (size_t k = 0; k < W * H; k++)
		d[k] += floor_v;
	int rc = warp2d_init(&s->wp, d, W, H, err);
	free(d);
	return rc;
}

int sky_procedural(const struct sky_opts *o, struct sky **out, struct acq_err *err)
{
	*out = NULL;
	if (o->width < 8 || o->width > 4096 || o->height < 4 || o->height > 4096)
		return acq_errf(err, ACQ_E_INVAL, "sky: map %d x %d (8..4096 x 4..4096)", o->width, o->height);
	for (int c = 0; c < 3; c++)
		if (!(o->zenith[c] >= 0 && o->horizon[c] >= 0 && o->ground[c] >= 0) || !isfinite(o->zenith[c] + o->horizon[c] + o->ground[c]))
			return acq_errf(err, ACQ_E_INVAL, "sky: colours must be finite and >= 0");
	if (!(o->glow >= 0) || !isfinite(o->glow))
		return acq_errf(err, ACQ_E_INVAL, "sky: glow must be finite and >= 0");
	struct sky *s = calloc(1, sizeof *s);
	if (!s)
		return acq_errf(err, ACQ_E_NOMEM, "sky: out of memory");
	s->w = o->width;
	s->h = o->height;
	s->map = malloc((size_t)s->w * s->h * 3 * sizeof *s->map);
	if (!s->map || set_sun(s, o, err)) {
		if (!s->map)
			acq_errf(err, ACQ_E_NOMEM, "sky: out of memory");
		sky_free(s);
		return -1;
	}
	double sl = s->has_sun ? lum(o->sun_rgb) : 0;
	for (int j = 0; j < s->h; j++)
		for (int i = 0; i < s->w; i++) {
			double d[3], L[3];
			dir_of_uv((i + 0.5) / s->w, (j + 0.5) / s->h, d);
			/* gradient above the horizon (smooth: 1 − (1 − y)³), ground below, blended over |y| < 0.03 */
			double y = d[1], a = y > 0 ? 1 - pow(1 - y, 3) : 0, t = fmin(1, fmax(0, (y + 0.03) / 0.06));
			for (int c = 0; c < 3; c++) {
				double skyv = o->horizon[c] + (o->zenith[c] - o->horizon[c]) * a;
				L[c] = t * skyv + (1 - t) * o->ground[c];
			}
			if (s->has_sun && sl > 0 && y > -0.03) {
				double cg = d[0] * s->sun_dir[0] + d[1] * s->sun_dir[1] + d[2] * s->sun_dir[2];
				double g = acos(fmax(-1, fmin(1, cg))) / (20 * M_PI / 180);
				for (int c = 0; c < 3; c++)
					L[c] += t * o->glow * o->sun_rgb[c] / sl * exp(-g * g);
			}
			for (int c = 0; c < 3; c++)
				s->map[((size_t)j * s->w + i) * 3 + c] = (float)L[c];
		}
	if (build_warp(s, err)) {
		sky_free(s);
		return -1;
	}
	snprintf(s->desc, sizeof s->desc, "procedural sky %dx%d (zenith %.3g %.3g %.3g, horizon %.3g %.3g %.3g, ground "
		 "%.3g %.3g %.3g, glow %.3g)%s", s->w, s->h, o->zenith[0], o->zenith[1], o->zenith[2], o->horizon[0],
		 o->horizon[1], o->horizon[2], o->ground[0], o->ground[1], o->ground[2], o->glow,
		 s->has_sun ? " + sun" : "");
	*out = s;
	return 0;
}

int sky_envmap(const char *path, double scale, const struct sky_opts *o, struct sky **out, struct acq_err *err)
{
	*out = NULL;
	if (!(scale > 0) || !isfinite(scale))
		return acq_errf(err, ACQ_E_INVAL, "sky: environment scale must be finite and > 0 (got %g)", scale);
	struct sky *s = calloc(1, sizeof *s);
	if (!s)
		return acq_errf(err, ACQ_E_NOMEM, "sky: out of memory");
	if (exrio_read_rgb(path, &s->map, &s->w, &s->h, err) || set_sun(s, o, err)) {
		sky_free(s);
		return -1;
	}
	for (size_t k = 0; k < (size_t)s->w * s->h * 3; k++)
		s->map[k] = (float)(s->map[k] * scale);
	if (build_warp(s, err)) {
		acq_err_prefix(err, "sky: %s: ", path);
		sky_free(s);
		return -1;
	}
	snprintf(s->desc, sizeof s->desc, "environment map %s (%dx%d lat-long, x %g)%s", path, s->w, s->h, scale,
		 s->has_sun ? " + sun" : "");
	*out = s;
	return 0;
}

void sky_free(struct sky *s)
{
	if (!s)
		return;
	warp2d_free(&s->wp);
	free(s->map);
	free(s);
}

void sky_radiance(const struct sky *s, const double d[3], double L[3])
{
	double u, v;
	uv_of_dir(d, &u, &v);
	map_lookup(s, u, v, L);
	if (s->has_sun && d[0] * s->sun_dir[0] + d[1] * s->sun_dir[1] + d[2] * s->sun_dir[2] >= s->sun_cos)
		for (int c = 0; c < 3; c++)
			L[c] += s->sun_L[c];
}

static double jac(double v)
{
	double st = sin(M_PI * v);
	return 2 * M_PI * M_PI * (st > 1e-9 ? st : 1e-9);
}

double sky_sample_map(const struct sky *s, const double u[2], double d[3])
{
	double uv[2], pdf;
	warp2d_sample(&s->wp, u, uv, &pdf);
	dir_of_uv(uv[0], uv[1], d);
	return pdf / jac(uv[1]);
}

double sky_pdf_map(const struct sky *s, const double d[3])
{
	double uv[2];
	uv_of_dir(d, &uv[0], &uv[1]);
	return warp2d_pdf(&s->wp, uv) / jac(uv[1]);
}

double sky_sample_sun(const struct sky *s, const double u[2], double d[3])
{
	if (!s->has_sun)
		return 0;
	/* strictly inside the cone (u < 1 − 1e-7), so that rounding never puts a sample outside the disc the
	 * radiance and the pdf test against */
	double ct = 1 - fmin(u[0], 1 - 1e-7) * (1 - s->sun_cos), st = sqrt(fmax(0, 1 - ct * ct)), p = 2 * M_PI * u[1];
	const double *n = s->sun_dir;
	double sign = copysign(1.0, n[2]), a = -1.0 / (sign + n[2]), b = n[0] * n[1] * a;
	double b1[3] = { 1 + sign * n[0] * n[0] * a, sign * b, -sign * n[0] }, b2[3] = { b, sign + n[1] * n[1] * a, -n[1] };
	for (int c = 0; c < 3; c++)
		d[c] = st * cos(p) * b1[c] + st * sin(p) * b2[c] + ct * n[c];
	return 1 / (2 * M_PI * (1 - s->sun_cos));
}

double sky_pdf_sun(const struct sky *s, const double d[3])
{
	if (!s->has_sun || d[0] * s->sun_dir[0] + d[1] * s->sun_dir[1] + d[2] * s->sun_dir[2] < s->sun_cos)
		return 0;
	return 1 / (2 * M_PI * (1 - s->sun_cos));
}
