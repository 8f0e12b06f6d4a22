/* sweep_retime: the rest of a first auto sweep's plan re-timed from its own exposures (see sweep_retime.h). */
#include "daemon/sweep_retime.h"

#include <math.h>

#include "daemon/exposure.h"

void sweep_retime_setup(struct sweep_retime *r, const struct plan_spec *spec, const struct plan_timing *tm)
{
	exp_prior_rows_free(&r->rows);
	r->tm = *tm;
	r->retimed = 0;
	r->at = -1;
	r->on = spec && spec->integ_mode == PLAN_INTEG_AUTO && !spec->adaptive && tm->prior.sweep == 0;
}

void sweep_retime_end(struct sweep_retime *r)
{
	exp_prior_rows_free(&r->rows);
	r->on = false;
}

bool sweep_retime_due(const struct sweep_retime *r, const struct plan_result *plan, int done)
{
	if (!r->on || !plan || done < 1 || done == r->at || (size_t)done >= plan->n_steps)
		return false;
	return fabs(plan->steps[done].pos.laser_theta - plan->steps[done - 1].pos.laser_theta) > 1e-6;
}

int sweep_retime_apply(struct sweep_retime *r, int done, struct store *st, long long sweep_id,
		       const struct plan_spec *spec, const struct bench_geom *g, struct plan_result *plan,
		       struct acq_err *err)
{
	struct plan_prior pr;
	r->at = done;
	if (exp_prior_update(&r->rows, st, sweep_id, g, &r->tm, &pr, err))
		return -1;
	if (pr.sweep <= 0 || pr.n_inc == 0)
		return 0;
	r->tm.prior = pr;
	plan_time_apply(spec, g, &r->tm, plan);
	r->retimed++;
	return 1;
}

double sweep_retime_plan_at(const void *plan, int i)
{
	const struct plan_result *r = plan;
	return i >= 0 && (size_t)i < r->n_steps ? r->steps[i].predicted_start_s : r->predicted_s;
}
