/* Unit tests of daemon/plan/plan_time.c: the executor's costs per step recomputed independently from the step's
 * motion (ordering model) and the timing parameters: one read-out per exposure, the integration ladder in auto
 * mode, probes, darks per incidence, the host's time per point times the time scale, the reference phase. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <cmocka.h>
#include <jansson.h>

#include "config/bench.h"
#include "daemon/executor.h"
#include "daemon/exposure.h"
#include "daemon/plan/plan.h"

#define TOL 1e-9 /* sums of a few dozen doubles of order 1-100 s */

static const char *PLAN_FIXED = "name: t\nincidence: {theta_deg: [20, 45]}\n"
				"observation: {theta_deg: [30, 60], phi_deg: [0, 90, 180, 270]}\n"
				"integration: {mode: fixed, ms: 20}\naverages: 3\nblind_points: drop\n";
/* one viewing zenith and spread 1: every point at the estimate's rung */
static const char *PLAN_AUTO = "name: t\nincidence: {theta_deg: [20, 45]}\n"
			       "observation: {theta_deg: [30], phi_deg: [0, 45, 90, 135, 180, 225, 270, 315]}\n"
			       "integration: {mode: auto, estimate_ms: 20, max_ms: 2000, spread: 1, hdr_fraction: 0}\n"
			       "averages: 3\n"
			       "blind_points: drop\n";
/* The sample's own spread 4 at one zenith, and the plan's zeniths 30° and 60° spread the times by
 * (cos 30°/cos 60°)² = 3 more: S = 12 */
static const char *PLAN_SPREAD = "name: t\nincidence: {theta_deg: [20, 45]}\n"
				 "observation: {theta_deg: [30, 60], phi_deg: [0, 90, 180, 270]}\n"
				 "integration: {mode: auto, estimate_ms: 20, max_ms: 2000, spread: 4, hdr_fraction: 0}\n"
				 "averages: 3\n"
				 "blind_points: drop\n";

/* predicted_s as the sum of its terms (plan.h) */
static double terms_sum(const struct plan_result *r)
{
	return r->reference_s + r->t_motion_s + r->t_settle_s + r->t_probe_s + r->darks_s + r->t_first_s + r->t_hdr_s +
	       r->host_s;
}

struct fx {
	struct bench_geom g;
	struct plan_spec *spec;
	struct plan_result *res;
};

static void load(struct fx *f, const char *text)
{
	struct acq_err err = { 0 };
	bench_defaults(&f->g);
	f->g.readout_s = 0.01;
	assert_int_equal(plan_load_string("t.yaml", text, &f->spec, &err), 0);
	assert_int_equal(plan_make(f->spec, &f->g, &f->res, &err), 0);
	assert_true(f->res->n_steps > 4);
}

static void unload(struct fx *f)
{
	plan_result_free(f->res);
	plan_spec_free(f->spec);
}

static struct plan_timing timing(void)
{
	struct plan_timing t;
	plan_timing_defaults(&t);
	t.reference = false;
	t.dark_averages = 8;
	t.exposure_overhead_s = 0.005;
	t.axis_poll_s = 0.05;
	t.point_overhead_s = 0.02;
	t.time_scale = 1;
	t.min_ms = 0.01;
	t.ladder_ratio = sqrt(2.0);
	return t;
}

/* Step i by hand: move + settle + polling when it moves, [probe, less the scan a pooled probe spares the exposure in
 * a share `pool` of the points], exposure, [dark], host time. */
static double by_hand(const struct fx *f, const struct plan_timing *t, size_t i, double ms, double probe_ms,
		      double pool)
{
	const struct plan_step *st = &f->res->steps[i];
	bool moves = st->move_s + st->settle_s > 0;
	bool new_inc = i == 0 || st->pos.laser_theta != f->res->steps[i - 1].pos.laser_theta;
	double shot_ovh = f->g.readout_s + t->exposure_overhead_s; /* one read-out per exposure, any averages */
	double d = st->move_s + st->settle_s + (moves ? PLAN_MOVE_POLLS * t->axis_poll_s + t->extra_settle_s : 0);
	if (probe_ms > 0)
		d += probe_ms / 1000 + shot_ovh - (probe_ms == ms ? pool * ms / 1000 : 0); /* the first: at the estimate */
	d += f->spec->averages * ms / 1000 + shot_ovh;
	if (new_inc)
		d += t->dark_averages * ms / 1000 + shot_ovh;
	return d + t->point_overhead_s * t->time_scale;
}

