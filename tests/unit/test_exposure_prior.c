/* Unit tests of daemon/exposure_prior.c and daemon/store_prior.c: the exposure prior of a sample from its previous
 * completed auto sweep in the database (which sweep is chosen, the per-incidence figures by hand, none for a fixed
 * sweep, another sample, an unfinished sweep or a sweep without a sample). */
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

#include "daemon/exposure.h"
#include "daemon/plan/plan.h"
#include "daemon/store.h"
#include "tests/unit/storefix.h"
#define UT_TMPDIR_NAME "test_exposure_prior"
#include "tests/unit/tmpdir.h"

#define TOL 1e-12 /* means of a few exact doubles */

/* One exposure of a point (completing it when last). */
static void shot(struct store *st, int64_t sw, int64_t pt, const char *kind, double ms, bool last)
{
	float c[4] = { 1, 2, 3, 4 };
	struct store_spectrum sp = { .sweep_id = sw, .point_id = pt, .kind = kind, .integration_ms = ms, .averages = 4,
				     .npix = 4, .counts = c, .temperature_c = NAN, .taken_at = 1000, .completes_point = last,
				     .laser_theta = NAN, .detector_theta = NAN, .detector_phi = NAN, .theta_i = NAN,
				     .phi_i = NAN, .theta_o = NAN, .phi_o = NAN };
	struct acq_err err = { 0 };
	assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), 0);
}

/* A sweep of sample (NULL: none) with two incidences, 10° (3 points) and 40° (2 points); the exposures of each point
 * (darks, then the sample exposures) as the table below; finished in state. */
static int64_t mk_sweep(struct store *st, const char *sample, bool aut, const char *state)
{
	struct store_point_new pts[5] = { { 0, 10, 0, 20, 0 }, { 1, 10, 0, 30, 90 }, { 2, 10, 0, 40, 180 },
					   { 3, 40, 0, 20, 0 }, { 4, 40, 0, 60, 90 } };
	struct store_sweep_new nw = { .name = "t", .plan_text = "name: t", .config_snapshot = "{}",
				      .software_version = "test", .created_at = 1000, .sample = sample,
				      .auto_exposure = aut };
	int64_t id = 0;
	struct acq_err err = { 0 };
	assert_int_equal(store_sweep_create(st, &nw, pts, 5, &id, &err), 0);
	for (int i = 0; i < 5; i++) {
		int order;
		int64_t pt;
		assert_int_equal(store_sweep_next_point(st, id, &order, &pt, &err), 0);
		assert_int_equal(order, i);
		switch (i) {
		case 0: /* 10°: a dark and an exposure at 40 ms */
			shot(st, id, pt, "dark", 40, false);
			shot(st, id, pt, "sample", 40, true);
			break;
		case 1: /* a dark at 20 ms, then an exposure at 20 ms and its HDR exposure at 160 ms (its dark too) */
			shot(st, id, pt, "dark", 20, false);
			shot(st, id, pt, "sample", 20, false);
			shot(st, id, pt, "dark", 160, false);
			shot(st, id, pt, "sample", 160, true);
			break;
		case 2: /* 40 ms again: no dark */
			shot(st, id, pt, "sample", 40, true);
			break;
		case 3: /* 40°: a dark and an exposure at 100 ms */
			shot(st, id, pt, "dark", 100, false);
			shot(st, id, pt, "sample", 100, true);
			break;
		default: /* an exposure at 400 ms with its dark */
			shot(st, id, pt, "dark", 400, false);
			shot(st, id, pt, "sample", 400, true);
		}
	}
	if (state)
		assert_int_equal(store_sweep_set_state(st, id, state, 1100, &err), 0);
	return id;
}

