/* Unit tests for the planner's adaptive part (daemon/plan/plan_adaptive.c, plan_make_points): the kind: adaptive
 * YAML and its located errors, the target as select takes it, the candidates (visible, within the limits,
 * reachable, never a measured configuration, costed at least their move and exposures), batches ordered from
 * the arms' position, a stored order replayed, a batch appended to a plan, and a batch continuing the sweep's dark
 * cache (base_s, open_s of the candidates), and select's price of a batch's exposures (the candidates' point_s,
 * dark_s, rungs, since, band_cos and the route's band nodes) against the planner's. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "config/bench.h"
#include "daemon/plan/plan.h"
#include "recon/select_int.h"

static const char *const ADAPTIVE = "name: ad\n"
				    "kind: adaptive\n"
				    "seed:\n"
				    "  incidence: {theta_deg: [8, 40]}\n"
				    "  observation: {fibonacci: {count: 10, max_theta_deg: 80}}\n"
				    "target: {dhr_sigma: {incidence_deg: [8, 30, 60], le: 0.002}}\n"
				    "budget: {seconds: 600, points: 60}\n"
				    "batch: 8\n"
				    "candidates: {incidence_deg: {from: 0, to: 60, step: 10}, per_incidence: 40}\n"
				    "integration: {mode: fixed, ms: 20}\n"
				    "averages: 2\n";

static struct plan_spec *load_ok(const char *text)
{
	struct plan_spec *s = NULL;
	struct acq_err err = { 0 };
	int rc = plan_load_string("t.yaml", text, &s, &err);
	if (rc)
		fprintf(stderr, "unexpected error: %s\n", err.msg);
	assert_int_equal(rc, 0);
	return s;
}

static void load_bad(const char *text, const char *want)
{
	struct plan_spec *s = NULL;
	struct acq_err err = { 0 };
	assert_int_not_equal(plan_load_string("t.yaml", text, &s, &err), 0);
	assert_null(s);
	if (!strstr(err.msg, want))
		fprintf(stderr, "message '%s' lacks '%s'\n", err.msg, want);
	assert_non_null(strstr(err.msg, want));
	assert_non_null(strstr(err.msg, "t.yaml:"));
}

/* An adaptive plan with target (YAML) and extra lines after its batch gives select's target spec want. */
static void target_spec_is(const char *target, const char *extra, const char *want)
{
	char text[512], spec[128];
	snprintf(text, sizeof text, "kind: adaptive\nseed: {incidence: {theta_deg: 30}, observation: {theta_deg: "
		 "[20, 50], phi_deg: [0, 180]}}\ntarget: %s\nbudget: {points: 20}\nbatch: 4\n%s", target, extra);
	struct plan_spec *s = load_ok(text);
	plan_adaptive_target_spec(s->adaptive, spec, sizeof spec);
	assert_string_equal(spec, want);
	plan_spec_free(s);
}

