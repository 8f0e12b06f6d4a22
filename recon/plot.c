/* plot: DHR(λ) figure (paper Fig. 4) drawn with cairo: hatched ±kσ bands, reference band, axes, legend. */
#include "recon/plot.h"

#include <cairo.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "recon/pngio.h"

#define PLOT_MAX_CURVES 64

/* Colour-blind-aware qualitative palette (Tableau 10 without its green, which the reference uses). */
static const double palette[][3] = {
	{ 0.122, 0.467, 0.706 }, /* blue */
	{ 1.000, 0.498, 0.055 }, /* orange */
	{ 0.839, 0.153, 0.157 }, /* red */
	{ 0.580, 0.404, 0.741 }, /* purple */
	{ 0.549, 0.337, 0.294 }, /* brown */
	{ 0.890, 0.467, 0.761 }, /* pink */
	{ 0.498, 0.498, 0.498 }, /* grey */
	{ 0.737, 0.741, 0.133 }, /* olive */
	{ 0.090, 0.745, 0.812 }, /* cyan */
};
#define PALETTE_N (sizeof(palette) / sizeof(palette[0]))
static const double ref_line[3] = { 0.0, 0.45, 0.0 };
static const double ref_band[3] = { 0.30, 0.75, 0.30 };

void plot_curve_colour(size_t i, double rgb[3])
{
	memcpy(rgb, palette[i % PALETTE_N], 3 * sizeof(double));
}

size_t plot_palette_size(void)
{
	return PALETTE_N;
}

void plot_reference_colour(double rgb[3])
{
	memcpy(rgb, ref_line, 3 * sizeof(double));
}

void plot_dhr_opts_default(struct plot_dhr_opts *o)
{
	memset(o, 0, sizeof(*o));
	o->width = 900;
	o->height = 560;
	o->band_k = 2;
	o->title = NULL;
	o->x_label = "Wavelength (nm)";
	o->y_label = "DHR";
	o->x_min = o->x_max = o->y_min = o->y_max = NAN;
}

double plot_x_to_px(const struct plot_frame *f, double x)
{
	return f->px_left + (x - f->x_min) / (f->x_max - f->x_min) * (f->px_right - f->px_left);
}

double plot_y_to_px(const struct plot_frame *f, double y)
{
	return f->px_bottom - (y - f->y_min) / (f->y_max - f->y_min) * (f->px_bottom - f->px_top);
}

/* Pixel coordinates for drawing, kept in a range cairo's fixed-point arithmetic handles. */
static double cx(const struct plot_frame *f, double x)
{
	return fmax(-1e5, fmin(1e5, plot_x_to_px(f, x)));
}

static double cy(const struct plot_frame *f, double y)
{
	return fmax(-1e5, fmin(1e5, plot_y_to_px(f, y)));
}

/* 1, 2 or 5 × 10^k, the smallest not below raw. */
static double nice_step(double raw)
{
	if (!(raw > 0) || !isfinite(raw))
		return 1;
	double p = pow(10, floor(log10(raw)));
	double m = raw / p;
	return (m <= 1 ? 1 : m <= 2 ? 2 : m <= 5 ? 5 : 10) * p;
}

static int point_ok(const struct plot_curve *c, size_t k)
{
	return isfinite(c->wl[k]) && isfinite(c->y[k]);
}

static int sigma_ok(const struct plot_curve *c, size_t k)
{
	return c->sigma && point_ok(c, k) && isfinite(c->sigma[k]) && c->sigma[k] >= 0;
}

static void extend(const struct plot_curve *c, double k, double *x0, double *x1, double *y0, double *y1)
{
	for (size_t i = 0; i < c->n; i++) {
		if (!point_ok(c, i))
			continue;
		double s = sigma_ok(c, i) ? k * c->sigma[i] : 0;
		*x0 = fmin(*x0, c->wl[i]);
		*x1 = fmax(*x1, c->wl[i]);
		*y0 = fmin(*y0, c->y[i] - s);
		*y1 = fmax(*y1, c->y[i] + s);
	}
}