static void test_prior_figures(void **state)
{
	(void)state;
	char p[300];
	struct store *st = ut_store_new(p, sizeof p, ut_dir, "a.db");
	struct acq_err err = { 0 };
	struct plan_prior pr;
	/* nothing yet; a sweep without a sample is never a prior */
	mk_sweep(st, NULL, true, "completed");
	assert_int_equal(exp_prior_load(st, "paint", 0, NULL, NULL, &pr, &err), 0);
	assert_int_equal(pr.sweep, 0);
	int64_t a = mk_sweep(st, "paint", true, "completed");
	mk_sweep(st, "paint", false, "completed");  /* fixed integration: its times are not the sample's */
	mk_sweep(st, "paint", true, "aborted");     /* not finished */
	mk_sweep(st, "white", true, "completed");   /* another sample */
	int64_t running = mk_sweep(st, "paint", true, NULL);
	assert_int_equal(exp_prior_load(st, "paint", running, NULL, NULL, &pr, &err), 0);
	assert_int_equal(pr.sweep, a);
	assert_string_equal(pr.sample, "paint");
	assert_int_equal(pr.points, 5);
	assert_int_equal(pr.n_inc, 2);
	/* first exposures 40, 20, 40 | 100, 400: median 40, spread 400/20; one point of five took an HDR exposure */
	assert_true(fabs(pr.median_ms - 40) < TOL && fabs(pr.spread - 20) < TOL && fabs(pr.hdr_fraction - 0.2) < TOL);
	const struct plan_prior_inc *q = &pr.inc[0];
	assert_true(fabs(q->theta_i - 10) < TOL);
	assert_int_equal(q->points, 3);
	assert_true(fabs(q->median_ms - 40) < TOL && fabs(q->mean_ms - 100.0 / 3) < TOL && fabs(q->spread - 2) < TOL);
	assert_true(fabs(q->log_var - log(2) * log(2) / 3) < TOL); /* ln 40, ln 20, ln 40: n - 1 divisor */
	assert_true(fabs(q->darks_per_clear - 3) < TOL && fabs(q->dark_ms - 220.0 / 3) < TOL);
	assert_true(fabs(q->extra_per_point - 1.0 / 3) < TOL && fabs(q->extra_ms - 160) < TOL);
	q = &pr.inc[1];
	assert_true(fabs(q->theta_i - 40) < TOL);
	assert_int_equal(q->points, 2);
	assert_true(fabs(q->median_ms - 250) < TOL && fabs(q->mean_ms - 250) < TOL && fabs(q->spread - 4) < TOL);
	assert_true(fabs(q->log_var - 2 * log(2) * log(2)) < TOL);
	assert_true(fabs(q->darks_per_clear - 2) < TOL && fabs(q->dark_ms - 250) < TOL);
	assert_true(q->extra_per_point == 0 && q->extra_ms == 0);
	/* no point's first time is its predecessor's (40, 20, 40, 100, 400): no probe was one of its scans */
	assert_true(pr.inc[0].pooled_per_point == 0 && pr.inc[1].pooled_per_point == 0);
	assert_int_equal(pr.host_points, 0); /* no bench, no time scale: the host's time is not measured */
	assert_true(pr.inc[0].rungs == 0 && pr.inc[1].rungs == 0); /* no timing: no ladder */
	/* the sample exposures' rungs (the darks they need, plan_time.c with dark_every -1) on a ladder 10 ms · 2^k:
	 * 20, 40, 160 ms at 10° (rungs 1, 2, 4; the 40 ms of two points is one rung), 100 ms (the nearest, 3) and
	 * 400 ms (5) at 40° */
	struct plan_timing t;
	plan_timing_defaults(&t);
	t.min_ms = 10;
	t.ladder_ratio = 2;
	assert_int_equal(exp_prior_load(st, "paint", running, NULL, &t, &pr, &err), 0);
	assert_true(pr.inc[0].rungs == ((1u << 1) | (1u << 2) | (1u << 4)));
	assert_true(pr.inc[1].rungs == ((1u << 3) | (1u << 5)));
	/* a newer completed sweep of the sample is the prior; excluded, the older one again */
	int64_t b = mk_sweep(st, "paint", true, "completed");
	assert_int_equal(exp_prior_load(st, "paint", 0, NULL, NULL, &pr, &err), 0);
	assert_int_equal(pr.sweep, b);
	assert_int_equal(exp_prior_load(st, "paint", b, NULL, NULL, &pr, &err), 0);
	assert_int_equal(pr.sweep, a);
	assert_int_equal(exp_prior_load(st, "nothing of that name", 0, NULL, NULL, &pr, &err), 0);
	assert_int_equal(pr.sweep, 0);
	assert_int_equal(exp_prior_load(st, "", 0, NULL, NULL, &pr, &err), 0);
	assert_int_equal(pr.sweep, 0);
	store_close(st);
}

