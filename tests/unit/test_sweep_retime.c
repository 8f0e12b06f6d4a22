/* Unit tests of daemon/sweep_retime.c with daemon/eta.c: a first auto sweep re-times the rest of its plan from its
 * own exposures at each new incidence, and the live ETA (time injected) then starts afresh against it. A simulated
 * bench (below, independent of the duration model) measures the quick plan on a sample darker than the plan's 20 ms
 * estimate; at the incidence change the ETA must be within 1 % of the time actually left with the re-timing; without
 * it, it is 4.6 % off (the band around the estimate, and the first incidence's excess carried over with its weight:
 * its darks at the sample's two times came first). */
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <sqlite3.h>
#include <cmocka.h>

#include "config/bench.h"
#include "daemon/eta.h"
#include "daemon/plan/plan.h"
#include "daemon/store.h"
#include "daemon/sweep_retime.h"
#include "tests/unit/storefix.h"
#define UT_TMPDIR_NAME "test_sweep_retime"
#include "tests/unit/tmpdir.h"

/* the quick plan (config/plan-quick.yaml) with its sample named */
static const char *PLAN = "name: t\nsample: dark paint\nincidence: {theta_deg: [20, 45]}\n"
			  "observation: {theta_deg: [30, 60], phi_deg: [0, 90, 180, 270]}\n"
			  "integration: {mode: auto, estimate_ms: 20, max_ms: 2000}\naverages: 2\nblind_points: drop\n";

#define HOST_S 0.004     /* the simulated host's real seconds per point */
#define DARK_N 10        /* exposures per dark (plan_timing_defaults) */

/* The simulated sample's first exposure at step i: two rungs of the ladder (1 ms · √2^k), 90.5 and 181 ms, in
 * turn (about 4.5 and 9 times the estimate) */
static double sample_ms(size_t i)
{
	return i % 2 ? 181.019336 : 90.509668;
}

/* One exposure as the simulated bench takes it: n averages, the read-out, the round trip. */
static double bench_shot(const struct bench_geom *g, const struct plan_timing *t, int n, double ms)
{
	return n * ms / 1000.0 + g->readout_s + t->exposure_overhead_s;
}

struct sim {
	double d[64];     /* real seconds of step i (time scale 1) */
	bool dark[64];    /* step i took a dark (its rung new at its incidence) */
};

/* The simulated bench's time per step: the planned move and its settling with PLAN_MOVE_POLLS polls, the probe at the previous
 * step's time (the first at the estimate), a dark when the step's rung is new at its incidence, the measurement, the
 * host. */
static void simulate(const struct plan_result *r, const struct bench_geom *g, const struct plan_timing *t,
		     struct sim *s)
{
	assert_true(r->n_steps <= 64);
	bool seen[2] = { false, false };
	for (size_t i = 0; i < r->n_steps; i++) {
		const struct plan_step *st = &r->steps[i];
		if (i > 0 && st->pos.laser_theta != r->steps[i - 1].pos.laser_theta)
			seen[0] = seen[1] = false;
		double move = st->move_s + st->settle_s > 0 ? st->move_s + st->settle_s + PLAN_MOVE_POLLS * t->axis_poll_s : 0;
		double probe = bench_shot(g, t, 1, i ? sample_ms(i - 1) : 20);
		s->dark[i] = !seen[i % 2];
		seen[i % 2] = true;
		s->d[i] = move + probe + (s->dark[i] ? bench_shot(g, t, DARK_N, sample_ms(i)) : 0) +
			  bench_shot(g, t, 2, sample_ms(i)) + HOST_S;
	}
}

/* A spectrum of point pt of sweep sw (completing the point when last, at real time at with the arms at p). */
static void put(struct store *st, int64_t sw, int64_t pt, const char *kind, double ms, int n, bool last, double at,
		const struct plan_pos *p)
{
	float c[4] = { 1, 2, 3, 4 };
	struct store_spectrum sp = { .sweep_id = sw, .point_id = pt, .kind = kind, .integration_ms = ms, .averages = n,
				     .npix = 4, .counts = c, .temperature_c = NAN, .taken_at = at, .completes_point = last,
				     .laser_theta = p->laser_theta, .detector_theta = p->det_theta,
				     .detector_phi = p->det_phi, .theta_i = fabs(p->laser_theta), .phi_i = 0,
				     .theta_o = fabs(p->det_theta), .phi_o = 0 };
	struct acq_err err = { 0 };
	assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), 0);
}

