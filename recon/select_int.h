/* select_int: the working state of one selection and the functions the selection's files share (recon/select.c
 * the greedy pick, select_state.c the state's set-up, select_setup.c the targets' functionals); internal to
 * recon/select*.c and their unit test. */
#ifndef RECON_SELECT_INT_H
#define RECON_SELECT_INT_H

#include <stddef.h>

#include "config/acq_err.h"
#include "recon/select.h"

/* The DHR's fixed rule (dhr.c: the GP part of its σ is computed on it). */
#define SEL_NMU 32
#define SEL_NPHI 48
/* A candidate at a sampled incidence zeroes the DHR's resolution term there (dhr.c: within 0.25°). */
#define SEL_RES_TOL (0.25 * M_PI / 180)
/* value channels: a value within this factor of the threshold is recomputed on all channels, so the stop decision
 * never rests on the subset (white at ACQ_SEED=3: the 1100 nm edge channel, σ 0.068, weighs 1/64 in the subset
 * against 1/651: 0.0087 on 64 channels, 0.0040 on all) */
#define SEL_VALUE_CHECK 4.0
/* The DHR functionals' covariances with the candidates are formed by blocks of this many candidates. */
#define SEL_JB 128
/* Canonical points this close (unit-vector coordinates) are the same measurement. */
#define SEL_SAME 1e-9
/* The ln f target's grid: θ up to 80° (beyond, no bench reaches and the prior alone speaks). */
#define LNF_TMAX 80
#define LNF_TSTEP 10
#define LNF_PSTEP 20
/* The RGB target's nodes: a 12 × 12 × 12 subset of the MERL table's cells (θh, θd, φd indices, cell centres). */
#define RGB_NODES 12

/* The working state of one selection (see "Choosing the next measurements" in recon/reconstruction.md). */
struct sel {
	const struct recon_model *m;
	const struct select_target *t;
	size_t n, L, J, F, Lc, nth, batch;
	double noise;    /* η · median r: the noise of a new measurement relative to the kernel's amplitude */
	double thr2;     /* threshold², 0 without one */
	double *A;       /* [n*n] Cholesky factor of K + ηΛ (column-major, lower) */
	double *Ainv;    /* [n*n] its inverse's lower triangle (recon_gp_setup; lent with A to recon_dhr_parts) */
	double *alpha;   /* [L] the GP amplitude per channel (leave-one-out) */
	size_t *chan;    /* [Lc] tracked channels */
	size_t *vchan;   /* SELECT_DHR: [LV] the channels the value is computed on (NULL: all L) */
	size_t LV;       /* their count (L without vchan) */
	size_t *cpos;    /* [Lc] each tracked channel's position among them */
	double *cu;      /* [J*6] unique candidates' canonical points */
	double *soaJ;    /* [6*J] same, structure of arrays */
	size_t *rep;     /* [J] input index of each unique candidate (the cheapest of its duplicates) */
	double *cost;    /* [J] */
	double *Kjn;     /* [J*n] k(candidate j, centre k) */
	double *G;       /* [J*n] A⁻¹ k_j (column j contiguous) */
	double *Pjj;     /* [J] posterior variance (unit amplitude) of g at candidate j */
	double *Z;       /* [F*J] posterior covariance of functional f with g at candidate j */
	double *v;       /* [F] posterior variance of functional f */
	double *U;       /* [batch*J] scaled posterior rows of the picks (the low-rank part of the update) */
	unsigned char *picked, *match; /* [J]; [nth*J] candidate j samples incidence t (SELECT_DHR) */
	/* SELECT_DHR: per (t, tracked channel): noise floor², the σ² parts the selection does not change, res² */
	double *sn2, *rest, *res2, *kappa;
	unsigned char *res_done; /* [nth] */
	double *xang;    /* SELECT_LNF, SELECT_RGB: [F*4] the grid's / nodes' pairs */
	double *xw;      /* SELECT_RGB: [F] the nodes' share of the table's projected measure (sum 1); SELECT_LNF: the
			  * grid cells' share of the hemisphere pair's (the criterion integrates the variance under it) */
	double *row, *zp; /* scratch of sel_update: [J], [F] */
	/* SELECT_DHR, the noise part's fall with n: the functional's linear noise variance q = Σ_k N_k h_k² under the
	 * GP's weights h = A⁻¹b (N_k = η λ_k, a new sample's = noise), tracked through the picks by the same block
	 * elimination as the posterior; the Monte-Carlo floor sn2 is predicted as sn2 · q/q0. */
	double *Nk;      /* [n] the samples' noise η λ_k */
	double *q, *q0, *qmin; /* [F] current, initial and smallest-so-far noise variance of each functional (the
			  * floor predicted never rises: an estimator may ignore a sample that would spread its weights) */
	double *X;       /* [F*J] Σ_k N_k h_fk w_jk over the current samples (w_j: candidate j's weights A⁻¹k_j) */
	double *Yn;      /* [J] Σ_k N_k w_jk² */
	double *Gc;      /* [J*n] w_j's part on the model's samples (the picks' parts in gn) */
	double *gn;      /* [batch*J] w_j's part on pick i */
	double *mrow, *gp; /* scratch: [J], [n] */
	size_t nbright;  /* SELECT_LNF under lnf:bright: the grid cells that took lnf:rad's weight (the model's lobe) */
	struct sel_prior *prior; /* SELECT_DHR: the energy prior's σ_E after picks (select_prior.c), or NULL */
	int shared;      /* A, Ainv, alpha, cu, soaJ, rep, cost, Kjn, G, Pjj, U, picked, row are another state's (sel_init_part:
			  * a combined target's second part; they do not depend on the target) */
};

