/* bench_plan: planner quality and speed — planned/raster and planned/lower-bound ratios for the paper's plan
 * and denser ones, on the simulated bench (config/bench-sim.yaml). CSV: $ACQ_BENCH_OUT/plan.csv. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "config/bench.h"
#include "config/yconf.h"
#include "daemon/plan/plan.h"

static const struct {
	const char *name, *file, *text;
} plans[] = {
	{ "paper-10x10x10", "plan-paper-10x10x10.yaml", NULL },
	{ "fibonacci-6x100+10rec", "plan-fibonacci.yaml", NULL },
	{ "grid-15x15x15", NULL,
	  "name: grid-15x15x15\nincidence: {theta_deg: {from: 0, to: 70, count: 15}}\n"
	  "observation: {theta_deg: {from: 5, to: 85, count: 15}, phi_deg: {from: 0, to: 336, count: 15}}\n"
	  "integration: {mode: fixed, ms: 50}\naverages: 4\nblind_points: drop\n" },
	{ "fibonacci-10x100", NULL,
	  "name: fibonacci-10x100\nincidence: {theta_deg: {from: 0, to: 75, count: 10}}\n"
	  "observation: {fibonacci: {count: 100}}\nintegration: {mode: fixed, ms: 50}\naverages: 4\nblind_points: move\n" },
	{ "fibonacci-10x250", NULL,
	  "name: fibonacci-10x250\nincidence: {theta_deg: {from: 0, to: 75, count: 10}}\n"
	  "observation: {fibonacci: {count: 250}}\nintegration: {mode: fixed, ms: 20}\naverages: 2\nblind_points: move\n" },
	{ "grid-20x20x36", NULL,
	  "name: grid-20x20x36\nincidence: {theta_deg: {from: 0, to: 76, count: 20}}\n"
	  "observation: {theta_deg: {from: 4, to: 84, count: 20}, phi_deg: {from: 0, to: 350, step: 10}}\n"
	  "integration: {mode: fixed, ms: 20}\naverages: 2\nblind_points: drop\n" },
};

static int load_bench(const char *path, struct bench_geom *g)
{
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	bench_defaults(g);
	if (yc_load_file(path, &doc, &err)) {
		fprintf(stderr, "bench_plan: %s\n", err.msg);
		return -1;
	}
	struct yc_node *b = yc_get(yc_root(doc), "bench");
	int rc = b ? bench_parse(b, g, &err) : 0;
	if (rc)
		fprintf(stderr, "bench_plan: %s\n", err.msg);
	yc_free(doc);
	return rc;
}

int main(void)
{
	const char *src = getenv("ACQ_SRC") ? getenv("ACQ_SRC") : ".";
	const char *outdir = getenv("ACQ_BENCH_OUT") ? getenv("ACQ_BENCH_OUT") : "build/bench";
	char path[4096];
	snprintf(path, sizeof path, "%s/config/bench-sim.yaml", src);
	struct bench_geom g;
	if (load_bench(path, &g))
		return 1;
	snprintf(path, sizeof path, "%s/plan.csv", outdir);
	FILE *csv = fopen(path, "w");
	if (!csv) {
		perror(path);
		return 1;
	}
	fprintf(csv, "plan,requested,measured,moved,dropped,duplicates,planned_s,raster_s,lower_bound_s,"
		     "planned_over_raster,planned_over_bound,detours,cpu_s\n");
	printf("%-24s %6s %6s %10s %10s %10s %8s %8s %7s\n", "plan", "req", "meas", "planned_s", "raster_s", "bound_s",
	       "pl/ras", "pl/lb", "cpu_s");
	int status = 0;
	for (size_t i = 0; i < sizeof plans / sizeof plans[0]; i++) {
		struct plan_spec *s = NULL;
		struct plan_result *r = NULL;
		struct acq_err err = { 0 };
		int rc;
		if (plans[i].file) {
			snprintf(path, sizeof path, "%s/config/%s", src, plans[i].file);
			rc = plan_load(path, &s, &err);
		} else {
			rc = plan_load_string(plans[i].name, plans[i].text, &s, &err);
		}
		clock_t c0 = clock();
		if (rc || plan_make(s, &g, &r, &err)) {
			fprintf(stderr, "bench_plan: %s: %s\n", plans[i].name, err.msg);
			plan_spec_free(s);
			status = 1;
			continue;
		}
		double cpu = (double)(clock() - c0) / CLOCKS_PER_SEC;
		double pr = r->duration_s / r->raster_s, pb = r->duration_s / r->lower_bound_s;
		printf("%-24s %6zu %6zu %10.1f %10.1f %10.1f %8.3f %8.3f %7.2f\n", plans[i].name, r->n_req, r->n_steps,
		       r->duration_s, r->raster_s, r->lower_bound_s, pr, pb, cpu);
		fprintf(csv, "%s,%zu,%zu,%zu,%zu,%zu,%.3f,%.3f,%.3f,%.4f,%.4f,%zu,%.3f\n", plans[i].name, r->n_req,
			r->n_steps, r->n_moved, r->n_dropped, r->n_duplicate, r->duration_s, r->raster_s,
			r->lower_bound_s, pr, pb, r->n_detours, cpu);
		plan_result_free(r);
		plan_spec_free(s);
	}
	fclose(csv);
	printf("target: planned/lower bound <= 1.15, planned/raster clearly < 1\n");
	return status;
}