/* The quick plan on the default bench (read-out 10 ms): its spec in *spec and the plan. */
static struct plan_result *load_plan(struct bench_geom *g, struct plan_spec **spec)
{
	struct acq_err err = { 0 };
	struct plan_result *r = NULL;
	bench_defaults(g);
	g->readout_s = 0.01;
	assert_int_equal(plan_load_string("t.yaml", PLAN, spec, &err), 0);
	assert_int_equal(plan_make(*spec, g, &r, &err), 0);
	return r;
}

/* The ETA's relative error at the first point of the second incidence, the sweep run on the simulated bench with
 * the ETA fed at every point (real time injected); with retime the sweep re-times its plan there. */
/* The ETA's interval at the incidence change (sweep_retime_eta), wall s: set by eta_error_at_change. */
static double eta_lo, eta_hi;

static double eta_error_at_change(bool retime, int *retimed)
{
	char path[300];
	char file[32];
	snprintf(file, sizeof file, "r%d.db", retime);
	struct store *st = ut_store_new(path, sizeof path, ut_dir, file);
	struct bench_geom g;
	struct plan_spec *spec = NULL;
	struct plan_result *r = load_plan(&g, &spec);
	struct acq_err err = { 0 };
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	tm.reference = false;
	plan_time_apply(spec, &g, &tm, r);
	struct sim s;
	simulate(r, &g, &tm, &s);
	size_t n = r->n_steps, change = 0;
	for (size_t i = 1; i < n && !change; i++)
		if (r->steps[i].pos.laser_theta != r->steps[i - 1].pos.laser_theta)
			change = i;
	assert_true(change >= 4 && change + 4 <= n);

	struct store_point_new pts[64];
	for (size_t i = 0; i < n; i++)
		pts[i] = (struct store_point_new){ (int)i, fabs(r->steps[i].pos.laser_theta), 0,
						   fabs(r->steps[i].pos.det_theta), 0 };
	struct store_sweep_new nw = { .name = "t", .plan_text = PLAN, .config_snapshot = "{}", .software_version = "test",
				      .created_at = 1000, .sample = "dark paint", .auto_exposure = true };
	int64_t sid = 0;
	assert_int_equal(store_sweep_create(st, &nw, pts, (int)n, &sid, &err), 0);

	struct sweep_retime rt = { 0 };
	sweep_retime_setup(&rt, spec, &tm);
	assert_true(rt.on);
	if (!retime)
		rt.on = false;
	assert_int_equal(sweep_retime_bounds(&rt, spec, &g, r, &err), 0); /* the policy's reach: nothing measured */
	assert_int_equal(rt.iv, PLAN_IV_POLICY);
	double first_lo = NAN, first_hi = NAN, first_left = 0;
	struct eta e;
	eta_reset(&e);
	double real = 1000;
	eta_running(&e, true, real, real);
	double eta = NAN;
	for (size_t done = 1; done <= change; done++) {
		/* step done-1 measured on the simulated bench and stored */
		size_t i = done - 1;
		real += s.d[i];
		int order;
		int64_t pt;
		assert_int_equal(store_sweep_next_point(st, sid, &order, &pt, &err), 0);
		assert_int_equal(order, (int)i);
		if (s.dark[i])
			put(st, sid, pt, "dark", sample_ms(i), DARK_N, false, real, &r->steps[i].pos);
		put(st, sid, pt, "sample", sample_ms(i), 2, true, real, &r->steps[i].pos);
		/* what sweep.c's on_progress does */
		assert_int_equal(sweep_retime_due(&rt, r, (int)done), retime && done == change);
		if (sweep_retime_due(&rt, r, (int)done)) {
			assert_int_equal(sweep_retime_apply(&rt, (int)done, st, sid, spec, &g, r, &err), 1);
			eta_replan(&e, sweep_retime_plan_at, r);
			assert_int_equal(sweep_retime_bounds(&rt, spec, &g, r, &err), 0);
			assert_int_equal(rt.iv, PLAN_IV_EXTRAPOLATED); /* 45° from the 20° measured */
			assert_false(sweep_retime_due(&rt, r, (int)done)); /* once per incidence */
		}
		eta = eta_update(&e, (int)done, (int)n, r->steps[done].predicted_start_s, r->predicted_s, real, real);
		if (done == 1)
			sweep_retime_eta(&rt, r, (int)done, eta, e.scale, &first_lo, &first_hi);
		if (done == change)
			sweep_retime_eta(&rt, r, (int)done, eta, e.scale, &eta_lo, &eta_hi);
	}
	double left = 0;
	for (size_t i = change; i < n; i++)
		left += s.d[i];
	for (size_t i = 1; i < n; i++)
		first_left += s.d[i];
	/* after the first point nothing says what the sample needs: the policy's reach, which holds the bench's time
	 * (the sample at 90 and 181 ms, the plan's estimate 20 ms) */
	assert_true(first_lo <= first_left && first_left <= first_hi);
	assert_true(first_hi > 2 * first_left);
	*retimed = rt.retimed;
	if (retime) {
		/* the interval at the change: the second incidence's times extrapolated from the first's (times
		 * exp(-/+ PLAN_EXPO_SLOPE_ONE · 25°)), around the ETA, holding the time left (the bench's sample has the
		 * same times at both incidences), and narrower than the policy's */
		assert_true(eta_lo < eta - 0.5 && eta + 0.5 < eta_hi);
		assert_true(eta_lo <= left && left <= eta_hi);
		assert_true(eta_hi - eta_lo < 0.5 * (first_hi - first_lo));
		/* the sweep's own prior: its first incidence's points, the host's time per point measured from them */
		assert_int_equal(rt.tm.prior.sweep, sid);
		assert_int_equal(rt.tm.prior.n_inc, 1);
		assert_int_equal(rt.tm.prior.inc[0].points, change);
		assert_true(fabs(rt.tm.prior.inc[0].darks_per_clear - 2) < 1e-12);
		assert_true(rt.tm.prior.host_points > 0 && fabs(rt.tm.prior.host_per_point_s - HOST_S) < 0.002);
	}
	sweep_retime_end(&rt);
	plan_result_free(r);
	plan_spec_free(spec);
	store_close(st);
	return eta / left - 1;
}

