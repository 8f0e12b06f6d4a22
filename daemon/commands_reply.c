/* commands_reply: what every command handler uses: the error reply, a number argument, the sweep's progress. */
#include "daemon/commands_int.h"

#include <math.h>

#include "daemon/sweep.h"

void cmd_reply_err(struct app *app, const struct srv_peer *peer, json_t *id, const struct acq_err *err)
{
	server_reply_error(app->srv, peer->serial, id, proto_code_of(err), err->msg);
}

double cmd_num_arg(json_t *req, const char *key, double dflt)
{
	json_t *v = json_object_get(req, key);
	return v ? json_number_value(v) : dflt;
}

json_t *cmd_progress_json(struct app *app)
{
	struct sweep_progress p;
	sweep_get_progress(app->sweep, &p);
	json_t *o = json_pack("{s:s,s:I,s:i,s:i,s:s}", "state", sweep_state_name(p.state), "id", (json_int_t)p.sweep_id,
			      "done", p.points_done, "total", p.points_total, "message", p.message);
	/* wall-clock seconds, only while running: a paused sweep has no ETA that counts down */
	json_object_set_new(o, "eta_s", p.state == SWEEP_RUNNING && isfinite(p.eta_s) ? json_real(p.eta_s) : json_null());
	if (p.state == SWEEP_RUNNING && isfinite(p.eta_s) && isfinite(p.eta_low_s) && isfinite(p.eta_high_s)) {
		/* where the rest's exposures are unknown (an auto sweep's unmeasured incidences) */
		json_object_set_new(o, "eta_low_s", json_real(p.eta_low_s));
		json_object_set_new(o, "eta_high_s", json_real(p.eta_high_s));
	}
	/* a pause asked while a point is measured takes effect after it (sweep.pause replies by then or after 10 s) */
	json_object_set_new(o, "pause_pending", json_boolean(p.state == SWEEP_RUNNING && p.pause_pending));
	return o;
}