static void test_fixed_steps(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_FIXED);
	struct plan_timing t = timing();
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double sum = 0, darks = 0;
	for (size_t i = 0; i < f.res->n_steps; i++) {
		double d = by_hand(&f, &t, i, 20, 0, 0);
		assert_true(fabs(f.res->steps[i].predicted_s - d) < TOL);
		assert_true(fabs(f.res->steps[i].predicted_start_s - sum) < TOL);
		sum += d;
		bool new_inc = i == 0 || f.res->steps[i].pos.laser_theta != f.res->steps[i - 1].pos.laser_theta;
		darks += new_inc ? 8 * 0.020 + 0.015 : 0;
	}
	assert_true(fabs(f.res->predicted_s - sum) < TOL);
	assert_true(fabs(f.res->darks_s - darks) < TOL);
	assert_true(f.res->reference_s == 0);
	/* fixed integration: no probe, no HDR exposure; every term sums to the total */
	assert_true(f.res->t_probe_s == 0 && f.res->t_hdr_s == 0);
	assert_true(fabs(f.res->t_first_s - (double)f.res->n_steps * (3 * 0.020 + 0.015)) < TOL);
	assert_true(fabs(terms_sum(f.res) - f.res->predicted_s) < TOL);
	/* two incidences: two darks */
	assert_true(fabs(darks - 2 * (8 * 0.020 + 0.015)) < TOL);
	unload(&f);
}

/* The host's time per point is real time: a simulated bench at time scale S sees it S times longer. */
static void test_time_scale(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_FIXED);
	struct plan_timing t = timing();
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double p1 = f.res->predicted_s;
	t.time_scale = 35;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(f.res->predicted_s - p1 - 34 * 0.02 * (double)f.res->n_steps) < TOL);
	unload(&f);
}

/* Auto integration: the estimate 20 ms on the ladder 0.01 ms · √2^k is 14.48 ms (k = 21); a probe per point,
 * the first at the estimate itself when there is no reference before it. */
static void test_auto_ladder(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_AUTO);
	struct plan_timing t = timing();
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double rung = 0.01 * pow(sqrt(2.0), 21);
	assert_true(rung < 20 && rung * sqrt(2.0) > 20);
	for (size_t i = 0; i < f.res->n_steps; i++) {
		double d = by_hand(&f, &t, i, rung, i == 0 ? 20 : rung, PLAN_PROBE_POOL);
		assert_true(fabs(f.res->steps[i].predicted_s - d) < 1e-6);
	}
	unload(&f);
}

/* Auto integration with the sample's spread: times log-uniform over a band S wide around the estimate, rounded
 * down to the ladder: each exposure and probe at est · (√S - 1/√S)/ln S · (1 - 1/√2)/ln √2, and a dark at the j-th
 * point of an incidence with probability (1 - 1/k)^j, k = 1 + ln S / ln √2 rungs: over an incidence of n points
 * k(1 - (1 - 1/k)^n) darks, more than the one of spread 1 and at most one per point. */
static void test_auto_spread(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_SPREAD);
	struct plan_timing t = timing();
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double c = cos(30 * M_PI / 180) / cos(60 * M_PI / 180), S = 4 * c * c, r2 = sqrt(2.0);
	double mean = 20 * (sqrt(S) - 1 / sqrt(S)) / log(S) * (1 - 1 / r2) / log(r2), k = 1 + log(S) / log(r2);
	assert_true(fabs(S - 12) < 1e-9 && mean > 21 && mean < 22 && k > 8 && k < 8.5);
	double shot_ovh = f.g.readout_s + t.exposure_overhead_s, dark = 8 * mean / 1000 + shot_ovh;
	double darks = 0, sum = 0;
	size_t j = 0;
	for (size_t i = 0; i < f.res->n_steps; i++) {
		const struct plan_step *st = &f.res->steps[i];
		bool new_inc = i == 0 || st->pos.laser_theta != f.res->steps[i - 1].pos.laser_theta;
		j = new_inc ? 0 : j + 1;
		double p = pow(1 - 1 / k, (double)j);
		double d = st->move_s + st->settle_s + (st->move_s + st->settle_s > 0 ? PLAN_MOVE_POLLS * t.axis_poll_s : 0) +
			   (i == 0 ? 20.0 : mean) / 1000 + shot_ovh + 3 * mean / 1000 + shot_ovh + p * dark +
			   t.point_overhead_s - (i ? PLAN_PROBE_POOL * mean / 1000 : 0);
		assert_true(fabs(st->predicted_s - d) < 1e-9);
		darks += p * dark;
		sum += d;
	}
	assert_true(fabs(f.res->darks_s - darks) < 1e-9);
	assert_true(fabs(f.res->predicted_s - sum) < 1e-9);
	/* two incidences of 8 (or 7) points: between 2 and 2k darks, k(1 - (1 - 1/k)^n) each */
	double n_darks = darks / dark;
	assert_true(n_darks > 2 * k * (1 - pow(1 - 1 / k, 7)) - 1e-9 && n_darks < 2 * k * (1 - pow(1 - 1 / k, 8)) + 1e-9);
	/* longer than with every point at the estimate's rung (spread 1 at one zenith: test_auto_ladder) */
	double spread = f.res->predicted_s;
	f.spec->integ_spread = 1;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(spread > f.res->predicted_s); /* the geometry alone (S = 3) still spreads the times */
	unload(&f);
}

