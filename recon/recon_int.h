/* recon_int: what the files of librecon's reconstruction core share (not an API): limits, the map back
 * through the transform and the trend, the evaluation block, the hemisphere quadrature and the energy table. */
#ifndef RECON_RECON_INT_H
#define RECON_RECON_INT_H

#include <math.h>
#include <stddef.h>

#include "recon/gp.h"
#include "recon/rbf.h"
#include "recon/recon.h"

/* Albedo quadrature (quad.c): node rules refined until a doubled rule agrees to TAB_TOL (relative); a channel
 * is also done once fine + 4·|fine − coarse| ≤ below (the energy table's "clearly below 1") with
 * |fine − coarse| ≤ TAB_BELOW_DIFF. */
#define TAB_TOL 1e-3
#define TAB_BELOW_DIFF 0.005
#define ALB_NMU_MAX 256   /* finest rule of recon_albedo, the DHR and the checker (Gauss-Legendre limit) */
/* Largest transformed value mapped back (e^69 ≈ 1e30 sr⁻¹): keeps every output finite. */
#define G_MAX 69.0
#ifndef TREND_RULE_SPACING
#define TREND_RULE_SPACING 0.5
#endif

/* Map a transformed value back to a BRDF value: non-negative and finite by construction. tf is the trend factor
 * (trend_factor): with a trend T (log transform only) g is relative to it, f̂ = max(0, (T + ε)·e^g − ε);
 * without, tf = 1 and f̂ = max(0, e^g − ε). */
static inline double untransform(int transform, double g, double eps, double tf)
{
	if (!(g == g))
		g = -G_MAX; /* unreachable with finite weights; never let NaN through */
	if (transform == RECON_T_SQRT) {
		if (g > 1e15)
			g = 1e15;
		if (g < -1e15)
			g = -1e15;
		return g * g;
	}
	if (g > G_MAX)
		g = G_MAX;
	double f = exp(g) * tf - eps;
	return f > 0 ? (f < 1e300 ? f : 1e300) : 0.0;
}

/* d f̂ / d g at g (the derivative of untransform; 0 where the clamp at 0 is active). */
static inline double untransform_deriv(int transform, double g, double eps, double tf)
{
	if (!(g == g))
		return 0.0;
	if (transform == RECON_T_SQRT)
		return 2.0 * fmin(fmax(g, -1e15), 1e15);
	if (g > G_MAX)
		g = G_MAX;
	double e = exp(g) * tf;
	return e - eps > 0 ? (e < 1e300 ? e : 1e300) : 0.0;
}

/* Trend basis at a canonical point (zeros without a trend); the trend value T of channel l; the trend factor
 * of the map back, T + ε with a trend and 1 without. */
static inline void trend_at(const struct recon_model *m, const double *c6, double b[TREND_NB])
{
	trend_eval_basis2(m->trend, m->trend_alpha, m->trend_alpha2, c6, b);
}

static inline double trend_val(const struct recon_model *m, const double b[TREND_NB], size_t l)
{
	return trend_dot(m->tcoef + l * TREND_NB, b);
}

static inline double trend_factor(const struct recon_model *m, const double b[TREND_NB], size_t l)
{
	return m->trend != RECON_TREND_NONE ? trend_val(m, b, l) + m->eps[l] : 1.0;
}

static inline double theta_of(const double *v)
{
	double z = v[2];
	return z >= 1.0 ? 0.0 : z <= 0.0 ? M_PI / 2 : acos(z);
}

/*
 * One block of b ≤ RECON_EVAL_BLOCK queries for nch channels (eval.c): chan[k] names the model channel of output
 * column k (chan NULL: every channel in order) and wsub holds those channels' weights, channel-major
 * (nch × n; m->w itself when chan is NULL). out is b × nch, row-major.
 */
void recon_eval_block(const struct recon_model *m, size_t b, const double *c6, int scaled, size_t nch,
		      const size_t *chan, const double *wsub, double *out, double *work);

