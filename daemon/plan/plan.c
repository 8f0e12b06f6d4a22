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

#include "daemon/plan/plan.h"

#define DEG (M_PI / 180.0)
#define MAX_REPS 4

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
};

static double norm360(double x)
{
	double r = fmod(x, 360.0);
	if (r < 0)
		r += 360.0;
	if (r >= 360.0)
		r = 0;
	return r;
}

static int phi_reps(const struct bench_geom *g, double phi, double out[MAX_REPS])
{
	int n = 0;
	for (int k = -3; k <= 3 && n < MAX_REPS; k++) {
		double x = phi + 360.0 * k;
		if (x >= g->detector_phi.min_deg - 1e-9 && x <= g->detector_phi.max_deg + 1e-9)
			out[n++] = fmin(fmax(x, g->detector_phi.min_deg), g->detector_phi.max_deg);
	}
	return n;
}

static void dir_of(double theta, double phi, double v[3])
{
	v[0] = sin(theta * DEG) * cos(phi * DEG);
	v[1] = sin(theta * DEG) * sin(phi * DEG);
	v[2] = cos(theta * DEG);
}

static void dir_to_angles(const double v[3], double *theta, double *phi, double phi_hint)
{
	double r = sqrt(v[0] * v[0] + v[1] * v[1]);
	*theta = atan2(r, v[2]) / DEG;
	*phi = r < 1e-12 ? phi_hint : norm360(atan2(v[1], v[0]) / DEG);
}

/* Canonical form: θD ≥ 0, φD in [0, 360). A negative zenith is the other side. */
static struct plan_pos canon(struct plan_pos p)
{
	if (p.det_theta < 0) {
		p.det_theta = -p.det_theta;
		p.det_phi += 180.0;
	}
	p.det_phi = norm360(p.det_phi);
	return p;
}

/* Blind reasons of a canonical point, trying each equivalent azimuth for the limits. */
static unsigned classify(const struct bench_geom *g, const struct plan_pos *p)
{
	double reps[MAX_REPS];
	int n = phi_reps(g, p->det_phi, reps);
	struct plan_pos q = *p;
	if (n == 0)
		return plan_blind(g, &q) | PLAN_R_LIMITS;
	q.det_phi = reps[0];
	return plan_blind(g, &q);
}

static double gc_deg(const double a[3], const double b[3])
{
	double c[3] = { a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0] };
	return atan2(sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]), a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / DEG;
}

/* Nearest visible observation direction at the same incidence: the blind zones are caps around ωi, so the
 * nearest point outside them lies on the great circle from ωi through ωo just past the largest active
 * half-angle; when that point breaks a limit, candidates on circles around ωi and along the limit
 * zeniths are tried and the nearest visible one wins. Returns false when none is within 30°. */
