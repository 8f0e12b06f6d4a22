/* app: the daemon's context-wide operations — clock, event emission, device notifications, the status line,
 * configuration reload (see app.h). */
#include "daemon/app.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <systemd/sd-daemon.h>

#include "daemon/conf_diff.h"
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

/* Settings changes listed in a reload's reply and log (the rest counted). */
#define APP_RELOAD_MAX_CHANGES 40

/* Compare the devices before and after a reload (devices_json() arrays): a device the new file drops or that no
 * longer answers goes to warnings, one it adds to changes. */
static void reload_devices(json_t *before, json_t *after, json_t *warnings, json_t *changes)
{
	for (size_t i = 0; i < json_array_size(after) && i < json_array_size(before); i++) {
		json_t *b = json_array_get(before, i), *a = json_array_get(after, i);
		const char *name = json_string_value(json_object_get(a, "name"));
		const char *note = json_string_value(json_object_get(a, "note"));
		bool bc = json_is_true(json_object_get(b, "configured")), ac = json_is_true(json_object_get(a, "configured"));
		bool ba = json_is_true(json_object_get(b, "available")), aa = json_is_true(json_object_get(a, "available"));
		char line[512];
		if (bc && !ac)
			snprintf(line, sizeof line, "%s: no longer configured (%s): closed%s", name,
				 note ? note : "not configured", ba ? " (it was available)" : "");
		else if (ba && ac && !aa)
			snprintf(line, sizeof line, "%s: unavailable after the reload: %s", name, note ? note : "?");
		else if (!bc && ac)
			snprintf(line, sizeof line, "%s: now configured, %s%s%s", name, aa ? "available" : "unavailable",
				 !aa && note ? ": " : "", !aa && note ? note : "");
		else
			continue;
		json_array_append_new(!bc && ac ? changes : warnings, json_string(line));
	}
}

int app_reload(struct app *app, json_t **report, struct acq_err *err)
{
	if (report)
		*report = NULL;
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
	json_t *before = devices_json(app->dev);
	if (devices_reconfigure(app->dev, nc, err)) {
		json_decref(before);
		conf_free(nc);
		sd_notify(0, "READY=1");
		return -1;
	}
	/* What the new file changed, said in the reply and the log: a wrong or damaged file that still parses (one
	 * without its device sections: `bench: {}`) must not close the devices unsaid. */
	json_t *after = devices_json(app->dev), *warnings = json_array(), *changes = json_array();
	reload_devices(before, after, warnings, changes);
	json_decref(before);
	json_decref(after);
	int ndev = (int)json_array_size(changes);
	int total = conf_diff(yc_root(app->conf->doc), yc_root(nc->doc), APP_RELOAD_MAX_CHANGES, changes);
	for (size_t i = 0; i < json_array_size(warnings); i++)
		log_msg(LOG_WARNING, "reload: %s", json_string_value(json_array_get(warnings, i)));
	for (size_t i = 0; i < json_array_size(changes); i++)
		log_msg(LOG_NOTICE, "reload: %s", json_string_value(json_array_get(changes, i)));
	if (total > APP_RELOAD_MAX_CHANGES)
		log_msg(LOG_NOTICE, "reload: and %d more settings changed", total - APP_RELOAD_MAX_CHANGES);
	/* The paths in use stay (app-owned copies made at start). */
	nc->d.socket_path = app->sock_path;
	nc->d.database = app->db_path;
	struct conf *old = app->conf;
	app->conf = nc;
	server_set_conf(app->srv, &nc->d);
	sweep_conf_changed(app->sweep, nc);
	log_set_level(nc->d.log_level);
	conf_free(old);
	log_msg(LOG_NOTICE, "configuration reloaded from %s%s", nc->path,
		json_array_size(warnings) ? " (see the warnings above)" : json_array_size(changes) ? "" : " (no setting changed)");
	json_t *ev = json_pack("{s:s}", "path", nc->path);
	if (ev && json_array_size(warnings)) /* a watcher sees the devices the reload closed */
		json_object_set_new(ev, "warnings", json_deep_copy(warnings));
	app_emit(app, "config", ev);
	if (report) {
		*report = json_pack("{s:o,s:o}", "warnings", warnings, "changes", changes);
		if (*report && total > APP_RELOAD_MAX_CHANGES)
			json_object_set_new(*report, "changes_total", json_integer(ndev + total));
	} else {
		json_decref(warnings);
		json_decref(changes);
	}
	sd_notify(0, "READY=1");
	return 0;
}