/* Parts of the interpolant f̂ = max(0, (T + ε)e^g − ε), T = T_smooth + T_lobe (the trend's Lambertian and
 * coated-diffuse terms, and its GGX lobe terms): all of it; max(0, (T_smooth + ε)e^g − ε); T_lobe·e^g. The
 * two parts add up to at least f̂ (max(0, a + b) ≤ max(0, a) + b for b ≥ 0), so their albedos bound f̂'s. */
/* RECON_PART_REST: the whole minus the lobe part, f̂ − T_lobe·e^g (so that REST + LOBE = ALL node by node; the DHR) */
/* RECON_PART_SMOOTH, RECON_PART_BASE: a two-lobe trend (coat) split three ways for the energy table: NOLOBE without
 * the base lobe's terms too (b0 only), and T_base·e^g (b1, b2: GGX of α2); one-lobe kinds: SMOOTH = NOLOBE, BASE 0.
 * SMOOTH + BASE + LOBE ≥ f̂ as above. LOBE and BASE are integrated over half vectors (recon_hv_nodes, α and α2). */
enum { RECON_PART_ALL = 0, RECON_PART_NOLOBE = 1, RECON_PART_LOBE = 2, RECON_PART_REST = 3, RECON_PART_SMOOTH = 4,
       RECON_PART_BASE = 5 };
/* Is part one of the products T_part·e^g integrated over half vectors? */
static inline int recon_part_hv(int part)
{
	return part == RECON_PART_LOBE || part == RECON_PART_BASE;
}
/* recon_eval_block for one part of the interpolant (eval.c). */
void recon_eval_block_part(const struct recon_model *m, size_t b, const double *c6, int scaled, int part, size_t nch,
			   const size_t *chan, const double *wsub, double *out, double *work);

/* Distance (chordal, product metric: |Δωi|² + |Δωo|², the reciprocal image included) from canonical point c6 to
 * the nearest centre of the model, whose index goes to *kmin (may be NULL) (eval.c). */
double recon_nearest_centre(const struct recon_model *m, const double *c6, size_t *kmin);

/* The prior on the unseen part of the hemisphere (recon/reconstruction.md): a direction pair farther than
 * RECON_PRIOR_R0 (chordal, product metric: 0.35 ≈ 20°) from every sample is partly unseen, beyond twice that
 * wholly; there ln f has the GP amplitude RECON_PRIOR_ALPHA (prior std √(α K(x, x)) ≈ 1-1.4, a factor e). The
 * paper's 10 × 10 × 10 plan leaves no node of the DHR at 8-60° that far. */
#define RECON_PRIOR_R0 0.35
#define RECON_PRIOR_ALPHA 1.0
/* 0 for d ≤ r0, 1 for d ≥ r1, smoothstep between. */
static inline double recon_ramp(double d, double r0, double r1)
{
	double u = (d - r0) / (r1 - r0);
	return u <= 0 ? 0 : u >= 1 ? 1 : u * u * (3 - 2 * u);
}
/* How unseen a point at distance d from the nearest sample is: 0 within R0, 1 beyond 2·R0, smoothstep between. */
static inline double recon_unseen(double d)
{
	return recon_ramp(d, RECON_PRIOR_R0, 2 * RECON_PRIOR_R0);
}

