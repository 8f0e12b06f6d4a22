/* store: the store module's core: opening (with the checks that refuse a foreign, corrupt or newer file untouched),
 * closing, the read-only worker connection and the SQLite helpers the other store files share (store_int.h).
 * The module's other files: store_migrate.c (schema creation and migrations), store_sweep.c (sweeps, points,
 * devices, calibrated samples, events), store_spectra.c (spectra and the stored reference), store_recon.c
 * (reconstruction runs), store_export.c (the CSV interchange format), store_prior.c (the sample a sweep measured,
 * the exposures of an exposure prior), store_group.c (a point's writes in one transaction), store_ckpt.c and
 * store_sync.c (the WAL's checkpoints and the commits' fsyncs on threads of their own). */
#include "daemon/store.h"

#include <errno.h>
#include <math.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "daemon/store_int.h"

static const char *const store_sql[ST__COUNT] = {
	[ST_SPECTRUM] = "INSERT INTO spectra (sweep_id, point_id, kind, spectrometer_id, integration_ms, averages, "
			"npix, counts, stddev, saturated_count, saturation_mask, temperature_c, taken_at) "
			"VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
	[ST_POINT_DONE] = "UPDATE points SET state = 'done', done_at = ?, laser_theta = ?, detector_theta = ?, "
			  "detector_phi = ?, m_theta_i = ?, m_phi_i = ?, m_theta_o = ?, m_phi_o = ? "
			  "WHERE id = ? AND state = 'pending'",
	[ST_EVENT] = "INSERT INTO events (at, sweep_id, kind, device, message) VALUES (?,?,?,?,?)",
};

int store_db_err(struct store *st, struct acq_err *err, const char *what)
{
	return acq_errf(err, ACQ_E_IO, "%s: %s: %s", st->path, what, sqlite3_errmsg(st->db));
}

int store_exec(struct store *st, const char *sql, struct acq_err *err)
{
	char *msg = NULL;
	if (sqlite3_exec(st->db, sql, NULL, NULL, &msg) != SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: %s", st->path, msg ? msg : sqlite3_errmsg(st->db));
		sqlite3_free(msg);
		return -1;
	}
	return 0;
}

int store_tx_end(struct store *st, int rc, int64_t row, int64_t *id, struct acq_err *err)
{
	if (st->group) {
		st->group_failed |= rc != 0;
		if (rc == 0 && id)
			*id = row;
		return rc ? -1 : 0;
	}
	if (rc == 0 && store_exec(st, "COMMIT", err) == 0) {
		if (id)
			*id = row;
		return 0;
	}
	store_exec(st, "ROLLBACK", NULL);
	return -1;
}

sqlite3_stmt *store_prep(struct store *st, const char *sql, struct acq_err *err)
{
	sqlite3_stmt *s = NULL;
	if (sqlite3_prepare_v2(st->db, sql, -1, &s, NULL) != SQLITE_OK) {
		store_db_err(st, err, "prepare");
		return NULL;
	}
	return s;
}

int64_t store_pragma_int(sqlite3 *db, const char *sql, int *ok)
{
	sqlite3_stmt *s = NULL;
	int64_t v = 0;
	*ok = 0;
	if (sqlite3_prepare_v2(db, sql, -1, &s, NULL) == SQLITE_OK && sqlite3_step(s) == SQLITE_ROW) {
		v = sqlite3_column_int64(s, 0);
		*ok = 1;
	}
	sqlite3_finalize(s);
	return v;
}

