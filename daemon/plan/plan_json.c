/* plan_json: a plan result as JSON (jansson), the shape of `acqctl plan --json` and of the daemon's reply. */
#include <jansson.h>
#include <math.h>
#include <stdint.h>

#include "daemon/plan/plan.h"

static const char *status_name(enum plan_status s)
{
	switch (s) {
	case PLAN_KEPT: return "kept";
	case PLAN_MOVED: return "moved";
	case PLAN_DROPPED: return "dropped";
	case PLAN_DUPLICATE: return "duplicate";
	}
	return "?";
}

static json_t *pos_json(const struct plan_pos *p)
{
	/* the arms' pose, by the axes' names (README "Names, one per thing"; theta_i, theta_o, phi_o before) */
	return json_pack("{s:f,s:f,s:f}", "laser.theta", p->laser_theta, "detector.theta", p->det_theta, "detector.phi",
			 p->det_phi);
}

json_t *plan_to_json(const struct plan_spec *s, const struct plan_result *r, bool points)
{
	json_t *o = json_object();
	if (!o)
		return NULL;
	json_object_set_new(o, "plan", json_string(s->name));
	json_object_set_new(o, "requested", json_integer((json_int_t)r->n_req));
	json_object_set_new(o, "kept", json_integer((json_int_t)r->n_kept));
	json_object_set_new(o, "moved", json_integer((json_int_t)r->n_moved));
	json_object_set_new(o, "dropped", json_integer((json_int_t)r->n_dropped));
	json_object_set_new(o, "duplicates", json_integer((json_int_t)r->n_duplicate));
	json_object_set_new(o, "measured", json_integer((json_int_t)r->n_steps));
	json_object_set_new(o, "incidences", json_integer((json_int_t)r->n_groups));
	json_object_set_new(o, "duration_s", json_real(r->duration_s));
	json_object_set_new(o, "raster_s", json_real(r->raster_s));
	json_object_set_new(o, "lower_bound_s", json_real(r->lower_bound_s));
	json_object_set_new(o, "dwell_s", json_real(r->dwell_s));
	json_object_set_new(o, "motion_s", json_real(r->motion_s));
	json_object_set_new(o, "point_dwell_s", json_real(r->point_dwell_s));
	json_object_set_new(o, "predicted_s", json_real(r->predicted_s));
	json_object_set_new(o, "reference_s", json_real(r->reference_s));
	json_object_set_new(o, "darks_s", json_real(r->darks_s));
	json_object_set_new(o, "host_s", json_real(r->host_s));
	/* predicted_s term by term, in the executor's order of a point (they sum to it; plan.h) */
	json_object_set_new(o, "predicted_terms",
			    json_pack("{s:f,s:f,s:f,s:f,s:f,s:f,s:f,s:f}", "reference_s", r->reference_s, "motion_s",
				      r->t_motion_s, "settle_s", r->t_settle_s, "probes_s", r->t_probe_s,
				      "darks_s", r->darks_s, "first_exposures_s", r->t_first_s, "hdr_s", r->t_hdr_s,
				      "host_s", r->host_s));
	json_object_set_new(o, "detours", json_integer((json_int_t)r->n_detours));
	json_object_set_new(o, "blind_points", json_string(s->blind_policy == PLAN_BLIND_MOVE ? "move" : "drop"));
	json_object_set_new(o, "averages", json_integer(s->averages));
	json_object_set_new(o, "integration_ms", json_real(s->integ_ms));
	json_object_set_new(o, "integration_mode", json_string(s->integ_mode == PLAN_INTEG_AUTO ? "auto" : "fixed"));
	size_t nrec = 0;
	for (size_t i = 0; i < r->n_req; i++)
		nrec += r->req[i].role == PLAN_ROLE_RECIPROCAL &&
			(r->req[i].status == PLAN_KEPT || r->req[i].status == PLAN_MOVED);
	json_object_set_new(o, "reciprocal_measured", json_integer((json_int_t)nrec));
	/* the axes' names as everywhere (README "Names, one per thing"; laser_theta... before schema 5) */
	json_object_set_new(o, "travel_deg", json_pack("{s:f,s:f,s:f}", "laser.theta", r->travel_deg[0],
						      "detector.theta", r->travel_deg[1], "detector.phi",
						      r->travel_deg[2]));
	json_t *dl = json_array(), *mv = json_array();
	for (size_t i = 0; i < r->n_req; i++) {
		const struct plan_req *q = &r->req[i];
		if (q->status == PLAN_DROPPED)
			json_array_append_new(dl, json_pack("{s:I,s:o,s:s,s:s}", "index", (json_int_t)i, "requested",
							    pos_json(&q->req), "reason", plan_reason_name(q->reason),
							    "role", q->role == PLAN_ROLE_GRID ? "grid" : "reciprocal"));
		else if (q->status == PLAN_MOVED)
			json_array_append_new(mv, json_pack("{s:I,s:o,s:o,s:f,s:s}", "index", (json_int_t)i,
							    "requested", pos_json(&q->req), "to", pos_json(&q->pos),
							    "by_deg", q->moved_deg, "reason",
							    plan_reason_name(q->reason)));
	}
	json_object_set_new(o, "dropped_points", dl);
	json_object_set_new(o, "moved_points", mv);
	if (points) {
		json_t *st = json_array();
		for (size_t i = 0; i < r->n_steps; i++) {
			const struct plan_step *p = &r->steps[i];
			json_t *w = json_array();
			for (size_t k = 0; k < p->n_wp; k++) {
				json_t *x = pos_json(&r->wps[p->first_wp + k].pos);
				json_object_set_new(x, "duration_s", json_real(r->wps[p->first_wp + k].duration_s));
				json_array_append_new(w, x);
			}
			json_t *x = pos_json(&p->pos);
			json_object_set_new(x, "request", json_integer((json_int_t)p->req));
			if (i < r->n_survey)
				json_object_set_new(x, "survey", json_true());
			json_object_set_new(x, "status", json_string(status_name(r->req[p->req].status)));
			json_object_set_new(x, "t_start_s", json_real(p->t_start_s));
			json_object_set_new(x, "predicted_start_s", json_real(p->predicted_start_s));
			json_object_set_new(x, "move_s", json_real(p->move_s));
			json_object_set_new(x, "settle_s", json_real(p->settle_s));
			json_object_set_new(x, "waypoints", w);
			json_array_append_new(st, x);
		}
		json_object_set_new(o, "steps", st);
	}
	return o;
}


