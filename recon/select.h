/* select: the next measurements of an adaptive sweep. Given a fitted model, reachable candidate direction pairs
 * with their bench-time costs and a target (the DHR's σ at listed incidences, or the largest posterior σ of ln f),
 * a greedy batch that maximises the expected reduction of the target's variance per second of bench time, under
 * the model's Gaussian-process reading, with a rank-one update of the posterior between picks
 * (recon/reconstruction.md, "Choosing the next measurements"). */
#ifndef RECON_SELECT_H
#define RECON_SELECT_H

#include <stddef.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "recon/recon.h"

#define SELECT_MAX_THETA 16

/* The ln f criterion's weighting of its grid points (select_target.lnf_rad; the spec's suffix). */
enum select_lnf_weight {
	SELECT_LNF_PROJECTED = 0, /* "lnf": cosθi cosθo dωi dωo */
	SELECT_LNF_RAD = 1,       /* "lnf:rad": the study's error measure */
	SELECT_LNF_MIX = 2,       /* "lnf:mix": both, each over its own criterion */
	SELECT_LNF_BRIGHT = 3,    /* "lnf:bright": per cell the larger of the two */
};

enum select_kind {
	SELECT_DHR = 0, /* σ of DHR(θi, λ) at listed incidences, RMS over the model's wavelengths, largest incidence */
	SELECT_LNF = 1, /* largest posterior σ of ln f (RMS over wavelengths) over a grid of the hemisphere pair */
	SELECT_RGB = 2  /* σ of the linear-sRGB BRDF (sr⁻¹) a MERL table of the model holds, through the outputs' colour
			 * chain, RMS over R, G, B and over the table under its projected measure cosθi cosθo dωi dωo */
};

struct select_target {
	int kind;                            /* enum select_kind */
	size_t nth;                          /* SELECT_DHR: incidences */
	double theta_deg[SELECT_MAX_THETA];  /* degrees, in [0, 90] */
	double threshold;                    /* the target is met at value ≤ threshold; NAN: none given */
	double lnf_threshold;                /* > 0: a combined target (kind SELECT_DHR): the DHR part ≤ threshold AND
					      * the ln f part ≤ lnf_threshold; its value is the larger of each part's
					      * value over its threshold (met at ≤ 1) */
	int lnf_rad;                         /* enum select_lnf_weight: the ln f criterion (SELECT_LNF, or a combined target's ln f part;
					      * spec "lnf:rad"): each grid point's variance weighed by the expected
					      * squared error of log(1 + f cosθi cosθo) under dωi dωo (the held-out
					      * log-RMSE of the time-to-accuracy study) instead of the projected
					      * measure cosθi cosθo dωi dωo (0, the default); the value is the same;
					      * 2 (spec "lnf:mix"): both weights, each over its own criterion;
					      * 3 (spec "lnf:bright"): per grid cell the larger of the two weights
					      * (lnf:rad's where the model is bright, the projected elsewhere) */
	double lobe_above_deg;               /* > 0 (spec suffix ":lobe_above=DEG", any target): candidates of incidence
					      * θi above it are kept only where the model has its own lobe at their pair
					      * (lnf:bright's rule there: lnf:rad's weight above the projected one);
					      * 0 (default): every candidate */
};

/* Parse "dhr:8,30,60", "lnf", "lnf:rad", "lnf:mix", "lnf:bright", "rgb", optionally followed by ":le=X" (X > 0), or the combined
 * "dhr:8,30,60:le=X+lnf[:rad|:mix|:bright]:le=Y" (both thresholds required); either optionally ending in
 * ":lobe_above=DEG" (0 < DEG < 90: the lobe gate). 0, or -1 with err saying what is wrong. */
int select_target_parse(const char *spec, struct select_target *t, struct acq_err *err);

/* The batch's route, for charging each pick its increment to it (NULL in select_opts: each pick costs its cost[j],
 * the measurement from the arms' position). Candidate j (input order) is measured at bench axis positions
 * pos[3j..3j+2] (laser θ, detector θ, detector φ, degrees) and costs base[j] seconds at an incidence (laser position)
 * the batch visits already (the arms' own included: the executor keeps its dark cache while the incidence stays),
 * base[j] + open[j] at one it does not (the darks of a new incidence); its motion is the
 * increment of inserting it into the batch's route from the arms (from) through the picks, at the cheapest place,
 * each move timed as the planner's straight move: per axis a trapezoid (speed, accel), the slowest axis, the largest
 * settle of the axes that move, plus move_s (polling, extra settling). The azimuth's distance is taken modulo 360°.
 * With band nodes (nnodes > 0) the exposures are priced as the planner's duration model does instead of base and open
 * (daemon/plan/plan_time.c): candidate j's point[j] seconds (probe, exposure, HDR share, host) and, as the k-th pick at
 * its incidence, a dark of dark[j] seconds with probability q^(since[j] + k), q = 1 - 1/rungs[j] (the dark cache's
 * rungs; since[j] the points measured there since the cache was cleared: the arms' incidence); the batch's band
 * rho = largest / smallest band_cos over its picks (1 when the smallest is ≤ 0.01) moves every pick's terms by the
 * nodes' (rho, point, dark, rungs, rho ascending from 1; linear in ln rho, held beyond the last): point by the
 * nodes' difference from rho 1, dark and rungs by their ratio. A pick that widens the band is charged what it adds
 * to the picks before it too. */