static void test_retime_eta(void **state)
{
	(void)state;
	int k = 0;
	double with = eta_error_at_change(true, &k);
	assert_int_equal(k, 1);
	double without = eta_error_at_change(false, &k);
	assert_int_equal(k, 0);
	print_message("ETA error at the incidence change: %+.2f %% re-timed, %+.2f %% not\n", 100 * with,
		      100 * without);
	assert_true(fabs(with) < 0.01);
	print_message("ETA interval at the change: %.2f .. %.2f s\n", eta_lo, eta_hi);
	assert_true(fabs(without) > 0.03); /* +4.6 %: the first incidence's darks, carried as an excess per point */
}

/* Who re-times: auto integration without a prior from an earlier sweep; not a fixed plan, an adaptive one or one
 * with a prior; due only at a new incidence after a measured point, once. */
static void test_retime_who(void **state)
{
	(void)state;
	struct bench_geom g;
	struct plan_spec *spec = NULL;
	struct plan_result *r = load_plan(&g, &spec);
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	struct sweep_retime rt = { 0 };
	sweep_retime_setup(&rt, spec, &tm);
	assert_true(rt.on);
	assert_false(sweep_retime_due(&rt, r, 0));
	int changes = 0;
	for (size_t i = 1; i < r->n_steps; i++) {
		bool inc = r->steps[i].pos.laser_theta != r->steps[i - 1].pos.laser_theta;
		assert_int_equal(sweep_retime_due(&rt, r, (int)i), inc);
		changes += inc;
	}
	assert_int_equal(changes, 1);
	assert_false(sweep_retime_due(&rt, r, (int)r->n_steps));
	tm.prior.sweep = 7;
	tm.prior.n_inc = 1;
	sweep_retime_setup(&rt, spec, &tm);
	assert_false(rt.on);
	tm.prior.sweep = 0;
	spec->integ_mode = PLAN_INTEG_FIXED;
	sweep_retime_setup(&rt, spec, &tm);
	assert_false(rt.on);
	sweep_retime_end(&rt);
	plan_result_free(r);
	plan_spec_free(spec);
}

