/* plan_adaptive: adaptive plans (kind: adaptive) — their YAML, the candidate measurements of a batch and their
 * cost, the target as `brdf-recon select` takes it, and the budget's worst case for the dry run.
 *
 * Layout (every key but candidates, integration and averages required):
 *   name: adaptive-paint
 *   kind: adaptive
 *   seed:                                   # any plan (grid or Fibonacci) without integration or averages
 *     incidence: {theta_deg: [0, 30, 60]}
 *     observation: {fibonacci: {count: 24}}
 *   target: {dhr_sigma: {incidence_deg: [8], le: 0.002}}   # or {lnf_sigma: {le: 0.05}} or {rgb_sigma: {le: 0.01}},
 *                                           # or dhr_sigma and lnf_sigma together: both must be met;
 *                                           # lnf_sigma: {le: X, weight: rad}: its picks reduce the expected error
 *                                           # of log(1 + f cosθi cosθo) over dωi dωo (select's lnf:rad) instead of
 *                                           # the variance of ln f under cosθi cosθo dωi dωo (weight: projected);
 *                                           # weight: mix, both (select's lnf:mix); weight: bright,
 *                                           # per point the larger of the two (select's lnf:bright)
 *   budget: {seconds: 1400, points: 866}    # one or both; the whole sweep, seed included
 *   batch: 12                               # points per batch
 *   candidates: {incidence_deg: RANGE, per_incidence: 150, max_theta_deg: 85,
 *                specular: {rings_deg: [2, 4, 7, 11], per_ring: 8},  # or specular: false
 *                lobe_above_deg: 70}        # the lobe gate: candidates of incidence above 70° only where the
 *                                           # model has its own lobe at their pair (select's :lobe_above=70)
 *   seed_specular_deg: [-4, 0, 4]           # the seed also measures these in-plane offsets from the mirror direction
 *   overlap: false                          # true: batch k+2 is chosen (from the model through batch k) while
 *                                           # batch k+1 is measured, so the arms need not wait for the refit
 *   integration: ...                        # as any plan: the seed's and every batch's
 *   averages: 1
 * The candidate defaults: incidences 0 to 70° every 5°, 150 Fibonacci directions per incidence over θ ≤ 85°, and per
 * incidence the mirror direction (θo = θi, φo = φi + 180°) with 8 directions on each of rings 2, 4, 7 and 11° around
 * it (a Fibonacci set ~11° apart never tests a lobe a few degrees wide; the rings resolve one of 4° half width). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/plan/plan_int.h"

/* RANGE at map[key] (plan_range_parse, values in [lo, hi]) into out[max], its count into *n; what names it. 0 or -1. */
static int parse_list(struct yc_node *map, const char *key, const char *what, double lo, double hi, double *out,
		      size_t max, size_t *n, struct acq_err *err)
{
	double *v = NULL;
	size_t nv = 0;
	if (plan_range_parse(map, key, what, lo, hi, &v, &nv, err))
		return -1;
	if (nv > max) {
		free(v);
		return yc_errf(err, yc_get(map, key), "%s: at most %zu values", what, max);
	}
	memcpy(out, v, nv * sizeof *v);
	*n = nv;
	free(v);
	return 0;
}

/* target.lnf_sigma.weight: projected (the default), rad, mix or bright (select's lnf:rad, lnf:mix, lnf:bright). */
static int parse_lnf_weight(struct yc_node *l, struct plan_adaptive *a, struct acq_err *err)
{
	const char *v = NULL;
	if (yc_string(l, "weight", false, &v, err))
		return -1;
	if (!v)
		return 0;
	if (strcmp(v, "rad") == 0)
		a->lnf_weight = 1;
	else if (strcmp(v, "mix") == 0)
		a->lnf_weight = 2;
	else if (strcmp(v, "bright") == 0)
		a->lnf_weight = 3;
	else if (strcmp(v, "projected") != 0)
		return yc_errf(err, yc_get(l, "weight"), "target.lnf_sigma.weight: 'projected' (the default: the variance "
			       "of ln f under cos(theta_i) cos(theta_o) dwi dwo), 'rad' (the error of log(1 + f cos(theta_i) "
			       "cos(theta_o)) over dwi dwo), 'mix' (both, each over its own criterion) or 'bright' (per "
			       "point the larger of the two: 'rad' where the model is bright)");
	return 0;
}

