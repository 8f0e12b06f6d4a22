/* plan_time: the planner's duration model of a sweep as the executor runs it (see plan.h, struct plan_timing).
 *
 * The ordering model (plan.c) times each step as trapezoidal moves (each axis's acceleration and velocity
 * profile, the slowest axis wins) + settling + averages × (integration + read-out): that is what the order
 * optimises, and it stays as it is. The executor spends more per step, and this model adds it:
 *   - a move is seen finished by polling the controllers: first at its predicted end, again a little later
 *     when the controller is behind, then a read confirms the axis stayed in position after settling
 *     (PLAN_MOVE_POLLS periods, plan.h: 0.1; 1.5 when the driver polled every period from the start), plus
 *     sweep.extra_settle_s;
 *   - an exposure of n averages at t ms lasts n·t, then the spectrometer's read-out (once per exposure: the
 *     AvaSpec averages on board and reads out about 10 ms after the last scan, shared/docs/avaspec-usb.md;
 *     acq-sim does the same), then a start/poll/fetch round trip (exposure_overhead_s, half a poll period);
 *   - auto integration: the executor rounds every time down to its ladder min_ms · ladder_ratio^k (so that
 *     darks can be reused), probes once per point at the previous point's time (the first probe at the plan's
 *     estimate), and takes a dark for each ladder time it has not taken one for since the cache was cleared
 *     (new incidence, dark_every, age). The sample decides those times: it needs a different time in every
 *     direction (on the simulated green paint 14.5 to 116 ms within one incidence for a 20 ms estimate). The
 *     model takes its times log-uniformly over a band of integration.spread (longest / shortest, default
 *     PLAN_AUTO_SPREAD) around the estimate, on the ladder's k rungs there: each exposure and probe at their
 *     mean, and the j-th point after a clearing needs a dark with probability (1 - 1/k)^j (its rung not yet
 *     visited), k(1 - (1 - 1/k)^n) darks for n points. spread: 1 is the old model (every point at the estimate,
 *     one dark per incidence). This was the term the model missed: auto plans ran 7-11 % longer than predicted,
 *     all of it from darks at the sample's other times (6 instead of 2 in the quick plan) and the longer
 *     integration (tests/bench/bench_duration.py, timeline per point);
 *   - darks (dark_averages exposures at the point's integration) at each new incidence, or every dark_every
 *     points, and when the last one is dark_max_age_s old; the first points reuse the reference's dark when
 *     the integration time is fixed (the executor's dark cache keeps it). dark_every -1 (session 16; the
 *     shipped configurations'): the executor keeps each time's dark across incidences until it ages (the laser
 *     is off for a dark: the incidence does not enter it), so the band's rungs decay over the whole sweep, not
 *     per incidence, and with a prior an incidence pays only the darks of the rungs its row used that have
 *     no dark yet or an aged one (plan_prior_inc.rungs; each rung's dark aged alone, as the executor does, at
 *     the incidence's start). Measured (tests/bench/bench_duration.py, seed 1): the
 *     metal's paper plan 865.9 -> 337.5 bench s of darks, the cloth-sheen's 184.8 -> 77.9;
 *   - the host's own time per point (point_overhead_s real seconds: calibration, storage, round trips), which
 *     a simulated bench running time_scale times faster sees time_scale times longer in bench seconds; with an
 *     exposure prior, the host's time per point its sweep measured (exp_prior_build: the real time between commits
 *     beyond the bench's part) instead of the default: the host, not the sample, made the paper plan's repeat at
 *     time scale 35 run shorter than predicted (session 9, tests/bench/bench_duration.py's terms: each exposure
 *     term of the repeat within 0.4 s of what it took, the host 10.3-17.9 ms per point by the load against the
 *     default's 16; the default is now a quiet machine's figure, 6.5 ms, see plan_timing_defaults);
 *   - the reference at the start: the move to ref_pose from where the arms are (when known: the daemon knows,
 *     a local dry run does not), probe, dark and the plan's averages there, then the move from ref_pose to
 *     the first point (the first step has no move in the ordering model).
 *   - auto integration, HDR: a fraction integration.hdr_fraction of the points (default PLAN_AUTO_HDR, 0.09 on the
 *     simulated green paint) takes a second exposure at hdr_ratio times the first's time when max_exposures > 1,
 *     its darks mostly those the longer base times took already (not counted again);
 *   - auto integration, the pooled probe (session 17): a point whose probe (at the previous point's time) says that
 *     time is its own counts the probe as one of its first exposure's scans (executor_acq.c, exp_probe_reusable)
 *     and takes one scan fewer; a share PLAN_PROBE_POOL of the points without a prior, the prior row's
 *     pooled_per_point with one (its points whose first time was the previous point's, exp_prior_build);
 *   - an exposure prior (t->prior, from the previous auto sweep of the same sample; plan.h): each incidence takes
 *     the nearest prior incidence's figures instead of the band: its mean first exposure for the probe and the
 *     measurement, its darks (as many distinct times as it needed, at their mean time) and its HDR exposures per
 *     point. The repeat of a sweep is then timed by what the sample took, whatever estimate the plan gives;
 *   - where the sample's exposures are unknown (no prior, or incidences the prior has not measured) the model
 *     also gives an interval (plan_time_interval, below), and an incidence beyond the measured zeniths follows the
 *     end rows' monotone trend at half its slope (trend_row; session 17, README "How long a sweep takes");
 * Not modelled: saturation redos, fault recovery, the operator's sample swap; the live ETA (daemon/eta.c) adds the time per
 * point the sweep has measured beyond this model. */