/* The plan's sample: key: a printable name of 1 to 63 characters, none when absent. */
/* The host's real seconds per point in the prior's sweep: the real time between two consecutive points' commits less
 * the bench's part at the time scale (the straight move between the reached angles with its polling, the probe at the
 * previous point's first time, the point's shots with read-out and round trip); arms' noise under 0.05° is no move; a
 * gap in the order or a pause (more than 1 s over the median) is left out; a point whose first time is its
 * predecessor's took one scan fewer (its probe was one, exp_probe_reusable). By hand at time scale 10. */
static void test_prior_host(void **state)
{
	(void)state;
	struct bench_geom g;
	bench_defaults(&g);
	g.readout_s = 0.01;
	struct plan_timing t;
	plan_timing_defaults(&t);
	t.exposure_overhead_s = 0.005;
	t.axis_poll_s = 0.05;
	t.time_scale = 10;
	/* theta_i, point, dark, ms, averages, order, done_at, arms */
	const struct store_prior_row rows[] = {
		{ 10, 1, false, 40, 4, 0, 100.0, { 10, 20, 0 } },
		{ 10, 2, true, 40, 8, 1, 101.0, { 10, 30, 0 } },   /* detector.theta moves 10° */
		{ 10, 2, false, 40, 4, 1, 101.0, { 10, 30, 0 } },
		{ 10, 3, false, 20, 4, 2, 101.5, { 10.01, 30.02, -0.02 } }, /* noise: not moved */
		{ 10, 4, false, 20, 4, 4, 200.0, { 10, 30, 0 } },  /* order 3 missing: not counted */
		{ 10, 5, false, 20, 4, 5, 300.0, { 10, 30, 0 } },  /* 100 s after order 4: a pause, left out */
	};
	struct plan_prior pr;
	assert_int_equal(exp_prior_build(rows, 6, &g, &t, &pr), 0);
	struct plan_pos a = { 10, 20, 0 }, b = { 10, 30, 0 };
	double ovh = 0.015, mv = plan_straight_s(&g, &a, &b);
	assert_true(mv > 0.5);
	/* order 1's first time 40 ms is order 0's: its probe was the first of its 4 scans, 3 taken */
	double h1 = 1.0 - (mv + PLAN_MOVE_POLLS * 0.05 + (8 * 0.040 + ovh) + (3 * 0.040 + ovh) + (0.040 + ovh)) / 10;
	double h2 = 0.5 - ((4 * 0.020 + ovh) + (0.040 + ovh)) / 10;
	assert_int_equal(pr.host_points, 2);
	assert_true(fabs(pr.host_per_point_s - (h1 + h2) / 2) < 1e-12);
	/* pooled: orders 1 (40 after 40) and 5 (20 after 20); not order 4 (its predecessor, order 3, is missing) */
	assert_int_equal(pr.n_inc, 1);
	assert_true(fabs(pr.inc[0].pooled_per_point - 2.0 / 5) < 1e-12);
	assert_true(fabs(pr.inc[0].pooled_ms - 30) < 1e-12); /* (40 + 20) / 2 */
	/* at time scale 1 the same commits leave the host less */
	t.time_scale = 1;
	assert_int_equal(exp_prior_build(rows, 6, &g, &t, &pr), 0);
	assert_true(pr.host_per_point_s < (h1 + h2) / 2 - 0.05);
	/* without the bench: not measured */
	assert_int_equal(exp_prior_build(rows, 6, NULL, NULL, &pr), 0);
	assert_int_equal(pr.host_points, 0);
}

/* A sweep of n points (no sample; plan kind `kind`, NULL: none recorded) that stay at one pose, one 10 ms exposure of
 * 4 averages each, committed every `every` seconds, then in state. */
