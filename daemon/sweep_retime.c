/* sweep_retime: the rest of a first auto sweep's plan re-timed from its own exposures (see sweep_retime.h). */
#include "daemon/sweep_retime.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/exposure.h"
#include "daemon/store.h"

static void bounds_free(struct sweep_retime *r)
{
	free(r->lo_at);
	free(r->hi_at);
	r->lo_at = r->hi_at = NULL;
	r->n_at = 0;
	r->iv = PLAN_IV_NONE;
}

void sweep_retime_setup(struct sweep_retime *r, const struct plan_spec *spec, const struct plan_timing *tm)
{
	exp_prior_rows_free(&r->rows);
	bounds_free(r);
	r->tm = *tm;
	r->retimed = 0;
	r->at = -1;
	r->on = spec && spec->integ_mode == PLAN_INTEG_AUTO && !spec->adaptive && tm->prior.sweep == 0;
	r->survey = 0;
	r->host_hint = NAN;
}

void sweep_retime_survey(struct sweep_retime *r, const struct plan_spec *spec, const struct plan_result *plan)
{
	r->survey = spec && plan && spec->integ_mode == PLAN_INTEG_AUTO && !spec->adaptive ? plan->n_survey : 0;
	if (r->survey > 0)
		r->on = true;
}

/* The rows of a sweep with a survey. The survey's points are not consecutive in the route, so their first exposures
 * say nothing of the pooled probe (exp_prior_build counts a point pooled when its predecessor in the plan's order had
 * its time): each row's share is taken over its route points only (the plan's steps from r->survey on), and
 * PLAN_PROBE_POOL at the row's mean time while fewer than SURVEY_POOL_MIN of them are measured; the rungs of such a
 * row filled between its shortest and longest (below). */
#define SURVEY_POOL_MIN 10
static void survey_rows(const struct sweep_retime *r, const struct plan_result *plan, struct plan_prior *pr)
{
	bool only[PLAN_PRIOR_MAX_INC] = { false };
	for (size_t i = 0; i < pr->n_inc && i < PLAN_PRIOR_MAX_INC; i++) {
		struct plan_prior_inc *q = &pr->inc[i];
		size_t sv = 0;
		for (size_t k = 0; k < r->survey && k < plan->n_steps; k++)
			sv += fabs(fabs(plan->steps[k].pos.laser_theta) - q->theta_i) <= PLAN_PRIOR_SAME_DEG;
		size_t route = q->points > sv ? q->points - sv : 0;
		if (route >= SURVEY_POOL_MIN) {
			q->pooled_per_point = q->pooled_per_point * (double)q->points / (double)route;
		} else {
			only[i] = true;
			q->pooled_per_point = PLAN_PROBE_POOL;
			q->pooled_ms = 0;
			/* and its darks: the route's points at the incidence use every rung between the survey's shortest and
			 * longest time (on the survey runs' databases, paper plan: the metal's survey rows 4-6 rungs, filled
			 * 13-23, its route 13-21; the green paint's 4-6, 5-14, 8-12), and each of them is refreshed as it
			 * ages (dark_max_age_s): priced by the survey's own rungs only, the metal's rest ran 96 darks short */
			int lo = -1, hi = -1;
			for (int b = 0; b < 64; b++)
				if (q->rungs >> b & 1) {
					lo = lo < 0 ? b : lo;
					hi = b;
				}
			for (int b = lo; b >= 0 && b <= hi; b++)
				q->rungs |= (uint64_t)1 << b;
			if (lo >= 0)
				q->darks_per_clear = fmax(q->darks_per_clear, (double)(hi - lo + 1));
		}
	}
	sweep_retime_smooth(pr, only);
}

/* A survey row's mean first exposure is that of a few points (K per incidence) of a wide spread: on the survey runs'
 * databases (paper plan, K 6) the metal's ln-times spread by 1.6-2.8 (standard deviation) within an incidence, its
 * 60° survey row 843 ms against the route's 579, the same picks every run. Each survey-only row takes instead the
 * mean of every row's mean weighted by a Gaussian kernel of the zenith difference (SURVEY_SMOOTH_DEG) over the row's
 * uncertainty (its ln-times' variance / points, plus SURVEY_SMOOTH_VAR for what differs between incidences), the
 * completed rows (all their points) among them. Offline on those databases (/work/notes/s18/survey2.md) the rest's
 * first exposures as incidences complete erred -29...+30 % (rms 10.3) by the rows alone, -9...+9 % (rms 3.4) so. */
