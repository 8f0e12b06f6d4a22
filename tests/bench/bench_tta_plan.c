/* bench_tta_plan: the planner's side of the daemon's adaptive loop for tests/bench/bench_time_to_accuracy.py (the
 * offline time-to-accuracy study), with the daemon's own code: its configuration loader and executor timing
 * (conf_load, sweep_init + sweep_plan_timing), the seed plan (plan_make + plan_time_apply, as a sweep start), the
 * candidates with their cost (plan_adaptive_candidates, as daemon/recon_select.c's child writes them), and a batch
 * (as daemon/sweep_adaptive.c's plan_batch: select's picks taken in order when their cost fits the budget left, a
 * dearer one skipped (plan_adaptive_fit_picks), planned from the arms with plan_make_points, re-planned one pick
 * shorter while the batch's predicted time exceeds what is left). Run alone (as `make bench` does) it only says what it is.
 *
 *   bench_tta_plan seed  CONF PLAN [--time-scale S]                 -> JSON {predicted_s, steps}
 *   bench_tta_plan cand  CONF PLAN STATE.json OUT.csv [--time-scale S] -> OUT.csv (rsel_write_candidates, as the
 *                                                   daemon writes them); prints the count, then select's --route
 *   bench_tta_plan batch CONF PLAN STATE.json SELECT.json [--time-scale S] -> JSON {k, predicted_s, steps}
 * STATE.json: {"done": [[laser_theta, detector_theta, detector_phi], ...] (every planned point so far),
 * "from": [..3..] (the arms), "spent_s": S (predicted seconds so far)}. A step is [laser_theta, detector_theta,
 * detector_phi, theta_i, phi_i, theta_o, phi_o, pick rank (batch; -1 for the seed)]; "split": where predicted_s
 * goes (split_json). With ACQ_TTA_SPLIT_LOG=FILE each seed and batch planned also appends its split to FILE, one
 * JSON line (the study runs this program per decision; the breakdown of an adaptive point's seconds by term:
 * README "Time to accuracy", session 17). Exit 2 on bad input. */
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/conf.h"
#include "daemon/executor.h"
#include "daemon/plan/plan.h"
#include "daemon/recon_select.h"
#include "daemon/sweep.h"

static int fail(const char *what, const char *msg)
{
	fprintf(stderr, "bench_tta_plan: %s: %s\n", what, msg);
	return 2;
}

/* The daemon's executor timing for the configuration file at path, at time scale scale. 0 or -1 (message printed). */
static int load(const char *path, double scale, struct conf **conf, struct plan_timing *t)
{
	struct acq_err err = { 0 };
	struct conf_sim sim = { .time_scale = scale };
	if (conf_load(path, scale != 1 ? &sim : NULL, conf, &err))
		return fail(path, err.msg), -1;
	struct sweep_env env = { .conf = *conf };
	struct sweep *sw = NULL;
	if (sweep_init(&env, &sw, &err))
		return fail(path, err.msg), -1;
	sweep_plan_timing(sw, t);
	/* not sweep_finish(): it would stop a loop this process has none of; the process ends soon */
	return 0;
}

static int pos_of(json_t *a, struct plan_pos *p)
{
	if (!json_is_array(a) || json_array_size(a) != 3)
		return -1;
	p->laser_theta = json_number_value(json_array_get(a, 0));
	p->det_theta = json_number_value(json_array_get(a, 1));
	p->det_phi = json_number_value(json_array_get(a, 2));
	return 0;
}

static json_t *steps_json(const struct bench_geom *g, const struct plan_result *r, bool batch)
{
	json_t *s = json_array();
	for (size_t i = 0; i < r->n_steps; i++) {
		double ti, pi, to, po;
		const struct plan_pos *p = &r->steps[i].pos;
		ex_pos_angles(g, p, &ti, &pi, &to, &po);
		json_array_append_new(s, json_pack("[ffffffff]", p->laser_theta, p->det_theta, p->det_phi, ti, pi, to, po,
						   batch ? (double)r->steps[i].req : -1.0));
	}
	return s;
}

/* Where a plan's predicted seconds go (plan.h: motion with settle, dwell, darks, reference, host: the ordering
 * model's split; and plan_time.c's terms t_*_s, which with darks, host and reference make up predicted_s) and the
 * axes' travel. */
