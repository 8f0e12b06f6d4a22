/* material: ground-truth spectral BRDFs of the simulated samples and their directional-hemispherical
 * reflectance by a stated quadrature (lobes and quadratures in sim/mat_lobes.h).
 *
 * Directions are unit vectors in the sample frame (normal +z). Every material is reciprocal, non-negative and
 * energy conserving by construction (tests/unit/test_material.c checks all three by quadrature); f = 0 when
 * either direction is at or below the horizon. Spectra are defined for 450-1100 nm (clamped outside).
 *
 * The trend-family materials (the first three):
 *  - green-paint: dielectric GGX lobe, alpha 0.12, exact unpolarised Fresnel of n = 1.5, height-correlated
 *    Smith shadowing; plus an energy-aware diffuse base f_d = rho_d (1 - E(mu_i)) (1 - E(mu_o)) / (pi (1 - E_avg))
 *    (Kelemen & Szirmay-Kalos) where E(mu) is the lobe's albedo (tabulated at 129 cosines, linear) and
 *    E_avg = 2 int E mu dmu, so the albedo E(mu_i) + rho_d (1 - E(mu_i)) <= 1 at every incidence.
 *    rho_d: green pigment (peak ~0.45 at 530 nm, ~0.05 in the red, NIR red edge to ~0.65).
 *  - white: Lambertian, rho between 0.97 and 0.99 (Spectralon-like).
 *  - metal: conductor GGX lobe, alpha 0.15, Fresnel of a gold-like complex index; no diffuse part.
 * Truths outside the reconstruction trend's family (issue 13 item 2; parameters chosen so that each one
 * stresses one thing the paper's 10 x 10 x 10 plan, 36 deg azimuth step, cannot see directly):
 *  - clear-coat: a clear dielectric coat (GGX alpha 0.05, n = 1.5: a narrow lobe, ~6 deg wide in wo) over a
 *    coloured metallic base (copper-like conductor GGX, alpha 0.30: a broad lobe), the base seen through the
 *    coat: f = f_coat + T(mu_i) T(mu_o) f_base with T = 1 - E_coat (the coat's albedo). Reciprocal (symmetric
 *    product), albedo <= E_coat(mu_i) + T(mu_i) E_base(mu_i) <= 1. Refraction of the base lobe is neglected.
 *  - rough-backscatter: Oren-Nayar (qualitative model, sigma = 0.5 rad) times a terracotta rho(l) (0.10 blue to
 *    0.60 NIR), plus an opposition (backscatter) peak rho/pi * 1.0 * exp(-gamma^2 / (2 (8 deg)^2)), gamma the
 *    angle between wi and wo: symmetric in wi, wo; peak mostly in and around the bench's blind zone (< 7.5 deg)
 *    so only its flank is measurable. Albedo <= rho (A + B/2 + 0.13) < 0.8.
 *  - cloth-sheen: Charlie sheen lobe (Estevez & Kulla 2017, r = 0.3, sin(theta_h)^(1/r): strongest at grazing
 *    configurations) with Neubelt-Pettineo visibility 1 / (4 (mu_i + mu_o - mu_i mu_o)), scaled by 0.9 / max E
 *    so its own albedo E_s <= 0.9, pale sheen colour s(l) (0.62-0.72); diffuse base: a red dye rho_d
 *    (0.04 blue, 0.40 red, 0.55 NIR) with the same energy-aware coupling as the paint (E = E_s).
 *  - sharp-lobe: a normalised (modified) Phong lobe about the mirror direction, f = k_s (n + 2) / (2 pi)
 *    max(0, wr.wo)^n with n = 250 (half width at half maximum 4.2 deg, far below the plan's 36 deg azimuth
 *    step), k_s = 0.30 achromatic, over a blue Lambertian base k_d(l) <= 0.55. wr.wo = 2 mu_i mu_o - wi.wo is
 *    symmetric; the lobe's albedo is <= k_s, so the total is <= 0.85.
 *  - narrow-lines: Lambertian with narrow absorption lines (holmium-oxide-like: 468, 485, 537, 641 nm and two
 *    NIR bands at 890, 1015 nm; Gaussian widths 2.5-6 nm, depths 0.30-0.55) on a 0.90-0.93 white base.
 *
 * A material from a MERL file (issue 17; `acq-sim truth merl:FILE`, `sim.merl_file` with `sim.sample: merl`):
 *  f(wi, wo, l) = sum_k rgb_k(wi, wo) B_k(l), rgb the table's linear sRGB BRDF at the cell of (wi, wo) (the
 *  reference lookup of recon/merl.h; "no data" cells 0), B_k a smooth spectral basis made so that
 *    (a) the upsampling is exact: W B = I for the RGB weights W of recon/colour.h (colour_opts_brdf, computed
 *        on 450:1100:1 nm, the spectrum extended flat below 450 nm), so the spectrum's RGB is the table's;
 *    (b) it preserves energy: B_k >= 0 and sum_k B_k = 1 at every wavelength, so f(l) is a convex combination
 *        of r, g, b and the spectral albedo lies between the smallest and largest channel albedo (<= 1 when the
 *        table's channels are);
 *  B = G M^-1 with G_k(l) = g_k(l) / sum_j g_j(l), g Gaussians of width 20 nm centred at 640 (red; 1 above),
 *  540 (green), 450 nm (blue; 1 below), M = W G (so sum_k B_k = 1 follows from W 1 = (1, 1, 1), the D65
 *  white point, to 1e-7); min B = 0.007 at these centres (a search of the centres for B >= 0; mat_new_merl checks it).
 *  Reciprocal as the table (the lookup folds phi_d mod pi). DHR: midpoint rule in (theta_o, phi_o) over
 *  (90 x 360) 2^level cells (the table is piecewise constant), bound 4 |Q(level+1) - Q(level)|.
 *
 * DHR quadrature (mat_dhr): Lambertian parts exactly; Kelemen-coupled diffuse by the exact segment rule of the E
 * table; half-vector lobes by lobe_hv_albedo, the Phong lobe and the backscatter peak by lobe_cone_albedo about
 * their centres; the Oren-Nayar term analytically:
 *   (1/pi) int max(0, cos dphi) sin(alpha) tan(beta) mu_o dwo
 *      = (2/pi) [sin(ti) (ti/2 - sin(2 ti)/4) + tan(ti) (1 - sin(ti)^3) / 3].
 * The value returned is level + 1; its error bound is 4 |Q(level+1) - Q(level)| (conductors: the largest
 * relative difference over the wavelengths, times the value) plus 2e-7 of the quadrature part. Measured at
 * level 2 against level 4, every material, incidences 0 to 89.9 deg: see tests/unit/test_material.c. */