/* Two priors alike, field by field (exactly: the same rows in the same order give the same sums). */
static void same_prior(const struct plan_prior *a, const struct plan_prior *b)
{
	assert_int_equal(a->sweep, b->sweep);
	assert_string_equal(a->sample, b->sample);
	assert_int_equal(a->points, b->points);
	assert_true(a->median_ms == b->median_ms && a->spread == b->spread && a->hdr_fraction == b->hdr_fraction);
	assert_true(a->host_per_point_s == b->host_per_point_s);
	assert_int_equal(a->host_points, b->host_points);
	assert_int_equal(a->n_inc, b->n_inc);
	for (size_t i = 0; i < a->n_inc; i++) {
		const struct plan_prior_inc *x = &a->inc[i], *y = &b->inc[i];
		assert_true(x->theta_i == y->theta_i && x->points == y->points && x->median_ms == y->median_ms &&
			    x->mean_ms == y->mean_ms && x->spread == y->spread &&
			    x->darks_per_clear == y->darks_per_clear && x->dark_ms == y->dark_ms &&
			    x->extra_per_point == y->extra_per_point && x->extra_ms == y->extra_ms &&
			    x->pooled_per_point == y->pooled_per_point && x->pooled_ms == y->pooled_ms);
	}
}

/* The re-timing reads only the points committed since the last one (exp_prior_update) and must give the prior and
 * the re-timed plan that reading every done point gives (exp_prior_load_sweep), whatever the incidences' order: a
 * plan of three incidences stored with incidence zeniths 40, 20, 40 (so the third merges into the first's rows, out
 * of the commit order), darks at each new rung, an HDR exposure every fifth point, commits at uneven times. Checked
 * after every point and at every incidence change through sweep_retime_apply against a sweep set up afresh there
 * (a recovered daemon reads everything). */
static void test_retime_incremental(void **state)
{
	(void)state;
	static const char *P3 = "name: t\nsample: dark paint\nincidence: {theta_deg: [20, 45, 60]}\n"
				"observation: {theta_deg: [30, 60], phi_deg: [0, 90, 180, 270]}\n"
				"integration: {mode: auto, estimate_ms: 20, max_ms: 2000}\naverages: 2\n"
				"blind_points: drop\n";
	char path[300];
	struct store *st = ut_store_new(path, sizeof path, ut_dir, "inc.db");
	struct bench_geom g;
	bench_defaults(&g);
	g.readout_s = 0.01;
	struct plan_spec *spec = NULL;
	struct plan_result *ra = NULL, *rb = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(plan_load_string("t.yaml", P3, &spec, &err), 0);
	assert_int_equal(plan_make(spec, &g, &ra, &err), 0);
	assert_int_equal(plan_make(spec, &g, &rb, &err), 0);
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	tm.reference = false;
	plan_time_apply(spec, &g, &tm, ra);
	plan_time_apply(spec, &g, &tm, rb);
	size_t n = ra->n_steps;
	assert_true(n >= 12 && n <= 64);
	/* incidence k of the plan stored at zenith 40, 20, 40 */
	struct store_point_new pts[64];
	int inc = 0;
	for (size_t i = 0; i < n; i++) {
		inc += i > 0 && ra->steps[i].pos.laser_theta != ra->steps[i - 1].pos.laser_theta;
		pts[i] = (struct store_point_new){ (int)i, inc == 1 ? 20 : 40, 0, fabs(ra->steps[i].pos.det_theta), 0 };
	}
	assert_int_equal(inc, 2);
	struct store_sweep_new nw = { .name = "t", .plan_text = P3, .config_snapshot = "{}", .software_version = "test",
				      .created_at = 1000, .sample = "dark paint", .auto_exposure = true };
	int64_t sid = 0;
	assert_int_equal(store_sweep_create(st, &nw, pts, (int)n, &sid, &err), 0);

	struct exp_prior_rows R = { 0 };
	struct sweep_retime inc_rt = { 0 }, full_rt = { 0 };
	sweep_retime_setup(&inc_rt, spec, &tm);
	double real = 1000;
	bool seen[2] = { false, false };
	int changes = 0;
	for (size_t done = 1; done <= n; done++) {
		size_t i = done - 1;
		if (i > 0 && ra->steps[i].pos.laser_theta != ra->steps[i - 1].pos.laser_theta)
			seen[0] = seen[1] = false;
		real += 0.3 + 0.01 * (double)(i % 7);
		int order;
		int64_t pt;
		assert_int_equal(store_sweep_next_point(st, sid, &order, &pt, &err), 0);
		assert_int_equal(order, (int)i);
		if (!seen[i % 2])
			put(st, sid, pt, "dark", sample_ms(i), DARK_N, false, real, &ra->steps[i].pos);
		seen[i % 2] = true;
		put(st, sid, pt, "sample", sample_ms(i), 2, i % 5 != 4, real, &ra->steps[i].pos);
		if (i % 5 == 4)
			put(st, sid, pt, "sample", 8 * sample_ms(i), 2, true, real, &ra->steps[i].pos);
		/* the cache after every point against a full read */
		struct plan_prior a, b;
		assert_int_equal(exp_prior_update(&R, st, sid, &g, &tm, &a, &err), 0);
		assert_int_equal(exp_prior_load_sweep(st, sid, &g, &tm, &b, &err), 0);
		assert_int_equal(a.points, done);
		same_prior(&a, &b);
		/* the re-timing at an incidence change, against a sweep that reads everything there */
		if (sweep_retime_due(&inc_rt, ra, (int)done)) {
			sweep_retime_setup(&full_rt, spec, &tm);
			assert_int_equal(sweep_retime_apply(&inc_rt, (int)done, st, sid, spec, &g, ra, &err), 1);
			assert_int_equal(sweep_retime_apply(&full_rt, (int)done, st, sid, spec, &g, rb, &err), 1);
			same_prior(&inc_rt.tm.prior, &full_rt.tm.prior);
			assert_true(ra->predicted_s == rb->predicted_s);
			for (size_t k = 0; k < n; k++)
				assert_true(ra->steps[k].predicted_start_s == rb->steps[k].predicted_start_s);
			changes++;
		}
	}
	assert_int_equal(changes, 2);
	/* the third incidence's rows merged into the first's: two incidences in the prior; nothing new to read */
	struct plan_prior a;
	assert_int_equal(exp_prior_update(&R, st, sid, &g, &tm, &a, &err), 0);
	assert_int_equal(a.n_inc, 2);
	assert_int_equal(a.points, n);
	assert_true(R.next_order == (long long)n);
	exp_prior_rows_free(&R);
	sweep_retime_end(&inc_rt);
	sweep_retime_end(&full_rt);
	plan_result_free(ra);
	plan_result_free(rb);
	plan_spec_free(spec);
	store_close(st);
}