#include "daemon/plan/plan.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

void plan_timing_defaults(struct plan_timing *t)
{
	*t = (struct plan_timing){
		.axis_poll_s = 0.05,          /* drivers/axis_modbus_cfg.c poll_s default */
		.extra_settle_s = 0,          /* sweep.extra_settle_s default */
		.probe_ms = 10,               /* daemon/exposure.c probe_ms default */
		.min_ms = 1,                  /* daemon/conf.c sweep.min_integration_ms default */
		.ladder_ratio = M_SQRT2,      /* daemon/executor.c ladder_ratio default */
		.exposure_overhead_s = 0.005, /* executor spectrometer poll 10 ms: half a period per exposure */
		.dark_averages = 10,          /* exposure.c dark_averages default */
		.dark_every = 0,
		.dark_max_age_s = 600,        /* exposure.c dark_max_age_s default */
		.max_exposures = 3,           /* exposure.c max_exposures default */
		.hdr_ratio = 8,               /* exposure.c hdr_ratio default */
		.reference = true,
		.ref_pose = { 0.0, 45.0, 180.0 }, /* executor.c reference_pose default */
		/* the host's time per point (real seconds: calibration, storage, protocol round trips, the arms' command
		 * delivery) when nothing better is known (the daemon uses what its latest completed sweep measured,
		 * sweep_plan_prior), measured with tests/bench/bench_duration.py as what a sweep took between commits
		 * beyond this model's bench part (exp_prior_build's host figure), the paper plan at time scale 35 on a
		 * quiet machine (session 14, load 0.3-3.7, nothing else or little running), restated for this model's
		 * price of a move (PLAN_MOVE_POLLS 0.1; each figure + (price it was measured at - 0.1) x 50 ms / 35):
		 * the old driver and price 1.5 (load 0.3-1.5) 5.09, 5.87, 6.23 -> 6.4, 7.2, 7.5 ms; at 1.5 with load 3.6
		 * 5.30 -> 6.6; the new driver at price 1.0 (load 2-3.7) 4.72, 5.23 -> 6.0, 6.5: the median, 6.5 ms.
		 * A bench PC runs nothing else, so the default is the quiet figure. The same sweeps on the shared
		 * development machine under load took 10.3-15.2 ms at price 1.5 (sessions 9-10, load 9-20; 12.1-12.9 at
		 * load 8-13 in session 13) and up to 25 ms in bursts: CPU contention, not work. The default of sessions
		 * 10-13, 13.5 ms (the loaded median at price 1.5), made the quiet first sweep's prediction 9-10 % long;
		 * a loaded machine's first sweep is now predicted short (about 10 % at session 13's loads; the live ETA
		 * measures its host, eta.c), its later ones are timed by the latest sweep's own figure. At time scale 1
		 * the host is well under 1 % of a point. Reported apart as host_s. */
		.point_overhead_s = 0.0065,
		.time_scale = 1,
		.prior_trend = true,          /* trend_row; an adaptive spec never (its candidates' prices) */
	};
}

double plan_move_time_s(const struct bench_geom *g, const struct plan_timing *t, const struct plan_pos *a,
			const struct plan_pos *b)
{
	double mv = plan_straight_s(g, a, b);
	return mv > 0 ? mv + PLAN_MOVE_POLLS * t->axis_poll_s + t->extra_settle_s : 0;
}

int plan_pose_parse(const struct yc_node *n, const char *what, struct plan_pos *out, struct acq_err *err)
{
	double v[3];
	if (yc_expect_seq(n, what, err))
		return -1;
	if (n->n != 3)
		return yc_errf(err, n, "%s: expected [laser.theta, detector.theta, detector.phi]", what);
	for (int i = 0; i < 3; i++)
		if (yc_node_double(n->items[i], what, -360, 720, &v[i], err))
			return -1;
	*out = (struct plan_pos){ v[0], v[1], v[2] };
	return 0;
}

/* The executor's integration ladder (executor_acq.c quantize): rounded down to min_ms · ratio^k, within
 * [min_ms, max_ms]. */
static double ladder(const struct plan_timing *t, double ms, double max_ms)
{
	double r = t->ladder_ratio > 1.0001 ? t->ladder_ratio : M_SQRT2;
	if (!(t->min_ms > 0) || !(ms > t->min_ms))
		return t->min_ms > 0 ? t->min_ms : ms;
	if (max_ms > 0 && ms >= max_ms)
		return max_ms;
	double k = floor(log(ms / t->min_ms) / log(r) + 1e-9);
	return t->min_ms * pow(r, k);
}

