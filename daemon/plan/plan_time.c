/* plan_time: the planner's duration model of a sweep as the executor runs it (see plan.h, struct plan_timing).
 *
 * The ordering model (plan.c) times each step as trapezoidal moves (each axis's acceleration and velocity
 * profile, the slowest axis wins) + settling + averages × (integration + read-out): that is what the order
 * optimises, and it stays as it is. The executor spends more per step, and this model adds it:
 *   - a move is seen finished by polling the controllers: on average half a poll period late, then one more
 *     read confirms the axis stayed in position after settling (1.5 periods), plus sweep.extra_settle_s;
 *   - auto integration: one probe exposure (at the plan's estimate, else probe_ms) before the measurement;
 *   - every exposure (probe, measurement, dark) costs a start/poll/fetch round trip beyond integration and
 *     read-out (exposure_overhead_s);
 *   - darks (dark_averages exposures at the point's integration) at each new incidence, or every dark_every
 *     points;
 *   - the host's own time per point (point_overhead_s real seconds: calibration, storage, round trips), which
 *     a simulated bench running time_scale times faster sees time_scale times longer in bench seconds;
 *   - the reference at the start: the move to ref_pose from where the arms are (when known: the daemon knows,
 *     a local dry run does not), probe, dark and the plan's averages there, then the move from ref_pose to
 *     the first point (the first step has no move in the ordering model).
 * In auto mode the integration time is the plan's estimate (integration.estimate_ms): the measurement picks
 * its own, so the prediction is only as good as the estimate; the live ETA then corrects with the measured
 * rate (daemon/eta.c). Not modelled: saturation redos and HDR second exposures (they depend on the sample),
 * fault recovery, the operator's sample swap. */
#include "daemon/plan/plan.h"

#include <math.h>

void plan_timing_defaults(struct plan_timing *t)
{
	*t = (struct plan_timing){
		.axis_poll_s = 0.05,          /* drivers/axis_modbus.c poll_s default */
		.extra_settle_s = 0,          /* sweep.extra_settle_s default */
		.probe_ms = 10,               /* daemon/exposure.c probe_ms default */
		.exposure_overhead_s = 0.005, /* executor spectrometer poll 10 ms: half a period per exposure */
		.dark_averages = 10,          /* exposure.c dark_averages default */
		.dark_every = 0,
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
		return yc_errf(err, n, "%s: expected [laser_theta, detector_theta, detector_phi]", what);
	for (int i = 0; i < 3; i++)
		if (yc_node_double(n->items[i], what, -360, 720, &v[i], err))
			return -1;
	*out = (struct plan_pos){ v[0], v[1], v[2] };
	return 0;
}

void plan_time_apply(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
		     struct plan_result *r)
{
	double integ = s->integ_ms / 1000.0, ro = g->readout_s, ovh = t->exposure_overhead_s;
	bool aut = s->integ_mode == PLAN_INTEG_AUTO;
	/* the executor probes at the plan's estimate when it gives one (sweep.c), else at probe_ms */
	double probe_ms = s->integ_ms > 0 ? s->integ_ms : t->probe_ms;
	double probe = aut && probe_ms > 0 ? probe_ms / 1000.0 + ro + ovh : 0;
	double meas = (double)s->averages * (integ + ro) + ovh;
	double dark = (double)t->dark_averages * (integ + ro) + ovh;
	double clock = 0;
	r->reference_s = r->darks_s = 0;
	if (r->n_steps > 0) {
		/* from where the arms are (when known) to the reference pose, the reference, then to the first point */
		const struct plan_pos *first = &r->steps[0].pos;
		if (t->have_start)
			r->reference_s += move_time(g, t, &t->start, t->reference ? &t->ref_pose : first);
		if (t->reference)
			r->reference_s += probe + dark + meas + move_time(g, t, &t->ref_pose, first);
		clock = r->reference_s;
	}
	for (size_t i = 0; i < r->n_steps; i++) {
		struct plan_step *st = &r->steps[i];
		bool moves = st->move_s + st->settle_s > 0;
		bool new_dark = t->dark_every > 0 ? i % (size_t)t->dark_every == 0
						  : i == 0 || st->pos.laser_theta != r->steps[i - 1].pos.laser_theta;
		double d = st->move_s + st->settle_s + (moves ? 1.5 * t->axis_poll_s + t->extra_settle_s : 0) + probe + meas +
			   (new_dark ? dark : 0) + t->point_overhead_s * t->time_scale;
		r->darks_s += new_dark ? dark : 0;
		st->predicted_start_s = clock;
		st->predicted_s = d;
		clock += d;
	}
	r->predicted_s = clock;
}