static bool move_point(const struct bench_geom *g, const struct plan_pos *p, struct plan_pos *out, double *dist)
{
	double m = g->safety_margin_deg, thr = g->laser_body_halfwidth_deg + g->detector_body_halfwidth_deg + m;
	if (g->detector_radius_mm < g->laser_radius_mm)
		thr = fmax(thr, g->detector_body_halfwidth_deg + g->beam_halfwidth_deg + m);
	if (g->laser_radius_mm < g->detector_radius_mm)
		thr = fmax(thr, g->laser_body_halfwidth_deg + g->fov_halfwidth_deg + m);
	double wi[3], wo[3];
	dir_of(p->laser_theta, g->laser_phi_deg, wi);
	dir_of(p->det_theta, p->det_phi, wo);
	/* tangent basis at ωi */
	double ref[3] = { 0, 0, 1 };
	if (fabs(wi[2]) > 0.9) {
		ref[0] = 1;
		ref[2] = 0;
	}
	double e1[3] = { wi[1] * ref[2] - wi[2] * ref[1], wi[2] * ref[0] - wi[0] * ref[2], wi[0] * ref[1] - wi[1] * ref[0] };
	double l = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
	for (int i = 0; i < 3; i++)
		e1[i] /= l;
	double e2[3] = { wi[1] * e1[2] - wi[2] * e1[1], wi[2] * e1[0] - wi[0] * e1[2], wi[0] * e1[1] - wi[1] * e1[0] };
	/* the azimuth of ωo around ωi */
	double u = wo[0] * e1[0] + wo[1] * e1[1] + wo[2] * e1[2], w = wo[0] * e2[0] + wo[1] * e2[1] + wo[2] * e2[2];
	double a0 = (fabs(u) + fabs(w) > 1e-12) ? atan2(w, u) : 0;
	bool found = false;
	double best = 1e9;
	struct plan_pos bp = *p;
	const struct bench_axis *dt = &g->detector_theta;
	for (int ring = 0; ring < 40; ring++) {
		double rho = (thr + 2 * PLAN_EDGE_DEG + ring * 0.5) * DEG;
		if (rho / DEG - thr > 30.0)
			break;
		for (int k = 0; k < 720; k++) {
			double a = a0 + (k % 2 ? -1 : 1) * ((k + 1) / 2) * (M_PI / 360.0);
			double v[3];
			for (int i = 0; i < 3; i++)
				v[i] = cos(rho) * wi[i] + sin(rho) * (cos(a) * e1[i] + sin(a) * e2[i]);
			struct plan_pos q = { p->laser_theta, 0, 0 };
			dir_to_angles(v, &q.det_theta, &q.det_phi, p->det_phi);
			double d = gc_deg(v, wo);
			if (d < best && !classify(g, &q)) {
				best = d;
				bp = q;
				found = true;
			}
		}
		/* points beyond the first ring are only needed when limits cut the cap's rim */
		if (found && best < rho / DEG + 1e-9)
			break;
	}
	/* along the limit zeniths (the cap rim may lie beyond them) */
	double zl[2] = { fmax(dt->min_deg, 0), fmin(dt->max_deg, 90) };
	for (int j = 0; j < 2; j++) {
		for (int k = 0; k < 3600; k++) {
			struct plan_pos q = { p->laser_theta, zl[j], k * 0.1 };
			double v[3];
			dir_of(q.det_theta, q.det_phi, v);
			double d = gc_deg(v, wo);
			if (d < best && !classify(g, &q)) {
				best = d;
				bp = q;
				found = true;
			}
		}
	}
	if (!found || best > 30.0)
		return false;
	*out = canon(bp);
	*dist = best;
	return true;
}

/* ---- expansion, duplicates, classification --------------------------------------------------------- */

static int expand(const struct plan_spec *s, struct plan_req **out, size_t *n, struct acq_err *err)
{
	size_t per = s->fib_count ? s->fib_count : s->n_obs_theta * s->n_obs_phi;
	size_t total = per * s->n_incidence;
	struct plan_req *r = calloc(total + s->reciprocal_pairs + 1, sizeof *r);
	if (!r)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory for %zu points", total);
	size_t k = 0;
	const double golden = 180.0 * (3.0 - sqrt(5.0)); /* degrees */
	for (size_t i = 0; i < s->n_incidence; i++) {
		if (s->fib_count) {
			double cmax = cos(s->fib_max_theta_deg * DEG);
			for (size_t j = 0; j < s->fib_count; j++) {
				double c = 1.0 - (1.0 - cmax) * ((double)j + 0.5) / (double)s->fib_count;
				r[k].req = (struct plan_pos){ s->incidence[i], acos(c) / DEG, norm360(golden * (double)j) };
				k++;
			}
		} else {
			for (size_t a = 0; a < s->n_obs_theta; a++)
				for (size_t b = 0; b < s->n_obs_phi; b++) {
					r[k].req = (struct plan_pos){ s->incidence[i], s->obs_theta[a], s->obs_phi[b] };
					k++;
				}
		}
	}
	*out = r;
	*n = k;
	return 0;
}

struct dkey {
	int64_t q[4];
	size_t i;
};

static int cmp_dkey(const void *x, const void *y)
{
	const struct dkey *a = x, *b = y;
	for (int i = 0; i < 4; i++)
		if (a->q[i] != b->q[i])
			return a->q[i] < b->q[i] ? -1 : 1;
	return (a->i > b->i) - (a->i < b->i);
}