/* HDR exposures: a fraction h of the points takes a second exposure at hdr_ratio times the estimate's rung (its
 * dark one the longer base times took already); none when the executor takes one exposure per point (max_exposures 1). */
static void test_auto_hdr(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_SPREAD);
	struct plan_timing t = timing();
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double without = f.res->predicted_s, darks0 = f.res->darks_s;
	f.spec->integ_hdr = 0.5;
	t.hdr_ratio = 8;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double rung = 0.01 * pow(sqrt(2.0), 21); /* the estimate's: 14.48 ms */
	double ovh = f.g.readout_s + t.exposure_overhead_s;
	double extra = (double)f.res->n_steps * 0.5 * (3 * 8 * rung / 1000 + ovh);
	assert_true(fabs(f.res->predicted_s - without - extra) < 1e-9);
	assert_true(fabs(f.res->darks_s - darks0) < 1e-12);
	t.max_exposures = 1;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(f.res->predicted_s - without) < 1e-9);
	unload(&f);
}

/* The reference phase: from the arms' position to the reference pose, probe/dark/exposure there, then to the
 * first point; the steps start after it. */
static void test_reference(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_FIXED);
	struct plan_timing t = timing();
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double without = f.res->predicted_s;
	t.reference = true;
	t.ref_pose = (struct plan_pos){ 0, 45, 180 };
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(f.res->reference_s > 8 * 0.02 + 3 * 0.02); /* at least the dark and the exposures */
	assert_true(fabs(f.res->steps[0].predicted_start_s - f.res->reference_s) < TOL);
	/* fixed integration: the first incidence uses the reference's dark (auto: the reference's time is the white
	 * standard's, so the first point takes its own) */
	double dark = 8 * 0.020 + 0.015;
	assert_true(fabs(f.res->darks_s - dark) < TOL);
	assert_true(fabs(f.res->predicted_s - (without - dark) - f.res->reference_s) < TOL);
	assert_true(fabs(terms_sum(f.res) - f.res->predicted_s) < TOL);
	/* the arms elsewhere: the move to the reference pose is added */
	double ref = f.res->reference_s;
	t.have_start = true;
	t.start = (struct plan_pos){ 60, 10, 300 };
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(f.res->reference_s > ref + 1);
	unload(&f);
}

/* A dark when the last one has aged (dark_max_age_s), whatever the incidence. */
static void test_dark_age(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_FIXED);
	struct plan_timing t = timing();
	t.dark_max_age_s = 0; /* never by age: one per incidence */
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double dark = 8 * 0.020 + 0.015, per_incidence = f.res->darks_s;
	assert_true(fabs(per_incidence - 2 * dark) < TOL);
	t.dark_max_age_s = 1.5 * f.res->predicted_s / (double)f.res->n_steps; /* about every 1.5 points */
	plan_time_apply(f.spec, &f.g, &t, f.res);
	int n = (int)lround(f.res->darks_s / dark);
	assert_true(fabs(f.res->darks_s - n * dark) < TOL);
	assert_true(n >= (int)f.res->n_steps / 3 && n <= (int)f.res->n_steps);
	unload(&f);
}

/* dark_every -1: the executor keeps each integration time's dark across incidences (by age only). Without a prior
 * the band's rungs decay over the whole sweep: the i-th point takes a dark with probability (1 - 1/k)^i, not
 * restarting at the second incidence (fixed integration: one dark for the sweep). With a prior, an incidence pays
 * the darks of the rungs its row used that no earlier incidence did, each at its rung's time, spread over its
 * points as the j-th takes (new darks / k)·(1 - 1/k)^j of them, k its row's rungs; the rest of each step as with
 * dark_every 0. */