static int check_curve(const struct plot_curve *c, const char *what, size_t i, struct acq_err *err)
{
	if (!c->wl || !c->y || c->n == 0)
		return acq_errf(err, ACQ_E_INVAL, "plot: %s %zu has no points", what, i);
	return 0;
}

/* Band path y ± kσ over each run of points with a usable σ; appended as closed sub-paths. */
static void band_path(cairo_t *cr, const struct plot_frame *f, const struct plot_curve *c, double k)
{
	size_t i = 0;
	while (i < c->n) {
		while (i < c->n && !sigma_ok(c, i))
			i++;
		size_t start = i;
		while (i < c->n && sigma_ok(c, i))
			i++;
		if (i - start < 2)
			continue;
		for (size_t j = start; j < i; j++) {
			double px = cx(f, c->wl[j]), py = cy(f, c->y[j] + k * c->sigma[j]);
			if (j == start)
				cairo_move_to(cr, px, py);
			else
				cairo_line_to(cr, px, py);
		}
		for (size_t j = i; j-- > start;)
			cairo_line_to(cr, cx(f, c->wl[j]), cy(f, c->y[j] - k * c->sigma[j]));
		cairo_close_path(cr);
	}
}

static void line_path(cairo_t *cr, const struct plot_frame *f, const struct plot_curve *c)
{
	int pen = 0;
	for (size_t j = 0; j < c->n; j++) {
		if (!point_ok(c, j)) {
			pen = 0;
			continue;
		}
		double px = cx(f, c->wl[j]), py = cy(f, c->y[j]);
		if (pen)
			cairo_line_to(cr, px, py);
		else
			cairo_move_to(cr, px, py);
		pen = 1;
	}
}

static void hatch(cairo_t *cr, const struct plot_frame *f, int dir, double spacing)
{
	double w = f->px_right - f->px_left, h = f->px_bottom - f->px_top;
	for (double s = -h; s < w + h; s += spacing) {
		double x = f->px_left + s;
		cairo_move_to(cr, x, dir > 0 ? f->px_bottom : f->px_top);
		cairo_line_to(cr, x + h, dir > 0 ? f->px_top : f->px_bottom);
	}
}

static void text_at(cairo_t *cr, const char *s, double x, double y, double ax, double ay)
{
	cairo_text_extents_t e;
	cairo_text_extents(cr, s, &e);
	cairo_move_to(cr, x - e.x_bearing - ax * e.width, y - e.y_bearing - ay * e.height);
	cairo_show_text(cr, s);
}

static int resolve_range(double *lo, double *hi, double dlo, double dhi, int nice, const char *axis,
			 struct acq_err *err)
{
	int given_lo = isfinite(*lo), given_hi = isfinite(*hi);
	if ((!isnan(*lo) && !given_lo) || (!isnan(*hi) && !given_hi))
		return acq_errf(err, ACQ_E_INVAL, "plot: %s range must be finite or NaN (automatic)", axis);
	if (!(dlo <= dhi)) { /* no finite data */
		dlo = 0;
		dhi = 1;
	}
	if (!given_lo)
		*lo = dlo;
	if (!given_hi)
		*hi = dhi;
	if (!(*hi > *lo)) {
		if (given_lo && given_hi)
			return acq_errf(err, ACQ_E_INVAL, "plot: %s range [%g, %g] is empty", axis, *lo, *hi);
		double pad = fabs(*lo) > 0 ? 0.1 * fabs(*lo) : 1;
		if (!given_hi)
			*hi = *lo + pad;
		else
			*lo = *hi - pad;
	}
	if (!isfinite(*hi - *lo) || (*hi - *lo) < 1e-12 * fmax(fabs(*lo), fabs(*hi)))
		return acq_errf(err, ACQ_E_INVAL, "plot: %s range [%g, %g] too wide or too narrow to draw", axis, *lo, *hi);
	if (nice) { /* round the automatic ends outward to the tick step */
		double step = nice_step((*hi - *lo) / 5);
		if (!given_lo)
			*lo = floor(*lo / step) * step;
		if (!given_hi)
			*hi = ceil(*hi / step - 1e-9) * step;
	}
	return 0;
}