int plan_rung(const struct plan_timing *t, double ms)
{
	double r = t->ladder_ratio > 1.0001 ? t->ladder_ratio : M_SQRT2, lo = t->min_ms > 0 ? t->min_ms : 1;
	double k = ms > lo ? round(log(ms / lo) / log(r)) : 0;
	return k > 63 ? 63 : (int)k;
}

/* One exposure of n averages at ms: integration, one read-out, the round trip. */
static double shot(const struct bench_geom *g, const struct plan_timing *t, double n, double ms)
{
	return n * ms / 1000.0 + g->readout_s + t->exposure_overhead_s;
}

/* Auto integration: the sample's times log-uniform over a band of width S (longest / shortest) whose geometric
 * middle is the estimate; the executor rounds each down to the ladder (ratio r: on average by (1 - 1/r)/ln r,
 * 0.845 for √2). Returns the expected number of rungs the band covers, 1 + ln S / ln r, and the expected time of
 * an exposure in *mean_ms: est · (√S - 1/√S) / ln S · (1 - 1/r) / ln r, within [min_ms, max_ms]. S = 1: the
 * estimate's own rung, one rung. */
static double auto_band(const struct plan_timing *t, double est_ms, double spread, double max_ms, double *mean_ms)
{
	double r = t->ladder_ratio > 1.0001 ? t->ladder_ratio : M_SQRT2;
	if (!(spread > 1.0001)) {
		*mean_ms = ladder(t, est_ms, max_ms);
		return 1;
	}
	double ls = log(spread), m = est_ms * (sqrt(spread) - 1 / sqrt(spread)) / ls * (1 - 1 / r) / log(r);
	if (t->min_ms > 0 && m < t->min_ms)
		m = t->min_ms;
	if (max_ms > 0 && m > max_ms)
		m = max_ms;
	*mean_ms = m;
	return 1 + ls / log(r);
}

/* The band's width for plan s: the sample's own spread at one viewing zenith (integration.spread, default
 * PLAN_AUTO_SPREAD) times the geometry's, (cos θo_min / cos θo_max)² over the plan's points: the signal from the lit
 * spot falls with the viewing zenith (the projected spot, and the paint's own fall towards grazing). The square is
 * empirical, from the simulated green paint: the quick plan (θo 30-60°) chose 14.5-81.9 ms within an incidence
 * (5.7x; 2 · 1.73² = 6), the paper plan (θo 0-81°) 16-256x within an incidence with a mean time 1.7x its median
 * (2 · 6.4² = 82); the first power fits one of them, not both. */
static double plan_spread(const struct plan_spec *s, const struct plan_result *r)
{
	double sample = s->integ_spread > 0 ? s->integ_spread : PLAN_AUTO_SPREAD;
	double cmin = 1, cmax = 0;
	for (size_t i = 0; i < r->n_steps; i++) {
		double c = cos(fabs(r->steps[i].pos.det_theta) * M_PI / 180);
		cmin = fmin(cmin, c);
		cmax = fmax(cmax, c);
	}
	return cmin > 0.01 && cmax >= cmin ? sample * (cmax / cmin) * (cmax / cmin) : sample;
}

/* ms within the plan's max_ms (auto). */
static double max_ms_of(const struct plan_spec *s, double ms)
{
	return s->max_integ_ms > 0 && ms > s->max_integ_ms ? s->max_integ_ms : ms;
}

/* The costs of one point of an incidence: its probe and measurement, a dark when one is due, the HDR term, and k,
 * the number of distinct times the dark cache needs there. */
struct inc_cost {
	double probe, meas, dark, hdr, k;
	double pool; /* seconds the pooled probe saves a point on average (pooled_s × the share of points pooling) */
};

/* What a pooled probe saves its point (executor_acq.c: the probe at the exposure's own time is its first scan): one
 * scan of n averages at ms, or the whole exposure when n is 1. */
static double pooled_s(const struct bench_geom *g, const struct plan_timing *t, double n, double ms)
{
	return n > 1 ? ms / 1000.0 : shot(g, t, 1, ms);
}

/* The prior's row for incidence zenith theta_i (degrees): the nearest one. */
static const struct plan_prior_inc *prior_row(const struct plan_prior *p, double theta_i)
{
	const struct plan_prior_inc *best = NULL;
	for (size_t i = 0; i < p->n_inc && i < PLAN_PRIOR_MAX_INC; i++)
		if (!best || fabs(p->inc[i].theta_i - theta_i) < fabs(best->theta_i - theta_i))
			best = &p->inc[i];
	return best;
}

static struct plan_prior_inc scaled_row(const struct plan_spec *s, const struct plan_timing *t,
					const struct plan_prior_inc *q, double theta_i, double f);