static void test_dark_keep(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_SPREAD); /* incidences 20° and 45°, 8 points each (or 7) */
	struct plan_timing t = timing();
	t.dark_max_age_s = 0;
	t.dark_every = 0;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double per_incidence = f.res->darks_s, total0 = f.res->predicted_s;
	t.dark_every = -1;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double shot_ovh = f.g.readout_s + t.exposure_overhead_s, mean, darks = 0;
	double r2 = sqrt(2.0), ls = log(12.0);
	mean = 20 * (sqrt(12.0) - 1 / sqrt(12.0)) / ls * (1 - 1 / r2) / log(r2);
	double k = 1 + ls / log(r2), dark = 8 * mean / 1000 + shot_ovh;
	for (size_t i = 0; i < f.res->n_steps; i++)
		darks += (i == 0 ? 1 : pow(1 - 1 / k, (double)i)) * dark;
	assert_true(fabs(f.res->darks_s - darks) < TOL);
	assert_true(f.res->darks_s < per_incidence - 0.5 * dark); /* fewer than two incidences' worth */
	assert_true(fabs(f.res->predicted_s - total0 - (f.res->darks_s - per_incidence)) < TOL); /* only darks change */
	assert_true(fabs(terms_sum(f.res) - f.res->predicted_s) < TOL);

	/* with a prior: 20° used rungs 24-26 (41, 58, 82 ms: 3 darks), 45° rungs 25-28 (to 164 ms): 27, 28 new there */
	t.prior = (struct plan_prior){ .sweep = 7, .n_inc = 2 };
	t.prior.inc[0] = (struct plan_prior_inc){ .theta_i = 20, .points = 8, .median_ms = 40, .mean_ms = 60,
						  .spread = 8, .darks_per_clear = 3, .dark_ms = 90,
						  .rungs = 7ull << 24 };
	t.prior.inc[1] = (struct plan_prior_inc){ .theta_i = 45, .points = 8, .median_ms = 100, .mean_ms = 150,
						  .spread = 4, .darks_per_clear = 4, .dark_ms = 150,
						  .rungs = 15ull << 25 };
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double rung[64];
	for (int b = 0; b < 64; b++)
		rung[b] = 8 * 0.01 * pow(r2, b) / 1000 + shot_ovh; /* a dark at rung b: min_ms 0.01 */
	double new20 = rung[24] + rung[25] + rung[26], new45 = rung[27] + rung[28];
	darks = 0;
	size_t j = 0;
	double sum = 0;
	for (size_t i = 0; i < f.res->n_steps; i++) {
		const struct plan_step *st = &f.res->steps[i];
		bool new_inc = i == 0 || st->pos.laser_theta != f.res->steps[i - 1].pos.laser_theta;
		j = new_inc ? 0 : j + 1;
		bool low = fabs(st->pos.laser_theta) < 30;
		double kk = low ? 3 : 4, d = (low ? new20 : new45) / kk * pow(1 - 1 / kk, (double)j);
		darks += d;
		sum += st->predicted_s;
	}
	assert_true(fabs(f.res->darks_s - darks) < TOL);
	assert_true(fabs(f.res->predicted_s - sum) < TOL);
	/* the same prior with dark_every 0: each incidence's own darks_per_clear at dark_ms, more than the new rungs */
	double kept = f.res->darks_s;
	t.dark_every = 0;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(f.res->darks_s > kept + 2 * rung[24]);
	unload(&f);
}

/* An exposure prior (plan.h) times each incidence with the nearest prior incidence's figures: the probe and the
 * measurement at its mean first exposure, one dark per clearing and then a new one with probability (1 - 1/k)^j for
 * its k darks at their mean time, its HDR exposures per point; the plan's estimate then only sets the first probe. */
