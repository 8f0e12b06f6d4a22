/* plan_int: what the planner's files share (plan.c: groups, costs, the sweep order and its result;
 * plan_classify.c: requested points, duplicates, blind zones; plan_order.c: one group's path). Not for other
 * modules: they use plan.h. */
#ifndef PLAN_INT_H
#define PLAN_INT_H

#include <stdbool.h>
#include <stddef.h>

#include "daemon/plan/plan.h"

#define DEG (M_PI / 180.0)
#define MAX_REPS 4
#define INF_COST 1e12

struct mpt {              /* a measured point */
	size_t req;
	struct plan_pos pos;  /* det_phi normalised to [0, 360) */
	double reps[MAX_REPS];
	int nreps;
};

struct group {
	double theta;
	size_t *idx;          /* indices into the measured array */
	size_t n;
	double *C;            /* (n) × (n) symmetric cost of moves (min over azimuth choices) */
};

struct planner {
	const struct bench_geom *g;
	struct mpt *m;
	size_t nm;
	struct group *grp;
	size_t ngrp;
	double dwell;
	bool have_start;      /* the arms start at start (not at the first point): its move counts */
	struct plan_pos start;
};

/* ---- plan_spec.c, plan_adaptive.c ---- */
/* RANGE at map[key] (a number, a list, {from, to, count} or {from, to, step}; values in [lo, hi]) into a new
 * array *out of *n values; what names it in messages. 0 or -1 with err. */
int plan_range_parse(struct yc_node *map, const char *key, const char *what, double lo, double hi, double **out,
		     size_t *n, struct acq_err *err);
/* The `integration` mapping of root onto s (defaults when absent). 0 or -1 with err. */
int plan_integration_parse(struct yc_node *root, struct plan_spec *s, struct acq_err *err);
/* A `kind: adaptive` plan document into a new spec (its seed's points, the adaptive part in spec->adaptive). */
int plan_adaptive_parse(struct yc_node *root, struct plan_spec **out, struct acq_err *err);
/* An adaptive seed's extra requests (seed_specular_deg: in-plane points around the mirror direction of each
 * incidence on bench g) appended to *r (count *n, reallocated). 0 or -1 with err. */
int plan_adaptive_seed_extra(const struct plan_spec *s, const struct bench_geom *g, struct plan_req **r, size_t *n,
			     struct acq_err *err);

/* ---- plan_classify.c ---- */
/* x in [0, 360). */
double plan_norm360(double x);
/* The detector azimuth's axis positions equivalent to phi (φ + k·360 within the limits) into out; their count. */
int plan_phi_reps(const struct bench_geom *g, double phi, double out[MAX_REPS]);
/* Unit vector of direction (θ, φ) in degrees. */
void plan_dir_of(double theta, double phi, double v[3]);
/* Canonical form: θD ≥ 0, φD in [0, 360) (a negative zenith is the other side). */
struct plan_pos plan_canon(struct plan_pos p);
/* Blind reasons of a canonical point, trying each equivalent azimuth for the limits (0: usable). */
unsigned plan_classify(const struct bench_geom *g, const struct plan_pos *p);
/* The spec's requested points (grid or Fibonacci set per incidence) into a new array with room for the
 * reciprocal partners. 0 or -1 with err. */
int plan_expand(const struct plan_spec *s, struct plan_req **out, size_t *n, struct acq_err *err);
/* Mark later requests of an already requested configuration duplicates (measured: compare where kept and
 * moved points are measured, else as requested). 0 or -1 with err. */
int plan_mark_duplicates(struct plan_req *r, size_t n, bool measured, struct acq_err *err);
/* Classify one request: kept, moved (policy move, grid role) or dropped, with its reasons and ψ. */
void plan_classify_req(const struct bench_geom *g, struct plan_req *r, enum plan_blind_policy policy);
/* Append the spec's reciprocal partners of evenly spread kept points to r (room made by plan_expand). 0. */
int plan_add_reciprocals(const struct plan_spec *s, const struct bench_geom *g, struct plan_req *r, size_t *n);

/* ---- plan_order.c ---- */
/* Order n points (symmetric move costs C, n × n; start costs s) as an open path into p: nearest neighbour,
 * 2-opt and Or-opt, with ils iterated double-bridge kicks (deterministic). */
void plan_order_group(const double *C, size_t n, const double *s, size_t *p, bool ils);

#endif