static int64_t mk_host_sweep_kind(struct store *st, int n, double every, const char *state, const char *kind)
{
	struct store_point_new pts[64];
	assert_true(n <= 64);
	for (int i = 0; i < n; i++)
		pts[i] = (struct store_point_new){ i, 10, 0, 30, 0 };
	struct store_sweep_new nw = { .name = "h", .plan_text = "name: h", .config_snapshot = "{}",
				      .software_version = "test", .created_at = 1000, .plan_kind = kind };
	int64_t id = 0;
	struct acq_err err = { 0 };
	assert_int_equal(store_sweep_create(st, &nw, pts, n, &id, &err), 0);
	float c[4] = { 1, 2, 3, 4 };
	for (int i = 0; i < n; i++) {
		int order;
		int64_t pt;
		assert_int_equal(store_sweep_next_point(st, id, &order, &pt, &err), 0);
		struct store_spectrum sp = { .sweep_id = id, .point_id = pt, .kind = "sample", .integration_ms = 10,
					     .averages = 4, .npix = 4, .counts = c, .temperature_c = NAN,
					     .taken_at = 2000 + every * i, .completes_point = true, .laser_theta = 10,
					     .detector_theta = 30, .detector_phi = 0, .theta_i = 10, .phi_i = 0, .theta_o = 30,
					     .phi_o = 0 };
		assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), 0);
	}
	assert_int_equal(store_sweep_set_state(st, id, state, 3000, &err), 0);
	return id;
}

static int64_t mk_host_sweep(struct store *st, int n, double every, const char *state)
{
	return mk_host_sweep_kind(st, n, every, state, NULL);
}

/* The host's time per point from the latest completed sweep of any sample (a plan without its sample's prior): at
 * time scale 10, points committed every 0.5 s, each the probe at 10 ms and an exposure of 4 x 10 ms with read-out
 * and round trip, of which the probe was one scan (at the previous point's time, exp_probe_reusable: 3 taken):
 * 0.5 - (0.01 + 0.015 + 0.03 + 0.015) / 10 s. Not from a sweep with fewer than EXP_HOST_MIN_POINTS
 * points measured, an unfinished one, or the excluded one. */
static void test_host_latest(void **state)
{
	(void)state;
	char p[300];
	struct store *st = ut_store_new(p, sizeof p, ut_dir, "h.db");
	struct bench_geom g;
	bench_defaults(&g);
	g.readout_s = 0.01;
	struct plan_timing t;
	plan_timing_defaults(&t);
	t.exposure_overhead_s = 0.005;
	t.time_scale = 10;
	struct acq_err err = { 0 };
	double host = -1;
	long long sweep = -1;
	assert_int_equal(exp_host_load(st, 0, NULL, &g, &t, &host, &sweep, &err), 0);
	assert_true(sweep == 0 && host == -1); /* no sweep yet */
	int64_t a = mk_host_sweep(st, EXP_HOST_MIN_POINTS + 1, 0.5, "completed");
	mk_host_sweep(st, EXP_HOST_MIN_POINTS + 1, 0.3, "aborted");
	assert_int_equal(exp_host_load(st, 0, NULL, &g, &t, &host, &sweep, &err), 0);
	assert_int_equal(sweep, a);
	assert_true(fabs(host - (0.5 - 0.07 / 10)) < 1e-9);
	/* a newer completed sweep too short to time the host: none (the default stays) */
	int64_t b = mk_host_sweep(st, EXP_HOST_MIN_POINTS, 0.4, "completed");
	host = -1;
	assert_int_equal(exp_host_load(st, 0, NULL, &g, &t, &host, &sweep, &err), 0);
	assert_true(sweep == 0 && host == -1);
	/* excluded: the one before */
	assert_int_equal(exp_host_load(st, b, NULL, &g, &t, &host, &sweep, &err), 0);
	assert_int_equal(sweep, a);
	store_close(st);
}

/* The timing of test_host_latest's sweeps (time scale 10, 10 ms read-out, 5 ms per exposure). */
static void host_timing(struct bench_geom *g, struct plan_timing *t)
{
	bench_defaults(g);
	g->readout_s = 0.01;
	plan_timing_defaults(t);
	t->exposure_overhead_s = 0.005;
	t->time_scale = 10;
}

/* The host's figure by plan kind: a grid auto sweep (0.5 s per point) then a newer Fibonacci fixed one (0.3 s): a
 * grid auto plan is timed by the first, a Fibonacci fixed one by the second, an adaptive plan (no sweep of its kind)
 * by the latest of any kind; a sweep without a recorded kind (before schema 6) times only plans of any kind. */