/* The energy-bounded prior on the unseen part (recon/reconstruction.md, "Honest σ where the data are thin"). For
 * energy, a direction pair is unseen from RECON_PRIOR_R0 on, wholly from a reach r1 on (a smoothstep between):
 * a lobe narrower than the distance to the nearest sample can hide there (the GP's softer recon_unseen counts a
 * node 20-40° away as partly seen, which for a sharp lobe it is not). r1 = recon_energy_reach(w) follows the
 * narrowest feature w of the fitted trend (recon_trend_width): RECON_PRIOR_RE (0.40) for a lobe narrower than
 * RECON_PRIOR_RE / RECON_PRIOR_WIDTHS, RECON_PRIOR_WIDTHS · w for broader ones (a lobe as wide as w centred 2w from
 * a sample shows there at e⁻⁴ of its peak: only beyond that can one of that width hide), at most the GP's 2·R0.
 * At one incidence, U is
 * the unseen share of the cosine-weighted hemisphere (Σ u_q w_q / π), A_seen and A_unseen the model's DHR over
 * the seen and the unseen parts (Σ (1 − u_q) w_q f̂_q and Σ u_q w_q f̂_q). Energy conservation bounds what the
 * unseen part holds by [0, R], R = 1 − A_seen, and nothing else does (a specular lobe the samples missed can carry
 * all of R). The prior: with probability p the unseen part holds an amount uniform on [0, R], else the model's
 * A_unseen is right; the RMS error of the model's value is then √p · √((R/2 − A_unseen)² + R²/12) (with p = 1
 * any truth in [0, R] is within √3 of it): the mixture's standard deviation, GUM's standard uncertainty. Its
 * linear form p · s was tried (tighter where p is small: a 3 × 4 × 6 plan of green paint, σ 0.0015-0.0028 instead
 * of 0.015-0.024 at 30/60° against errors ≤ 0.004) and left a sharp-lobe fit of 11 samples at |z| 7.7 at 60°
 * (√p · s: 1.9): an error that has probability p must not read as 7σ. p = U (a missed lobe's direction uniform over the cosine-weighted
 * hemisphere), but 1 where the mirror direction itself is unseen (recon_mirror_unseen: where a specular lobe
 * would be); U is weighted by recon_prior_pockets (session 15: only where the data give a lobe a reason to hide).
 * The paper's plan has U = 0 and its mirror directions seen at 8-60° (nothing changes there). */
#define RECON_PRIOR_RE 0.40
#define RECON_PRIOR_WIDTHS 2.0
/* The mirror direction is seen by a sample within RECON_PRIOR_R0 of it (product metric) whose own offset ψ from
 * its mirror direction is within the trend lobe's width w: wholly unseen from ψ = RECON_PRIOR_LOBE_CUT · w on. A
 * sample 10° off its mirror does not see a lobe 5° wide (session 9: a 3 × 4 × 6 plan of sharp-lobe at 30°,
 * |z| 7.3, the nearest sample at θi 40°, θo 30°). */
#define RECON_PRIOR_LOBE_CUT 1.25
/* Without a trend the data show no lobe and bound no width: the mirror then needs a sample within R0/2 (10°) of
 * its own mirror direction (an 11-sample sharp-lobe fit, trend none, its mirror at 8° "seen" by a sample 12° off
 * its own: |z| 4.0). */
#define RECON_PRIOR_LOBE_NONE (0.5 * RECON_PRIOR_R0)
static inline double recon_energy_reach(double w)
{
	return fmin(2 * RECON_PRIOR_R0, fmax(RECON_PRIOR_RE, RECON_PRIOR_WIDTHS * w));
}
static inline double recon_unseen_energy(double d, double r1)
{
	return recon_ramp(d, RECON_PRIOR_R0, r1);
}
/* ψ at canonical point c6: the angle between ωo and the mirror image of ωi (cos ψ = 2 μi μo − ωi·ωo). */
static inline double recon_mirror_offset(const double c6[6])
{
	double c = c6[2] * c6[5] - c6[0] * c6[3] - c6[1] * c6[4];
	return acos(c > 1 ? 1 : c < -1 ? -1 : c);
}
/* How unseen the mirror point mir is by one sample at canonical point a (its reciprocal image ta), given the specular
 * lobe width w (INFINITY: the distance alone): max(recon_unseen_energy(d, RECON_PRIOR_RE), the ramp of ψ/w from 1
 * to RECON_PRIOR_LOBE_CUT), d the nearer image's distance, ψ the sample's own mirror offset. */
