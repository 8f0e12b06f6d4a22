/* plan_cli: the planner's local dry run behind `acqctl plan PLAN.yaml [--config BENCH.yaml] [--points]`.
 *
 * Nothing touches hardware: the plan is classified, ordered and timed against the `bench:` section of a
 * configuration file. Without --config the bench file is found, in this order, at $ACQ_BENCH_CONFIG,
 * $ACQ_SRC/config/bench-sim.yaml, <dir of the executable>/../config/bench-sim.yaml or ../../config/...
 * (a build tree: build/acqctl, build/san/acqctl), /etc/acquisitiond/acquisitiond.yaml (the bench's own file)
 * and <dir of the executable>/../share/acquisitiond/config/bench-sim.yaml (an installed tree's example).
 * acqctl renders the JSON (the same as the daemon's plan reply). */
#include <jansson.h>
#include <limits.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "config/bench.h"
#include "config/yconf.h"
#include "daemon/plan/plan.h"
#include "daemon/plan/plan_cli.h"

static bool readable(const char *p)
{
	return access(p, R_OK) == 0;
}

/* The default bench configuration (see the file comment); buf receives the path. */
static const char *find_bench(char *buf, size_t len)
{
	const char *e = getenv("ACQ_BENCH_CONFIG");
	if (e && *e) {
		snprintf(buf, len, "%s", e);
		return buf;
	}
	e = getenv("ACQ_SRC");
	if (e && *e) {
		snprintf(buf, len, "%s/config/bench-sim.yaml", e);
		if (readable(buf))
			return buf;
	}
	char exe[PATH_MAX];
	ssize_t n = readlink("/proc/self/exe", exe, sizeof exe - 1);
	bool dir = false;
	if (n > 0) {
		exe[n] = '\0';
		char *slash = strrchr(exe, '/');
		if (slash) {
			*slash = '\0';
			dir = true;
			/* build/acqctl, build/san/acqctl: the source tree is one or two levels up */
			snprintf(buf, len, "%s/../config/bench-sim.yaml", exe);
			if (readable(buf))
				return buf;
			snprintf(buf, len, "%s/../../config/bench-sim.yaml", exe);
			if (readable(buf))
				return buf;
		}
	}
	/* An installed tree: the bench's own configuration before the simulator's example (a real bench's dry run
	 * must not be priced with the simulated geometry). */
	snprintf(buf, len, "/etc/acquisitiond/acquisitiond.yaml");
	if (readable(buf))
		return buf;
	if (dir) {
		snprintf(buf, len, "%s/../share/acquisitiond/config/bench-sim.yaml", exe);
		if (readable(buf))
			return buf;
	}
	return NULL;
}

/* The executor's timing from the file's sweep section when it has one (as the daemon reads it): sweep.
 * extra_settle_s, dark_every, min_integration_ms; sweep.acquisition probe_ms, ladder_ratio, dark_averages, dark_max_age_s, poll_s,
 * max_exposures, hdr_ratio,
 * take_reference, reference_pose. Absent keys keep the defaults. 0 or -1. */
static int load_timing(struct yc_node *root, struct plan_timing *t, struct acq_err *err)
{
	struct yc_node *sw = yc_get(root, "sweep"), *acq = sw ? yc_get(sw, "acquisition") : NULL;
	long long every = t->dark_every, davg = t->dark_averages, nexp = t->max_exposures;
	double poll = 2 * t->exposure_overhead_s;
	if (sw && (yc_double(sw, "extra_settle_s", false, 0, 60, &t->extra_settle_s, err) ||
		   yc_int(sw, "dark_every", false, -1, 100000, &every, err) ||
		   yc_double(sw, "min_integration_ms", false, 0.002, 600000, &t->min_ms, err)))
		return -1;
	if (acq && (yc_double(acq, "probe_ms", false, 1e-3, 1e6, &t->probe_ms, err) ||
		    yc_double(acq, "ladder_ratio", false, 1.01, 10, &t->ladder_ratio, err) ||
		    yc_double(acq, "dark_max_age_s", false, 0, 1e7, &t->dark_max_age_s, err) ||
		    yc_int(acq, "dark_averages", false, 1, 100000, &davg, err) ||
		    yc_double(acq, "poll_s", false, 1e-4, 10, &poll, err) ||
		    yc_int(acq, "max_exposures", false, 1, 8, &nexp, err) ||
		    yc_double(acq, "hdr_ratio", false, 1.01, 1e4, &t->hdr_ratio, err) ||
		    yc_bool(acq, "take_reference", false, &t->reference, err)))
		return -1;
	struct yc_node *pose = acq ? yc_get(acq, "reference_pose") : NULL;
	if (pose && plan_pose_parse(pose, "sweep.acquisition.reference_pose", &t->ref_pose, err))
		return -1;
	t->dark_every = (int)every;
	t->dark_averages = (int)davg;
	t->max_exposures = (int)nexp;
	t->exposure_overhead_s = poll / 2;
	return 0;
}

static int load_bench(const char *path, struct bench_geom *g, struct plan_timing *t, struct acq_err *err)
{
	struct yc_doc *doc = NULL;
	bench_defaults(g);
	plan_timing_defaults(t);
	if (yc_load_file(path, &doc, err))
		return -1;
	struct yc_node *root = yc_root(doc), *b = NULL;
	int rc = 0;
	if (!root || yc_expect_map(root, "configuration", err))
		rc = root ? -1 : yc_errf(err, NULL, "empty configuration file");
	else if (!(b = yc_get(root, "bench")))
		rc = yc_errf(err, root, "no 'bench:' section");
	else
		rc = bench_parse(b, g, err) || load_timing(root, t, err) ? -1 : 0;
	yc_free(doc);
	return rc;
}

json_t *plan_cli_json(const char *plan_path, const char *bench_path, bool points, struct acq_err *err)
{
	char buf[PATH_MAX + 64];
	if (!bench_path && !(bench_path = find_bench(buf, sizeof buf))) {
		acq_errf(err, ACQ_E_NOTFOUND, "no bench configuration found (give --config BENCH.yaml)");
		return NULL;
	}
	struct bench_geom g;
	struct plan_timing tm;
	struct plan_spec *spec = NULL;
	struct plan_result *res = NULL;
	json_t *o = NULL;
	if (load_bench(bench_path, &g, &tm, err)) {
		acq_err_prefix(err, "bench configuration: ");
		goto out;
	}
	if (plan_load(plan_path, &spec, err) || plan_make(spec, &g, &res, err))
		goto out;
	o = plan_dry_run_json(spec, &g, &tm, res, points);
	if (!o || json_object_set_new(o, "bench_config", json_string(bench_path))) {
		json_decref(o);
		o = NULL;
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
out:
	plan_result_free(res);
	plan_spec_free(spec);
	return o;
}
