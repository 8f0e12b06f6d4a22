/* store_adaptive: the decisions of adaptive sweeps (store_adaptive.h; tables adaptive_batches and adaptive_picks of
 * daemon/schema.sql). Part of the store module. */
#include "daemon/store_adaptive.h"

#include <math.h>
#include <sqlite3.h>

#include "daemon/store_int.h"

static void bind_int_or_null(sqlite3_stmt *s, int i, int v)
{
	if (v < 0)
		sqlite3_bind_null(s, i);
	else
		sqlite3_bind_int(s, i, v);
}

static int put_batch(struct store *st, int64_t sweep_id, const struct store_batch *b, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "INSERT INTO adaptive_batches (sweep_id, batch, decided_at, first_order_index, "
				     "n_points, target_spec, target_value, target_met, predicted_value, model, criterion, "
				     "warm, candidates, predicted_s, waited_s, stop_reason) "
				     "VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	sqlite3_bind_int(s, 2, b->batch);
	sqlite3_bind_double(s, 3, b->decided_at);
	sqlite3_bind_int(s, 4, b->first_order_index);
	sqlite3_bind_int(s, 5, b->n_points);
	store_bind_text(s, 6, b->target_spec ? b->target_spec : "");
	store_bind_real(s, 7, b->target_value);
	bind_int_or_null(s, 8, b->target_met);
	store_bind_real(s, 9, b->predicted_value);
	store_bind_text(s, 10, b->model);
	store_bind_text(s, 11, b->criterion);
	bind_int_or_null(s, 12, b->warm);
	bind_int_or_null(s, 13, b->candidates);
	store_bind_real(s, 14, b->predicted_s);
	store_bind_real(s, 15, b->waited_s);
	store_bind_text(s, 16, b->stop_reason);
	return store_run1(st, s, err, "recording an adaptive batch");
}

static int put_picks(struct store *st, int64_t sweep_id, int batch, const struct store_pick *p, int n,
		     struct acq_err *err)
{
	if (n <= 0)
		return 0;
	sqlite3_stmt *s = store_prep(st, "INSERT INTO adaptive_picks (sweep_id, batch, rank, candidate_id, order_index, "
				     "laser_theta, detector_theta, detector_phi, gain, cost_s, predicted_value_after) "
				     "VALUES (?,?,?,?,?,?,?,?,?,?,?)", err);
	if (!s)
		return -1;
	for (int i = 0; i < n; i++) {
		sqlite3_bind_int64(s, 1, sweep_id);
		sqlite3_bind_int(s, 2, batch);
		sqlite3_bind_int(s, 3, p[i].rank);
		sqlite3_bind_int64(s, 4, p[i].candidate_id);
		bind_int_or_null(s, 5, p[i].order_index);
		sqlite3_bind_double(s, 6, p[i].laser_theta);
		sqlite3_bind_double(s, 7, p[i].detector_theta);
		sqlite3_bind_double(s, 8, p[i].detector_phi);
		store_bind_real(s, 9, p[i].gain);
		store_bind_real(s, 10, p[i].cost_s);
		store_bind_real(s, 11, p[i].predicted_value_after);
		if (store_step_done(st, s, err, "recording a pick")) {
			sqlite3_finalize(s);
			return -1;
		}
	}
	sqlite3_finalize(s);
	return 0;
}

