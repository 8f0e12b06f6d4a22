/* commands_recon: recon.start and recon.status; the executor owns the reconstruction chain (sweep_recon_start),
 * here are the checks and the replies. */
#include "daemon/commands_int.h"

#include <string.h>

#include "daemon/log.h"
#include "daemon/store.h"
#include "daemon/sweep.h"

void cmd_recon_start(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	int64_t sweep = (int64_t)cmd_num_arg(req->root, "sweep", 0);
	json_t *sw = store_sweep_show(app->store, sweep, false, &err);
	if (!sw)
		return cmd_reply_err(app, peer, req->id, &err);
	const char *state = json_string_value(json_object_get(sw, "state"));
	json_int_t ncal = json_integer_value(json_object_get(sw, "calibrated"));
	if (!state || strcmp(state, "completed") || ncal == 0) {
		acq_errf(&err, ACQ_E_STATE, "sweep %lld is %s with %lld calibrated samples: nothing to reconstruct yet",
			 (long long)sweep, state ? state : "?", (long long)ncal);
		json_decref(sw);
		return cmd_reply_err(app, peer, req->id, &err);
	}
	json_decref(sw);
	if (sweep_recon_busy(app->sweep)) {
		acq_errf(&err, ACQ_E_STATE, "a reconstruction is already running");
		return cmd_reply_err(app, peer, req->id, &err);
	}
	int64_t run = 0;
	if (sweep_recon_start(app->sweep, sweep, &run, &err))
		return cmd_reply_err(app, peer, req->id, &err);
	if (run)
		app->recon_run = run;
	app->recon_sweep = sweep;
	log_msg(LOG_INFO, "reconstruction of sweep %lld started (run %lld)", (long long)sweep, (long long)run);
	server_reply(app->srv, peer->serial, req->id,
		     json_pack("{s:I,s:I}", "run", (json_int_t)run, "sweep", (json_int_t)sweep));
}

void cmd_recon_status(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	int64_t run = (int64_t)cmd_num_arg(req->root, "run", 0), sweep = (int64_t)cmd_num_arg(req->root, "sweep", 0);
	if (!run && !sweep) {
		/* the latest run, whoever started it (recon.start or the end of a sweep) */
		if (!(run = store_recon_latest(app->store))) {
			acq_errf(&err, ACQ_E_NOTFOUND, "no reconstruction has run yet; give sweep or run");
			return cmd_reply_err(app, peer, req->id, &err);
		}
	}
	json_t *r = store_recon_show(app->store, run, sweep, &err);
	if (!r)
		return cmd_reply_err(app, peer, req->id, &err);
	server_reply(app->srv, peer->serial, req->id, json_pack("{s:o}", "run", r));
}
