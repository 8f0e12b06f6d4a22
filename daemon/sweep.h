/* sweep: the seam between the daemon's body and the sweep executor (daemon/sweep.c, owned by the sweep
 * engineer). The executor walks a plan on the daemon's loop — timers and device state machines, never a
 * blocking call — commits each spectrum through store.h and reports progress through env->emit.
 *
 * Contract with the body:
 *  - The body calls sweep_init() after the store, devices and server exist, and sweep_finish() before
 *    them at shutdown (the executor leaves an unfinished sweep 'paused' in the store, with an event).
 *  - Commands arrive through sweep_start_planned/pause/resume/abort; errors are struct acq_err with ACQ_E_STATE
 *    (not now), ACQ_E_NOTFOUND, ACQ_E_INVAL (bad plan, message names line:col), ACQ_E_UNSUPPORTED (missing
 *    piece), ACQ_E_DEVICE/ACQ_E_DISCONNECTED (device fault) — the body maps them to wire codes.
 *  - Events the executor emits (env->emit(ctx, name, data), data consumed): "sweep.progress"
 *    {sweep, state, done, total, eta_s, point; eta_low_s, eta_high_s where the rest's exposures
 *    are unknown}, "sweep.state" {sweep, state, reason}, "sweep.fault"
 *    {sweep, device, message}; the body forwards them to watchers and to systemd's STATUS=.
 *  - sweep_busy() true blocks configuration reloads and manual moves/measurements.
 *  - Device faults: the executor calls devices_lost() (devices.h); the body reconnects and calls
 *    sweep_device_back() when a device is available again (auto-resume if configured). */
#ifndef SWEEP_H
#define SWEEP_H

#include <jansson.h>
#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "daemon/conf.h"

struct loop;
struct store;
struct devices;
struct sweep;
struct plan_spec;
struct plan_result;

enum sweep_state {
	SWEEP_IDLE = 0,    /* no sweep loaded */
	SWEEP_RUNNING,     /* moving / measuring */
	SWEEP_PAUSED,      /* paused by the operator */
	SWEEP_FAULTED,     /* suspended by a device fault (resumes by itself when the device is back, if allowed) */
	SWEEP_STOPPING,    /* a halt in progress (pause, fault, abort, failure, completion): the laser's emission-off is
			    * queued and not yet confirmed by a read of the laser (ex_stopping) */
};

struct sweep_progress {
	enum sweep_state state;
	int64_t sweep_id;          /* 0 when idle */
	int points_done, points_total;
	double eta_s;              /* estimated seconds left, NaN if unknown */
	double eta_low_s, eta_high_s; /* its interval where the rest's exposures are unknown (NaN: none) */
	double started_at;         /* Unix seconds, 0 if idle */
	char message[256];         /* what it is doing or why it is suspended */
	bool pause_pending;        /* running, and pauses after the point in hand */
};

struct sweep_env {
	struct loop *loop;         /* time: loop_now(); schedule with loop_timer_add() */
	struct store *store;
	struct devices *devices;
	const struct conf *conf;   /* replaced by sweep_conf_changed() after a reload */
	void (*emit)(void *ctx, const char *event, json_t *data);
	void *emit_ctx;
	double (*wallclock)(void); /* Unix seconds for the database */
	const char *software_version;
};

/* Create the executor (copies env). 0 or -1. */
int sweep_init(const struct sweep_env *env, struct sweep **out, struct acq_err *err);
/* Stop timers, leave an unfinished sweep resumable (state 'paused' + event), free. NULL is fine. */
void sweep_finish(struct sweep *sw);
/* Whether a sweep could start now (none loaded or being planned, every device up). 0 or -1. */
int sweep_start_check(const struct sweep *sw, struct acq_err *err);
/* Mark a plan being made elsewhere for sweep_start_planned() (a worker: large plans take long); meanwhile
 * sweep_busy() is true (no reload, manual operation or other start). */
void sweep_set_planning(struct sweep *sw, bool planning);
/* Stored sweep → running, from spec and plan already made from plan_text (plan_load_string, plan_make,
 * plan_time_apply with sweep_plan_timing(), in a worker); *id is the new sweep's id. Takes both, freed on failure
 * too. 0 or -1. */