/* A plan with a survey (plan_survey_apply): re-timed once, at the survey's end (not at the incidence changes within
 * it), from rows of the survey's points alone (every incidence), their pooled share the route's default (the survey's
 * points are not consecutive in the route) and the host's time the live ETA's (sweep_retime.host_hint: no route point
 * done yet); the re-timed plan is then the plan timed with those rows by hand, and its interval none (every incidence
 * measured). The simulated sample needs one time per incidence (32, 64, 128 ms: the survey measures it exactly). */
static void test_retime_survey(void **state)
{
	(void)state;
	static const char *PS = "name: s\nsample: dark paint\nincidence: {theta_deg: [10, 30, 50]}\n"
				"observation: {theta_deg: [20, 35, 50, 65], phi_deg: [0, 60, 120, 180, 240, 300]}\n"
				"integration: {mode: auto, estimate_ms: 20, max_ms: 2000}\naverages: 2\nblind_points: drop\n"
				"survey: 2\n";
	static const double inc_ms[3] = { 32, 64, 128 }; /* rungs 10, 12, 14 of 1 ms · √2^k */
	int seen50 = 0; /* 50°: its second point at 512 ms (rung 18): the row's rungs are then 14..18 */
	char path[300];
	struct store *st = ut_store_new(path, sizeof path, ut_dir, "survey.db");
	struct bench_geom g;
	bench_defaults(&g);
	g.readout_s = 0.01;
	struct plan_spec *spec = NULL;
	struct plan_result *r = NULL, *r2 = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(plan_load_string("s.yaml", PS, &spec, &err), 0);
	assert_int_equal(spec->survey, 2);
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	tm.reference = false;
	tm.dark_every = -1; /* the shipped configurations': darks by rung, kept across incidences */
	assert_int_equal(plan_make(spec, &g, &r, &err), 0);
	assert_int_equal(plan_survey_apply(spec, &g, &tm, r, &err), 0);
	assert_int_equal(r->n_survey, 6);
	plan_time_apply(spec, &g, &tm, r);
	size_t n = r->n_steps;
	struct store_point_new pts[72];
	assert_true(n <= 72);
	for (size_t i = 0; i < n; i++)
		pts[i] = (struct store_point_new){ (int)i, fabs(r->steps[i].pos.laser_theta), 0,
						   fabs(r->steps[i].pos.det_theta), 0 };
	struct store_sweep_new nw = { .name = "s", .plan_text = PS, .config_snapshot = "{}", .software_version = "test",
				      .created_at = 1000, .sample = "dark paint", .auto_exposure = true };
	int64_t sid = 0;
	assert_int_equal(store_sweep_create(st, &nw, pts, (int)n, &sid, &err), 0);
	struct sweep_retime rt = { 0 };
	sweep_retime_setup(&rt, spec, &tm);
	sweep_retime_survey(&rt, spec, r);
	assert_true(rt.on);
	assert_int_equal(rt.survey, 6);
	double real = 1000;
	for (size_t done = 1; done <= 6; done++) {
		size_t i = done - 1;
		int order;
		int64_t pt;
		assert_int_equal(store_sweep_next_point(st, sid, &order, &pt, &err), 0);
		assert_int_equal(order, (int)i);
		double th = fabs(r->steps[i].pos.laser_theta);
		real += 3; /* the survey's long moves */
		double ms = th < 20 ? inc_ms[0] : th < 40 ? inc_ms[1] : seen50++ ? 512 : inc_ms[2];
		put(st, sid, pt, "sample", ms, 2, true, real, &r->steps[i].pos);
		/* never within the survey, though its points change incidence; at its end whatever the next incidence */
		assert_int_equal(sweep_retime_due(&rt, r, (int)done), done == 6);
	}
	rt.host_hint = 0.003;
	assert_int_equal(sweep_retime_apply(&rt, 6, st, sid, spec, &g, r, &err), 1);
	assert_false(sweep_retime_due(&rt, r, 6));
	const struct plan_prior *p = &rt.tm.prior;
	assert_int_equal(p->n_inc, 3);
	struct plan_timing th = tm; /* the same rows by hand */
	th.prior = (struct plan_prior){ .sweep = sid, .host_per_point_s = 0.003, .host_points = 1, .n_inc = 3 };
	/* the survey rows (10°: 32, 32 ms; 30°: 64, 64; 50°: 128, 512) smoothed across incidences (sweep_retime_smooth):
	 * each the Gaussian-kernel mean (12°) of the three rows' means weighted by 1 / (ln-variance / 2 + 0.4), the
	 * 50° row's ln-variance ln(4)^2 / 2 */
	static const double raw[3] = { 32, 64, 320 };
	double wv[3] = { 1 / 0.4, 1 / 0.4, 1 / (log(4) * log(4) / 2 / 2 + 0.4) };
	for (size_t k = 0; k < 3; k++) {
		double sw = 0, sm = 0;
		for (size_t u = 0; u < 3; u++) {
			double d = (20.0 * (double)u - 20.0 * (double)k) / 12;
			sw += wv[u] * exp(-0.5 * d * d);
			sm += wv[u] * exp(-0.5 * d * d) * raw[u];
		}
		double mean = sm / sw;
		assert_int_equal(p->inc[k].points, 2);
		assert_true(fabs(p->inc[k].mean_ms - mean) < 1e-9 * mean && fabs(p->inc[k].median_ms - mean) < 1e-9 * mean);
		assert_true(p->inc[k].pooled_per_point == PLAN_PROBE_POOL && p->inc[k].pooled_ms == 0);
		/* the rungs between the survey's shortest and longest time (the route's points use them all) */
		uint64_t rungs = k < 2 ? (uint64_t)1 << (10 + 2 * k) : (uint64_t)0x1f << 14;
		assert_true(p->inc[k].rungs == rungs);
		th.prior.inc[k] = (struct plan_prior_inc){ .theta_i = p->inc[k].theta_i, .points = 2, .mean_ms = mean,
							    .median_ms = mean, .log_var = p->inc[k].log_var, .spread = k < 2 ? 1 : 4, .rungs = rungs,
							    .darks_per_clear = k < 2 ? 1 : 5,
							    .pooled_per_point = PLAN_PROBE_POOL };
	}
	assert_true(p->host_per_point_s == 0.003 && p->host_points == 1);
	assert_int_equal(plan_make(spec, &g, &r2, &err), 0);
	assert_int_equal(plan_survey_apply(spec, &g, &tm, r2, &err), 0);
	plan_time_apply(spec, &g, &th, r2);
	print_message("re-timed at the survey's end: %.6f s (its first %.6f s the survey's), by hand %.6f s\n",
		      r->predicted_s, r->steps[6].predicted_start_s, r2->predicted_s);
	assert_true(fabs(r->predicted_s - r2->predicted_s) < 1e-9 * r2->predicted_s);
	assert_int_equal(sweep_retime_bounds(&rt, spec, &g, r, &err), 0);
	assert_int_equal(rt.iv, PLAN_IV_NONE); /* every incidence measured: the interval is the point */
	sweep_retime_end(&rt);
	plan_result_free(r);
	plan_result_free(r2);
	plan_spec_free(spec);
	store_close(st);
}

