/* store_prior: the sample a sweep measured and the exposures an exposure prior is built from (part of the store
 * module, store.h; the prior's figures are computed by exp_prior_build, daemon/exposure.c). */
#include "daemon/store.h"

#include <sqlite3.h>

#include "daemon/store_int.h"

int store_sweep_sample_put(struct store *st, int64_t sweep_id, const char *sample, bool auto_exposure,
			   struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "INSERT INTO sweep_samples (sweep_id, sample, auto_exposure) VALUES (?,?,?)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	store_bind_text(s, 2, sample);
	sqlite3_bind_int(s, 3, auto_exposure ? 1 : 0);
	return store_run1(st, s, err, "recording the sweep's sample");
}

int store_prior_each(struct store *st, const char *sample, int64_t exclude, int64_t *sweep_id, store_prior_fn fn,
		     void *ctx, struct acq_err *err)
{
	*sweep_id = 0;
	if (!sample || !*sample)
		return 0;
	sqlite3_stmt *s = store_prep(st, "SELECT w.id FROM sweep_samples m JOIN sweeps w ON w.id = m.sweep_id "
				         "WHERE m.sample = ? AND m.auto_exposure = 1 AND w.state = 'completed' AND w.id <> ? "
				         "ORDER BY w.id DESC LIMIT 1", err);
	if (!s)
		return -1;
	store_bind_text(s, 1, sample);
	sqlite3_bind_int64(s, 2, exclude);
	int rc = sqlite3_step(s);
	int64_t id = rc == SQLITE_ROW ? sqlite3_column_int64(s, 0) : 0;
	sqlite3_finalize(s);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return store_db_err(st, err, "finding the sample's previous sweep");
	if (!id)
		return 0;
	if (store_prior_rows(st, id, 0, fn, ctx, err))
		return -1;
	*sweep_id = id;
	return 0;
}

int store_prior_rows(struct store *st, int64_t sweep_id, int64_t from_order, store_prior_fn fn, void *ctx,
		     struct acq_err *err)
{
	/* a dark is stored with the point it was taken for (before that point's exposure) */
	sqlite3_stmt *s = store_prep(st,
				     "SELECT p.theta_i, p.id, x.kind = 'dark', x.integration_ms, x.averages, p.order_index, "
				     "coalesce(p.done_at, 0), coalesce(p.laser_theta, 0), coalesce(p.detector_theta, 0), "
				     "coalesce(p.detector_phi, 0) FROM points p "
				     "JOIN spectra x ON x.sweep_id = p.sweep_id AND x.point_id = p.id "
				     "WHERE p.sweep_id = ? AND p.order_index >= ? AND p.state = 'done' "
				     "AND x.kind IN ('sample', 'dark') ORDER BY p.theta_i, p.order_index, x.id", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	sqlite3_bind_int64(s, 2, from_order);
	int rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		struct store_prior_row r = { sqlite3_column_double(s, 0), sqlite3_column_int64(s, 1),
					     sqlite3_column_int(s, 2) != 0, sqlite3_column_double(s, 3),
					     sqlite3_column_int(s, 4), sqlite3_column_int64(s, 5),
					     sqlite3_column_double(s, 6),
					     { sqlite3_column_double(s, 7), sqlite3_column_double(s, 8),
					       sqlite3_column_double(s, 9) } };
		if (fn(ctx, &r))
			break;
	}
	sqlite3_finalize(s);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return store_db_err(st, err, "reading a sweep's exposures");
	return 0;
}

int store_latest_completed(struct store *st, int64_t exclude, const char *kind, int64_t *sweep_id,
			   struct acq_err *err)
{
	*sweep_id = 0;
	sqlite3_stmt *s = store_prep(st, "SELECT id FROM sweeps WHERE state = 'completed' AND id <> ?1 "
				         "AND (?2 IS NULL OR plan_kind = ?2) ORDER BY id DESC LIMIT 1", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, exclude);
	store_bind_text(s, 2, kind);
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW)
		*sweep_id = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return store_db_err(st, err, "finding the latest completed sweep");
	return 0;
}