/* Mark later requests of an already requested configuration (same θL, same ωo to ~1e-7) duplicates.
 * measured: compare where points are measured (pos) among kept and moved ones, else as requested. */
static int mark_duplicates(struct plan_req *r, size_t n, bool measured, struct acq_err *err)
{
	struct dkey *k = malloc((n ? n : 1) * sizeof *k);
	if (!k)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	size_t m = 0;
	for (size_t i = 0; i < n; i++) {
		if (measured && r[i].status != PLAN_KEPT && r[i].status != PLAN_MOVED)
			continue;
		const struct plan_pos *p = measured ? &r[i].pos : &r[i].req;
		double v[3];
		dir_of(p->det_theta, p->det_phi, v);
		k[m].q[0] = llround(p->laser_theta * 1e7);
		for (int j = 0; j < 3; j++)
			k[m].q[j + 1] = llround(v[j] * 1e7);
		k[m].i = i;
		m++;
	}
	qsort(k, m, sizeof *k, cmp_dkey);
	for (size_t i = 1; i < m; i++) {
		if (!memcmp(k[i].q, k[i - 1].q, sizeof k[i].q)) {
			size_t first = k[i - 1].i;
			if (r[first].status == PLAN_DUPLICATE)
				first = r[first].same_as;
			r[k[i].i].status = PLAN_DUPLICATE;
			r[k[i].i].same_as = first;
		}
	}
	free(k);
	return 0;
}

static void classify_req(const struct bench_geom *g, struct plan_req *r, enum plan_blind_policy policy)
{
	r->pos = canon(r->req);
	r->reason = classify(g, &r->pos);
	r->moved_deg = 0;
	if (!r->reason) {
		r->status = PLAN_KEPT;
	} else if (policy == PLAN_BLIND_MOVE && r->role == PLAN_ROLE_GRID &&
		   g->laser_theta.min_deg - 1e-9 <= r->pos.laser_theta &&
		   r->pos.laser_theta <= g->laser_theta.max_deg + 1e-9) {
		struct plan_pos q;
		double d;
		if (move_point(g, &r->pos, &q, &d)) {
			r->status = PLAN_MOVED;
			r->pos = q;
			r->moved_deg = d;
		} else {
			r->status = PLAN_DROPPED;
			r->reason |= PLAN_R_NO_NEARBY;
		}
	} else {
		r->status = PLAN_DROPPED;
	}
	r->psi_deg = plan_psi_deg(g, &r->pos);
}

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

#define INF_COST 1e12
#define OR_K 10
#define NCAND 5 /* candidate orders */

static double pcost(const double *C, size_t n, size_t a, size_t b)
{
	return C[a * n + b];
}

