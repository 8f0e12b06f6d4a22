/* colour: the spectral → RGB chain of paper Fig. 2, every stage an explicit decision recorded in metadata. */
#ifndef RECON_COLOUR_H
#define RECON_COLOUR_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>

#include "config/acq_err.h"

/*
 * The chain, in order (each stage is a field of struct colour_opts):
 *
 *  1. Spectral integration (linear). The spectrum s(λ) given at ascending wavelengths λ_k is read as the
 *     piecewise-linear function through its samples; XYZ = ∫ E(λ) x̄ȳz̄(λ) s(λ) dλ over 360–830 nm, summed
 *     on the CIE 1 nm grid where each 1 nm bin [λ−0.5, λ+0.5] takes the exact MEAN of the interpolant over
 *     the bin (so sub-nanometre spectra are averaged, not sub-sampled). E is D65 (5 nm table, linearly
 *     interpolated to 1 nm) or E (equal energy, "reflectance colour").
 *     Gap: the bench covers 450–1100 nm, the observer 360–830 nm. Outside the samples the spectrum is
 *     EXTENDED with its end value (default; a flat reflector stays neutral) or set to ZERO (a flat
 *     reflector then loses the 0.54 % of D65 luminance and most z̄ weight below 450 nm: it turns yellow).
 *  2. Chromatic adaptation (linear): BRADFORD from the illuminant's white (computed with the same
 *     tables) to the sRGB white (x, y) = (0.3127, 0.3290) (default), or NONE. Under E without it a white
 *     reflector is not neutral in sRGB.
 *  3. XYZ → linear sRGB with the matrix of the CIE README (IEC 61966-2-1, 7 decimals).
 *  4. Normalisation (linear). Y is first divided by ∫E ȳ dλ, so a flat spectrum of value v has Y = v.
 *     ABSOLUTE: keep the input unit (sr⁻¹ for a BRDF). WHITE: divide by `white`, the input value of the
 *     reference white (default 1/π sr⁻¹: the perfect diffuse reflector as a BRDF; 1 for reflectance
 *     input such as a DHR); the reference white maps to (1, 1, 1). MAX_ALBEDO: scale so that the largest
 *     albedo `max_albedo` (given by the caller, as a reflectance) maps to `target`: factor
 *     target / (max_albedo · white). Then `exposure` multiplies (default 1).
 *  5. Out of gamut (non-linear): a colour with a negative component is CLAMPED (negatives → 0) or
 *     DESATURATED toward the achromatic axis (mixed with its own luminance grey until the smallest
 *     component is 0; luminance kept; a colour of luminance ≤ 0 becomes black). Counted.
 *  6. Dynamic range (non-linear): KEEP (values > 1 stay: for float outputs such as MERL), CLIP to [0, 1]
 *     (counted), or REINHARD: rgb · (1 + L/Lw²) / (1 + L) with L the luminance and Lw = `reinhard_white`
 *     (the luminance that maps to 1), then clip (counted).
 *  7. Encoding: linear (default) or the sRGB transfer curve (for 8-bit images).
 *
 * Stages 1–4 are linear: colour_weights() folds them into a 3 × n matrix so that a model linear in the
 * spectrum can be reduced to three channels before it is evaluated at many directions. colour_finish()
 * applies stages 5–7 to one linear-sRGB triple. Non-finite values never come out: they become 0, counted.
 */

enum colour_illum { COLOUR_ILLUM_D65 = 0, COLOUR_ILLUM_E };
enum colour_gap { COLOUR_GAP_EXTEND = 0, COLOUR_GAP_ZERO };
enum colour_adapt { COLOUR_ADAPT_BRADFORD = 0, COLOUR_ADAPT_NONE };
enum colour_norm { COLOUR_NORM_WHITE = 0, COLOUR_NORM_ABSOLUTE, COLOUR_NORM_MAX_ALBEDO };
enum colour_gamut { COLOUR_GAMUT_CLAMP = 0, COLOUR_GAMUT_DESATURATE };
enum colour_range { COLOUR_RANGE_KEEP = 0, COLOUR_RANGE_CLIP, COLOUR_RANGE_REINHARD };

struct colour_opts {
	enum colour_illum illum;   /* D65 */
	enum colour_gap gap;       /* EXTEND */
	enum colour_adapt adapt;   /* BRADFORD */
	enum colour_norm norm;     /* WHITE */
	double white;              /* input value of the reference white; 1/π (BRDF of the perfect diffuser) */
	double max_albedo;         /* MAX_ALBEDO only: largest albedo of the data (reflectance, > 0) */
	double target;             /* MAX_ALBEDO only: value the largest albedo maps to; 1 */
	double exposure;           /* multiplies after normalisation; 1 */
	enum colour_gamut gamut;   /* CLAMP */
	enum colour_range range;   /* KEEP */
	double reinhard_white;     /* REINHARD only: luminance mapped to 1; 4 */
	bool srgb_encode;          /* apply the sRGB transfer curve; false */
};