/* The prior's row for an incidence at theta_i when t->prior_trend: beyond the measured zeniths, when the three
 * measured rows at that end rise (or fall) monotonically, the end row's times scaled by exp(w · s · Δθ), s the
 * three rows' slope of ln(mean time) per degree, w = PLAN_TREND_WEIGHT; else (or between measured rows) the nearest
 * row, *q itself. Chosen on the simulated bench's paper-plan rows (seed 1; the rest's summed mean first exposure
 * after m = 4..8 measured incidences against what followed): the nearest row metal -31/-23/-18/-10/-1 %, cloth-sheen
 * +12/+11/+11/+10/+6 %, green paint -1/-1/-3/-7/-7 %; the full trend (w 1) metal +6/+17/+13/+13/+17 % (its rise
 * levels off past 52.5°), cloth +12/+3/+5/+4/-1, green -1/-1/-3/-10/-7; w 1/2 metal -15/-5/-4/+1/+8, cloth
 * +12/+7/+8/+7/+2, green -1/-1/-3/-8/-7. A plain log-linear fit over all rows (session 16) was 8-18 % off on the
 * green paint: its rows are not monotone, so no trend is taken there. */
static struct plan_prior_inc trend_row(const struct plan_spec *s, const struct plan_timing *t,
				       const struct plan_prior *p, const struct plan_prior_inc *q, double theta_i)
{
	size_t n = p->n_inc < PLAN_PRIOR_MAX_INC ? p->n_inc : PLAN_PRIOR_MAX_INC;
	const struct plan_prior_inc *e[3] = { NULL, NULL, NULL };
	bool above = true;
	for (size_t i = 0; i < n; i++) {
		if (!(p->inc[i].mean_ms > 0) || p->inc[i].points == 0)
			continue;
		if (p->inc[i].theta_i >= theta_i - PLAN_PRIOR_SAME_DEG)
			above = false;
	}
	bool below = true;
	for (size_t i = 0; i < n; i++)
		if (p->inc[i].mean_ms > 0 && p->inc[i].points > 0 && p->inc[i].theta_i <= theta_i + PLAN_PRIOR_SAME_DEG)
			below = false;
	if (!t->prior_trend || s->adaptive || (!above && !below))
		return *q;
	/* the three measured rows nearest theta_i (all on one side of it): e[0] the nearest */
	for (size_t i = 0; i < n; i++) {
		const struct plan_prior_inc *r = &p->inc[i];
		if (!(r->mean_ms > 0) || r->points == 0)
			continue;
		for (int k = 0; k < 3; k++)
			if (!e[k] || fabs(r->theta_i - theta_i) < fabs(e[k]->theta_i - theta_i)) {
				for (int j = 2; j > k; j--)
					e[j] = e[j - 1];
				e[k] = r;
				break;
			}
	}
	if (!e[2] || fabs(e[0]->theta_i - e[2]->theta_i) < 1)
		return *q;
	double d1 = log(e[0]->mean_ms / e[1]->mean_ms), d2 = log(e[1]->mean_ms / e[2]->mean_ms);
	if (!(d1 * d2 > 0))
		return *q;
	double slope = log(e[0]->mean_ms / e[2]->mean_ms) / (e[0]->theta_i - e[2]->theta_i);
	return scaled_row(s, t, e[0], theta_i, exp(PLAN_TREND_WEIGHT * slope * (theta_i - e[0]->theta_i)));
}

/* An incidence timed by the prior's row q: the times the previous sweep of the sample took there (each point's
 * first exposure at the mean, the darks it needed, its HDR exposures per point), not the band around the estimate. */
static struct inc_cost prior_cost(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
				  const struct plan_prior_inc *q)
{
	struct inc_cost c;
	c.probe = shot(g, t, 1, q->mean_ms);
	c.meas = shot(g, t, s->averages, q->mean_ms);
	c.dark = shot(g, t, t->dark_averages, q->dark_ms > 0 ? q->dark_ms : q->mean_ms);
	c.hdr = q->extra_per_point > 0 ? q->extra_per_point * shot(g, t, s->averages, q->extra_ms) : 0;
	c.k = q->darks_per_clear >= 1 ? q->darks_per_clear : 1;
	c.pool = q->pooled_per_point > 0
			 ? q->pooled_per_point * pooled_s(g, t, s->averages, q->pooled_ms > 0 ? q->pooled_ms : q->mean_ms)
			 : 0;
	return c;
}

/* The band's costs of a plan whose radiance spread is `spread`: auto integration, the band around the estimate
 * (est_ms: the first probe's time) and the HDR exposure a fraction h of the points needs, at hdr_ratio times a typical
 * first time (paper plan on green paint: 76 HDR exposures of 326 ms on average, 8 x 40.96 ms, the rung of its 50 ms
 * estimate); its darks are those of the longer base times the incidence has taken already (paper plan: 100 darks in
 * all, 10 per incidence, what the base rungs alone give). Fixed integration: the spec's time, one rung. */
static struct inc_cost band_cost(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
				 double est_ms, double spread)
{
	bool aut = s->integ_mode == PLAN_INTEG_AUTO;
	double ms = s->integ_ms, k = 1;
	if (aut)
		k = auto_band(t, est_ms, spread, s->max_integ_ms, &ms);
	double h = aut && t->max_exposures > 1 && t->hdr_ratio > 1 ? (s->integ_hdr >= 0 ? s->integ_hdr : PLAN_AUTO_HDR) : 0;
	return (struct inc_cost){
		aut ? shot(g, t, 1, ms) : 0, shot(g, t, s->averages, ms), shot(g, t, t->dark_averages, ms),
		h > 0 ? h * shot(g, t, s->averages, max_ms_of(s, t->hdr_ratio * ladder(t, est_ms, s->max_integ_ms))) : 0, k,
		aut ? PLAN_PROBE_POOL * pooled_s(g, t, s->averages, ms) : 0
	};
}

