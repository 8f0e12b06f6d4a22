/* plan_order: the order of one incidence group's points as an open path from a start row (nearest neighbour,
 * then 2-opt and Or-opt under the true move cost, optionally iterated with double-bridge kicks; internal to the
 * planner, plan_int.h), and the survey's order of a planned route (plan_survey_k, plan_survey_apply: plan.h). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "config/acq_rng.h"
#include "daemon/plan/plan_int.h"

#define OR_K 10

static double pcost(const double *C, size_t n, size_t a, size_t b)
{
	return C[a * n + b];
}

#define E(i, j) ((i) == SIZE_MAX ? s[(j)] : pcost(C, n, (i), (j)))

/* p[x..y] reversed in place. */
static void reverse_run(size_t *p, size_t x, size_t y)
{
	for (; x < y; x++, y--) {
		size_t t = p[x];
		p[x] = p[y];
		p[y] = t;
	}
}

/* One 2-opt pass: reverse p[i..j] wherever that shortens the path; the edge into p[i] comes from p[i-1] (or
 * the start), the edge out of p[j] goes to p[j+1] (or nothing at the end of the open path). Whether any did. */
static bool two_opt_pass(const double *C, size_t n, const double *s, size_t *p)
{
	bool improved = false;
	for (size_t i = 0; i + 1 < n; i++) {
		size_t a = i ? p[i - 1] : SIZE_MAX;
		for (size_t j = i + 1; j < n; j++) {
			double before = E(a, p[i]) + (j + 1 < n ? pcost(C, n, p[j], p[j + 1]) : 0);
			double after = E(a, p[j]) + (j + 1 < n ? pcost(C, n, p[i], p[j + 1]) : 0);
			if (after < before - 1e-9) {
				reverse_run(p, i, j);
				improved = true;
				a = i ? p[i - 1] : SIZE_MAX;
			}
		}
	}
	return improved;
}

/* Or-opt's view of the segment p[i..i+L) taken out of the path p: the path without it ("the rest", nr = n − L
 * points, REST(k) its k-th) and what taking it out saves. */
struct or_seg {
	size_t i, L, f, l, nr;  /* place, length, first and last point, length of the rest */
	double removed;         /* the path's length saved by taking the segment out (its edges in and out, less the
				 * edge that closes the gap) */
};

#define REST(g, k) (p[(k) < (g)->i ? (k) : (k) + (g)->L])

static struct or_seg or_seg_at(const double *C, size_t n, const double *s, const size_t *p, size_t i, size_t L)
{
	struct or_seg g = { .i = i, .L = L, .f = p[i], .l = p[i + L - 1], .nr = n - L };
	size_t a = i ? p[i - 1] : SIZE_MAX;
	bool has_next = i + L < n;
	size_t nx = has_next ? p[i + L] : 0;
	g.removed = E(a, g.f) + (has_next ? pcost(C, n, g.l, nx) : 0) - (has_next ? E(a, nx) : 0);
	return g;
}

/* The insertion places to try for segment g (places k in the rest: before REST(k); nr is the end): both ends
 * of the path, and each side of the K nearest neighbours of the segment's ends. Their count (≤ 4·OR_K + 2). */
static size_t or_candidates(const struct or_seg *g, const size_t *pos, const size_t *nbr, size_t kn, size_t *cand)
{
	size_t ncand = 0;
	cand[ncand++] = 0;
	cand[ncand++] = g->nr;
	for (int e = 0; e < 2; e++) {
		const size_t *nb = &nbr[(e ? g->l : g->f) * kn];
		for (size_t q = 0; q < kn; q++) {
			size_t pj = pos[nb[q]];
			if (pj >= g->i && pj < g->i + g->L)
				continue;
			size_t r = pj < g->i ? pj : pj - g->L;
			cand[ncand++] = r;
			cand[ncand++] = r + 1;
		}
	}
	return ncand;
}