struct select_route {
	const double *pos, *base, *open;
	const double *point, *dark, *rungs, *since, *band_cos; /* with nodes */
	const double *nodes; /* [4 nnodes] */
	size_t nnodes;
	double from[3];
	double speed[3], accel[3], settle[3]; /* degrees/s, degrees/s², s; speed and accel > 0 */
	double move_s;
};

struct select_opts {
	const struct select_route *route; /* NULL (default): each pick costs cost[j] */
	size_t batch;     /* largest number of picks (default 16) */
	int ndraws;       /* Monte-Carlo draws of the DHR's noise part (default 16) */
	uint64_t seed;    /* their seed (default 1) */
	size_t nchan;     /* channels on which the GP part is tracked (default 24, evenly spread) */
	size_t nvalue;    /* SELECT_DHR: the value (and the σ parts the selection holds) on this many channels, evenly
			   * spread, the tracked ones among them, when the model has more (0, the default: on all) */
	int reference;    /* 1: the reference path (each candidate's criterion by its own call, each part of a combined
			   * target its own candidates' set-up): the same picks, slower; for the tests (default 0) */
};
void select_opts_default(struct select_opts *o);

struct select_pick {
	size_t index;          /* the candidate (input order) */
	double gain;           /* expected reduction of the criterion (target variance above the threshold²; a combined
				* target: the sum of each part's reduction relative to its criterion before the batch) */
	double gain_per_s;     /* gain / cost */
	double cost;           /* the seconds charged: cost[index], or with a route its increment to the batch's route */
	double predicted;      /* predicted target value after this pick and the ones before it */
	double predicted_per[SELECT_MAX_THETA + 1];
};

struct select_result {
	double value;                       /* the target's current value */
	double per[SELECT_MAX_THETA + 1];   /* per incidence (SELECT_DHR; a combined target: then the ln f part's value)
					     * or [0] = value (SELECT_LNF, SELECT_RGB) */
	size_t nper;
	int met;                            /* a threshold was given and value ≤ threshold */
	double where[4];                    /* SELECT_LNF: the grid pair (θi, φi, θo, φo radians) of the largest σ */
	size_t nunique;                     /* distinct candidates (reciprocal/isotropic duplicates merged) */
	size_t nvalue;                      /* SELECT_DHR: the channels the value was computed on (0 otherwise) */
	int value_checked;                  /* SELECT_DHR on value channels: the value, near the threshold, was
					     * recomputed on all channels (so met is decided on all) */
	double part[2];                     /* a combined target: the DHR part's value and the ln f part's */
	size_t nbeyond, nadmitted;          /* lobe_above_deg > 0: the candidates above the bound, of them kept */
	size_t nbright;                     /* lnf:bright (alone or a combined target's part): the ln f grid's cells that
					     * took lnf:rad's weight (0: the weights are lnf's, the picks too) */
	size_t npicks;
	struct select_pick *picks;          /* in choice order */
};

/* With t->lobe_above_deg > 0 the candidates above it the lobe gate leaves out are removed first (the rest in
 * input order, so a gate that keeps none gives the picks of the candidates at or below the bound alone, bit for bit);
 * picks' indices are the caller's. Choose up to o->batch of nc candidates ang[j*4..] (θi, φi, θo, φo radians, θ
 * in [0, π/2]) with costs cost[j] (> 0 seconds) for target t on model m. Candidates whose canonical points coincide (the same pair up to rotation,
 * mirror or reciprocity) count once, at the cheapest cost. Picking stops at the batch size, when the predicted
 * value meets the threshold, or when no candidate reduces the criterion (an empty batch is a result). r is filled
 * (select_result_free); 0, or -1 with err. */
int select_batch(const struct recon_model *m, size_t nc, const double *ang, const double *cost,
		 const struct select_target *t, const struct select_opts *o, struct select_result *r, struct acq_err *err);
/* Release r's picks (idempotent). */
void select_result_free(struct select_result *r);

#endif
