/* armhost: test helpers shared by the motion tests: host the simulated arm controllers (sim/sim_arm.c) in a
 * thread of the test process (same poll loop contract as acq-sim), start socat pty pairs, the pymodbus peer
 * (tests/integration/az_peer.py) and mbpoll, and step the axis driver in bench time. Header-only. */
#ifndef ARMHOST_H
#define ARMHOST_H

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "config/yconf.h"
#include "drivers/axis.h"
#include "drivers/axis_modbus.h"
#include "sim/sim.h"
#include "sim/sim_arm.h"

static inline double ah_mono(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static inline void ah_sleep(double s)
{
	if (s <= 0)
		return;
	struct timespec ts = { (time_t)s, (long)((s - (double)(time_t)s) * 1e9) };
	nanosleep(&ts, NULL);
}

static inline unsigned long long ah_seed(void)
{
	const char *s = getenv("ACQ_SEED");
	return s ? strtoull(s, NULL, 10) : 1;
}

static inline const char *ah_src(void)
{
	const char *s = getenv("ACQ_SRC");
	return s ? s : ".";
}

/* ---- the simulated arms in a thread ------------------------------------------------------------------ */

struct armhost {
	struct sim_world w;
	struct yc_doc *doc;
	struct sim_service *svc[2];
	int nsvc;
	pthread_t th;
	pthread_mutex_t mu;
	volatile int stop;
	bool running;
};

static inline double ah_now(const struct armhost *h)
{
	return (ah_mono() - h->w.t0_mono) * h->w.scale;
}

static inline void *ah_loop(void *p)
{
	struct armhost *h = p;
	while (!h->stop) {
		struct pollfd fds[64];
		int first[2], count[2], n = 0;
		pthread_mutex_lock(&h->mu);
		for (int i = 0; i < h->nsvc; i++) {
			first[i] = n;
			count[i] = h->svc[i]->pollfds(h->svc[i]->self, fds + n, 64 - n);
			n += count[i];
		}
		pthread_mutex_unlock(&h->mu);
		int r = poll(fds, (nfds_t)n, 1);
		pthread_mutex_lock(&h->mu);
		double now = ah_now(h);
		for (int i = 0; i < h->nsvc; i++) {
			if (r > 0)
				h->svc[i]->handle(h->svc[i]->self, fds + first[i], count[i], now);
			h->svc[i]->tick(h->svc[i]->self, now);
		}
		pthread_mutex_unlock(&h->mu);
	}
	return NULL;
}

/* Start the arms described by yaml (bench + devices; register maps from maps_from when not NULL) at time
 * scale. 0 or -1 with err. */
static inline int ah_start(struct armhost *h, const char *yaml, struct yc_node *maps_from, double scale,
		    struct acq_err *err)
{
	memset(h, 0, sizeof *h);
	pthread_mutex_init(&h->mu, NULL);
	if (yc_load_string("arms.yaml", yaml, strlen(yaml), &h->doc, err))
		return -1;
	h->w.scale = scale;
	h->w.seed = ah_seed();
	h->w.t0_mono = ah_mono();
	bench_defaults(&h->w.geom);
	h->w.laser_theta_deg = 0;
	h->w.detector_theta_deg = 60;
	h->w.detector_phi_deg = 180;
	struct yc_node *root = yc_root(h->doc), *dev = yc_get(root, "devices"), *bench = yc_get(root, "bench");
	if (bench && bench_parse(bench, &h->w.geom, err))
		return -1;
	struct yc_node *maps = maps_from ? maps_from : yc_get(dev, "register_maps");
	if (yc_get(dev, "laser_arm")) {
		if (!(h->svc[h->nsvc] = sim_arm_new(&h->w, SIM_ARM_LASER, yc_get(dev, "laser_arm"), maps, NULL, err)))
			return -1;
		h->nsvc++;
	}
	if (yc_get(dev, "detector_arm")) {
		if (!(h->svc[h->nsvc] = sim_arm_new(&h->w, SIM_ARM_DETECTOR, yc_get(dev, "detector_arm"), maps, NULL, err)))
			return -1;
		h->nsvc++;
	}
	if (pthread_create(&h->th, NULL, ah_loop, h) != 0)
		return acq_errf(err, ACQ_E_IO, "pthread_create failed");
	h->running = true;
	return 0;
}

static inline void ah_stop(struct armhost *h)
{
	if (h->running) {
		h->stop = 1;
		pthread_join(h->th, NULL);
		h->running = false;
	}
	for (int i = h->nsvc - 1; i >= 0; i--)
		h->svc[i]->destroy(h->svc[i]->self);
	h->nsvc = 0;
	yc_free(h->doc);
	h->doc = NULL;
	pthread_mutex_destroy(&h->mu);
}

static inline void ah_lock(struct armhost *h) { pthread_mutex_lock(&h->mu); }
static inline void ah_unlock(struct armhost *h) { pthread_mutex_unlock(&h->mu); }

/* ---- child processes ---------------------------------------------------------------------------------- */

static inline pid_t ah_spawn(char *const argv[], const char *log)
{
	pid_t pid = fork();
	if (pid == 0) {
		setpgid(0, 0);
		prctl(PR_SET_PDEATHSIG, SIGKILL); /* a crashed test leaves no socat or peer behind */
		int fd = open(log ? log : "/dev/null", O_WRONLY | O_CREAT | O_TRUNC, 0644);
		if (fd >= 0) {
			dup2(fd, 1);
			dup2(fd, 2);
		}
		execv(argv[0], argv);
		_exit(127);
	}
	return pid;
}

static inline void ah_kill(pid_t *pid)
{
	if (*pid > 0) {
		kill(*pid, SIGTERM);
		int st;
		for (int i = 0; i < 200; i++) {
			if (waitpid(*pid, &st, WNOHANG) == *pid) {
				*pid = 0;
				return;
			}
			ah_sleep(0.01);
		}
		kill(*pid, SIGKILL);
		waitpid(*pid, &st, 0);
		*pid = 0;
	}
}

static inline bool ah_wait_file(const char *path, double timeout_s)
{
	double t = ah_mono() + timeout_s;
	struct stat sb;
	while (ah_mono() < t) {
		if (stat(path, &sb) == 0)
			return true;
		ah_sleep(0.02);
	}
	return false;
}

/* A socat pty pair: dir/A and dir/B. */
struct ah_pty {
	pid_t pid;
	char a[256], b[256];
};

static inline int ah_pty_start(struct ah_pty *p, const char *dir)
{
	snprintf(p->a, sizeof p->a, "%s/ttyA", dir);
	snprintf(p->b, sizeof p->b, "%s/ttyB", dir);
	char la[300], lb[300], log[300];
	snprintf(la, sizeof la, "pty,raw,echo=0,link=%s", p->a);
	snprintf(lb, sizeof lb, "pty,raw,echo=0,link=%s", p->b);
	snprintf(log, sizeof log, "%s/socat.log", dir);
	char *argv[] = { "/usr/bin/socat", "-d", "-d", la, lb, NULL };
	if (access(argv[0], X_OK) != 0)
		return -1;
	p->pid = ah_spawn(argv, log);
	if (!ah_wait_file(p->a, 5) || !ah_wait_file(p->b, 5)) {
		ah_kill(&p->pid);
		return -1;
	}
	return 0;
}

static inline char *ah_mkdtemp(void)
{
	static char tmpl[64];
	const char *t = getenv("TMPDIR");
	snprintf(tmpl, sizeof tmpl, "%s/motion.XXXXXX", t && strlen(t) < 40 ? t : "/tmp");
	return mkdtemp(tmpl);
}

static inline void ah_rmrf(const char *dir)
{
	char cmd[512];
	if (dir && strstr(dir, "motion.")) {
		snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
		if (system(cmd) != 0)
			fprintf(stderr, "cannot remove %s\n", dir);
	}
}

/* ---- driving the axis -------------------------------------------------------------------------------- */

/* Step a begun move until done or failed, sleeping in real time between polls; clock(): bench seconds. */
static inline int ah_wait_move(struct axis *ax, double (*clock)(void *), void *cl, double scale, struct acq_err *err)
{
	for (;;) {
		double now = clock(cl);
		int rc = axis_move_step(ax, now, err);
		if (rc != AXIS_MOVE_RUNNING)
			return rc;
		double dt = (axis_next_poll(ax) - clock(cl)) / scale;
		ah_sleep(dt < 0.001 ? 0.001 : dt);
	}
}

#endif