static void test_parse(void **state)
{
	(void)state;
	struct plan_spec *s = load_ok(ADAPTIVE);
	assert_non_null(s->adaptive);
	assert_string_equal(s->name, "ad");
	assert_int_equal(s->n_incidence, 2);
	assert_int_equal(s->fib_count, 10);
	assert_int_equal(s->integ_mode, PLAN_INTEG_FIXED);
	assert_true(s->integ_ms == 20);
	assert_int_equal(s->averages, 2);
	const struct plan_adaptive *a = s->adaptive;
	assert_int_equal(a->target, PLAN_TARGET_DHR_SIGMA);
	assert_int_equal(a->n_target_inc, 3);
	assert_true(a->le == 0.002 && a->budget_s == 600 && a->budget_points == 60 && a->batch == 8);
	assert_int_equal(a->n_cand_inc, 7);
	assert_int_equal(a->cand_count, 40);
	char spec[128];
	plan_adaptive_target_spec(a, spec, sizeof spec);
	assert_string_equal(spec, "dhr:8,30,60:le=0.002");
	plan_spec_free(s);

	s = load_ok("kind: adaptive\nseed: {incidence: {theta_deg: 30}, observation: {theta_deg: [20, 50], phi_deg: [0, 180]}}\n"
		    "target: {lnf_sigma: {le: 0.05}}\nbudget: {points: 20}\nbatch: 4\n");
	plan_adaptive_target_spec(s->adaptive, spec, sizeof spec);
	assert_string_equal(spec, "lnf:le=0.05");
	assert_int_equal(s->adaptive->n_cand_inc, 15); /* the default candidates: 0..70 every 5 */
	assert_true(s->adaptive->budget_s == 0);
	plan_spec_free(s);
	/* lnf_sigma's weight (select's lnf, lnf:rad, lnf:mix, lnf:bright), alone and in a combined target; projected is
	 * the default; and the rgb target */
	static const char *const targets[][2] = {
		{ "{lnf_sigma: {le: 0.05, weight: rad}}", "lnf:rad:le=0.05" },
		{ "{dhr_sigma: {incidence_deg: [8, 30], le: 0.002}, lnf_sigma: {le: 0.05, weight: rad}}",
		  "dhr:8,30:le=0.002+lnf:rad:le=0.05" },
		{ "{dhr_sigma: {incidence_deg: [8], le: 0.002}, lnf_sigma: {le: 0.05, weight: projected}}",
		  "dhr:8:le=0.002+lnf:le=0.05" },
		{ "{dhr_sigma: {incidence_deg: [8], le: 0.002}, lnf_sigma: {le: 0.05, weight: mix}}",
		  "dhr:8:le=0.002+lnf:mix:le=0.05" },
		{ "{lnf_sigma: {le: 0.05, weight: bright}}", "lnf:bright:le=0.05" },
		{ "{rgb_sigma: {le: 0.004}}", "rgb:le=0.004" },
	};
	for (size_t k = 0; k < sizeof targets / sizeof targets[0]; k++)
		target_spec_is(targets[k][0], "", targets[k][1]);
	/* the lobe gate (candidates.lobe_above_deg): select's :lobe_above= suffix, after any target */
	static const char *const gated[][2] = {
		{ "{dhr_sigma: {incidence_deg: [8, 30], le: 0.002}, lnf_sigma: {le: 0.05, weight: bright}}",
		  "dhr:8,30:le=0.002+lnf:bright:le=0.05:lobe_above=70" },
		{ "{dhr_sigma: {incidence_deg: [8], le: 0.002}}", "dhr:8:le=0.002:lobe_above=70" },
		{ "{lnf_sigma: {le: 0.05}}", "lnf:le=0.05:lobe_above=70" },
	};
	for (size_t k = 0; k < sizeof gated / sizeof gated[0]; k++)
		target_spec_is(gated[k][0], "candidates: {incidence_deg: {from: 0, to: 80, step: 5}, lobe_above_deg: 70}\n",
			       gated[k][1]);
	/* the other kinds, named */
	s = load_ok("kind: grid\nincidence: {theta_deg: 30}\nobservation: {theta_deg: 40, phi_deg: 0}\n");
	assert_null(s->adaptive);
	plan_spec_free(s);
}

static void test_errors(void **state)
{
	(void)state;
	/* after "kind: adaptive" and a seed: the rest of the plan, and what the refusal must say */
	static const char *const bad[][2] = {
		{ "budget: {points: 20}\nbatch: 4\n", "missing key 'target'" },
		{ "target: {lnf_sigma: {le: 1}}\nbatch: 4\n", "missing key 'budget'" },
		{ "target: {lnf_sigma: {le: 1}}\nbudget: {}\nbatch: 4\n", "give 'seconds'" },
		{ "target: {lnf_sigma: {le: 1}, dhr_sigma: {incidence_deg: 8, le: 1}, rgb_sigma: {le: 1}}\n"
		  "budget: {points: 9}\nbatch: 4\n",
		  "exactly one of" },
		{ "target: {lnf_sigma: {le: 1, weight: radx}}\n"
		  "budget: {points: 9}\nbatch: 4\n",
		  "target.lnf_sigma.weight: 'projected'" },
		{ "target: {lnf_sigma: {le: 1, weight: rad}, dhr_sigma: {incidence_deg: 8, le: 1, weight: rad}}\n"
		  "budget: {points: 9}\nbatch: 4\n",
		  "unknown key 'weight' in target.dhr_sigma" },
		{ "target: {lnf_sigma: {}, dhr_sigma: {incidence_deg: 8, le: 1}}\n"
		  "budget: {points: 9}\nbatch: 4\n",
		  "le" },
		{ "target: {lnf_sigma: {le: 1}}\n"
		  "budget: {points: 9}\nbatch: 4\ncandidates: {specular: {per_ring: 0}}\n",
		  "per_ring" },
		{ "target: {lnf_sigma: {le: 1}}\n"
		  "budget: {points: 9}\nbatch: 4\ncandidates: {specular: {rings: [2]}}\n",
		  "unknown key 'rings' in candidates.specular" },
		{ "target: {lnf_sigma: {le: 1}}\n"
		  "budget: {points: 9}\nbatch: 4\ncandidates: {lobe_above_deg: 90}\n",
		  "lobe_above_deg" },
		{ "target: {lnf_sigma: {le: 1}}\n"
		  "budget: {points: 9}\nbatch: 4\nseed_specular_deg: [0, 60]\n",
		  "seed_specular_deg" },
		{ "target: {rgb_sigma: {le: 1}, lnf_sigma: {le: 1}}\n"
		  "budget: {points: 9}\nbatch: 4\n",
		  "exactly one of" },
		{ "target: {rgb_sigma: {incidence_deg: 8, le: 1}}\n"
		  "budget: {points: 9}\nbatch: 4\n",
		  "unknown key 'incidence_deg' in target.rgb_sigma" },
		{ "target: {lnf_sigma: {le: 1}}\nbudget: {points: 9}\n", "batch" },
		{ "target: {lnf_sigma: {le: 1}}\nbudget: {points: 9}\nbatch: 4\nbogus: 1\n", "bogus" },
	};
	const char *seed = "seed: {incidence: {theta_deg: 30}, observation: {fibonacci: {count: 5}}}\n";
	char buf[1024];
	for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
		snprintf(buf, sizeof buf, "kind: adaptive\n%s%s", seed, bad[k][0]);
		load_bad(buf, bad[k][1]);
	}
	load_bad("kind: adaptive\nseed: {incidence: {theta_deg: 30}, observation: {fibonacci: {count: 5}}, averages: 2}\n"
		 "target: {lnf_sigma: {le: 1}}\nbudget: {points: 9}\nbatch: 4\n", "belongs at the top");
	load_bad("kind: adaptive\nseed: {kind: adaptive}\ntarget: {lnf_sigma: {le: 1}}\nbudget: {points: 9}\nbatch: 4\n",
		 "cannot seed another");
	load_bad("kind: fibonacci\nincidence: {theta_deg: 30}\nobservation: {theta_deg: 40, phi_deg: 0}\n",
		 "kind fibonacci needs");
	load_bad("kind: spiral\nincidence: {theta_deg: 30}\nobservation: {theta_deg: 40, phi_deg: 0}\n", "kind");
}

