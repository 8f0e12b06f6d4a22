/* plan_cli: `acqctl plan PLAN.yaml [--config BENCH.yaml] [--json] [--points]`, the planner's dry run.
 *
 * Nothing touches hardware: the plan is classified, ordered and timed against the `bench:` section of a
 * configuration file. Without --config the bench file is found, in this order, at $ACQ_BENCH_CONFIG,
 * $ACQ_SRC/config/bench-sim.yaml, <dir of the executable>/../config/bench-sim.yaml or ../../config/...
 * (a build tree: build/acqctl, build/san/acqctl),
 * <dir of the executable>/../share/acquisitiond/config/bench-sim.yaml (an installed tree) and
 * /etc/acquisitiond/acquisitiond.yaml. Exit status: 0 done, 1 error (message on stderr), 2 usage. */
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

static int usage(void)
{
	fprintf(stderr,
		"usage: acqctl plan PLAN.yaml [--config BENCH.yaml] [--json] [--points]\n"
		"  dry run of the sampling planner: points kept, dropped and moved, duration, motion summary\n"
		"  --config  bench description (its bench: section); default: $ACQ_BENCH_CONFIG,\n"
		"            $ACQ_SRC/config/bench-sim.yaml, config/bench-sim.yaml of the build tree,\n"
		"            PREFIX/share/acquisitiond/config/bench-sim.yaml, /etc/acquisitiond/acquisitiond.yaml\n"
		"  --json    one JSON object (kept, dropped, moved, duration_s, raster_s, lower_bound_s, ...)\n"
		"  --points  also list every step in sweep order with its waypoints\n");
	return 2;
}

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
	if (n > 0) {
		exe[n] = '\0';
		char *slash = strrchr(exe, '/');
		if (slash) {
			*slash = '\0';
			/* build/acqctl, build/san/acqctl: the source tree is one or two levels up */
			snprintf(buf, len, "%s/../config/bench-sim.yaml", exe);
			if (readable(buf))
				return buf;
			snprintf(buf, len, "%s/../../config/bench-sim.yaml", exe);
			if (readable(buf))
				return buf;
			snprintf(buf, len, "%s/../share/acquisitiond/config/bench-sim.yaml", exe);
			if (readable(buf))
				return buf;
		}
	}
	snprintf(buf, len, "/etc/acquisitiond/acquisitiond.yaml");
	if (readable(buf))
		return buf;
	return NULL;
}

static int load_bench(const char *path, struct bench_geom *g, struct acq_err *err)
{
	struct yc_doc *doc = NULL;
	bench_defaults(g);
	if (yc_load_file(path, &doc, err))
		return -1;
	struct yc_node *root = yc_root(doc), *b = NULL;
	int rc = 0;
	if (!root || yc_expect_map(root, "configuration", err))
		rc = root ? -1 : yc_errf(err, NULL, "empty configuration file");
	else if (!(b = yc_get(root, "bench")))
		rc = yc_errf(err, root, "no 'bench:' section");
	else
		rc = bench_parse(b, g, err);
	yc_free(doc);
	return rc;
}

static void hms(double s, char *buf, size_t len)
{
	long t = (long)(s + 0.5);
	snprintf(buf, len, "%ldh%02ldm%02lds", t / 3600, (t / 60) % 60, t % 60);
}

