/* trend: the physically based mean function of the reconstruction. A Lambertian term and one isotropic GGX
 * microfacet lobe (Smith height-correlated masking) with a Fresnel factor made of (1 − cosθd)^k, k = 0, 2, 5, and a
 * coated-diffuse term (Ashikhmin-Shirley), shared
 * roughness, non-negative coefficients per wavelength. The RBF interpolates the data relative to it, so
 * between samples (a lobe narrower than the sampling) the BRDF follows a microfacet lobe fitted to the
 * samples around the specular direction instead of the kernel's shape. */
#ifndef RECON_TREND_H
#define RECON_TREND_H

#include <stddef.h>

#include "config/acq_err.h"

enum recon_trend {
	RECON_TREND_NONE = 0, /* constant: the plain RBF interpolant of the transformed data */
	RECON_TREND_GGX = 1,  /* c0/π + c1·AS diffuse + D·G2/(4μiμo)·(c2 + c3(1 − ωi·h)² + c4(1 − ωi·h)⁵) */
	RECON_TREND_PHONG = 2, /* c0/π + c1·AS diffuse + P_n(ψ)·(c2 + c3(1 − ωi·h)² + c4(1 − ωi·h)⁵), a normalised
				* Phong lobe about the mirror direction, n = 2/α² − 2 */
	RECON_TREND_SHEEN = 3, /* c0/π + c1·AS diffuse + c2·Charlie sheen (r = α) + c3·sheen·(1 − ωi·h)⁵ + c4·ON */
	RECON_TREND_ROUGH = 4, /* c0/π + c1·AS diffuse + c2·retro-reflection peak (width α rad) + c3·ON + c4·LS: a
				* rough diffuse (Oren–Nayar's second term, Lommel–Seeliger) with an opposition peak */
	RECON_TREND_COAT = 5,  /* c0/π + GGX(α2)·(c1·tS(μi)tS(μo) + c2·tE(μi)tE(μo)) + GGX(α)·(c3·F(ωi·h) +
				* c4(1 − ωi·h)⁵): two lobes of different widths, a narrow coat (α, F a dielectric's
				* Fresnel) over a broad base (α2 ≥ 2α) seen through it (tS: a smooth interface's
				* transmission, tE = 1 − the coat's albedo); model file v4 (v3: session 7's form) */
	RECON_TREND__COUNT
};

#define TREND_NB 5            /* basis functions (coefficients per wavelength) */
#define TREND_LOBE 2          /* the lobe terms are b[TREND_LOBE .. TREND_NB) (coat: trend_lobe_first) */
#define TREND_ALPHA_MIN 0.005 /* roughness range searched by the fit */
#define TREND_ALPHA_MAX 1.0
#define TREND_NGRID 40        /* the roughness search: a log grid over the range, then golden sections ... */
#define TREND_NGOLDEN 24      /* ... of TREND_NGOLDEN steps about the grid's best (trend.c; dhr.c's width profile) */
/* Golden section of f(ctx, x) over [lo, hi] (TREND_NGOLDEN steps; nothing when hi <= lo): the best x and its value
 * into *x, *fx, which are kept where no point beats *fx (the fit's roughness search; dhr.c's width profile). */
void trend_golden(double (*f)(void *ctx, double x), void *ctx, double lo, double hi, double *x, double *fx);
#define TREND_NCH 16          /* the channels the roughness and leave-one-out searches score: at most 16 ... */
/* ... evenly spread over the L channels (chan[0..*nc) ascending, the first and the last included): fit.c's choice,
 * which dhr.c's width profile repeats. */
static inline size_t trend_score_channels(size_t L, size_t chan[TREND_NCH])
{
	size_t nc = L < TREND_NCH ? L : TREND_NCH;
	for (size_t c = 0; c < nc; c++)
		chan[c] = nc > 1 ? c * (L - 1) / (nc - 1) : 0;
	return nc;
}

/* Basis values of trend t at c6 (zeros for none); finite and ≥ 0 on and above the horizon, symmetric in ωi ↔ ωo.
 * alpha2 is the second roughness of the two-lobe kind (coat: the base lobe; ignored by the others). */
void trend_eval_basis2(int t, double alpha, double alpha2, const double c6[6], double b[TREND_NB]);
/* trend_eval_basis2 for the one-roughness kinds (the coat kind's base term is 0 here: use trend_eval_basis2). */
void trend_eval_basis(int t, double alpha, const double c6[6], double b[TREND_NB]);
/* The first of trend t's narrow-lobe terms b[first .. TREND_NB) (the terms a quadrature must resolve at the scale
 * of its roughness α): TREND_LOBE, or 3 for the coat kind, whose b1 and b2 are its broad base lobe. */
