/* mat_lobes: the building blocks of the simulator's materials (sim/material.c) and their albedo quadratures:
 * Fresnel reflectance, GGX and Charlie (sheen) half-vector lobes, albedo tables E(mu), and a quadrature centred
 * on a direction for lobes that are functions of the angle to it (a Phong lobe about the mirror direction, a
 * backscatter peak about the incidence direction).
 *
 * Half-vector quadrature (lobe_hv_albedo): a(wi) = int f(wi, wo) mu_o dwo = int f mu_o 4 (wi.h) dwh, with
 * tan(theta_h) = alpha tan(s), s from 0 to the exact horizon cut-off of each phi_h (mu_o = 0), composite 8-point
 * Gauss-Legendre graded geometrically towards both ends down to the scale mu_i / alpha at grazing incidence;
 * phi_h in [0, pi] (the integrand is even) by composite Gauss-Legendre in t with phi_h = pi/2 + pi/2 sinh(k t) /
 * sinh(k) (nodes clustered where the cut-off turns at grazing incidence). Level L: 2 << L panels per dimension.
 *
 * Cone quadrature (lobe_cone_albedo): int_{mu_o > 0} g(wo) mu_o dwo with wo at angle gamma from a centre c and
 * azimuth psi about it: psi in [0, 2 pi) by composite Gauss-Legendre (4 << L panels of 8 nodes), gamma from 0 to
 * min(gmax, the exact horizon angle of that psi) by composite Gauss-Legendre (4 << L panels) graded towards 0
 * (gamma = gend x^2 concentrates nodes at the centre). g must be negligible beyond gmax. */
#ifndef MAT_LOBES_H
#define MAT_LOBES_H

#define LOBE_NE 128 /* albedo table segments */

enum lobe_kind { LOBE_GGX = 0, LOBE_CHARLIE };

/* A half-vector lobe: GGX  f = F(c) D G2 / (4 mu_i mu_o) (height-correlated Smith), or
 * Charlie sheen f = scale D_r(theta_h) / (4 (mu_i + mu_o - mu_i mu_o)) (Estevez-Kulla distribution, Neubelt-
 * Pettineo visibility); optionally times T(mu_i) T(mu_o) (ttab, a coat's transmission 1 - E_coat). */
struct lobe_hv {
	enum lobe_kind kind;
	double alpha;             /* GGX roughness; Charlie: r (sin^(1/r) theta_h) */
	double scale;             /* factor of the whole lobe (1 for GGX) */
	double n_diel;            /* Fresnel of a dielectric of this index when cn is NULL; 0: F = 1 */
	const double *cn, *ck;    /* conductor index n + ik per wavelength (nwl values), or NULL */
	int nwl;
	const double *ttab;       /* LOBE_NE + 1 values of T(mu) = 1 - E_coat(mu) at mu = j / LOBE_NE, or NULL */
};

/* An albedo table: E(mu) at mu = j / LOBE_NE and eavg = 2 int E mu dmu. */
struct lobe_etab {
	double e[LOBE_NE + 1];
	double eavg;
};

/* Exact unpolarised Fresnel reflectance from air onto n + ik (k = 0: dielectric) at incidence cosine c. */
double lobe_fresnel(double c, double n, double k);
/* The lobe's value without its Fresnel factor at wi, wo (cosines mi, mo > 0), half-vector cosine ch with the
 * normal; 0 when undefined. */
double lobe_hv_geom(const struct lobe_hv *L, double mi, double mo, double ch);
/* Albedo of the lobe at incidence cosine mu_i by the half-vector quadrature (level 0..7). out != NULL: the
 * conductor Fresnel per wavelength accumulated into out[nwl] (zeroed first), returns 0; out == NULL: the
 * achromatic (dielectric or F = 1) albedo returned. flags 1: D's normalisation int D cos dwh (a check). */
double lobe_hv_albedo(const struct lobe_hv *L, double mu_i, int level, int flags, double *out);
/* Fill t with the achromatic albedo of L (quadrature level 2) and its mean. */
void lobe_etab_fill(struct lobe_etab *t, const struct lobe_hv *L);
/* E(mu) by linear interpolation in the table. */
double lobe_etab_at(const double *e, double mu);
/* int_0^1 g(mu) mu dmu for g = E (which 0) or 1 - E (which 1), exact for the piecewise-linear table. */
double lobe_etab_moment(const double *e, int which);

typedef double (*lobe_fn)(const void *ctx, const double wo[3]);
/* int over mu_o > 0 of g(wo) mu_o dwo about the unit centre c (c_z > 0) out to angle gmax (see above). */
double lobe_cone_albedo(const double c[3], double gmax, int level, lobe_fn g, const void *ctx);

#endif