static int parse_target(struct yc_node *root, struct plan_adaptive *a, struct acq_err *err)
{
	struct yc_node *t = yc_get(root, "target");
	if (!t)
		return yc_errf(err, root, "adaptive plan: missing key 'target' ({dhr_sigma: {incidence_deg: [8], le: X}}, "
			       "{lnf_sigma: {le: X}}, {rgb_sigma: {le: X}}, or dhr_sigma and lnf_sigma together)");
	if (yc_expect_map(t, "target", err))
		return -1;
	struct yc_node *d = yc_get(t, "dhr_sigma"), *l = yc_get(t, "lnf_sigma"), *g = yc_get(t, "rgb_sigma");
	if (yc_check_unknown(t, "target", err))
		return -1;
	bool both = d && l && !g;
	if ((d != NULL) + (l != NULL) + (g != NULL) != 1 && !both)
		return yc_errf(err, t, "target: give exactly one of 'dhr_sigma', 'lnf_sigma' and 'rgb_sigma', or 'dhr_sigma' and "
			       "'lnf_sigma' together (both must be met)");
	if (both) {
		if (yc_expect_map(l, "target.lnf_sigma", err) || yc_double(l, "le", true, 1e-12, 1e6, &a->le_lnf, err) ||
		    parse_lnf_weight(l, a, err) || yc_check_unknown(l, "target.lnf_sigma", err))
			return -1;
	}
	struct yc_node *n = d ? d : l ? l : g;
	const char *what = d ? "target.dhr_sigma" : l ? "target.lnf_sigma" : "target.rgb_sigma";
	if (yc_expect_map(n, what, err) || yc_double(n, "le", true, 1e-12, 1e6, &a->le, err) ||
	    (l && !both && parse_lnf_weight(l, a, err)))
		return -1;
	a->target = d ? PLAN_TARGET_DHR_SIGMA : l ? PLAN_TARGET_LNF_SIGMA : PLAN_TARGET_RGB_SIGMA;
	if (d && parse_list(n, "incidence_deg", "target.dhr_sigma.incidence_deg", 0, 89, a->target_inc,
			    PLAN_MAX_TARGET_INC, &a->n_target_inc, err))
		return -1;
	return yc_check_unknown(n, what, err);
}

static int parse_budget(struct yc_node *root, struct plan_adaptive *a, struct acq_err *err)
{
	struct yc_node *b = yc_get(root, "budget");
	long long pts = 0;
	if (!b)
		return yc_errf(err, root, "adaptive plan: missing key 'budget' ({seconds: S} and/or {points: N})");
	if (yc_expect_map(b, "budget", err) || yc_double(b, "seconds", false, 1, 1e7, &a->budget_s, err) ||
	    yc_int(b, "points", false, 1, PLAN_MAX_POINTS, &pts, err) || yc_check_unknown(b, "budget", err))
		return -1;
	if (!yc_get(b, "seconds") && !yc_get(b, "points"))
		return yc_errf(err, b, "budget: give 'seconds' (bench time, seed included) and/or 'points'");
	a->budget_points = (size_t)pts;
	return 0;
}

/* Candidates per incidence around the mirror direction: itself and its rings. */
static size_t spec_count(const struct plan_adaptive *a)
{
	return a->cand_specular ? 1 + a->n_spec_rings * a->spec_per_ring : 0;
}

/* candidates.specular: false, or {rings_deg: LIST, per_ring: N} (defaults: rings 2, 4, 7, 11°, 8 per ring). */
static int parse_specular(struct yc_node *c, struct plan_adaptive *a, struct acq_err *err)
{
	static const double rings[] = { 2, 4, 7, 11 };
	a->cand_specular = true;
	a->n_spec_rings = sizeof rings / sizeof rings[0];
	memcpy(a->spec_rings_deg, rings, sizeof rings);
	a->spec_per_ring = 8;
	struct yc_node *sp = c ? yc_get(c, "specular") : NULL;
	if (!sp)
		return 0;
	if (sp->type == YC_SCALAR)
		return yc_bool(c, "specular", false, &a->cand_specular, err);
	long long per = (long long)a->spec_per_ring;
	if (yc_expect_map(sp, "candidates.specular", err) ||
	    yc_int(sp, "per_ring", false, 1, 64, &per, err))
		return -1;
	a->spec_per_ring = (size_t)per;
	if (yc_get(sp, "rings_deg") && parse_list(sp, "rings_deg", "candidates.specular.rings_deg", 0.1, 45,
						  a->spec_rings_deg, PLAN_MAX_SPEC_RINGS, &a->n_spec_rings, err))
		return -1;
	return yc_check_unknown(sp, "candidates.specular", err);
}