static inline int trend_lobe_first(int t)
{
	return t == RECON_TREND_COAT ? 3 : TREND_LOBE;
}
/* Does trend t have a second roughness (a second lobe: the coat kind)? */
static inline int trend_two_lobes(int t)
{
	return t == RECON_TREND_COAT;
}
/* The trend value Σ_j coef[j]·b[j] of one channel's coefficients at basis values b. */
static inline double trend_dot(const double *coef, const double b[TREND_NB])
{
	double t = 0;
	for (int j = 0; j < TREND_NB; j++)
		t += coef[j] * b[j];
	return t;
}

/* Basis values b[TREND_NB] of the GGX trend at a canonical point c6 (ωi = c6[0..2], ωo = c6[3..5], unit, z up);
 * finite and ≥ 0 for every direction on or above the horizon (μ clamped to 1e-9). */
void trend_basis(double alpha, const double c6[6], double b[TREND_NB]);

/*
 * Fit the trend to n merged samples: linear values val[l*n + k] (channel-major, L channels), transform offsets
 * eps[l] (the log transform's ε), canonical points c6[k*6]. Roughness by a search over
 * [TREND_ALPHA_MIN, TREND_ALPHA_MAX] scored on the channels chan[0..nc) by the RMS of ln(f + ε) − ln(T + ε);
 * per channel, non-negative least squares with relative weights 1/(f + ε)² (the log residual to first order).
 * Writes *alpha and coef[l*TREND_NB + j] for every channel; *rms (may be NULL) the score at the optimum.
 */
int trend_fit(size_t n, size_t L, const double *val, const double *eps, const double *c6, const size_t *chan,
	      size_t nc, double *alpha, double *coef, double *rms, struct acq_err *err);
/* The non-negative coefficients c[TREND_NB] of one channel at a fixed roughness: basis values B[k*TREND_NB] at the
 * n samples, linear values v[k] (negatives count as 0), offset eps; weights 1/(f + ε)² as in trend_fit. Returns
 * the sum of squared log residuals. */
double trend_fit_coef(size_t n, const double *v, double eps, const double *B, double *c);
/* trend_fit for the trend kind t (RECON_TREND_GGX .. RECON_TREND__COUNT − 1); *alpha2 (may be NULL for the
 * one-roughness kinds, 0 written there) the second roughness of the two-lobe kind: a 2-D search (log grid, then
 * alternating golden sections) over α ∈ [TREND_ALPHA_MIN, α2/2], α2 ≤ TREND_ALPHA_MAX. */
int trend_fit_kind2(int t, size_t n, size_t L, const double *val, const double *eps, const double *c6,
		    const size_t *chan, size_t nc, double *alpha, double *alpha2, double *coef, double *rms,
		    struct acq_err *err);
/* The fit's admissibility rule for the (narrow) lobe of the one-roughness kind t at roughness alpha (the coat kind: its
 * coat lobe's core and flank): 1 if the samples c6[6n] measure its width — ≥ 3 in its core (GGX: tanθh ≤ α; the
 * others: shape ≥ 1/4) and, but for GGX, ≥ 3 on its flank (shape 0.01-0.9) — else 0 (trend.c, score). */
int trend_lobe_measured(int t, double alpha, size_t n, const double *c6);
/* Node spacing (radians in ωo) a hemisphere rule needs for the terms of trend t that the energy table does NOT
 * integrate over half vectors (the coat kind's base lobe b1, GGX of α2: 0.5·α2); INFINITY for the other kinds. */
double trend_base_step(int t, double alpha2);
/* Node spacing (radians in ωo) a quadrature rule needs to resolve the lobe terms of trend t at parameter alpha
 * (a quarter of the lobe's half width at a quarter of its peak); INFINITY when the lobe terms are broad. */
double trend_rule_step(int t, double alpha);
/* The GGX roughness whose half-vector nodes (recon_hv_nodes) resolve the lobe terms of trend t at alpha, or 0 when
 * those nodes do not fit its lobe (sheen, rough: not a lobe about the half vector near the normal). GGX: α; phong:
 * α/2 (cosⁿψ ≈ exp(−ψ²/α²) and ψ ≈ 2θh near the mirror: a Beckmann lobe of α/2 in θh). */
double trend_hv_alpha(int t, double alpha);

/* Name of a trend ("none", "ggx", "phong", "sheen", "rough", "coat") or NULL; and back (−1 if unknown). */
const char *trend_name(int t);
int trend_from_name(const char *name);

#endif