json_t *plan_dry_run_json(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
			  struct plan_result *r, bool points)
{
	/* A first auto sweep of a sample (no exposure prior) is timed from the plan's estimate: nothing on the bench
	 * knows the sample before it is on the stage (the white standard is there when the plan is made). The reply
	 * says so and what the same model predicts for a sample needing half or twice the estimate (each integration
	 * time scaled: the band, its darks, HDR exposures and probes), the plan itself timed last. */
	bool guess = s->integ_mode == PLAN_INTEG_AUTO && !(t->prior.sweep > 0 && t->prior.n_inc > 0);
	/* the survey (plan_survey_apply) where the sample's exposures of some incidence are unknown: its cost is the
	 * timed model's difference from the route without it (the extra motion) */
	double route_s = NAN;
	struct acq_err err = { 0 };
	if (plan_survey_k(s, t, r) > 0 && r->n_survey == 0) {
		plan_time_apply(s, g, t, r);
		route_s = r->predicted_s;
		if (plan_survey_apply(s, g, t, r, &err))
			return NULL;
	}
	double est_ms = s->integ_ms > 0 ? s->integ_ms : t->probe_ms, at[2] = { NAN, NAN };
	for (int k = 0; guess && k < 2; k++) {
		struct plan_spec v = *s;
		v.integ_ms = est_ms * (k ? 2.0 : 0.5);
		plan_time_apply(&v, g, t, r);
		at[k] = r->predicted_s;
	}
	double lo = NAN, hi = NAN;
	enum plan_interval iv = plan_time_interval(s, g, t, r, NULL, NULL, &lo, &hi);
	json_t *o = plan_to_json(s, r, points);
	if (o && iv != PLAN_IV_NONE) {
		/* the duration's interval where the exposures are unknown (plan_time_interval): the policy's reach
		 * before any exposure of the sample is known, else the unmeasured incidences extrapolated from the
		 * measured ones by up to exp(slope · Δθ) */
		const struct plan_prior *p = &t->prior;
		json_t *x = json_pack("{s:f,s:f,s:s}", "low_s", lo, "high_s", hi, "basis",
				      iv == PLAN_IV_POLICY ? "policy" : "extrapolated");
		if (x && iv == PLAN_IV_EXTRAPOLATED)
			json_object_set_new(x, "slope_per_deg", json_real(plan_prior_slope(p)));
		if (x && iv == PLAN_IV_POLICY) {
			json_object_set_new(x, "min_ms", json_real(t->min_ms > 0 ? t->min_ms : 1));
			json_object_set_new(x, "max_ms", json_real(s->max_integ_ms > 0 ? s->max_integ_ms : 5000));
		}
		json_object_set_new(o, "interval", x ? x : json_null());
	}
	if (o && r->n_survey > 0)
		/* the survey: its points (survey_k per incidence, measured first), the time it adds (bench s), and the
		 * basis of the prediction after it (the ETA re-timed from the survey's own exposures, sweep_retime.c) */
		json_object_set_new(o, "survey", json_pack("{s:I,s:I,s:f,s:o,s:s}", "points", (json_int_t)r->n_survey,
							   "per_incidence", (json_int_t)r->survey_k, "motion_s",
							   r->survey_motion_s, "cost_s",
							   isfinite(route_s) ? json_real(r->predicted_s - route_s)
									     : json_null(),
							   "then", "re-timed from the survey's exposures"));
	if (o && guess)
		json_object_set_new(o, "estimate", json_pack("{s:f,s:f,s:f}", "ms", est_ms, "predicted_at_half_s", at[0],
							     "predicted_at_double_s", at[1]));
	long long host_sweep = 0;
	bool own = false;
	double host = plan_time_host(s, t, &host_sweep, &own);
	if (o && host_sweep > 0 && !(t->prior.sweep > 0 && t->prior.host_points > 0)) {
		/* the host's time per point as that sweep measured it, not the default (sweep_plan_prior): a sweep of
		 * the plan's own kind when there is one (host_kind), else the latest of any kind */
		char kind[PLAN_KIND_MAX];
		json_object_set_new(o, "host_sweep", json_integer(host_sweep));
		json_object_set_new(o, "host_per_point_s", json_real(host));
		json_object_set_new(o, "host_kind", own ? json_string(plan_kind_of(s, kind)) : json_null());
	}
	if (o && s->integ_mode == PLAN_INTEG_AUTO) {
		/* which exposure prior timed the auto exposures: the previous sweep of the same sample, or none (the
		 * band around the estimate) */
		const struct plan_prior *p = &t->prior;
		json_t *pr = p->sweep > 0 && p->n_inc > 0
				     ? json_pack("{s:I,s:s,s:I,s:I,s:f,s:f,s:f}", "sweep", (json_int_t)p->sweep, "sample",
						 p->sample, "points", (json_int_t)p->points, "incidences", (json_int_t)p->n_inc,
						 "median_ms", p->median_ms, "spread", p->spread, "hdr_fraction", p->hdr_fraction)
				     : json_null();
		if (pr && p->host_points > 0) /* the host's time per point that sweep measured (plan_time.c) */
			json_object_set_new(pr, "host_per_point_s", json_real(p->host_per_point_s));
		json_object_set_new(o, "exposure_prior", pr ? pr : json_null());
		if (s->sample[0])
			json_object_set_new(o, "sample", json_string(s->sample));
	}
	const struct plan_adaptive *a = s->adaptive;
	if (!o || !a)
		return o;
	double worst_s = 0;
	size_t worst_pts = 0;
	plan_adaptive_worst(s, g, t, r, &worst_s, &worst_pts);
	char spec[256];
	plan_adaptive_target_spec(a, spec, sizeof spec);
	json_t *ad = json_pack("{s:s,s:f,s:I,s:I,s:I,s:f,s:I}", "target", spec, "threshold", plan_adaptive_threshold(a),
			       "batch",
			       (json_int_t)a->batch, "candidate_incidences", (json_int_t)a->n_cand_inc,
			       "candidates_per_incidence", (json_int_t)a->cand_count, "worst_case_s", worst_s,
			       "worst_case_points", (json_int_t)worst_pts);
	if (!ad) {
		json_decref(o);
		return NULL;
	}
	json_object_set_new(ad, "budget_s", a->budget_s > 0 ? json_real(a->budget_s) : json_null());
	json_object_set_new(ad, "budget_points", a->budget_points > 0 ? json_integer((json_int_t)a->budget_points)
								   : json_null());
	json_object_set_new(ad, "overlap", json_boolean(a->overlap));
	json_object_set_new(o, "kind", json_string("adaptive"));
	json_object_set_new(o, "adaptive", ad);
	return o;
}