#define E(i, j) ((i) == SIZE_MAX ? s[(j)] : pcost(C, n, (i), (j)))
/* 2-opt and Or-opt until no move improves (or 200 passes). */
static void local_search(const double *C, size_t n, const double *s, size_t *p, size_t *tmp, size_t *pos,
			 const size_t *nbr, size_t kn)
{
	bool improved = true;
	for (int pass = 0; improved && pass < 200; pass++) {
		improved = false;
		/* 2-opt: reverse p[i..j]; the edge into p[i] comes from p[i-1] (or the start), the edge out of
		 * p[j] goes to p[j+1] (or nothing at the end of the open path). */
		for (size_t i = 0; i + 1 < n; i++) {
			size_t a = i ? p[i - 1] : SIZE_MAX;
			for (size_t j = i + 1; j < n; j++) {
				double before = E(a, p[i]) + (j + 1 < n ? pcost(C, n, p[j], p[j + 1]) : 0);
				double after = E(a, p[j]) + (j + 1 < n ? pcost(C, n, p[i], p[j + 1]) : 0);
				if (after < before - 1e-9) {
					for (size_t x = i, y = j; x < y; x++, y--) {
						size_t t = p[x];
						p[x] = p[y];
						p[y] = t;
					}
					improved = true;
					a = i ? p[i - 1] : SIZE_MAX;
				}
			}
		}
		/* Or-opt: move p[i..i+L) elsewhere, possibly reversed. Insertion places are tried next to the
		 * K nearest neighbours of the segment's ends (and at both ends of the path): O(n·K) per pass. */
		for (size_t x = 0; x < n; x++)
			pos[p[x]] = x;
		for (size_t L = 1; L <= 3 && L < n; L++) {
			for (size_t i = 0; i + L <= n; i++) {
				size_t a = i ? p[i - 1] : SIZE_MAX, f = p[i], l = p[i + L - 1];
				bool has_next = i + L < n;
				size_t nx = has_next ? p[i + L] : 0;
				size_t nr = n - L;
				double removed = E(a, f) + (has_next ? pcost(C, n, l, nx) : 0) -
						 (has_next ? E(a, nx) : 0);
#define REST(k) (p[(k) < i ? (k) : (k) + L])
				size_t cand[4 * OR_K + 2], ncand = 0;
				cand[ncand++] = 0;
				cand[ncand++] = nr;
				for (int e = 0; e < 2; e++) {
					const size_t *nb = &nbr[(e ? l : f) * kn];
					for (size_t q = 0; q < kn; q++) {
						size_t pj = pos[nb[q]];
						if (pj >= i && pj < i + L)
							continue;
						size_t r = pj < i ? pj : pj - L;
						cand[ncand++] = r;
						cand[ncand++] = r + 1;
					}
				}
				double bestg = 1e-9;
				size_t bk = SIZE_MAX;
				bool brev = false;
				for (size_t ci = 0; ci < ncand; ci++) {
					size_t k = cand[ci];
					if (k == i || k > nr)
						continue; /* the same place */
					size_t pa = k ? REST(k - 1) : SIZE_MAX;
					for (int rev = 0; rev < 2; rev++) {
						size_t s1 = rev ? l : f, s2 = rev ? f : l;
						double add = E(pa, s1) + (k < nr ? pcost(C, n, s2, REST(k)) : 0) -
							     (k < nr ? E(pa, REST(k)) : 0);
						double gain = removed - add;
						if (gain > bestg) {
							bestg = gain;
							bk = k;
							brev = rev;
						}
					}
				}
#undef REST
				if (bk == SIZE_MAX)
					continue;
				size_t seg[3];
				for (size_t x = 0; x < L; x++)
					seg[x] = p[i + (brev ? L - 1 - x : x)];
				size_t w = 0;
				for (size_t x = 0; x < n; x++)
					if (x < i || x >= i + L)
						tmp[w++] = p[x];
				w = 0;
				for (size_t x = 0; x < bk; x++)
					p[w++] = tmp[x];
				for (size_t x = 0; x < L; x++)
					p[w++] = seg[x];
				for (size_t x = bk; x < nr; x++)
					p[w++] = tmp[x];
				for (size_t x = 0; x < n; x++)
					pos[p[x]] = x;
				improved = true;
			}
		}
	}
}

static double open_len(const double *C, size_t n, const double *s, const size_t *p)
{
	double t = s[p[0]];
	for (size_t i = 1; i < n; i++)
		t += pcost(C, n, p[i - 1], p[i]);
	return t;
}
#undef E

/* Nearest neighbour from the start row, then 2-opt and Or-opt (segments of 1–3, either orientation) until
 * no move improves. C is symmetric; the start row s is not part of it. */
