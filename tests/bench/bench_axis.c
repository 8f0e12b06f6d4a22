/* bench_axis: latency of the Modbus axis driver against the simulated controller over TCP and over RTU
 * (socat pty, 115200 baud): one status read (two transactions), one move start (status + FC16 block), and
 * the bench-time accuracy of complete moves. Writes $ACQ_BENCH_OUT/axis_latency.csv and prints a table. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "tests/unit/armhost.h"

#define N 300
#define SCALE 20.0

static int cmp(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

static double pct(double *v, int n, double p)
{
	qsort(v, (size_t)n, sizeof *v, cmp);
	return v[(int)(p * (n - 1))];
}

static double clock_of(void *h)
{
	return ah_now(h);
}

static int run(const char *label, bool rtu, FILE *csv)
{
	struct armhost h;
	struct acq_err err = { 0 };
	char path[512], yaml[2048], link_sim[300], link_drv[300];
	struct ah_pty pty = { 0 };
	char *dir = ah_mkdtemp();
	snprintf(path, sizeof path, "%s/config/bench-sim.yaml", ah_src());
	struct yc_doc *maps = NULL;
	if (!dir || yc_load_file(path, &maps, &err))
		return -1;
	struct yc_node *mapsn = yc_get(yc_get(yc_root(maps), "devices"), "register_maps");
	if (rtu) {
		if (ah_pty_start(&pty, dir)) {
			printf("%-4s skipped (no socat)\n", label);
			yc_free(maps);
			return 0;
		}
		snprintf(link_sim, sizeof link_sim, "{type: rtu, device: %s, baud: 115200}", pty.b);
	} else {
		snprintf(link_sim, sizeof link_sim, "{type: tcp, port: 0}");
	}
	snprintf(yaml, sizeof yaml, "devices:\n  detector_arm:\n    link: %s\n    axes:\n"
		 "      theta: {unit: 1, map: oriental_az, speed_dps: 20, accel_dps2: 60, poll_s: 0.01}\n", link_sim);
	if (ah_start(&h, yaml, mapsn, SCALE, &err)) {
		fprintf(stderr, "%s\n", err.msg);
		return -1;
	}
	if (rtu)
		snprintf(link_drv, sizeof link_drv, "{type: rtu, device: %s, baud: 115200}", pty.a);
	else
		snprintf(link_drv, sizeof link_drv, "{type: tcp, port: %d}", simarm_port(h.svc[0]));
	snprintf(yaml, sizeof yaml, "link: %s\naxes:\n  theta: {unit: 1, map: oriental_az, speed_dps: 20, "
		 "accel_dps2: 60, poll_s: 0.01, settle_s: 0}\n", link_drv);
	struct yc_doc *doc = NULL;
	struct axis_cfg *cfg[1];
	int n = 0;
	struct axis *ax = NULL;
	if (yc_load_string("b.yaml", yaml, strlen(yaml), &doc, &err) ||
	    axis_arm_parse(yc_root(doc), mapsn, "detector_arm", cfg, 1, &n, &err) || axis_open(cfg[0], &ax, &err)) {
		fprintf(stderr, "%s\n", err.msg);
		return -1;
	}
	static double st_lat[N], mv_lat[N];
	struct axis_status st;
	for (int i = 0; i < N; i++) {
		double t0 = ah_mono();
		if (axis_read_status(ax, &st, &err))
			return fprintf(stderr, "%s\n", err.msg), -1;
		st_lat[i] = (ah_mono() - t0) * 1e3;
	}
	/* move starts: status read + block write; each move is stopped right away */
	for (int i = 0; i < N; i++) {
		double t0 = ah_mono();
		if (axis_move_begin(ax, i % 2 ? 40 : 50, ah_now(&h), &err))
			return fprintf(stderr, "%s\n", err.msg), -1;
		mv_lat[i] = (ah_mono() - t0) * 1e3;
		axis_stop(ax, &err);
		ah_sleep(0.002);
	}
	/* whole moves: bench-time duration against the trapezoid */
	double worst = 0;
	for (int i = 0; i < 5; i++) {
		if (axis_read_status(ax, &st, &err))
			return -1;
		double target = 20 + 10 * i, d = fabs(target - st.position_deg);
		double t0 = ah_now(&h);
		if (axis_move_begin(ax, target, t0, &err) ||
		    ah_wait_move(ax, clock_of, &h, SCALE, &err) != AXIS_MOVE_DONE)
			return fprintf(stderr, "%s\n", err.msg), -1;
		double over = (ah_now(&h) - t0) - axis_trapezoid_s(d, 20, 60, 60);
		worst = over > worst ? over : worst;
	}
	double s50 = pct(st_lat, N, 0.5), s99 = pct(st_lat, N, 0.99), m50 = pct(mv_lat, N, 0.5),
	       m99 = pct(mv_lat, N, 0.99);
	printf("%-4s status read (2 transactions): p50 %.3f ms, p99 %.3f ms | move start: p50 %.3f ms, p99 %.3f ms | "
	       "move end detected at most %.3f bench-s (%.1f ms real) after the trapezoid\n",
	       label, s50, s99, m50, m99, worst, worst / SCALE * 1e3);
	if (csv)
		fprintf(csv, "%s,%.4f,%.4f,%.4f,%.4f,%.4f\n", label, s50, s99, m50, m99, worst);
	axis_close(ax);
	axis_cfg_free(cfg[0]);
	yc_free(doc);
	ah_stop(&h);
	yc_free(maps);
	ah_kill(&pty.pid);
	ah_rmrf(dir);
	return 0;
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	const char *out = getenv("ACQ_BENCH_OUT");
	char path[512];
	FILE *csv = NULL;
	if (out) {
		snprintf(path, sizeof path, "%s/axis_latency.csv", out);
		csv = fopen(path, "w");
		if (csv)
			fprintf(csv, "link,status_p50_ms,status_p99_ms,move_start_p50_ms,move_start_p99_ms,"
				     "move_end_over_trapezoid_bench_s\n");
	}
	int rc = run("tcp", false, csv) || run("rtu", true, csv);
	if (csv)
		fclose(csv);
	return rc ? 1 : 0;
}
