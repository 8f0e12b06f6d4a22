/* store: the SQLite database of sweeps, points, spectra, calibrations, reconstruction runs and events
 * (schema: daemon/schema.sql; the module's files daemon/store*.c, listed in store.c). WAL mode, one transaction
 * per write (a point's writes grouped in one), commits made durable by the store's own thread (store_durable),
 * versioned schema with migrations; a foreign or corrupt file is refused and never written. Never logs: -1 +
 * struct acq_err. */
#ifndef STORE_H
#define STORE_H

#include <jansson.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "config/acq_err.h"
#include "drivers/spectro.h"

#define STORE_APPLICATION_ID 0x42524446  /* "BRDF" */
#define STORE_SCHEMA_VERSION 6

struct store;
struct spectro_info;

struct store_sweep_new {
	const char *name;
	const char *plan_text;
	const char *config_snapshot;
	const char *software_version;
	const char *calibration_method;  /* may be NULL */
	int64_t spectrometer_id;         /* 0 = unknown */
	double created_at;               /* Unix seconds */
	const char *sample;              /* the sample's name (the plan's sample:), NULL or "": not recorded */
	bool auto_exposure;              /* its exposures are the auto exposure's choice (an exposure prior's source) */
	const char *plan_kind;           /* the plan's kind (plan_kind_of), NULL: not recorded */
};

struct store_point_new {
	int order_index;
	double theta_i, phi_i, theta_o, phi_o;
};

struct store_spectrum {
	int64_t sweep_id, point_id;      /* 0 = none (manual measurement) */
	const char *kind;                /* "sample", "dark", "reference", "beam" */
	int64_t spectrometer_id;         /* 0 = unknown */
	double integration_ms;
	int averages;
	int npix;
	const float *counts;             /* npix values */
	const float *stddev;             /* npix values or NULL */
	int saturated_count;
	const unsigned char *saturated;  /* npix flags or NULL */
	double temperature_c;            /* NaN = unknown */
	double taken_at;
	/* When set, the same transaction marks point_id done with these actual angles (NaN = unknown): the arms'
	 * and the sample-frame angles they make (ex_pos_angles), which every reader of the samples uses. */
	bool completes_point;
	double laser_theta, detector_theta, detector_phi;
	double theta_i, phi_i, theta_o, phi_o;
};

/* Open (creating if absent or empty) the database at path; migrate an older schema. Refuses, without
 * writing a byte, a file that is not SQLite, is corrupt, belongs to another application, or has a newer
 * schema. 0 or -1. */
int store_open(const char *path, struct store **out, struct acq_err *err);
/* Checkpoint and close. NULL is fine. */
void store_close(struct store *st);
/* The underlying schema version of an open store. */
int store_schema_version(struct store *st);

/* Create a sweep in state 'planned' with its points (one transaction). 0 or -1. */
int store_sweep_create(struct store *st, const struct store_sweep_new *sw, const struct store_point_new *pts,
		       int npts, int64_t *id, struct acq_err *err);
/* Set a sweep's state (planned/running/paused/completed/aborted/failed) and the matching time. 0 or -1. */
int store_sweep_set_state(struct store *st, int64_t id, const char *state, double at, struct acq_err *err);
/* The most recent sweep left 'running' or 'paused' (interrupted by a crash), 0 if none. 0 or -1. */
int store_sweep_interrupted(struct store *st, int64_t *id, struct acq_err *err);
/* Order index of the first point of sweep id not yet done/skipped/failed (-1 when all are). 0 or -1. */
int store_sweep_next_point(struct store *st, int64_t id, int *order_index, int64_t *point_id,
			   struct acq_err *err);
/* Delete the spectra of a point not yet done (a partial point before a resume: nothing twice). 0 or -1. */
int store_point_discard_partial(struct store *st, int64_t point_id, struct acq_err *err);

/* Insert one spectrum in its own transaction (committed on return; on disk once store_durable says so). *id may be
 * NULL. 0 or -1. */
int store_spectrum_add(struct store *st, const struct store_spectrum *sp, int64_t *id, struct acq_err *err);
/* Number of spectra (of sweep_id, or all when sweep_id is 0). -1 on error. */
int64_t store_spectrum_count(struct store *st, int64_t sweep_id, struct acq_err *err);

/* Record a spectrometer identity and wavelength calibration (existing row reused). 0 or -1. */
int store_spectrometer_put(struct store *st, const struct spectro_info *info, double at, int64_t *id,
			   struct acq_err *err);
/* Record a device identity (existing row reused, last_seen updated). 0 or -1. */
int store_device_put(struct store *st, const char *name, const char *vendor, const char *model,
		     const char *serial, const char *firmware, double at, int64_t *id, struct acq_err *err);
/* Link a device to a sweep (provenance). 0 or -1. */
int store_sweep_device(struct store *st, int64_t sweep_id, int64_t device_id, struct acq_err *err);