static void test_prior(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_SPREAD); /* incidences 20° and 45° */
	struct plan_timing t = timing();
	t.prior = (struct plan_prior){ .sweep = 7, .n_inc = 2 };
	/* rows at 18° and 50°: the plan's 20° takes the first, 45° the second (the nearest) */
	t.prior.inc[0] = (struct plan_prior_inc){ .theta_i = 18, .points = 9, .median_ms = 40, .mean_ms = 60,
						  .spread = 8, .darks_per_clear = 3, .dark_ms = 90, .extra_per_point = 0.25,
						  .extra_ms = 320 };
	t.prior.inc[1] = (struct plan_prior_inc){ .theta_i = 50, .points = 9, .median_ms = 100, .mean_ms = 150,
						  .spread = 4, .darks_per_clear = 1, .dark_ms = 150, .extra_per_point = 0,
						  .extra_ms = 0 };
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double shot_ovh = f.g.readout_s + t.exposure_overhead_s, sum = 0, darks = 0;
	/* the terms by hand: motion, settle (with polling), probes, first exposures, HDR exposures, host */
	double motion = 0, settle = 0, probes = 0, firsts = 0, hdrs = 0, host = 0;
	size_t j = 0;
	for (size_t i = 0; i < f.res->n_steps; i++) {
		const struct plan_step *st = &f.res->steps[i];
		bool new_inc = i == 0 || st->pos.laser_theta != f.res->steps[i - 1].pos.laser_theta;
		j = new_inc ? 0 : j + 1;
		const struct plan_prior_inc *q = &t.prior.inc[fabs(st->pos.laser_theta) < 30 ? 0 : 1];
		double p = new_inc ? 1 : pow(1 - 1 / q->darks_per_clear, (double)j); /* k = 1: no second dark */
		double dark = 8 * q->dark_ms / 1000 + shot_ovh;
		double se = st->settle_s + (st->move_s + st->settle_s > 0 ? PLAN_MOVE_POLLS * t.axis_poll_s : 0);
		double pb = (i == 0 ? 20.0 : q->mean_ms) / 1000 + shot_ovh, fe = 3 * q->mean_ms / 1000 + shot_ovh;
		double hd = q->extra_per_point * (3 * q->extra_ms / 1000 + shot_ovh);
		double d = st->move_s + se + pb + fe + p * dark + hd + t.point_overhead_s;
		assert_true(fabs(st->predicted_s - d) < TOL);
		motion += st->move_s;
		settle += se;
		probes += pb;
		firsts += fe;
		hdrs += hd;
		host += t.point_overhead_s;
		darks += p * dark;
		sum += d;
	}
	assert_true(fabs(f.res->darks_s - darks) < TOL);
	assert_true(fabs(f.res->predicted_s - sum) < TOL);
	const struct plan_result *r = f.res;
	assert_true(fabs(r->t_motion_s - motion) < TOL && fabs(r->t_settle_s - settle) < TOL);
	assert_true(fabs(r->t_probe_s - probes) < TOL && fabs(r->t_first_s - firsts) < TOL);
	assert_true(fabs(r->t_hdr_s - hdrs) < TOL && fabs(r->host_s - host) < TOL && r->reference_s == 0);
	assert_true(motion > 1 && settle > 1 && probes > 0.1 && firsts > 0.1 && hdrs > 0.1 && darks > 0.1);
	assert_true(fabs(terms_sum(r) - r->predicted_s) < TOL);
	/* the host's time per point the prior's sweep measured replaces the default (at the time scale) */
	t.prior.host_per_point_s = 0.004;
	t.prior.host_points = 40;
	t.time_scale = 35;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(r->host_s - 0.004 * 35 * (double)r->n_steps) < TOL);
	assert_true(fabs(r->predicted_s - (sum - host + r->host_s)) < TOL);
	assert_true(fabs(terms_sum(r) - r->predicted_s) < TOL);
	t.prior.host_points = 0; /* not measured: the default */
	t.time_scale = 1;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(r->predicted_s - sum) < TOL);
	/* with the prior, the estimate only moves the first probe: 80 ms instead of 20 adds 60 ms */
	double at20 = f.res->predicted_s;
	f.spec->integ_ms = 80;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(f.res->predicted_s - at20 - 0.060) < TOL);
	/* a fixed plan ignores the prior; an auto plan without one (sweep 0) is the band model again */
	f.spec->integ_ms = 20;
	t.prior.sweep = 0;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double band = f.res->predicted_s;
	assert_true(fabs(band - at20) > 1);
	struct plan_timing t0 = timing();
	plan_time_apply(f.spec, &f.g, &t0, f.res);
	assert_true(fabs(f.res->predicted_s - band) < TOL);
	unload(&f);
	load(&f, PLAN_FIXED);
	plan_time_apply(f.spec, &f.g, &t0, f.res);
	double fixed = f.res->predicted_s;
	t.prior.sweep = 7;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(f.res->predicted_s - fixed) < TOL);
	unload(&f);
}

/* The model's defaults (what `acqctl plan` uses without a daemon; the daemon takes them from its configuration,
 * sweep_plan_timing) are the executor's and the auto exposure's own defaults, as plan_time.c's comments say: a
 * default changed in one place and not the other times every daemonless dry run wrong. */
static void test_defaults_match(void **state)
{
	(void)state;
	struct plan_timing t;
	plan_timing_defaults(&t);
	struct ex_cfg ex;
	ex_cfg_defaults(&ex);
	struct exp_policy pol;
	exp_policy_defaults(&pol);
	assert_true(t.probe_ms == pol.probe_ms && t.probe_ms == ex.pol.probe_ms);
	assert_true(t.ladder_ratio == ex.ladder_ratio);
	assert_true(t.exposure_overhead_s == ex.poll_s / 2);
	assert_true(t.extra_settle_s == ex.extra_settle_s);
	assert_int_equal(t.dark_averages, (int)pol.dark_averages);
	assert_int_equal(t.dark_every, ex.dark_every);
	assert_true(t.dark_max_age_s == pol.dark_max_age_s);
	assert_int_equal(t.max_exposures, pol.max_exposures);
	assert_true(t.hdr_ratio == pol.hdr_ratio);
	assert_true(t.reference == ex.take_reference);
	assert_true(t.ref_pose.laser_theta == ex.ref_pose.laser_theta && t.ref_pose.det_theta == ex.ref_pose.det_theta &&
		    t.ref_pose.det_phi == ex.ref_pose.det_phi);
}

/* predicted_s of PLAN_AUTO with its estimate replaced by est_ms, planned from its own text (independent of the
 * reply's way of varying the estimate) */
static double auto_at(const struct plan_timing *t, const char *est)
{
	char text[1024];
	const char *at = strstr(PLAN_AUTO, "estimate_ms: 20");
	assert_non_null(at);
	snprintf(text, sizeof text, "%.*sestimate_ms: %s%s", (int)(at - PLAN_AUTO), PLAN_AUTO, est,
		 at + strlen("estimate_ms: 20"));
	struct fx f;
	load(&f, text);
	plan_time_apply(f.spec, &f.g, t, f.res);
	double s = f.res->predicted_s;
	unload(&f);
	return s;
}

/* A first auto sweep's dry run says the estimate it assumed and the same model's time for a sample needing half
 * and twice it; the plan itself (its steps) stays timed at the estimate. With a prior, or fixed integration: no
 * such figures (the times are known). */