/* sweep_retime_smooth: a survey row's mean pulled toward its neighbours by their certainty; completed rows kept. */
static void test_retime_smooth(void **state)
{
	(void)state;
	struct plan_prior pr = { .sweep = 1, .n_inc = 10 };
	bool only[PLAN_PRIOR_MAX_INC] = { false }, none[PLAN_PRIOR_MAX_INC] = { false };
	for (size_t i = 0; i < 10; i++) {
		bool sv = i >= 5; /* the route has done 0-30°; 37.5-67.5° have the survey's 6 points each */
		only[i] = sv;
		pr.inc[i] = (struct plan_prior_inc){ .theta_i = 7.5 * (double)i, .points = sv ? 6 : 100,
						     .mean_ms = 100, .median_ms = 90, .log_var = sv ? 1 : 0.2 };
	}
	struct plan_prior same = pr;
	sweep_retime_smooth(&same, only); /* every row the same mean: nothing moves */
	for (size_t i = 0; i < 10; i++)
		assert_true(fabs(same.inc[i].mean_ms - 100) < 1e-9 && fabs(same.inc[i].median_ms - 90) < 1e-9);
	pr.inc[8].mean_ms = 300; /* 60°: a survey row of a wide spread far above its neighbours (the metal's 843 ms) */
	pr.inc[8].log_var = 3;
	pr.inc[2].mean_ms = 50;  /* 15°: completed */
	struct plan_prior kept = pr;
	sweep_retime_smooth(&kept, none); /* no survey-only row: unchanged */
	assert_memory_equal(&kept, &pr, sizeof pr);
	sweep_retime_smooth(&pr, only);
	for (size_t i = 0; i < 5; i++) /* completed rows as measured */
		assert_true(pr.inc[i].mean_ms == kept.inc[i].mean_ms && pr.inc[i].median_ms == 90);
	/* by hand: weights 1 / (log_var / points + 0.4) times exp(-(Δθ / 12°)² / 2), over the rows' own means */
	for (size_t i = 5; i < 10; i++) {
		double sw = 0, sm = 0;
		for (size_t u = 0; u < 10; u++) {
			double d = 7.5 * ((double)u - (double)i) / 12;
			double w = exp(-0.5 * d * d) / (kept.inc[u].log_var / (double)kept.inc[u].points + 0.4);
			sw += w;
			sm += w * kept.inc[u].mean_ms;
		}
		double want = sm / sw;
		print_message("%.1f°: %.1f ms -> %.2f ms\n", pr.inc[i].theta_i, kept.inc[i].mean_ms, pr.inc[i].mean_ms);
		assert_true(fabs(pr.inc[i].mean_ms - want) < 1e-9 * want);
		assert_true(fabs(pr.inc[i].median_ms / pr.inc[i].mean_ms - 0.9 * 100 / kept.inc[i].mean_ms) < 1e-12);
	}
	assert_true(pr.inc[8].mean_ms > 100 && pr.inc[8].mean_ms < 200); /* most of the outlier gone */
	assert_true(pr.inc[7].mean_ms > 100 && pr.inc[9].mean_ms > pr.inc[5].mean_ms);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_retime_eta),
		cmocka_unit_test(test_retime_who),
		cmocka_unit_test(test_retime_incremental),
		cmocka_unit_test(test_retime_survey),
		cmocka_unit_test(test_retime_smooth),
	};
	return cmocka_run_group_tests(tests, ut_dir_setup, ut_dir_teardown);
}
