/* slices_draw: the pictures of the in-plane slices (slices.c computes them): the log-scale in-plane figure and the
 * polar panels, PNG via cairo. */
#include "recon/slices_int.h"

#include <cairo.h>
#include <math.h>
#include <stdio.h>

#include "recon/plot.h"
#include "recon/pngio.h"

static double px(const struct slices_frame *fr, double x)
{
	return fr->l + (x - fr->x0) / (fr->x1 - fr->x0) * (fr->r - fr->l);
}

static double py(const struct slices_frame *fr, double v)
{
	double y = log10(fmax(v, pow(10, fr->y0 - 1)));
	return fr->b - (y - fr->y0) / (fr->y1 - fr->y0) * (fr->b - fr->t);
}

static void text(cairo_t *cr, double x, double y, const char *s, double ax, double ay)
{
	cairo_text_extents_t e;
	cairo_text_extents(cr, s, &e);
	cairo_move_to(cr, x - ax * e.width - e.x_bearing, y - ay * e.height - e.y_bearing);
	cairo_show_text(cr, s);
}

/* Curves past the palette's length are dashed, so two incidences never look alike. */
static void set_dash(cairo_t *cr, size_t t)
{
	static const double dash[2] = { 7, 4 };
	if (t >= plot_palette_size())
		cairo_set_dash(cr, dash, 2, 0);
}

/* Where a series' point (x, value) is drawn: in the in-plane frame fr, or (fr NULL) on a polar panel centred at cx, cy
 * of radius R, log10 of the value on [y0, y1] (draw_polar). */
struct slices_map {
	const struct slices_frame *fr;
	double cx, cy, R, y0, y1;
};

static void map_at(const struct slices_map *mp, double x, double v, double *X, double *Y)
{
	if (mp->fr) {
		*X = px(mp->fr, x);
		*Y = py(mp->fr, v);
		return;
	}
	double r = mp->R * fmin(1, fmax(0, (log10(fmax(v, 1e-300)) - mp->y0) / (mp->y1 - mp->y0)));
	*X = mp->cx + r * sin(x * M_PI / 180);
	*Y = mp->cy - r * cos(x * M_PI / 180);
}

/* Series s's band (filled, translucent) and model curve (2 px, dashed as series t) in colour c, placed by mp. Beyond
 * the measured range (slices_beyond; judged at each segment's midpoint) the band is paler and the curve dotted: there
 * the model extrapolates. */
static void band_and_model(cairo_t *cr, const struct slices_series *s, const struct slices_map *mp, const double c[3],
			   size_t t)
{
	static const double dot[2] = { 1.5, 4 };
	double X, Y;
	for (size_t i0 = 0; i0 + 1 < s->np;) {
		int out = slices_beyond(s, 0.5 * (s->x[i0] + s->x[i0 + 1]));
		size_t i1 = i0 + 1; /* the run of segments [i0, i1] on the same side of the limit */
		while (i1 + 1 < s->np && slices_beyond(s, 0.5 * (s->x[i1] + s->x[i1 + 1])) == out)
			i1++;
		cairo_set_source_rgba(cr, c[0], c[1], c[2], out ? 0.08 : 0.22);
		for (size_t i = i0; i <= i1; i++) {
			map_at(mp, s->x[i], s->hi[i], &X, &Y);
			(i > i0 ? cairo_line_to : cairo_move_to)(cr, X, Y);
		}
		for (size_t i = i1 + 1; i-- > i0;) {
			map_at(mp, s->x[i], s->lo[i], &X, &Y);
			cairo_line_to(cr, X, Y);
		}
		cairo_close_path(cr);
		cairo_fill(cr);
		cairo_set_source_rgb(cr, c[0], c[1], c[2]);
		cairo_set_line_width(cr, 2);
		if (out)
			cairo_set_dash(cr, dot, 2, 0);
		else
			set_dash(cr, t);
		for (size_t i = i0; i <= i1; i++) {
			map_at(mp, s->x[i], s->f[i], &X, &Y);
			(i > i0 ? cairo_line_to : cairo_move_to)(cr, X, Y);
		}
		cairo_stroke(cr);
		cairo_set_dash(cr, NULL, 0, 0);
		i0 = i1;
	}
}