static inline double recon_mirror_term(const double mir[6], const double a[6], const double ta[6], double w)
{
	double u = recon_unseen_energy(sqrt(rbf_canon_dist2(mir, a, ta)), RECON_PRIOR_RE);
	if (u < 1 && isfinite(w))
		u = fmax(u, recon_ramp(recon_mirror_offset(a) / w, 1.0, RECON_PRIOR_LOBE_CUT));
	return u;
}
/* The width (rad) of the narrowest feature of m's trend: a specular lobe's ψ-width 2·α_hv (exp(−ψ²/w²) about the
 * mirror: GGX and the coat's narrow lobe 2α, Phong α), the retro-reflection peak's α, the sheen band's half width
 * √(2 ln 4 · r). Without a trend 0: the data show no feature, so nothing bounds how narrow a missed one is (an
 * 11-sample sharp-lobe fit has no trend: reach 0.70 instead of 0.40 read |z| 6.7 at 60°). specular: the
 * specular lobe's width only: INFINITY for the kinds without one (sheen, rough), RECON_PRIOR_LOBE_NONE without a
 * trend. */
double recon_trend_width(const struct recon_model *m, int specular);
/* How unseen the mirror point mir (canonical) is: the least recon_mirror_term over the samples. */
double recon_mirror_unseen(const struct recon_model *m, const double mir[6], double w);
static inline double recon_prior_energy_sd(double p, double a_seen, double a_unseen)
{
	double R = 1.0 - a_seen;
	if (!(R > 0) || !(p > 0))
		return 0.0;
	double c = 0.5 * R - a_unseen;
	return sqrt(fmin(p, 1.0) * (c * c + R * R / 12.0));
}

/* The worst sample of recon_misfit: index k (merged direction), channel l, measured and model values (sr⁻¹). */
struct recon_misfit_worst {
	size_t k, l;
	double data, model;
};
/* Samples the final model does not honour: |g_k − ĝ_k| (transformed units) > max(rmin, zlim·σ_g). Fills
 * df[k*L + l] = data − model (sr⁻¹) there and 0 elsewhere, ratio[k*L + l] (may be NULL) = (data + ε)/(model + ε) there
 * and 1 elsewhere, worst (may be NULL) with the largest |data − model|; returns the count, or -1 with err (eval.c). */
long recon_misfit(const struct recon_model *m, double zlim, double rmin, double *df, double *ratio,
		  struct recon_misfit_worst *worst, struct acq_err *err);

/* Hemisphere nodes at θi (quad.c): nmu × nphi canonical points c6 and weights wt (cosθo included); square_rule =
 * Gauss-Legendre in cos²θo (the checker's independent rule). Returns -1 on a bad size. */
int recon_hemi_nodes(double theta_i, int nmu, int nphi, int square_rule, double *c6, double *wt);