static void test_host_kind(void **state)
{
	(void)state;
	char p[300];
	struct store *st = ut_store_new(p, sizeof p, ut_dir, "k.db");
	struct bench_geom g;
	struct plan_timing t;
	host_timing(&g, &t);
	struct acq_err err = { 0 };
	int64_t old = mk_host_sweep(st, EXP_HOST_MIN_POINTS + 1, 0.7, "completed");
	int64_t a = mk_host_sweep_kind(st, EXP_HOST_MIN_POINTS + 1, 0.5, "completed", "grid/auto");
	int64_t b = mk_host_sweep_kind(st, EXP_HOST_MIN_POINTS + 1, 0.3, "completed", "fibonacci/fixed");
	double host = -1;
	long long sweep = -1;
	assert_int_equal(exp_host_load(st, 0, "grid/auto", &g, &t, &host, &sweep, &err), 0);
	assert_int_equal(sweep, a);
	assert_true(fabs(host - (0.5 - 0.07 / 10)) < 1e-9);
	assert_int_equal(exp_host_load(st, 0, NULL, &g, &t, &host, &sweep, &err), 0);
	assert_int_equal(sweep, b);
	assert_int_equal(exp_host_load(st, 0, "adaptive/auto", &g, &t, &host, &sweep, &err), 0);
	assert_int_equal(sweep, 0);
	struct exp_host_cache c = { 0 };
	assert_int_equal(exp_host_cached(&c, st, 0, &g, &t, &err), 0);
	assert_int_equal(t.host_sweep, b);
	assert_int_equal(t.n_host_kind, 2);
	struct plan_spec grid = { .integ_mode = PLAN_INTEG_AUTO }, fib = { .fib_count = 10, .integ_mode = PLAN_INTEG_FIXED };
	struct plan_adaptive ad = { 0 };
	struct plan_spec adapt = { .integ_mode = PLAN_INTEG_AUTO, .adaptive = &ad };
	char kind[PLAN_KIND_MAX];
	assert_string_equal(plan_kind_of(&grid, kind), "grid/auto");
	assert_string_equal(plan_kind_of(&fib, kind), "fibonacci/fixed");
	assert_string_equal(plan_kind_of(&adapt, kind), "adaptive/auto");
	/* every kind a plan can have is one the cache enumerates (plan_kind_name), and the six are distinct */
	bool seen[PLAN_HOST_KINDS] = { false };
	for (int c3 = 0; c3 < 8; c3++) {
		struct plan_spec s = { .integ_mode = c3 & 1 ? PLAN_INTEG_FIXED : PLAN_INTEG_AUTO,
				       .fib_count = c3 & 2 ? 10 : 0, .adaptive = c3 & 4 ? &ad : NULL };
		int i = plan_kind_index(&s);
		assert_true(i >= 0 && i < PLAN_HOST_KINDS);
		char name[PLAN_KIND_MAX];
		assert_non_null(plan_kind_name(i, name));
		assert_string_equal(plan_kind_of(&s, kind), name);
		seen[i] = true;
	}
	for (int i = 0; i < PLAN_HOST_KINDS; i++) {
		assert_true(seen[i]);
		char ni[PLAN_KIND_MAX], nj[PLAN_KIND_MAX];
		for (int j = 0; j < i; j++)
			assert_string_not_equal(plan_kind_name(i, ni), plan_kind_name(j, nj));
	}
	assert_null(plan_kind_name(PLAN_HOST_KINDS, kind));
	assert_null(plan_kind_name(-1, kind));
	bool own = false;
	assert_true(fabs(plan_time_host(&grid, &t, &sweep, &own) - (0.5 - 0.07 / 10)) < 1e-9);
	assert_true(sweep == a && own);
	assert_true(fabs(plan_time_host(&fib, &t, &sweep, &own) - (0.3 - 0.07 / 10)) < 1e-9);
	assert_true(sweep == b && own);
	assert_true(fabs(plan_time_host(&adapt, &t, &sweep, &own) - (0.3 - 0.07 / 10)) < 1e-9);
	assert_true(sweep == b && !own);
	/* without b no Fibonacci sweep is left: the latest of any kind (a, a grid) times the Fibonacci plan; the old
	 * sweep without a kind never times a plan of a kind */
	assert_int_equal(exp_host_cached(&c, st, b, &g, &t, &err), 0);
	assert_true(fabs(plan_time_host(&fib, &t, &sweep, &own) - (0.5 - 0.07 / 10)) < 1e-9);
	assert_true(sweep == a && !own);
	(void)old;
	store_close(st);
}