/* seed_specular_deg: in-plane offsets (degrees of θo) from the mirror direction the seed also measures. */
static int parse_seed_specular(struct yc_node *root, struct plan_adaptive *a, struct acq_err *err)
{
	if (!yc_get(root, "seed_specular_deg"))
		return 0;
	return parse_list(root, "seed_specular_deg", "seed_specular_deg", -45, 45, a->seed_spec_deg, PLAN_MAX_SEED_SPEC,
			  &a->n_seed_spec, err);
}

static int parse_candidates(struct yc_node *root, struct plan_adaptive *a, struct acq_err *err)
{
	struct yc_node *c = yc_get(root, "candidates");
	long long per = 150;
	a->cand_max_theta_deg = 85;
	if (c && (yc_expect_map(c, "candidates", err) ||
		  yc_int(c, "per_incidence", false, 1, PLAN_MAX_PER_INCIDENCE, &per, err) ||
		  yc_double(c, "max_theta_deg", false, 0.1, 90, &a->cand_max_theta_deg, err) ||
		  yc_double(c, "lobe_above_deg", false, 0.1, 89.9, &a->cand_lobe_above_deg, err)))
		return -1;
	if (parse_specular(c, a, err))
		return -1;
	if (c && yc_get(c, "incidence_deg")) {
		if (plan_range_parse(c, "incidence_deg", "candidates.incidence_deg", -90, 90, &a->cand_inc, &a->n_cand_inc,
				     err))
			return -1;
	} else {
		a->n_cand_inc = 15;
		if (!(a->cand_inc = malloc(a->n_cand_inc * sizeof *a->cand_inc)))
			return acq_errf(err, ACQ_E_NOMEM, "out of memory");
		for (size_t i = 0; i < a->n_cand_inc; i++)
			a->cand_inc[i] = 5.0 * (double)i;
	}
	if (c && yc_check_unknown(c, "candidates", err))
		return -1;
	a->cand_count = (size_t)per;
	if ((double)(a->cand_count + spec_count(a)) * (double)a->n_cand_inc > PLAN_MAX_POINTS)
		return yc_errf(err, c, "candidates: %zu incidences × %zu directions is more than %d", a->n_cand_inc,
			       a->cand_count, PLAN_MAX_POINTS);
	return 0;
}

int plan_adaptive_parse(struct yc_node *root, struct plan_spec **out, struct acq_err *err)
{
	static const char *const keys[] = { "name", "kind", "seed", "target", "budget", "batch", "candidates",
					    "overlap", "integration", "averages", "seed_specular_deg", NULL };
	struct plan_spec *s = NULL;
	struct plan_adaptive *a = calloc(1, sizeof *a);
	*out = NULL;
	if (!a)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	for (size_t i = 0; keys[i]; i++)
		yc_get(root, keys[i]);
	const char *name = "adaptive";
	long long batch = 0, averages = 1;
	if (yc_check_unknown(root, "adaptive plan", err) || yc_string(root, "name", false, &name, err))
		goto fail;
	struct yc_node *seed = yc_get(root, "seed");
	if (!seed) {
		yc_errf(err, root, "adaptive plan: missing key 'seed' (a plan: incidence, observation, ...)");
		goto fail;
	}
	if (yc_expect_map(seed, "seed", err))
		goto fail;
	struct yc_node *sk = yc_get(seed, "kind");
	if (sk && sk->type == YC_SCALAR && sk->value && !strcmp(sk->value, "adaptive")) {
		yc_errf(err, sk, "seed: an adaptive plan cannot seed another");
		goto fail;
	}
	for (const char *k = "integration";; k = "averages") {
		if (yc_get(seed, k)) {
			yc_errf(err, yc_get(seed, k), "seed: '%s' belongs at the top of the adaptive plan (one policy for "
				"the seed and every batch)", k);
			goto fail;
		}
		if (!strcmp(k, "averages"))
			break;
	}
	if (plan_parse(seed, &s, err))
		goto fail;
	snprintf(s->name, sizeof s->name, "%s", name);
	if (plan_integration_parse(root, s, err) || yc_int(root, "averages", false, 1, 100000, &averages, err) ||
	    yc_int(root, "batch", true, 1, 1000, &batch, err) || yc_bool(root, "overlap", false, &a->overlap, err) ||
	    parse_target(root, a, err) ||
	    parse_budget(root, a, err) || parse_candidates(root, a, err) || parse_seed_specular(root, a, err))
		goto fail;
	s->averages = (int)averages;
	a->batch = (size_t)batch;
	s->adaptive = a;
	*out = s;
	return 0;
fail:
	if (a)
		free(a->cand_inc);
	free(a);
	plan_spec_free(s);
	return -1;
}

