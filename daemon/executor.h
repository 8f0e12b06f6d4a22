/* executor: the sweep state machine — walks a plan to calibrated spectral BRDF samples on the bench through a
 * table of device operations, committing each point to the store before the next move.
 *
 * States: idle → running ↔ paused / suspended → completed | aborted | failed.
 *   running    per point: move along the planner's safe waypoints, settle, acquire (auto-exposure probe,
 *              darks with the laser off, exposures with the laser on, merge, calibrate), commit.
 *   paused     by the operator (after the current point), after the white reference (to place the sample), or
 *              when a faulted device did not come back within the retry limits. Laser off.
 *   suspended  a device error: laser off, arms stopped, reconnection attempts with exponential backoff; the
 *              point restarts from its move when the device answers again.
 * A halt (pause, suspend, abort, failure, completion) queues the laser's emission-off; until a read of the laser
 * confirms it, ex_stopping() is true (status `stopping`), so no state without laser is reported while it emits.
 * Commit order of a point: its darks and exposures, one transaction each, then the calibrated sample, then
 * the last exposure in the transaction that marks the point done (so a done point always has its raw
 * spectra and its calibrated sample; a crash inside the sequence leaves a pending point whose partial
 * spectra are discarded on resume).
 *
 * Time is injected: every call takes `now` (monotonic seconds of the caller's loop); ex_step() returns when
 * it wants to be called next. The executor never sleeps and never logs: events go to the sink. */
#ifndef EXECUTOR_H
#define EXECUTOR_H

#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "config/bench.h"
#include "daemon/calib.h"
#include "daemon/exposure.h"
#include "daemon/plan/plan.h"
#include "drivers/spectro.h"

struct store;

enum ex_state { EX_IDLE = 0, EX_RUNNING, EX_PAUSED, EX_SUSPENDED, EX_COMPLETED, EX_ABORTED, EX_FAILED,
	       EX_WAITING /* hold_at_end: every step done, laser off, the sweep still running: ex_extend or ex_finish */ };

/* Devices, in the daemon's slot order (conf_dev). */
enum ex_dev { EX_DEV_LASER_THETA = 0, EX_DEV_DETECTOR_THETA, EX_DEV_DETECTOR_PHI, EX_DEV_SPECTRO, EX_DEV_LASER,
	      EX_DEV__COUNT };

/* A read that is on its way (position, laser_state, reconnect): call it again after the executor is stepped. */
#define EX_PENDING 1

/* Device operations: the executor's one seam to the devices, with one implementation (devices_ex_ops() in
 * devices_ex.c: each operation becomes a request to the device manager, run on that device's port thread) and one
 * test double (tests/unit/test_executor.c: a fake bench at injected time, so a whole sweep with faults runs in
 * seconds). It is kept on purpose, and it is not a driver table: the drivers' tables (drivers/axis_backend.h,
 * laser_backend.h, spectro_backend.h) are one per device class and synchronous, and only the port threads call
 * them; this table is one per executor and speaks for all five devices as the loop sees them: commands only
 * queued, reads that may be EX_PENDING, a reconnection the executor schedules, `lost` handing a failed device
 * back to the manager. Folding it into direct calls of devices_ex.c would tie the executor to the daemon's
 * threads and real time (its unit test could no longer inject either); folding it into the drivers' tables
 * would put driver calls on the loop again.
 * Each returns 0 or -1 with err unless stated; axis is EX_DEV_LASER_THETA..
 * EX_DEV_DETECTOR_PHI. Commands (move_begin, home_begin, stop, alarm_reset, laser_set, laser_power,
 * spectro_start, spectro_stop) may only queue the operation: its failure is then reported by the next poll
 * (move_step, spectro_fetch) or read of that device. Reads (position, laser_state, reconnect) may return
 * EX_PENDING: the result comes with a later call, after the owner stepped the executor again. */
struct ex_ops {
	int (*move_begin)(void *ctx, int axis, double target_deg, double now, struct acq_err *err);
	int (*move_step)(void *ctx, int axis, double now, struct acq_err *err); /* enum axis_move_state */
	double (*next_poll)(void *ctx, int axis);
	int (*stop)(void *ctx, int axis, struct acq_err *err);
	/* Actual position, and whether the axis is homed and free of alarms. */
	int (*position)(void *ctx, int axis, double *deg, bool *homed, bool *alarm, struct acq_err *err);
	int (*home_begin)(void *ctx, int axis, double now, struct acq_err *err);
	int (*alarm_reset)(void *ctx, int axis, struct acq_err *err);
	/* Re-establish a device and check it answers (bounded; the executor schedules the backoff). */
	int (*reconnect)(void *ctx, int dev, struct acq_err *err);
	int (*laser_set)(void *ctx, bool on, struct acq_err *err);
	int (*laser_power)(void *ctx, double pct, struct acq_err *err); /* NULL: power left as it is */
	/* Laser state: emission on, interlock closed and no fault. */
	int (*laser_state)(void *ctx, bool *emission, bool *ready, struct acq_err *err);
	int (*spectro_start)(void *ctx, const struct spectro_meas *m, double now, struct acq_err *err);
	int (*spectro_fetch)(void *ctx, struct spectro_frame *f, double now, struct acq_err *err); /* 1, 0, -1 */
	int (*spectro_stop)(void *ctx, struct acq_err *err);
	const struct spectro_info *(*spectro_info)(void *ctx); /* NULL while the spectrometer is absent */
	double (*wall)(void *ctx); /* Unix seconds for the records (NULL: the system clock) */
	/* Soft limits of an axis in degrees (NULL: no limits known). */
	void (*limits)(void *ctx, int axis, double *min_deg, double *max_deg);
	/* A device operation failed with err (may be NULL): the owner may close and reconnect it. */
	void (*lost)(void *ctx, int dev, const struct acq_err *err);
};