#ifndef MATERIAL_H
#define MATERIAL_H

#include "config/acq_err.h"

enum mat_id {
	MAT_GREEN_PAINT = 0,
	MAT_WHITE,
	MAT_METAL,
	MAT_CLEAR_COAT,
	MAT_ROUGH_BACKSCATTER,
	MAT_CLOTH_SHEEN,
	MAT_SHARP_LOBE,
	MAT_NARROW_LINES,
	MAT_MERL,                  /* loaded from a MERL file (mat_new_merl) */
	MAT__COUNT
};

#define MAT_WL_MIN 450.0
#define MAT_WL_MAX 1100.0
#define MAT_MAX_TERMS 3

/* Spectral factors of a term (mat_terms): fixed spectra, or Fresnel factors that depend on a cosine. */
enum mat_spec { MAT_S_RHO = 0, MAT_S_FIX2, MAT_S_DIEL, MAT_S_COND, MAT_S_BASIS_R, MAT_S_BASIS_G, MAT_S_BASIS_B,
		MAT_S__COUNT };

/* One term of f(wi, wo, l) = sum_k w_k S_k(l, c_k) (w in 1/sr). */
struct mat_term {
	double w;
	enum mat_spec spec;
	double c;                  /* cosine between wi and the lobe's half vector (Fresnel spectra) */
};

struct mat;

/* Name → id ("green-paint" (or "paint"), "white", "metal", "clear-coat", ...); -1 when unknown. */
int mat_from_name(const char *name);
/* Canonical name of a material id ("?" when out of range). */
const char *mat_name(enum mat_id id);
/* The canonical names joined by ", " (for messages). */
const char *mat_names_list(void);
/* Instantiate material id at nwl wavelengths (nm, copied); NULL with err on failure. */
struct mat *mat_new(enum mat_id id, int nwl, const double *wl, struct acq_err *err);
/* A material from the MERL file at path (see above), instantiated at nwl wavelengths; NULL with err. */
struct mat *mat_new_merl(const char *path, int nwl, const double *wl, struct acq_err *err);
/* Free a material; NULL is fine. */
void mat_free(struct mat *m);
/* The material's id. */
enum mat_id mat_id_of(const struct mat *m);
/* f(wi, wo, wl_k) in 1/sr for every wavelength k into out[nwl]; 0 below the horizon. */
void mat_eval(const struct mat *m, const double wi[3], const double wo[3], double *out);
/* The decomposition f = sum_k w_k S_k(l, c_k) used by mat_eval into t[MAT_MAX_TERMS]; returns the number of
 * terms (zero-weight terms included), so spectral reductions (RGB) can be folded before evaluation. */
int mat_terms(const struct mat *m, const double wi[3], const double wo[3], struct mat_term *t);
/* The spectral factor S(l_k, c) of a term kind for every wavelength into out[nwl] (0 when the material has
 * no such factor). */
void mat_spectrum(const struct mat *m, enum mat_spec s, double c, double *out);
/* Diffuse albedo rho_d(wl) of the material (metal: 0), for documentation and tests. */
double mat_rho_d(enum mat_id id, double wl);
/* DHR at incidence zenith theta_i (radians, [0, pi/2]) for every wavelength, with an error bound per
 * wavelength (see the header comment); level 0..6. 0 or -1 with err. */
int mat_dhr(const struct mat *m, double theta_i, int level, double *dhr, double *sigma, struct acq_err *err);

/* Unit vector of zenith theta, azimuth phi (radians); negative zeniths are allowed (the arm's convention). */
void mat_dir(double theta, double phi, double out[3]);

#endif
