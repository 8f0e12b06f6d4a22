/* acqd_start: the daemon's start-up in order (each step needs the ones before it) and its stop in reverse. */
#include "daemon/acquisitiond/acqd.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <systemd/sd-daemon.h>

#include "acq_version.h"
#include "daemon/crashpoint.h"
#include "daemon/devices.h"
#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/server.h"
#include "daemon/store.h"
#include "daemon/sweep.h"

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

/* The configuration loaded into app, its notes logged, the state folder made. 0, or -1 after logging why. */
static int start_conf(struct app *app, const struct acqd_options *o)
{
	struct acq_err err = { 0 };
	if (conf_load(o->conf_path, app->have_sim ? &app->sim : NULL, &app->conf, &err)) {
		log_msg(LOG_ERR, "%s", err.msg);
		return -1;
	}
	log_set_level(app->conf->d.log_level);
	snprintf(app->sock_path, sizeof app->sock_path, "%s", app->conf->d.socket_path);
	snprintf(app->db_path, sizeof app->db_path, "%s", app->conf->d.database);
	app->conf->d.socket_path = app->sock_path;
	app->conf->d.database = app->db_path;
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		if (app->conf->devnote[d][0])
			log_msg(LOG_NOTICE, "%s: %s", conf_dev_name((enum conf_dev)d), app->conf->devnote[d]);
	if (app->conf->bench.deprecated[0])
		log_msg(LOG_WARNING, "%s: deprecated keys (still accepted): %s", o->conf_path, app->conf->bench.deprecated);
	if (mkdir_p(app->conf->d.state_dir, 0750) < 0) {
		log_msg(LOG_ERR, "%s: %s", app->conf->d.state_dir, strerror(errno));
		return -1;
	}
	return 0;
}

/* The loop, on the simulated bench's clock when it runs faster than real time (device state machines and the
 * executor's timers are in bench seconds; database times stay wall-clock). 0 or -1 with err. */
static int start_loop(struct app *app, struct acq_err *err)
{
	static struct loop_scaled_clock scaled;
	struct loop_clock clk = { loop_monotonic, NULL, 1 };
	if (app->have_sim && app->sim.time_scale != 1) {
		scaled.rate = app->sim.time_scale;
		clk = (struct loop_clock){ loop_scaled_now, &scaled, app->sim.time_scale };
		log_msg(LOG_NOTICE, "simulated bench time runs %g times faster than real time", app->sim.time_scale);
	}
	if (!(app->lp = loop_new(&clk, err)))
		return -1;
	app->started_mono = loop_now(app->lp);
	app->started_wall = app_wallclock();
	return 0;
}

/* The database, and the runs a stopped daemon left running marked interrupted. 0 or -1 with err. */
static int start_store(struct app *app, struct acq_err *err)
{
	if (store_open(app->conf->d.database, &app->store, err))
		return -1;
	if (store_degraded(app->store))
		log_msg(LOG_WARNING, "database: %s", store_degraded(app->store));
	crash_slow_sync(app->store);
	/* Runs of a daemon that died: their children died with it (PR_SET_PDEATHSIG, daemon/job.c). */
	int n = 0;
	if (store_recon_interrupted(app->store, app_wallclock(), &n, err))
		return -1;
	if (n)
		log_msg(LOG_WARNING, "%d reconstruction run(s) left running by a stopped daemon marked interrupted", n);
	return 0;
}

/* The sweep, and with daemon.auto_resume the interrupted one re-planned off the loop. 0 or -1 with err. */
static int start_sweep(struct app *app, struct acq_err *err)
{
	struct sweep_env env = { .loop = app->lp, .store = app->store, .devices = app->dev, .conf = app->conf,
				 .emit = app_emit, .emit_ctx = app, .wallclock = app_wallclock,
				 .software_version = ACQ_VERSION };
	if (sweep_init(&env, &app->sweep, err))
		return -1;
	if (app->conf->d.auto_resume) {
		int64_t id = 0;
		int64_t pending = 0;
		store_sweep_interrupted(app->store, &pending, NULL);
		if (pending && commands_auto_resume(app, &id, err))
			log_msg(LOG_WARNING, "interrupted sweep %lld not resumed: %s", (long long)pending, err->msg);
		else if (id) /* planned off the loop: "resuming interrupted sweep N" is logged once it is */
			log_msg(LOG_NOTICE, "re-planning interrupted sweep %lld off the loop to resume it", (long long)id);
	}
	return 0;
}

int acqd_start(struct app *app, const struct acqd_options *o)
{
	bool journal = !o->foreground && getenv("JOURNAL_STREAM") && getenv("INVOCATION_ID");
	log_init(LOG_INFO, journal);
	if (start_conf(app, o))
		return -1;
	struct acq_err err = { 0 };
	if (start_loop(app, &err))
		goto fail;
	/* The job helper (this program run again in its helper mode): plans are forked from it, never from the
	 * daemon (job.h, job_fork_msg). */
	job_init(app->lp);
	if (job_helper_start(&err) || start_store(app, &err) || acqd_signals_init(app, &err) ||
	    server_init(app->lp, &app->conf->d, ACQ_VERSION, commands_handle, app, &app->srv, &err) ||
	    devices_init(app->lp, app->store, app->conf, app_device_notify, app, app_wallclock, &app->dev, &err) ||
	    start_sweep(app, &err))
		goto fail;
	double rate = app->have_sim && app->sim.time_scale > 0 ? app->sim.time_scale : 1; /* loop seconds per s */
	acqd_timers_start(app, rate);
	log_msg(LOG_NOTICE, "acquisitiond %s ready: socket %s, database %s, %d/%d devices available%s", ACQ_VERSION,
		app->conf->d.socket_path, app->conf->d.database, devices_available(app->dev), CONF_DEV__COUNT,
		app->have_sim ? " (simulated bench)" : "");
	sd_notifyf(0, "READY=1\nMAINPID=%d\nSTATUS=%s", (int)getpid(), acqd_timers_status());
	return 0;
fail:
	log_msg(LOG_ERR, "%s", err.msg);
	return -1;
}

void acqd_stop(struct app *app, bool clean)
{
	/* Reverse order of start-up. The sweep first (it records where it stopped), then the devices (laser off,
	 * arms stopped), the clients, the children, the database. */
	sweep_finish(app->sweep);
	devices_finish(app->dev); /* laser off and arms stopped first; a failure is logged per device */
	server_finish(app->srv);
	job_finish();
	acqd_signals_finish();
	store_close(app->store);
	loop_free(app->lp);
	if (clean)
		log_msg(LOG_NOTICE, "stopped");
	conf_free(app->conf);
	log_finish();
}