/* Counters filled by colour_finish() (zero it first; it accumulates). */
struct colour_stats {
	size_t n;             /* colours processed */
	size_t out_of_gamut;  /* had a negative linear component */
	size_t clipped;       /* had a component > 1 cut by CLIP/REINHARD */
	size_t nonfinite;     /* had a NaN/Inf component (output set to 0) */
};

/* Fill o with the defaults listed in struct colour_opts. */
void colour_opts_default(struct colour_opts *o);

/* Options for RGB BRDF values in sr⁻¹ (MERL tables, the render callback): the defaults, then ABSOLUTE,
 * CLAMP, KEEP, linear. Only out-of-gamut negatives are changed (to 0), so values stay a physical BRDF. */
void colour_opts_brdf(struct colour_opts *o);

/* Check o (enum ranges, positive finite white/max_albedo/target/exposure/reinhard_white); 0 or -1. */
int colour_opts_check(const struct colour_opts *o, struct acq_err *err);

/* Set one option from text: key ∈ illum(d65|e) gap(extend|zero) adapt(bradford|none)
 * norm(white|absolute|max_albedo) white max_albedo target exposure gamut(clamp|desaturate)
 * range(keep|clip|reinhard) reinhard_white srgb_encode(true|false); 0, or -1 with err (ACQ_E_INVAL). */
int colour_opts_set(struct colour_opts *o, const char *key, const char *value, struct acq_err *err);

struct yc_node;

/* Read the keys of colour_opts_set from a YAML mapping (config/yconf.h) over the values already in o
 * (enum values spelled as in the JSON: D65 E, extend zero, ...); unknown keys and bad values are errors
 * with file:line:col. map NULL → 0, o unchanged. 0 or -1. */
int colour_opts_from_yaml(struct yc_node *map, struct colour_opts *o, struct acq_err *err);

/* Write the decisions of o (and stats if non-NULL) as one JSON object (no trailing newline); returns
 * the length snprintf would need, like snprintf (buf may be NULL when len is 0). */
int colour_opts_json(const struct colour_opts *o, const struct colour_stats *stats, char *buf, size_t len);

/* Same as colour_opts_json, written to f; 0, or -1 with err on a write error. */
int colour_opts_write_json(FILE *f, const struct colour_opts *o, const struct colour_stats *stats,
			   struct acq_err *err);

/* Raw CIE weights for wavelengths wl[0..n-1] (strictly ascending, finite, n ≥ 1; nm): Wxyz[c*n + k] such
 * that XYZ_c = Σ_k Wxyz[c*n+k]·s_k is ∫E·cmf_c·s dλ (stage 1, gap rule applied, no normalisation);
 * also returns ∫E ȳ dλ (the Y of a flat unit spectrum, gap ignored) in *ynorm if non-NULL. 0 or -1. */
int colour_xyz_weights(enum colour_illum illum, enum colour_gap gap, const double *wl, size_t n, double *Wxyz,
		       double *ynorm, struct acq_err *err);

/* XYZ of the illuminant itself (∫E·cmf over 360–830 nm at 1 nm), scaled to Y = 1. */
void colour_illum_white_xyz(enum colour_illum illum, double xyz[3]);

/* The 3 × n matrix W (W[c*n + k], c = R, G, B) of stages 1–4: linear sRGB = W · s. 0 or -1 with err. */
int colour_weights(const struct colour_opts *o, const double *wl, size_t n, double *W, struct acq_err *err);

/* rgb_lin = W · s for one spectrum s[0..n-1] (W from colour_weights). */
void colour_apply_weights(const double *W, size_t n, const double *s, double rgb_lin[3]);

/* Stages 5–7 on one linear-sRGB triple; out may alias lin; stats may be NULL. Never produces NaN/Inf. */
void colour_finish(const struct colour_opts *o, const double lin[3], double out[3], struct colour_stats *stats);

/* Whole chain for one spectrum (allocates the weights; use colour_weights for many spectra). 0 or -1. */
int colour_spectrum_rgb(const struct colour_opts *o, const double *wl, const double *s, size_t n, double rgb[3],
			struct colour_stats *stats, struct acq_err *err);

/* The sRGB transfer curve (IEC 61966-2-1) and its inverse, for one linear component in [0, 1]. */
double colour_srgb_encode(double v);
double colour_srgb_decode(double v);

/* Relative luminance of a linear-sRGB triple (0.2126, 0.7152, 0.0722). */
double colour_luminance(const double rgb[3]);

#endif
