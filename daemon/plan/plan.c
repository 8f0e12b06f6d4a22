/* plan: turn a plan spec into an ordered, collision-safe sweep with duration estimates.
 *
 * Steps: (1) expand the spec into requested points (grid or Fibonacci set per incidence, then reciprocal
 * partners); (2) merge duplicates (same incidence, same observation direction: e.g. every azimuth at θD = 0);
 * (3) classify against the blind zones and the axis limits, dropping blind points or moving them to the
 * nearest visible observation direction at the same incidence; (4) order: group by incidence (the laser
 * arm is the slow one), order each group as an open path from where the previous group ended (nearest
 * neighbour, then 2-opt and Or-opt under the true move cost), for both directions of the incidence sweep;
 * (5) choose the detector azimuth's axis position of every point (φ, φ ± 360 within limits) by dynamic
 * programming over the order with the real, collision-safe move times; keep the cheapest of the candidate
 * orders, the request (raster) order included, so the plan is never slower than the raster.
 * Steps (1)–(3) are in plan_classify.c, the path within one group in plan_order.c (shared: plan_int.h).
 *
 * The lower bound: every point dwells the same fixed time, so dwell is a constant; the moves form a
 * Hamiltonian path over the measured points, which is a spanning tree, so their total is at least the
 * minimum spanning tree under any edge weight that under-estimates every real move. The weight used is
 * w(a, b) = max over axes of T_axis(|Δ|) plus the largest settling time among axes whose Δ ≠ 0 (for the
 * azimuth, |Δ| is the smallest over the equivalent axis positions): a real move takes segments whose
 * durations each bound each axis's own trapezoid time, the trapezoid time is concave with T(0) = 0 hence
 * subadditive, so Σ segments ≥ T_axis(total distance) ≥ T_axis(|Δ|), and an axis with Δ ≠ 0 does move and
 * is settled. The laser alone also needs T(θL range): the bound is dwell + max(MST, that). */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/plan/plan_int.h"
#define NCAND 5 /* candidate orders */

/* ---- ordering ---------------------------------------------------------------------------------------- */

double plan_straight_s(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b)
{
	double s = 0;
	if (a->laser_theta != b->laser_theta)
		s = fmax(s, g->laser_theta.settle_s);
	if (a->det_theta != b->det_theta)
		s = fmax(s, g->detector_theta.settle_s);
	if (a->det_phi != b->det_phi)
		s = fmax(s, g->detector_phi.settle_s);
	return plan_seg_time(g, a, b) + s;
}

/* Time of the fastest safe move between two measured points over their azimuth choices (-1: none).
 * Choices are tried by increasing lower bound and the search stops when no remaining one can win. */
static double mcost(const struct planner *P, const struct mpt *a, const struct mpt *b)
{
	struct {
		double lb;
		struct plan_pos pa, pb;
	} c[MAX_REPS * MAX_REPS];
	int nc = 0;
	for (int i = 0; i < a->nreps; i++)
		for (int j = 0; j < b->nreps; j++) {
			c[nc].pa = a->pos;
			c[nc].pb = b->pos;
			c[nc].pa.det_phi = a->reps[i];
			c[nc].pb.det_phi = b->reps[j];
			c[nc].lb = plan_straight_s(P->g, &c[nc].pa, &c[nc].pb);
			/* insertion sort by lower bound */
			for (int k = nc; k > 0 && c[k].lb < c[k - 1].lb; k--) {
				__typeof__(c[0]) t = c[k];
				c[k] = c[k - 1];
				c[k - 1] = t;
			}
			nc++;
		}
	double best = -1;
	struct plan_wp w[PLAN_MAX_WP];
	size_t nw;
	for (int k = 0; k < nc; k++) {
		if (best >= 0 && c[k].lb >= best)
			break;
		double t = plan_move(P->g, &c[k].pa, &c[k].pb, w, &nw);
		if (t >= 0 && (best < 0 || t < best))
			best = t;
	}
	return best;
}

static int cmp_double(const void *x, const void *y)
{
	double a = *(const double *)x, b = *(const double *)y;
	return (a > b) - (a < b);
}