/* select's ln f spec per lnf_sigma's weight */
static const char *const LNF_SPEC[] = { "lnf", "lnf:rad", "lnf:mix", "lnf:bright" };

void plan_adaptive_target_spec(const struct plan_adaptive *a, char *buf, size_t len)
{
	size_t n = 0;
	if (!len)
		return;
	buf[0] = '\0';
	if (a->target != PLAN_TARGET_DHR_SIGMA) {
		n += (size_t)snprintf(buf, len, "%s:le=%.9g",
				      a->target == PLAN_TARGET_LNF_SIGMA ? LNF_SPEC[a->lnf_weight] : "rgb", a->le);
	} else {
		n += (size_t)snprintf(buf, len, "dhr:");
		for (size_t i = 0; i < a->n_target_inc && n < len; i++)
			n += (size_t)snprintf(buf + n, len - n, "%s%.9g", i ? "," : "", a->target_inc[i]);
		if (n < len)
			n += (size_t)snprintf(buf + n, len - n, ":le=%.9g", a->le);
		if (a->le_lnf > 0 && n < len)
			n += (size_t)snprintf(buf + n, len - n, "+%s:le=%.9g", LNF_SPEC[a->lnf_weight], a->le_lnf);
	}
	if (a->cand_lobe_above_deg > 0 && n < len) /* select's lobe gate */
		snprintf(buf + n, len - n, ":lobe_above=%.9g", a->cand_lobe_above_deg);
}

size_t plan_adaptive_fit_picks(const double *cost, size_t n, double left_s, size_t max_k, size_t *keep)
{
	size_t k = 0;
	double spent = 0;
	for (size_t i = 0; i < n && k < max_k; i++)
		if (spent + cost[i] <= left_s) {
			spent += cost[i];
			keep[k++] = i;
		}
	return k;
}

double plan_adaptive_threshold(const struct plan_adaptive *a)
{
	return a->le_lnf > 0 ? 1.0 : a->le;
}

/* The incidence direction's azimuth of laser position th on g, degrees. */
static double inc_phi(const struct bench_geom *g, double th)
{
	return g->laser_phi_deg + (th < 0 ? 180.0 : 0.0);
}

/* Direction r of the set around the mirror direction of laser position th (0: the mirror direction; then ring
 * (r-1)/per_ring at azimuth step (r-1)%per_ring about it, odd rings turned by half a step) as a bench position;
 * -1 when it leaves the cap θ ≤ max_theta. */
static int spec_dir(const struct plan_adaptive *a, const struct bench_geom *g, double th, size_t r, struct plan_pos *out)
{
	double ti = fabs(th), pm = inc_phi(g, th) + 180.0, m[3], e1[3], e2[3], v[3];
	plan_dir_of(ti, pm, m);
	e1[0] = cos(ti * DEG) * cos(pm * DEG); /* along θ in the specular plane */
	e1[1] = cos(ti * DEG) * sin(pm * DEG);
	e1[2] = -sin(ti * DEG);
	e2[0] = -sin(pm * DEG); /* across it */
	e2[1] = cos(pm * DEG);
	e2[2] = 0;
	double d = 0, psi = 0;
	if (r > 0) {
		size_t ring = (r - 1) / a->spec_per_ring, k = (r - 1) % a->spec_per_ring;
		d = a->spec_rings_deg[ring] * DEG;
		psi = 2.0 * M_PI * ((double)k + 0.5 * (double)(ring % 2)) / (double)a->spec_per_ring;
	}
	for (int i = 0; i < 3; i++)
		v[i] = cos(d) * m[i] + sin(d) * (cos(psi) * e1[i] + sin(psi) * e2[i]);
	double to = atan2(sqrt(v[0] * v[0] + v[1] * v[1]), v[2]) / DEG;
	if (to > a->cand_max_theta_deg + 1e-9)
		return -1;
	double po = fabs(v[0]) + fabs(v[1]) < 1e-12 ? pm : atan2(v[1], v[0]) / DEG;
	*out = plan_canon((struct plan_pos){ th, to, po });
	return 0;
}

