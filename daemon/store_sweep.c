/* store_sweep: sweeps, their points and provenance (devices, spectrometers), calibrated samples and the event
 * log, and the JSON views of sweeps (part of the store module, store.h). */
#include "daemon/store.h"

#include <errno.h>
#include <math.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/store_int.h"
#include "drivers/spectro.h"

static const char *const sweep_states[] = { "planned", "running", "paused", "completed", "aborted", "failed", NULL };

int store_points_insert(struct store *st, int64_t sweep_id, const struct store_point_new *pts, int npts,
			struct acq_err *err)
{
	if (npts <= 0)
		return 0;
	sqlite3_stmt *s = store_prep(st, "INSERT INTO points (sweep_id, order_index, theta_i, phi_i, theta_o, phi_o) "
				     "VALUES (?,?,?,?,?,?)", err);
	if (!s)
		return -1;
	for (int i = 0; i < npts; i++) {
		sqlite3_bind_int64(s, 1, sweep_id);
		sqlite3_bind_int(s, 2, pts[i].order_index);
		sqlite3_bind_double(s, 3, pts[i].theta_i);
		sqlite3_bind_double(s, 4, pts[i].phi_i);
		sqlite3_bind_double(s, 5, pts[i].theta_o);
		sqlite3_bind_double(s, 6, pts[i].phi_o);
		if (store_step_done(st, s, err, "adding point")) {
			sqlite3_finalize(s);
			return -1;
		}
	}
	sqlite3_finalize(s);
	return 0;
}

int store_sweep_create(struct store *st, const struct store_sweep_new *sw, const struct store_point_new *pts,
		       int npts, int64_t *id, struct acq_err *err)
{
	if (!sw->plan_text || !sw->config_snapshot || npts < 0)
		return acq_errf(err, ACQ_E_INVAL, "store: sweep without plan or configuration");
	if (store_exec(st, "BEGIN IMMEDIATE", err))
		return -1;
	int rc = -1;
	int64_t sid = 0;
	sqlite3_stmt *s = store_prep(st, "INSERT INTO sweeps (name, plan_text, config_snapshot, state, created_at, "
				         "software_version, calibration_method, spectrometer_id, points_total, plan_kind) "
				         "VALUES (?,?,?,'planned',?,?,?,?,?,?)", err);
	if (!s)
		goto end;
	store_bind_text(s, 1, sw->name ? sw->name : "");
	store_bind_text(s, 2, sw->plan_text);
	store_bind_text(s, 3, sw->config_snapshot);
	sqlite3_bind_double(s, 4, sw->created_at);
	store_bind_text(s, 5, sw->software_version ? sw->software_version : "unknown");
	store_bind_text(s, 6, sw->calibration_method);
	store_bind_id(s, 7, sw->spectrometer_id);
	sqlite3_bind_int(s, 8, npts);
	store_bind_text(s, 9, sw->plan_kind && *sw->plan_kind ? sw->plan_kind : NULL);
	if (store_run1(st, s, err, "creating sweep"))
		goto end;
	sid = sqlite3_last_insert_rowid(st->db);
	if (sw->sample && *sw->sample && store_sweep_sample_put(st, sid, sw->sample, sw->auto_exposure, err))
		goto end;
	rc = store_points_insert(st, sid, pts, npts, err);
end:
	return store_tx_end(st, rc, sid, id, err);
}

int store_sweep_set_state(struct store *st, int64_t id, const char *state, double at, struct acq_err *err)
{
	if (!store_in_list(state, sweep_states))
		return acq_errf(err, ACQ_E_INVAL, "store: unknown sweep state '%s'", state ? state : "(null)");
	const char *sql = !strcmp(state, "running")
				  ? "UPDATE sweeps SET state = ?1, started_at = coalesce(started_at, ?2) WHERE id = ?3"
			  : store_in_list(state, (const char *const[]){ "completed", "aborted", "failed", NULL })
				  ? "UPDATE sweeps SET state = ?1, finished_at = ?2 WHERE id = ?3"
				  : "UPDATE sweeps SET state = ?1 WHERE id = ?3 AND ?2 IS NOT NULL";
	sqlite3_stmt *s = store_prep(st, sql, err);
	if (!s)
		return -1;
	store_bind_text(s, 1, state);
	sqlite3_bind_double(s, 2, at);
	sqlite3_bind_int64(s, 3, id);
	if (store_run1(st, s, err, "setting sweep state"))
		return -1;
	if (sqlite3_changes(st->db) != 1)
		return acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)id);
	if (!strcmp(state, "completed"))
		st->completed_gen++;
	return 0;
}

unsigned long store_completed_gen(const struct store *st)
{
	return st->completed_gen;
}

int store_sweep_interrupted(struct store *st, int64_t *id, struct acq_err *err)
{
	*id = 0;
	sqlite3_stmt *s = store_prep(st, "SELECT id FROM sweeps WHERE state IN ('running','paused') ORDER BY id DESC LIMIT 1",
			             err);
	if (!s)
		return -1;
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW)
		*id = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	return rc == SQLITE_ROW || rc == SQLITE_DONE ? 0 : store_db_err(st, err, "finding interrupted sweep");
}