static bool same_config(const struct plan_pos *a, const struct plan_pos *b)
{
	double va[3] = { sin(a->det_theta * M_PI / 180) * cos(a->det_phi * M_PI / 180),
			 sin(a->det_theta * M_PI / 180) * sin(a->det_phi * M_PI / 180), cos(a->det_theta * M_PI / 180) };
	double vb[3] = { sin(b->det_theta * M_PI / 180) * cos(b->det_phi * M_PI / 180),
			 sin(b->det_theta * M_PI / 180) * sin(b->det_phi * M_PI / 180), cos(b->det_theta * M_PI / 180) };
	return fabs(a->laser_theta - b->laser_theta) < 1e-6 && fabs(va[0] - vb[0]) < 1e-6 && fabs(va[1] - vb[1]) < 1e-6 &&
	       fabs(va[2] - vb[2]) < 1e-6;
}

static void test_candidates(void **state)
{
	(void)state;
	struct bench_geom g;
	bench_defaults(&g);
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	struct plan_spec *s = load_ok(ADAPTIVE);
	struct plan_result *seed = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(plan_make(s, &g, &seed, &err), 0);
	assert_true(seed->n_steps > 0);
	struct plan_pos *done = calloc(seed->n_steps, sizeof *done);
	for (size_t i = 0; i < seed->n_steps; i++)
		done[i] = seed->steps[i].pos;
	struct plan_pos from = seed->steps[seed->n_steps - 1].pos;
	struct plan_cand *c = NULL;
	size_t n = 0;
	assert_int_equal(plan_adaptive_candidates(s, &g, &tm, &from, done, seed->n_steps, &c, &n, &err), 0);
	const struct plan_adaptive *ad = s->adaptive;
	size_t all = ad->n_cand_inc * (ad->cand_count + 1 + ad->n_spec_rings * ad->spec_per_ring);
	assert_true(ad->cand_specular); /* the default */
	assert_true(n > all / 2 && n <= all);
	double dwell = s->averages * (s->integ_ms / 1000 + g.readout_s);
	size_t blind_total = 0;
	for (size_t i = 0; i < all; i++) {
		struct plan_pos q;
		assert_int_equal(plan_adaptive_cand_pos(s, &g, i, &q), 0);
		blind_total += plan_blind(&g, &q) != 0;
	}
	assert_true(blind_total > 0); /* the set reaches into the blind zones: they must be left out */
	assert_int_equal(plan_adaptive_cand_pos(s, &g, all, &(struct plan_pos){ 0 }), -1);
	for (size_t i = 0; i < n; i++) {
		assert_int_equal(plan_blind(&g, &c[i].pos), 0);
		struct plan_pos q;
		assert_int_equal(plan_adaptive_cand_pos(s, &g, c[i].id, &q), 0);
		assert_true(fabs(q.laser_theta - c[i].pos.laser_theta) < 1e-9);
		for (size_t d = 0; d < seed->n_steps; d++)
			assert_false(same_config(&q, &done[d]));
		struct plan_wp w[PLAN_MAX_WP];
		size_t nw;
		double mv = plan_move(&g, &from, &c[i].pos, w, &nw);
		assert_true(mv >= 0);
		/* the cost: at least the move found and the dwell, and the move is the fastest over the azimuth's turns */
		assert_true(c[i].cost_s >= mv + dwell - 1e-9);
		assert_true(c[i].cost_s >= plan_straight_s(&g, &from, &c[i].pos) + dwell - 1e-9);
	}
	/* measuring a candidate removes it */
	struct plan_pos *done2 = realloc(done, (seed->n_steps + 1) * sizeof *done2);
	done = done2;
	done[seed->n_steps] = c[0].pos;
	struct plan_cand *c2 = NULL;
	size_t n2 = 0;
	assert_int_equal(plan_adaptive_candidates(s, &g, &tm, &from, done, seed->n_steps + 1, &c2, &n2, &err), 0);
	assert_int_equal(n2, n - 1);
	for (size_t i = 0; i < n2; i++)
		assert_true(c2[i].id != c[0].id);
	/* the dry run's worst case: the budget's */
	double ws;
	size_t wp;
	plan_adaptive_worst(s, &g, &tm, seed, &ws, &wp);
	assert_true(ws == 600);
	assert_int_equal(wp, 60);
	free(c);
	free(c2);
	free(done);
	plan_result_free(seed);
	plan_spec_free(s);
}

