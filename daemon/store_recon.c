/* store_recon: reconstruction runs (running, then succeeded/failed/cancelled, or interrupted when the daemon
 * died during the run), their output files and JSON view (part of the store module, store.h). */
#include "daemon/store.h"

#include <errno.h>
#include <math.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/store_int.h"
#include "drivers/spectro.h"

int store_recon_begin(struct store *st, int64_t sweep_id, const char *program, const char *args, double at,
		      int64_t *run_id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "INSERT INTO recon_runs (sweep_id, state, program, args, started_at) "
				         "VALUES (?, 'running', ?, ?, ?)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	store_bind_text(s, 2, program);
	store_bind_text(s, 3, args ? args : "[]");
	sqlite3_bind_double(s, 4, at);
	if (store_run1(st, s, err, "starting reconstruction run"))
		return -1;
	*run_id = sqlite3_last_insert_rowid(st->db);
	return 0;
}

int store_recon_interrupted(struct store *st, double at, int *n, struct acq_err *err)
{
	*n = 0;
	sqlite3_stmt *s = store_prep(st, "UPDATE recon_runs SET state = 'interrupted', finished_at = ?, output = "
				         "'interrupted: the daemon stopped (crash or kill) during the run; its child died with it' "
				         "|| CASE WHEN output IS NULL THEN '' ELSE char(10) || output END WHERE state = 'running'", err);
	if (!s)
		return -1;
	sqlite3_bind_double(s, 1, at);
	if (store_run1(st, s, err, "marking interrupted reconstruction runs"))
		return -1;
	*n = sqlite3_changes(st->db);
	return 0;
}

int store_recon_end(struct store *st, int64_t run_id, const char *state, int exit_status, const char *output,
		    double at, struct acq_err *err)
{
	if (!store_in_list(state, (const char *const[]){ "succeeded", "failed", "cancelled", NULL }))
		return acq_errf(err, ACQ_E_INVAL, "store: unknown run state");
	sqlite3_stmt *s = store_prep(st, "UPDATE recon_runs SET state = ?, exit_status = ?, output = ?, finished_at = ? "
				         "WHERE id = ?", err);
	if (!s)
		return -1;
	store_bind_text(s, 1, state);
	sqlite3_bind_int(s, 2, exit_status);
	store_bind_text(s, 3, output);
	sqlite3_bind_double(s, 4, at);
	sqlite3_bind_int64(s, 5, run_id);
	return store_run1(st, s, err, "finishing reconstruction run");
}

int store_recon_output(struct store *st, int64_t run_id, const char *kind, const char *path, double at,
		       struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "INSERT INTO recon_outputs (run_id, kind, path, created_at) VALUES (?,?,?,?)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, run_id);
	store_bind_text(s, 2, kind);
	store_bind_text(s, 3, path);
	sqlite3_bind_double(s, 4, at);
	return store_run1(st, s, err, "recording reconstruction output");
}

json_t *store_recon_show(struct store *st, int64_t run_id, int64_t sweep_id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, run_id ? "SELECT id, sweep_id, state, program, started_at, finished_at, exit_status, "
					         "substr(output, -2000) AS output_tail FROM recon_runs WHERE id = ?"
					       : "SELECT id, sweep_id, state, program, started_at, finished_at, exit_status, "
					         "substr(output, -2000) AS output_tail FROM recon_runs WHERE sweep_id = ? "
					         "ORDER BY id DESC LIMIT 1", err);
	if (!s)
		return NULL;
	sqlite3_bind_int64(s, 1, run_id ? run_id : sweep_id);
	json_t *rows = store_rows_json(st, s, err);
	if (!rows)
		return NULL;
	json_t *run = json_incref(json_array_get(rows, 0));
	json_decref(rows);
	if (!run) {
		acq_errf(err, ACQ_E_NOTFOUND, "no reconstruction run %s %lld", run_id ? "" : "for sweep",
			 (long long)(run_id ? run_id : sweep_id));
		return NULL;
	}
	s = store_prep(st, "SELECT kind, path, created_at FROM recon_outputs WHERE run_id = ? ORDER BY id", err);
	json_t *outs = s ? (sqlite3_bind_int64(s, 1, json_integer_value(json_object_get(run, "id"))), store_rows_json(st, s, err))
			 : NULL;
	if (!outs) {
		json_decref(run);
		return NULL;
	}
	json_object_set_new(run, "outputs", outs);
	return run;
}

int64_t store_recon_latest(struct store *st)
{
	sqlite3_stmt *s = store_prep(st, "SELECT coalesce(max(id), 0) FROM recon_runs", NULL);
	int64_t id = 0;
	if (s && sqlite3_step(s) == SQLITE_ROW)
		id = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	return id;
}
