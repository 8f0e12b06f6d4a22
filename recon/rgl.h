/* rgl: the reconstructed model as a spectral RGL tabulated BRDF (".bsdf", Dupuy & Jakob 2018), isotropic. */
#ifndef RECON_RGL_H
#define RECON_RGL_H

#include <stddef.h>

#include "config/acq_err.h"
#include "recon/recon.h"

#define RGL_MAX_WL 4096

struct rgl_opts {
	const double *wl;     /* output wavelengths (nm, increasing, inside the model's range); NULL = the model's */
	size_t nwl;
	int res;              /* nodes per side of the warped grid (vndf, luminance, spectra); 4..256, default 32 */
	int ndf_res;          /* nodes per side of the ndf and sigma tables; 8..1024, default 128 */
	int ntheta;           /* incidence nodes θ_k = k·90°/ntheta, k = 0..ntheta−1; 2..180, default 30 */
	int threads;          /* 1..16 (results identical for any count); default 1 */
	const char *source;   /* the model's path, recorded in the description (may be NULL) */
	int rgb;              /* 1: an RGB file (field `rgb` [1, Nθ, 3, H, W] of linear sRGB, no `wavelengths`), what
			       * Mitsuba 3's RGB variants load; the spectra reduced by colour_opts_brdf's chain */
};

/* What was written (all measured while writing). */
struct rgl_stats {
	size_t bytes;           /* file size */
	size_t nwl, ntheta, res, ndf_res;
	size_t zero_nodes;      /* warped-grid nodes whose reflected direction is below the horizon (value 0) */
	double ndf_floor;       /* floor added to the NDF (relative to its maximum), so D > 0 everywhere */
	size_t rgb_clamped;     /* RGB file: table values below 0 (out of the sRGB gamut) written as 0 */
};

/* Defaults above. */
void rgl_opts_default(struct rgl_opts *o);

/* Tabulate model m and write the file atomically. The tables come from the model: the NDF by the retro-
 * reflection fixed point of Dupuy & Jakob (luminance-weighted), its projected area σ by quadrature, the VNDF
 * per incidence node, and at each node s of the warped grid f(ωi, ωo(s), λ)·cosθo·4σ(ωi)/D(ωm(s)) (and its CIE
 * Y luminance) so that the renderers' rule f·cosθo = spectra(s)·D(ωm)/(4σ(ωi)) returns the model at the nodes.
 * Deterministic (no time stamps; any thread count). 0, or -1 with err. */
int rgl_write(const struct recon_model *m, const struct rgl_opts *o, const char *path, struct rgl_stats *st,
	      struct acq_err *err);

/* Parse a wavelength list "400:700:10" (first:last:step, inclusive) or "450,500,550" into wl (up to max);
 * *n receives the count. 0, or -1 with err. */
int rgl_parse_wavelengths(const char *spec, double *wl, size_t max, size_t *n, struct acq_err *err);

#endif