/* Angle (degrees) between the observation direction of bench position p and the mirror direction of its
 * incidence: invariant under reciprocity (swapping the pair) and rotation about the normal. */
static double off_specular_deg(const struct bench_geom *g, const struct plan_pos *p)
{
	double pi = g->laser_phi_deg + (p->laser_theta < 0 ? 180 : 0), ti = fabs(p->laser_theta), d = M_PI / 180;
	double m[3] = { sin(ti * d) * cos((pi + 180) * d), sin(ti * d) * sin((pi + 180) * d), cos(ti * d) };
	double v[3] = { sin(p->det_theta * d) * cos(p->det_phi * d), sin(p->det_theta * d) * sin(p->det_phi * d),
			cos(p->det_theta * d) };
	double c = fmin(1, fmax(-1, m[0] * v[0] + m[1] * v[1] + m[2] * v[2]));
	return acos(c) / d;
}

/* The mirror-direction candidates: per candidate incidence the mirror direction itself whenever it is usable and
 * reachable, rings at their stated angular radius (a hidden ring direction offered as its reciprocal when that is
 * usable, never when hidden too), nothing blind, out of the limits or unreachable; and the seed's specular plane. */
static void test_specular(void **state)
{
	(void)state;
	struct bench_geom g;
	bench_defaults(&g);
	g.detector_theta.max_deg = 56; /* ring directions beyond it are hidden; their reciprocals are not */
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	struct plan_spec *s = load_ok("kind: adaptive\nseed: {incidence: {theta_deg: [8, 40]}, observation: "
				      "{fibonacci: {count: 10, max_theta_deg: 50}}}\n"
				      "target: {dhr_sigma: {incidence_deg: [8], le: 0.002}}\nbudget: {points: 60}\nbatch: 8\n"
				      "candidates: {incidence_deg: {from: 0, to: 55, step: 5}, per_incidence: 40, "
				      "max_theta_deg: 80, specular: {rings_deg: [2, 4, 7], per_ring: 6}}\n"
				      "seed_specular_deg: [-4, 0, 4]\nintegration: {mode: fixed, ms: 20}\n");
	const struct plan_adaptive *a = s->adaptive;
	assert_true(a->cand_specular && a->n_spec_rings == 3 && a->spec_per_ring == 6 && a->n_seed_spec == 3);
	size_t nfib = a->n_cand_inc * a->cand_count, ns = 1 + 3 * 6, nall = nfib + a->n_cand_inc * ns;
	struct plan_result *seed = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(plan_make(s, &g, &seed, &err), 0);
	/* the seed: the mirror direction and ±4° in the specular plane at each incidence, where usable */
	size_t seed_spec = 0;
	for (int i = 0; i < 2; i++)
		for (int k = -1; k <= 1; k++) {
			double th = i ? 40 : 8;
			struct plan_pos q = { th, th + 4 * k, g.laser_phi_deg + 180 };
			bool found = false;
			for (size_t x = 0; x < seed->n_steps; x++)
				found |= same_config(&q, &seed->steps[x].pos);
			if (plan_blind(&g, &q) == 0) {
				assert_true(found);
				seed_spec++;
			}
		}
	assert_true(seed_spec >= 4);
	struct plan_pos from = seed->steps[seed->n_steps - 1].pos;
	struct plan_cand *c = NULL;
	size_t n = 0, mirrors = 0, recip = 0, hidden_both = 0;
	assert_int_equal(plan_adaptive_candidates(s, &g, &tm, &from, NULL, 0, &c, &n, &err), 0);
	assert_int_equal(plan_adaptive_cand_pos(s, &g, nall, &(struct plan_pos){ 0 }), -1);
	for (size_t id = nfib; id < nall; id++) {
		size_t i = (id - nfib) / ns, r = (id - nfib) % ns;
		double th = a->cand_inc[i], want = r == 0 ? 0 : a->spec_rings_deg[(r - 1) / 6];
		struct plan_pos q;
		if (plan_adaptive_cand_pos(s, &g, id, &q))
			continue; /* beyond the cap */
		assert_true(fabs(off_specular_deg(&g, &q) - want) < 1e-6);
		bool offered = false;
		for (size_t k = 0; k < n; k++)
			if (c[k].id == id) {
				offered = true;
				assert_true(same_config(&q, &c[k].pos));
			}
		struct plan_pos direct = q;
		if (fabs(q.laser_theta - th) > 1e-9) { /* the reciprocal: usable, and the direct position is hidden */
			recip++;
			assert_int_equal(plan_blind(&g, &q), 0);
			direct = (struct plan_pos){ th, q.laser_theta, 0 };
			assert_true(q.det_theta == fabs(th) || fabs(q.det_theta - fabs(th)) < 1e-9);
		} else if (plan_blind(&g, &q)) {
			hidden_both++;
			assert_false(offered);
			continue;
		}
		(void)direct;
		struct plan_wp w[PLAN_MAX_WP];
		size_t nw;
		bool reach = false;
		for (double k = -360; k <= 360; k += 360) {
			struct plan_pos p = q;
			p.det_phi += k;
			if (p.det_phi >= g.detector_phi.min_deg && p.det_phi <= g.detector_phi.max_deg &&
			    plan_move(&g, &from, &p, w, &nw) >= 0)
				reach = true;
		}
		assert_true(offered == reach);
		if (r == 0 && offered)
			mirrors++;
	}
	printf("specular candidates: %zu incidences, %zu mirror directions offered, %zu reciprocals, %zu hidden both ways\n",
	       a->n_cand_inc, mirrors, recip, hidden_both);
	assert_true(mirrors >= a->n_cand_inc - 2); /* at 0° (and 5°) the mirror is the laser's own direction */
	assert_true(recip > 0);
	assert_true(hidden_both > 0);
	free(c);
	plan_result_free(seed);
	plan_spec_free(s);

	/* candidates.specular: false: the Fibonacci set only; the combined target's spec */
	s = load_ok("kind: adaptive\nseed: {incidence: {theta_deg: [8]}, observation: {fibonacci: {count: 10}}}\n"
		    "target: {dhr_sigma: {incidence_deg: [8, 30], le: 0.002}, lnf_sigma: {le: 0.05}}\nbudget: {points: 60}\n"
		    "batch: 8\ncandidates: {specular: false, per_incidence: 20}\n");
	assert_false(s->adaptive->cand_specular);
	assert_int_equal(plan_adaptive_cand_pos(s, &g, s->adaptive->n_cand_inc * 20, &(struct plan_pos){ 0 }), -1);
	char spec[128];
	plan_adaptive_target_spec(s->adaptive, spec, sizeof spec);
	assert_string_equal(spec, "dhr:8,30:le=0.002+lnf:le=0.05");
	assert_true(plan_adaptive_threshold(s->adaptive) == 1.0);
	plan_spec_free(s);
}