/* dark_every -1 with a prior, an incidence starting at clock: the darks of the rungs in `want` that have none in the
 * cache or one dark_max_age_s old (taken[k]: when rung k's was taken, -INFINITY never; those taken are set to
 * clock, as the executor ages each time's dark alone), each dark_averages exposures at its rung's time. */
static double new_rung_darks(const struct bench_geom *g, const struct plan_timing *t, uint64_t want, double clock,
			     double *taken)
{
	double r = t->ladder_ratio > 1.0001 ? t->ladder_ratio : M_SQRT2, lo = t->min_ms > 0 ? t->min_ms : 1, s = 0;
	for (int k = 0; k < 64; k++)
		if (want >> k & 1 &&
		    (!isfinite(taken[k]) || (t->dark_max_age_s > 0 && clock - taken[k] >= t->dark_max_age_s))) {
			s += shot(g, t, t->dark_averages, lo * pow(r, k));
			taken[k] = clock;
		}
	return s;
}

static int popcount64(uint64_t v)
{
	int n = 0;
	for (; v; v &= v - 1)
		n++;
	return n;
}

/* The sample's exposure prior the timing uses (auto integration with a prior), or NULL. */
static const struct plan_prior *used_prior(const struct plan_spec *s, const struct plan_timing *t)
{
	return s->integ_mode == PLAN_INTEG_AUTO && t->prior.sweep > 0 && t->prior.n_inc > 0 ? &t->prior : NULL;
}

/* The plan kinds' one vocabulary: a kind's index is layout × KIND_MODES + mode. */
static const char *const kind_layouts[] = { "grid", "fibonacci", "adaptive" };
static const char *const kind_modes[] = { "auto", "fixed" };
#define KIND_LAYOUTS (int)(sizeof kind_layouts / sizeof *kind_layouts)
#define KIND_MODES (int)(sizeof kind_modes / sizeof *kind_modes)
_Static_assert(sizeof kind_layouts / sizeof *kind_layouts * (sizeof kind_modes / sizeof *kind_modes) ==
		       PLAN_HOST_KINDS,
	       "PLAN_HOST_KINDS counts every plan kind");

int plan_kind_index(const struct plan_spec *s)
{
	int layout = s->adaptive ? 2 : s->fib_count > 0 ? 1 : 0, mode = s->integ_mode == PLAN_INTEG_AUTO ? 0 : 1;
	return layout * KIND_MODES + mode;
}

const char *plan_kind_name(int i, char *buf)
{
	if (i < 0 || i >= PLAN_HOST_KINDS)
		return NULL;
	snprintf(buf, PLAN_KIND_MAX, "%s/%s", kind_layouts[i / KIND_MODES], kind_modes[i % KIND_MODES]);
	return buf;
}

const char *plan_kind_of(const struct plan_spec *s, char *buf)
{
	return plan_kind_name(plan_kind_index(s), buf);
}

/* The host's time per point differs by kind (the quick fixed plan 5.1 ms at time scale 10, the paper's auto plan
 * 10-15 ms at 35: fewer exposures and requests per point), so a plan takes its own kind's figure when the daemon
 * has one, and the latest sweep's of any kind only when not. */
double plan_time_host(const struct plan_spec *s, const struct plan_timing *t, long long *sweep, bool *own_kind)
{
	char kind[PLAN_KIND_MAX];
	plan_kind_of(s, kind);
	for (int i = 0; i < t->n_host_kind && i < PLAN_HOST_KINDS; i++)
		if (!strcmp(t->host_kind[i].kind, kind)) {
			*sweep = t->host_kind[i].sweep;
			*own_kind = true;
			return t->host_kind[i].host_s;
		}
	*sweep = t->host_sweep;
	*own_kind = false;
	return t->point_overhead_s;
}

/* The host's seconds per point: as the prior's sweep measured it on this host, else plan_time_host's. */
static double host_s(const struct plan_spec *s, const struct plan_timing *t, const struct plan_prior *pr)
{
	long long sweep;
	bool own;
	return (pr && pr->host_points > 0 ? pr->host_per_point_s : plan_time_host(s, t, &sweep, &own)) * t->time_scale;
}

