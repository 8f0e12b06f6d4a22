/* warp2d: a 2-D distribution on the unit square from a bilinear density at grid nodes, sampled and inverted by
 * the inversion method (marginal over rows, conditional along each row); used by the RGL writer and the sky. */
#ifndef RECON_WARP2D_H
#define RECON_WARP2D_H

#include <stddef.h>

#include "config/acq_err.h"

/*
 * Nodes: w columns (x, the contiguous index) by h rows (y); node (i, j) sits at (i/(w−1), j/(h−1)) and the density
 * is bilinear between nodes. Row j's mass r_j = Δx·Σ trapezoids; the marginal of y is linear between the r_j,
 * and the conditional along x at a height between rows j and j+1 is the linear blend of the two rows. So both
 * inverse CDFs are closed forms (a quadratic per cell), sample() and invert() are exact inverses of each other.
 */
struct warp2d {
	size_t w, h;
	double *d;     /* [h*w] node densities (as given, not normalised) */
	double *cond;  /* [h*w] cumulative mass along each row at its nodes (units of Δx·density) */
	double *marg;  /* [h] cumulative marginal mass at the row nodes */
	double total;  /* marg[h-1] */
};

/* Build from w×h non-negative finite node values (row-major, x contiguous); w, h >= 2; total mass > 0.
 * 0, or -1 with err. */
int warp2d_init(struct warp2d *wp, const double *d, size_t w, size_t h, struct acq_err *err);
/* Release (zeroed struct is fine). */
void warp2d_free(struct warp2d *wp);
/* Map a uniform point s in [0,1]² to the point u of the square distributed by the density; pdf (may be NULL)
 * receives the normalised density at u. */
void warp2d_sample(const struct warp2d *wp, const double s[2], double u[2], double *pdf);
/* The inverse of warp2d_sample: u in [0,1]² (clamped) to s. */
void warp2d_invert(const struct warp2d *wp, const double u[2], double s[2]);
/* Normalised density (integral 1 over the square) at u (clamped into the square). */
double warp2d_pdf(const struct warp2d *wp, const double u[2]);
/* Bilinear interpolation of a w×h node table (row-major, x contiguous) at u in [0,1]² (clamped). */
double warp2d_bilerp(const double *t, size_t w, size_t h, const double u[2]);

#endif
