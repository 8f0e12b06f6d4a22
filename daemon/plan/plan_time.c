/* plan_time: the planner's duration model of a sweep as the executor runs it (see plan.h, struct plan_timing).
 *
 * The ordering model (plan.c) times each step as trapezoidal moves (each axis's acceleration and velocity
 * profile, the slowest axis wins) + settling + averages × (integration + read-out): that is what the order
 * optimises, and it stays as it is. The executor spends more per step, and this model adds it:
 *   - a move is seen finished by polling the controllers: on average half a poll period late, then one more
 *     read confirms the axis stayed in position after settling (1.5 periods), plus sweep.extra_settle_s;
 *   - an exposure of n averages at t ms lasts n·t, then the spectrometer's read-out (once per exposure: the
 *     AvaSpec averages on board and reads out about 10 ms after the last scan, shared/docs/avaspec-usb.md;
 *     acq-sim does the same), then a start/poll/fetch round trip (exposure_overhead_s, half a poll period);
 *   - auto integration: the executor rounds every time down to its ladder min_ms · ladder_ratio^k (so that
 *     darks can be reused), probes once per point at the previous point's time (the first probe at the plan's
 *     estimate), and takes a dark for each ladder time it has not taken one for since the cache was cleared
 *     (new incidence, dark_every, age). The sample decides those times: it needs a different time in every
 *     direction (on the simulated green paint 14.5 to 116 ms within one incidence for a 20 ms estimate). The
 *     model takes its times log-uniformly over a band of integration.spread (longest / shortest, default
 *     PLAN_AUTO_SPREAD = 8) around the estimate, on the ladder's k rungs there: each exposure and probe at their
 *     mean, and the j-th point after a clearing needs a dark with probability (1 - 1/k)^j (its rung not yet
 *     visited), k(1 - (1 - 1/k)^n) darks for n points. spread: 1 is the old model (every point at the estimate,
 *     one dark per incidence). This was the term the model missed: auto plans ran 7-11 % longer than predicted,
 *     all of it from darks at the sample's other times (6 instead of 2 in the quick plan) and the longer
 *     integration (tests/bench/bench_duration.py, timeline per point);
 *   - darks (dark_averages exposures at the point's integration) at each new incidence, or every dark_every
 *     points, and when the last one is dark_max_age_s old; the first points reuse the reference's dark when
 *     the integration time is fixed (the executor's dark cache keeps it);
 *   - the host's own time per point (point_overhead_s real seconds: calibration, storage, round trips), which
 *     a simulated bench running time_scale times faster sees time_scale times longer in bench seconds;
 *   - the reference at the start: the move to ref_pose from where the arms are (when known: the daemon knows,
 *     a local dry run does not), probe, dark and the plan's averages there, then the move from ref_pose to
 *     the first point (the first step has no move in the ordering model).
 * Not modelled: the second (HDR) exposures a faint end of the spectrum asks for (2 of 15 points on green paint),
 * saturation redos, fault recovery, the operator's sample swap; the live ETA (daemon/eta.c) adds the time per
 * point the sweep has measured beyond this model. */
#include "daemon/plan/plan.h"

#include <math.h>

void plan_timing_defaults(struct plan_timing *t)
{
	*t = (struct plan_timing){
		.axis_poll_s = 0.05,          /* drivers/axis_modbus.c poll_s default */
		.extra_settle_s = 0,          /* sweep.extra_settle_s default */
		.probe_ms = 10,               /* daemon/exposure.c probe_ms default */
		.min_ms = 1,                  /* daemon/conf.c sweep.min_integration_ms default */
		.ladder_ratio = M_SQRT2,      /* daemon/executor.c ladder_ratio default */
		.exposure_overhead_s = 0.005, /* executor spectrometer poll 10 ms: half a period per exposure */
		.dark_averages = 10,          /* exposure.c dark_averages default */
		.dark_every = 0,
		.dark_max_age_s = 600,        /* exposure.c dark_max_age_s default */
		.reference = true,
		.ref_pose = { 0.0, 45.0, 180.0 }, /* executor.c reference_pose default */
		/* measured on the shared 2-core development machine (tests/bench/bench_duration.py, the paper plan
		 * at time scale 35, 1358 bench s predicted without this term): 2246 and 2040 bench s in two runs, i.e.
		 * 0.029 and 0.0225 real s per point depending on the machine's load; their mean */
		.point_overhead_s = 0.026,
		.time_scale = 1,
	};
}