void plan_time_apply(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
		     struct plan_result *r)
{
	bool aut = s->integ_mode == PLAN_INTEG_AUTO;
	/* the executor's first probe is at the plan's estimate when it gives one (sweep.c), else at probe_ms;
	 * the next ones at the previous point's time */
	double est_ms = s->integ_ms > 0 ? s->integ_ms : t->probe_ms;
	struct inc_cost band = band_cost(s, g, t, est_ms, plan_spread(s, r)), c = band;
	double first_probe = aut ? shot(g, t, 1, est_ms) : 0, meas = band.meas, dark = band.dark;
	double clock = 0, dark_at = -INFINITY;
	double since_clear = t->cont ? t->cont_since_clear : 0; /* points since the dark cache was last cleared */
	const struct plan_prior *pr = used_prior(s, t);
	/* dark_every -1 (darks kept across incidences, refreshed by age): with a prior, each incidence pays the darks
	 * of the rungs its prior row used that have no dark yet or an aged one (new_rung_darks), spread over its points
	 * as the j-th takes one with probability (1 - 1/k)^j, k its row's rungs; without, the band's rungs decay over
	 * the whole sweep (restarting only when the last clearing has aged) instead of at each incidence */
	bool keep = t->dark_every < 0;
	const struct plan_prior_inc *row = NULL;
	struct plan_prior_inc trow; /* the row an unmeasured incidence is timed by (trend_row) */
	double taken[64];
	for (int k = 0; k < 64; k++)
		taken[k] = -INFINITY;
	double inc_darks = 0, inc_k = 1, since_inc = 0;
	double host = host_s(s, t, pr);
	r->reference_s = r->darks_s = r->t_motion_s = r->t_settle_s = r->t_probe_s = r->t_first_s = r->t_hdr_s = 0;
	r->host_s = host * (double)r->n_steps;
	if (r->n_steps > 0) {
		/* from where the arms are (when known) to the reference pose, the reference, then to the first point */
		const struct plan_pos *first = &r->steps[0].pos;
		if (t->have_start)
			r->reference_s += plan_move_time_s(g, t, &t->start, t->reference ? &t->ref_pose : first);
		if (t->reference) {
			r->reference_s += first_probe;
			dark_at = r->reference_s; /* fixed integration: the first points use the reference's dark */
			r->reference_s += dark + meas + plan_move_time_s(g, t, &t->ref_pose, first);
		}
		clock = r->reference_s;
	}
	if (t->cont)
		dark_at = 0; /* a continued sweep: its dark's age is counted from the batch's start (plan_timing_continue) */
	for (size_t i = 0; i < r->n_steps; i++) {
		struct plan_step *st = &r->steps[i];
		bool moves = st->move_s + st->settle_s > 0;
		bool new_inc = i == 0 || st->pos.laser_theta != r->steps[i - 1].pos.laser_theta;
		if (pr && new_inc) {
			trow = trend_row(s, t, pr, prior_row(pr, fabs(st->pos.laser_theta)), fabs(st->pos.laser_theta));
			row = &trow;
			c = prior_cost(s, g, t, row);
		}
		/* the dark cache is cleared every dark_every points or at each new incidence, and a dark is due when
		 * the last one has aged; the first point uses the reference's dark when it has the same (fixed) time */
		double prev_laser = i ? r->steps[i - 1].pos.laser_theta : t->cont_laser;
		bool clear = i == 0 && !t->cont ? aut || !t->reference
			    : t->dark_every > 0 ? ((t->cont ? (size_t)t->cont_since_clear : 0) + i) % (size_t)t->dark_every == 0
			    : t->dark_every == 0 ? fabs(st->pos.laser_theta - prev_laser) > 1e-6
						 : false;
		if (t->dark_max_age_s > 0 && clock - dark_at >= t->dark_max_age_s)
			clear = true;
		if (clear)
			since_clear = 0;
		/* expected darks: fixed, one per clearing; auto, one per rung first visited since the clearing (the
		 * point's rung is new with probability (1 - 1/k)^j after j points) */
		double p_dark = clear ? 1.0 : aut ? pow(1.0 - 1.0 / c.k, since_clear) : 0.0;
		double dark_s = p_dark * c.dark;
		if (keep && aut && row && row->rungs) {
			if (new_inc) {
				inc_darks = new_rung_darks(g, t, row->rungs, clock, taken);
				inc_k = popcount64(row->rungs);
				since_inc = 0;
			}
			dark_s = inc_darks / inc_k * pow(1.0 - 1.0 / inc_k, since_inc++);
		}
		double settle = st->settle_s + (moves ? PLAN_MOVE_POLLS * t->axis_poll_s + t->extra_settle_s : 0);
		bool first = i == 0 && !t->reference;
		double pr_s = first ? first_probe : c.probe;
		double pool = first ? 0 : c.pool; /* the first probe, at the estimate, is at no rung of the exposure's */
		double d = st->move_s + settle + pr_s + c.meas - pool + dark_s + c.hdr + host;
		r->t_motion_s += st->move_s;
		r->t_settle_s += settle;
		r->t_probe_s += pr_s;
		r->t_first_s += c.meas - pool;
		r->t_hdr_s += c.hdr;
		r->darks_s += dark_s;
		if (clear)
			dark_at = clock + d - (c.meas - pool) - host; /* taken before the exposure */
		since_clear++;
		st->predicted_start_s = clock;
		st->predicted_s = d;
		clock += d;
	}
	r->predicted_s = clock;
}

