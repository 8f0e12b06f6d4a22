/* commands: what each protocol command does in the daemon (dispatch from server.c; see proto_cmds[]): the
 * dispatch and the information commands (version, status, config, spectrum, reload); the families of commands
 * have a file each, and the helpers every handler uses are in commands_reply.c (commands_int.h). */
#include "daemon/commands_int.h"

#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "acq_version.h"
#include "daemon/devices.h"
#include "daemon/export.h"
#include "daemon/store.h"
#include "daemon/sweep.h"

/* ---- information ---- */
static void cmd_spectrum(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	json_t *s = store_spectrum_json(app->store, (int64_t)cmd_num_arg(req->root, "spectrum", 0), &err);
	if (!s)
		return cmd_reply_err(app, peer, req->id, &err);
	server_reply(app->srv, peer->serial, req->id, json_pack("{s:o}", "spectrum", s));
}

static json_t *config_json(struct app *app, bool text)
{
	const struct conf *c = app->conf;
	json_t *ctl = json_array(), *obs = json_array(), *notes = json_object();
	for (int i = 0; i < c->d.ncontrollers; i++)
		json_array_append_new(ctl, json_string(c->d.controllers[i]));
	for (int i = 0; i < c->d.nobservers; i++)
		json_array_append_new(obs, json_string(c->d.observers[i]));
	for (int d = 0; d < CONF_DEV__COUNT; d++)
		if (c->devnote[d][0])
			json_object_set_new(notes, conf_dev_name((enum conf_dev)d), json_string(c->devnote[d]));
	char mode[8];
	snprintf(mode, sizeof mode, "%04o", (unsigned)c->d.socket_mode);
	json_t *o = json_pack(
		"{s:s,s:b,s:{s:s,s:s,s:s,s:s,s:s?,s:i,s:o,s:o,s:b,s:f},"
		"s:{s:f,s:i,s:f,s:f,s:f,s:f,s:i,s:i,s:b,s:b},s:{s:s,s:f,s:i,s:s},s:o}",
		"path", c->path, "sim", c->have_sim,
		"daemon", "state_dir", c->d.state_dir, "database", c->d.database, "socket", c->d.socket_path, "socket_mode",
		mode, "socket_group", c->d.socket_group, "tcp_port", c->d.tcp_port, "controllers", ctl, "observers", obs,
		"auto_resume", c->d.auto_resume, "device_retry_s", c->d.device_retry_s,
		"sweep", "move_timeout_s", c->sweep.move_timeout_s, "move_retries", c->sweep.move_retries, "extra_settle_s",
		c->sweep.extra_settle_s, "target_peak", c->sweep.target_peak, "min_integration_ms",
		c->sweep.min_integration_ms, "max_integration_ms", c->sweep.max_integration_ms, "averages",
		c->sweep.averages, "dark_every", c->sweep.dark_every, "auto_resume_faults", c->sweep.auto_resume_faults,
		"auto_recon", c->sweep.auto_recon,
		"recon", "program", c->recon.program, "timeout_s", c->recon.timeout_s, "threads", c->recon.threads,
		"output_dir", c->recon.output_dir,
		"device_notes", notes);
	if (o && text)
		json_object_set_new(o, "text", json_string(c->text));
	return o;
}

