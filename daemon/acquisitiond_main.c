/* acquisitiond: the daemon's entry point — options, start-up in order, the event loop, signals through a
 * self-pipe, reload on SIGHUP, graceful stop in reverse order (laser off, arms stopped, database closed). */
#include <errno.h>
#include <fcntl.h>
#include <getopt.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <systemd/sd-daemon.h>

#include "acq_version.h"
#include "daemon/app.h"
#include "daemon/conf.h"
#include "daemon/cputime.h"
#include "daemon/crashpoint.h"
#include "daemon/devices.h"
#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/plan_worker.h"
#include "daemon/recon_select.h"
#include "daemon/server.h"
#include "daemon/store.h"
#include "daemon/sweep.h"
#include "drivers/laser.h"

static int sig_pipe[2] = { -1, -1 };

/* Signal handlers only write the signal number to the self-pipe; the loop does the work. */
static void on_signal(int sig)
{
	int e = errno;
	unsigned char b = (unsigned char)sig;
	ssize_t w = write(sig_pipe[1], &b, 1);
	(void)w;
	errno = e;
}

static int signals_init(struct acq_err *err)
{
	if (pipe2(sig_pipe, O_CLOEXEC | O_NONBLOCK) < 0)
		return acq_errf(err, ACQ_E_IO, "pipe: %s", strerror(errno));
	struct sigaction sa = { .sa_handler = on_signal, .sa_flags = SA_RESTART };
	sigemptyset(&sa.sa_mask);
	int sigs[] = { SIGTERM, SIGINT, SIGHUP, SIGCHLD };
	for (size_t i = 0; i < sizeof sigs / sizeof sigs[0]; i++)
		if (sigaction(sigs[i], &sa, NULL) < 0)
			return acq_errf(err, ACQ_E_IO, "sigaction: %s", strerror(errno));
	signal(SIGPIPE, SIG_IGN);
	return 0;
}

static void signals_finish(void)
{
	signal(SIGTERM, SIG_DFL);
	signal(SIGINT, SIG_DFL);
	signal(SIGHUP, SIG_DFL);
	signal(SIGCHLD, SIG_DFL);
	close(sig_pipe[0]);
	close(sig_pipe[1]);
}

static bool want_stop;

static void on_sigpipe(struct loop *lp, int fd, short revents, void *arg)
{
	(void)revents;
	struct app *app = arg;
	unsigned char b[64];
	ssize_t n;
	while ((n = read(fd, b, sizeof b)) > 0)
		for (ssize_t i = 0; i < n; i++) {
			switch (b[i]) {
			case SIGTERM:
			case SIGINT:
				log_msg(LOG_NOTICE, "signal %d: stopping", b[i]);
				want_stop = true;
				loop_stop(lp);
				break;
			case SIGHUP: {
				struct acq_err err = { 0 };
				if (app_reload(app, &err))
					log_msg(LOG_WARNING, "SIGHUP: %s", err.msg);
				break;
			}
			case SIGCHLD:
				job_reap();
				break;
			}
		}
}

static char last_status[256];

static void status_tick(struct loop *lp, void *arg)
{
	(void)lp;
	struct app *app = arg;
	char line[256];
	app_status_line(app, line, sizeof line);
	if (strcmp(line, last_status)) {
		snprintf(last_status, sizeof last_status, "%s", line);
		sd_notifyf(0, "STATUS=%s", line);
	}
}

/* The watchdog is fed by a timer of the loop itself (no thread): a loop blocked by anything stops feeding it
 * and systemd restarts the daemon (the sweep resumes after its last committed point). A turn that came
 * late is logged with the measured block, so a stall shorter than WatchdogSec is visible too. */
static double wd_period_real, wd_last_real, wd_last_cpu_wait;

static void watchdog_tick(struct loop *lp, void *arg)
{
	(void)lp;
	(void)arg;
	double now = loop_monotonic(NULL);
	struct cputime ct; /* how much of a block was the machine's: the loop's thread waiting for a CPU */
	cputime_thread(&ct);
	if (wd_last_real > 0 && now - wd_last_real > wd_period_real + 1.0)
		log_msg(LOG_WARNING, "watchdog: the loop was blocked for about %.1f s (fed %.1f s after the last time, "
			"period %.1f s; the loop's thread waited %.1f s of it for a CPU)", now - wd_last_real - wd_period_real,
			now - wd_last_real, wd_period_real, ct.waiting - wd_last_cpu_wait);
	wd_last_real = now;
	wd_last_cpu_wait = ct.waiting;
	sd_notify(0, "WATCHDOG=1");
}