void plan_time_point(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t, double theta_i,
		     double rho, struct plan_point_cost *out)
{
	/* plan_time_apply's figures for one point of a plan whose band spread is the sample's times rho² */
	bool aut = s->integ_mode == PLAN_INTEG_AUTO;
	double est_ms = s->integ_ms > 0 ? s->integ_ms : t->probe_ms;
	double sample = s->integ_spread > 0 ? s->integ_spread : PLAN_AUTO_SPREAD;
	struct inc_cost c = band_cost(s, g, t, est_ms, sample * fmax(rho, 1) * fmax(rho, 1));
	const struct plan_prior *pr = used_prior(s, t);
	if (pr)
		c = prior_cost(s, g, t, prior_row(pr, fabs(theta_i)));
	out->point_s = c.probe + c.meas - c.pool + c.hdr + host_s(s, t, pr);
	out->dark_s = c.dark;
	out->rungs = aut ? c.k : 1; /* fixed integration: one dark per clearing */
}

/* The interval of an auto sweep's duration where its exposures are not known (plan.h plan_time_interval).
 * A sample's exposure times change with the incidence, and a sweep cannot know by how much before it measures
 * there: on the simulated bench (tests/bench/bench_duration.py, seed 1, paper plan) the incidences' mean first
 * exposures went 321 -> 600 ms on the metal (0 -> 60°), 135 -> 104 on the cloth-sheen, 103 -> 92 -> 109 on the green
 * paint, and 190 -> 494 ms on the metal's quick plan (20 -> 45°, 2.6x in 25°). Each unmeasured incidence therefore
 * takes its nearest measured row (the point estimate, plan_time_apply) with its times scaled by exp(-/+ g·Δθ) for the
 * interval's ends, g the steepest change of ln(mean time) per degree between two measured incidences of adjacent
 * zenith, at least PLAN_EXPO_SLOPE_MIN; with one measured incidence g = PLAN_EXPO_SLOPE_ONE (nothing says how fast the
 * sample changes). Checked offline on the three samples' paper-plan rows (the rest's exposures after each measured
 * incidence, 27 cases): covered but for the green paint's last incidence (+17 % in 7.5°, at 90 % of the sweep). */
double plan_prior_slope(const struct plan_prior *p)
{
	size_t n = p->n_inc < PLAN_PRIOR_MAX_INC ? p->n_inc : PLAN_PRIOR_MAX_INC;
	const struct plan_prior_inc *row[PLAN_PRIOR_MAX_INC];
	size_t m = 0;
	for (size_t i = 0; i < n; i++)
		if (p->inc[i].mean_ms > 0 && p->inc[i].points > 0)
			row[m++] = &p->inc[i];
	if (m < 2)
		return PLAN_EXPO_SLOPE_ONE;
	for (size_t i = 1; i < m; i++) /* by zenith (insertion sort: at most PLAN_PRIOR_MAX_INC) */
		for (size_t j = i; j > 0 && row[j]->theta_i < row[j - 1]->theta_i; j--) {
			const struct plan_prior_inc *x = row[j];
			row[j] = row[j - 1];
			row[j - 1] = x;
		}
	double g = PLAN_EXPO_SLOPE_MIN;
	for (size_t i = 1; i < m; i++) {
		double d = row[i]->theta_i - row[i - 1]->theta_i;
		if (d > PLAN_PRIOR_SAME_DEG)
			g = fmax(g, fabs(log(row[i]->mean_ms / row[i - 1]->mean_ms)) / d);
	}
	return g;
}

/* ms times f, within [min_ms, max_ms] (max_ms <= 0: no upper bound). */
static double scale_ms(double ms, double f, double min_ms, double max_ms)
{
	double v = ms * f;
	if (min_ms > 0 && v < min_ms)
		v = min_ms;
	if (max_ms > 0 && v > max_ms)
		v = max_ms;
	return v;
}

/* Row q's times scaled by f (the interval's end at an unmeasured incidence theta_i): its mean and median first
 * exposure, darks and HDR times; its rungs moved by the same number of ladder steps. */
static struct plan_prior_inc scaled_row(const struct plan_spec *s, const struct plan_timing *t,
					const struct plan_prior_inc *q, double theta_i, double f)
{
	struct plan_prior_inc v = *q;
	double lo = t->min_ms > 0 ? t->min_ms : 0, hi = s->max_integ_ms;
	v.theta_i = theta_i;
	v.mean_ms = scale_ms(q->mean_ms, f, lo, hi);
	v.median_ms = scale_ms(q->median_ms, f, lo, hi);
	v.dark_ms = q->dark_ms > 0 ? scale_ms(q->dark_ms, f, lo, hi) : 0;
	v.extra_ms = q->extra_ms > 0 ? scale_ms(q->extra_ms, f, lo, hi) : 0;
	v.pooled_ms = q->pooled_ms > 0 ? scale_ms(q->pooled_ms, f, lo, hi) : 0;
	double r = t->ladder_ratio > 1.0001 ? t->ladder_ratio : M_SQRT2;
	int shift = (int)lround(log(f) / log(r));
	v.rungs = 0;
	for (int k = 0; k < 64; k++)
		if (q->rungs >> k & 1) {
			int nk = k + shift < 0 ? 0 : k + shift > 63 ? 63 : k + shift;
			v.rungs |= (uint64_t)1 << nk;
		}
	return v;
}