/* The residual panel between pixel rows top and bottom under the plot frame f (same x mapping): r->y in units of
 * σ, symmetric range at least ±3, lines at 0 and ±2, points joined. -1 if no point is finite. */
static int residual_panel(cairo_t *cr, const struct plot_frame *f, const struct plot_curve *r, double top, double bottom)
{
	double m = 3;
	size_t ok = 0;
	for (size_t i = 0; r->wl && r->y && i < r->n; i++)
		if (point_ok(r, i)) {
			m = fmax(m, fabs(r->y[i]) * 1.1);
			ok++;
		}
	if (!ok || bottom - top < 16)
		return -1;
	m = fmin(m, 1e6);
	struct plot_frame g = *f;
	g.px_top = top;
	g.px_bottom = bottom;
	g.y_min = -m;
	g.y_max = m;
	char lab[32];
	cairo_set_font_size(cr, 11);
	for (int k = -2; k <= 2; k += 2) {
		double py = round(plot_y_to_px(&g, k)) + 0.5;
		cairo_set_source_rgb(cr, k ? 0.75 : 0.4, k ? 0.3 : 0.4, k ? 0.3 : 0.4);
		cairo_set_line_width(cr, 1);
		cairo_move_to(cr, g.px_left, py);
		cairo_line_to(cr, g.px_right, py);
		cairo_stroke(cr);
		cairo_set_source_rgb(cr, 0, 0, 0);
		snprintf(lab, sizeof lab, "%+d", k);
		text_at(cr, k ? lab : "0", g.px_left - 8, py, 1, 0.5);
	}
	cairo_save(cr);
	cairo_rectangle(cr, g.px_left, g.px_top, g.px_right - g.px_left, g.px_bottom - g.px_top);
	cairo_clip(cr);
	line_path(cr, &g, r);
	cairo_set_source_rgb(cr, 0.1, 0.1, 0.1);
	cairo_set_line_width(cr, 1.5);
	cairo_stroke(cr);
	cairo_restore(cr);
	cairo_set_source_rgb(cr, 0, 0, 0);
	cairo_rectangle(cr, g.px_left + 0.5, g.px_top + 0.5, g.px_right - g.px_left - 1, g.px_bottom - g.px_top - 1);
	cairo_stroke(cr);
	cairo_save(cr);
	cairo_translate(cr, 16, (g.px_top + g.px_bottom) / 2);
	cairo_rotate(cr, -M_PI / 2);
	text_at(cr, r->label && *r->label ? r->label : "residual / \xcf\x83", 0, 0, 0.5, 0);
	cairo_restore(cr);
	return 0;
}

/* plot_dhr_png's arguments checked: 0, or -1 with err saying which. */
static int check_args(const char *path, const struct plot_curve *curves, size_t ncurves,
		      const struct plot_curve *reference, const struct plot_dhr_opts *o, struct acq_err *err)
{
	if (!path || !*path)
		return acq_errf(err, ACQ_E_INVAL, "plot: no output path");
	if (o->width < 64 || o->width > 8192 || o->height < 64 || o->height > 8192)
		return acq_errf(err, ACQ_E_INVAL, "plot: image size %d × %d outside 64..8192", o->width, o->height);
	if (!(o->band_k > 0) || !isfinite(o->band_k))
		return acq_errf(err, ACQ_E_INVAL, "plot: band_k must be finite and > 0 (got %g)", o->band_k);
	if ((ncurves > 0 && !curves) || ncurves > PLOT_MAX_CURVES)
		return acq_errf(err, ACQ_E_INVAL, "plot: %zu curves (at most %d)", ncurves, PLOT_MAX_CURVES);
	if (ncurves == 0 && !reference)
		return acq_errf(err, ACQ_E_INVAL, "plot: nothing to plot");
	for (size_t i = 0; i < ncurves; i++)
		if (check_curve(&curves[i], "curve", i, err) != 0)
			return -1;
	if (reference && check_curve(reference, "reference", 0, err) != 0)
		return -1;
	return 0;
}

/* The frame *f: data ranges (bands included; y starts at 0 unless data go below) unless o gives them, and the
 * pixel box of the axes (the residual panel, if any, below it). 0, or -1 with err. */