int plan_adaptive_cand_pos(const struct plan_spec *s, const struct bench_geom *g, size_t id, struct plan_pos *out)
{
	const struct plan_adaptive *a = s->adaptive;
	if (!a || !a->cand_count)
		return -1;
	size_t nfib = a->n_cand_inc * a->cand_count, ns = spec_count(a);
	if (id >= nfib) {
		if (!ns || (id - nfib) / ns >= a->n_cand_inc)
			return -1;
		double th = a->cand_inc[(id - nfib) / ns];
		struct plan_pos q;
		if (spec_dir(a, g, th, (id - nfib) % ns, &q))
			return -1;
		*out = q;
		if (plan_classify(g, &q)) { /* hidden: its reciprocal (the pair swapped; isotropy keeps the azimuth) */
			struct plan_pos rq = plan_canon((struct plan_pos){ q.det_theta, fabs(th),
									  g->laser_phi_deg + q.det_phi - inc_phi(g, th) });
			if (!plan_classify(g, &rq))
				*out = rq;
		}
		return 0;
	}
	size_t i = id / a->cand_count, j = id % a->cand_count;
	const double golden = 180.0 * (3.0 - sqrt(5.0)); /* degrees */
	double cmax = cos(a->cand_max_theta_deg * DEG);
	double cz = 1.0 - (1.0 - cmax) * ((double)j + 0.5) / (double)a->cand_count;
	*out = plan_canon((struct plan_pos){ a->cand_inc[i], acos(cz) / DEG, plan_norm360(golden * (double)j) });
	return 0;
}

int plan_adaptive_seed_extra(const struct plan_spec *s, const struct bench_geom *g, struct plan_req **r, size_t *n,
			     struct acq_err *err)
{
	const struct plan_adaptive *a = s->adaptive;
	if (!a || !a->n_seed_spec)
		return 0;
	size_t add = a->n_seed_spec * s->n_incidence;
	struct plan_req *q = realloc(*r, (*n + add + s->reciprocal_pairs + 1) * sizeof *q);
	if (!q)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	*r = q;
	for (size_t i = 0; i < s->n_incidence; i++)
		for (size_t k = 0; k < a->n_seed_spec; k++) {
			double th = s->incidence[i];
			memset(&q[*n], 0, sizeof q[*n]);
			q[*n].req = (struct plan_pos){ th, fabs(th) + a->seed_spec_deg[k], inc_phi(g, th) + 180.0 };
			q[*n].req.det_phi = plan_norm360(q[*n].req.det_phi);
			(*n)++;
		}
	return 0;
}