static void order_group(const double *C, size_t n, const double *s, size_t *p, bool ils)
{
	if (n == 0)
		return;
	char *used = calloc(n, 1);
	size_t cur = 0;
	for (size_t i = 0; i < n; i++) {
		size_t bi = 0;
		double bc = INFINITY;
		for (size_t j = 0; j < n; j++) {
			if (used && used[j])
				continue;
			double c = i == 0 ? s[j] : pcost(C, n, cur, j);
			if (c < bc) {
				bc = c;
				bi = j;
			}
		}
		if (!used) { /* out of memory: identity order */
			p[i] = i;
			continue;
		}
		used[bi] = 1;
		p[i] = bi;
		cur = bi;
	}
	free(used);
	size_t kn = n - 1 < OR_K ? n - 1 : OR_K;
	size_t *tmp = malloc(n * sizeof *tmp), *pos = malloc(n * sizeof *pos);
	size_t *nbr = malloc((n * kn + 1) * sizeof *nbr);
	if (!tmp || !pos || !nbr) {
		free(tmp);
		free(pos);
		free(nbr);
		return;
	}
	/* the kn nearest neighbours of every node, by insertion into a short sorted list */
	for (size_t u = 0; u < n; u++) {
		size_t *nb = &nbr[u * kn], m = 0;
		for (size_t v = 0; v < n; v++) {
			if (v == u)
				continue;
			double c = pcost(C, n, u, v);
			if (m == kn && c >= pcost(C, n, u, nb[m - 1]))
				continue;
			size_t k = m < kn ? m++ : kn - 1;
			while (k > 0 && pcost(C, n, u, nb[k - 1]) > c) {
				nb[k] = nb[k - 1];
				k--;
			}
			nb[k] = v;
		}
	}
	local_search(C, n, s, p, tmp, pos, nbr, kn);
	/* Iterated local search: a double-bridge kick (three cut points, segments B and C swapped), local
	 * search again, keep it if shorter. The random generator is local and seeded by n: deterministic. */
	size_t *q = malloc(n * sizeof *q);
	if (q && ils && n >= 8) {
		double best = open_len(C, n, s, p);
		uint64_t rng = 0x9E3779B97F4A7C15ull ^ (uint64_t)n;
		int kicks = n <= 300 ? 60 : n <= 1000 ? 15 : 4;
		for (int k = 0; k < kicks; k++) {
			size_t cut[3];
			for (int c = 0; c < 3; c++) {
				rng ^= rng << 13;
				rng ^= rng >> 7;
				rng ^= rng << 17;
				cut[c] = 1 + (size_t)(rng % (n - 1));
			}
			/* sort the cuts */
			for (int a = 0; a < 3; a++)
				for (int b = a + 1; b < 3; b++)
					if (cut[b] < cut[a]) {
						size_t t = cut[a];
						cut[a] = cut[b];
						cut[b] = t;
					}
			if (cut[0] == cut[1] || cut[1] == cut[2])
				continue;
			size_t w = 0;
			for (size_t x = 0; x < cut[0]; x++)
				q[w++] = p[x];
			for (size_t x = cut[1]; x < cut[2]; x++)
				q[w++] = p[x];
			for (size_t x = cut[0]; x < cut[1]; x++)
				q[w++] = p[x];
			for (size_t x = cut[2]; x < n; x++)
				q[w++] = p[x];
			local_search(C, n, s, q, tmp, pos, nbr, kn);
			double len = open_len(C, n, s, q);
			if (len < best - 1e-9) {
				best = len;
				memcpy(p, q, n * sizeof *p);
			}
		}
	}
	free(q);
	free(tmp);
	free(pos);
	free(nbr);
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
			double c = last == SIZE_MAX ? 0 : mcost(P, &P->m[last], &P->m[G->idx[j]]);
			s[j] = c < 0 ? INF_COST : c;
		}
		order_group(G->C, G->n, s, p, ils);
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
				dp[i * MAX_REPS + j] = 0;
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

static int add_reciprocals(const struct plan_spec *s, const struct bench_geom *g, struct plan_req *r, size_t *n)
{
	size_t ngrid = *n, nvis = 0;
	for (size_t i = 0; i < ngrid; i++)
		nvis += r[i].status == PLAN_KEPT;
	size_t want = s->reciprocal_pairs < nvis ? s->reciprocal_pairs : nvis;
	size_t seen = 0, k = 0;
	for (size_t i = 0; i < ngrid && k < want; i++) {
		if (r[i].status != PLAN_KEPT)
			continue;
		/* evenly spread: take visible point number floor(j·nvis/want) */
		if (seen++ != (k * nvis) / want)
			continue;
		struct plan_req *q = &r[*n];
		memset(q, 0, sizeof *q);
		/* swap ωi and ωo, rotated about the normal so the laser stays at its azimuth (isotropic sample):
		 * the relative azimuth φo − φi changes sign */
		double rel = r[i].pos.det_phi - g->laser_phi_deg;
		q->req = (struct plan_pos){ r[i].pos.det_theta, r[i].pos.laser_theta, g->laser_phi_deg - rel };
		if (q->req.det_theta < 0) {
			q->req.det_theta = -q->req.det_theta;
			q->req.det_phi += 180.0;
		}
		q->req.det_phi = norm360(q->req.det_phi);
		q->role = PLAN_ROLE_RECIPROCAL;
		q->partner = i;
		(*n)++;
		k++;
	}
	return 0;
}