static int layout(const struct plot_curve *curves, size_t ncurves, const struct plot_curve *reference,
		  const struct plot_dhr_opts *o, struct plot_frame *f, struct acq_err *err)
{
	double k = o->band_k;
	double x0 = INFINITY, x1 = -INFINITY, y0 = 0, y1 = -INFINITY;
	for (size_t i = 0; i < ncurves; i++)
		extend(&curves[i], k, &x0, &x1, &y0, &y1);
	if (reference)
		extend(reference, k, &x0, &x1, &y0, &y1);
	if (!(y1 >= y0))
		y1 = y0;
	*f = (struct plot_frame){ 0 };
	f->x_min = o->x_min;
	f->x_max = o->x_max;
	f->y_min = o->y_min;
	f->y_max = o->y_max;
	if (resolve_range(&f->x_min, &f->x_max, x0, x1, 0, "x", err) != 0 ||
	    resolve_range(&f->y_min, &f->y_max, y0, y1, 1, "y", err) != 0)
		return -1;
	double W = o->width, H = o->height;
	f->px_left = 78;
	f->px_right = W - 18;
	f->px_top = o->title ? 42 : 18;
	f->px_bottom = H - 58;
	double panel = o->residual ? floor(0.26 * (H - 58 - f->px_top)) : 0; /* residual panel below the axes */
	f->px_bottom -= panel;
	if (f->px_right - f->px_left < 16 || f->px_bottom - f->px_top < 16)
		return acq_errf(err, ACQ_E_INVAL, "plot: image %d × %d too small for the axes", o->width, o->height);
	return 0;
}

/* Grid lines and ticks with their labels, x then y. */
static void draw_grid(cairo_t *cr, const struct plot_frame *f)
{
	double xs = nice_step((f->x_max - f->x_min) / 8), ys = nice_step((f->y_max - f->y_min) / 6);
	char lab[64];
	cairo_set_line_width(cr, 1);
	double xstart = ceil(f->x_min / xs - 1e-9) * xs, ystart = ceil(f->y_min / ys - 1e-9) * ys;
	for (int it = 0; it < 100; it++) {
		double x = xstart + it * xs;
		if (x > f->x_max + 1e-9 * xs)
			break;
		double px = round(plot_x_to_px(f, x)) + 0.5;
		cairo_set_source_rgb(cr, 0.9, 0.9, 0.9);
		cairo_move_to(cr, px, f->px_top);
		cairo_line_to(cr, px, f->px_bottom);
		cairo_stroke(cr);
		cairo_set_source_rgb(cr, 0, 0, 0);
		cairo_move_to(cr, px, f->px_bottom);
		cairo_line_to(cr, px, f->px_bottom + 5);
		cairo_stroke(cr);
		snprintf(lab, sizeof(lab), "%g", fabs(x) < 1e-12 * xs ? 0.0 : x);
		text_at(cr, lab, px, f->px_bottom + 8, 0.5, 0);
	}
	for (int it = 0; it < 100; it++) {
		double y = ystart + it * ys;
		if (y > f->y_max + 1e-9 * ys)
			break;
		double py = round(plot_y_to_px(f, y)) + 0.5;
		cairo_set_source_rgb(cr, 0.9, 0.9, 0.9);
		cairo_move_to(cr, f->px_left, py);
		cairo_line_to(cr, f->px_right, py);
		cairo_stroke(cr);
		cairo_set_source_rgb(cr, 0, 0, 0);
		cairo_move_to(cr, f->px_left - 5, py);
		cairo_line_to(cr, f->px_left, py);
		cairo_stroke(cr);
		snprintf(lab, sizeof(lab), "%g", fabs(y) < 1e-12 * ys ? 0.0 : y);
		text_at(cr, lab, f->px_left - 8, py, 1, 0.5);
	}
}