static void test_estimate_range(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_AUTO);
	struct plan_timing t = timing();
	json_t *o = plan_dry_run_json(f.spec, &f.g, &t, f.res, false);
	assert_non_null(o);
	json_t *es = json_object_get(o, "estimate");
	assert_true(json_is_object(es));
	double nominal = auto_at(&t, "20"), half = auto_at(&t, "10"), twice = auto_at(&t, "40");
	assert_true(half < nominal && nominal < twice);
	assert_true(fabs(json_real_value(json_object_get(es, "ms")) - 20) < TOL);
	assert_true(fabs(json_real_value(json_object_get(es, "predicted_at_half_s")) - half) < TOL);
	assert_true(fabs(json_real_value(json_object_get(es, "predicted_at_double_s")) - twice) < TOL);
	/* the plan's own figures are the estimate's: the reply's and every step's */
	assert_true(fabs(json_real_value(json_object_get(o, "predicted_s")) - nominal) < TOL);
	double last = f.res->steps[f.res->n_steps - 1].predicted_start_s;
	json_decref(o);
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(f.res->steps[f.res->n_steps - 1].predicted_start_s - last) < TOL);
	/* a first sweep's survey (survey: -1, the prior lacks the incidences: one point of each here, at most an eighth
	 * of its 8): the dry run orders it first and says what it adds to the route's time */
	f.spec->survey = -1;
	o = plan_dry_run_json(f.spec, &f.g, &t, f.res, false);
	json_t *sv = json_object_get(o, "survey");
	assert_true(json_is_object(sv));
	assert_int_equal(json_integer_value(json_object_get(sv, "points")), 2);
	assert_int_equal(f.res->n_survey, 2);
	assert_true(fabs(json_real_value(json_object_get(o, "predicted_s")) - nominal -
			 json_real_value(json_object_get(sv, "cost_s"))) < TOL);
	json_decref(o);
	/* with an exposure prior the sample's times are known */
	t.prior = (struct plan_prior){ .sweep = 3, .n_inc = 1 };
	t.prior.inc[0] = (struct plan_prior_inc){ .theta_i = 30, .points = 8, .median_ms = 50, .mean_ms = 55,
						  .spread = 2, .darks_per_clear = 2, .dark_ms = 60 };
	o = plan_dry_run_json(f.spec, &f.g, &t, f.res, false);
	assert_non_null(o);
	assert_null(json_object_get(o, "estimate"));
	json_decref(o);
	unload(&f);
	load(&f, PLAN_FIXED);
	t = timing();
	o = plan_dry_run_json(f.spec, &f.g, &t, f.res, false);
	assert_non_null(o);
	assert_null(json_object_get(o, "estimate"));
	json_decref(o);
	unload(&f);
}

/* The steepest change of ln(mean exposure) per degree between the prior's adjacent rows (in zenith order, whatever
 * the rows' order), at least PLAN_EXPO_SLOPE_MIN; PLAN_EXPO_SLOPE_ONE with one row. */
static void test_prior_slope(void **state)
{
	(void)state;
	struct plan_prior p = { .sweep = 1, .n_inc = 3 };
	p.inc[0] = (struct plan_prior_inc){ .theta_i = 20, .points = 5, .mean_ms = 160 };
	p.inc[1] = (struct plan_prior_inc){ .theta_i = 0, .points = 5, .mean_ms = 100 };
	p.inc[2] = (struct plan_prior_inc){ .theta_i = 10, .points = 5, .mean_ms = 150 };
	/* 0 -> 10°: ln 1.5 / 10; 10 -> 20°: ln(160/150) / 10; not 0 -> 20° as the array's neighbours would give */
	assert_true(fabs(plan_prior_slope(&p) - log(1.5) / 10) < TOL);
	p.inc[0].mean_ms = 101; /* flat: the floor */
	p.inc[2].mean_ms = 100.5;
	assert_true(fabs(plan_prior_slope(&p) - PLAN_EXPO_SLOPE_MIN) < TOL);
	p.inc[2].mean_ms = 30; /* a fall counts as a rise does: ln(101/30) / 10 */
	assert_true(fabs(plan_prior_slope(&p) - log(101.0 / 30) / 10) < TOL);
	p.n_inc = 1;
	assert_true(fabs(plan_prior_slope(&p) - PLAN_EXPO_SLOPE_ONE) < TOL);
}

/* The interval of an auto plan's time where its exposures are unknown: with no prior every exposure at the policy's
 * reach (min_ms, the plan's max_ms) by hand; with a prior row at 20° only, the 45° incidence timed as by a row of
 * its own whose times are the 20° row's times exp(-/+ g · 25°); none when both incidences are measured. */
