/* app: the daemon's context-wide operations — clock, event emission, device notifications, the status line,
 * configuration reload (see app.h). */
#include "daemon/app.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <systemd/sd-daemon.h>

#include "daemon/crashpoint.h"
#include "daemon/devices.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/store.h"
#include "daemon/sweep.h"

double app_wallclock(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* Crash injection for the kill tests (crashpoint.h): the durable steps are the events emitted here, once
 * committed: a sweep event kind (start, reference, pause, resume, fault, complete, ...), "point" (a point committed)
 * or "recon" (a reconstruction event: exported, a stage started, ...). */
static void crash_hook(const char *event, json_t *data)
{
	crash_point(!strcmp(event, "sweep.progress") ? "point"
		    : !strcmp(event, "sweep.fault") ? "fault"
		    : !strcmp(event, "recon") ? "recon"
		    : !strcmp(event, "sweep.state") ? json_string_value(json_object_get(data, "kind")) : NULL);
}

void app_emit(void *ctx, const char *event, json_t *data)
{
	struct app *app = ctx;
	crash_hook(event, data);
	if (!strncmp(event, "sweep.", 6) && app->sweep) { /* systemd's STATUS= follows the sweep at once */
		char line[256];
		app_status_line(app, line, sizeof line);
		sd_notifyf(0, "STATUS=%s", line);
	}
	if (app->srv)
		server_broadcast(app->srv, event, data);
	else
		json_decref(data);
}

void app_device_notify(void *ctx, enum conf_dev dev, bool up, const char *why)
{
	struct app *app = ctx;
	log_msg(up ? LOG_INFO : LOG_WARNING, "%s: %s", conf_dev_name(dev), up ? "available" : why);
	if (app->store)
		store_event(app->store, 0, up ? "recovered" : "fault", conf_dev_name(dev), why, app_wallclock(), NULL);
	app_emit(app, "device", json_pack("{s:s,s:b,s:s}", "name", conf_dev_name(dev), "available", up, "message", why));
	if (up && app->sweep)
		sweep_device_back(app->sweep, dev);
}

void app_status_line(struct app *app, char *buf, size_t cap)
{
	struct sweep_progress p;
	sweep_get_progress(app->sweep, &p);
	int avail = app->dev ? devices_available(app->dev) : 0;
	if (p.state == SWEEP_IDLE)
		snprintf(buf, cap, "idle; devices %d/%d available%s", avail, CONF_DEV__COUNT,
			 sweep_recon_busy(app->sweep) ? "; reconstruction running" : "");
	else if (p.state == SWEEP_FAULTED && p.message[0]) /* what is wrong matters more than the ETA */
		snprintf(buf, cap, "sweep %lld %s: %d/%d points: %s", (long long)p.sweep_id, sweep_state_name(p.state),
			 p.points_done, p.points_total, p.message);
	else if (p.state == SWEEP_RUNNING && isfinite(p.eta_s)) { /* a paused sweep's ETA does not count down */
		long s = lround(p.eta_s);
		snprintf(buf, cap, "sweep %lld %s: %d/%d points, ETA %ld:%02ld:%02ld", (long long)p.sweep_id,
			 sweep_state_name(p.state), p.points_done, p.points_total, s / 3600, s / 60 % 60, s % 60);
	}
	else
		snprintf(buf, cap, "sweep %lld %s: %d/%d points", (long long)p.sweep_id, sweep_state_name(p.state),
			 p.points_done, p.points_total);
}

int app_reload(struct app *app, struct acq_err *err)
{
	if (sweep_busy(app->sweep))
		return acq_errf(err, ACQ_E_STATE, "a sweep is loaded; reload after it ends or is aborted");
	if (devices_busy(app->dev))
		return acq_errf(err, ACQ_E_STATE, "a manual move or measurement is running");
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	sd_notifyf(0, "RELOADING=1\nMONOTONIC_USEC=%llu",
		   (unsigned long long)ts.tv_sec * 1000000ULL + (unsigned long long)ts.tv_nsec / 1000);
	struct conf *nc = NULL;
	if (conf_load(app->conf_path, app->have_sim ? &app->sim : NULL, &nc, err)) {
		sd_notify(0, "READY=1");
		return acq_err_prefix(err, "reload refused, the running configuration stays: ");
	}
	if (strcmp(nc->d.socket_path, app->conf->d.socket_path) || strcmp(nc->d.database, app->conf->d.database) ||
	    nc->d.tcp_port != app->conf->d.tcp_port)
		log_msg(LOG_WARNING, "reload: socket, database and tcp_port changes take effect at the next restart");
	/* Devices are reopened from the new configuration (same object: the executor keeps its pointer);
	 * socket and database stay. */
	if (devices_reconfigure(app->dev, nc, err)) {
		conf_free(nc);
		sd_notify(0, "READY=1");
		return -1;
	}
	/* The paths in use stay (app-owned copies made at start). */
	nc->d.socket_path = app->sock_path;
	nc->d.database = app->db_path;
	struct conf *old = app->conf;
	app->conf = nc;
	server_set_conf(app->srv, &nc->d);
	sweep_conf_changed(app->sweep, nc);
	log_set_level(nc->d.log_level);
	conf_free(old);
	log_msg(LOG_NOTICE, "configuration reloaded from %s", nc->path);
	app_emit(app, "config", json_pack("{s:s}", "path", nc->path));
	sd_notify(0, "READY=1");
	return 0;
}