/* Inspect an existing file read-only: it must be ours (or an empty SQLite database) and not corrupt. */
static int check_existing(const char *path, struct acq_err *err)
{
	sqlite3 *db = NULL;
	int rc = -1, ok;
	/* Without a -wal beside it, inspect the file as immutable: SQLite then creates no -wal/-shm even when a
	 * corrupt header claims WAL mode. With a -wal (ours after a crash), a plain read-only open reads it. */
	char uri[4200], wal[4200];
	snprintf(wal, sizeof wal, "%s-wal", path);
	struct stat sb;
	bool immutable = stat(wal, &sb) != 0;
	char *enc = sqlite3_mprintf("%s", path);
	snprintf(uri, sizeof uri, "file:%s%s", enc ? enc : path, immutable ? "?immutable=1" : "");
	sqlite3_free(enc);
	/* A path with URI metacharacters is opened as a plain name (no immutable flag then). */
	bool plain = strpbrk(path, "?#%") != NULL;
	if (sqlite3_open_v2(plain ? path : uri, &db, SQLITE_OPEN_READONLY | (plain ? 0 : SQLITE_OPEN_URI), NULL) !=
	    SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: cannot open: %s", path, db ? sqlite3_errmsg(db) : "out of memory");
		goto out;
	}
	int64_t appid = store_pragma_int(db, "PRAGMA application_id", &ok);
	if (!ok) {
		acq_errf(err, ACQ_E_IO, "%s: not an SQLite database or corrupt (%s); refusing to use it, left as is",
			 path, sqlite3_errmsg(db));
		goto out;
	}
	int64_t ntables = store_pragma_int(db, "SELECT count(*) FROM sqlite_master", &ok);
	if (!ok) {
		acq_errf(err, ACQ_E_IO, "%s: unreadable schema (%s); refusing to use it, left as is", path,
			 sqlite3_errmsg(db));
		goto out;
	}
	if (appid != STORE_APPLICATION_ID && (appid != 0 || ntables > 0)) {
		acq_errf(err, ACQ_E_INVAL, "%s: not an acquisitiond database (application_id 0x%08llx, %lld tables); "
			 "refusing to use it, left as is", path, (unsigned long long)(uint32_t)appid, (long long)ntables);
		goto out;
	}
	int64_t ver = store_pragma_int(db, "PRAGMA user_version", &ok);
	/* Ours always carries a schema version: application_id and user_version are set in one transaction. */
	if (appid == STORE_APPLICATION_ID && ver == 0) {
		acq_errf(err, ACQ_E_INVAL, "%s: carries acquisitiond's application_id but no schema version (%lld tables): "
			 "not a database this daemon wrote; refusing to use it, left as is", path, (long long)ntables);
		goto out;
	}
	if (ver > STORE_SCHEMA_VERSION) {
		acq_errf(err, ACQ_E_UNSUPPORTED, "%s: schema version %lld is newer than this acquisitiond's (%d)", path,
			 (long long)ver, STORE_SCHEMA_VERSION);
		goto out;
	}
	sqlite3_stmt *s = NULL;
	if (sqlite3_prepare_v2(db, "PRAGMA quick_check", -1, &s, NULL) != SQLITE_OK || sqlite3_step(s) != SQLITE_ROW ||
	    strcmp((const char *)sqlite3_column_text(s, 0), "ok")) {
		acq_errf(err, ACQ_E_IO, "%s: integrity check failed (%s); refusing to use it, left as is", path,
			 s && sqlite3_column_text(s, 0) ? (const char *)sqlite3_column_text(s, 0) : sqlite3_errmsg(db));
		sqlite3_finalize(s);
		goto out;
	}
	sqlite3_finalize(s);
	rc = 0;
out:
	sqlite3_close(db);
	return rc;
}

const char *store_degraded(const struct store *st)
{
	return st->degraded[0] ? st->degraded : NULL;
}

int store_open(const char *path, struct store **out, struct acq_err *err)
{
	*out = NULL;
	struct stat sb;
	if (stat(path, &sb) == 0) {
		if (!S_ISREG(sb.st_mode))
			return acq_errf(err, ACQ_E_INVAL, "%s: not a regular file", path);
		if (sb.st_size > 0 && check_existing(path, err))
			return -1;
	} else if (errno != ENOENT) {
		return acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(errno));
	}
	struct store *st = calloc(1, sizeof *st);
	if (!st || !(st->path = strdup(path))) {
		free(st);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	if (sqlite3_open_v2(path, &st->db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOFOLLOW, NULL) !=
	    SQLITE_OK) {
		store_db_err(st, err, "open");
		goto fail;
	}
	sqlite3_busy_timeout(st->db, 2000);
	sqlite3_extended_result_codes(st->db, 1);
	/* synchronous=FULL: a committed spectrum survives a crash of the process and of the machine. */
	if (store_exec(st, "PRAGMA journal_mode = WAL; PRAGMA synchronous = FULL; PRAGMA foreign_keys = ON;", err) ||
	    store_migrate(st, err))
		goto fail;
	for (int i = 0; i < ST__COUNT; i++)
		if (!(st->st[i] = store_prep(st, store_sql[i], err)))
			goto fail;
	/* The commits' fsyncs and the WAL's checkpoints on threads of their own, off the caller's (the daemon's
	 * loop); what cannot start falls back to SQLite's own on the committing thread, said by store_degraded(). */
	struct acq_err e1 = { 0 }, e2 = { 0 };
	if (store_ckpt_start(st, &e1))
		snprintf(st->degraded, sizeof st->degraded, "%s: SQLite checkpoints the WAL inside commits", e1.msg);
	if (store_sync_start(st, &e2) == 0) {
		if (store_exec(st, "PRAGMA synchronous = NORMAL", err))
			goto fail;
	} else {
		size_t n = strlen(st->degraded);
		snprintf(st->degraded + n, sizeof st->degraded - n, "%s%s: every commit fsyncs before it returns",
			 n ? "; " : "", e2.msg);
	}
	if (st->ckpt || st->sync)
		sqlite3_wal_hook(st->db, store_wal_hook, st);
	*out = st;
	return 0;
fail:
	store_close(st);
	return -1;
}