/* The loop's heartbeat for the laser's keep-alive: the laser's thread refreshes it only while the loop beats,
 * so a daemon that dies, or whose loop hangs, leaves the laser to switch emission off by itself
 * (devices.laser.keepalive_ms after the process dies; 3 × that after the loop's last beat). */
static void laser_heartbeat_tick(struct loop *lp, void *arg)
{
	(void)lp;
	struct app *app = arg;
	if (app->dev)
		devices_heartbeat(app->dev);
}

/* --laser-off (ExecStopPost=): open the configured laser, which switches emission off, and close it. */
static int laser_off_main(const char *path, const struct conf_sim *sim)
{
	struct conf *c = NULL;
	struct acq_err err = { 0 };
	if (conf_load(path, sim, &c, &err)) {
		fprintf(stderr, "acquisitiond --laser-off: %s\n", err.msg);
		return 1;
	}
	int rc = 0;
	struct laser *l = NULL;
	if (!c->laser) {
		fprintf(stderr, "acquisitiond --laser-off: no laser configured: nothing to switch off\n");
	} else if (laser_open(c->laser, &l, &err)) {
		fprintf(stderr, "acquisitiond --laser-off: laser emission off NOT confirmed: %s\n", err.msg);
		rc = 1;
	} else {
		struct laser_status st;
		if (laser_status(l, &st, &err) || st.emission) {
			fprintf(stderr, "acquisitiond --laser-off: laser emission off NOT confirmed: %s\n",
				err.msg[0] ? err.msg : "it still reports emission");
			rc = 1;
		} else {
			printf("acquisitiond --laser-off: laser emission off (confirmed by its status)\n");
		}
		laser_close(l);
	}
	conf_free(c);
	return rc;
}

static void usage(FILE *f)
{
	fprintf(f, "usage: acquisitiond -c FILE [-f] [--sim PORTS.json]\n"
		   "       acquisitiond --check-config FILE [--sim PORTS.json]\n"
		   "       acquisitiond --laser-off -c FILE [--sim PORTS.json]\n"
		   "  -c, --config FILE     configuration (bench, devices, daemon, sweep, recon)\n"
		   "  -f, --foreground      log to stderr even when started by systemd (it never forks)\n"
		   "      --sim PORTS.json  use the simulator's endpoints (acq-sim's ports file)\n"
		   "      --check-config F  validate F and exit 0 (valid) or 1\n"
		   "      --laser-off       switch the configured laser's emission off and exit 0 (confirmed) or 1\n"
		   "                        (the unit's ExecStopPost=, after any exit of the daemon)\n"
		   "  -V, --version         print the version\n");
}

static int check_config(const char *path, const struct conf_sim *sim)
{
	struct conf *c = NULL;
	struct acq_err err = { 0 };
	if (conf_load(path, sim, &c, &err)) {
		fprintf(stderr, "%s\n", err.msg);
		return 1;
	}
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		if (c->devnote[d][0])
			printf("note: %s: %s\n", conf_dev_name((enum conf_dev)d), c->devnote[d]);
	if (c->bench.deprecated[0])
		printf("warning: deprecated keys (still accepted): %s\n", c->bench.deprecated);
	printf("%s: ok\n", path);
	conf_free(c);
	return 0;
}

static int mkdir_p(const char *path, mode_t mode)
{
	char buf[4096];
	snprintf(buf, sizeof buf, "%s", path);
	for (char *p = buf + 1; *p; p++)
		if (*p == '/') {
			*p = 0;
			if (mkdir(buf, mode) < 0 && errno != EEXIST)
				return -1;
			*p = '/';
		}
	return mkdir(buf, mode) < 0 && errno != EEXIST ? -1 : 0;
}

/* The children the job helper runs for the daemon (job_kinds_main: a request names one by its place here). */
static const struct job_kind *const job_kinds[] = { &commands_plan_kind, &plan_worker_kind, &rsel_inputs_kind };

