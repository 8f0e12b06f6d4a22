/* eta: remaining wall-clock time of a sweep (see eta.h). The planner's figure is in bench seconds: it is
 * divided by the measured ratio of the loop's clock to the real one (the simulator's time scale, 1 on a real
 * bench). The measured rate is real seconds per point over running intervals only; the two are blended with
 * the measured weight n/(n + 5) after n points, so a few points already dominate a poor plan estimate. */
#include "daemon/eta.h"

#include <math.h>

#define ETA_PLAN_WEIGHT 5.0   /* points of measurement worth as much as the plan's estimate */

void eta_reset(struct eta *e)
{
	*e = (struct eta){ .t0_loop = NAN, .t0_real = NAN, .scale = 1, .last_real = NAN };
}

static void clocks(struct eta *e, double loop_now, double real_now)
{
	if (!isfinite(e->t0_real)) {
		e->t0_loop = loop_now;
		e->t0_real = real_now;
	} else if (real_now - e->t0_real > 0.5) {
		double s = (loop_now - e->t0_loop) / (real_now - e->t0_real);
		if (s > 0 && isfinite(s))
			e->scale = s;
	}
}

void eta_running(struct eta *e, bool running, int done, double loop_now, double real_now)
{
	clocks(e, loop_now, real_now);
	e->last_real = running ? real_now : NAN;
	e->last_done = done;
}

double eta_update(struct eta *e, int done, int total, double plan_left_s, double loop_now, double real_now)
{
	clocks(e, loop_now, real_now);
	if (isfinite(e->last_real) && done > e->last_done) {
		e->run_real += real_now - e->last_real;
		e->measured += done - e->last_done;
	}
	e->last_real = real_now;
	e->last_done = done;
	int left = total - done;
	if (left <= 0)
		return 0;
	double plan = isfinite(plan_left_s) && plan_left_s >= 0 ? plan_left_s / e->scale : NAN;
	if (e->measured <= 0)
		return plan;
	double meas = e->run_real / e->measured * left;
	if (!isfinite(plan))
		return meas;
	double w = e->measured / (e->measured + ETA_PLAN_WEIGHT);
	return (1 - w) * plan + w * meas;
}
