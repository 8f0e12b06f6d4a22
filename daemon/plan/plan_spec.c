/* plan_spec: read and validate plan files (YAML) into a struct plan_spec; every error names file:line:col.
 *
 * Layout (all keys but incidence and observation optional):
 *   name: paper-10x10x10
 *   incidence: {theta_deg: RANGE}
 *   observation: {theta_deg: RANGE, phi_deg: RANGE}          # grid, per incidence
 *            or  {fibonacci: {count: N, max_theta_deg: 85}}  # near-uniform directions, per incidence
 *   integration: {mode: auto, target_peak: 0.8, estimate_ms: 50, max_ms: 5000, spread: 4} | {mode: fixed, ms: 20}
 *                (timing only: spread, the longest / shortest time the sample needs at one viewing zenith;
 *                hdr_fraction, the points that need a second exposure)
 *   averages: 4
 *   reciprocal_pairs: 10
 *   blind_points: drop | move
 *   sample: green-paint-A3                  # the sample's name: a later sweep of the same name times its auto
 *                                           # exposures from this one's (the exposure prior, plan.h)
 *   kind: grid | fibonacci | adaptive       # optional; adaptive: see plan_adaptive.c
 *   survey: 6                               # auto: points per incidence measured first (plan_survey_apply;
 *                                           # -1: 6 where the sample's exposure prior lacks an incidence; 0, the
 *                                           # default: none)
 * RANGE is a number, a list of numbers, {from, to, count} or {from, to, step}. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/plan/plan_int.h"

#define PLAN_MAX_VALUES 100000

void plan_spec_free(struct plan_spec *s)
{
	if (!s)
		return;
	free(s->incidence);
	free(s->obs_theta);
	free(s->obs_phi);
	if (s->adaptive)
		free(s->adaptive->cand_inc);
	free(s->adaptive);
	free(s);
}

int plan_range_parse(struct yc_node *map, const char *key, const char *what, double lo, double hi, double **out,
		       size_t *n, struct acq_err *err)
{
	struct yc_node *node = yc_get(map, key);
	*out = NULL;
	*n = 0;
	if (!node)
		return yc_errf(err, map, "%s: missing key '%s' (a number, a list, {from, to, count} or {from, to, step})",
			       what, key);
	double *v = NULL;
	size_t cnt = 0;
	if (node->type == YC_SCALAR) {
		v = malloc(sizeof *v);
		if (!v)
			return acq_errf(err, ACQ_E_NOMEM, "out of memory");
		if (yc_node_double(node, what, lo, hi, &v[0], err)) {
			free(v);
			return -1;
		}
		cnt = 1;
	} else if (node->type == YC_SEQ) {
		if (node->n == 0)
			return yc_errf(err, node, "%s: empty list", what);
		if (node->n > PLAN_MAX_VALUES)
			return yc_errf(err, node, "%s: more than %d values", what, PLAN_MAX_VALUES);
		v = malloc(node->n * sizeof *v);
		if (!v)
			return acq_errf(err, ACQ_E_NOMEM, "out of memory");
		for (size_t i = 0; i < node->n; i++) {
			if (yc_node_double(node->items[i], what, lo, hi, &v[i], err)) {
				free(v);
				return -1;
			}
		}
		cnt = node->n;
	} else {
		double from = 0, to = 0, step = 0;
		long long count = 0;
		if (yc_double(node, "from", true, lo, hi, &from, err) || yc_double(node, "to", true, lo, hi, &to, err) ||
		    yc_int(node, "count", false, 1, PLAN_MAX_VALUES, &count, err) ||
		    yc_double(node, "step", false, -1e4, 1e4, &step, err))
			return -1;
		if (yc_check_unknown(node, what, err))
			return -1;
		bool has_count = yc_get(node, "count") != NULL, has_step = yc_get(node, "step") != NULL;
		if (has_count == has_step)
			return yc_errf(err, node, "%s: give exactly one of 'count' and 'step'", what);
		if (has_step) {
			if (step == 0 || (to - from) * step < 0)
				return yc_errf(err, yc_get(node, "step"), "%s: step %g does not lead from %g to %g", what,
					       step, from, to);
			double k = floor((to - from) / step + 1e-9);
			if (k + 1 > PLAN_MAX_VALUES)
				return yc_errf(err, yc_get(node, "step"), "%s: more than %d values", what,
					       PLAN_MAX_VALUES);
			count = (long long)k + 1;
		} else if (count == 1 && from != to) {
			return yc_errf(err, yc_get(node, "count"), "%s: count 1 needs from == to", what);
		}
		v = malloc((size_t)count * sizeof *v);
		if (!v)
			return acq_errf(err, ACQ_E_NOMEM, "out of memory");
		for (long long i = 0; i < count; i++)
			v[i] = has_step ? from + (double)i * step
					: (count == 1 ? from : from + (to - from) * (double)i / (double)(count - 1));
		cnt = (size_t)count;
	}
	*out = v;
	*n = cnt;
	return 0;
}

/* The optional top-level key sample: (a name of printable characters) of a plan document into out ("" when
 * absent). 0 or -1 with err. */