int main(int argc, char **argv)
{
	job_kinds_main(argc, argv, job_kinds, sizeof job_kinds / sizeof job_kinds[0]);
	static const struct option opts[] = { { "config", required_argument, NULL, 'c' },
					      { "foreground", no_argument, NULL, 'f' },
					      { "sim", required_argument, NULL, 's' },
					      { "check-config", required_argument, NULL, 'k' },
					      { "laser-off", no_argument, NULL, 'L' },
					      { "version", no_argument, NULL, 'V' },
					      { "help", no_argument, NULL, 'h' },
					      { NULL, 0, NULL, 0 } };
	const char *conf_path = NULL, *sim_path = NULL, *check = NULL;
	bool foreground = false, laser_off = false;
	int o;
	while ((o = getopt_long(argc, argv, "c:fVh", opts, NULL)) != -1) {
		switch (o) {
		case 'c': conf_path = optarg; break;
		case 'f': foreground = true; break;
		case 's': sim_path = optarg; break;
		case 'k': check = optarg; break;
		case 'L': laser_off = true; break;
		case 'V': printf("acquisitiond %s (protocol %d, schema %d)\n", ACQ_VERSION, PROTO_VERSION,
				 STORE_SCHEMA_VERSION); return 0;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (optind < argc || (!conf_path && !check)) {
		usage(stderr);
		return 2;
	}
	struct app app = { .conf_path = conf_path };
	struct acq_err err = { 0 };
	if (sim_path) {
		if (conf_sim_read(sim_path, &app.sim, &err)) {
			fprintf(stderr, "acquisitiond: %s\n", err.msg);
			return 1;
		}
		app.have_sim = true;
	}
	if (check)
		return check_config(check, sim_path ? &app.sim : NULL);
	if (laser_off)
		return laser_off_main(conf_path, sim_path ? &app.sim : NULL);

	int rc = 1;
	bool journal = !foreground && getenv("JOURNAL_STREAM") && getenv("INVOCATION_ID");
	log_init(LOG_INFO, journal);
	if (conf_load(conf_path, app.have_sim ? &app.sim : NULL, &app.conf, &err)) {
		log_msg(LOG_ERR, "%s", err.msg);
		return 1;
	}
	log_set_level(app.conf->d.log_level);
	snprintf(app.sock_path, sizeof app.sock_path, "%s", app.conf->d.socket_path);
	snprintf(app.db_path, sizeof app.db_path, "%s", app.conf->d.database);
	app.conf->d.socket_path = app.sock_path;
	app.conf->d.database = app.db_path;
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		if (app.conf->devnote[d][0])
			log_msg(LOG_NOTICE, "%s: %s", conf_dev_name((enum conf_dev)d), app.conf->devnote[d]);
	if (app.conf->bench.deprecated[0])
		log_msg(LOG_WARNING, "%s: deprecated keys (still accepted): %s", conf_path, app.conf->bench.deprecated);
	if (mkdir_p(app.conf->d.state_dir, 0750) < 0) {
		log_msg(LOG_ERR, "%s: %s", app.conf->d.state_dir, strerror(errno));
		goto out_conf;
	}
	/* The simulated bench may run faster than real time: the loop's clock follows it (device state machines
	 * and the executor's timers are in bench seconds); database times stay wall-clock. */
	static struct loop_scaled_clock scaled;
	struct loop_clock clk = { loop_monotonic, NULL, 1 };
	if (app.have_sim && app.sim.time_scale != 1) {
		scaled.rate = app.sim.time_scale;
		clk = (struct loop_clock){ loop_scaled_now, &scaled, app.sim.time_scale };
		log_msg(LOG_NOTICE, "simulated bench time runs %g times faster than real time", app.sim.time_scale);
	}
	if (!(app.lp = loop_new(&clk, &err)))
		goto fail;
	app.started_mono = loop_now(app.lp);
	app.started_wall = app_wallclock();
	/* The job helper (this program run again in its helper mode): plans are forked from it, never from the
	 * daemon (job.h, job_fork_msg). */
	job_init(app.lp);
	if (job_helper_start(&err))
		goto fail;
	if (store_open(app.conf->d.database, &app.store, &err))
		goto fail;
	if (store_degraded(app.store))
		log_msg(LOG_WARNING, "database: %s", store_degraded(app.store));
	crash_slow_sync(app.store);
	{
		/* Runs of a daemon that died: their children died with it (PR_SET_PDEATHSIG, daemon/job.c). */
		int n = 0;
		if (store_recon_interrupted(app.store, app_wallclock(), &n, &err))
			goto fail;
		if (n)
			log_msg(LOG_WARNING, "%d reconstruction run(s) left running by a stopped daemon marked interrupted", n);
	}
	if (signals_init(&err) || loop_fd_add(app.lp, sig_pipe[0], POLLIN, on_sigpipe, &app, &err))
		goto fail;
	if (server_init(app.lp, &app.conf->d, ACQ_VERSION, commands_handle, &app, &app.srv, &err))
		goto fail;
	if (devices_init(app.lp, app.store, app.conf, app_device_notify, &app, app_wallclock, &app.dev, &err))
		goto fail;
	struct sweep_env env = { .loop = app.lp, .store = app.store, .devices = app.dev, .conf = app.conf,
				 .emit = app_emit, .emit_ctx = &app, .wallclock = app_wallclock,
				 .software_version = ACQ_VERSION };
	if (sweep_init(&env, &app.sweep, &err))
		goto fail;
	if (app.conf->d.auto_resume) {
		int64_t id = 0;
		int64_t pending = 0;
		store_sweep_interrupted(app.store, &pending, NULL);
		if (pending && commands_auto_resume(&app, &id, &err))
			log_msg(LOG_WARNING, "interrupted sweep %lld not resumed: %s", (long long)pending, err.msg);
		else if (id) /* planned off the loop: "resuming interrupted sweep N" is logged once it is */
			log_msg(LOG_NOTICE, "re-planning interrupted sweep %lld off the loop to resume it", (long long)id);
	}
	uint64_t wd_usec = 0;
	double rate = app.have_sim && app.sim.time_scale > 0 ? app.sim.time_scale : 1; /* loop seconds per s */
	if (sd_watchdog_enabled(0, &wd_usec) > 0 && wd_usec)
		wd_period_real = (double)wd_usec / 2e6;
	else if (app.conf->d.watchdog_s > 0)
		wd_period_real = app.conf->d.watchdog_s / 2;
	if (wd_period_real > 0) /* WATCHDOG_USEC is real time; the loop's clock may run faster (simulated bench) */
		loop_timer_add(app.lp, wd_period_real * rate, wd_period_real * rate, watchdog_tick, NULL);
	loop_timer_add(app.lp, 1.0, 1.0, status_tick, &app);
	if (app.conf->laser) {
		/* Every 250 ms real time (the loop's clock may run faster: simulated bench), well within the 3 ×
		 * keepalive_ms (>= 1.5 s) the laser's thread waits for a beat. */
		loop_timer_add(app.lp, 0.25 * rate, 0.25 * rate, laser_heartbeat_tick, &app);
	}
	status_tick(app.lp, &app);
	log_msg(LOG_NOTICE, "acquisitiond %s ready: socket %s, database %s, %d/%d devices available%s", ACQ_VERSION,
		app.conf->d.socket_path, app.conf->d.database, devices_available(app.dev), CONF_DEV__COUNT,
		app.have_sim ? " (simulated bench)" : "");
	sd_notifyf(0, "READY=1\nMAINPID=%d\nSTATUS=%s", (int)getpid(), last_status);
	while (!want_stop)
		if (loop_run(app.lp) < 0) {
			log_msg(LOG_ERR, "poll: %s", strerror(errno));
			break;
		}
	sd_notify(0, "STOPPING=1\nSTATUS=stopping: laser off, arms stopped, closing the database");
	rc = 0;
	goto out;
fail:
	log_msg(LOG_ERR, "%s", err.msg);
	rc = 1;
out:
	/* Reverse order of start-up. The sweep first (it records where it stopped), then the devices (laser off,
	 * arms stopped), the clients, the children, the database. */
	sweep_finish(app.sweep);
	devices_finish(app.dev); /* laser off and arms stopped first; a failure is logged per device */
	server_finish(app.srv);
	job_finish();
	if (sig_pipe[0] >= 0)
		signals_finish();
	store_close(app.store);
	loop_free(app.lp);
	if (!rc)
		log_msg(LOG_NOTICE, "stopped");
out_conf:
	conf_free(app.conf);
	log_finish();
	return rc;
}
