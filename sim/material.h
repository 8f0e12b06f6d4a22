/* material: the simulator's ground-truth spectral BRDFs (green paint, white reference, gold-like metal) and
 * their directional-hemispherical reflectance by a stated quadrature.
 *
 * Directions are unit vectors in the sample frame (normal +z). Every material is reciprocal, non-negative and
 * energy conserving by construction; f = 0 when either direction is at or below the horizon.
 *
 * Models (all defined for 450-1100 nm; wavelengths outside are clamped to that range):
 *  - green-paint: dielectric GGX (Trowbridge-Reitz) lobe, alpha 0.12, exact unpolarised Fresnel of n = 1.5,
 *    height-correlated Smith shadowing; plus an energy-aware diffuse base
 *       f_d = rho_d(l) (1 - E(mu_i)) (1 - E(mu_o)) / (pi (1 - E_avg))
 *    (Kelemen & Szirmay-Kalos coupling) where E(mu) is the specular lobe's albedo (tabulated at 129 cosines,
 *    linear interpolation) and E_avg = 2 int E(mu) mu dmu, so the total albedo is
 *    E(mu_i) + rho_d (1 - E(mu_i)) <= 1 at every incidence, grazing included. rho_d: green pigment
 *    (peak ~0.45 at 530 nm, ~0.05 in the red, a NIR "red edge" rising to ~0.65).
 *  - white: Lambertian, rho(l) between 0.97 and 0.99 (Spectralon-like); f = rho/pi exactly.
 *  - metal: conductor GGX lobe, alpha 0.15, exact unpolarised Fresnel of a complex index n + ik interpolated
 *    from a gold-like table (R at normal ~0.4 at 450 nm, ~0.97 above 700 nm). No diffuse part.
 *
 * DHR quadrature (mat_dhr): the diffuse part is integrated over mu_o with 2-point Gauss-Legendre on every
 * segment of the E table (exact for the piecewise-linear integrand); the specular part in half-vector
 * coordinates, where the lobe is smooth: a(wi) = int F(wi.h) D(h) G2 (wi.h) / mu_i dwh, with
 * tan(theta_h) = alpha tan(s), s from 0 to the exact horizon cut-off of each phi_h (mu_o = 0, where the
 * integrand vanishes through G2) by composite 8-point Gauss-Legendre (16 * 2^level nodes), the panels graded
 * geometrically towards both ends down to the scale mu_i / alpha at grazing incidence (where G2 turns at
 * mu_o ~ mu_i); phi_h in [0, pi] (the integrand is even) by composite Gauss-Legendre in t with
 * phi_h = pi/2 + pi/2 sinh(k t) / sinh(k) (nodes clustered where the cut-off turns at grazing incidence).
 * The value returned is level + 1; its error bound is 4 |Q(level+1) - Q(level)| (metal: the largest relative
 * difference over the wavelengths, times the value) plus 2e-7 of the specular value (convergence is fast but
 * not monotone). Measured at level 2 (the default) against level 4, every material, incidences 0 to 89.9 deg:
 * |error| <= 1.4e-7 (bounds 2e-15 to 7e-5); the Lambertian is exact to 1e-12 (tests/unit/test_material.c). */
#ifndef MATERIAL_H
#define MATERIAL_H

#include "config/acq_err.h"

enum mat_id { MAT_GREEN_PAINT = 0, MAT_WHITE, MAT_METAL, MAT__COUNT };

#define MAT_WL_MIN 450.0
#define MAT_WL_MAX 1100.0

struct mat;

/* Name → id ("green-paint" (or "paint"), "white", "metal"); -1 when unknown. */
int mat_from_name(const char *name);
/* Canonical name of a material id. */
const char *mat_name(enum mat_id id);
/* Instantiate material id at nwl wavelengths (nm, copied); NULL with err on failure. */
struct mat *mat_new(enum mat_id id, int nwl, const double *wl, struct acq_err *err);
/* Free a material; NULL is fine. */
void mat_free(struct mat *m);
/* Number of wavelengths the material was instantiated at. */
int mat_nwl(const struct mat *m);
/* f(wi, wo, wl_k) in 1/sr for every wavelength k into out[nwl]; 0 below the horizon. */
void mat_eval(const struct mat *m, const double wi[3], const double wo[3], double *out);
/* The decomposition f(wl) = diff * rho_d(wl) + spec * F(wl, c) used by mat_eval (diff, spec in 1/sr, c the
 * cosine between wi and the half vector), so spectral reductions (RGB) can be folded before evaluation. */
void mat_terms(const struct mat *m, const double wi[3], const double wo[3], double *diff, double *spec, double *c);
/* The Fresnel factor F(wl_k, c) of mat_terms for every wavelength into out[nwl] (0 for white). */
void mat_fresnel(const struct mat *m, double c, double *out);
/* Diffuse albedo rho_d(wl) (white: rho; metal: 0) at wavelength wl, for documentation and tests. */
double mat_rho_d(enum mat_id id, double wl);
/* DHR at incidence zenith theta_i (radians, [0, pi/2]) for every wavelength, with an error bound per
 * wavelength (see the header comment); level 0..6. 0 or -1 with err. */
int mat_dhr(const struct mat *m, double theta_i, int level, double *dhr, double *sigma, struct acq_err *err);

/* Unit vector of zenith theta, azimuth phi (radians); negative zeniths are allowed (the arm's convention). */
void mat_dir(double theta, double phi, double out[3]);

#endif
