/* warp2d: inversion-method warping of a bilinear density on the unit square (closed-form quadratic per cell). */
#include "recon/warp2d.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void warp2d_free(struct warp2d *wp)
{
	if (!wp)
		return;
	free(wp->d);
	free(wp->cond);
	free(wp->marg);
	memset(wp, 0, sizeof *wp);
}

int warp2d_init(struct warp2d *wp, const double *d, size_t w, size_t h, struct acq_err *err)
{
	memset(wp, 0, sizeof *wp);
	if (w < 2 || h < 2 || w > 65536 || h > 65536)
		return acq_errf(err, ACQ_E_INVAL, "warp2d: grid %zu x %zu (each side 2..65536)", w, h);
	for (size_t k = 0; k < w * h; k++)
		if (!isfinite(d[k]) || d[k] < 0)
			return acq_errf(err, ACQ_E_INVAL, "warp2d: node %zu (row %zu, column %zu) is %g (needs a finite "
					"value >= 0)", k, k / w, k % w, d[k]);
	wp->d = malloc(w * h * sizeof *wp->d);
	wp->cond = malloc(w * h * sizeof *wp->cond);
	wp->marg = malloc(h * sizeof *wp->marg);
	if (!wp->d || !wp->cond || !wp->marg) {
		warp2d_free(wp);
		return acq_errf(err, ACQ_E_NOMEM, "warp2d: out of memory");
	}
	wp->w = w;
	wp->h = h;
	memcpy(wp->d, d, w * h * sizeof *d);
	double dx = 1.0 / (double)(w - 1), dy = 1.0 / (double)(h - 1), prev_r = 0;
	for (size_t j = 0; j < h; j++) {
		const double *row = d + j * w;
		double *c = wp->cond + j * w;
		c[0] = 0;
		for (size_t i = 0; i + 1 < w; i++)
			c[i + 1] = c[i] + 0.5 * dx * (row[i] + row[i + 1]);
		double r = c[w - 1];
		wp->marg[j] = j ? wp->marg[j - 1] + 0.5 * dy * (prev_r + r) : 0;
		prev_r = r;
	}
	wp->total = wp->marg[h - 1];
	if (!(wp->total > 0) || !isfinite(wp->total)) {
		warp2d_free(wp);
		return acq_errf(err, ACQ_E_INVAL, "warp2d: the density has no mass (all nodes 0)");
	}
	return 0;
}

static double clamp01(double x)
{
	return x < 0 ? 0 : x > 1 ? 1 : x;
}

/* t in [0, 1] with a·t + (b − a)·t²/2 = c (the mass of a linear density from a to b over [0, t] equals c). */
static double solve_lin(double a, double b, double c)
{
	if (c <= 0)
		return 0;
	double disc = a * a + 2 * (b - a) * c;
	double den = a + sqrt(disc > 0 ? disc : 0);
	if (!(den > 0))
		return b > 0 ? 1 : 0.5; /* zero density on the cell: any point; the middle */
	return clamp01(2 * c / den);
}

/* Largest k in [0, n−2] with cum[k] <= v (cum non-decreasing): past any empty cells that end at v. */
static size_t find_cell(const double *cum, size_t n, double v)
{
	size_t lo = 0, hi = n - 1;
	while (hi - lo > 1) {
		size_t mid = (lo + hi) / 2;
		if (cum[mid] <= v)
			lo = mid;
		else
			hi = mid;
	}
	return lo;
}

void warp2d_sample(const struct warp2d *wp, const double s[2], double u[2], double *pdf)
{
	size_t w = wp->w, h = wp->h;
	double dx = 1.0 / (double)(w - 1), dy = 1.0 / (double)(h - 1);
	double ty = clamp01(s[1]) * wp->total;
	size_t j = find_cell(wp->marg, h, ty);
	double r0 = wp->cond[j * w + w - 1], r1 = wp->cond[(j + 1) * w + w - 1];
	double t = solve_lin(r0, r1, (ty - wp->marg[j]) / dy);
	u[1] = clamp01(((double)j + t) * dy);
	const double *c0 = wp->cond + j * w, *c1 = wp->cond + (j + 1) * w;
	const double *d0 = wp->d + j * w, *d1 = wp->d + (j + 1) * w;
	double q = (1 - t) * c0[w - 1] + t * c1[w - 1];
	if (!(q > 0)) {
		u[0] = clamp01(s[0]);
	} else {
		double tx = clamp01(s[0]) * q;
		/* binary search on the blended cumulative row */
		size_t lo = 0, hi = w - 1;
		while (hi - lo > 1) {
			size_t mid = (lo + hi) / 2;
			if ((1 - t) * c0[mid] + t * c1[mid] <= tx)
				lo = mid;
			else
				hi = mid;
		}
		double base = (1 - t) * c0[lo] + t * c1[lo];
		double a = (1 - t) * d0[lo] + t * d1[lo], b = (1 - t) * d0[lo + 1] + t * d1[lo + 1];
		u[0] = clamp01(((double)lo + solve_lin(a, b, (tx - base) / dx)) * dx);
	}
	if (pdf)
		*pdf = warp2d_pdf(wp, u);
}

void warp2d_invert(const struct warp2d *wp, const double u_in[2], double s[2])
{
	size_t w = wp->w, h = wp->h;
	double dx = 1.0 / (double)(w - 1), dy = 1.0 / (double)(h - 1);
	double x = clamp01(u_in[0]) * (double)(w - 1), y = clamp01(u_in[1]) * (double)(h - 1);
	size_t i = x >= (double)(w - 1) ? w - 2 : (size_t)x, j = y >= (double)(h - 1) ? h - 2 : (size_t)y;
	double tx = x - (double)i, ty = y - (double)j;
	double r0 = wp->cond[j * w + w - 1], r1 = wp->cond[(j + 1) * w + w - 1];
	s[1] = clamp01((wp->marg[j] + dy * (r0 * ty + 0.5 * (r1 - r0) * ty * ty)) / wp->total);
	const double *c0 = wp->cond + j * w, *c1 = wp->cond + (j + 1) * w;
	const double *d0 = wp->d + j * w, *d1 = wp->d + (j + 1) * w;
	double q = (1 - ty) * c0[w - 1] + ty * c1[w - 1];
	double a = (1 - ty) * d0[i] + ty * d1[i], b = (1 - ty) * d0[i + 1] + ty * d1[i + 1];
	double cx = (1 - ty) * c0[i] + ty * c1[i] + dx * (a * tx + 0.5 * (b - a) * tx * tx);
	s[0] = q > 0 ? clamp01(cx / q) : clamp01(u_in[0]);
}

double warp2d_bilerp(const double *t, size_t w, size_t h, const double u[2])
{
	double x = clamp01(u[0]) * (double)(w - 1), y = clamp01(u[1]) * (double)(h - 1);
	size_t i = x >= (double)(w - 1) ? w - 2 : (size_t)x, j = y >= (double)(h - 1) ? h - 2 : (size_t)y;
	double tx = x - (double)i, ty = y - (double)j;
	const double *r0 = t + j * w, *r1 = t + (j + 1) * w;
	return (1 - ty) * ((1 - tx) * r0[i] + tx * r0[i + 1]) + ty * ((1 - tx) * r1[i] + tx * r1[i + 1]);
}

double warp2d_pdf(const struct warp2d *wp, const double u[2])
{
	return warp2d_bilerp(wp->d, wp->w, wp->h, u) / wp->total;
}