static void draw_inplane(cairo_t *cr, const struct slices_opts *o, const struct slices_series *S, size_t nth,
			 const struct slices_frame *fr, const char *title)
{
	cairo_set_source_rgb(cr, 1, 1, 1);
	cairo_paint(cr);
	cairo_select_font_face(cr, "sans-serif", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
	cairo_set_font_size(cr, 13);
	cairo_set_line_width(cr, 1);
	/* grid: decades and every 15° */
	int minor = fr->y1 - fr->y0 <= 2.5;
	for (int d = (int)floor(fr->y0); d <= (int)ceil(fr->y1); d++) {
		for (int mlt = 2; minor && mlt <= 5; mlt += 3) {
			double lv = d + log10(mlt);
			if (lv < fr->y0 || lv > fr->y1)
				continue;
			double y = py(fr, pow(10, lv));
			char b[32];
			cairo_set_source_rgb(cr, 0.94, 0.94, 0.94);
			cairo_move_to(cr, fr->l, y);
			cairo_line_to(cr, fr->r, y);
			cairo_stroke(cr);
			snprintf(b, sizeof b, "%ge%d", (double)mlt, d);
			cairo_set_source_rgb(cr, 0.3, 0.3, 0.3);
			text(cr, fr->l - 6, y, b, 1, 0.5);
		}
		if (d < fr->y0 - 1e-9 || d > fr->y1 + 1e-9)
			continue;
		double y = py(fr, pow(10, d));
		cairo_set_source_rgb(cr, 0.88, 0.88, 0.88);
		cairo_move_to(cr, fr->l, y);
		cairo_line_to(cr, fr->r, y);
		cairo_stroke(cr);
		char b[32];
		snprintf(b, sizeof b, "1e%d", d);
		cairo_set_source_rgb(cr, 0, 0, 0);
		text(cr, fr->l - 6, y, b, 1, 0.5);
	}
	for (int a = -90; a <= 90; a += 15) {
		double x = px(fr, a);
		cairo_set_source_rgb(cr, 0.88, 0.88, 0.88);
		cairo_move_to(cr, x, fr->t);
		cairo_line_to(cr, x, fr->b);
		cairo_stroke(cr);
		char b[16];
		snprintf(b, sizeof b, "%d", a);
		cairo_set_source_rgb(cr, 0, 0, 0);
		text(cr, x, fr->b + 6, b, 0.5, 0);
	}
	cairo_set_source_rgb(cr, 0, 0, 0);
	cairo_rectangle(cr, fr->l, fr->t, fr->r - fr->l, fr->b - fr->t);
	cairo_stroke(cr);
	text(cr, 0.5 * (fr->l + fr->r), fr->b + 26, "\u03b8o (\u00b0): \u2212 backward (\u03c6o \u2212 \u03c6i = 0\u00b0), "
	     "+ forward (\u03c6o \u2212 \u03c6i = 180\u00b0)", 0.5, 0);
	cairo_save(cr);
	cairo_translate(cr, 18, 0.5 * (fr->t + fr->b));
	cairo_rotate(cr, -M_PI / 2);
	text(cr, 0, 0, "f (sr\u207b\u00b9), log scale", 0.5, 0.5);
	cairo_restore(cr);
	if (title) {
		cairo_set_font_size(cr, 15);
		text(cr, 0.5 * (fr->l + fr->r), 12, title, 0.5, 0);
		cairo_set_font_size(cr, 13);
	}
	cairo_rectangle(cr, fr->l, fr->t, fr->r - fr->l, fr->b - fr->t);
	cairo_save(cr);
	cairo_clip(cr);
	for (size_t t = 0; t < nth; t++) {
		const struct slices_series *s = &S[t];
		double c[3];
		plot_curve_colour(t, c);
		/* band, and the model (dashed once the palette repeats) */
		band_and_model(cr, s, &(struct slices_map){ .fr = fr }, c, t);
		/* samples with ± k σ bars */
		cairo_set_line_width(cr, 1.2);
		for (size_t i = 0; i < s->ns; i++) {
			double x = px(fr, s->sx[i]), y = py(fr, s->sv[i]);
			if (isfinite(s->ss[i]) && s->ss[i] > 0) {
				double a = py(fr, s->sv[i] + o->band_k * s->ss[i]), b = py(fr, s->sv[i] - o->band_k * s->ss[i]);
				cairo_move_to(cr, x, a);
				cairo_line_to(cr, x, b);
				cairo_move_to(cr, x - 3, a);
				cairo_line_to(cr, x + 3, a);
				cairo_move_to(cr, x - 3, b);
				cairo_line_to(cr, x + 3, b);
				cairo_stroke(cr);
			}
			cairo_new_sub_path(cr);
			cairo_arc(cr, x, y, 3.2, 0, 2 * M_PI);
			cairo_fill(cr);
		}
	}
	cairo_restore(cr);
	/* legend */
	cairo_set_line_width(cr, 2);
	for (size_t t = 0; t < nth; t++) {
		double c[3], y = fr->t + 14 + 18 * (double)t;
		char b[48];
		plot_curve_colour(t, c);
		cairo_set_source_rgb(cr, c[0], c[1], c[2]);
		set_dash(cr, t);
		cairo_move_to(cr, fr->r + 10, y);
		cairo_line_to(cr, fr->r + 34, y);
		cairo_stroke(cr);
		cairo_set_dash(cr, NULL, 0, 0);
		snprintf(b, sizeof b, "\u03b8i = %.4g\u00b0 (%zu)", S[t].theta * 180 / M_PI, S[t].ns);
		cairo_set_source_rgb(cr, 0, 0, 0);
		text(cr, fr->r + 40, y, b, 0, 0.5);
	}
	char b[96];
	snprintf(b, sizeof b, "band, bars: \u00b1%g\u03c3", o->band_k);
	text(cr, fr->r + 10, fr->t + 14 + 18 * (double)nth + 8, b, 0, 0.5);
	text(cr, fr->r + 10, fr->t + 14 + 18 * (double)nth + 26, "(n) = in-plane samples", 0, 0.5);
	int beyond = 0;
	for (size_t t = 0; t < nth; t++)
		for (size_t i = 0; i < S[t].np; i++)
			beyond |= slices_beyond(&S[t], S[t].x[i]);
	if (beyond) { /* the extrapolated part's key: a dotted line over a pale band */
		double y = fr->t + 14 + 18 * (double)nth + 48;
		static const double dot[2] = { 1.5, 4 };
		cairo_set_source_rgba(cr, 0.3, 0.3, 0.3, 0.08);
		cairo_rectangle(cr, fr->r + 10, y - 6, 24, 12);
		cairo_fill(cr);
		cairo_set_source_rgb(cr, 0.3, 0.3, 0.3);
		cairo_set_dash(cr, dot, 2, 0);
		cairo_move_to(cr, fr->r + 10, y);
		cairo_line_to(cr, fr->r + 34, y);
		cairo_stroke(cr);
		cairo_set_dash(cr, NULL, 0, 0);
		cairo_set_source_rgb(cr, 0, 0, 0);
		text(cr, fr->r + 40, y, "beyond the largest", 0, 0.5);
		text(cr, fr->r + 40, y + 16, "measured \u03b8o", 0, 0.5);
	}
}

/* One polar panel: angle θo from the normal (up), forward to the right; radius log-scaled on [y0, y1]. */
static void draw_polar(cairo_t *cr, const struct slices_opts *o, const struct slices_series *s, size_t idx, double cx,
		       double cy, double R, double y0, double y1)
{
	(void)o;
	double c[3];
	plot_curve_colour(idx, c);
	cairo_new_path(cr);
#define PR(v) (R * fmin(1, fmax(0, (log10(fmax((v), 1e-300)) - y0) / (y1 - y0))))
#define PXY(a, r) cx + (r) * sin((a) * M_PI / 180), cy - (r) * cos((a) * M_PI / 180)
	cairo_set_line_width(cr, 1);
	cairo_set_source_rgb(cr, 0.85, 0.85, 0.85);
	for (int d = (int)ceil(y0); d <= (int)floor(y1); d++) {
		cairo_new_sub_path(cr);
		cairo_arc(cr, cx, cy, PR(pow(10, d)), M_PI, 2 * M_PI);
		cairo_stroke(cr);
	}
	for (int a = -90; a <= 90; a += 30) {
		cairo_move_to(cr, cx, cy);
		cairo_line_to(cr, PXY(a, R));
		cairo_stroke(cr);
	}
	/* incident direction (on the backward side) and its mirror */
	double ti = s->theta * 180 / M_PI;
	cairo_set_source_rgb(cr, 0.3, 0.3, 0.3);
	double dash[2] = { 4, 3 };
	cairo_set_dash(cr, dash, 2, 0);
	cairo_move_to(cr, cx, cy);
	cairo_line_to(cr, PXY(-ti, R));
	cairo_stroke(cr);
	cairo_set_dash(cr, NULL, 0, 0);
	band_and_model(cr, s, &(struct slices_map){ .cx = cx, .cy = cy, .R = R, .y0 = y0, .y1 = y1 }, c, idx);
	for (size_t i = 0; i < s->ns; i++) {
		cairo_new_sub_path(cr);
		cairo_arc(cr, PXY(s->sx[i], PR(s->sv[i])), 3, 0, 2 * M_PI);
		cairo_fill(cr);
	}
	cairo_set_source_rgb(cr, 0, 0, 0);
	char b[48];
	snprintf(b, sizeof b, "\u03b8i = %.4g\u00b0", ti);
	text(cr, cx, cy + 8, b, 0.5, 0);
#undef PR
#undef PXY
}

int slices_draw_inplane(const struct slices_series *S, size_t nth, const struct slices_opts *o, const struct slices_frame *fr,
			const char *png, struct acq_err *err)
{
	char title[160];
	if (o->wl_lo == o->wl_hi)
		snprintf(title, sizeof title, "In-plane BRDF at \u03bb = %g nm (model, \u00b1%g\u03c3 band; samples \u00b1%g\u03c3)",
			 o->wl_lo, o->band_k, o->band_k);
	else
		snprintf(title, sizeof title, "In-plane BRDF, %g\u2013%g nm band mean (model, \u00b1%g\u03c3 band; samples "
			 "\u00b1%g\u03c3)", o->wl_lo, o->wl_hi, o->band_k, o->band_k);
	cairo_surface_t *sf = cairo_image_surface_create(CAIRO_FORMAT_RGB24, o->width, o->height);
	cairo_t *cr = cairo_create(sf);
	draw_inplane(cr, o, S, nth, fr, title);
	cairo_destroy(cr);
	int rc = pngio_write_surface(sf, png, err);
	cairo_surface_destroy(sf);
	return rc;
}

int slices_draw_polar(const struct slices_series *S, size_t nth, const struct slices_opts *o, const struct slices_frame *fr,
		      double vmin, const char *png, struct acq_err *err)
{
	int cols = nth < 4 ? (int)nth : 4, rows = (int)((nth + 3) / 4), pw = 300, ph = 190;
	cairo_surface_t *sf = cairo_image_surface_create(CAIRO_FORMAT_RGB24, cols * pw, rows * ph + 30);
	cairo_t *cr = cairo_create(sf);
	cairo_set_source_rgb(cr, 1, 1, 1);
	cairo_paint(cr);
	cairo_select_font_face(cr, "sans-serif", CAIRO_FONT_SLANT_NORMAL, CAIRO_FONT_WEIGHT_NORMAL);
	cairo_set_font_size(cr, 12);
	cairo_set_source_rgb(cr, 0, 0, 0);
	/* radius: log f from a little below the smallest value, so the diffuse part is not squeezed */
	double py0 = fmax(fr->y0, log10(vmin) - 0.25);
	char pt[160];
	snprintf(pt, sizeof pt, "polar: radius log10 f from %.3g to %.3g (rings at decades); dashed: incidence; dotted: "
		 "beyond the largest measured \u03b8o", py0,
		 fr->y1);
	text(cr, cols * pw / 2.0, 8, pt, 0.5, 0);
	for (size_t t = 0; t < nth; t++)
		draw_polar(cr, o, &S[t], t, pw * (double)(t % 4) + pw / 2.0, 30 + ph * (double)(t / 4) + ph - 32, 130, py0,
			   fr->y1);
	cairo_destroy(cr);
	int rc = pngio_write_surface(sf, png, err);
	cairo_surface_destroy(sf);
	return rc;
}