int sweep_start_planned(struct sweep *sw, const char *plan_text, const char *name, struct plan_spec *spec,
			struct plan_result *plan, int64_t *id, struct acq_err *err);
/* Pause after the current spectrum is committed. 0 or -1 (ACQ_E_STATE when nothing runs). */
int sweep_pause(struct sweep *sw, struct acq_err *err);
/* Resume the paused sweep, or the interrupted sweep id from the store (id 0: the current one). 0 or -1. */
int sweep_resume(struct sweep *sw, int64_t id, struct acq_err *err);
/* For sweep_resume() off the loop: when no sweep is loaded, the interrupted sweep id (0: the latest) that
 * would be resumed, in *found, with its stored plan text and name (the caller frees; name may be NULL) to plan
 * elsewhere for sweep_resume_planned(). 1 when a sweep is loaded (sweep_resume() then plans nothing), 0, -1. */
int sweep_resume_plan_text(struct sweep *sw, int64_t id, int64_t *found, char **text, char **name,
			   struct acq_err *err);
/* sweep_resume() of the interrupted sweep id with spec and plan made from its stored text (as for
 * sweep_start_planned; takes both, freed on failure too). hold (the resume at start-up, daemon.auto_resume): a
 * sweep paused for the operator before the restart stays paused. 0 or -1. */
int sweep_resume_planned(struct sweep *sw, int64_t id, struct plan_spec *spec, struct plan_result *plan, bool hold,
			 struct acq_err *err);
/* Abort: laser off, arms stopped, sweep 'aborted'. 0 or -1. */
int sweep_abort(struct sweep *sw, struct acq_err *err);
/* `recon.start`: run the completion chain again for a finished sweep (export of its calibrated samples,
 * then the reconstruction stages in child processes through job.h). *run_id: its recon_runs row (0 if not
 * known yet). ACQ_E_STATE while a sweep or a reconstruction runs, ACQ_E_NOTFOUND for no such sweep,
 * ACQ_E_UNSUPPORTED when brdf-recon is absent. 0 or -1. */
int sweep_recon_start(struct sweep *sw, int64_t sweep_id, int64_t *run_id, struct acq_err *err);
/* True while a reconstruction child of the executor runs. (Weak default: false.) */
bool sweep_recon_busy(const struct sweep *sw);
/* A device came back (called by the body after a reconnect). */
void sweep_device_back(struct sweep *sw, enum conf_dev dev);
/* The configuration was reloaded (only while !sweep_busy()). */
void sweep_conf_changed(struct sweep *sw, const struct conf *c);
/* Current progress (never fails). */
void sweep_get_progress(const struct sweep *sw, struct sweep_progress *p);
/* True while a sweep is loaded (running, paused, faulted or stopping). */
bool sweep_busy(const struct sweep *sw);
/* The planner's timing of this daemon's executor (acquisition, sweep settings) for plan_time_apply(). */
struct plan_timing;
void sweep_plan_timing(const struct sweep *sw, struct plan_timing *t);
/* The exposure prior of spec into t->prior (plan.h): for an auto plan that names its sample, from the latest
 * completed auto sweep of that sample but exclude (0: none); none otherwise. Without the prior's host figure, the
 * host's time per point (t->point_overhead_s, t->host_sweep: the latest completed sweep but exclude when it
 * measured it; t->host_kind: the latest of each plan kind), kept in sw until a sweep completes (exp_host_cached).
 * A database error is logged (the defaults then). */
void sweep_plan_prior(struct sweep *sw, const struct plan_spec *spec, int64_t exclude, struct plan_timing *t);
/* The same from what it reads of the spec: the sample's name for an auto plan ("" for none), NULL for no spec. */
void sweep_plan_prior_of(struct sweep *sw, const char *sample, int64_t exclude, struct plan_timing *t);
/* "idle", "running", "paused", "faulted", "stopping". */
const char *sweep_state_name(enum sweep_state s);

#endif