#define SURVEY_SMOOTH_DEG 12.0
#define SURVEY_SMOOTH_VAR 0.4
void sweep_retime_smooth(struct plan_prior *pr, const bool *only)
{
	size_t n = pr->n_inc < PLAN_PRIOR_MAX_INC ? pr->n_inc : PLAN_PRIOR_MAX_INC;
	double m[PLAN_PRIOR_MAX_INC], w[PLAN_PRIOR_MAX_INC];
	for (size_t u = 0; u < n; u++) {
		const struct plan_prior_inc *q = &pr->inc[u];
		m[u] = q->mean_ms;
		w[u] = q->points > 0 && isfinite(q->mean_ms) && q->mean_ms > 0
			       ? 1.0 / (fmax(q->log_var, 0) / (double)q->points + SURVEY_SMOOTH_VAR)
			       : 0;
	}
	for (size_t i = 0; i < n; i++) {
		if (!only[i] || !(w[i] > 0))
			continue;
		double sw = 0, sm = 0;
		for (size_t u = 0; u < n; u++) {
			double d = (pr->inc[u].theta_i - pr->inc[i].theta_i) / SURVEY_SMOOTH_DEG;
			double k = w[u] * exp(-0.5 * d * d);
			sw += k;
			sm += k * (w[u] > 0 ? m[u] : 0);
		}
		double f = sm / sw / m[i];
		pr->inc[i].mean_ms *= f;
		pr->inc[i].median_ms *= f;
	}
}

void sweep_retime_end(struct sweep_retime *r)
{
	exp_prior_rows_free(&r->rows);
	bounds_free(r);
	r->on = false;
}

bool sweep_retime_due(const struct sweep_retime *r, const struct plan_result *plan, int done)
{
	if (!r->on || !plan || done < 1 || done == r->at || (size_t)done >= plan->n_steps)
		return false;
	if (r->survey > 0 && (size_t)done <= r->survey) /* at the survey's end: every incidence measured */
		return (size_t)done == r->survey;
	return fabs(plan->steps[done].pos.laser_theta - plan->steps[done - 1].pos.laser_theta) > 1e-6;
}

/* The host's time per point of a sweep with a survey: over the route's points (order from r->survey on; the rows'
 * host figure, exp_prior_build's prior_host, over them alone) once SURVEY_HOST_MIN are done, else r->host_hint (the
 * live ETA's, whose bench work holds the probes the survey's points actually took), else none (the default). */
#define SURVEY_HOST_MIN 10
static void survey_host(const struct sweep_retime *r, const struct bench_geom *g, struct plan_prior *pr)
{
	size_t n = 0;
	struct store_prior_row *v = malloc((r->rows.n ? r->rows.n : 1) * sizeof *v);
	for (size_t i = 0; v && i < r->rows.n; i++)
		if (r->rows.v[i].order_index >= (int64_t)r->survey)
			v[n++] = r->rows.v[i];
	struct plan_prior h;
	memset(&h, 0, sizeof h);
	if (v && n > 0 && exp_prior_build(v, n, g, &r->tm, &h) == 0 && h.host_points >= SURVEY_HOST_MIN) {
		pr->host_per_point_s = h.host_per_point_s;
		pr->host_points = h.host_points;
	} else if (isfinite(r->host_hint) && r->host_hint >= 0) {
		pr->host_per_point_s = r->host_hint;
		pr->host_points = 1;
	} else {
		pr->host_points = 0;
	}
	free(v);
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
	if (r->survey > 0) {
		survey_rows(r, plan, &pr);
		survey_host(r, g, &pr);
	}
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

int sweep_retime_bounds(struct sweep_retime *r, const struct plan_spec *spec, const struct bench_geom *g,
			const struct plan_result *plan, struct acq_err *err)
{
	bounds_free(r);
	if (!spec || !plan || spec->integ_mode != PLAN_INTEG_AUTO || spec->adaptive || plan->n_steps == 0)
		return 0;
	struct plan_result c = *plan; /* the steps timed on a copy: the sweep's plan keeps its own times */
	c.steps = malloc(plan->n_steps * sizeof *c.steps);
	r->lo_at = malloc((plan->n_steps + 1) * sizeof *r->lo_at);
	r->hi_at = malloc((plan->n_steps + 1) * sizeof *r->hi_at);
	if (!c.steps || !r->lo_at || !r->hi_at) {
		free(c.steps);
		bounds_free(r);
		return acq_errf(err, ACQ_E_NOMEM, "the duration's interval: out of memory");
	}
	memcpy(c.steps, plan->steps, plan->n_steps * sizeof *c.steps);
	double lo, hi;
	r->iv = plan_time_interval(spec, g, &r->tm, &c, r->lo_at, r->hi_at, &lo, &hi);
	r->n_at = plan->n_steps + 1;
	free(c.steps);
	if (r->iv == PLAN_IV_NONE)
		bounds_free(r);
	return 0;
}

void sweep_retime_eta(const struct sweep_retime *r, const struct plan_result *plan, int done, double eta,
		      double scale, double *lo, double *hi)
{
	*lo = *hi = NAN;
	if (r->iv == PLAN_IV_NONE || !plan || !r->lo_at || r->n_at != plan->n_steps + 1 || done < 0 ||
	    (size_t)done >= r->n_at || !isfinite(eta) || !(scale > 0))
		return;
	double rest = sweep_retime_plan_at(plan, (int)plan->n_steps) - sweep_retime_plan_at(plan, done);
	double l = eta + (r->lo_at[r->n_at - 1] - r->lo_at[done] - rest) / scale;
	double h = eta + (r->hi_at[r->n_at - 1] - r->hi_at[done] - rest) / scale;
	*lo = fmax(0, fmin(l, eta));
	*hi = fmax(h, eta);
}