int plan_make_fixed(const struct plan_spec *s, const struct bench_geom *g, const struct plan_pos *pts, size_t n,
		    const struct plan_pos *start, struct plan_result **out, struct acq_err *err)
{
	*out = NULL;
	struct plan_result *R = calloc(1, sizeof *R);
	if (!R || !(R->req = calloc(n ? n : 1, sizeof *R->req)) || !(R->steps = calloc(n ? n : 1, sizeof *R->steps)) ||
	    !(R->wps = calloc((n ? n : 1) * PLAN_MAX_WP, sizeof *R->wps))) {
		plan_result_free(R);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	double dwell = (double)s->averages * (s->integ_ms / 1000.0 + g->readout_s), clock = 0;
	struct plan_pos cur = start ? *start : (n ? pts[0] : (struct plan_pos){ 0, 0, 0 });
	for (size_t i = 0; i < n; i++) {
		struct plan_req *q = &R->req[i];
		struct plan_step *st = &R->steps[i];
		q->req = q->pos = pts[i];
		q->status = PLAN_KEPT;
		q->psi_deg = plan_psi_deg(g, &pts[i]);
		st->req = i;
		st->pos = pts[i];
		st->first_wp = R->n_wps;
		if (i > 0 || start) {
			size_t nw = 0;
			double mv = plan_move(g, &cur, &st->pos, &R->wps[R->n_wps], &nw);
			if (mv < 0) {
				plan_result_free(R);
				return acq_errf(err, ACQ_E_RANGE, "plan '%s': no safe move to point %zu (%g, %g, %g)", s->name, i,
						pts[i].laser_theta, pts[i].det_theta, pts[i].det_phi);
			}
			for (size_t k = 0; k < nw; k++)
				st->move_s += R->wps[R->n_wps + k].duration_s;
			st->settle_s = mv - st->move_s;
			st->n_wp = nw;
			st->detour = nw > 1;
			R->n_detours += st->detour;
			R->n_wps += nw;
		}
		st->t_start_s = clock;
		st->dwell_s = dwell;
		clock += st->move_s + st->settle_s + dwell;
		R->motion_s += st->move_s + st->settle_s;
		R->dwell_s += dwell;
		cur = st->pos;
	}
	R->n_req = R->n_steps = R->n_kept = n;
	R->duration_s = clock;
	R->point_dwell_s = dwell;
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	plan_time_apply(s, g, &tm, R);
	*out = R;
	return 0;
}

int plan_result_append(struct plan_result *r, const struct plan_result *b, struct acq_err *err)
{
	size_t nr = r->n_req + b->n_req, ns = r->n_steps + b->n_steps, nw = r->n_wps + b->n_wps;
	struct plan_req *q = realloc(r->req, (nr ? nr : 1) * sizeof *q);
	if (q)
		r->req = q;
	struct plan_step *st = q ? realloc(r->steps, (ns ? ns : 1) * sizeof *st) : NULL;
	if (st)
		r->steps = st;
	struct plan_wp *w = st ? realloc(r->wps, (nw ? nw : 1) * sizeof *w) : NULL;
	if (!w)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	r->wps = w;
	memcpy(r->req + r->n_req, b->req, b->n_req * sizeof *b->req);
	memcpy(r->wps + r->n_wps, b->wps, b->n_wps * sizeof *b->wps);
	double t0 = r->duration_s, p0 = r->predicted_s;
	for (size_t i = 0; i < b->n_steps; i++) {
		struct plan_step s = b->steps[i];
		s.req += r->n_req;
		s.first_wp += r->n_wps;
		s.t_start_s += t0;
		s.predicted_start_s += p0;
		r->steps[r->n_steps + i] = s;
	}
	r->n_req = nr;
	r->n_steps = ns;
	r->n_wps = nw;
	r->n_kept += b->n_kept;
	r->n_moved += b->n_moved;
	r->n_dropped += b->n_dropped;
	r->n_duplicate += b->n_duplicate;
	r->duration_s += b->duration_s;
	r->dwell_s += b->dwell_s;
	r->motion_s += b->motion_s;
	r->predicted_s += b->predicted_s;
	r->darks_s += b->darks_s;
	r->n_detours += b->n_detours;
	for (int k = 0; k < 3; k++)
		r->travel_deg[k] += b->travel_deg[k];
	return 0;
}

/* The same configuration (same incidence, same observation direction to ~1e-6). */
static bool same_config(const struct plan_pos *a, const struct plan_pos *b)
{
	if (fabs(a->laser_theta - b->laser_theta) > 1e-6)
		return false;
	struct plan_pos ca = plan_canon(*a), cb = plan_canon(*b);
	double va[3], vb[3];
	plan_dir_of(ca.det_theta, ca.det_phi, va);
	plan_dir_of(cb.det_theta, cb.det_phi, vb);
	return fabs(va[0] - vb[0]) < 1e-6 && fabs(va[1] - vb[1]) < 1e-6 && fabs(va[2] - vb[2]) < 1e-6;
}

/* Bench seconds to measure q from the arms at from through the safe move of mv seconds (segments segs), as the
 * executor spends them (plan_time.c): a two-step sweep without reference whose second step is q. */
static double point_cost(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
			 const struct plan_pos *from, const struct plan_pos *q, double mv, double segs)
{
	struct plan_step st[2] = { { .pos = *from }, { .pos = *q, .move_s = segs, .settle_s = mv - segs } };
	struct plan_result r = { .steps = st, .n_steps = 2 };
	struct plan_timing tt = *t;
	tt.reference = false;
	tt.have_start = false;
	plan_time_apply(s, g, &tt, &r);
	return st[1].predicted_s;
}

int plan_adaptive_candidates(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
			     const struct plan_pos *from, const struct plan_pos *done, size_t n_done,
			     struct plan_cand **out, size_t *n, struct acq_err *err)
{
	const struct plan_adaptive *a = s->adaptive;
	*out = NULL;
	*n = 0;
	if (!a)
		return acq_errf(err, ACQ_E_INVAL, "plan '%s' is not adaptive", s->name);
	size_t nfib = a->n_cand_inc * a->cand_count, nall = nfib + a->n_cand_inc * spec_count(a);
	struct plan_cand *c = malloc((nall + 1) * sizeof *c);
	if (!c)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	size_t k = 0;
	struct plan_wp w[PLAN_MAX_WP];
	struct plan_timing tc = *t; /* the executor's dark cache as the measured points left it, the arms' point once */
	plan_timing_continue(&tc, done, n_done, sizeof *done);
	double since = tc.cont_since_clear; /* the points at the arms' incidence since the cache was cleared */
	if (tc.cont && tc.cont_since_clear > 0)
		tc.cont_since_clear--; /* point_cost's first step is the arms' point, counted again */
	for (size_t id = 0; id < nall; id++) {
		struct plan_pos q;
		if (plan_adaptive_cand_pos(s, g, id, &q) || plan_classify(g, &q))
			continue;
		bool seen = false;
		for (size_t d = 0; d < n_done && !seen; d++)
			seen = same_config(&q, &done[d]);
		if (seen)
			continue;
		double reps[MAX_REPS], best = -1, best_segs = 0;
		int nr = plan_phi_reps(g, q.det_phi, reps);
		struct plan_pos bq = q;
		for (int r = 0; r < nr; r++) {
			struct plan_pos p = q;
			p.det_phi = reps[r];
			if (best >= 0 && plan_straight_s(g, from, &p) >= best)
				continue;
			size_t nw = 0;
			double mv = plan_move(g, from, &p, w, &nw);
			if (mv < 0 || (best >= 0 && mv >= best))
				continue;
			best = mv;
			best_segs = 0;
			for (size_t x = 0; x < nw; x++)
				best_segs += w[x].duration_s;
			bq = p;
		}
		if (best < 0)
			continue; /* no safe move reaches it from here */
		c[k].id = id;
		c[k].pos = bq;
		c[k].cost_s = point_cost(s, g, &tc, from, &bq, best, best_segs);
		/* the same point without a move: from its own incidence, then from another one (its darks) */
		struct plan_pos other = bq;
		other.laser_theta += 1;
		c[k].base_s = point_cost(s, g, &tc, &bq, &bq, 0, 0);
		c[k].open_s = fmax(point_cost(s, g, &tc, &other, &bq, 0, 0) - c[k].base_s, 0);
		struct plan_point_cost pc;
		plan_time_point(s, g, t, bq.laser_theta, 1, &pc);
		c[k].point_s = pc.point_s;
		c[k].dark_s = pc.dark_s;
		c[k].rungs = pc.rungs;
		c[k].since = tc.cont && fabs(bq.laser_theta - tc.cont_laser) <= 1e-6 ? since : 0;
		c[k].band_cos = cos(fabs(bq.det_theta) * M_PI / 180);
		k++;
	}
	*out = c;
	*n = k;
	return 0;
}

void plan_adaptive_worst(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
			 const struct plan_result *seed, double *worst_s, size_t *worst_points)
{
	const struct plan_adaptive *a = s->adaptive;
	*worst_s = seed->predicted_s;
	*worst_points = seed->n_steps;
	if (!a || seed->n_steps == 0)
		return;
	double lo = INFINITY, hi = 0;
	struct plan_pos *done = malloc(seed->n_steps * sizeof *done);
	struct plan_cand *c = NULL;
	size_t nc = 0;
	if (done) {
		for (size_t i = 0; i < seed->n_steps; i++)
			done[i] = seed->steps[i].pos;
		if (plan_adaptive_candidates(s, g, t, &seed->steps[seed->n_steps - 1].pos, done, seed->n_steps, &c, &nc,
					     NULL))
			nc = 0;
	}
	for (size_t i = 0; i < nc; i++) {
		lo = fmin(lo, c[i].cost_s);
		hi = fmax(hi, c[i].cost_s);
	}
	free(c);
	free(done);
	size_t left_pts = a->budget_points > seed->n_steps ? a->budget_points - seed->n_steps : 0;
	if (nc < left_pts)
		left_pts = nc;
	if (a->budget_s > 0)
		*worst_s = fmax(a->budget_s, seed->predicted_s);
	else
		*worst_s = seed->predicted_s + (double)left_pts * (nc ? hi : 0);
	if (a->budget_points > 0)
		*worst_points = seed->n_steps + left_pts;
	else if (nc && lo > 0)
		*worst_points = seed->n_steps +
				(size_t)fmin((double)nc, floor(fmax(0, a->budget_s - seed->predicted_s) / lo));
}

/* The band nodes of the route spec: rho = cos ratio of the batch's detector zeniths, 1 to ROUTE_BAND_MAX (plan_time's
 * band ignores cos θ ≤ 0.01) in ROUTE_BAND_NODES geometric steps (select interpolates linearly in ln rho). */
#define ROUTE_BAND_NODES 20
#define ROUTE_BAND_MAX 100.0

void plan_adaptive_route_spec(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
			      const struct plan_pos *from, char *buf, size_t len)
{
	const struct bench_axis *ax[3] = { &g->laser_theta, &g->detector_theta, &g->detector_phi };
	size_t n = (size_t)snprintf(buf, len, "%.9g,%.9g,%.9g", from->laser_theta, from->det_theta, from->det_phi);
	for (int k = 0; k < 3 && n < len; k++)
		n += (size_t)snprintf(buf + n, len - n, ",%.9g,%.9g,%.9g", ax[k]->speed_dps, ax[k]->accel_dps2,
				      ax[k]->settle_s);
	if (n < len)
		n += (size_t)snprintf(buf + n, len - n, ",%.9g", PLAN_MOVE_POLLS * t->axis_poll_s + t->extra_settle_s);
	/* the band's nodes, priced at the arms' incidence (the band itself is the same at every incidence; a prior's
	 * per-incidence figures do not depend on it, and then one node says so) */
	struct plan_point_cost lo, hi;
	plan_time_point(s, g, t, from->laser_theta, 1, &lo);
	plan_time_point(s, g, t, from->laser_theta, ROUTE_BAND_MAX, &hi);
	bool flat = hi.point_s == lo.point_s && hi.dark_s == lo.dark_s && hi.rungs == lo.rungs;
	for (int k = 0; k < (flat ? 1 : ROUTE_BAND_NODES) && n < len; k++) {
		double rho = pow(ROUTE_BAND_MAX, (double)k / (ROUTE_BAND_NODES - 1));
		struct plan_point_cost pc;
		plan_time_point(s, g, t, from->laser_theta, rho, &pc);
		n += (size_t)snprintf(buf + n, len - n, ",%.9g,%.9g,%.9g,%.9g", rho, pc.point_s, pc.dark_s, pc.rungs);
	}
}

void plan_timing_continue(struct plan_timing *t, const struct plan_pos *done, size_t n, size_t stride)
{
	t->cont = n > 0;
	t->cont_since_clear = 0;
	if (!n)
		return;
	const char *b = (const char *)done;
	double last = ((const struct plan_pos *)(const void *)(b + (n - 1) * stride))->laser_theta;
	t->cont_laser = last;
	for (size_t i = n; i-- > 0;) {
		if (fabs(((const struct plan_pos *)(const void *)(b + i * stride))->laser_theta - last) > 1e-6)
			break;
		t->cont_since_clear++;
	}
	if (t->dark_every > 0)
		t->cont_since_clear = (double)(n % (size_t)t->dark_every);
	else if (t->dark_every < 0) /* darks kept across incidences: none cleared since the sweep began */
		t->cont_since_clear = (double)n;
}