/* exp_host_cached reads the database once, then not again until a sweep completes (or exclude changes, or the cache
 * is dropped): a newer completed sweep's figure is seen at the next call; an aborted one changes nothing. */
static void test_host_cache(void **state)
{
	(void)state;
	char p[300];
	struct store *st = ut_store_new(p, sizeof p, ut_dir, "c.db");
	struct bench_geom g;
	struct plan_timing t;
	host_timing(&g, &t);
	struct acq_err err = { 0 };
	struct exp_host_cache c = { 0 };
	assert_int_equal(exp_host_cached(&c, st, 0, &g, &t, &err), 0);
	assert_true(c.reads == 1 && t.host_sweep == 0 && t.n_host_kind == 0);
	int64_t a = mk_host_sweep_kind(st, EXP_HOST_MIN_POINTS + 1, 0.5, "completed", "grid/auto");
	assert_int_equal(exp_host_cached(&c, st, 0, &g, &t, &err), 0); /* a sweep completed: read again */
	assert_true(c.reads == 2 && t.host_sweep == a && t.n_host_kind == 1);
	for (int i = 0; i < 3; i++) /* the `plan` requests after it: no read */
		assert_int_equal(exp_host_cached(&c, st, 0, &g, &t, &err), 0);
	assert_int_equal(c.reads, 2);
	mk_host_sweep_kind(st, EXP_HOST_MIN_POINTS + 1, 0.3, "aborted", "grid/auto");
	assert_int_equal(exp_host_cached(&c, st, 0, &g, &t, &err), 0);
	assert_true(c.reads == 2 && t.host_sweep == a);
	int64_t b = mk_host_sweep_kind(st, EXP_HOST_MIN_POINTS + 1, 0.4, "completed", "grid/auto");
	assert_int_equal(exp_host_cached(&c, st, 0, &g, &t, &err), 0);
	assert_true(c.reads == 3 && t.host_sweep == b && t.host_kind[0].sweep == b);
	assert_true(fabs(t.host_kind[0].host_s - (0.4 - 0.07 / 10)) < 1e-9);
	assert_int_equal(exp_host_cached(&c, st, b, &g, &t, &err), 0); /* another exclude: read again */
	assert_true(c.reads == 4 && t.host_sweep == a);
	exp_host_cache_drop(&c);
	assert_int_equal(exp_host_cached(&c, st, b, &g, &t, &err), 0);
	assert_int_equal(c.reads, 5);
	store_close(st);
}

static void test_plan_sample_key(void **state)
{
	(void)state;
	const char *base = "name: t\nincidence: {theta_deg: [20]}\nobservation: {theta_deg: [30], phi_deg: [0]}\n";
	char text[512];
	struct plan_spec *s = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(plan_load_string("t.yaml", base, &s, &err), 0);
	assert_string_equal(s->sample, "");
	plan_spec_free(s);
	snprintf(text, sizeof text, "%ssample: green paint A3\n", base);
	assert_int_equal(plan_load_string("t.yaml", text, &s, &err), 0);
	assert_string_equal(s->sample, "green paint A3");
	plan_spec_free(s);
	snprintf(text, sizeof text, "%ssample: \"\"\n", base);
	assert_int_equal(plan_load_string("t.yaml", text, &s, &err), -1);
	assert_non_null(strstr(err.msg, "sample"));
	snprintf(text, sizeof text, "%ssample: \"a\\tb\"\n", base);
	assert_int_equal(plan_load_string("t.yaml", text, &s, &err), -1);
	assert_non_null(strstr(err.msg, "control character"));
	snprintf(text, sizeof text, "%ssample: %064d\n", base, 7);
	assert_int_equal(plan_load_string("t.yaml", text, &s, &err), -1);
	assert_non_null(strstr(err.msg, "1 to 63"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_prior_figures),
		cmocka_unit_test(test_prior_host),
		cmocka_unit_test(test_host_latest),
		cmocka_unit_test(test_host_kind),
		cmocka_unit_test(test_host_cache),
		cmocka_unit_test(test_plan_sample_key),
	};
	return cmocka_run_group_tests(tests, ut_dir_setup, ut_dir_teardown);
}