/* The batch's route while it is chosen (select_route.c): the arms, then the picks in route order; the incidences
 * (laser positions) the arms and the picks visit. */
struct sel_route {
	const struct select_route *r;
	double *pts;     /* [(batch+1)*3] */
	size_t n;
	double *inc;     /* [batch+2]: the arms' incidence, then the picks' new ones */
	size_t ng;
	/* with band nodes: per incidence the picks visit (its first pick's figures at rho 1) */
	double *gl, *gn, *gs, *gd, *gk; /* [batch+1]: laser position, picks, since, dark, rungs */
	size_t ngl;
	double cmin, cmax; /* band_cos over the picks */
	double pt;       /* Σ point over the picks */
	double T;        /* the picks' exposure seconds at their band */
};
/* Set up an empty route from r->from for at most batch picks. 0, or -1 out of memory (w freed). */
int sel_route_init(struct sel_route *w, const struct select_route *r, size_t batch);
/* Release it (idempotent after init or on a failed init). */
void sel_route_free(struct sel_route *w);
/* Candidate i's (input order) cost with the route as it is: its cheapest insertion's motion, base, and open when its
 * incidence is new (with band nodes: its increment to the picks' exposure seconds); where it would go into *at (may
 * be NULL). > 0. */
double sel_route_cost(const struct sel_route *w, size_t i, size_t *at);
/* Insert candidate i at place at (from sel_route_cost). */
void sel_route_add(struct sel_route *w, size_t i, size_t at);
/* The straight move's seconds from bench position p to q under r's axis model (0: no axis moves). */
double sel_route_move(const struct select_route *r, const double *p, const double *q);

/* A model's factorisation handed from the lobe gate to the selection that follows it (recon_gp_setup's A, Ainv,
 * alpha; all NULL: none handed). Whoever holds non-NULL buffers frees them. */
struct sel_gp {
	double *A, *Ainv, *alpha;
};
/* Free what gp still holds (none taken over); its pointers NULL after. */
void sel_gp_free(struct sel_gp *gp);

/* Everything before the first pick: the factorisation, the candidates, the target's functionals and their
 * covariances with the candidates, the current value into r. 0, or -1 with err (sel_free in both cases). */
int sel_init(struct sel *s, const struct recon_model *m, size_t nc, const double *ang, const double *cost,
	     const struct select_target *t, const struct select_opts *o, struct select_result *r, struct acq_err *err);
/* sel_init for a further part of a combined target: own's factor and candidates' arrays borrowed (own != NULL; same
 * model and candidates), not set up again; its picks then go through sel_update_row/_target/_cands. Without own, a
 * factor in gp (non-NULL buffers) is taken over instead of computed again (gp's pointers then NULL). */
int sel_init_part(struct sel *s, const struct sel *own, struct sel_gp *gp, const struct recon_model *m, size_t nc,
		  const double *ang,
		  const double *cost, const struct select_target *t, const struct select_opts *o, struct select_result *r,
		  struct acq_err *err);