/* A straight move between two poses as the executor sees it: trapezoids, settling, polling. */
static double move_time(const struct bench_geom *g, const struct plan_timing *t, const struct plan_pos *a,
			const struct plan_pos *b)
{
	double mv = plan_straight_s(g, a, b);
	return mv > 0 ? mv + 1.5 * t->axis_poll_s + t->extra_settle_s : 0;
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

/* One exposure of n averages at ms: integration, one read-out, the round trip. */
static double shot(const struct bench_geom *g, const struct plan_timing *t, double n, double ms)
{
	return n * ms / 1000.0 + g->readout_s + t->exposure_overhead_s;
}

/* Auto integration: the ladder's rungs inside the band the sample's times fall in, [est/√spread, est·√spread]
 * (the estimate its geometric middle; within [min_ms, max_ms]), each taken as likely; at least the estimate's rung.
 * Returns their count k (<= cap) and their mean in *mean_ms. */
static int auto_rungs(const struct plan_timing *t, double est_ms, double spread, double max_ms, double *mean_ms)
{
	enum { cap = 64 };
	double r = t->ladder_ratio > 1.0001 ? t->ladder_ratio : M_SQRT2, half = sqrt(spread >= 1 ? spread : 1);
	double lo = ladder(t, est_ms / half, max_ms), hi = ladder(t, est_ms * half, max_ms), sum = 0;
	if (lo < est_ms / half * (1 - 1e-9))
		lo *= r; /* the first rung inside the band */
	int k = 0;
	for (double v = lo; v <= hi * (1 + 1e-9) && k < cap; v *= r, k++)
		sum += v;
	if (k == 0) {
		*mean_ms = ladder(t, est_ms, max_ms);
		return 1;
	}
	*mean_ms = sum / k;
	return k;
}

void plan_time_apply(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
		     struct plan_result *r)
{
	bool aut = s->integ_mode == PLAN_INTEG_AUTO;
	/* the executor's first probe is at the plan's estimate when it gives one (sweep.c), else at probe_ms;
	 * the next ones at the previous point's time */
	double est_ms = s->integ_ms > 0 ? s->integ_ms : t->probe_ms;
	double ms = s->integ_ms;
	int k = 1;
	if (aut)
		k = auto_rungs(t, est_ms, s->integ_spread > 0 ? s->integ_spread : PLAN_AUTO_SPREAD, s->max_integ_ms, &ms);
	double first_probe = aut ? shot(g, t, 1, est_ms) : 0, probe = aut ? shot(g, t, 1, ms) : 0;
	double meas = shot(g, t, s->averages, ms);
	double dark = shot(g, t, t->dark_averages, ms);
	double clock = 0, dark_at = -INFINITY;
	size_t since_clear = 0; /* points since the dark cache was last cleared */
	r->reference_s = r->darks_s = 0;
	r->host_s = t->point_overhead_s * t->time_scale * (double)r->n_steps;
	if (r->n_steps > 0) {
		/* from where the arms are (when known) to the reference pose, the reference, then to the first point */
		const struct plan_pos *first = &r->steps[0].pos;
		if (t->have_start)
			r->reference_s += move_time(g, t, &t->start, t->reference ? &t->ref_pose : first);
		if (t->reference) {
			r->reference_s += first_probe;
			dark_at = r->reference_s; /* fixed integration: the first points use the reference's dark */
			r->reference_s += dark + meas + move_time(g, t, &t->ref_pose, first);
		}
		clock = r->reference_s;
	}
	for (size_t i = 0; i < r->n_steps; i++) {
		struct plan_step *st = &r->steps[i];
		bool moves = st->move_s + st->settle_s > 0;
		/* the dark cache is cleared every dark_every points or at each new incidence, and a dark is due when
		 * the last one has aged; the first point uses the reference's dark when it has the same (fixed) time */
		bool clear = i == 0 ? aut || !t->reference
			    : t->dark_every > 0 ? i % (size_t)t->dark_every == 0
						: st->pos.laser_theta != r->steps[i - 1].pos.laser_theta;
		if (t->dark_max_age_s > 0 && clock - dark_at >= t->dark_max_age_s)
			clear = true;
		if (clear)
			since_clear = 0;
		/* expected darks: fixed, one per clearing; auto, one per rung first visited since the clearing (the
		 * point's rung is new with probability (1 - 1/k)^j after j points) */
		double p_dark = clear ? 1.0 : aut ? pow(1.0 - 1.0 / k, (double)since_clear) : 0.0;
		double d = st->move_s + st->settle_s + (moves ? 1.5 * t->axis_poll_s + t->extra_settle_s : 0) +
			   (i == 0 && !t->reference ? first_probe : probe) + meas + p_dark * dark +
			   t->point_overhead_s * t->time_scale;
		r->darks_s += p_dark * dark;
		if (clear)
			dark_at = clock + d - meas - t->point_overhead_s * t->time_scale; /* taken before the exposure */
		since_clear++;
		st->predicted_start_s = clock;
		st->predicted_s = d;
		clock += d;
	}
	r->predicted_s = clock;
}