/* The data, clipped to the plot area: bands (the reference's filled, the curves' hatched), then the lines. */
static void draw_data(cairo_t *cr, const struct plot_frame *f, const struct plot_curve *curves, size_t ncurves,
		      const struct plot_curve *reference, double k)
{
	cairo_save(cr);
	cairo_rectangle(cr, f->px_left, f->px_top, f->px_right - f->px_left, f->px_bottom - f->px_top);
	cairo_clip(cr);
	if (reference && reference->sigma) {
		band_path(cr, f, reference, k);
		cairo_set_source_rgba(cr, ref_band[0], ref_band[1], ref_band[2], 0.35);
		cairo_fill(cr);
	}
	for (size_t i = 0; i < ncurves; i++) {
		if (!curves[i].sigma)
			continue;
		const double *c = palette[i % PALETTE_N];
		cairo_save(cr);
		band_path(cr, f, &curves[i], k);
		cairo_set_source_rgba(cr, c[0], c[1], c[2], 0.10);
		cairo_fill_preserve(cr);
		cairo_clip(cr);
		hatch(cr, f, i % 2 ? -1 : 1, 7 + (double)(i % 3));
		cairo_set_source_rgba(cr, c[0], c[1], c[2], 0.45);
		cairo_set_line_width(cr, 1);
		cairo_stroke(cr);
		cairo_restore(cr);
	}
	cairo_set_line_join(cr, CAIRO_LINE_JOIN_ROUND);
	cairo_set_line_width(cr, 2);
	if (reference) {
		line_path(cr, f, reference);
		cairo_set_source_rgb(cr, ref_line[0], ref_line[1], ref_line[2]);
		cairo_stroke(cr);
	}
	for (size_t i = 0; i < ncurves; i++) {
		const double *c = palette[i % PALETTE_N];
		line_path(cr, f, &curves[i]);
		cairo_set_source_rgb(cr, c[0], c[1], c[2]);
		cairo_stroke(cr);
	}
	cairo_restore(cr);
}

/* The axes' frame, the axis labels and the title. */
static void draw_labels(cairo_t *cr, const struct plot_frame *f, const struct plot_dhr_opts *o)
{
	double W = o->width, H = o->height;
	cairo_set_source_rgb(cr, 0, 0, 0);
	cairo_set_line_width(cr, 1);
	cairo_rectangle(cr, f->px_left + 0.5, f->px_top + 0.5, f->px_right - f->px_left - 1, f->px_bottom - f->px_top - 1);
	cairo_stroke(cr);
	cairo_set_font_size(cr, 14);
	text_at(cr, o->x_label ? o->x_label : "", (f->px_left + f->px_right) / 2, H - 22, 0.5, 0);
	cairo_save(cr);
	cairo_translate(cr, 16, (f->px_top + f->px_bottom) / 2);
	cairo_rotate(cr, -M_PI / 2);
	text_at(cr, o->y_label ? o->y_label : "", 0, 0, 0.5, 0);
	cairo_restore(cr);
	if (o->title) {
		cairo_set_font_size(cr, 15);
		text_at(cr, o->title, W / 2, 12, 0.5, 0);
	}
}

/* The legend's label of curve i (i == ncurves: the reference); NULL or "" for none. */
static const char *legend_label(const struct plot_curve *c, size_t i, size_t ncurves)
{
	return i < ncurves ? c->label : (c->label && *c->label ? c->label : "reference");
}

