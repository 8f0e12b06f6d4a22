/* commands_int.h: what the command handlers' files share (commands.c dispatches; one file per family of
 * commands: commands_plan.c, commands_sweep.c, commands_manual.c, commands_recon.c; the helpers they all use:
 * commands_reply.c). Internal to the daemon. */
#ifndef COMMANDS_INT_H
#define COMMANDS_INT_H

#include <stddef.h>

#include "daemon/app.h"

/* The address-space bound of a planning child: the dry run (`plan`) and sweep.start's planner alike. */
#define PLAN_MEM_BYTES ((size_t)1 << 30)

/* commands_reply.c: helpers for every handler */
/* Reply to client peer's request id with err's protocol code and message. */
void cmd_reply_err(struct app *app, const struct srv_peer *peer, json_t *id, const struct acq_err *err);
/* The number req[key] (0 if it is not a number), or dflt when the key is absent. */
double cmd_num_arg(json_t *req, const char *key, double dflt);
/* The sweep's progress as a reply object {state, id, done, total, message, eta_s, pause_pending} (new ref). */
json_t *cmd_progress_json(struct app *app);

/* commands_plan.c: `plan`, a dry run in a forked child bounded in time, memory and number; the reply comes
 * when the child ends. */
void cmd_plan_handle(struct app *app, const struct srv_peer *peer, struct proto_req *req);

/* commands_sweep.c: sweep.list/show/start/pause/resume/abort (start and the resume of an interrupted sweep are
 * planned in a worker first; pause/resume/abort reply once the state is reached or after 10 s). */
void cmd_sweep_handle(struct app *app, const struct srv_peer *peer, struct proto_req *req);

/* commands_manual.c: manual device operations, refused while a sweep is loaded; each replies when the devices'
 * threads have done it. */
/* move: the three axes (any subset) to a target whose straight way is collision-free. */
void cmd_manual_move(struct app *app, const struct srv_peer *peer, struct proto_req *req);
/* measure (kind "sample"), dark or reference: one spectrum by hand. */
void cmd_manual_measure(struct app *app, const struct srv_peer *peer, struct proto_req *req, const char *kind);
/* devices: a fresh status read (one at a time; observers at most once per second), else the cached view. */
void cmd_manual_devices(struct app *app, const struct srv_peer *peer, struct proto_req *req);
/* home [axis]: one axis or all three in turn, each only if its way home is collision-free. */
void cmd_manual_home(struct app *app, const struct srv_peer *peer, struct proto_req *req);
/* stop: ends a manual move, homing or measurement; the reply holds where the arms stopped. */
void cmd_manual_stop(struct app *app, const struct srv_peer *peer, struct proto_req *req);
/* laser.off: the laser's thread switches it off and reads it back. */
void cmd_manual_laser_off(struct app *app, const struct srv_peer *peer, struct proto_req *req);

/* commands_recon.c: reconstructions (the executor owns the chain). */
/* recon.start: reconstruct a completed sweep with calibrated samples; replies {run, sweep} at once. */
void cmd_recon_start(struct app *app, const struct srv_peer *peer, struct proto_req *req);
/* recon.status: a run by run or sweep id, or the latest run. */
void cmd_recon_status(struct app *app, const struct srv_peer *peer, struct proto_req *req);

#endif