static json_t *split_json(const struct plan_result *r)
{
	if (!r)
		return json_object();
	json_t *o = json_pack("{s:f, s:f, s:f, s:f, s:f, s:f, s:f, s:f, s:I}", "motion_s", r->motion_s, "dwell_s",
			      r->dwell_s, "darks_s", r->darks_s, "reference_s", r->reference_s, "host_s", r->host_s,
			      "laser_deg", r->travel_deg[0], "det_theta_deg", r->travel_deg[1], "det_phi_deg",
			      r->travel_deg[2], "incidences", (json_int_t)r->n_groups);
	/* plan_time.c's own terms of predicted_s: with darks_s, host_s and reference_s they sum to it; rest_s is what
	 * they miss (0 to rounding on this model: a term added to plan_time.c without its figure in plan_result shows) */
	double rest = r->predicted_s - (r->t_motion_s + r->t_settle_s + r->t_probe_s + r->t_first_s + r->t_hdr_s +
					r->darks_s + r->host_s + r->reference_s);
	json_object_set_new(o, "rest_s", json_real(fabs(rest) > 1e-9 * fmax(1, r->predicted_s) ? rest : 0));
	json_object_set_new(o, "t_move_s", json_real(r->t_motion_s));
	json_object_set_new(o, "t_settle_s", json_real(r->t_settle_s));
	json_object_set_new(o, "t_probe_s", json_real(r->t_probe_s));
	json_object_set_new(o, "t_first_s", json_real(r->t_first_s));
	json_object_set_new(o, "t_hdr_s", json_real(r->t_hdr_s));
	json_object_set_new(o, "points", json_integer((json_int_t)r->n_steps));
	return o;
}

/* With ACQ_TTA_SPLIT_LOG set, one JSON line per planned seed or batch appended to that file: the study's bench
 * seconds by term (split_json), for a breakdown of where an adaptive point's seconds go. */
static void split_log(const char *what, const struct plan_result *r)
{
	const char *path = getenv("ACQ_TTA_SPLIT_LOG");
	FILE *f = path && *path && r ? fopen(path, "a") : NULL;
	if (!f)
		return;
	json_t *o = split_json(r);
	json_object_set_new(o, "what", json_string(what));
	json_object_set_new(o, "predicted_s", json_real(r->predicted_s));
	json_dumpf(o, f, JSON_COMPACT);
	fputc('\n', f);
	json_decref(o);
	fclose(f);
}

static int print_json(json_t *o)
{
	int rc = json_dumpf(o, stdout, JSON_COMPACT) || fputc('\n', stdout) == EOF ? 1 : 0;
	json_decref(o);
	return rc;
}

/* The sweep's state: done positions (new array, count in *n), the arms in *from, the predicted seconds so far. */
static int state_load(const char *path, struct plan_pos **done, size_t *n, struct plan_pos *from, double *spent)
{
	json_error_t je;
	json_t *o = json_load_file(path, 0, &je), *d = o ? json_object_get(o, "done") : NULL;
	if (!o || !json_is_array(d) || pos_of(json_object_get(o, "from"), from)) {
		json_decref(o);
		return fail(path, o ? "needs done [[3 numbers]...] and from [3 numbers]" : je.text), -1;
	}
	*n = json_array_size(d);
	*done = calloc(*n + 1, sizeof **done);
	for (size_t i = 0; i < *n; i++)
		if (pos_of(json_array_get(d, i), &(*done)[i])) {
			json_decref(o);
			return fail(path, "a done position is not [3 numbers]"), -1;
		}
	*spent = json_number_value(json_object_get(o, "spent_s"));
	json_decref(o);
	return 0;
}

static int cmd_cand(const struct plan_spec *s, const struct bench_geom *g, const struct plan_timing *t,
		    const char *state, const char *out)
{
	struct plan_pos *done = NULL, from;
	size_t nd = 0, n = 0;
	double spent;
	if (state_load(state, &done, &nd, &from, &spent))
		return 2;
	struct plan_cand *c = NULL;
	struct acq_err err = { 0 };
	if (plan_adaptive_candidates(s, g, t, &from, done, nd, &c, &n, &err)) {
		free(done);
		return fail("candidates", err.msg);
	}
	int bad = rsel_write_candidates(out, g, c, n, &err); /* as the daemon's decision writes them */
	char route[PLAN_ROUTE_SPEC_LEN];
	plan_adaptive_route_spec(s, g, t, &from, route, sizeof route);
	printf("%zu\n%s\n", n, route);
	free(done);
	free(c);
	return bad ? fail(out, err.msg) : 0;
}