static int build_groups(struct planner *P, struct acq_err *err)
{
	double *th = malloc((P->nm ? P->nm : 1) * sizeof *th);
	if (!th)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	for (size_t i = 0; i < P->nm; i++)
		th[i] = P->m[i].pos.laser_theta;
	qsort(th, P->nm, sizeof *th, cmp_double);
	size_t ng = 0;
	for (size_t i = 0; i < P->nm; i++)
		if (i == 0 || th[i] != th[i - 1])
			th[ng++] = th[i];
	P->grp = calloc(ng ? ng : 1, sizeof *P->grp);
	if (!P->grp) {
		free(th);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	P->ngrp = ng;
	for (size_t k = 0; k < ng; k++) {
		struct group *G = &P->grp[k];
		G->theta = th[k];
		for (size_t i = 0; i < P->nm; i++)
			G->n += P->m[i].pos.laser_theta == th[k];
		G->idx = malloc(G->n * sizeof *G->idx);
		G->C = malloc(G->n * G->n * sizeof *G->C);
		if (!G->idx || !G->C) {
			free(th);
			return acq_errf(err, ACQ_E_NOMEM, "out of memory for a group of %zu points", G->n);
		}
		size_t w = 0;
		for (size_t i = 0; i < P->nm; i++)
			if (P->m[i].pos.laser_theta == th[k])
				G->idx[w++] = i;
		for (size_t i = 0; i < G->n; i++) {
			G->C[i * G->n + i] = 0;
			for (size_t j = i + 1; j < G->n; j++) {
				double c = mcost(P, &P->m[G->idx[i]], &P->m[G->idx[j]]);
				c = c < 0 ? INF_COST : c;
				G->C[i * G->n + j] = G->C[j * G->n + i] = c;
			}
		}
	}
	free(th);
	return 0;
}

/* The arms' start position as a measured point (its azimuth as it is on the axis). */
static struct mpt start_mpt(const struct planner *P)
{
	struct mpt s = { .req = SIZE_MAX, .pos = P->start, .nreps = 1 };
	s.reps[0] = P->start.det_phi;
	return s;
}

/* Fastest safe move from the start position to b (-1: none). */
static double start_cost(const struct planner *P, const struct mpt *b)
{
	struct mpt s = start_mpt(P);
	return mcost(P, &s, b);
}

/* An order over all measured points: groups in the given direction, each ordered from the previous end. */
static int order_all(struct planner *P, bool descending, bool ils, size_t *order, struct acq_err *err)
{
	size_t w = 0, last = SIZE_MAX;
	for (size_t gi = 0; gi < P->ngrp; gi++) {
		struct group *G = &P->grp[descending ? P->ngrp - 1 - gi : gi];
		double *s = malloc(G->n * sizeof *s);
		size_t *p = malloc(G->n * sizeof *p);
		if (!s || !p) {
			free(s);
			free(p);
			return acq_errf(err, ACQ_E_NOMEM, "out of memory");
		}
		for (size_t j = 0; j < G->n; j++) {
			double c = last == SIZE_MAX ? (P->have_start ? start_cost(P, &P->m[G->idx[j]]) : 0)
						    : mcost(P, &P->m[last], &P->m[G->idx[j]]);
			s[j] = c < 0 ? INF_COST : c;
		}
		plan_order_group(G->C, G->n, s, p, ils);
		for (size_t j = 0; j < G->n; j++)
			order[w++] = G->idx[p[j]];
		last = G->idx[p[G->n - 1]];
		free(s);
		free(p);
	}
	return 0;
}

/* Azimuth choice by dynamic programming over a fixed order with the true move times. Points that no
 * safe move reaches are skipped (*keep[i] = 0). Returns the total motion time, or -1 on memory error. */
static double choose_reps(const struct planner *P, const size_t *order, size_t n, int *rep, char *keep)
{
	double *dp = malloc((n ? n : 1) * MAX_REPS * sizeof *dp);
	int *bp = malloc((n ? n : 1) * MAX_REPS * sizeof *bp);
	size_t *prevk = malloc((n ? n : 1) * sizeof *prevk);
	if (!dp || !bp || !prevk) {
		free(dp);
		free(bp);
		free(prevk);
		return -1;
	}
	size_t prev = SIZE_MAX;
	struct plan_wp wps[PLAN_MAX_WP];
	size_t nw;
	for (size_t i = 0; i < n; i++) {
		const struct mpt *b = &P->m[order[i]];
		bool any = false;
		for (int j = 0; j < b->nreps; j++) {
			dp[i * MAX_REPS + j] = INFINITY;
			bp[i * MAX_REPS + j] = -1;
			if (prev == SIZE_MAX) {
				double t0 = 0;
				if (P->have_start) {
					struct plan_pos pb = b->pos;
					pb.det_phi = b->reps[j];
					t0 = plan_move(P->g, &P->start, &pb, wps, &nw);
					if (t0 < 0)
						continue;
				}
				dp[i * MAX_REPS + j] = t0;
				any = true;
				continue;
			}
			const struct mpt *a = &P->m[order[prev]];
			for (int k = 0; k < a->nreps; k++) {
				if (!isfinite(dp[prev * MAX_REPS + k]))
					continue;
				struct plan_pos pa = a->pos, pb = b->pos;
				pa.det_phi = a->reps[k];
				pb.det_phi = b->reps[j];
				double t = plan_move(P->g, &pa, &pb, wps, &nw);
				if (t < 0)
					continue;
				double v = dp[prev * MAX_REPS + k] + t;
				if (v < dp[i * MAX_REPS + j]) {
					dp[i * MAX_REPS + j] = v;
					bp[i * MAX_REPS + j] = k;
					any = true;
				}
			}
		}
		keep[i] = any;
		prevk[i] = prev;
		if (any)
			prev = i;
	}
	double total = 0;
	if (prev != SIZE_MAX) {
		const struct mpt *a = &P->m[order[prev]];
		int bj = 0;
		for (int j = 1; j < a->nreps; j++)
			if (dp[prev * MAX_REPS + j] < dp[prev * MAX_REPS + bj])
				bj = j;
		total = dp[prev * MAX_REPS + bj];
		size_t i = prev;
		int j = bj;
		for (;;) {
			rep[i] = j;
			int k = bp[i * MAX_REPS + j];
			size_t pi = prevk[i];
			if (pi == SIZE_MAX || k < 0)
				break;
			i = pi;
			j = k;
		}
	}
	free(dp);
	free(bp);
	free(prevk);
	return total;
}

/* Raster: request order, first azimuth choice, no optimisation; unreachable points skipped. */
static double raster_time(const struct planner *P)
{
	double t = 0;
	struct plan_pos cur = { 0, 0, 0 };
	bool have = false;
	struct plan_wp wps[PLAN_MAX_WP];
	size_t nw;
	for (size_t i = 0; i < P->nm; i++) {
		const struct mpt *b = &P->m[i];
		struct plan_pos pb = b->pos;
		double c = -1;
		for (int j = 0; j < b->nreps && c < 0; j++) {
			pb.det_phi = b->reps[j];
			c = have ? plan_move(P->g, &cur, &pb, wps, &nw) : 0;
		}
		if (c < 0) {
			continue;
		}
		t += c + P->dwell;
		cur = pb;
		have = true;
	}
	return t;
}

static double lower_bound_w(const struct planner *P, const struct mpt *a, const struct mpt *b)
{
	const struct bench_geom *g = P->g;
	double dl = fabs(a->pos.laser_theta - b->pos.laser_theta), dt = fabs(a->pos.det_theta - b->pos.det_theta);
	double dp = INFINITY;
	for (int i = 0; i < a->nreps; i++)
		for (int j = 0; j < b->nreps; j++)
			dp = fmin(dp, fabs(a->reps[i] - b->reps[j]));
	double t = fmax(plan_axis_time(&g->laser_theta, dl),
			fmax(plan_axis_time(&g->detector_theta, dt), plan_axis_time(&g->detector_phi, dp)));
	double s = 0;
	if (dl > 0)
		s = fmax(s, g->laser_theta.settle_s);
	if (dt > 0)
		s = fmax(s, g->detector_theta.settle_s);
	if (dp > 0)
		s = fmax(s, g->detector_phi.settle_s);
	return t + s;
}

static double lower_bound(const struct planner *P)
{
	size_t n = P->nm;
	if (n == 0)
		return 0;
	double *key = malloc(n * sizeof *key);
	char *in = calloc(n, 1);
	double mst = 0;
	if (!key || !in) {
		free(key);
		free(in);
		return P->dwell * (double)n; /* still a valid bound */
	}
	for (size_t i = 0; i < n; i++)
		key[i] = INFINITY;
	key[0] = 0;
	for (size_t it = 0; it < n; it++) {
		size_t u = SIZE_MAX;
		for (size_t i = 0; i < n; i++)
			if (!in[i] && (u == SIZE_MAX || key[i] < key[u]))
				u = i;
		in[u] = 1;
		mst += key[u];
		for (size_t i = 0; i < n; i++)
			if (!in[i]) {
				double w = lower_bound_w(P, &P->m[u], &P->m[i]);
				if (w < key[i])
					key[i] = w;
			}
	}
	double lo = INFINITY, hi = -INFINITY;
	for (size_t i = 0; i < n; i++) {
		lo = fmin(lo, P->m[i].pos.laser_theta);
		hi = fmax(hi, P->m[i].pos.laser_theta);
	}
	double laser = plan_axis_time(&P->g->laser_theta, hi - lo);
	free(key);
	free(in);
	return P->dwell * (double)n + fmax(mst, laser);
}

/* ---- result ------------------------------------------------------------------------------------------ */

void plan_result_free(struct plan_result *r)
{
	if (!r)
		return;
	free(r->req);
	free(r->steps);
	free(r->wps);
	free(r);
}

static void free_planner(struct planner *P)
{
	for (size_t k = 0; k < P->ngrp; k++) {
		free(P->grp[k].idx);
		free(P->grp[k].C);
	}
	free(P->grp);
	free(P->m);
}


static int make_order(const struct plan_spec *s, const struct bench_geom *g, const struct plan_pos *start,
		      struct plan_result *R, struct acq_err *err);

/* The spec's requests expanded, de-duplicated and classified into R->req. 0 or -1 with err. */
static int make_requests(const struct plan_spec *s, const struct bench_geom *g, struct plan_result *R,
			 struct acq_err *err)
{
	if (s->averages < 1 || !(s->integ_ms > 0) || (!s->fib_count && (!s->n_obs_theta || !s->n_obs_phi)) ||
	    !s->n_incidence) {
		return acq_errf(err, ACQ_E_INVAL, "plan '%s': empty or invalid plan", s->name);
	}
	{
		/* a spec built by code gets the checks a file gets */
		size_t per = s->fib_count ? s->fib_count : s->n_obs_theta * s->n_obs_phi;
		if (per > PLAN_MAX_PER_INCIDENCE || (double)per * (double)s->n_incidence > PLAN_MAX_POINTS) {
			return acq_errf(err, ACQ_E_RANGE, "plan '%s': too many points (%zu per incidence, max %d; %d in all)",
					s->name, per, PLAN_MAX_PER_INCIDENCE, PLAN_MAX_POINTS);
		}
		bool finite = true;
		for (size_t i = 0; i < s->n_incidence; i++)
			finite &= isfinite(s->incidence[i]);
		for (size_t i = 0; !s->fib_count && i < s->n_obs_theta; i++)
			finite &= isfinite(s->obs_theta[i]);
		for (size_t i = 0; !s->fib_count && i < s->n_obs_phi; i++)
			finite &= isfinite(s->obs_phi[i]);
		if (!finite || (s->fib_count && !(s->fib_max_theta_deg > 0 && s->fib_max_theta_deg <= 90))) {
			return acq_errf(err, ACQ_E_INVAL, "plan '%s': non-finite or out-of-range angle", s->name);
		}
	}
	if (plan_expand(s, &R->req, &R->n_req, err) || plan_adaptive_seed_extra(s, g, &R->req, &R->n_req, err))
		return -1;
	for (size_t i = 0; i < R->n_req; i++)
		R->req[i].status = PLAN_KEPT;
	if (plan_mark_duplicates(R->req, R->n_req, false, err))
		return -1;
	for (size_t i = 0; i < R->n_req; i++)
		if (R->req[i].status != PLAN_DUPLICATE)
			plan_classify_req(g, &R->req[i], s->blind_policy);
		else {
			R->req[i].pos = plan_canon(R->req[i].req);
			R->req[i].psi_deg = plan_psi_deg(g, &R->req[i].pos);
		}
	if (s->reciprocal_pairs) {
		size_t n0 = R->n_req;
		plan_add_reciprocals(s, g, R->req, &R->n_req);
		for (size_t i = n0; i < R->n_req; i++)
			plan_classify_req(g, &R->req[i], PLAN_BLIND_DROP);
	}
	/* a moved point may land on another point, a reciprocal partner may be a grid point: measure once */
	return plan_mark_duplicates(R->req, R->n_req, true, err);
}

int plan_make(const struct plan_spec *s, const struct bench_geom *g, struct plan_result **out, struct acq_err *err)
{
	*out = NULL;
	struct plan_result *R = calloc(1, sizeof *R);
	if (!R)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	if (make_requests(s, g, R, err) || make_order(s, g, NULL, R, err)) {
		plan_result_free(R);
		return -1;
	}
	*out = R;
	return 0;
}

int plan_make_points(const struct plan_spec *s, const struct bench_geom *g, const struct plan_pos *pts, size_t n,
		     const struct plan_pos *start, struct plan_result **out, struct acq_err *err)
{
	*out = NULL;
	if (n > PLAN_MAX_POINTS)
		return acq_errf(err, ACQ_E_RANGE, "plan '%s': %zu points is more than %d", s->name, n, PLAN_MAX_POINTS);
	struct plan_result *R = calloc(1, sizeof *R);
	if (!R || !(R->req = calloc(n ? n : 1, sizeof *R->req))) {
		free(R);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	R->n_req = n;
	for (size_t i = 0; i < n; i++) {
		if (!isfinite(pts[i].laser_theta) || !isfinite(pts[i].det_theta) || !isfinite(pts[i].det_phi)) {
			plan_result_free(R);
			return acq_errf(err, ACQ_E_INVAL, "plan '%s': point %zu: non-finite angle", s->name, i);
		}
		R->req[i].req = pts[i];
		R->req[i].status = PLAN_KEPT;
	}
	if (plan_mark_duplicates(R->req, n, false, err))
		goto fail;
	for (size_t i = 0; i < n; i++)
		if (R->req[i].status != PLAN_DUPLICATE)
			plan_classify_req(g, &R->req[i], PLAN_BLIND_DROP);
	if (make_order(s, g, start, R, err))
		goto fail;
	*out = R;
	return 0;
fail:
	plan_result_free(R);
	return -1;
}

/* Order R's measured requests into steps with safe moves (from start when given), time them. 0 or -1. */
static int make_order(const struct plan_spec *s, const struct bench_geom *g, const struct plan_pos *start,
		      struct plan_result *R, struct acq_err *err)
{
	struct planner P = { .g = g, .have_start = start != NULL };
	if (start)
		P.start = *start;
	size_t *order[NCAND] = { NULL };
	int *rep[NCAND] = { NULL };
	char *keep[NCAND] = { NULL };
	R->point_dwell_s = (double)s->averages * (s->integ_ms / 1000.0 + g->readout_s);
	P.dwell = R->point_dwell_s;

	/* measured points */
	P.m = calloc(R->n_req ? R->n_req : 1, sizeof *P.m);
	if (!P.m) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto fail;
	}
	for (size_t i = 0; i < R->n_req; i++) {
		struct plan_req *q = &R->req[i];
		if (q->status != PLAN_KEPT && q->status != PLAN_MOVED)
			continue;
		struct mpt *m = &P.m[P.nm];
		m->req = i;
		m->pos = q->pos;
		m->nreps = plan_phi_reps(g, q->pos.det_phi, m->reps);
		if (m->nreps == 0) { /* cannot happen: classify checked the limits */
			q->status = PLAN_DROPPED;
			q->reason |= PLAN_R_LIMITS;
			continue;
		}
		P.nm++;
	}
	if (build_groups(&P, err))
		goto fail;
	R->n_groups = P.ngrp;

	/* candidates: ascending incidences, descending (each with plain local search, and with kicks: the
	 * kicks shorten each group but move its end, so neither always wins), request order */
	double best = INFINITY;
	int bi = -1;
	for (int c = 0; c < NCAND; c++) {
		order[c] = malloc((P.nm ? P.nm : 1) * sizeof *order[c]);
		rep[c] = calloc(P.nm ? P.nm : 1, sizeof *rep[c]);
		keep[c] = calloc(P.nm ? P.nm : 1, 1);
		if (!order[c] || !rep[c] || !keep[c]) {
			acq_errf(err, ACQ_E_NOMEM, "out of memory");
			goto fail;
		}
		if (c < NCAND - 1) {
			if (order_all(&P, c & 1, c >= 2, order[c], err))
				goto fail;
		} else {
			for (size_t i = 0; i < P.nm; i++)
				order[c][i] = i;
		}
		double t = choose_reps(&P, order[c], P.nm, rep[c], keep[c]);
		if (t < 0) {
			acq_errf(err, ACQ_E_NOMEM, "out of memory");
			goto fail;
		}
		size_t nk = 0;
		for (size_t i = 0; i < P.nm; i++)
			nk += keep[c][i] != 0;
		t += (double)nk * P.dwell;
		/* prefer the order that keeps the most points, then the fastest */
		size_t bk = 0;
		if (bi >= 0)
			for (size_t i = 0; i < P.nm; i++)
				bk += keep[bi][i] != 0;
		if (bi < 0 || nk > bk || (nk == bk && t < best)) {
			best = t;
			bi = c;
		}
	}

	/* steps and waypoints of the chosen order */
	R->steps = calloc(P.nm ? P.nm : 1, sizeof *R->steps);
	R->wps = calloc((P.nm ? P.nm : 1) * PLAN_MAX_WP, sizeof *R->wps);
	if (!R->steps || !R->wps) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto fail;
	}
	double clock = 0;
	struct plan_pos cur = P.have_start ? P.start : (struct plan_pos){ 0, 0, 0 };
	for (size_t i = 0; i < P.nm; i++) {
		const struct mpt *m = &P.m[order[bi][i]];
		if (!keep[bi][i]) {
			R->req[m->req].status = PLAN_DROPPED;
			R->req[m->req].reason |= PLAN_R_UNREACHABLE;
			continue;
		}
		struct plan_step *st = &R->steps[R->n_steps];
		st->req = m->req;
		st->pos = m->pos;
		st->pos.det_phi = m->reps[rep[bi][i]];
		st->first_wp = R->n_wps;
		if (R->n_steps > 0 || P.have_start) {
			size_t nw = 0;
			double t = plan_move(g, &cur, &st->pos, &R->wps[R->n_wps], &nw);
			if (t < 0) { /* the DP proved this move exists */
				acq_errf(err, ACQ_E_NUMERIC, "internal: no safe move found on replay");
				goto fail;
			}
			double segs = 0;
			for (size_t k = 0; k < nw; k++) {
				segs += R->wps[R->n_wps + k].duration_s;
				R->travel_deg[0] += fabs(R->wps[R->n_wps + k].pos.laser_theta -
							 (k ? R->wps[R->n_wps + k - 1].pos.laser_theta : cur.laser_theta));
				R->travel_deg[1] += fabs(R->wps[R->n_wps + k].pos.det_theta -
							 (k ? R->wps[R->n_wps + k - 1].pos.det_theta : cur.det_theta));
				R->travel_deg[2] += fabs(R->wps[R->n_wps + k].pos.det_phi -
							 (k ? R->wps[R->n_wps + k - 1].pos.det_phi : cur.det_phi));
			}
			st->n_wp = nw;
			st->move_s = segs;
			st->settle_s = t - segs;
			st->detour = nw > 1;
			R->n_detours += st->detour;
			R->n_wps += nw;
		}
		st->t_start_s = clock;
		st->dwell_s = P.dwell;
		clock += st->move_s + st->settle_s + st->dwell_s;
		R->motion_s += st->move_s + st->settle_s;
		R->dwell_s += st->dwell_s;
		cur = st->pos;
		R->n_steps++;
	}
	R->duration_s = clock;
	R->raster_s = raster_time(&P);
	/* the bound is over the points actually measured */
	{
		size_t w = 0;
		for (size_t i = 0; i < P.nm; i++)
			if (R->req[P.m[i].req].status == PLAN_KEPT || R->req[P.m[i].req].status == PLAN_MOVED)
				P.m[w++] = P.m[i];
		P.nm = w;
		R->lower_bound_s = lower_bound(&P);
	}
	for (size_t i = 0; i < R->n_req; i++) {
		switch (R->req[i].status) {
		case PLAN_KEPT: R->n_kept++; break;
		case PLAN_MOVED: R->n_moved++; break;
		case PLAN_DROPPED: R->n_dropped++; break;
		case PLAN_DUPLICATE: R->n_duplicate++; break;
		}
	}
	for (int c = 0; c < NCAND; c++) {
		free(order[c]);
		free(rep[c]);
		free(keep[c]);
	}
	free_planner(&P);
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	plan_time_apply(s, g, &tm, R);
	return 0;
fail:
	for (int c = 0; c < NCAND; c++) {
		free(order[c]);
		free(rep[c]);
		free(keep[c]);
	}
	free_planner(&P);
	return -1;
}