/* Bright directions whose neighbourhood every hemisphere rule integrates with its own finer rule (quad.c). */
#define RECON_BOX_MAX 3
/* Workspace of recon_albedo_adaptive, sized for the finest rule it may reach (grown for the boxes). */
struct albedo_ws {
	size_t qmax, L;
	int part;     /* RECON_PART_*: which part of the interpolant; the lobe part is integrated over half vectors */
	double evals; /* work so far in kernel evaluations, a channel's GEMM counting 1/64 of one (measured: a
		       * Wendland row value ≈ 3.5 ns, a multiply-add of the GEMM ≈ 0.05 ns); for budgets */
	const double *offset; /* [L] or NULL: added to a channel's value in the "clearly below" test (split albedo) */
	const double *floor_ch; /* [L] or NULL: a channel's own floor of the relative tolerance (the DHR's rest part:
				 * its lobe part's value, so the rest is refined relative to the whole) */
	double *c6, *wt, *work, *vals, *wsub, *fine;
	size_t *chan;
	/* the data's brightest directions (quad.c): bright[n] the largest value of the interpolant's data over the
	 * channels at each centre; cand[2n·3] scratch; nbox boxes {x_lo, x_hi, φ_lo, φ_hi} (x = cosθo, or cos²θo for
	 * the square rule) refined by boxn nodes per dimension at the starting rule */
	double *bright, *cand;
	int nbox, boxn;
	/* box_fine: boxes sized for the rule 2^box_fine times finer than the starting rule (half-width RECON_BOX_HW·h and
	 * RECON_BOX_N nodes a side divided by 2^box_fine: the same density on a quarter of the area per step; the energy
	 * table's nodes past its work budget, whose starting rule is the half of the table's, set 1) */
	int box_fine;
	/* cell_min: nodes per side of every cell of a composite rule (boxes, steps; quad.c box_nodes), 2 at the starting
	 * rule and doubled with it, so that a doubling refines every cell, however narrow */
	int cell_min;
	/* gl[n]: Gauss-Legendre's n nodes on [0, 1] then their weights (2n values), computed once per size (box_nodes
	 * asks for one per cell and rule) */
	double *gl[257];
	double box[RECON_BOX_MAX][4];
	/* nested: the hemisphere rules are Clenshaw-Curtis in cosθo × the trapezoid rule in azimuth, each doubling
	 * holding the rule before it, whose values (keep[q·L + l], rule keep_n × keep_m; 0: none) it reuses (the
	 * energy table's; quad.c) */
	int nested, store, keep_n, keep_m;
	double *keep;
	size_t keep_cap;
	/* steps: the x (cosθo, or cos²θo) of the energy factor's steps at this θi (scaled rules; quad.c), nstep of
	 * them (room for the table's nodes): every rule integrates between them, the factor being constant there */
	double *step;
	int nstep;
	/* indep: before accepting a doubling, the coarser rule's independent twin (nodes in cos²θo, azimuths shifted
	 * by half a step; alt[L] its values) must agree with the finer rule too (the DHR's; quad.c) */
	int indep, alt_rule;
	double *alt;
};
/* Allocate for rules of up to qmax nodes (-1 with err on failure); free (idempotent). */
int recon_albedo_ws_init(struct albedo_ws *ws, const struct recon_model *m, size_t qmax, struct acq_err *err);
void recon_albedo_ws_free(struct albedo_ws *ws);
/*
 * The extrapolation beyond the plan's last observation zenith (extrap.c; recon/reconstruction.md, sessions 12-13).
 * DHR nodes whose larger zenith lies beyond te, the largest zenith of any sample (either direction, reciprocity),
 * are an extrapolation of the model's form that no sample checks; the GP's σ there is the amplitude of its
 * residuals inside the range. Whether the form extrapolates is measured on the data, as a SIZE: the ring of samples
 * at the last zenith (within RECON_EDGE_RING of te) is held out as a block and predicted from the others (the GP's
 * block leave-out, e_B = ((A⁻¹)_BB)⁻¹ (A⁻¹(g − μ))_B, covariance α (A⁻¹)_BB⁻¹); a is the RMS over channels of the
 * ring's mean held-out residual in ln f, its noise variance subtracted, over the kriging amplitude √α_λ (session 12
 * used its significance, which grows with the ring's size and fired on the paper plan's many-sample ring). Measured
 * (20 seeds): clear-coat 0.37-0.52 on 5 × 6 × 8, 7 × 8 × 8 and 10 × 10 × 10; every other simulator material ≤ 0.22.
 * Session 14: that was the coat kind's base transmission (Schlick's, 0 at grazing); with the fitted transmission
 * (trend.c coat_basis) the coat reads 0.03-0.08 and no simulator material fires the gate on those plans (3 × 4 × 6
 * last rings still partly: cloth-sheen).
 * The band beyond te carries σ_X = RECON_EXTRAP_K · Σ_q w_q |f̂(x_q) − f̂(x_q clamped to te)| · ramp(a; A0, A1):
 * the model's own change from the edge to the node is the scale of what can be wrong there (measured: the clear
 * coat's error beyond te is 0.45-0.53 of it on all three plans), the same sign over the band (summed).
 * RECON_EXTRAP_K: see reconstruction.md, session 13 (the paper plan's coverage of the coat rested on an interior error
 * of the opposite sign, so K is the largest value keeping it ≥ 0.7); kept in session 14, where the coat no longer
 * switches the term on (reconstruction.md, session 14: no simulator cell that fires it to re-choose K on).
 */