static json_t *status_json(struct app *app)
{
	int clients = 0, watchers = 0;
	server_counts(app->srv, &clients, &watchers);
	char line[256];
	app_status_line(app, line, sizeof line);
	struct server_stats ss;
	server_get_stats(app->srv, &ss);
	json_t *srvj = json_pack("{s:I,s:I,s:I,s:I,s:I}", "refused", (json_int_t)ss.refused, "dropped_unread",
				 (json_int_t)ss.dropped_output, "dropped_stalled", (json_int_t)ss.dropped_stalled,
				 "timed_out", (json_int_t)ss.timed_out, "rate_limited", (json_int_t)ss.rate_limited);
	int64_t rrun = store_recon_latest(app->store), rsweep = 0;
	if (rrun) {
		json_t *r = store_recon_show(app->store, rrun, 0, NULL);
		rsweep = (int64_t)json_integer_value(json_object_get(r, "sweep_id"));
		json_decref(r);
	}
	json_t *o = json_pack("{s:s,s:s,s:i,s:f,s:f,s:o,s:{s:i,s:i},s:i,s:i,s:{s:b,s:I,s:I},s:s,s:b}", "daemon", "running",
			 "version", ACQ_VERSION, "pid", (int)getpid(), "uptime_s", app_wallclock() - app->started_wall,
			 "started_at", app->started_wall, "sweep", cmd_progress_json(app), "devices", "available",
			 devices_available(app->dev), "total", CONF_DEV__COUNT, "clients", clients, "watchers", watchers,
			 "recon", "running", sweep_recon_busy(app->sweep), "run", (json_int_t)rrun, "sweep", (json_int_t)rsweep,
			 "summary", line, "sim", app->have_sim);
	if (o)
		json_object_set_new(o, "server", srvj);
	else
		json_decref(srvj);
	return o;
}

void commands_handle(void *ctx, const struct srv_peer *peer, struct proto_req *req)
{
	struct app *app = ctx;
	const char *cmd = req->cmd;
	struct acq_err err = { 0 };
	if (!strcmp(cmd, "version")) {
		server_reply(app->srv, peer->serial, req->id,
			     json_pack("{s:s,s:i,s:s,s:i,s:s}", "version", ACQ_VERSION, "protocol", PROTO_VERSION, "server",
				       "acquisitiond", "schema", store_schema_version(app->store), "role",
				       peer->role == PROTO_CONTROLLER ? "controller" : "observer"));
	} else if (!strcmp(cmd, "status")) {
		server_reply(app->srv, peer->serial, req->id, status_json(app));
	} else if (!strcmp(cmd, "devices")) {
		cmd_manual_devices(app, peer, req);
	} else if (!strcmp(cmd, "config")) {
		bool text = json_is_true(json_object_get(req->root, "text"));
		if (text && peer->tcp) /* the file may name users, paths and devices: local users with a uid only */
			server_reply_error(app->srv, peer->serial, req->id, PROTO_E_FORBIDDEN,
					   "config text: not over TCP (no credentials); use the Unix socket");
		else
			server_reply(app->srv, peer->serial, req->id, json_pack("{s:o}", "config", config_json(app, text)));
	} else if (!strcmp(cmd, "plan")) {
		cmd_plan_handle(app, peer, req);
	} else if (!strncmp(cmd, "sweep.", 6)) {
		cmd_sweep_handle(app, peer, req);
	} else if (!strcmp(cmd, "move")) {
		cmd_manual_move(app, peer, req);
	} else if (!strcmp(cmd, "home")) {
		cmd_manual_home(app, peer, req);
	} else if (!strcmp(cmd, "stop")) {
		cmd_manual_stop(app, peer, req);
	} else if (!strcmp(cmd, "laser.off")) {
		cmd_manual_laser_off(app, peer, req);
	} else if (!strcmp(cmd, "spectrum")) {
		cmd_spectrum(app, peer, req);
	} else if (!strcmp(cmd, "measure")) {
		cmd_manual_measure(app, peer, req, "sample");
	} else if (!strcmp(cmd, "dark") || !strcmp(cmd, "reference")) {
		cmd_manual_measure(app, peer, req, cmd);
	} else if (!strcmp(cmd, "recon.start")) {
		cmd_recon_start(app, peer, req);
	} else if (!strcmp(cmd, "recon.status")) {
		cmd_recon_status(app, peer, req);
	} else if (!strcmp(cmd, "export")) {
		export_handle(app, peer, req);
	} else if (!strcmp(cmd, "reload")) {
		json_t *report = NULL;
		if (app_reload(app, &report, &err))
			cmd_reply_err(app, peer, req->id, &err);
		else { /* with what the new file changed: warnings (devices closed or lost) and changes */
			json_object_set_new(report, "config", json_string(app->conf->path));
			server_reply(app->srv, peer->serial, req->id, report);
		}
	} else {
		server_reply_error(app->srv, peer->serial, req->id, PROTO_E_INTERNAL, "command in the table but not handled");
	}
}