/* Set the wavelength grid (nm, n values) of a sweep's calibrated samples. 0 or -1. */
int store_sweep_set_grid(struct store *st, int64_t sweep_id, const float *nm, int n, struct acq_err *err);
/* Store (replace) the calibrated BRDF and sigma (n values each, over the grid) of a point. 0 or -1. */
int store_calibrated_put(struct store *st, int64_t sweep_id, int64_t point_id, const float *brdf,
			 const float *sigma, int n, struct acq_err *err);

/* Start a reconstruction run record (args: JSON array text). 0 or -1. */
int store_recon_begin(struct store *st, int64_t sweep_id, const char *program, const char *args, double at,
		      int64_t *run_id, struct acq_err *err);
/* Runs left 'running' by a daemon that died (call at start, before any run begins): 'interrupted', with an
 * output line saying why. *n = runs marked. 0 or -1. */
int store_recon_interrupted(struct store *st, double at, int *n, struct acq_err *err);
/* Finish a run: state succeeded/failed/cancelled, exit status, captured output. 0 or -1. */
int store_recon_end(struct store *st, int64_t run_id, const char *state, int exit_status, const char *output,
		    double at, struct acq_err *err);
/* Record one output file of a run (path relative to the state directory). 0 or -1. */
int store_recon_output(struct store *st, int64_t run_id, const char *kind, const char *path, double at,
		       struct acq_err *err);
/* JSON object of a run (id, sweep_id, state, times, exit_status, outputs) or the latest of a sweep
 * (run_id 0). NULL with ACQ_E_NOTFOUND if none. */
json_t *store_recon_show(struct store *st, int64_t run_id, int64_t sweep_id, struct acq_err *err);

/* Append to the event log (sweep_id 0 = none, device may be NULL). 0 or -1. */
int store_event(struct store *st, int64_t sweep_id, const char *kind, const char *device, const char *message,
		double at, struct acq_err *err);

/* JSON array of sweeps (id, name, state, times, points_total, points_done), newest first, at most limit. */
json_t *store_sweep_list(struct store *st, int limit, struct acq_err *err);
/* JSON object of one sweep (with plan text, counts, events); NULL with ACQ_E_NOTFOUND if absent. */
json_t *store_sweep_show(struct store *st, int64_t id, bool with_points, struct acq_err *err);
/* One spectrum of a sweep's stored reference (store_reference_each). */
struct store_ref_spectrum {
	char kind[16];                   /* "dark", "reference" or "beam" */
	double integration_ms;
	int averages, npix;
	double counts[SPECTRO_MAX_PIXELS];
	float stddev[SPECTRO_MAX_PIXELS];          /* 0 when not stored */
	unsigned char saturated[SPECTRO_MAX_PIXELS];
	double temperature_c;            /* NaN = unknown */
};
/* Called per spectrum in id order; nonzero stops. */
typedef int (*store_reference_fn)(void *ctx, const struct store_ref_spectrum *sp);
/* The spectra listed by the sweep's last "reference" event (crash-resume), each to fn; *detector_theta (may
 * be NULL) gets the detector zenith the reference was measured at when the event says. The number of spectra
 * (0: no reference stored), or -1 with err. */
int store_reference_each(struct store *st, int64_t sweep_id, double *detector_theta, store_reference_fn fn,
			 void *ctx, struct acq_err *err);
/* Write a sweep's calibrated samples in the CSV interchange format (design.md): the calibrated_samples view,
 * i.e. the sample-frame angles measured at commit. Rows written in *nrows. ACQ_E_NOTFOUND for no sweep,
 * ACQ_E_STATE if it has no calibrated samples. 0 or -1. */
int store_export_csv(struct store *st, int64_t sweep_id, FILE *out, int *nrows, struct acq_err *err);
/* The same into the file path, whole or not at all (written beside it, then renamed). 0 or -1. */
int store_export_csv_file(struct store *st, int64_t sweep_id, const char *path, int *nrows, struct acq_err *err);
/* store_export_csv() of the first limit rows in sweep order (limit <= 0: all). */
int store_export_csv_n(struct store *st, int64_t sweep_id, int limit, FILE *out, int *nrows, struct acq_err *err);
/* A sweep's grid row: its wavelength grid (n float32 nm as stored; nm malloc'd, the caller frees it) and its
 * spectrometer's pixel count (npix; -1: none recorded) and wavelength coefficients c0..c4. */
struct store_grid {
	float *nm;
	int n, npix;
	double coef[5];
};
/* store_export_csv_file() that also hands the sweep's grid row it read to *g (may be NULL; zeroed on failure), so that
 * what is binned on it (the recon chain's reference noise) does not read it again. 0 or -1. */
int store_export_csv_grid(struct store *st, int64_t sweep_id, const char *path, int *nrows, struct store_grid *g,
			  struct acq_err *err);
/* ---- exposure priors (store_prior.c) */
/* Record the sample a sweep measures (in the caller's transaction: store_sweep_create does). 0 or -1. */
int store_sweep_sample_put(struct store *st, int64_t sweep_id, const char *sample, bool auto_exposure,
			   struct acq_err *err);
/* One exposure of a done point of a prior's source sweep: its incidence zenith (sample frame, planned), the point,
 * whether it is a dark (else a sample exposure) and its integration time. */