static int plan_sample_parse(struct yc_node *root, char out[PLAN_SAMPLE_MAX], struct acq_err *err)
{
	const char *v = NULL;
	out[0] = 0;
	if (yc_string(root, "sample", false, &v, err))
		return -1;
	if (!v)
		return 0;
	size_t n = strlen(v);
	if (n == 0 || n >= PLAN_SAMPLE_MAX)
		return yc_errf(err, yc_get(root, "sample"), "sample: expected a name of 1 to %d characters", PLAN_SAMPLE_MAX - 1);
	for (size_t i = 0; i < n; i++)
		if ((unsigned char)v[i] < 0x20 || v[i] == 0x7f)
			return yc_errf(err, yc_get(root, "sample"), "sample: a control character at position %zu", i + 1);
	memcpy(out, v, n + 1);
	return 0;
}

int plan_integration_parse(struct yc_node *root, struct plan_spec *s, struct acq_err *err)
{
	static const char *const modes[] = { "auto", "fixed", NULL };
	struct yc_node *n = yc_get(root, "integration");
	s->integ_mode = PLAN_INTEG_AUTO;
	s->integ_ms = 50;
	s->target_peak = 0.8;
	s->max_integ_ms = 5000;
	s->integ_hdr = -1; /* PLAN_AUTO_HDR unless the plan says */
	if (!n)
		return 0;
	if (yc_expect_map(n, "integration", err))
		return -1;
	int mode = 0;
	if (yc_enum(n, "mode", true, modes, &mode, err))
		return -1;
	s->integ_mode = mode == 0 ? PLAN_INTEG_AUTO : PLAN_INTEG_FIXED;
	if (s->integ_mode == PLAN_INTEG_FIXED) {
		if (yc_double(n, "ms", true, 0.001, 600000, &s->integ_ms, err))
			return -1;
	} else {
		if (yc_double(n, "target_peak", false, 0.01, 1.0, &s->target_peak, err) ||
		    yc_double(n, "max_ms", false, 0.001, 600000, &s->max_integ_ms, err) ||
		    yc_double(n, "estimate_ms", false, 0.001, 600000, &s->integ_ms, err) ||
		    yc_double(n, "spread", false, 1, 1e6, &s->integ_spread, err) ||
		    yc_double(n, "hdr_fraction", false, 0, 1, &s->integ_hdr, err))
			return -1;
		if (s->integ_ms > s->max_integ_ms)
			return yc_errf(err, yc_get(n, "estimate_ms"), "integration: estimate_ms (%g) exceeds max_ms (%g)",
				       s->integ_ms, s->max_integ_ms);
	}
	return yc_check_unknown(n, "integration", err);
}

