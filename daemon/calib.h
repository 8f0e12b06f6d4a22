/* calib: net count rates → spectral BRDF (sr⁻¹) with a standard-uncertainty budget per wavelength, by the
 * relative (white reference) or absolute (direct beam) method, resampled from detector pixels to a grid.
 *
 * Methods (brdf-reconstruction.md, "From raw counts to BRDF"); R are net rates (S − D)/t in counts/ms:
 *   relative: f = R_s / R_ref · ρ_ref(λ)/π · cos θo_ref / cos θo   (the cosine ratio is 1 when the reference
 *             was seen under the sample's own geometry, ref_theta_o_deg = NaN)
 * Bench model behind the cosines: the detector's field of view contains the whole illuminated spot, so the
 * collected signal is P · f · cos θo · Ω_det whatever θi (the spot grows as 1/cos θi while the irradiance
 * falls as cos θi); a Lambertian reference seen at θo_ref gives P · ρ_ref/π · cos θo_ref · Ω_det.
 *   absolute: f = R_s / (R_beam · Ω_det · cos θo)
 * Uncertainty budget, each a standard uncertainty in sr⁻¹:
 *   noise  the sample's scan noise (per-pixel std / √averages, over t)
 *   dark   the dark's noise, same form
 *   ref    the reference's (or beam's) own noise and dark, combined with u(ρ_ref) (or u(Ω_det))
 *   angle  positioning: |∂f/∂θ| · σ_pos, with |∂f/∂θ| = angle_rel_per_deg · f (configured), plus the cosine
 *          factor's own sensitivity.
 * Binning: a grid value is the plain mean of the valid pixels in [λ − step/2, λ + step/2); components that
 * are independent per pixel (noise, dark, reference noise) add in quadrature (/n), components common to all
 * pixels of a bin (ρ_ref or Ω_det scale, angle) add linearly. A bin with no pixel interpolates linearly between
 * its two neighbours. Saturated (invalid) pixels are never used, nor pixels where the reference is not above
 * three times its own noise (no light to compare with); a bin with only such pixels is NaN. */
#ifndef CALIB_H
#define CALIB_H

#include <stdbool.h>

#include "config/acq_err.h"
#include "config/yconf.h"
#include "daemon/exposure.h"

#define CALIB_MAX_GRID 4096
#define CALIB_MAX_TABLE 512

enum calib_method { CALIB_RELATIVE = 0, CALIB_ABSOLUTE = 1 };

/* A spectral table with standard uncertainty, linearly interpolated, constant beyond its ends. */
struct calib_table {
	int n;
	double wl[CALIB_MAX_TABLE], val[CALIB_MAX_TABLE], u[CALIB_MAX_TABLE];
};

struct calib_cfg {
	enum calib_method method;
	struct calib_table rho_ref;  /* relative: the reference's reflectance ρ_ref(λ) and u(ρ_ref) */
	double ref_theta_o_deg;      /* relative: viewing zenith of the reference measurement; NaN = same as sample */
	double omega_det_sr;         /* absolute: detector solid angle */
	double u_omega_rel;          /* absolute: relative standard uncertainty of Ω_det */
	double angle_rel_per_deg;    /* configured |∂f/∂θ| / f, per degree */
	double sigma_pos_deg;        /* positioning standard uncertainty of each arm, degrees */
	double grid_min_nm, grid_max_nm, grid_step_nm; /* output grid */
};

/* Per-pixel result. */
struct calib_px {
	int npix;
	double f[SPECTRO_MAX_PIXELS];
	double u_noise[SPECTRO_MAX_PIXELS], u_dark[SPECTRO_MAX_PIXELS];
	double u_refn[SPECTRO_MAX_PIXELS];  /* reference noise + dark (independent per pixel) */
	double u_refs[SPECTRO_MAX_PIXELS];  /* reference scale: ρ_ref or Ω_det (common within a bin) */
	double u_angle[SPECTRO_MAX_PIXELS];
	unsigned char valid[SPECTRO_MAX_PIXELS];
};

/* A calibrated spectrum on the grid. NaN where not measured. */
struct calib_spectrum {
	int n;
	enum calib_method method;
	double wl[CALIB_MAX_GRID];
	double f[CALIB_MAX_GRID], u[CALIB_MAX_GRID];            /* value and combined standard uncertainty */
	double u_noise[CALIB_MAX_GRID], u_dark[CALIB_MAX_GRID], u_ref[CALIB_MAX_GRID], u_angle[CALIB_MAX_GRID];
	int npix[CALIB_MAX_GRID];                               /* pixels averaged (0: interpolated or none) */
	double vfac[CALIB_MAX_GRID]; /* Σ w² of the bin's pixel weights: variance of the bin per unit independent
				      * per-pixel variance (1/npix for a plain mean) */
};

/* Geometry of one sample, degrees. */
struct calib_geom {
	double theta_i, theta_o;
};

/* Defaults: relative, ρ_ref = 0.99 ± 0.005, same geometry, Ω_det 1e-3 sr ± 2 %, angle 0 %/°, σ_pos 0.005°,
 * grid 450–1100 nm at 1 nm. */
void calib_cfg_defaults(struct calib_cfg *c);
/* Parse a `calibration:` mapping onto c (absent keys keep their values). 0 or -1 with file:line:col. */
int calib_cfg_parse(struct yc_node *node, struct calib_cfg *c, struct acq_err *err);
/* Stable method name, "relative" or "absolute". */
const char *calib_method_name(enum calib_method m);
/* Number of grid points of the configured grid. */
int calib_grid_size(const struct calib_cfg *c);
/* Interpolate a table at wl (value and uncertainty). */
void calib_table_eval(const struct calib_table *t, double wl, double *val, double *u);

/* Bin pixel values onto the configured grid (see the header comment). 0 or -1. */
int calib_resample(const struct calib_cfg *c, const double *wl, const struct calib_px *px,
		   struct calib_spectrum *out, struct acq_err *err);
#define CALIB_REFN_POOL_NM 5.0 /* calib_ref_noise pools the per-pixel variance over ±this */

/* The relative standard uncertainty u(R_ref)/R_ref of the reference's (or beam's) own noise and dark, per bin of
 * c's grid into u_rel[calib_grid_size(c)], binned as calib_resample bins u_refn (NaN where no usable pixel),
 * the per-pixel variance pooled over ±CALIB_REFN_POOL_NM: the part of every sample's u_ref that one reference
 * spectrum shares with all samples of a sweep. 0 or -1. */
int calib_ref_noise(const struct calib_cfg *c, const double *wl, const struct exp_rate *ref, double *u_rel,
		    struct acq_err *err);
/* calib_pixels then calib_resample. 0 or -1. */
int calib_spectrum(const struct calib_cfg *c, const double *wl, const struct exp_rate *sample,
		   const struct exp_rate *ref, const struct calib_geom *g, struct calib_spectrum *out,
		   struct acq_err *err);

#endif
