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
 *    "laser": {"device": "unix:PATH"} (with sim.laser.link: pty, "/dev/pts/K"),
 *    "spectrometer": {"socket": PATH, "pixels": N}, "control": {"socket": PATH}}
 * (the arm and laser members are written by their services' describe()). */
#include <errno.h>
#include <getopt.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "acq_version.h"
#include "config/acq_num.h"
#include "config/acq_out.h"
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

/* Bench seconds now. */
static double sim_now(const struct sim_world *w)
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
	struct acq_out o;
	if (acq_out_open(&o, path, ACQ_OUT_STDIO, NULL))
		return -1;
	FILE *f = o.f;
	fprintf(f, "{\"pid\": %ld, \"time_scale\": %.17g, \"seed\": %llu", (long)getpid(), scale, seed);
	for (int i = 0; i < n; i++) {
		char buf[1024] = "";
		if (svc[i]->describe)
			svc[i]->describe(svc[i]->self, buf, sizeof buf);
		if (buf[0])
			fprintf(f, ", %s", buf);
	}
	fprintf(f, "}\n");
	return acq_out_commit(&o, NULL);
}

/* The services of the bench, in the order of the ports file, the config's sim.services and --disable. */
static const char *const svc_keys[] = { "laser_arm", "detector_arm", "laser", "spectrometer", NULL };

/* The command line of the serving mode. */
struct sim_opts {
	const char *config, *ports_file, *control;
	bool enabled[4];               /* by svc_keys: not left out by --disable */
	double scale;
	unsigned long long seed;
};

/* The serving mode's options into o. -1 to go on, else the exit status (help printed, or the error reported). */
static int parse_options(int argc, char **argv, struct sim_opts *o)
{
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
		case 'c': o->config = optarg; break;
		case 's':
			if (acq_num_parse(optarg, 0.01, 1e5, &o->scale)) {
				fprintf(stderr, "acq-sim: --time-scale: expected a number in [0.01, 100000], got '%s'\n", optarg);
				return 2;
			}
			break;
		case 'S':
			errno = 0;
			o->seed = strtoull(optarg, &end, 10);
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
				o->enabled[k] = false;
			}
			break;
		}
		case 'p': o->ports_file = optarg; break;
		case 'C': o->control = optarg; break;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (!o->config) {
		usage(stderr);
		return 2;
	}
	return -1;
}

/* The config's sections the services read: bench (into world->geom), devices, its register_maps, sim; and
 * sim.services, which leaves services out of o->enabled. 0 or -1 with err. */
static int read_config(struct yc_doc *doc, struct sim_world *world, struct sim_opts *o, struct yc_node **devices,
		       struct yc_node **maps, struct yc_node **simcfg, struct acq_err *err)
{
	struct yc_node *root = yc_root(doc);
	*devices = yc_get(root, "devices");
	*simcfg = yc_get(root, "sim");
	*maps = NULL;
	struct yc_node *bench = yc_get(root, "bench");
	if (bench && bench_parse(bench, &world->geom, err))
		return -1;
	if (world->geom.deprecated[0])
		fprintf(stderr, "acq-sim: warning: deprecated keys (still accepted): %s\n", world->geom.deprecated);
	if (yc_expect_map(*devices, "devices", err))
		return -1;
	*maps = yc_get(*devices, "register_maps");
	if (*simcfg && yc_expect_map(*simcfg, "sim", err))
		return -1;
	struct yc_node *services = *simcfg ? yc_get(*simcfg, "services") : NULL;
	if (services) {
		if (yc_expect_map(services, "sim.services", err))
			return -1;
		for (int k = 0; svc_keys[k]; k++) {
			bool on = true;
			if (yc_bool(services, svc_keys[k], false, &on, err))
				return -1;
			o->enabled[k] = o->enabled[k] && on;
		}
		if (yc_check_unknown(services, "sim.services", err))
			return -1;
	}
	return 0;
}

/* The world at start: the detector arm parked away from the laser arm; the white reference on the stage. */
static void world_park(struct sim_world *world)
{
	world->laser_theta_deg = 0;
	world->detector_theta_deg = 60;
	world->detector_phi_deg = 180;
	world->sample = SIM_SAMPLE_WHITE;
	world->sensor_temp_c = 5.0;
}

/* Start the enabled services and the control socket into svc[0..*nsvc-1] (those started, also on failure). 0 or
 * -1 with err. */
static int start_services(struct sim_world *world, const struct sim_opts *o, struct yc_node *devices,
			  struct yc_node *maps, struct yc_node *simcfg, struct sim_service **svc, int *nsvc,
			  struct acq_err *err)
{
	const bool *enabled = o->enabled;
	if (enabled[0] &&
	    !(svc[(*nsvc)++] = sim_arm_new(world, SIM_ARM_LASER, yc_get(devices, "laser_arm"), maps, simcfg, err)))
		goto fail_svc;
	if (enabled[1] &&
	    !(svc[(*nsvc)++] = sim_arm_new(world, SIM_ARM_DETECTOR, yc_get(devices, "detector_arm"), maps, simcfg, err)))
		goto fail_svc;
	if (enabled[2] && !(svc[(*nsvc)++] = sim_laser_new(world, yc_get(devices, "laser"), simcfg, err)))
		goto fail_svc;
	if (enabled[3] && !(svc[(*nsvc)++] = sim_spectro_new(world, yc_get(devices, "spectrometer"), simcfg, err)))
		goto fail_svc;
	if (!(svc[(*nsvc)++] = sim_control_new(world, simcfg, o->control, err)))
		goto fail_svc;
	return 0;
fail_svc:
	(*nsvc)--; /* the failed constructor returned NULL */
	return -1;
}