int store_sweep_next_point(struct store *st, int64_t id, int *order_index, int64_t *point_id,
			   struct acq_err *err)
{
	*order_index = -1;
	*point_id = 0;
	sqlite3_stmt *s = store_prep(st, "SELECT order_index, id FROM points WHERE sweep_id = ? AND state = 'pending' "
				         "ORDER BY order_index LIMIT 1", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, id);
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW) {
		*order_index = sqlite3_column_int(s, 0);
		*point_id = sqlite3_column_int64(s, 1);
	}
	sqlite3_finalize(s);
	return rc == SQLITE_ROW || rc == SQLITE_DONE ? 0 : store_db_err(st, err, "finding next point");
}

int store_point_discard_partial(struct store *st, int64_t point_id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "DELETE FROM spectra WHERE point_id = ?1 AND "
				         "(SELECT state FROM points WHERE id = ?1) = 'pending'", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, point_id);
	return store_run1(st, s, err, "discarding a partial point");
}

/* Bind a spectrometer's identity (model, serial, firmware, pixels, wavelength coefficients) as parameters 1-9. */
static void bind_identity(sqlite3_stmt *s, const struct spectro_info *info)
{
	store_bind_text(s, 1, info->model);
	store_bind_text(s, 2, info->serial);
	store_bind_text(s, 3, info->firmware);
	sqlite3_bind_int(s, 4, info->npix);
	for (int i = 0; i < 5; i++)
		sqlite3_bind_double(s, 5 + i, info->wl_coef[i]);
}

int store_spectrometer_put(struct store *st, const struct spectro_info *info, double at, int64_t *id,
			   struct acq_err *err)
{
	char nonlin[1024] = "";
	if (info->nonlin_enabled) {
		json_t *o = json_pack("{s:f,s:f,s:[f,f,f,f,f,f,f,f]}", "low", info->nonlin_low, "high", info->nonlin_high,
				      "coef", info->nonlin_coef[0], info->nonlin_coef[1], info->nonlin_coef[2],
				      info->nonlin_coef[3], info->nonlin_coef[4], info->nonlin_coef[5],
				      info->nonlin_coef[6], info->nonlin_coef[7]);
		char *t = o ? json_dumps(o, JSON_COMPACT) : NULL;
		snprintf(nonlin, sizeof nonlin, "%s", t ? t : "");
		free(t);
		json_decref(o);
	}
	sqlite3_stmt *s = store_prep(st, "INSERT OR IGNORE INTO spectrometers (model, serial, firmware, npix, c0, c1, c2, c3, c4, "
				         "nonlinearity, first_seen) VALUES (?,?,?,?,?,?,?,?,?,?,?)", err);
	if (!s)
		return -1;
	bind_identity(s, info);
	store_bind_text(s, 10, nonlin[0] ? nonlin : NULL);
	sqlite3_bind_double(s, 11, at);
	if (store_run1(st, s, err, "recording spectrometer"))
		return -1;
	s = store_prep(st, "SELECT id FROM spectrometers WHERE model=? AND serial=? AND firmware=? AND npix=? AND c0=? AND c1=? "
		           "AND c2=? AND c3=? AND c4=?", err);
	if (!s)
		return -1;
	bind_identity(s, info);
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW && id)
		*id = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	return rc == SQLITE_ROW ? 0 : store_db_err(st, err, "finding spectrometer");
}

int store_device_put(struct store *st, const char *name, const char *vendor, const char *model,
		     const char *serial, const char *firmware, double at, int64_t *id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "INSERT INTO devices (name, vendor, model, serial, firmware, first_seen, last_seen) "
				         "VALUES (?,?,?,?,?,?,?6) ON CONFLICT (name, vendor, model, serial, firmware) "
				         "DO UPDATE SET last_seen = excluded.last_seen RETURNING id", err);
	if (!s)
		return -1;
	store_bind_text(s, 1, name);
	store_bind_text(s, 2, vendor ? vendor : "");
	store_bind_text(s, 3, model ? model : "");
	store_bind_text(s, 4, serial ? serial : "");
	store_bind_text(s, 5, firmware ? firmware : "");
	sqlite3_bind_double(s, 6, at);
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW && id)
		*id = sqlite3_column_int64(s, 0);
	if (rc == SQLITE_ROW)
		rc = sqlite3_step(s);
	sqlite3_finalize(s);
	return rc == SQLITE_DONE ? 0 : store_db_err(st, err, "recording device");
}

int store_sweep_device(struct store *st, int64_t sweep_id, int64_t device_id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "INSERT OR IGNORE INTO sweep_devices (sweep_id, device_id) VALUES (?,?)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	sqlite3_bind_int64(s, 2, device_id);
	return store_run1(st, s, err, "linking device to sweep");
}