/* The best of the candidate places for segment g, either orientation: whether one gains more than 1e-9, and
 * then its place *bk and orientation *brev. */
static bool or_best_place(const double *C, size_t n, const double *s, const size_t *p, const struct or_seg *g,
			  const size_t *cand, size_t ncand, size_t *bk, bool *brev)
{
	double bestg = 1e-9;
	*bk = SIZE_MAX;
	*brev = false;
	for (size_t ci = 0; ci < ncand; ci++) {
		size_t k = cand[ci];
		if (k == g->i || k > g->nr)
			continue; /* the same place */
		size_t pa = k ? REST(g, k - 1) : SIZE_MAX;
		for (int rev = 0; rev < 2; rev++) {
			size_t s1 = rev ? g->l : g->f, s2 = rev ? g->f : g->l;
			double add = E(pa, s1) + (k < g->nr ? pcost(C, n, s2, REST(g, k)) : 0) -
				     (k < g->nr ? E(pa, REST(g, k)) : 0);
			double gain = g->removed - add;
			if (gain > bestg) {
				bestg = gain;
				*bk = k;
				*brev = rev;
			}
		}
	}
	return *bk != SIZE_MAX;
}
#undef REST

/* Move segment g of p to place bk of the rest (reversed if brev); pos kept the inverse of p. tmp: n entries. */
static void or_move(size_t n, size_t *p, size_t *tmp, size_t *pos, const struct or_seg *g, size_t bk, bool brev)
{
	size_t seg[3];
	for (size_t x = 0; x < g->L; x++)
		seg[x] = p[g->i + (brev ? g->L - 1 - x : x)];
	size_t w = 0;
	for (size_t x = 0; x < n; x++)
		if (x < g->i || x >= g->i + g->L)
			tmp[w++] = p[x];
	w = 0;
	for (size_t x = 0; x < bk; x++)
		p[w++] = tmp[x];
	for (size_t x = 0; x < g->L; x++)
		p[w++] = seg[x];
	for (size_t x = bk; x < g->nr; x++)
		p[w++] = tmp[x];
	for (size_t x = 0; x < n; x++)
		pos[p[x]] = x;
}

/* One Or-opt pass: move each p[i..i+L) (L = 1..3) elsewhere, possibly reversed, where that shortens the path.
 * Insertion places are tried next to the K nearest neighbours of the segment's ends (and at both ends of the
 * path): O(n·K) per pass. Whether any moved. */
static bool or_opt_pass(const double *C, size_t n, const double *s, size_t *p, size_t *tmp, size_t *pos,
			const size_t *nbr, size_t kn)
{
	bool improved = false;
	for (size_t x = 0; x < n; x++)
		pos[p[x]] = x;
	for (size_t L = 1; L <= 3 && L < n; L++) {
		for (size_t i = 0; i + L <= n; i++) {
			struct or_seg g = or_seg_at(C, n, s, p, i, L);
			size_t cand[4 * OR_K + 2], ncand = or_candidates(&g, pos, nbr, kn, cand), bk;
			bool brev;
			if (!or_best_place(C, n, s, p, &g, cand, ncand, &bk, &brev))
				continue;
			or_move(n, p, tmp, pos, &g, bk, brev);
			improved = true;
		}
	}
	return improved;
}