static void test_interval(void **state)
{
	(void)state;
	struct fx f;
	load(&f, PLAN_AUTO); /* 20° and 45°, estimate 20 ms, max 2000 ms, no HDR */
	struct plan_timing t = timing();
	size_t n = f.res->n_steps;
	double lo_at[64], hi_at[64], lo, hi;
	assert_true(n + 1 <= 64);
	assert_int_equal(plan_time_interval(f.spec, &f.g, &t, f.res, lo_at, hi_at, &lo, &hi), PLAN_IV_POLICY);
	double pred = f.res->predicted_s, blo = 0, bhi = 0;
	for (size_t i = 0; i < n; i++) { /* the first probe at the estimate, every other exposure and dark at the end */
		assert_true(fabs(lo_at[i] - blo) < TOL && fabs(hi_at[i] - bhi) < TOL);
		blo += by_hand(&f, &t, i, 0.01, i ? 0.01 : 20, 1); /* every point at min_ms: each probe pooled */
		bhi += by_hand(&f, &t, i, 2000, i ? 2000 : 20, 0); /* none: the upper end */
	}
	assert_true(fabs(lo - blo) < TOL && fabs(hi - bhi) < TOL);
	assert_true(fabs(lo_at[n] - lo) < TOL && fabs(hi_at[n] - hi) < TOL);
	assert_true(lo < pred && pred < hi && hi > 2 * pred);
	/* r is left timed at the point estimate */
	double p0 = f.res->predicted_s;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(f.res->predicted_s - p0) < TOL);
	/* the dry run's reply carries it */
	json_t *o = plan_dry_run_json(f.spec, &f.g, &t, f.res, false);
	json_t *iv = json_object_get(o, "interval");
	assert_true(json_is_object(iv));
	assert_string_equal(json_string_value(json_object_get(iv, "basis")), "policy");
	assert_true(fabs(json_real_value(json_object_get(iv, "low_s")) - lo) < TOL);
	assert_true(fabs(json_real_value(json_object_get(iv, "high_s")) - hi) < TOL);
	json_decref(o);

	/* one measured incidence (20°): 45° is 25° away, its times scaled by exp(-/+ PLAN_EXPO_SLOPE_ONE · 25) */
	t.dark_every = -1;
	t.prior = (struct plan_prior){ .sweep = 4, .n_inc = 1 };
	struct plan_prior_inc q = { .theta_i = 20, .points = 8, .median_ms = 50, .mean_ms = 60, .spread = 2,
				    .darks_per_clear = 2, .dark_ms = 70, .extra_per_point = 0.25, .extra_ms = 400,
				    .rungs = (uint64_t)1 << plan_rung(&t, 60) | (uint64_t)1 << plan_rung(&t, 85) };
	t.prior.inc[0] = q;
	assert_int_equal(plan_time_interval(f.spec, &f.g, &t, f.res, lo_at, hi_at, &lo, &hi), PLAN_IV_EXTRAPOLATED);
	pred = f.res->predicted_s;
	double end[2];
	for (int e = 0; e < 2; e++) {
		double fac = exp((e ? 1 : -1) * PLAN_EXPO_SLOPE_ONE * 25);
		int shift = (int)lround(log(fac) / log(sqrt(2.0)));
		struct plan_timing u = t;
		u.prior.n_inc = 2;
		/* its HDR share: none at the low end, the measured rows' most (0.25) at the high end */
		u.prior.inc[1] = (struct plan_prior_inc){ .theta_i = 45, .points = 8, .median_ms = 50 * fac,
							  .mean_ms = 60 * fac, .spread = 2, .darks_per_clear = 2,
							  .dark_ms = 70 * fac, .extra_per_point = e ? 0.25 : 0,
							  .extra_ms = fmin(400 * fac, 2000),
							  .rungs = (uint64_t)1 << (plan_rung(&t, 60) + shift) |
								   (uint64_t)1 << (plan_rung(&t, 85) + shift) };
		plan_time_apply(f.spec, &f.g, &u, f.res);
		end[e] = f.res->predicted_s;
		/* the 20° steps are the point estimate's at both ends */
		for (size_t i = 0; i < n && f.res->steps[i].pos.laser_theta < 30; i++)
			assert_true(fabs((e ? hi_at : lo_at)[i] - f.res->steps[i].predicted_start_s) < TOL);
	}
	assert_true(fabs(lo - end[0]) < TOL && fabs(hi - end[1]) < TOL);
	assert_true(lo < pred - 0.1 && pred + 0.5 < hi);
	/* both incidences measured: no interval, both ends the prediction */
	t.prior.n_inc = 2;
	t.prior.inc[1] = q;
	t.prior.inc[1].theta_i = 45.2;
	assert_int_equal(plan_time_interval(f.spec, &f.g, &t, f.res, lo_at, hi_at, &lo, &hi), PLAN_IV_NONE);
	assert_true(lo == f.res->predicted_s && hi == f.res->predicted_s && lo_at[n] == hi);
	o = plan_dry_run_json(f.spec, &f.g, &t, f.res, false);
	assert_null(json_object_get(o, "interval"));
	json_decref(o);
	unload(&f);
	/* fixed integration: none */
	load(&f, PLAN_FIXED);
	t = timing();
	assert_int_equal(plan_time_interval(f.spec, &f.g, &t, f.res, NULL, NULL, &lo, &hi), PLAN_IV_NONE);
	assert_true(lo == hi);
	unload(&f);
}

