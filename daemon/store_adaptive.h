/* store_adaptive: the decisions of adaptive sweeps in the database (tables adaptive_batches and adaptive_picks,
 * daemon/schema.sql): one row per batch (0: the seed plan; the last row of a finished sweep says why it
 * stopped), select's picks of each batch in choice order with the planned arm angles and the point measuring
 * each. Part of the store module (store.h conventions: never logs, -1 + struct acq_err). */
#ifndef STORE_ADAPTIVE_H
#define STORE_ADAPTIVE_H

#include <jansson.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "daemon/store.h"

/* One decision (NaN reals, negative ints and NULL texts are stored as NULL). */
struct store_batch {
	int batch;                  /* 0: the seed plan */
	double decided_at;          /* Unix seconds */
	int first_order_index;      /* its points: order_index first_order_index .. + n_points - 1 */
	int n_points;
	const char *target_spec;    /* as given to brdf-recon select --target */
	double target_value;        /* the target's value from the model the decision used (NaN: the seed) */
	int target_met;             /* -1: not known */
	double predicted_value;     /* select's predicted value after the batch */
	const char *model;          /* the model file the decision used, relative to the state directory */
	const char *criterion;
	int warm;                   /* the fit was warm-started (-1: no fit) */
	int candidates;             /* reachable candidates offered (-1: none written) */
	double predicted_s;         /* the batch's predicted bench seconds */
	double waited_s;            /* bench seconds the arms waited for this decision */
	const char *stop_reason;    /* the final row: why the sweep stopped (then n_points is 0) */
};

/* One pick of select, in its choice order. */
struct store_pick {
	int rank;
	int64_t candidate_id;
	int order_index;            /* the point measuring it (-1: left out by the budget) */
	double laser_theta, detector_theta, detector_phi; /* planned arm angles */
	double gain, cost_s, predicted_value_after;
};

/* Record decision b of sweep_id with its picks and append its points (order_index continuing, points_total
 * updated), all in one transaction. 0 or -1 (nothing written). */
int store_adaptive_batch(struct store *st, int64_t sweep_id, const struct store_batch *b,
			 const struct store_pick *picks, int npicks, const struct store_point_new *pts, int npts,
			 struct acq_err *err);
/* The batches of sweep_id in order, each an object of its columns with "picks": [its picks by rank]; an empty
 * array for a sweep without any. NULL with err. */
json_t *store_adaptive_show(struct store *st, int64_t sweep_id, struct acq_err *err);
/* The wall seconds sweep_id's measurement took so far, from its stored points: per done point, in order, done_at minus
 * the latest of the previous done point's done_at, its batch's decision time (when it opens a batch: the arms' wait
 * for a decision is not measuring) and the sweep's last start/resume event before it (a pause, the sample swap or
 * a daemon restart is not measuring either; a point interrupted by one is counted from the resume). The white
 * reference taken before a swap pause is not counted. *npoints (may be NULL): the done points. 0 or -1. */
int store_adaptive_measured(struct store *st, int64_t sweep_id, double *wall_s, int *npoints, struct acq_err *err);

#endif
