/* app: the daemon's one context — every module's instance, wired by acquisitiond/acqd_start.c and used by the
 * command handlers (commands.c). Only the daemon's body sees it; the sweep executor gets sweep_env. */
#ifndef APP_H
#define APP_H

#include <stdbool.h>
#include <stdint.h>

#include "daemon/conf.h"
#include "daemon/job.h"
#include "daemon/server.h"
#include "proto/proto.h"

struct loop;
struct store;
struct devices;
struct sweep;

struct app {
	struct loop *lp;
	struct conf *conf;
	const char *conf_path;
	struct conf_sim sim;
	bool have_sim;
	struct store *store;
	struct devices *dev;
	struct sweep *sweep;
	struct server *srv;
	double started_wall, started_mono;
	/* last reconstruction started by recon.start (the executor runs it) */
	int64_t recon_run, recon_sweep;
	bool stopping;
	char sock_path[256], db_path[4096];  /* in use until exit, whatever a reload says */
};

/* Handle one authorised request (server_req_fn). */
void commands_handle(void *ctx, const struct srv_peer *peer, struct proto_req *req);
/* At start-up with daemon.auto_resume: re-plan the latest interrupted sweep's stored plan in a worker (as
 * sweep.resume does), so the loop serves clients and feeds the watchdog meanwhile; once planned it resumes after
 * its last committed point (paused for the operator if it was), and the outcome is logged. *id: the sweep
 * being planned. 0 (planning, or nothing to resume) or -1 with err. */
int commands_auto_resume(struct app *app, int64_t *id, struct acq_err *err);
/* The `plan` command's child, run by the job helper (the program's table of job kinds, job_kinds_main). */
extern const struct job_kind commands_plan_kind;
/* Reload the configuration file: refused while a sweep (loaded: running, paused or faulted) or a manual
 * operation runs. What the new file changes is logged and, when report is not NULL, put in *report (a new
 * object: "warnings", the devices it closes or that no longer answer; "changes", the settings it changes and
 * the devices it adds; "changes_total" when more than listed). 0 or -1. */
int app_reload(struct app *app, json_t **report, struct acq_err *err);
/* Unix time now, seconds. */
double app_wallclock(void);
/* Emit an event to watchers (data consumed) — the sweep executor's env->emit. */
void app_emit(void *ctx, const char *event, json_t *data);
/* A device changed availability (devices_notify_fn). */
void app_device_notify(void *ctx, enum conf_dev dev, bool up, const char *why);
/* One-line status for systemd's STATUS= and logs. */
void app_status_line(struct app *app, char *buf, size_t cap);

#endif
