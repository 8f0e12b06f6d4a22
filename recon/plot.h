/* plot: the DHR(λ) figure of paper Fig. 4 (curves per incidence with uncertainty bands, reference) as PNG via cairo. */
#ifndef RECON_PLOT_H
#define RECON_PLOT_H

#include <stddef.h>

#include "config/acq_err.h"

/* One curve: n points (wl[k] nm, y[k] DHR), optional 1σ uncertainty sigma[k] (NULL: no band). Points with
 * a non-finite wl or y break the line; a non-finite or negative σ draws no band there. */
struct plot_curve {
	const char *label; /* legend text, e.g. "θi = 8°" (UTF-8); NULL or "" = not in the legend */
	const double *wl;
	const double *y;
	const double *sigma;
	size_t n;
};

struct plot_dhr_opts {
	int width, height;   /* pixels, 64..8192; default 900 × 560 */
	double band_k;       /* bands are y ± band_k·σ; default 2 (±2σ, ~95 %); must be > 0 */
	const char *title;   /* NULL = none */
	const char *x_label; /* default "Wavelength (nm)" */
	const char *y_label; /* default "DHR" */
	double x_min, x_max; /* axis range; NaN (default) = automatic (data range) */
	double y_min, y_max; /* NaN (default) = automatic (0 .. nice value above max y + k·σ) */
	const struct plot_curve *residual; /* NULL (default) or a lower panel: y = (model − reference)/σ (both
					    * uncertainties), with lines at 0 and ±2; its label names it (recon side) */
};

/* Where the data went: plot area in pixels (left, top, right, bottom edges) and the axis ranges. */
struct plot_frame {
	double px_left, px_top, px_right, px_bottom;
	double x_min, x_max, y_min, y_max;
};

/* Fill o with the defaults. */
void plot_dhr_opts_default(struct plot_dhr_opts *o);

/* Draw the computed curves (each in palette colour i: line, hatched ±k·σ band) and the optional reference
 * (green line with a filled green ±k·σ band, label "reference" unless it has one), axes with ticks and
 * labels, grid, legend; write a PNG atomically (temp file + rename). frame (may be NULL) receives the
 * data → pixel mapping. o NULL = defaults. 0, or -1 with err. */
int plot_dhr_png(const char *path, const struct plot_curve *curves, size_t ncurves, const struct plot_curve *reference,
		 const struct plot_dhr_opts *o, struct plot_frame *frame, struct acq_err *err);

/* Palette colour (sRGB components 0..1) of computed curve i; plot_reference_colour for the reference line. */
void plot_curve_colour(size_t i, double rgb[3]);
void plot_reference_colour(double rgb[3]);
/* Number of distinct curve colours (plot_curve_colour repeats after it). */
size_t plot_palette_size(void);

/* Data → pixel coordinates (pixel edges: pixel (i, j) covers [i, i+1) × [j, j+1)). */
double plot_x_to_px(const struct plot_frame *f, double x);
double plot_y_to_px(const struct plot_frame *f, double y);

#endif