int plan_parse(struct yc_node *root, struct plan_spec **out, struct acq_err *err)
{
	*out = NULL;
	if (!root)
		return acq_errf(err, ACQ_E_CONFIG, "empty plan file");
	if (yc_expect_map(root, "plan", err))
		return -1;
	struct plan_spec *s = calloc(1, sizeof *s);
	if (!s)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	const char *name = "plan";
	long long averages = 1, recip = 0, survey = 0;
	int policy = 0;
	static const char *const policies[] = { "drop", "move", NULL };
	/* a misspelt key is reported as such, before any "missing key" it causes */
	static const char *const keys[] = { "name", "incidence", "observation", "integration", "averages",
					    "reciprocal_pairs", "blind_points", "kind", "sample", "survey", NULL };
	static const char *const kinds[] = { "grid", "fibonacci", "adaptive", NULL };
	int kind = -1;
	if (yc_get(root, "kind") && yc_enum(root, "kind", false, kinds, &kind, err))
		goto fail;
	if (kind == 2) {
		free(s);
		return plan_adaptive_parse(root, out, err);
	}
	for (size_t i = 0; keys[i]; i++)
		yc_get(root, keys[i]);
	if (yc_check_unknown(root, "plan", err))
		goto fail;
	if (yc_string(root, "name", false, &name, err))
		goto fail;
	for (size_t i = 0; name && name[i]; i++) /* as sample: (a newline or an escape in logs and tables) */
		if ((unsigned char)name[i] < 0x20 || name[i] == 0x7f) {
			yc_errf(err, yc_get(root, "name"), "name: a control character at position %zu", i + 1);
			goto fail;
		}
	snprintf(s->name, sizeof s->name, "%s", name);
	if (plan_sample_parse(root, s->sample, err))
		goto fail;

	struct yc_node *inc = yc_get(root, "incidence");
	if (!inc) {
		yc_errf(err, root, "plan: missing key 'incidence' ({theta_deg: RANGE})");
		goto fail;
	}
	if (yc_expect_map(inc, "incidence", err) ||
	    plan_range_parse(inc, "theta_deg", "incidence.theta_deg", -90, 90, &s->incidence, &s->n_incidence, err) ||
	    yc_check_unknown(inc, "incidence", err))
		goto fail;

	struct yc_node *obs = yc_get(root, "observation");
	if (!obs) {
		yc_errf(err, root, "plan: missing key 'observation' ({theta_deg, phi_deg} or {fibonacci})");
		goto fail;
	}
	if (yc_expect_map(obs, "observation", err))
		goto fail;
	struct yc_node *fib = yc_get(obs, "fibonacci");
	if (fib) {
		long long count = 0;
		s->fib_max_theta_deg = 85;
		if (yc_expect_map(fib, "observation.fibonacci", err) ||
		    yc_int(fib, "count", true, 1, PLAN_MAX_VALUES, &count, err) ||
		    yc_double(fib, "max_theta_deg", false, 0.1, 90, &s->fib_max_theta_deg, err) ||
		    yc_check_unknown(fib, "observation.fibonacci", err))
			goto fail;
		s->fib_count = (size_t)count;
		if (yc_get(obs, "theta_deg") || yc_get(obs, "phi_deg")) {
			yc_errf(err, obs, "observation: give either 'fibonacci' or 'theta_deg' + 'phi_deg', not both");
			goto fail;
		}
	} else {
		if (plan_range_parse(obs, "theta_deg", "observation.theta_deg", -90, 90, &s->obs_theta, &s->n_obs_theta,
				err) ||
		    plan_range_parse(obs, "phi_deg", "observation.phi_deg", -360, 720, &s->obs_phi, &s->n_obs_phi, err))
			goto fail;
	}
	if (yc_check_unknown(obs, "observation", err))
		goto fail;
	if ((kind == 0 && fib) || (kind == 1 && !fib)) {
		yc_errf(err, obs, "observation: kind %s needs %s", kinds[kind],
			kind == 0 ? "'theta_deg' + 'phi_deg'" : "'fibonacci'");
		goto fail;
	}

	if (plan_integration_parse(root, s, err) || yc_int(root, "averages", false, 1, 100000, &averages, err) ||
	    yc_int(root, "reciprocal_pairs", false, 0, PLAN_MAX_VALUES, &recip, err) ||
	    yc_enum(root, "blind_points", false, policies, &policy, err) ||
	    yc_int(root, "survey", false, -1, PLAN_MAX_PER_INCIDENCE, &survey, err))
		goto fail;
	s->survey = (int)survey;
	s->averages = (int)averages;
	s->reciprocal_pairs = (size_t)recip;
	s->blind_policy = policy == 1 ? PLAN_BLIND_MOVE : PLAN_BLIND_DROP;
	size_t per = s->fib_count ? s->fib_count : s->n_obs_theta * s->n_obs_phi;
	if (per > PLAN_MAX_PER_INCIDENCE) {
		yc_errf(err, obs, "observation: %zu directions per incidence is more than %d", per,
			PLAN_MAX_PER_INCIDENCE);
		goto fail;
	}
	if ((double)per * (double)s->n_incidence > PLAN_MAX_POINTS) {
		yc_errf(err, inc, "plan: %zu incidences × %zu directions is more than %d points", s->n_incidence, per,
			PLAN_MAX_POINTS);
		goto fail;
	}
	if (yc_check_unknown(root, "plan", err))
		goto fail;
	*out = s;
	return 0;
fail:
	plan_spec_free(s);
	return -1;
}

int plan_load_string(const char *name, const char *text, struct plan_spec **out, struct acq_err *err)
{
	struct yc_doc *doc = NULL;
	*out = NULL;
	if (yc_load_string(name, text, strlen(text), &doc, err))
		return -1;
	int rc = plan_parse(yc_root(doc), out, err);
	if (rc && err && err->code == ACQ_E_CONFIG && !strstr(err->msg, name))
		acq_err_prefix(err, "%s: ", name);
	yc_free(doc);
	return rc;
}

int plan_load(const char *path, struct plan_spec **out, struct acq_err *err)
{
	struct yc_doc *doc = NULL;
	*out = NULL;
	if (yc_load_file(path, &doc, err))
		return -1;
	int rc = plan_parse(yc_root(doc), out, err);
	if (rc && err && !strstr(err->msg, path))
		acq_err_prefix(err, "%s: ", path);
	yc_free(doc);
	return rc;
}