/* The legend, top right inside the plot area: one row per labelled curve, then the band convention. */
static void draw_legend(cairo_t *cr, const struct plot_frame *f, const struct plot_curve *curves, size_t ncurves,
			const struct plot_curve *reference, double k)
{
	cairo_set_font_size(cr, 12);
	size_t rows = 0;
	double wmax = 0;
	int any_sigma = reference && reference->sigma;
	char bandtxt[64];
	for (size_t i = 0; i <= ncurves; i++) {
		const struct plot_curve *c = i < ncurves ? &curves[i] : reference;
		if (!c)
			continue;
		any_sigma |= c->sigma != NULL;
		const char *l = legend_label(c, i, ncurves);
		if (!l || !*l)
			continue;
		cairo_text_extents_t e;
		cairo_text_extents(cr, l, &e);
		wmax = fmax(wmax, e.x_advance);
		rows++;
	}
	snprintf(bandtxt, sizeof(bandtxt), "bands: \xc2\xb1%g\xcf\x83", k); /* "±kσ" */
	if (any_sigma) {
		cairo_text_extents_t e;
		cairo_text_extents(cr, bandtxt, &e);
		wmax = fmax(wmax, e.x_advance - 30);
		rows++;
	}
	if (rows == 0)
		return;
	double rowh = 18, bw = wmax + 46, bh = (double)rows * rowh + 8;
	double bx = f->px_right - bw - 8, by = f->px_top + 8, y = by + 4;
	cairo_rectangle(cr, bx, by, bw, bh);
	cairo_set_source_rgba(cr, 1, 1, 1, 0.85);
	cairo_fill_preserve(cr);
	cairo_set_source_rgb(cr, 0.6, 0.6, 0.6);
	cairo_stroke(cr);
	for (size_t i = 0; i <= ncurves; i++) {
		const struct plot_curve *c = i < ncurves ? &curves[i] : reference;
		if (!c)
			continue;
		const char *l = legend_label(c, i, ncurves);
		if (!l || !*l)
			continue;
		const double *col = i < ncurves ? palette[i % PALETTE_N] : ref_line;
		if (c->sigma) {
			cairo_rectangle(cr, bx + 6, y + 3, 26, rowh - 6);
			if (i < ncurves)
				cairo_set_source_rgba(cr, col[0], col[1], col[2], 0.25);
			else
				cairo_set_source_rgba(cr, ref_band[0], ref_band[1], ref_band[2], 0.35);
			cairo_fill(cr);
		}
		cairo_set_source_rgb(cr, col[0], col[1], col[2]);
		cairo_set_line_width(cr, 2);
		cairo_move_to(cr, bx + 6, y + rowh / 2);
		cairo_line_to(cr, bx + 32, y + rowh / 2);
		cairo_stroke(cr);
		cairo_set_source_rgb(cr, 0, 0, 0);
		text_at(cr, l, bx + 38, y + rowh / 2, 0, 0.5);
		y += rowh;
	}
	if (any_sigma) {
		cairo_set_source_rgb(cr, 0.25, 0.25, 0.25);
		text_at(cr, bandtxt, bx + 8, y + rowh / 2, 0, 0.5);
	}
}

int plot_dhr_png(const char *path, const struct plot_curve *curves, size_t ncurves, const struct plot_curve *reference,
		 const struct plot_dhr_opts *o, struct plot_frame *frame, struct acq_err *err)
{
	struct plot_dhr_opts def;
	plot_dhr_opts_default(&def);
	if (!o)
		o = &def;
	struct plot_frame f;
	if (check_args(path, curves, ncurves, reference, o, err) != 0 ||
	    layout(curves, ncurves, reference, o, &f, err) != 0)
		return -1;

	cairo_surface_t *surf = cairo_image_surface_create(CAIRO_FORMAT_RGB24, o->width, o->height);
	cairo_t *cr = cairo_create(surf);
	cairo_set_source_rgb(cr, 1, 1, 1);
	cairo_paint(cr);
	cairo_select_font_face(cr, "sans-serif", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
	cairo_set_font_size(cr, 13);
	draw_grid(cr, &f);
	draw_data(cr, &f, curves, ncurves, reference, o->band_k);
	draw_labels(cr, &f, o);
	draw_legend(cr, &f, curves, ncurves, reference, o->band_k);
	if (o->residual && residual_panel(cr, &f, o->residual, f.px_bottom + 26, o->height - 58) != 0)
		cairo_set_source_rgb(cr, 0, 0, 0); /* nothing drawable: the panel stays empty */

	cairo_surface_flush(surf);
	int rc = 0;
	if (cairo_status(cr) != CAIRO_STATUS_SUCCESS)
		rc = acq_errf(err, ACQ_E_NOMEM, "plot: drawing failed: %s", cairo_status_to_string(cairo_status(cr)));
	cairo_destroy(cr);
	if (rc == 0)
		rc = pngio_write_surface(surf, path, err);
	cairo_surface_destroy(surf);
	if (rc == 0 && frame)
		*frame = f;
	return rc;
}