/* A batch's picks within what is left of the budget: in select's order, a dearer pick skipped for a cheaper later one
 * (before, the first pick that did not fit ended the batch, and a first pick too dear stopped the sweep). */
static void test_fit_picks(void **state)
{
	(void)state;
	const double cost[6] = { 10, 3, 8, 2, 1, 4 };
	size_t keep[6];
	assert_int_equal(plan_adaptive_fit_picks(cost, 6, 6, 6, keep), 3); /* 10 skipped, 3, 8 skipped, 2, 1 */
	assert_true(keep[0] == 1 && keep[1] == 3 && keep[2] == 4);
	assert_int_equal(plan_adaptive_fit_picks(cost, 6, 6, 2, keep), 2); /* the points left */
	assert_true(keep[0] == 1 && keep[1] == 3);
	assert_int_equal(plan_adaptive_fit_picks(cost, 6, INFINITY, 6, keep), 6); /* no limit: all, in order */
	for (size_t i = 0; i < 6; i++)
		assert_int_equal(keep[i], i);
	assert_int_equal(plan_adaptive_fit_picks(cost, 6, 0.5, 6, keep), 0); /* none fits */
	assert_int_equal(plan_adaptive_fit_picks(cost, 0, 100, 6, keep), 0);
}

static void test_batch_order(void **state)
{
	(void)state;
	struct bench_geom g;
	bench_defaults(&g);
	struct plan_spec *s = load_ok(ADAPTIVE);
	struct acq_err err = { 0 };
	struct plan_pos pts[6] = { { 40, 30, 200 }, { 0, 45, 90 }, { 40, 60, 10 }, { 0, 20, 300 }, { 40, 70, 150 },
				   { 0, 1, 0 } /* blind at normal incidence: dropped */ };
	struct plan_pos start = { 40, 60, 20 };
	struct plan_result *r = NULL;
	assert_int_equal(plan_make_points(s, &g, pts, 6, &start, &r, &err), 0);
	assert_int_equal(r->n_steps, 5);
	assert_int_equal(r->n_dropped, 1);
	assert_int_equal(r->req[5].status, PLAN_DROPPED);
	/* from the arms at θL 40: that incidence first (the laser is the slow arm), its first step moves from start */
	assert_true(r->steps[0].pos.laser_theta == 40);
	assert_true(r->steps[0].move_s > 0);
	double from_start = plan_straight_s(&g, &start, &r->steps[0].pos);
	assert_true(r->steps[0].move_s + r->steps[0].settle_s >= from_start - 1e-9);
	/* the stored order replayed as it is */
	struct plan_pos order[5];
	for (size_t i = 0; i < 5; i++)
		order[i] = r->steps[4 - i].pos;
	struct plan_result *f = NULL;
	assert_int_equal(plan_make_fixed(s, &g, order, 5, &start, &f, &err), 0);
	assert_int_equal(f->n_steps, 5);
	for (size_t i = 0; i < 5; i++)
		assert_memory_equal(&f->steps[i].pos, &order[i], sizeof order[i]);
	/* appended: indices and predicted times follow */
	struct plan_result *seed = NULL;
	assert_int_equal(plan_make(s, &g, &seed, &err), 0);
	size_t ns = seed->n_steps, nw = seed->n_wps, nr = seed->n_req;
	double ps = seed->predicted_s;
	assert_int_equal(plan_result_append(seed, f, &err), 0);
	assert_int_equal(seed->n_steps, ns + 5);
	assert_int_equal(seed->n_wps, nw + f->n_wps);
	for (size_t i = 0; i < 5; i++) {
		const struct plan_step *st = &seed->steps[ns + i];
		assert_memory_equal(&st->pos, &order[i], sizeof order[i]);
		assert_int_equal(st->req, nr + i);
		assert_int_equal(st->first_wp, nw + f->steps[i].first_wp);
		assert_true(fabs(st->predicted_start_s - (ps + f->steps[i].predicted_start_s)) < 1e-9);
	}
	assert_true(fabs(seed->predicted_s - (ps + f->predicted_s)) < 1e-9);
	plan_result_free(seed);
	plan_result_free(f);
	plan_result_free(r);
	plan_spec_free(s);
}