void store_close(struct store *st)
{
	if (!st)
		return;
	for (int i = 0; i < ST__COUNT; i++)
		sqlite3_finalize(st->st[i]);
	if (st->db) {
		if (!st->reader) {
			sqlite3_wal_hook(st->db, NULL, NULL);
			store_sync_stop(st);
			store_ckpt_stop(st);
		}
		if (!st->reader)
			sqlite3_exec(st->db, "PRAGMA wal_checkpoint(TRUNCATE)", NULL, NULL, NULL);
		sqlite3_close(st->db);
	}
	free(st->path);
	free(st);
}

int store_schema_version(struct store *st)
{
	int ok;
	return (int)store_pragma_int(st->db, "PRAGMA user_version", &ok);
}

/* Bind helpers: 0 means NULL for ids; NaN means NULL for reals. */
void store_bind_id(sqlite3_stmt *s, int i, int64_t v)
{
	if (v > 0)
		sqlite3_bind_int64(s, i, v);
	else
		sqlite3_bind_null(s, i);
}

void store_bind_real(sqlite3_stmt *s, int i, double v)
{
	if (isfinite(v))
		sqlite3_bind_double(s, i, v);
	else
		sqlite3_bind_null(s, i);
}

void store_bind_text(sqlite3_stmt *s, int i, const char *v)
{
	if (v)
		sqlite3_bind_text(s, i, v, -1, SQLITE_STATIC);
	else
		sqlite3_bind_null(s, i);
}

/* Step a statement expecting DONE; reset it. 0 or -1. */
int store_step_done(struct store *st, sqlite3_stmt *s, struct acq_err *err, const char *what)
{
	int rc = sqlite3_step(s);
	int r = 0;
	if (rc != SQLITE_DONE)
		r = acq_errf(err, rc == SQLITE_CONSTRAINT || (rc & 0xff) == SQLITE_CONSTRAINT ? ACQ_E_INVAL : ACQ_E_IO,
			     "%s: %s: %s", st->path, what, sqlite3_errmsg(st->db));
	sqlite3_reset(s);
	sqlite3_clear_bindings(s);
	return r;
}

int store_run1(struct store *st, sqlite3_stmt *s, struct acq_err *err, const char *what)
{
	int r = store_step_done(st, s, err, what);
	sqlite3_finalize(s);
	return r;
}

bool store_in_list(const char *v, const char *const *list)
{
	for (; v && *list; list++)
		if (!strcmp(v, *list))
			return true;
	return false;
}

static json_t *col_json(sqlite3_stmt *s, int i)
{
	switch (sqlite3_column_type(s, i)) {
	case SQLITE_INTEGER: return json_integer(sqlite3_column_int64(s, i));
	case SQLITE_FLOAT: return json_real(sqlite3_column_double(s, i));
	case SQLITE_TEXT: return json_string((const char *)sqlite3_column_text(s, i));
	case SQLITE_BLOB: return json_integer(sqlite3_column_bytes(s, i)); /* size only */
	default: return json_null();
	}
}

/* Rows of a prepared statement as an array of objects named by column. */
json_t *store_rows_json(struct store *st, sqlite3_stmt *s, struct acq_err *err)
{
	json_t *arr = json_array();
	int rc;
	while (arr && (rc = sqlite3_step(s)) == SQLITE_ROW) {
		json_t *o = json_object();
		for (int i = 0; i < sqlite3_column_count(s); i++)
			json_object_set_new(o, sqlite3_column_name(s, i), col_json(s, i));
		json_array_append_new(arr, o);
	}
	if (arr && rc != SQLITE_DONE) {
		store_db_err(st, err, "query");
		json_decref(arr);
		arr = NULL;
	}
	sqlite3_finalize(s);
	return arr;
}

int store_open_reader(const char *path, struct store **out, struct acq_err *err)
{
	*out = NULL;
	struct store *st = calloc(1, sizeof *st);
	if (!st || !(st->path = strdup(path))) {
		free(st);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	if (sqlite3_open_v2(path, &st->db, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOFOLLOW, NULL) != SQLITE_OK) {
		store_db_err(st, err, "open");
		sqlite3_close(st->db);
		free(st->path);
		free(st);
		return -1;
	}
	sqlite3_busy_timeout(st->db, 2000);
	sqlite3_extended_result_codes(st->db, 1);
	st->reader = true;
	*out = st;
	return 0;
}