/* Where the executor reports: every interruption and state change (kind: start, pause, resume, fault,
 * recovered, abort, complete, failed, reference, info) and progress after each point. The executor also
 * writes the events to the store's event log itself. */
struct ex_sink {
	void (*event)(void *ctx, int64_t sweep_id, const char *kind, const char *device, const char *message);
	void (*progress)(void *ctx, int64_t sweep_id, int done, int total, double eta_s, const char *phase);
	void *ctx;
};

struct ex_cfg {
	struct exp_policy pol;
	struct calib_cfg cal;
	double laser_power_pct;      /* set before the first emission and after a laser fault */
	bool fixed_integration;      /* the plan fixes the integration time: no probe, one exposure */
	double fixed_ms;
	int dark_every;              /* fresh darks every N points; 0: at every new incidence; -1: never by schedule
				      * (each time's dark kept until it ages or the sensor temperature moves) */
	double extra_settle_s;       /* wait after every move, on top of the controller's own settling */
	double poll_s;               /* spectrometer polling period while an exposure runs */
	double ladder_ratio;         /* integration times are rounded down to min_ms · ratio^k (dark reuse) */
	int fault_retries;           /* reconnection attempts before pausing for the operator */
	double fault_backoff_s, fault_backoff_max_s;
	bool auto_resume_faults;     /* false: a fault pauses for the operator at once */
	struct plan_pos ref_pose;    /* where the reference (relative) or direct beam (absolute) is measured */
	bool take_reference;         /* measure the reference at the start of the sweep */
	bool pause_after_reference;  /* pause so the operator swaps the reference for the sample */
	bool home_unhomed;           /* home an axis that reports not homed (one at a time, path checked); else
				      * its feedback position is used as it is */
	double home_deg[3];          /* where each axis ends after homing (for the collision check) */
	int max_point_attempts;      /* acquisitions of one point spoiled by saturation before accepting it */
	int max_point_faults;        /* faults on one point (each recovered) before pausing for the operator */
	double max_invalid_frac;     /* saturated share of the grid range that spoils an acquisition */
	bool hold_at_end;            /* an adaptive sweep: after the last step wait (EX_WAITING) for more steps */
	bool durable_async;          /* a point's commit is waited on disk through store_durable_fd(), which the
				      * caller watches and then steps the executor (false: the step waits, blocking) */
};

/* Counters for tests and status. */
struct ex_stats {
	int points_done, points_total;
	int spectra, darks, probes, exposures, merges;
	int probes_pooled;           /* probes counted as one scan of their point's first exposure (exp_probe_reusable) */
	int faults, recoveries, retries, saturated_redos; /* redos: saturated or misled (underexposed) */
	int dark_rejects;            /* darks taken again because of saturated pixels */
	double shots_s;              /* bench seconds of the counted points' shots as the planner prices them (n · t +
				      * read-out + half a spectrometer poll, plan_time.c shot): the ETA's split of a
				      * point's real time into the bench's and the host's (eta.h eta_work) */
	bool laser_on;               /* what the executor last commanded */
	int laser_on_while_moving;   /* violations seen (must stay 0) */
};

struct ex;

/* Defaults: exp/calib defaults, 10 ms poll, ladder √2, 5 retries from 0.5 s to 8 s, reference at laser 0°,
 * detector 45° azimuth 180°, taken at start and paused after, 3 attempts, 0.5 % invalid. */
void ex_cfg_defaults(struct ex_cfg *c);

/* A new executor for sweep sweep_id of store st, whose points are the plan's steps (order_index = step
 * index). plan (borrowed, must outlive the executor) is the result the points were made from. NULL + err. */
struct ex *ex_new(const struct ex_cfg *cfg, const struct ex_ops *ops, void *ops_ctx, const struct ex_sink *sink,
		  struct store *st, int64_t sweep_id, int64_t spectrometer_id, const struct bench_geom *geom,
		  const struct plan_result *plan, struct acq_err *err);