/* The default bench and executor timing of an adaptive batch (no reference: a batch continues the sweep). */
static void batch_setup(struct bench_geom *g, struct plan_timing *tm)
{
	bench_defaults(g);
	plan_timing_defaults(tm);
	tm->reference = false;
}

/* An adaptive batch continues the sweep's dark cache (executor_acq.c clears it only when the batch starts at another
 * incidence): a batch of fixed integration at the last point's incidence is predicted without a dark at its first
 * step, one at another incidence with it, and without the continuation (the old model) the first step always had
 * one. The candidates' base_s and open_s: cost_s is base_s (+ open_s at another incidence than the arms') plus the
 * move; open_s is one dark, 0 for nothing. */
static void test_continue_darks(void **state)
{
	(void)state;
	struct bench_geom g;
	struct plan_timing tm;
	batch_setup(&g, &tm);
	struct plan_spec *s = load_ok(ADAPTIVE);
	struct acq_err err = { 0 };
	struct plan_pos done[3] = { { 0, 30, 10 }, { 40, 30, 200 }, { 40, 60, 10 } }, same = { 40, 45, 100 },
			other = { 20, 45, 100 };
	double dark = tm.dark_averages * s->integ_ms / 1000 + g.readout_s + tm.exposure_overhead_s; /* one exposure */
	struct plan_result *r = NULL;
	for (int k = 0; k < 2; k++) {
		const struct plan_pos *p = k ? &other : &same;
		assert_int_equal(plan_make_points(s, &g, p, 1, &done[2], &r, &err), 0);
		plan_time_apply(s, &g, &tm, r);
		double fresh = r->darks_s;
		struct plan_timing tc = tm;
		plan_timing_continue(&tc, done, 3, sizeof *done);
		assert_true(tc.cont && tc.cont_laser == 40 && tc.cont_since_clear == 2);
		plan_time_apply(s, &g, &tc, r);
		printf("continue: batch at %s incidence: darks %.3f s (fresh cache %.3f s)\n", k ? "another" : "the same",
		       r->darks_s, fresh);
		assert_true(fabs(fresh - dark) < 1e-9);
		assert_true(fabs(r->darks_s - (k ? dark : 0)) < 1e-9);
		plan_result_free(r);
	}
	/* darks kept across incidences (sweep.dark_every -1): every point measured so far is since the last clearing */
	struct plan_timing tk = tm;
	tk.dark_every = -1;
	plan_timing_continue(&tk, done, 3, sizeof *done);
	assert_true(tk.cont && tk.cont_since_clear == 3);
	tk.dark_every = 2;
	plan_timing_continue(&tk, done, 3, sizeof *done);
	assert_true(tk.cont_since_clear == 1);
	plan_timing_continue(&tm, done, 0, sizeof *done);
	assert_false(tm.cont);
	/* the candidates from the arms at done[2]: cost = base (+ open at another incidence) + the move */
	struct plan_cand *c = NULL;
	size_t n = 0;
	assert_int_equal(plan_adaptive_candidates(s, &g, &tm, &done[2], done, 3, &c, &n, &err), 0);
	size_t nsame = 0, nother = 0;
	for (size_t i = 0; i < n; i++) {
		struct plan_wp w[PLAN_MAX_WP];
		size_t nw;
		double mv = plan_move(&g, &done[2], &c[i].pos, w, &nw), poll = mv > 0 ? PLAN_MOVE_POLLS * tm.axis_poll_s : 0;
		bool at = c[i].pos.laser_theta == 40;
		nsame += at;
		nother += !at;
		assert_true(c[i].base_s > 0 && fabs(c[i].open_s - dark) < 1e-9);
		assert_true(fabs(c[i].cost_s - (c[i].base_s + (at ? 0 : c[i].open_s) + mv + poll)) < 1e-6);
	}
	assert_true(nsame > 0 && nother > 0);
	free(c);
	plan_spec_free(s);
}