#define RECON_EDGE_RING (1.0 * M_PI / 180) /* the last ring: samples within 1° of the last zenith */
#define RECON_EDGE_MIN 3                   /* fewer samples in the ring, or outside it: no verdict (a = 0) */
#define RECON_EDGE_A0 0.25
#define RECON_EDGE_A1 0.35
#define RECON_EXTRAP_K 0.17
/* The energy prior's pockets (recon/reconstruction.md, session 15): how far the unseen share U away from the mirror
 * direction counts in σ_E's p = max(mirror unseen-ness, pockets). On a plan that sees most of the hemisphere the
 * pockets (on 3 × 4 × 6 ≥ 95 % of U lies beyond the plan's last observation zenith, in the azimuth gaps at
 * grazing) can hide a lobe only where the data give a reason; the pockets' share is the largest of
 *  - U × the edge gate ramp(a; RECON_EDGE_A0, A1): the last ring's held-out misfit says the trend's form misses
 *    the band beyond the last zenith, where the pockets lie;
 *  - U_w, node by node, w_s the trend's specular lobe width (recon_trend_width(m, 1); none for the sheen and rough
 *    kinds or without a trend): the unseen nodes whose hole d (distance from every sample) is deeper than 2 w_s
 *    (recon_prior_lobe_hides), U_w = Σ_{q: d_q > 2 w_s} ue_q wt_q / π (dhr.c unseen_and_misfit): a lobe of width w
 *    hides only 2w from every sample (the reach rule's e⁻⁴ argument), so only there can the plan miss a lobe of the
 *    trend's kind — a lobe hides only in holes deeper than itself.
 *    History (recon/reconstruction.md, session 17): session 15 weighed all of U by 1 − ramp(2 w_s; RE, 2 R0), a
 *    ramp ending at a hole no coarse plan has at 8-60° (acq-sim's 3 × 4 × 6: deepest 0.40 / 0.47 / 0.52), so a GGX
 *    lobe 2w = 0.48 wide still weighed 0.84 (green paint: σ 12-15× its error at 30 / 60°); honest3 ended the ramp
 *    at the incidence's deepest hole h, which still charged all of U wherever one node was deeper than 2 w_s
 *    (green paint at 60°: h 0.517, 2 w_s 0.476, g 0.27, z RMS 0.24, while 4 % of U lies deeper than 2 w_s);
 *    the ramp per node (end d instead of h) left green paint's 60° bias at |z| up to 4 (share 0.952): not taken;
 *  - U × ramp(U; RECON_PRIOR_U0, U1): much of the hemisphere is unseen (few directions): the data have no say on what
 *    it holds (the fit warns from 20 %).
 * Otherwise the data show no lobe the holes could hide and the form holds at the edge: a missed lobe of an
 * isotropic material would sit at the mirror direction, which p keeps. U itself is session 9's rule. */
#define RECON_PRIOR_U0 0.05
#define RECON_PRIOR_U1 0.20
/* Can a lobe of width w (rad) hide in a hole d deep (distance from every sample): 1 if 2w < d, else 0; 0 for w ≤ 0
 * or not finite (the trend shows no specular lobe). */
static inline double recon_prior_lobe_hides(double d, double w)
{
	return w > 0 && isfinite(w) && RECON_PRIOR_WIDTHS * w < d ? 1.0 : 0.0;
}
/* The pockets' share of σ_E's p: U (share of the hemisphere unseen), aedge the edge misfit, Uw the share of unseen
 * nodes that can hide the trend's lobe (recon_prior_lobe_hides; U_w ≤ U). */