/* Release what sel_init allocated (idempotent on a zeroed state). */
void sel_free(struct sel *s);

/* The targets' set-ups (select_setup.c): the current value into r, the tracked functionals' posterior variances
 * s->v and covariances s->Z with the candidates (DHR: also its fixed parts). 0, or -1 with err. */
int sel_setup_dhr(struct sel *s, const struct select_opts *o, struct select_result *r, struct acq_err *err);
int sel_setup_lnf(struct sel *s, struct select_result *r, struct acq_err *err);
int sel_setup_rgb(struct sel *s, struct select_result *r, struct acq_err *err);
/* The DHR functional's coefficients at incidence th (select_setup.c; arrays as there). 0, or -1 with err. */
int sel_dhr_coef(const struct sel *s, double th, double *c6, double *wt, double *KQn, double *Y, double *Wc,
		 double *C, struct acq_err *err);
/* The ln f target's grid pairs into ang[F*4] and their cells' shares of the hemisphere pair's projected measure
 * cosθi cosθo dωi dωo into w[F] (sum 1; either NULL: count only); returns F. */
size_t sel_lnf_grid(double *ang, double *w);
/* The lobe gate (select_setup.c): keep[j] = 1 for candidates j (ang as select_batch's) of θi ≤ above (radians) and
 * for those above it where lnf:bright's rule puts the model's own lobe at their pair; the count above the bound into
 * *nbeyond, of them kept into *nadmit. The model's factorisation, when it made one, into gp (gp NULL: freed) for
 * the selection that follows. 0, or -1 with err. */
int sel_lobe_gate(const struct recon_model *m, double above, size_t nc, const double *ang, unsigned char *keep,
		  size_t *nbeyond, size_t *nadmit, struct sel_gp *gp, struct acq_err *err);
/* The RGB target's node pairs into ang[F*4] and their measure shares into w[F] (either NULL); returns F. */
size_t sel_rgb_nodes(double *ang, double *w);

/* The energy prior's σ_E after picks (select_prior.c; SELECT_DHR): set up from the DHR's σ_E se[t*ldse + l] at
 * the incidences th; 0, or -1 with err. sel_prior_e2: σ_E² at incidence t, tracked channel c with candidate j
 * measured (SIZE_MAX: as it is; 0 without a prior). sel_prior_pick: candidate p measured. */
int sel_prior_init(struct sel *s, const double *th, const double *se, size_t ldse, struct acq_err *err);
double sel_prior_e2(const struct sel *s, size_t t, size_t c, size_t j);
/* The prior's arrays as sel_prior_e2 reads them (all NULL without a prior): σ_E² e2[t*Lc + c], p[t], and p with
 * candidate j added pj[t*J + j]; for sel_excess_all's loop over the candidates. */
struct sel_prior_view {
	const double *e2, *p, *pj;
	size_t Lc;
};
struct sel_prior_view sel_prior_view(const struct sel *s);
void sel_prior_pick(struct sel *s, size_t p);
void sel_prior_free(struct sel *s);

/* The criterion's value with candidate j measured (SIZE_MAX: as it is), predicted per-incidence values into per
 * (may be NULL). */
double sel_excess(const struct sel *s, size_t j, double *per);
/* sel_excess(s, j, NULL) for every candidate not picked into ex[J] (the same bits; acc: scratch [J]). */
void sel_excess_all(const struct sel *s, double *ex, double *acc);
/* Candidate p's measurement, the k-th pick, added to the posterior (rank-one update): sel_update_row, then
 * sel_update_target, then sel_update_cands. */
void sel_update(struct sel *s, size_t p, size_t k);
/* Its parts. _row: the posterior covariance of p with every candidate into s->row; returns S, p's posterior
 * variance + noise. _target: the target's covariances (one call per part of a combined target). _cands: the
 * candidates' own posterior (once, on the state owning them). */
double sel_update_row(struct sel *s, size_t p, size_t k);
void sel_update_target(struct sel *s, size_t p, size_t k, double S);
void sel_update_cands(struct sel *s, size_t p, size_t k, double S);
/* The noise variance's terms after candidate p's measurement (the k-th pick; S its posterior variance + noise). */
void sel_update_noise(struct sel *s, size_t p, size_t k, double S);

#endif