/* Select's price of a batch against the planner's (recon/select_route.c against plan_time.c): an auto-integration
 * batch of 12 candidates over three incidences (5 at the arms' incidence, whose dark cache holds 2 points' rungs)
 * with a spread of detector zeniths, each pick charged its increment as `brdf-recon select --route` does from the
 * candidates' point_s, dark_s, rungs, since, band_cos and the route spec's band nodes: the charged exposure seconds
 * are the planner's batch seconds without the motion to 1 % (the planner's first probe is at the estimate, not the
 * band's mean). The old price (base_s, open_s at a new incidence) charged ~3/4 of it (printed), as session 10
 * measured on whole runs. The charge of the same pick with a dark due (since 0 instead of the cache's count) or more
 * rungs is higher. */
static void test_route_price(void **state)
{
	(void)state;
	struct bench_geom g;
	struct plan_timing tm;
	batch_setup(&g, &tm);
	char yaml[2048];
	const char *fixed = strstr(ADAPTIVE, "integration:");
	snprintf(yaml, sizeof yaml, "%.*sintegration: {mode: auto, estimate_ms: 20}\naverages: 2\n", (int)(fixed - ADAPTIVE),
		 ADAPTIVE);
	struct plan_spec *s = load_ok(yaml);
	struct acq_err err = { 0 };
	struct plan_pos done[3] = { { 0, 30, 10 }, { 40, 30, 200 }, { 40, 60, 10 } };
	struct plan_cand *c = NULL;
	size_t n = 0;
	assert_int_equal(plan_adaptive_candidates(s, &g, &tm, &done[2], done, 3, &c, &n, &err), 0);
	/* the route spec as select parses it */
	char spec[PLAN_ROUTE_SPEC_LEN];
	plan_adaptive_route_spec(s, &g, &tm, &done[2], spec, sizeof spec);
	double v[13 + 4 * 64];
	size_t nv = 0;
	for (char *p = spec, *e; nv < sizeof v / sizeof *v; p = e + 1) {
		v[nv++] = strtod(p, &e);
		if (!*e)
			break;
	}
	assert_true(nv > 13 + 4 && (nv - 13) % 4 == 0);
	assert_true(v[13] == 1 && v[nv - 4] > v[13] && v[nv - 3] > v[14]); /* the band widens: dearer points */
	/* 12 picks: at the arms' incidence 40 (5), 0 (4), 20 (3), every 5th candidate there */
	const double inc[3] = { 40, 0, 20 };
	const size_t want[3] = { 5, 4, 3 };
	size_t pick[12], k = 0;
	for (int q = 0; q < 3; q++)
		for (size_t i = 0, m = 0, got = 0; i < n && got < want[q]; i++)
			if (c[i].pos.laser_theta == inc[q] && m++ % 5 == 0)
				pick[k++] = i, got++;
	assert_int_equal(k, 12);
	double *col = malloc(9 * n * sizeof *col);
	assert_non_null(col);
	for (size_t i = 0; i < n; i++) {
		col[3 * i] = c[i].pos.laser_theta;
		col[3 * i + 1] = c[i].pos.det_theta;
		col[3 * i + 2] = c[i].pos.det_phi;
		double *r = col + 3 * n;
		r[i] = c[i].base_s, r[n + i] = c[i].open_s, r[2 * n + i] = c[i].point_s, r[3 * n + i] = c[i].dark_s;
		r[4 * n + i] = c[i].rungs, r[5 * n + i] = c[i].since;
	}
	double *bc = malloc(n * sizeof *bc);
	assert_non_null(bc);
	for (size_t i = 0; i < n; i++)
		bc[i] = c[i].band_cos;
	struct select_route rt = { .pos = col, .base = col + 3 * n, .open = col + 4 * n, .point = col + 5 * n,
				   .dark = col + 6 * n, .rungs = col + 7 * n, .since = col + 8 * n, .band_cos = bc,
				   .nodes = v + 13, .nnodes = (nv - 13) / 4, .move_s = v[12] };
	for (int a = 0; a < 3; a++)
		rt.from[a] = v[a], rt.speed[a] = v[3 + 3 * a], rt.accel[a] = v[4 + 3 * a], rt.settle[a] = v[5 + 3 * a];
	struct sel_route w;
	assert_int_equal(sel_route_init(&w, &rt, 12), 0);
	double charged = 0, old = 0, moves = 0;
	struct plan_pos pts[12];
	for (size_t j = 0; j < 12; j++) {
		size_t at, i = pick[j];
		double cj = sel_route_cost(&w, i, &at);
		/* the exposure part of the charge: the charge less the insertion's motion */
		double before = w.T;
		sel_route_add(&w, i, at);
		charged += cj;
		moves += cj - (w.T - before);
		bool seen = false;
		for (size_t x = 0; x < j; x++)
			seen |= c[pick[x]].pos.laser_theta == c[i].pos.laser_theta;
		old += c[i].base_s + (seen || c[i].pos.laser_theta == 40 ? 0 : c[i].open_s);
		pts[j] = c[i].pos;
	}
	/* a dark due (since 0) or more rungs make the same last pick dearer: the route before it, then each variant */
	struct sel_route w2;
	assert_int_equal(sel_route_init(&w2, &rt, 12), 0);
	for (size_t j = 0; j < 11; j++) {
		size_t at;
		sel_route_cost(&w2, pick[j], &at);
		sel_route_add(&w2, pick[j], at);
	}
	size_t last = pick[0]; /* at the arms' incidence, since 2: its dark partly cached */
	double *since = col + 8 * n, *rungs = col + 7 * n;
	struct sel_route w3;
	assert_int_equal(sel_route_init(&w3, &rt, 12), 0);
	size_t at;
	double c0 = sel_route_cost(&w3, last, &at);
	since[last] = 0;
	double cdue = sel_route_cost(&w3, last, &at);
	since[last] = c[last].since;
	rungs[last] *= 2;
	double crung = sel_route_cost(&w3, last, &at);
	rungs[last] = c[last].rungs;
	printf("route price: first pick at the arms' incidence %.4f s, with a dark due %.4f s, twice the rungs %.4f s\n",
	       c0, cdue, crung);
	/* alone in the batch (its own band): the dark's probability q^since against 1, q = 1 - 1/rungs */
	double q = 1 - 1 / c[last].rungs;
	assert_true(c[last].since == 2 && c[last].dark_s > 0 && c[last].rungs > 2);
	assert_true(fabs(cdue - c0 - c[last].dark_s * (1 - q * q)) < 1e-9);
	assert_true(fabs(crung - c0 - c[last].dark_s * (pow(1 - 0.5 / c[last].rungs, 2) - q * q)) < 1e-9);
	sel_route_free(&w3);
	sel_route_free(&w2);
	/* the planner's batch */
	struct plan_result *r = NULL;
	assert_int_equal(plan_make_points(s, &g, pts, 12, &done[2], &r, &err), 0);
	assert_int_equal(r->n_steps, 12);
	struct plan_timing tc = tm;
	plan_timing_continue(&tc, done, 3, sizeof *done);
	plan_time_apply(s, &g, &tc, r);
	double expo = r->predicted_s - r->t_motion_s - r->t_settle_s;
	printf("route price: planner %.3f s (exposures %.3f s, darks %.3f s); charged %.3f s (exposures %.3f, motion "
	       "%.3f s); the old price's exposures %.3f s (%.1f %%)\n", r->predicted_s, expo, r->darks_s, charged, w.T,
	       moves, old, 100 * old / expo);
	assert_true(fabs(w.T - expo) < 0.01 * expo);
	assert_true(fabs(charged - moves - w.T) < 1e-9);
	sel_route_free(&w);
	plan_result_free(r);
	free(bc);
	free(col);
	free(c);
	plan_spec_free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_parse),
		cmocka_unit_test(test_errors),
		cmocka_unit_test(test_candidates),
		cmocka_unit_test(test_specular),
		cmocka_unit_test(test_fit_picks),
		cmocka_unit_test(test_batch_order),
		cmocka_unit_test(test_continue_darks),
		cmocka_unit_test(test_route_price),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