static void print_text(const struct plan_spec *s, const struct plan_result *r, const char *bench, bool points)
{
	char a[32], b[32], c[32];
	printf("plan %s (bench %s)\n", s->name, bench);
	printf("  requested %zu: kept %zu, moved %zu, dropped %zu, duplicates merged %zu; %zu to measure at %zu "
	       "incidences\n",
	       r->n_req, r->n_kept, r->n_moved, r->n_dropped, r->n_duplicate, r->n_steps, r->n_groups);
	hms(r->duration_s, a, sizeof a);
	hms(r->raster_s, b, sizeof b);
	hms(r->lower_bound_s, c, sizeof c);
	printf("  estimated duration %.1f s (%s); raster order %.1f s (%s); lower bound %.1f s (%s)\n", r->duration_s,
	       a, r->raster_s, b, r->lower_bound_s, c);
	if (r->lower_bound_s > 0 && r->duration_s > 0)
		printf("  planned/lower bound %.3f, planned/raster %.3f\n", r->duration_s / r->lower_bound_s,
		       r->raster_s > 0 ? r->duration_s / r->raster_s : 0.0);
	printf("  dwell %.1f s (%.3f s per point), motion %.1f s (settling included), %zu detoured moves\n",
	       r->dwell_s, r->point_dwell_s, r->motion_s, r->n_detours);
	printf("  travel: laser zenith %.1f deg, detector zenith %.1f deg, detector azimuth %.1f deg\n",
	       r->travel_deg[0], r->travel_deg[1], r->travel_deg[2]);
	size_t listed = 0, limit = points ? SIZE_MAX : 20;
	for (size_t i = 0; i < r->n_req; i++) {
		const struct plan_req *q = &r->req[i];
		if ((q->status == PLAN_DROPPED || q->status == PLAN_MOVED) && listed++ >= limit)
			continue;
		if (q->status == PLAN_DROPPED)
			printf("  dropped #%zu (%g, %g, %g): %s%s\n", i, q->req.laser_theta, q->req.det_theta,
			       q->req.det_phi, plan_reason_name(q->reason),
			       q->role == PLAN_ROLE_RECIPROCAL ? " (reciprocal partner)" : "");
		else if (q->status == PLAN_MOVED)
			printf("  moved   #%zu (%g, %g, %g) -> (%.2f, %.2f, %.2f) by %.2f deg: %s\n", i,
			       q->req.laser_theta, q->req.det_theta, q->req.det_phi, q->pos.laser_theta,
			       q->pos.det_theta, q->pos.det_phi, q->moved_deg, plan_reason_name(q->reason));
	}
	if (listed > limit)
		printf("  ... and %zu more dropped or moved points (--points or --json lists them all)\n", listed - limit);
	if (points) {
		for (size_t i = 0; i < r->n_steps; i++) {
			const struct plan_step *p = &r->steps[i];
			printf("  %5zu t=%9.2f s  θi %7.2f  θo %7.2f  φo %8.2f  move %.2f s%s\n", i, p->t_start_s,
			       p->pos.laser_theta, p->pos.det_theta, p->pos.det_phi, p->move_s + p->settle_s,
			       p->detour ? "  (detour)" : "");
			for (size_t k = 0; p->detour && k < p->n_wp; k++) {
				const struct plan_wp *w = &r->wps[p->first_wp + k];
				printf("          via θi %7.2f  θo %7.2f  φo %8.2f  (%.2f s)\n", w->pos.laser_theta,
				       w->pos.det_theta, w->pos.det_phi, w->duration_s);
			}
		}
	}
}

int plan_cli_main(int argc, char **argv)
{
	const char *plan_path = NULL, *bench_path = NULL;
	bool json = false, points = false;
	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "--json"))
			json = true;
		else if (!strcmp(argv[i], "--points"))
			points = true;
		else if (!strcmp(argv[i], "--config") || !strcmp(argv[i], "-c")) {
			if (++i >= argc)
				return usage();
			bench_path = argv[i];
		} else if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
			usage();
			return 0;
		} else if (argv[i][0] == '-' || plan_path)
			return usage();
		else
			plan_path = argv[i];
	}
	if (!plan_path)
		return usage();
	char buf[PATH_MAX + 64];
	if (!bench_path && !(bench_path = find_bench(buf, sizeof buf))) {
		fprintf(stderr, "acqctl plan: no bench configuration found (give --config BENCH.yaml)\n");
		return 1;
	}
	struct acq_err err = { 0 };
	struct bench_geom g;
	struct plan_spec *spec = NULL;
	struct plan_result *res = NULL;
	int rc = 1;
	if (load_bench(bench_path, &g, &err)) {
		fprintf(stderr, "acqctl plan: bench configuration: %s\n", err.msg);
		goto out;
	}
	if (plan_load(plan_path, &spec, &err)) {
		fprintf(stderr, "acqctl plan: %s\n", err.msg);
		goto out;
	}
	if (plan_make(spec, &g, &res, &err)) {
		fprintf(stderr, "acqctl plan: %s\n", err.msg);
		goto out;
	}
	if (json) {
		json_t *o = plan_to_json(spec, res, points);
		if (o)
			json_object_set_new(o, "bench_config", json_string(bench_path));
		char *txt = o ? json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(10)) : NULL;
		if (!txt) {
			fprintf(stderr, "acqctl plan: out of memory\n");
			json_decref(o);
			goto out;
		}
		puts(txt);
		free(txt);
		json_decref(o);
	} else {
		print_text(spec, res, bench_path, points);
	}
	rc = 0;
out:
	plan_result_free(res);
	plan_spec_free(spec);
	return rc;
}
