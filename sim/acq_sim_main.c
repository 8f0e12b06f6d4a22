/* acq-sim: the simulated bench in one process: arm controllers over Modbus, the laser on a pty, the
 * spectrometer, fault injection; one poll loop; bench time runs --time-scale times faster than real. */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "config/bench.h"
#include "config/yconf.h"
#include "sim/sim.h"

#define MAX_SERVICES 8
#define MAX_FDS 256

static volatile sig_atomic_t stop_requested;

static void on_signal(int sig)
{
	(void)sig;
	stop_requested = 1;
}

static double mono_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

double sim_now(const struct sim_world *w)
{
	return (mono_now() - w->t0_mono) * w->scale;
}

static void usage(FILE *f)
{
	fprintf(f, "usage: acq-sim -c CONFIG [--time-scale N] [--seed N] [--ports-file FILE] [--control SOCKET]\n"
		   "       acq-sim truth --help\n"
		   "Serves the simulated bench described by CONFIG (sections bench, devices, sim).\n");
}

static int write_ports(const char *path, struct sim_service **svc, int n)
{
	char tmp[4096];
	snprintf(tmp, sizeof tmp, "%s.tmp", path);
	FILE *f = fopen(tmp, "w");
	if (!f)
		return -1;
	fprintf(f, "{\"pid\": %ld", (long)getpid());
	for (int i = 0; i < n; i++) {
		char buf[1024] = "";
		if (svc[i]->describe)
			svc[i]->describe(svc[i]->self, buf, sizeof buf);
		if (buf[0])
			fprintf(f, ", %s", buf);
	}
	fprintf(f, "}\n");
	if (fclose(f) != 0)
		return -1;
	return rename(tmp, path);
}

int main(int argc, char **argv)
{
	if (argc > 1 && !strcmp(argv[1], "truth"))
		return sim_truth_main(argc - 1, argv + 1);

	const char *config = NULL, *ports_file = NULL, *control = NULL;
	double scale = 1.0;
	unsigned long long seed = 1;
	static const struct option opts[] = {
		{ "config", required_argument, NULL, 'c' }, { "time-scale", required_argument, NULL, 's' },
		{ "seed", required_argument, NULL, 'S' },   { "ports-file", required_argument, NULL, 'p' },
		{ "control", required_argument, NULL, 'C' }, { "help", no_argument, NULL, 'h' },
		{ NULL, 0, NULL, 0 },
	};
	int c;
	while ((c = getopt_long(argc, argv, "c:h", opts, NULL)) != -1) {
		char *end;
		switch (c) {
		case 'c': config = optarg; break;
		case 's':
			scale = strtod(optarg, &end);
			if (*end || !(scale >= 0.01 && scale <= 1e5)) {
				fprintf(stderr, "acq-sim: --time-scale: expected a number in [0.01, 100000], got '%s'\n", optarg);
				return 2;
			}
			break;
		case 'S': seed = strtoull(optarg, NULL, 10); break;
		case 'p': ports_file = optarg; break;
		case 'C': control = optarg; break;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (!config) {
		usage(stderr);
		return 2;
	}

	struct acq_err err = { 0 };
	struct yc_doc *doc = NULL;
	if (yc_load_file(config, &doc, &err)) {
		fprintf(stderr, "acq-sim: %s\n", err.msg);
		return 1;
	}
	static struct sim_world world;
	world.scale = scale;
	world.seed = seed;
	world.t0_mono = mono_now();
	bench_defaults(&world.geom);

	struct sim_service *svc[MAX_SERVICES];
	int nsvc = 0, rc = 1;
	struct yc_node *root = yc_root(doc), *devices = yc_get(root, "devices"), *simcfg = yc_get(root, "sim");
	struct yc_node *bench = yc_get(root, "bench");
	if (bench && bench_parse(bench, &world.geom, &err))
		goto out;
	if (yc_expect_map(devices, "devices", &err))
		goto out;
	struct yc_node *maps = yc_get(devices, "register_maps");
	/* The detector arm starts parked away from the laser arm. */
	world.laser_theta_deg = 0;
	world.detector_theta_deg = 60;
	world.detector_phi_deg = 180;
	if (!(svc[nsvc++] = sim_arm_new(&world, SIM_ARM_LASER, yc_get(devices, "laser_arm"), maps, simcfg, &err)))
		goto fail_svc;
	if (!(svc[nsvc++] = sim_arm_new(&world, SIM_ARM_DETECTOR, yc_get(devices, "detector_arm"), maps, simcfg, &err)))
		goto fail_svc;
	if (!(svc[nsvc++] = sim_laser_new(&world, yc_get(devices, "laser"), simcfg, &err)))
		goto fail_svc;
	if (!(svc[nsvc++] = sim_spectro_new(&world, yc_get(devices, "spectrometer"), simcfg, &err)))
		goto fail_svc;
	if (!(svc[nsvc++] = sim_control_new(&world, simcfg, control, &err)))
		goto fail_svc;

	if (ports_file && write_ports(ports_file, svc, nsvc)) {
		acq_errf(&err, ACQ_E_IO, "%s: cannot write ports file: %s", ports_file, strerror(errno));
		goto out;
	}
	struct sigaction sa = { .sa_handler = on_signal };
	sigaction(SIGTERM, &sa, NULL);
	sigaction(SIGINT, &sa, NULL);
	signal(SIGPIPE, SIG_IGN);
	fprintf(stderr, "acq-sim: serving (time scale %g, seed %llu)\n", scale, seed);

	while (!stop_requested) {
		struct pollfd fds[MAX_FDS];
		int first[MAX_SERVICES], count[MAX_SERVICES], nfds = 0;
		for (int i = 0; i < nsvc; i++) {
			first[i] = nfds;
			count[i] = svc[i]->pollfds ? svc[i]->pollfds(svc[i]->self, fds + nfds, MAX_FDS - nfds) : 0;
			nfds += count[i];
		}
		/* Models advance every millisecond of real time at most; motion is smooth at any scale. */
		int n = poll(fds, (nfds_t)nfds, 1);
		if (n < 0 && errno != EINTR) {
			acq_errf(&err, ACQ_E_IO, "poll: %s", strerror(errno));
			goto out;
		}
		double now = sim_now(&world);
		for (int i = 0; i < nsvc; i++) {
			if (n > 0 && count[i] && svc[i]->handle)
				svc[i]->handle(svc[i]->self, fds + first[i], count[i], now);
			if (svc[i]->tick)
				svc[i]->tick(svc[i]->self, now);
		}
	}
	rc = 0;
	goto out;
fail_svc:
	nsvc--; /* the failed constructor returned NULL */
out:
	if (rc)
		fprintf(stderr, "acq-sim: %s\n", err.msg);
	for (int i = nsvc - 1; i >= 0; i--)
		svc[i]->destroy(svc[i]->self);
	yc_free(doc);
	return rc;
}