/* An incidence beyond the prior's zeniths follows the three end rows' trend at half its slope when they rise (or
 * fall) monotonically: timed as by a row of its own with the end row's times scaled; not when they do not, nor with
 * prior_trend off, nor for an incidence between measured rows. */
static void test_prior_trend(void **state)
{
	(void)state;
	struct fx f;
	load(&f, "name: t\nincidence: {theta_deg: [20, 27.5, 35, 50]}\n"
		 "observation: {theta_deg: [30], phi_deg: [0, 45, 90, 135, 180, 225, 270, 315]}\n"
		 "integration: {mode: auto, estimate_ms: 20, max_ms: 2000, spread: 1, hdr_fraction: 0}\naverages: 3\n"
		 "blind_points: drop\n");
	struct plan_timing t = timing();
	assert_true(t.prior_trend); /* the model's default */
	t.prior = (struct plan_prior){ .sweep = 5, .n_inc = 3 };
	double mean[3] = { 60, 80, 100 }, th[3] = { 35, 20, 27.5 }; /* the rows in any order */
	for (int i = 0; i < 3; i++) {
		double m = mean[th[i] == 20 ? 0 : th[i] == 27.5 ? 1 : 2];
		t.prior.inc[i] = (struct plan_prior_inc){ .theta_i = th[i], .points = 8, .median_ms = m, .mean_ms = m,
							  .spread = 2, .darks_per_clear = 2, .dark_ms = m,
							  .extra_per_point = 0.5, .extra_ms = 4 * m };
	}
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double trend = f.res->predicted_s;
	/* by hand: a fourth row at 50° = the 35° row times exp(0.5 · ln(100/60)/15 · 15) = (5/3)^0.5 */
	double fac = sqrt(100.0 / 60);
	struct plan_timing u = t;
	u.prior_trend = false;
	plan_time_apply(f.spec, &f.g, &u, f.res);
	double nearest = f.res->predicted_s;
	u.prior.n_inc = 4;
	u.prior.inc[3] = (struct plan_prior_inc){ .theta_i = 50, .points = 8, .median_ms = 100 * fac,
						  .mean_ms = 100 * fac, .spread = 2, .darks_per_clear = 2,
						  .dark_ms = 100 * fac, .extra_per_point = 0.5, .extra_ms = 400 * fac };
	plan_time_apply(f.spec, &f.g, &u, f.res);
	assert_true(fabs(trend - f.res->predicted_s) < TOL);
	assert_true(trend > nearest + 0.5);
	/* not monotone (60, 80, 70): the nearest row */
	t.prior.inc[0].mean_ms = 70;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double bumpy = f.res->predicted_s;
	t.prior_trend = false;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(bumpy - f.res->predicted_s) < TOL);
	/* a falling trend lowers it: 100, 80, 60 */
	t.prior_trend = true;
	t.prior.inc[0].mean_ms = 60;  /* 35° */
	t.prior.inc[1].mean_ms = 100; /* 20° */
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double fall = f.res->predicted_s;
	t.prior_trend = false;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fall < f.res->predicted_s - 0.2);
	/* rows at 20, 35 and 50° rising: the plan's 27.5° lies between them, no trend (the nearest row's times) */
	t.prior.inc[0] = t.prior.inc[1] = t.prior.inc[2] = (struct plan_prior_inc){ .points = 8, .spread = 2,
										     .darks_per_clear = 2 };
	for (int i = 0; i < 3; i++) {
		t.prior.inc[i].theta_i = 20 + 15 * i;
		t.prior.inc[i].mean_ms = t.prior.inc[i].median_ms = t.prior.inc[i].dark_ms = 60 + 20 * i;
	}
	t.prior_trend = true;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	double between = f.res->predicted_s;
	t.prior_trend = false;
	plan_time_apply(f.spec, &f.g, &t, f.res);
	assert_true(fabs(between - f.res->predicted_s) < TOL);
	unload(&f);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_fixed_steps),
		cmocka_unit_test(test_time_scale),
		cmocka_unit_test(test_auto_ladder),
		cmocka_unit_test(test_auto_spread),
		cmocka_unit_test(test_auto_hdr),
		cmocka_unit_test(test_reference),
		cmocka_unit_test(test_dark_age),
		cmocka_unit_test(test_prior),
		cmocka_unit_test(test_dark_keep),
		cmocka_unit_test(test_defaults_match),
		cmocka_unit_test(test_estimate_range),
		cmocka_unit_test(test_prior_slope),
		cmocka_unit_test(test_interval),
		cmocka_unit_test(test_prior_trend),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