/* 2-opt and Or-opt passes until neither improves (or 200 rounds). */
static void local_search(const double *C, size_t n, const double *s, size_t *p, size_t *tmp, size_t *pos,
			 const size_t *nbr, size_t kn)
{
	bool improved = true;
	for (int pass = 0; improved && pass < 200; pass++) {
		improved = two_opt_pass(C, n, s, p);
		improved |= or_opt_pass(C, n, s, p, tmp, pos, nbr, kn);
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

/* The greedy start: from the cheapest first point (s), always the nearest unvisited one, into p (the identity
 * order when out of memory). */
static void nearest_start(const double *C, size_t n, const double *s, size_t *p)
{
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
}

/* The kn nearest neighbours of every node into nbr[u * kn ...], by insertion into a short sorted list. */
static void nearest_lists(const double *C, size_t n, size_t *nbr, size_t kn)
{
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
}

/* Iterated local search: a double-bridge kick (three cut points, segments B and C swapped), local search again,
 * keep it if shorter. The tree's generator (config/acq_rng.h) seeded by n: deterministic, the same order for the
 * same group on every run. q: n scratch entries. */
static void kick_search(const double *C, size_t n, const double *s, size_t *p, size_t *q, size_t *tmp, size_t *pos,
			const size_t *nbr, size_t kn)
{
	double best = open_len(C, n, s, p);
	struct acq_rng rng;
	acq_rng_seed(&rng, (uint64_t)n);
	int kicks = n <= 300 ? 60 : n <= 1000 ? 15 : 4;
	for (int k = 0; k < kicks; k++) {
		size_t cut[3];
		for (int c = 0; c < 3; c++)
			cut[c] = 1 + (size_t)(acq_rng_next(&rng) % (n - 1));
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

/* Nearest neighbour from the start row, then 2-opt and Or-opt (segments of 1–3, either orientation) until
 * no move improves, then (ils) the kicks. C is symmetric; the start row s is not part of it. */
void plan_order_group(const double *C, size_t n, const double *s, size_t *p, bool ils)
{
	if (n == 0)
		return;
	nearest_start(C, n, s, p);
	size_t kn = n - 1 < OR_K ? n - 1 : OR_K;
	size_t *tmp = malloc(n * sizeof *tmp), *pos = malloc(n * sizeof *pos);
	size_t *nbr = malloc((n * kn + 1) * sizeof *nbr);
	if (!tmp || !pos || !nbr) {
		free(tmp);
		free(pos);
		free(nbr);
		return;
	}
	nearest_lists(C, n, nbr, kn);
	local_search(C, n, s, p, tmp, pos, nbr, kn);
	size_t *q = malloc(n * sizeof *q);
	if (q && ils && n >= 8)
		kick_search(C, n, s, p, q, tmp, pos, nbr, kn);
	free(q);
	free(tmp);
	free(pos);
	free(nbr);
}


/* ---- the survey (plan.h plan_survey_apply) ---- */

/* The detector zenith of a step as the survey's strata see it (rounded to 0.01°). */
static double survey_level(const struct plan_step *st)
{
	return round(fabs(st->pos.det_theta) * 100) / 100;
}

static int cmp_dbl(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

/* The survey's picks of one incidence group, steps[first .. first + n) in route order: k of them, stratified over
 * the group's detector zeniths in proportion to their points (the j-th pick at the zenith of the point of rank
 * floor((j + f) · n / k) by zenith, f = frac(gi · 0.618…): the groups take different zeniths, so that over the
 * incidences all are seen), and at that zenith the point whose azimuth is nearest 360° · frac(0.3 · gi + 0.7 · j)
 * (a different azimuth per pick and group). Stratified by points, not by distinct zeniths: a zenith with few points
 * (θo 0°, one direction; near the blind zone) weighs little in the incidence's mean (offline on the paper plan's
 * databases, by distinct zeniths the survey's estimate of the rest's first exposures ran 1-4 % of the sweep low).
 * Marks pick[i - first] for the chosen ones; their count. */
static size_t survey_group(const struct plan_step *steps, size_t first, size_t n, size_t gi, size_t k, char *pick)
{
	double *lev = malloc((n ? n : 1) * sizeof *lev);
	if (!lev)
		return 0;
	for (size_t i = 0; i < n; i++)
		lev[i] = survey_level(&steps[first + i]);
	qsort(lev, n, sizeof *lev, cmp_dbl);
	size_t got = 0;
	double f = fmod((double)gi * 0.6180339887498949, 1.0);
	for (size_t j = 0; j < k && got < n; j++) {
		double want_lev = lev[(size_t)fmin((double)n - 1, floor(((double)j + f) * (double)n / (double)k))];
		double want_phi = 360.0 * fmod(0.3 * (double)gi + 0.7 * (double)j, 1.0);
		size_t best = SIZE_MAX;
		double bl = INFINITY, bp = INFINITY;
		for (size_t i = 0; i < n; i++) {
			if (pick[i])
				continue;
			double dl = fabs(survey_level(&steps[first + i]) - want_lev);
			double dp = fabs(fmod(fmod(steps[first + i].pos.det_phi - want_phi, 360.0) + 540.0, 360.0) - 180.0);
			if (dl < bl - 1e-9 || (dl < bl + 1e-9 && dp < bp)) {
				best = i;
				bl = dl;
				bp = dp;
			}
		}
		if (best == SIZE_MAX)
			break;
		pick[best] = 1;
		got++;
	}
	free(lev);
	return got;
}

/* r's steps reached in the order ord[0..n) (indices into old): each move planned again from the previous step (the
 * first keeps none), the ordering model's times, travel and detours recomputed. 0, or -1 (out of memory, or a move
 * no clear path makes: r is then unchanged). */
static int restep(const struct bench_geom *g, struct plan_result *r, const struct plan_step *old, const size_t *ord)
{
	size_t n = r->n_steps;
	struct plan_step *st = calloc(n ? n : 1, sizeof *st);
	struct plan_wp *wp = calloc((n ? n : 1) * PLAN_MAX_WP, sizeof *wp);
	if (!st || !wp) {
		free(st);
		free(wp);
		return -1;
	}
	size_t nw = 0, detours = 0;
	double clock = 0, motion = 0, dwell = 0, travel[3] = { 0, 0, 0 };
	for (size_t i = 0; i < n; i++) {
		st[i] = old[ord[i]];
		st[i].first_wp = nw;
		st[i].n_wp = 0;
		st[i].move_s = st[i].settle_s = 0;
		st[i].detour = false;
		if (i > 0) {
			size_t k = 0;
			const struct plan_pos cur = st[i - 1].pos;
			double t = plan_move(g, &cur, &st[i].pos, &wp[nw], &k);
			if (t < 0) {
				free(st);
				free(wp);
				return -1;
			}
			double segs = 0;
			for (size_t w = 0; w < k; w++) {
				const struct plan_pos *a = w ? &wp[nw + w - 1].pos : &cur, *b = &wp[nw + w].pos;
				segs += wp[nw + w].duration_s;
				travel[0] += fabs(b->laser_theta - a->laser_theta);
				travel[1] += fabs(b->det_theta - a->det_theta);
				travel[2] += fabs(b->det_phi - a->det_phi);
			}
			st[i].n_wp = k;
			st[i].move_s = segs;
			st[i].settle_s = t - segs;
			st[i].detour = k > 1;
			detours += k > 1;
			nw += k;
		}
		st[i].t_start_s = clock;
		clock += st[i].move_s + st[i].settle_s + st[i].dwell_s;
		motion += st[i].move_s + st[i].settle_s;
		dwell += st[i].dwell_s;
	}
	free(r->steps);
	free(r->wps);
	r->steps = st;
	r->wps = wp;
	r->n_wps = nw;
	r->n_detours = detours;
	r->duration_s = clock;
	r->motion_s = motion;
	r->dwell_s = dwell;
	memcpy(r->travel_deg, travel, sizeof travel);
	return 0;
}

size_t plan_survey_k(const struct plan_spec *s, const struct plan_timing *t, const struct plan_result *r)
{
	if (s->integ_mode != PLAN_INTEG_AUTO || s->adaptive || !r || r->n_steps == 0 || r->steps[0].n_wp > 0 ||
	    s->survey == 0)
		return 0;
	if (s->survey > 0)
		return (size_t)s->survey;
	/* the default: only where the exposure prior lacks one of the plan's incidences */
	const struct plan_prior *p = t && t->prior.sweep > 0 ? &t->prior : NULL;
	for (size_t i = 0; i < r->n_steps; i++) {
		double th = fabs(r->steps[i].pos.laser_theta);
		bool seen = false;
		for (size_t j = 0; p && j < p->n_inc && j < PLAN_PRIOR_MAX_INC && !seen; j++)
			seen = fabs(p->inc[j].theta_i - th) <= PLAN_PRIOR_SAME_DEG;
		if (!seen)
			return PLAN_SURVEY_DEFAULT;
	}
	return 0;
}

int plan_survey_apply(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
		      struct plan_result *r, struct acq_err *err)
{
	size_t k = plan_survey_k(s, t, r), n = r ? r->n_steps : 0;
	if (k == 0 || r->n_survey > 0)
		return 0;
	/* the arrays at the plan's size (the survey picks at most all of its points); its cost matrix C once its size
	 * is known */
	char *pick = calloc(n, 1);
	size_t *ord = malloc(n * sizeof *ord), *gstart = malloc((n + 1) * sizeof *gstart);
	size_t *sp = malloc(n * sizeof *sp), *p = malloc(n * sizeof *p);
	double *C = NULL, *s0 = malloc(n * sizeof *s0);
	struct plan_step *old = malloc(n * sizeof *old);
	int rc = 0;
	if (!pick || !ord || !gstart || !sp || !p || !s0 || !old) {
		rc = acq_errf(err, ACQ_E_NOMEM, "the survey's order: out of memory");
		goto out;
	}
	memcpy(old, r->steps, n * sizeof *old);
	/* the incidence groups: runs of one laser zenith in route order (start of group j in gstart[j]) */
	size_t ng = 0, ns = 0, w = 0;
	for (size_t a = 0; a < n;) {
		size_t b = a;
		while (b < n && fabs(old[b].pos.laser_theta - old[a].pos.laser_theta) <= 1e-6)
			b++;
		gstart[ng++] = a;
		a = b;
	}
	gstart[ng] = n;
	/* at most an eighth of a group (at least one point): a small plan's survey is not most of it */
	for (size_t j = 0; j < ng; j++) {
		size_t gn = gstart[j + 1] - gstart[j], kj = k < gn / 8 ? k : gn / 8 ? gn / 8 : 1;
		ns += survey_group(old, gstart[j], gn, j, kj, pick + gstart[j]);
	}
	/* the survey's own path over its picks (all incidences together: the laser arm is the cheap axis to move
	 * between two picks of different viewing directions), ordered from the route's first point and then walked
	 * backwards, so that it ends next to where the route starts */
	C = malloc((ns ? ns * ns : 1) * sizeof *C);
	if (!C) {
		rc = acq_errf(err, ACQ_E_NOMEM, "the survey's order: out of memory");
		goto out;
	}
	size_t m = 0;
	for (size_t i = 0; i < n; i++)
		if (pick[i])
			sp[m++] = i;
	for (size_t a = 0; a < ns; a++) {
		s0[a] = plan_straight_s(g, &old[0].pos, &old[sp[a]].pos);
		for (size_t b = 0; b < ns; b++)
			C[a * ns + b] = a == b ? 0 : plan_straight_s(g, &old[sp[a]].pos, &old[sp[b]].pos);
	}
	plan_order_group(C, ns, s0, p, true);
	for (size_t a = ns; a-- > 0;)
		ord[w++] = sp[p[a]];
	for (size_t i = 0; i < n; i++)
		if (!pick[i])
			ord[w++] = i;
	double before = r->motion_s;
	if (ns > 0 && ns < n && restep(g, r, old, ord) == 0) {
		r->n_survey = ns;
		r->survey_k = k;
		r->survey_motion_s = r->motion_s - before;
	} /* else (no clear move between two of the new neighbours, out of memory) the route as it was: no survey */
out:
	free(sp);
	free(p);
	free(C);
	free(s0);
	free(gstart);
	free(pick);
	free(ord);
	free(old);
	return rc;
}