/* The poll loop: every service's descriptors, its handler when they are ready and its tick at least every
 * millisecond of real time, until SIGTERM or SIGINT. 0, or -1 with err (poll failed). */
static int serve(struct sim_world *world, struct sim_service **svc, int nsvc, struct acq_err *err)
{
	while (!stop_requested) {
		struct pollfd fds[MAX_FDS];
		int first[MAX_SERVICES], count[MAX_SERVICES], nfds = 0;
		for (int i = 0; i < nsvc; i++) {
			first[i] = nfds;
			count[i] = svc[i]->pollfds ? svc[i]->pollfds(svc[i]->self, fds + nfds, MAX_FDS - nfds) : 0;
			nfds += count[i];
		}
		/* Models advance every millisecond of real time at most; motion is smooth at any scale. */
		double wait_mono = mono_now();
		int n = poll(fds, (nfds_t)nfds, 1);
		if (n < 0 && errno != EINTR)
			return acq_errf(err, ACQ_E_IO, "poll: %s", strerror(errno));
		double now = sim_now(world), woke = now / world->scale + world->t0_mono;
		/* A 1 ms wait that ended more than SIM_LAG_SLACK_S late: the host did not run this process when its
		 * models were due (load), late by the rest; summed as the ctl status' lag_s (scheduling only, not the
		 * handlers' own work). */
		if (n == 0 && woke - wait_mono > 0.001 + SIM_LAG_SLACK_S)
			world->lag_s += woke - wait_mono - 0.001;
		for (int i = 0; i < nsvc; i++) {
			if (n > 0 && count[i] && svc[i]->handle)
				svc[i]->handle(svc[i]->self, fds + first[i], count[i], now);
			if (svc[i]->tick)
				svc[i]->tick(svc[i]->self, now);
		}
	}
	return 0;
}

int main(int argc, char **argv)
{
	if (argc > 1 && !strcmp(argv[1], "truth"))
		return simtruth_main(argc - 1, argv + 1);
	if (argc > 1 && !strcmp(argv[1], "ctl"))
		return simctl_main(argc - 1, argv + 1);
	if (argc > 1 && !strcmp(argv[1], "--version")) {
		printf("acq-sim %s\n", ACQ_VERSION);
		return 0;
	}
	struct sim_opts o = { .enabled = { true, true, true, true }, .scale = 1.0, .seed = 1 };
	int rc = parse_options(argc, argv, &o);
	if (rc >= 0)
		return rc;

	struct acq_err err = { 0 };
	struct yc_doc *doc = NULL;
	if (yc_load_file(o.config, &doc, &err)) {
		fprintf(stderr, "acq-sim: %s\n", err.msg);
		return 1;
	}
	if (!yc_root(doc)) { /* its sections' errors could not say which file */
		fprintf(stderr, "acq-sim: %s: empty configuration: expected a mapping with bench, devices, sim\n", o.config);
		yc_free(doc);
		return 1;
	}
	static struct sim_world world;
	world.scale = o.scale;
	world.seed = o.seed;
	world.t0_mono = mono_now();
	bench_defaults(&world.geom);

	struct sim_service *svc[MAX_SERVICES];
	int nsvc = 0;
	rc = 1;
	struct yc_node *devices, *maps, *simcfg;
	if (read_config(doc, &world, &o, &devices, &maps, &simcfg, &err))
		goto out;
	/* Socket files that simulators killed before their clean-up left behind (SIGKILL, a crash). */
	int stale = sim_stale_sockets_remove("/tmp");
	if (stale > 0)
		fprintf(stderr, "acq-sim: removed %d stale socket file(s) of simulators no longer running from /tmp\n", stale);
	world_park(&world);
	if (start_services(&world, &o, devices, maps, simcfg, svc, &nsvc, &err))
		goto out;
	/* Unknown keys of `sim:` are reported when every service ran (a disabled one did not ask for its keys). */
	const bool *enabled = o.enabled;
	if (simcfg && enabled[0] && enabled[1] && enabled[2] && enabled[3] && yc_check_unknown(simcfg, "sim", &err))
		goto out;

	if (o.ports_file && write_ports(o.ports_file, svc, nsvc, o.scale, o.seed)) {
		acq_errf(&err, ACQ_E_IO, "%s: cannot write ports file: %s", o.ports_file, strerror(errno));
		goto out;
	}
	struct sigaction sa = { .sa_handler = on_signal };
	sigaction(SIGTERM, &sa, NULL);
	sigaction(SIGINT, &sa, NULL);
	signal(SIGPIPE, SIG_IGN);
	fprintf(stderr, "acq-sim: serving (time scale %g, seed %llu)\n", o.scale, o.seed);
	if (serve(&world, svc, nsvc, &err))
		goto out;
	rc = 0;
out:
	if (rc)
		fprintf(stderr, "acq-sim: %s\n", err.msg);
	for (int i = nsvc - 1; i >= 0; i--)
		svc[i]->destroy(svc[i]->self);
	yc_free(doc);
	return rc;
}
