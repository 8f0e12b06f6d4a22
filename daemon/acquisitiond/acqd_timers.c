/* acqd_timers: the loop's periodic duties — systemd's status line, the watchdog fed by the loop itself, and the
 * laser keep-alive's heartbeat. */
#include "daemon/acquisitiond/acqd.h"

#include <stdio.h>
#include <string.h>
#include <systemd/sd-daemon.h>

#include "daemon/cputime.h"
#include "daemon/devices.h"
#include "daemon/log.h"
#include "daemon/loop.h"

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

void acqd_timers_start(struct app *app, double rate)
{
	uint64_t wd_usec = 0;
	if (sd_watchdog_enabled(0, &wd_usec) > 0 && wd_usec)
		wd_period_real = (double)wd_usec / 2e6;
	else if (app->conf->d.watchdog_s > 0)
		wd_period_real = app->conf->d.watchdog_s / 2;
	if (wd_period_real > 0) /* WATCHDOG_USEC is real time; the loop's clock may run faster (simulated bench) */
		loop_timer_add(app->lp, wd_period_real * rate, wd_period_real * rate, watchdog_tick, NULL);
	loop_timer_add(app->lp, 1.0, 1.0, status_tick, app);
	if (app->conf->laser) {
		/* Every 250 ms real time (the loop's clock may run faster: simulated bench), well within the 3 ×
		 * keepalive_ms (>= 1.5 s) the laser's thread waits for a beat. */
		loop_timer_add(app->lp, 0.25 * rate, 0.25 * rate, laser_heartbeat_tick, app);
	}
	status_tick(app->lp, app);
}

const char *acqd_timers_status(void)
{
	return last_status;
}
