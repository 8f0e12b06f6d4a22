/* acq-sim: the simulated bench in one process: arm controllers over Modbus, the laser on a pty, the
 * spectrometer, fault injection; one poll loop; bench time runs --time-scale times faster than real.
 *
 * Which services run: all four devices by default; `sim.services: {laser_arm: false, detector_arm: false,
 * laser: false, spectrometer: false}` in the config, or `--disable laser_arm,detector_arm,laser,spectrometer`
 * on the command line, leaves one out (its endpoint is then absent from the ports file). The control socket
 * always runs. Without the arm or laser services, the world keeps its initial state (laser arm at 0°,
 * detector at 60°/180°, laser off) until the control socket's `pose` and `laser` commands change it.
 *
 * Ports file (--ports-file, JSON, written atomically once every service listens):
 *   {"pid": N, "time_scale": S, "seed": N, "laser_arm": {"port": N}, "detector_arm": {"port": N},
 *    "laser": {"device": "/dev/pts/K"}, "spectrometer": {"socket": PATH, "pixels": N},
 *    "control": {"socket": PATH}}
 * (the arm and laser members are written by their services' describe()). */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "acq_version.h"
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
		   "               [--disable laser_arm,detector_arm,laser,spectrometer]\n"
		   "       acq-sim truth --help | acq-sim ctl --help | acq-sim --version\n"
		   "Serves the simulated bench described by CONFIG (sections bench, devices, sim).\n");
}

static int write_ports(const char *path, struct sim_service **svc, int n, double scale, unsigned long long seed)
{
	char tmp[4096];
	snprintf(tmp, sizeof tmp, "%s.tmp", path);
	FILE *f = fopen(tmp, "w");
	if (!f)
		return -1;
	fprintf(f, "{\"pid\": %ld, \"time_scale\": %.17g, \"seed\": %llu", (long)getpid(), scale, seed);
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
	if (argc > 1 && !strcmp(argv[1], "ctl"))
		return simctl_main(argc - 1, argv + 1);
	if (argc > 1 && !strcmp(argv[1], "--version")) {
		printf("acq-sim %s\n", ACQ_VERSION);
		return 0;
	}

	const char *config = NULL, *ports_file = NULL, *control = NULL;
	static const char *const svc_keys[] = { "laser_arm", "detector_arm", "laser", "spectrometer", NULL };
	bool enabled[4] = { true, true, true, true };
	double scale = 1.0;
	unsigned long long seed = 1;
	static const struct option opts[] = {
		{ "config", required_argument, NULL, 'c' }, { "time-scale", required_argument, NULL, 's' },
		{ "seed", required_argument, NULL, 'S' },   { "ports-file", required_argument, NULL, 'p' },
		{ "control", required_argument, NULL, 'C' }, { "help", no_argument, NULL, 'h' },
		{ "disable", required_argument, NULL, 'D' },
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
		case 'S':
			errno = 0;
			seed = strtoull(optarg, &end, 10);
			if (*end || end == optarg || errno || optarg[0] == '-') {
				fprintf(stderr, "acq-sim: --seed: expected a non-negative integer, got '%s'\n", optarg);
				return 2;
			}
			break;
		case 'D': {
			char buf[256];
			snprintf(buf, sizeof buf, "%s", optarg);
			for (char *save = NULL, *t = strtok_r(buf, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
				int k = 0;
				while (svc_keys[k] && strcmp(svc_keys[k], t))
					k++;
				if (!svc_keys[k]) {
					fprintf(stderr, "acq-sim: --disable: unknown service '%s' (expected laser_arm, "
							"detector_arm, laser, spectrometer)\n", t);
					return 2;
				}
				enabled[k] = false;
			}
			break;
		}
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
	if (simcfg && yc_expect_map(simcfg, "sim", &err))
		goto out;
	struct yc_node *services = simcfg ? yc_get(simcfg, "services") : NULL;
	if (services) {
		if (yc_expect_map(services, "sim.services", &err))
			goto out;
		for (int k = 0; svc_keys[k]; k++) {
			bool on = true;
			if (yc_bool(services, svc_keys[k], false, &on, &err))
				goto out;
			enabled[k] = enabled[k] && on;
		}
		if (yc_check_unknown(services, "sim.services", &err))
			goto out;
	}
	/* The detector arm starts parked away from the laser arm; the white reference is on the stage. */
	world.laser_theta_deg = 0;
	world.detector_theta_deg = 60;
	world.detector_phi_deg = 180;
	world.sample = SIM_SAMPLE_WHITE;
	world.sensor_temp_c = 5.0;
	if (enabled[0] && !(svc[nsvc++] = sim_arm_new(&world, SIM_ARM_LASER, yc_get(devices, "laser_arm"), maps, simcfg, &err)))
		goto fail_svc;
	if (enabled[1] &&
	    !(svc[nsvc++] = sim_arm_new(&world, SIM_ARM_DETECTOR, yc_get(devices, "detector_arm"), maps, simcfg, &err)))
		goto fail_svc;
	if (enabled[2] && !(svc[nsvc++] = sim_laser_new(&world, yc_get(devices, "laser"), simcfg, &err)))
		goto fail_svc;
	if (enabled[3] && !(svc[nsvc++] = sim_spectro_new(&world, yc_get(devices, "spectrometer"), simcfg, &err)))
		goto fail_svc;
	if (!(svc[nsvc++] = sim_control_new(&world, simcfg, control, &err)))
		goto fail_svc;
	/* Unknown keys of `sim:` are reported when every service ran (a disabled one did not ask for its keys). */
	if (simcfg && enabled[0] && enabled[1] && enabled[2] && enabled[3] && yc_check_unknown(simcfg, "sim", &err))
		goto out;

	if (ports_file && write_ports(ports_file, svc, nsvc, scale, seed)) {
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
