/* slices: in-plane BRDF slices (φo − φi = 0° / 180°) per incidence on a log scale, with the reconstruction's
 * pointwise uncertainty band and the measured samples with their error bars, and polar plots; PNG via cairo. */
#ifndef RECON_SLICES_H
#define RECON_SLICES_H

#include <stddef.h>

#include "config/acq_err.h"
#include "recon/csvio.h"
#include "recon/recon.h"

#define SLICES_MAX_THETA 32

struct slices_opts {
	double wl_lo, wl_hi; /* nm: one wavelength (equal) or a band (its channels averaged, trapezoid weights) */
	double band_k;       /* band and error bars are ± band_k σ; default 2 */
	double phi_tol_deg;  /* a sample is in the plane when |sin(φo − φi)| ≤ sin(tol); default 2 */
	int width, height;   /* in-plane figure; default 1000 × 640 (64..8192) */
	int npts;            /* model points per side of the plane; default 90 */
};

/* What was drawn. */
struct slices_result {
	size_t nth;                        /* incidences */
	double theta[SLICES_MAX_THETA];    /* their θi, radians */
	size_t nsamples;                   /* measured in-plane samples drawn */
	size_t nchannels;                  /* model channels in the selection */
	double theta_o_max[SLICES_MAX_THETA]; /* largest measured θo per incidence (deg; NaN without samples) */
	size_t beyond[SLICES_MAX_THETA];   /* model points drawn beyond it (dotted, pale band; beyond_data 1 in the CSV) */
};

/* Defaults above; the wavelength range is left NaN (the caller chooses). */
void slices_opts_default(struct slices_opts *o);

/* Channel weights of a selection: wsel[l] (model channels, sum 1): the two channels around one wavelength
 * (linear), or the channels inside [lo, hi] with trapezoid weights (the nearest channel if none is inside).
 * 0, or -1 with err (outside the model's range, lo > hi). */
int slices_weights(const struct recon_model *m, double lo, double hi, double *wsel, struct acq_err *err);


/* Draw the in-plane figure to png (and the polar panels to polar_png if not NULL; curve data to csv if not
 * NULL: kind,theta_i,theta_o_signed,value,lo,hi,beyond_data with θo signed + on the forward side φo − φi = 180°;
 * the model beyond the largest measured θo of an incidence drawn dotted over a paler band) for the
 * incidences theta[nth] (radians), or, with nth = 0, every incidence at which samples s has in-plane samples
 * (up to SLICES_MAX_THETA). s may be NULL (no samples drawn; then nth must be > 0). 0, or -1 with err. */
int slices_plot(const struct recon_model *m, const struct recon_samples *s, const double *theta, size_t nth,
		const struct slices_opts *o, const char *png, const char *polar_png, const char *csv,
		struct slices_result *res, struct acq_err *err);

#endif