static int cmd_batch(const struct plan_spec *s, const struct bench_geom *g, struct plan_timing t, const char *state,
		     const char *sel)
{
	struct plan_pos *done = NULL, from;
	size_t nd = 0;
	double spent;
	if (state_load(state, &done, &nd, &from, &spent))
		return 2;
	plan_timing_continue(&t, done, nd, sizeof *done); /* as sweep_adaptive.c's plan_batch */
	free(done);
	json_error_t je;
	json_t *o = json_load_file(sel, 0, &je), *picks = o ? json_object_get(o, "picks") : NULL;
	if (!json_is_array(picks)) {
		json_decref(o);
		return fail(sel, o ? "no picks []" : je.text);
	}
	const struct plan_adaptive *ad = s->adaptive;
	size_t n = json_array_size(picks), k = 0;
	double left_s = ad->budget_s > 0 ? ad->budget_s - spent : INFINITY;
	size_t left_pts = ad->budget_points ? (ad->budget_points > nd ? ad->budget_points - nd : 0) : n;
	struct plan_pos *pos = calloc(n + 1, sizeof *pos);
	for (size_t i = 0; i < n; i++) {
		json_t *id = json_object_get(json_array_get(picks, i), "id");
		if (!json_is_integer(id) || plan_adaptive_cand_pos(s, g, (size_t)json_integer_value(id), &pos[i])) {
			free(pos);
			json_decref(o);
			return fail(sel, "a pick names no candidate of the plan");
		}
	}
	double *cost_of = calloc(n + 1, sizeof *cost_of);
	size_t *keep = calloc(n + 1, sizeof *keep);
	for (size_t i = 0; i < n; i++)
		cost_of[i] = json_number_value(json_object_get(json_array_get(picks, i), "cost_s"));
	k = plan_adaptive_fit_picks(cost_of, n, left_s, left_pts, keep); /* as sweep_adaptive.c's plan_batch */
	for (size_t i = 0; i < k; i++)
		pos[i] = pos[keep[i]];
	free(cost_of);
	json_decref(o);
	t.reference = false;
	t.have_start = false;
	struct plan_result *r = NULL;
	struct acq_err err = { 0 };
	for (; k > 0; k--) {
		if (plan_make_points(s, g, pos, k, &from, &r, &err)) {
			free(pos);
			free(keep);
			return fail("planning the batch", err.msg);
		}
		plan_time_apply(s, g, &t, r);
		if (r->predicted_s <= left_s || !isfinite(left_s))
			break;
		plan_result_free(r);
		r = NULL;
	}
	free(pos);
	split_log("batch", r);
	for (size_t i = 0; r && i < r->n_steps; i++)
		r->steps[i].req = keep[r->steps[i].req]; /* the pick's rank in select's order */
	free(keep);
	json_t *out = json_pack("{s:I, s:f, s:o, s:o}", "k", (json_int_t)k, "predicted_s", r ? r->predicted_s : 0.0,
				"steps", r ? steps_json(g, r, true) : json_array(), "split", split_json(r));
	plan_result_free(r);
	return print_json(out);
}

int main(int argc, char **argv)
{
	if (argc < 4) {
		printf("bench_tta_plan: the planner side of tests/bench/bench_time_to_accuracy.py (run by it; nothing to "
		       "measure alone)\n");
		return argc == 1 ? 0 : 2;
	}
	double scale = 1;
	if (argc >= 6 && strcmp(argv[argc - 2], "--time-scale") == 0) {
		scale = strtod(argv[argc - 1], NULL);
		argc -= 2;
		if (!(scale > 0))
			return fail("--time-scale", "not a positive number");
	}
	struct conf *conf = NULL;
	struct plan_timing t;
	struct plan_spec *s = NULL;
	struct acq_err err = { 0 };
	if (load(argv[2], scale, &conf, &t))
		return 2;
	if (plan_load(argv[3], &s, &err)) {
		conf_free(conf);
		return fail(argv[3], err.msg);
	}
	const struct bench_geom *g = &conf->bench;
	int rc;
	if (strcmp(argv[1], "seed") == 0 && argc == 4) {
		struct plan_result *r = NULL;
		if (plan_make(s, g, &r, &err))
			rc = fail(argv[3], err.msg);
		else {
			plan_time_apply(s, g, &t, r);
			split_log("seed", r);
			rc = print_json(json_pack("{s:f, s:o, s:o}", "predicted_s", r->predicted_s, "steps",
						  steps_json(g, r, false), "split", split_json(r)));
		}
		plan_result_free(r);
	} else if (!s->adaptive)
		rc = fail(argv[3], "not an adaptive plan");
	else if (strcmp(argv[1], "cand") == 0 && argc == 6)
		rc = cmd_cand(s, g, &t, argv[4], argv[5]);
	else if (strcmp(argv[1], "batch") == 0 && argc == 6)
		rc = cmd_batch(s, g, t, argv[4], argv[5]);
	else
		rc = fail(argv[1], "usage: seed CONF PLAN | cand CONF PLAN STATE OUT.csv | batch CONF PLAN STATE SELECT.json");
	plan_spec_free(s);
	conf_free(conf);
	return rc;
}