/* Stop motion, laser off (best effort), free. NULL is fine. */
void ex_free(struct ex *x, double now);
/* Parse the `sweep.acquisition` mapping (exposure policy keys plus reference_pose [θL, θD, φD],
 * take_reference, pause_after_reference, fault_retries, fault_backoff_s, fault_backoff_max_s, ladder_ratio,
 * poll_s, max_point_attempts, max_invalid_frac, home_unhomed, home_deg, laser_power_pct) and `sweep.calibration` (calib_cfg_parse) onto c. Either node
 * may be NULL. 0 or -1 with file:line:col. */
int ex_cfg_parse(struct yc_node *acq, struct yc_node *cal, struct ex_cfg *c, struct acq_err *err);
/* A sweep's stored white reference (or direct beam) rebuilt as the executor's crash-resume reload does, into the
 * caller's out, without an executor (npix pixels, policy pol, detector full scale; optically black pixels not
 * masked); *detector_theta (may be NULL) as store_reference_each. 1 loaded, 0 none stored, -1 with err. */
int ex_reference_rate(struct store *st, int64_t sweep_id, const struct exp_policy *pol, int npix, double full_scale,
		      struct exp_rate *out, double *detector_theta, struct acq_err *err);
/* Daemon shutdown with the sweep unfinished: stop, laser off, leave it 'paused' in the store with an event
 * so it can be resumed after its last committed point. */
void ex_shutdown(struct ex *x, const char *why);
/* After ex_start(resumed): stay paused (the sweep was paused for the operator before the restart), with why. */
void ex_hold(struct ex *x, const char *why);

/* Start from the first pending point (first_step): 0 for a new sweep; after a crash, the step after the
 * last committed point — positions are then verified (re-homed when unknown) before the first move. */
int ex_start(struct ex *x, int first_step, bool resumed, double now, struct acq_err *err);
/* Advance the machine; returns the monotonic time at which it wants to be called again (≤ now: at once,
 * +INFINITY: nothing scheduled, e.g. paused or finished). */
double ex_step(struct ex *x, double now);
/* Pause after the current point (running/suspended); 0 or -1 (ACQ_E_STATE). */
int ex_pause(struct ex *x, double now, struct acq_err *err);
/* Resume a paused or suspended sweep; 0 or -1 (ACQ_E_STATE). */
int ex_resume(struct ex *x, double now, struct acq_err *err);
/* Abort now: stop the arms, laser off, record why. 0 or -1 (ACQ_E_STATE when already finished). */
int ex_abort(struct ex *x, const char *why, double now, struct acq_err *err);

/* hold_at_end: plan (borrowed, replaces the previous one) has the steps so far as its prefix and more after them:
 * a waiting sweep goes on with them (positions verified, then a fresh safe path from where the arms are); a
 * paused one takes them and stays paused. 0 or -1 (ACQ_E_STATE when not waiting or paused, ACQ_E_INVAL). */
int ex_extend(struct ex *x, const struct plan_result *plan, double now, struct acq_err *err);
/* hold_at_end: complete a waiting (or paused, every step done) sweep, why in the event. 0 or -1 (ACQ_E_STATE). */
int ex_finish(struct ex *x, const char *why, struct acq_err *err);

enum ex_state ex_state(const struct ex *x);
/* Stable name of a state ("running", ...). */
const char *ex_state_name(enum ex_state s);
/* The current phase in words ("moving", "acquiring", "reference", "suspended: spectrometer", ...). */
const char *ex_phase(const struct ex *x);
const struct ex_stats *ex_stats(const struct ex *x);
/* The reason of the last pause/failure/abort ("" if none). */
const char *ex_reason(const struct ex *x);
/* True while the sweep halted (paused, suspended, aborted, failed, completed) and the laser's emission-off it
 * queued is not yet confirmed by a read of the laser: the owner reports it `stopping` and keeps stepping it (a
 * finished sweep is released only after). Never for long: a laser that does not answer ends it with an event. */
bool ex_stopping(const struct ex *x);
/* True while a pause was asked and the point in hand is still being measured (it pauses after it). */
bool ex_pause_pending(const struct ex *x);
/* True while a state or event of the sweep could not be stored (disk full...) and awaits a retry. */
bool ex_has_unrecorded(const struct ex *x);
/* Store the records the database refused, oldest first. 0 when all are stored, or -1 with err. */
int ex_flush_unrecorded(struct ex *x, struct acq_err *err);
/* Index of the step being worked on (== n_steps when done). */
int ex_current_step(const struct ex *x);

/* Sweep angles of a bench position (θi, φi, θo, φo in degrees, zeniths ≥ 0, azimuths in [0, 360)). */
void ex_pos_angles(const struct bench_geom *g, const struct plan_pos *p, double *ti, double *pi, double *to,
		   double *po);

#endif