int plan_make(const struct plan_spec *s, const struct bench_geom *g, struct plan_result **out, struct acq_err *err)
{
	*out = NULL;
	struct planner P = { .g = g };
	struct plan_result *R = calloc(1, sizeof *R);
	size_t *order[NCAND] = { NULL };
	int *rep[NCAND] = { NULL };
	char *keep[NCAND] = { NULL };
	if (!R)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	if (s->averages < 1 || !(s->integ_ms > 0) || (!s->fib_count && (!s->n_obs_theta || !s->n_obs_phi)) ||
	    !s->n_incidence) {
		acq_errf(err, ACQ_E_INVAL, "plan '%s': empty or invalid plan", s->name);
		goto fail;
	}
	{
		/* a spec built by code gets the checks a file gets */
		size_t per = s->fib_count ? s->fib_count : s->n_obs_theta * s->n_obs_phi;
		if (per > PLAN_MAX_PER_INCIDENCE || (double)per * (double)s->n_incidence > PLAN_MAX_POINTS) {
			acq_errf(err, ACQ_E_RANGE, "plan '%s': too many points (%zu per incidence, max %d; %d in all)",
				 s->name, per, PLAN_MAX_PER_INCIDENCE, PLAN_MAX_POINTS);
			goto fail;
		}
		bool finite = true;
		for (size_t i = 0; i < s->n_incidence; i++)
			finite &= isfinite(s->incidence[i]);
		for (size_t i = 0; !s->fib_count && i < s->n_obs_theta; i++)
			finite &= isfinite(s->obs_theta[i]);
		for (size_t i = 0; !s->fib_count && i < s->n_obs_phi; i++)
			finite &= isfinite(s->obs_phi[i]);
		if (!finite || (s->fib_count && !(s->fib_max_theta_deg > 0 && s->fib_max_theta_deg <= 90))) {
			acq_errf(err, ACQ_E_INVAL, "plan '%s': non-finite or out-of-range angle", s->name);
			goto fail;
		}
	}
	if (expand(s, &R->req, &R->n_req, err))
		goto fail;
	for (size_t i = 0; i < R->n_req; i++)
		R->req[i].status = PLAN_KEPT;
	if (mark_duplicates(R->req, R->n_req, false, err))
		goto fail;
	for (size_t i = 0; i < R->n_req; i++)
		if (R->req[i].status != PLAN_DUPLICATE)
			classify_req(g, &R->req[i], s->blind_policy);
		else {
			R->req[i].pos = canon(R->req[i].req);
			R->req[i].psi_deg = plan_psi_deg(g, &R->req[i].pos);
		}
	if (s->reciprocal_pairs) {
		size_t n0 = R->n_req;
		add_reciprocals(s, g, R->req, &R->n_req);
		for (size_t i = n0; i < R->n_req; i++)
			classify_req(g, &R->req[i], PLAN_BLIND_DROP);
	}
	/* a moved point may land on another point, a reciprocal partner may be a grid point: measure once */
	if (mark_duplicates(R->req, R->n_req, true, err))
		goto fail;
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
		m->nreps = phi_reps(g, q->pos.det_phi, m->reps);
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
	struct plan_pos cur = { 0, 0, 0 };
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
		if (R->n_steps > 0) {
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
	*out = R;
	return 0;
fail:
	for (int c = 0; c < NCAND; c++) {
		free(order[c]);
		free(rep[c]);
		free(keep[c]);
	}
	free_planner(&P);
	plan_result_free(R);
	return -1;
}