/* A prior row at every one of r's incidences for the interval's end `end` (-1 low, +1 high): from the policy's reach
 * (no prior: every exposure at min_ms, or at the plan's max_ms with the HDR share) or the prior's rows, an
 * unmeasured incidence's extrapolated (scaled_row). *extrapolated: some incidence was. */
static void bound_prior(const struct plan_spec *s, const struct plan_timing *t, const struct plan_result *r, int end,
			struct plan_prior *out, bool *extrapolated)
{
	const struct plan_prior *pr = used_prior(s, t);
	double g = pr ? plan_prior_slope(pr) : 0, max_extra = 0;
	for (size_t i = 0; pr && i < pr->n_inc && i < PLAN_PRIOR_MAX_INC; i++)
		max_extra = fmax(max_extra, pr->inc[i].extra_per_point);
	if (pr)
		*out = *pr;
	else {
		memset(out, 0, sizeof *out);
		out->sweep = -1; /* not a sweep: the policy's reach */
	}
	out->n_inc = 0;
	for (size_t i = 0; i < r->n_steps && out->n_inc < PLAN_PRIOR_MAX_INC; i++) {
		double th = fabs(r->steps[i].pos.laser_theta);
		bool seen = false;
		for (size_t j = 0; j < out->n_inc && !seen; j++)
			seen = fabs(out->inc[j].theta_i - th) < 1e-9;
		if (seen)
			continue;
		struct plan_prior_inc *v = &out->inc[out->n_inc++];
		if (!pr) {
			double ms = end < 0 ? (t->min_ms > 0 ? t->min_ms : 1) : s->max_integ_ms > 0 ? s->max_integ_ms : 5000;
			double h = end > 0 && t->max_exposures > 1 && t->hdr_ratio > 1
					   ? (s->integ_hdr >= 0 ? s->integ_hdr : PLAN_AUTO_HDR) : 0;
			*v = (struct plan_prior_inc){ .theta_i = th, .points = 1, .mean_ms = ms, .median_ms = ms, .spread = 1,
						      .darks_per_clear = 1, .dark_ms = ms, .extra_per_point = h,
						      .extra_ms = ms, .rungs = (uint64_t)1 << plan_rung(t, ms),
						      .pooled_per_point = end < 0 ? 1 : 0 };
			continue;
		}
		const struct plan_prior_inc *q = prior_row(pr, th);
		double d = fabs(q->theta_i - th);
		if (d <= PLAN_PRIOR_SAME_DEG)
			*v = *q;
		else {
			*v = scaled_row(s, t, q, th, exp(end * g * d));
			/* its HDR share too: none at the low end, the most any measured incidence took at the high end (the
			 * green paint's went 0.11 -> 0.05 per point from θi 45° to 52.5°, its ETA +7.6 % at the re-timing
			 * that priced 52.5° by 45°) */
			v->extra_per_point = end < 0 ? 0 : max_extra;
			*extrapolated = true;
		}
	}
	if (!pr)
		*extrapolated = true;
}

/* predicted_start_s of r's steps into at[0..n_steps) and predicted_s into at[n_steps] (at may be NULL). */
static void starts(const struct plan_result *r, double *at)
{
	if (!at)
		return;
	for (size_t i = 0; i < r->n_steps; i++)
		at[i] = r->steps[i].predicted_start_s;
	at[r->n_steps] = r->predicted_s;
}

enum plan_interval plan_time_interval(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
				      struct plan_result *r, double *lo_at, double *hi_at, double *lo_s, double *hi_s)
{
	enum plan_interval kind = PLAN_IV_NONE;
	if (s->integ_mode == PLAN_INTEG_AUTO && !s->adaptive) {
		bool ex = false;
		struct plan_timing v = *t;
		bound_prior(s, t, r, -1, &v.prior, &ex);
		if (ex) {
			kind = used_prior(s, t) ? PLAN_IV_EXTRAPOLATED : PLAN_IV_POLICY;
			v.prior.sweep = v.prior.sweep > 0 ? v.prior.sweep : 1; /* used_prior's test */
			plan_time_apply(s, g, &v, r);
			*lo_s = r->predicted_s;
			starts(r, lo_at);
			bound_prior(s, t, r, +1, &v.prior, &ex);
			v.prior.sweep = v.prior.sweep > 0 ? v.prior.sweep : 1;
			plan_time_apply(s, g, &v, r);
			*hi_s = r->predicted_s;
			starts(r, hi_at);
		}
	}
	plan_time_apply(s, g, t, r);
	if (kind == PLAN_IV_NONE) {
		*lo_s = *hi_s = r->predicted_s;
		starts(r, lo_at);
		starts(r, hi_at);
	}
	/* the point estimate within its interval whatever the ends' darks and rounding did */
	*lo_s = fmin(*lo_s, r->predicted_s);
	*hi_s = fmax(*hi_s, r->predicted_s);
	return kind;
}