static int put_points(struct store *st, int64_t sweep_id, const struct store_point_new *p, int n, struct acq_err *err)
{
	if (n <= 0)
		return 0;
	if (store_points_insert(st, sweep_id, p, n, err))
		return -1;
	sqlite3_stmt *s = store_prep(st, "UPDATE sweeps SET points_total = (SELECT count(*) FROM points WHERE sweep_id = ?1) "
				     "WHERE id = ?1", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	return store_run1(st, s, err, "counting the sweep's points");
}

int store_adaptive_batch(struct store *st, int64_t sweep_id, const struct store_batch *b,
			 const struct store_pick *picks, int npicks, const struct store_point_new *pts, int npts,
			 struct acq_err *err)
{
	if (!b || npicks < 0 || npts < 0 || (npts > 0 && !pts) || (npicks > 0 && !picks))
		return acq_errf(err, ACQ_E_INVAL, "store: an adaptive batch without its records");
	if (store_exec(st, "BEGIN IMMEDIATE", err))
		return -1;
	if (put_batch(st, sweep_id, b, err) || put_picks(st, sweep_id, b->batch, picks, npicks, err) ||
	    put_points(st, sweep_id, pts, npts, err) || store_exec(st, "COMMIT", err)) {
		store_exec(st, "ROLLBACK", NULL);
		return acq_err_prefix(err, "sweep %lld, adaptive batch %d: ", (long long)sweep_id, b->batch);
	}
	return 0;
}

json_t *store_adaptive_show(struct store *st, int64_t sweep_id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "SELECT batch, decided_at, first_order_index, n_points, target_spec, target_value, "
				     "target_met, predicted_value, model, criterion, warm, candidates, predicted_s, waited_s, "
				     "stop_reason FROM adaptive_batches WHERE sweep_id = ? ORDER BY batch", err);
	if (!s)
		return NULL;
	sqlite3_bind_int64(s, 1, sweep_id);
	json_t *rows = store_rows_json(st, s, err);
	size_t i;
	json_t *row;
	json_array_foreach(rows, i, row) {
		s = store_prep(st, "SELECT rank, candidate_id, order_index, laser_theta, detector_theta, detector_phi, gain, "
			       "cost_s, predicted_value_after FROM adaptive_picks WHERE sweep_id = ? AND batch = ? ORDER BY rank",
			       err);
		json_t *p = NULL;
		if (s) {
			sqlite3_bind_int64(s, 1, sweep_id);
			sqlite3_bind_int64(s, 2, json_integer_value(json_object_get(row, "batch")));
			p = store_rows_json(st, s, err);
		}
		if (!p) {
			json_decref(rows);
			return NULL;
		}
		json_object_set_new(row, "picks", p);
	}
	return rows;
}

int store_adaptive_measured(struct store *st, int64_t sweep_id, double *wall_s, int *npoints, struct acq_err *err)
{
	/* per done point in order: its done_at, the previous done point's, its batch's decision time when it opens a
	 * batch, and the sweep's last start/resume event before it */
	sqlite3_stmt *s = store_prep(st, "SELECT p.done_at, p.prev, b.decided_at, (SELECT max(e.at) FROM events e WHERE "
				     "e.sweep_id = ?1 AND e.kind IN ('start', 'resume') AND e.at <= p.done_at) FROM "
				     "(SELECT order_index, done_at, lag(done_at) OVER (ORDER BY order_index) AS prev FROM points "
				     "WHERE sweep_id = ?1 AND state = 'done' AND done_at IS NOT NULL) p LEFT JOIN "
				     "adaptive_batches b ON b.sweep_id = ?1 AND b.first_order_index = p.order_index AND "
				     "b.n_points > 0 ORDER BY p.order_index", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	double sum = 0;
	int n = 0, rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		double done = sqlite3_column_double(s, 0), from = -INFINITY;
		for (int c = 1; c <= 3; c++)
			if (sqlite3_column_type(s, c) != SQLITE_NULL)
				from = fmax(from, sqlite3_column_double(s, c));
		if (isfinite(from) && done > from)
			sum += done - from;
		n++;
	}
	sqlite3_finalize(s);
	if (rc != SQLITE_DONE)
		return acq_errf(err, ACQ_E_IO, "store: sweep %lld: reading its points' times: %s", (long long)sweep_id,
				sqlite3_errstr(rc));
	*wall_s = sum;
	if (npoints)
		*npoints = n;
	return 0;
}