int store_sweep_set_grid(struct store *st, int64_t sweep_id, const float *nm, int n, struct acq_err *err)
{
	if (n <= 0 || !nm)
		return acq_errf(err, ACQ_E_INVAL, "store: empty wavelength grid");
	for (int i = 0; i < n; i++)
		if (!isfinite(nm[i]) || nm[i] <= 0 || (i && nm[i] <= nm[i - 1]))
			return acq_errf(err, ACQ_E_INVAL, "store: wavelength grid must be positive and increasing");
	sqlite3_stmt *s = store_prep(st, "UPDATE sweeps SET wavelength_grid = ? WHERE id = ?", err);
	if (!s)
		return -1;
	sqlite3_bind_blob(s, 1, nm, n * 4, SQLITE_STATIC);
	sqlite3_bind_int64(s, 2, sweep_id);
	if (store_run1(st, s, err, "setting wavelength grid"))
		return -1;
	return sqlite3_changes(st->db) == 1 ? 0 : acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)sweep_id);
}

int store_calibrated_put(struct store *st, int64_t sweep_id, int64_t point_id, const float *brdf,
			 const float *sigma, int n, struct acq_err *err)
{
	if (n <= 0 || !brdf || !sigma)
		return acq_errf(err, ACQ_E_INVAL, "store: empty calibrated sample");
	sqlite3_stmt *s = store_prep(st, "INSERT OR REPLACE INTO calibrated (point_id, sweep_id, brdf, sigma) VALUES (?,?,?,?)",
			             err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, point_id);
	sqlite3_bind_int64(s, 2, sweep_id);
	sqlite3_bind_blob(s, 3, brdf, n * 4, SQLITE_STATIC);
	sqlite3_bind_blob(s, 4, sigma, n * 4, SQLITE_STATIC);
	return store_run1(st, s, err, "storing calibrated sample");
}

int64_t store_calibrated_count(struct store *st, int64_t sweep_id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "SELECT (SELECT count(*) FROM calibrated WHERE sweep_id = ?1), "
				         "(SELECT count(*) FROM sweeps WHERE id = ?1)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	int64_t n = -1;
	if (sqlite3_step(s) == SQLITE_ROW) {
		if (sqlite3_column_int64(s, 1) == 0)
			acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)sweep_id);
		else
			n = sqlite3_column_int64(s, 0);
	} else {
		store_db_err(st, err, "counting samples");
	}
	sqlite3_finalize(s);
	return n;
}

int store_event(struct store *st, int64_t sweep_id, const char *kind, const char *device, const char *message,
		double at, struct acq_err *err)
{
	sqlite3_stmt *s = st->st[ST_EVENT];
	sqlite3_bind_double(s, 1, at);
	store_bind_id(s, 2, sweep_id);
	store_bind_text(s, 3, kind ? kind : "info");
	store_bind_text(s, 4, device);
	store_bind_text(s, 5, message ? message : "");
	return store_step_done(st, s, err, "logging event");
}

#define SWEEP_COLS "id, name, state, created_at, started_at, finished_at, software_version, calibration_method, " \
		   "points_total, (SELECT count(*) FROM points p WHERE p.sweep_id = sweeps.id AND p.state = 'done') " \
		   "AS points_done"

json_t *store_sweep_list(struct store *st, int limit, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "SELECT " SWEEP_COLS " FROM sweeps ORDER BY id DESC LIMIT ?", err);
	if (!s)
		return NULL;
	sqlite3_bind_int(s, 1, limit > 0 ? limit : 100);
	return store_rows_json(st, s, err);
}

json_t *store_sweep_show(struct store *st, int64_t id, bool with_points, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "SELECT " SWEEP_COLS ", plan_text, (SELECT count(*) FROM spectra WHERE "
				         "spectra.sweep_id = sweeps.id) AS spectra, (SELECT count(*) FROM calibrated c "
				         "WHERE c.sweep_id = sweeps.id) AS calibrated FROM sweeps WHERE id = ?", err);
	if (!s)
		return NULL;
	sqlite3_bind_int64(s, 1, id);
	json_t *rows = store_rows_json(st, s, err);
	if (!rows)
		return NULL;
	json_t *sw = json_incref(json_array_get(rows, 0));
	json_decref(rows);
	if (!sw) {
		acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)id);
		return NULL;
	}
	s = store_prep(st, "SELECT at, kind, device, message FROM events WHERE sweep_id = ? ORDER BY id DESC LIMIT 50", err);
	json_t *ev = s ? (sqlite3_bind_int64(s, 1, id), store_rows_json(st, s, err)) : NULL;
	if (!ev)
		goto fail;
	json_object_set_new(sw, "events", ev);
	if (with_points) {
		/* the reply names the axes as everywhere (laser.theta); SQL spells them laser_theta (README) */
		s = store_prep(st, "SELECT id, order_index, theta_i, phi_i, theta_o, phi_o, laser_theta AS \"laser.theta\", "
			           "detector_theta AS \"detector.theta\", detector_phi AS \"detector.phi\", state FROM points "
			           "WHERE sweep_id = ? ORDER BY order_index", err);
		json_t *pts = s ? (sqlite3_bind_int64(s, 1, id), store_rows_json(st, s, err)) : NULL;
		if (!pts)
			goto fail;
		json_object_set_new(sw, "points", pts);
	}
	return sw;
fail:
	json_decref(sw);
	return NULL;
}
