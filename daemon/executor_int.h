/* executor internals: the state shared by the executor's core (executor.c), motion (executor_motion.c) and
 * acquisition (executor_acq.c) files. Not for other modules (the unit test reaches in to simulate a crash). */
#ifndef EXECUTOR_INT_H
#define EXECUTOR_INT_H

#include "daemon/executor.h"

#define EX_MAX_PENDING 24
#define EX_MAX_TIMES 8
#define EX_POS_TOL_DEG 1e-3
#define EX_OFF_TRIES 3 /* a halt sends emission off this many times while the laser reads on, then says so */
#define EX_IO_RECHECK_S 0.25  /* a read is pending: step again at the latest after this (its completion kicks) */

enum phase {
	PH_NONE = 0,
	PH_VERIFY,   /* read positions, reset alarms, home what is not homed */
	PH_HOMING,
	PH_MOVE,     /* waypoint segments */
	PH_SETTLE,
	PH_ACQ,      /* acquisition shots */
	PH_LASER_OFF, /* the laser confirmed off, then the move starts */
	PH_DURABLE,  /* the point is committed: wait for its fsync (store_durable) before going on */
};

enum shot_kind { SHOT_PROBE, SHOT_DARK, SHOT_EXPOSE };

/* What the executor waited for between two steps (ex_stall_step). */
enum ex_stall { EX_STALL_LASER_OFF, EX_STALL_VERIFY, EX_STALL_HOMING, EX_STALL_MOVE, EX_STALL_SETTLE, EX_STALL_DARK,
		EX_STALL_EXPOSURE, EX_STALL_ACQ, EX_STALL_RETRY, EX_STALL_DURABLE, EX_STALL_OTHER, EX_STALL__COUNT };

struct pending {
	const char *kind;            /* "dark", "sample", "reference", "beam" */
	struct spectro_frame *frame;
	double taken_at;
};

struct ex {
	struct ex_cfg cfg;
	struct ex_ops ops;
	void *octx;
	struct ex_sink sink;
	struct store *st;
	int64_t sweep_id, spectro_id;
	struct bench_geom geom;
	const struct plan_result *plan;
	int nsteps;

	enum ex_state state;
	enum phase phase;
	int cur;                     /* step being worked on */
	bool in_reference;           /* the current target is the reference pose */
	bool power_set;              /* the laser's power was set since the last laser fault */
	bool laser_unknown;          /* after a (re)start: switch the laser off whatever we believe */
	bool have_ref;
	bool first_move;             /* next move starts from the measured position (plan_move) */
	bool pause_requested;
	bool paused_by_fault;
	bool laser_confirm;          /* a laser command was queued: read the state before relying on it (and a halt
				      * reports `stopping` until it is read off: ex_stopping) */
	int off_tries;               /* emission-off commands a halt sent while the laser still read on */
	bool move_from_verify;       /* PH_LASER_OFF after verifying positions (else after a commit) */
	bool alarm_reset_sent[3];    /* this verification already reset the axis's alarm */
	bool pos_got[3];             /* positions read so far by this read of all three axes */
	double pos_val[3];
	bool pos_homed[3], pos_alarm[3];
	char reason[512];
	char phase_text[96];
	double wake;

	/* Records of the sweep the database refused (disk full, I/O error): ex_flush_unrecorded() retries them. */
	char lost_state[16];         /* the latest sweep state not stored ("" = none) */
	double lost_state_at;
	struct ex_lost_event {
		char kind[16], device[32], msg[768];
		double at;
	} lost_ev[4];                /* the oldest are dropped past 4; the last (the end) is kept */
	int nlost_ev;

	/* motion */
	struct plan_wp wps[PLAN_MAX_WP + 1];
	int n_wps, wp;
	bool moving[3];
	double settle_until;
	struct plan_pos known;       /* last commanded or measured position */
	bool known_valid;
	struct plan_pos seg_from;    /* where the last segment started (a safe way back from anywhere along it) */
	bool seg_from_valid;
	struct plan_pos actual;      /* measured after settling */
	bool homing[3];

	/* acquisition */
	bool shot_in_flight;
	bool shot_landed;            /* the frame is in; the laser check after it may be pending */
	enum shot_kind shot;
	struct spectro_meas meas;
	struct spectro_frame *frame; /* receive buffer */
	int probe_no;
	double t_probe, t_last;      /* t_last: previous point's base time, the first probe of the next */
	struct spectro_frame *probe; /* the last probe, when it counts as one scan of the first exposure */
	bool probe_pooled;           /* probe is at times[0] (exp_probe_reusable): that exposure takes one scan fewer */
	bool have_t0;
	double times[EX_MAX_TIMES];
	int ntimes, e;
	int nref;                    /* reference exposures reloaded so far (ex_load_reference) */
	struct exp_rate *rates[EX_MAX_TIMES];
	struct exp_rate *merged, *ref_rate;
	uint64_t durable_mark;       /* PH_DURABLE: the point's commit (store_commit_mark) */
	/* A point committed but not yet on disk while the sweep goes on (durable_async: its laser off and the next
	 * move overlap the fsync): counted and announced (progress) once durable, and the next point's commit waits
	 * for that (PH_DURABLE with commit_waits). */
	bool ack_pending, commit_waits;
	uint64_t ack_mark;           /* its commit (store_commit_mark) */
	int ack_point;               /* its step */
	double shots_s;              /* bench seconds of every shot taken (priced as stats.shots_s) */
	double ack_shots_s;          /* shots_s at that commit: stats.shots_s once it is counted */
	struct pending pend[EX_MAX_PENDING];
	int npend;
	int attempts;                /* acquisitions of this point spoiled by saturation */
	int dark_retries;            /* darks in a row rejected for saturated pixels */
	struct exp_darks *darks;
	double temperature;
	const struct spectro_info *info;
	double wl[SPECTRO_MAX_PIXELS];
	unsigned char roi[SPECTRO_MAX_PIXELS];
	int nroi;
	struct calib_spectrum *cal;
	struct exp_avg *avg;
	float scratch[SPECTRO_MAX_PIXELS > 2 * CALIB_MAX_GRID ? SPECTRO_MAX_PIXELS : 2 * CALIB_MAX_GRID]; /* float32 rows for the store */