struct store_prior_row {
	double theta_i;
	int64_t point_id;
	bool dark;
	double integration_ms;
	int averages;
	/* the point's: */
	int64_t order_index;
	double done_at;             /* wall clock, s */
	double arm[3];              /* the arms' reached angles: laser.theta, detector.theta, detector.phi */
};
typedef int (*store_prior_fn)(void *ctx, const struct store_prior_row *row);
/* The latest completed sweep of sample (by name) whose exposures the auto exposure chose, other than exclude (0:
 * none): its id in *sweep_id (0 when there is none, and fn is not called), and its done points' sample and dark
 * exposures with their point's order, commit time and reached angles to fn, by incidence, point and time taken (fn
 * nonzero stops). 0 or -1. */
int store_prior_each(struct store *st, const char *sample, int64_t exclude, int64_t *sweep_id, store_prior_fn fn,
		     void *ctx, struct acq_err *err);
/* The latest completed sweep other than exclude (0: none), any sample and mode, of plan kind `kind` (NULL: any
 * kind), in *sweep_id (0: none). 0 or -1. */
int store_latest_completed(struct store *st, int64_t exclude, const char *kind, int64_t *sweep_id,
			   struct acq_err *err);
/* How many sweeps this store has set completed since it was opened (store_sweep_set_state): a cache of what the
 * completed sweeps say is stale when it changes. */
unsigned long store_completed_gen(const struct store *st);
/* The done points' sample and dark exposures of sweep_id (any state: a running sweep's so far) whose order index is
 * from_order or more to fn, as store_prior_each gives them. 0 or -1. */
int store_prior_rows(struct store *st, int64_t sweep_id, int64_t from_order, store_prior_fn fn, void *ctx,
		     struct acq_err *err);

/* A read-only connection to an existing database (no migration, no checkpoint at close) for a worker thread:
 * only the export and show functions may be used on it. 0 or -1. */
int store_open_reader(const char *path, struct store **out, struct acq_err *err);
/* Number of calibrated samples of a sweep; -1 with ACQ_E_NOTFOUND if there is no such sweep. */
int64_t store_calibrated_count(struct store *st, int64_t sweep_id, struct acq_err *err);
/* The id of the latest reconstruction run (started by the operator or after a sweep), 0 if none. */
int64_t store_recon_latest(struct store *st);
/* One stored spectrum: id, kind, settings, counts (and stddev), sweep/point, and wavelength_nm from its
 * spectrometer's polynomial when known. NULL with ACQ_E_NOTFOUND if there is none. */
json_t *store_spectrum_json(struct store *st, int64_t id, struct acq_err *err);

/* Group the writes that follow, until store_group_end(), in one transaction (one commit): a point's spectra, its
 * calibrated sample and its completion, stored whole or not at all (store_group.c). 0 or -1. */
int store_group_begin(struct store *st, struct acq_err *err);
/* End the group: commit when rc is 0 and no write in it failed, else roll all of it back. 0 or -1. */
int store_group_end(struct store *st, int rc, struct acq_err *err);
/* The WAL's checkpoints run so far on the store's own thread (store_ckpt.c): how many, their seconds in all, the
 * longest (zeros where SQLite checkpoints on the committing thread instead). */
void store_ckpt_stats(const struct store *st, unsigned long *runs, double *seconds, double *max_s);
/* True when no checkpoint is due or under way on the store's thread (always true without that thread). */
bool store_ckpt_idle(const struct store *st);

/* ---- durability (store_sync.c). A read-write store's commits return before their fsync (synchronous=NORMAL: a
 * process crash keeps them, a power loss may lose the latest); a thread of the store's fsyncs the WAL after them.
 * A commit is on disk once store_durable() says so for its mark. Where that thread cannot start, every commit
 * fsyncs before it returns (store_degraded() says so) and every mark is durable at once. */
/* The mark of the latest commit on st (0: none yet). */
uint64_t store_commit_mark(const struct store *st);
/* 1 when every commit up to mark is on disk, 0 not yet, -1 with err when an fsync failed (sticky: no later
 * commit is known durable either). */
int store_durable(struct store *st, uint64_t mark, struct acq_err *err);
/* store_durable(), waiting (blocking) while it is 0. 1 or -1. */
int store_durable_wait(struct store *st, uint64_t mark, struct acq_err *err);
/* A descriptor readable when more commits became durable or an fsync failed (-1: none, durability is
 * synchronous); store_durable_drain() resets it (non-blocking). */
int store_durable_fd(const struct store *st);
void store_durable_drain(struct store *st);
/* What of the store's own threads could not start, and what SQLite does instead (NULL: all run). */
const char *store_degraded(const struct store *st);
/* Test seam: fn(ctx) runs on the fsync thread before each fsync (a delay; nonzero with why filled: that fsync
 * fails). NULL removes it. */
typedef int (*store_sync_hook_fn)(void *ctx, char *why, size_t n);
void store_sync_set_hook(struct store *st, store_sync_hook_fn fn, void *ctx);

#endif