static inline double recon_prior_pockets(double U, double aedge, double Uw)
{
	double g = fmax(recon_ramp(aedge, RECON_EDGE_A0, RECON_EDGE_A1), recon_ramp(U, RECON_PRIOR_U0, RECON_PRIOR_U1));
	return fmax(U * g, Uw);
}
/* The largest zenith of any sample (radians). */
double recon_last_zenith(const struct recon_model *m);
/* a, the size of the last ring's held-out residual (above), from recon_gp_setup's Ainv (lower triangle) and α; 0
 * when there is no ring to test, −1 when out of memory. */
double recon_edge_size(const struct recon_model *m, const double *Ainv, const double *alpha);
/* xs[L] = gate · σ_X at one incidence's Q nodes c6 (weights wt, Σ = π); 0 without nodes beyond te or gate 0. */
int recon_extrap_sd(const struct recon_model *m, size_t Q, const double *c6, const double *wt, double gate, double *xs,
		    struct acq_err *err);

/* Raise the starting rule nmu × nphi to the narrowest lobe the model can make (without the trend's own lobe when
 * no_trend_lobe, and without a two-lobe trend's base lobe too when it is 2: the energy table integrates those over
 * half vectors); *qmax the finest rule reachable. */
void recon_lobe_rule(const struct recon_model *m, int nmu_max, int no_trend_lobe, int *nmu, int *nphi, size_t *qmax);
/* The largest sum over m's channels of its trend's narrow-lobe coefficients (trend_lobe_first on): a bound of the lobe
 * terms' albedo; 0 without a trend (quad.c). */
double recon_trend_lobe_coef(const struct recon_model *m);
/* Half-vector nodes about the mirror of θi for a GGX lobe of roughness α (quad.c): nu nodes in u = tan²θh/(α² +
 * tan²θh) (Gauss-Legendre) × nphi azimuths of h over [0, π] (mirror doubled); canonical points c6 and weights wt
 * (dωo = 4(ωo·h) dωh, cosθo included, 0 below the horizon). */
int recon_hv_nodes(double theta_i, double alpha, int nu, int nphi, double *c6, double *wt);
/* Albedo of every channel at θi by doubling rules (quad.c has the full contract); out[L], diff[L] may be NULL. */
int recon_albedo_adaptive(const struct recon_model *m, double theta_i, int nmu, int nphi, int nmu_max,
			  int square_rule, int scaled, double tol, double floor, double below, struct albedo_ws *ws,
			  double *out, double *diff, struct acq_err *err);

/* The checker's albedo of every channel at θi (quad.c): globally adaptive cubature over cells of (cosθo, azimuth), Genz-Malik
 * degree 7/5 on each, from ncx × ncp cells until every channel's error estimate is ≤ tol · max(|value|, floor) or
 * max_cells cells (per chunk of RECON_CUB_CHUNK channels); out[L], errest[L]; *unresolved counts the channels left
 * above their target. -1 with err on a bad argument or no memory. */
#define RECON_CUB_CHUNK 64
int recon_albedo_cubature(const struct recon_model *m, double theta_i, int ncx, int ncp, int scaled, double tol,
			  double floor, size_t max_cells, struct albedo_ws *ws, double *out, double *errest,
			  size_t *unresolved, struct acq_err *err);

/* Build m->tab_theta, m->tab_alb, m->ntab, m->alb_margin: the energy table of the unscaled interpolant
 * (energy.c). */
int recon_energy_table(struct recon_model *m, struct acq_err *err, recon_progress_fn pf, void *pctx);
/* The same with energy.c's room rule on (room_rule 1: recon_energy_table) or off (0: tests) and a work budget in
 * kernel evaluations (< 0: energy.c's own; 0: every node on the rule of the nodes past it: tests); replaces m's table. */
int recon_energy_table_room(struct recon_model *m, int room_rule, double budget, struct acq_err *err,
			    recon_progress_fn pf, void *pctx);

#endif