	/* faults */
	int point_faults;            /* faults since the current point started (reset when it commits) */
	int fault_dev;
	int fault_attempts;
	double backoff, retry_at;
	bool reconnecting;           /* an attempt is under way (its reads may be pending) */
	int recon_stage;             /* 0: the device answers? 1: the laser is ready? */
	char fault_msg[512];

	/* progress */
	double point_started, point_avg_s;
	/* where the real time since the last commit went (ex_stall_*, logged at debug level with stall.h's) */
	double stall_in[EX_STALL__COUNT];
	double stall_from, stall_last, stall_cpu_wait0, stall_ck_s;
	bool stall_stale; /* the baselines were not kept (debug off): the next report only restarts them */
	unsigned long stall_ck_runs;
	int stall_bucket;
	struct ex_stats stats;
};

/* Device names in slot order (enum ex_dev). */
extern const char *const ex_dev_names[EX_DEV__COUNT];

/* ---- core (executor.c) ---- */
/* ex_step's state machine (ex_step in executor_stall.c counts the real time around it). */
double ex_step_run(struct ex *x, double now);
/* Start counting where the real time goes from now (a commit, a start). */
void ex_stall_reset(struct ex *x);
/* After a point's commit: log (debug level) where the real time since the previous commit went. */
void ex_stall_report(struct ex *x, int point);
/* Unix seconds for the records (ops.wall, else the system clock). */
double ex_wall_now(struct ex *x);
/* Record an event in the store and tell the sink (a store failure is not fatal). */
void ex_event(struct ex *x, const char *kind, const char *device, const char *fmt, ...)
	__attribute__((format(printf, 4, 5)));
/* The sweep's state and its event in one transaction (a halt: both stored or neither), then the sink as
 * ex_event. */
void ex_state_event(struct ex *x, const char *state, const char *kind, const char *device, const char *fmt, ...)
	__attribute__((format(printf, 5, 6)));
/* The sweep's state in the store (best effort). */
void ex_set_db_state(struct ex *x, const char *state);
/* Free every pending spectrum. */
void ex_clear_pending(struct ex *x);
/* Discard the pending spectra (and their darks from the cache) and restart the point's acquisition. */
void ex_reset_acq(struct ex *x);
/* Laser off (0, or -1 with err). */
int ex_laser_off(struct ex *x, struct acq_err *err);
/* Best effort: stop the spectrometer and the arms, laser off. */
void ex_safe_stop(struct ex *x);
/* The phase in words (ex_phase). */
void ex_set_phase_text(struct ex *x, const char *s);
/* Stop everything and fail the sweep with the reason. */
void ex_failed(struct ex *x, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Stop everything and pause (by_fault: resuming retries the faulted device first). */
void ex_pause_now(struct ex *x, bool by_fault, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* A device error: suspend and retry the device with backoff, or pause at once. */
void ex_fault(struct ex *x, int dev, const struct acq_err *err);
/* Start a segment of points: verify positions (laser state unknown) before the next move. */
void ex_begin_segment(struct ex *x, double now);
/* A device read is on its way (EX_PENDING): wait for its completion's kick. */
void ex_io_wait(struct ex *x, double now);

/* ---- motion (executor_motion.c) ---- */
/* Waypoints to the current target into x->wps; 0, or -1 when no collision-free path stays inside the limits. */
int ex_plan_path(struct ex *x);
/* Start the first waypoint segment of the current move, or settle at once when there is none. */
void ex_begin_waypoints(struct ex *x, double now);
/* Phase steps: verify positions (and home), home, move along the waypoints, settle. */
void ex_run_verify(struct ex *x, double now);
void ex_run_homing(struct ex *x, double now);
void ex_run_move(struct ex *x, double now);
void ex_run_settle(struct ex *x, double now);
/* Confirm the laser is off (when a command switched it), plan the path, start the move. */
void ex_run_laser_off(struct ex *x, double now);

/* ---- acquisition (executor_acq.c) ---- */
/* The spectrometer's wavelengths and region of interest, once known; false while it is absent. */
bool ex_want_wl(struct ex *x);
/* The sweep's reference from the database (crash-resume): 1 loaded, 0 none, -1 with err. */
int ex_load_reference(struct ex *x, struct acq_err *err);
/* hold_at_end: every step done; laser off, wait (EX_WAITING) for ex_extend or ex_finish. */
void ex_wait_batch(struct ex *x);
/* Phase step: acquisition shots, then the point's commit. */
void ex_run_acq(struct ex *x, double now);
/* Phase step: the committed point on disk? Then the sweep goes on to the next (a failed fsync fails it); with
 * commit_waits: the previous point on disk? Then this point's commit. */
void ex_run_durable(struct ex *x, double now);
/* The point committed with the sweep going on (ack_pending): once on disk, count and announce it. 1 when none is
 * pending any more, 0 still waiting, -1 the fsync failed (the sweep failed). */
int ex_ack_step(struct ex *x);

#endif
