/* store: SQLite persistence of the acquisition (see store.h and daemon/schema.sql). */
#include "daemon/store.h"

#include <errno.h>
#include <math.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "config/acq_out.h"
#include "drivers/spectro.h"

/* The schema text is daemon/schema.sql itself, embedded at build time (one source of truth). */
__asm__(".pushsection .rodata\n"
	".global store_schema_sql\n"
	"store_schema_sql:\n"
	".incbin \"daemon/schema.sql\"\n"
	".byte 0\n"
	".popsection\n");
extern const char store_schema_sql[];

#define WRAP360(x) "CASE WHEN (" x ") >= 360 THEN (" x ") - 360 WHEN (" x ") < 0 THEN (" x ") + 360 ELSE (" x ") END"

/* Migrations: entry v brings the schema from version v to v + 1 (a new database is created from schema.sql, the
 * current version, in one step). */
static const char *const store_migrations[STORE_SCHEMA_VERSION] = {
	[0] = NULL, /* version 1's own schema: no database is created at version 1 any more */
	/* 1 → 2: the measured sample-frame angles of each point and the view readers share. Points done under
	 * version 1 get their arm angles in the sample frame (the laser's azimuth from the plan: exact for plans
	 * whose incidence zenith is >= 0, i.e. every plan); done without recorded arm angles, the planned angles. */
	[1] = "ALTER TABLE points ADD COLUMN m_theta_i REAL;"
	      "ALTER TABLE points ADD COLUMN m_phi_i REAL;"
	      "ALTER TABLE points ADD COLUMN m_theta_o REAL;"
	      "ALTER TABLE points ADD COLUMN m_phi_o REAL;"
	      "UPDATE points SET m_theta_i = abs(laser_theta), m_theta_o = abs(detector_theta), "
	      "m_phi_i = " WRAP360("phi_i + CASE WHEN laser_theta < 0 THEN 180 ELSE 0 END") ", "
	      "m_phi_o = " WRAP360("detector_phi + CASE WHEN detector_theta < 0 THEN 180 ELSE 0 END") " "
	      "WHERE state = 'done' AND laser_theta IS NOT NULL AND detector_theta IS NOT NULL AND "
	      "detector_phi IS NOT NULL;"
	      "UPDATE points SET m_theta_i = theta_i, m_phi_i = phi_i, m_theta_o = theta_o, m_phi_o = phi_o "
	      "WHERE state = 'done' AND m_theta_i IS NULL;"
	      "CREATE VIEW calibrated_samples AS\n"
	      "  SELECT c.sweep_id AS sweep_id, p.id AS point_id, p.order_index AS order_index, p.m_theta_i AS theta_i,\n"
	      "         p.m_phi_i AS phi_i, p.m_theta_o AS theta_o, p.m_phi_o AS phi_o, c.brdf AS brdf, c.sigma AS sigma\n"
	      "  FROM calibrated c JOIN points p ON p.id = c.point_id\n"
	      "  WHERE p.state = 'done';",
};

enum { ST_SPECTRUM, ST_POINT_DONE, ST_EVENT, ST__COUNT };
static const char *const store_sql[ST__COUNT] = {
	[ST_SPECTRUM] = "INSERT INTO spectra (sweep_id, point_id, kind, spectrometer_id, integration_ms, averages, "
			"npix, counts, stddev, saturated_count, saturation_mask, temperature_c, taken_at) "
			"VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?)",
	[ST_POINT_DONE] = "UPDATE points SET state = 'done', done_at = ?, laser_theta = ?, detector_theta = ?, "
			  "detector_phi = ?, m_theta_i = ?, m_phi_i = ?, m_theta_o = ?, m_phi_o = ? "
			  "WHERE id = ? AND state = 'pending'",
	[ST_EVENT] = "INSERT INTO events (at, sweep_id, kind, device, message) VALUES (?,?,?,?,?)",
};

struct store {
	sqlite3 *db;
	char *path;
	sqlite3_stmt *st[ST__COUNT];
	bool reader;  /* store_open_reader(): read-only, no statements prepared, no checkpoint at close */
};

static int db_err(struct store *st, struct acq_err *err, const char *what)
{
	return acq_errf(err, ACQ_E_IO, "%s: %s: %s", st->path, what, sqlite3_errmsg(st->db));
}

static int exec(struct store *st, const char *sql, struct acq_err *err)
{
	char *msg = NULL;
	if (sqlite3_exec(st->db, sql, NULL, NULL, &msg) != SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: %s", st->path, msg ? msg : sqlite3_errmsg(st->db));
		sqlite3_free(msg);
		return -1;
	}
	return 0;
}

static sqlite3_stmt *prep(struct store *st, const char *sql, struct acq_err *err)
{
	sqlite3_stmt *s = NULL;
	if (sqlite3_prepare_v2(st->db, sql, -1, &s, NULL) != SQLITE_OK) {
		db_err(st, err, "prepare");
		return NULL;
	}
	return s;
}

static int64_t pragma_int(sqlite3 *db, const char *sql, int *ok)
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
	int64_t appid = pragma_int(db, "PRAGMA application_id", &ok);
	if (!ok) {
		acq_errf(err, ACQ_E_IO, "%s: not an SQLite database or corrupt (%s); refusing to use it, left as is",
			 path, sqlite3_errmsg(db));
		goto out;
	}
	int64_t ntables = pragma_int(db, "SELECT count(*) FROM sqlite_master", &ok);
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
	int64_t ver = pragma_int(db, "PRAGMA user_version", &ok);
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

static int migrate(struct store *st, struct acq_err *err)
{
	int ok;
	int64_t ver = pragma_int(st->db, "PRAGMA user_version", &ok);
	if (!ok)
		return db_err(st, err, "reading user_version");
	for (int64_t v = ver; v < STORE_SCHEMA_VERSION; v++) {
		char bump[128];
		int64_t to = v == 0 ? STORE_SCHEMA_VERSION : v + 1; /* a new database: the current schema at once */
		snprintf(bump, sizeof bump, "PRAGMA application_id = %d; PRAGMA user_version = %lld;",
			 STORE_APPLICATION_ID, (long long)to);
		if (exec(st, "BEGIN IMMEDIATE", err))
			return -1;
		if (exec(st, v == 0 ? store_schema_sql : store_migrations[v], err) || exec(st, bump, err)) {
			exec(st, "ROLLBACK", NULL);
			return acq_err_prefix(err, "migrating schema %lld → %lld: ", (long long)v, (long long)v + 1);
		}
		if (exec(st, "COMMIT", err))
			return -1;
		v = to - 1;
	}
	return 0;
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
		db_err(st, err, "open");
		goto fail;
	}
	sqlite3_busy_timeout(st->db, 2000);
	sqlite3_extended_result_codes(st->db, 1);
	/* synchronous=FULL: a committed spectrum survives a crash of the process and of the machine. */
	if (exec(st, "PRAGMA journal_mode = WAL; PRAGMA synchronous = FULL; PRAGMA foreign_keys = ON;", err) ||
	    migrate(st, err))
		goto fail;
	for (int i = 0; i < ST__COUNT; i++)
		if (!(st->st[i] = prep(st, store_sql[i], err)))
			goto fail;
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
	return (int)pragma_int(st->db, "PRAGMA user_version", &ok);
}

/* Bind helpers: 0 means NULL for ids; NaN means NULL for reals. */
static void bind_id(sqlite3_stmt *s, int i, int64_t v)
{
	if (v > 0)
		sqlite3_bind_int64(s, i, v);
	else
		sqlite3_bind_null(s, i);
}

static void bind_real(sqlite3_stmt *s, int i, double v)
{
	if (isfinite(v))
		sqlite3_bind_double(s, i, v);
	else
		sqlite3_bind_null(s, i);
}

static void bind_text(sqlite3_stmt *s, int i, const char *v)
{
	if (v)
		sqlite3_bind_text(s, i, v, -1, SQLITE_STATIC);
	else
		sqlite3_bind_null(s, i);
}

/* Step a statement expecting DONE; reset it. 0 or -1. */
static int step_done(struct store *st, sqlite3_stmt *s, struct acq_err *err, const char *what)
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

static int run1(struct store *st, sqlite3_stmt *s, struct acq_err *err, const char *what)
{
	int r = step_done(st, s, err, what);
	sqlite3_finalize(s);
	return r;
}

static const char *const sweep_states[] = { "planned", "running", "paused", "completed", "aborted", "failed", NULL };

static bool in_list(const char *v, const char *const *list)
{
	for (; v && *list; list++)
		if (!strcmp(v, *list))
			return true;
	return false;
}

int store_sweep_create(struct store *st, const struct store_sweep_new *sw, const struct store_point_new *pts,
		       int npts, int64_t *id, struct acq_err *err)
{
	if (!sw->plan_text || !sw->config_snapshot || npts < 0)
		return acq_errf(err, ACQ_E_INVAL, "store: sweep without plan or configuration");
	if (exec(st, "BEGIN IMMEDIATE", err))
		return -1;
	sqlite3_stmt *s = prep(st, "INSERT INTO sweeps (name, plan_text, config_snapshot, state, created_at, "
				   "software_version, calibration_method, spectrometer_id, points_total) "
				   "VALUES (?,?,?,'planned',?,?,?,?,?)", err);
	if (!s)
		goto fail;
	bind_text(s, 1, sw->name ? sw->name : "");
	bind_text(s, 2, sw->plan_text);
	bind_text(s, 3, sw->config_snapshot);
	sqlite3_bind_double(s, 4, sw->created_at);
	bind_text(s, 5, sw->software_version ? sw->software_version : "unknown");
	bind_text(s, 6, sw->calibration_method);
	bind_id(s, 7, sw->spectrometer_id);
	sqlite3_bind_int(s, 8, npts);
	if (run1(st, s, err, "creating sweep"))
		goto fail;
	int64_t sid = sqlite3_last_insert_rowid(st->db);
	s = prep(st, "INSERT INTO points (sweep_id, order_index, theta_i, phi_i, theta_o, phi_o) VALUES (?,?,?,?,?,?)",
		 err);
	if (!s)
		goto fail;
	for (int i = 0; i < npts; i++) {
		sqlite3_bind_int64(s, 1, sid);
		sqlite3_bind_int(s, 2, pts[i].order_index);
		sqlite3_bind_double(s, 3, pts[i].theta_i);
		sqlite3_bind_double(s, 4, pts[i].phi_i);
		sqlite3_bind_double(s, 5, pts[i].theta_o);
		sqlite3_bind_double(s, 6, pts[i].phi_o);
		if (step_done(st, s, err, "adding point")) {
			sqlite3_finalize(s);
			goto fail;
		}
	}
	sqlite3_finalize(s);
	if (exec(st, "COMMIT", err))
		goto fail;
	if (id)
		*id = sid;
	return 0;
fail:
	exec(st, "ROLLBACK", NULL);
	return -1;
}

int store_sweep_set_state(struct store *st, int64_t id, const char *state, double at, struct acq_err *err)
{
	if (!in_list(state, sweep_states))
		return acq_errf(err, ACQ_E_INVAL, "store: unknown sweep state '%s'", state ? state : "(null)");
	const char *sql = !strcmp(state, "running")
				  ? "UPDATE sweeps SET state = ?1, started_at = coalesce(started_at, ?2) WHERE id = ?3"
			  : in_list(state, (const char *const[]){ "completed", "aborted", "failed", NULL })
				  ? "UPDATE sweeps SET state = ?1, finished_at = ?2 WHERE id = ?3"
				  : "UPDATE sweeps SET state = ?1 WHERE id = ?3 AND ?2 IS NOT NULL";
	sqlite3_stmt *s = prep(st, sql, err);
	if (!s)
		return -1;
	bind_text(s, 1, state);
	sqlite3_bind_double(s, 2, at);
	sqlite3_bind_int64(s, 3, id);
	if (run1(st, s, err, "setting sweep state"))
		return -1;
	if (sqlite3_changes(st->db) != 1)
		return acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)id);
	return 0;
}

int store_sweep_interrupted(struct store *st, int64_t *id, struct acq_err *err)
{
	*id = 0;
	sqlite3_stmt *s = prep(st, "SELECT id FROM sweeps WHERE state IN ('running','paused') ORDER BY id DESC LIMIT 1",
			       err);
	if (!s)
		return -1;
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW)
		*id = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	return rc == SQLITE_ROW || rc == SQLITE_DONE ? 0 : db_err(st, err, "finding interrupted sweep");
}

int store_sweep_next_point(struct store *st, int64_t id, int *order_index, int64_t *point_id,
			   struct acq_err *err)
{
	*order_index = -1;
	*point_id = 0;
	sqlite3_stmt *s = prep(st, "SELECT order_index, id FROM points WHERE sweep_id = ? AND state = 'pending' "
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
	return rc == SQLITE_ROW || rc == SQLITE_DONE ? 0 : db_err(st, err, "finding next point");
}

int store_point_discard_partial(struct store *st, int64_t point_id, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "DELETE FROM spectra WHERE point_id = ?1 AND "
				   "(SELECT state FROM points WHERE id = ?1) = 'pending'", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, point_id);
	return run1(st, s, err, "discarding a partial point");
}

int store_spectrum_add(struct store *st, const struct store_spectrum *sp, int64_t *id, struct acq_err *err)
{
	static const char *const kinds[] = { "sample", "dark", "reference", "beam", NULL };
	if (!in_list(sp->kind, kinds))
		return acq_errf(err, ACQ_E_INVAL, "store: spectrum kind must be sample, dark, reference or beam");
	if (sp->npix <= 0 || sp->npix > SPECTRO_MAX_PIXELS || !sp->counts)
		return acq_errf(err, ACQ_E_INVAL, "store: spectrum without counts or with %d pixels", sp->npix);
	if (sp->completes_point && sp->point_id <= 0)
		return acq_errf(err, ACQ_E_INVAL, "store: completes_point without a point");
	if (exec(st, "BEGIN IMMEDIATE", err))
		return -1;
	sqlite3_stmt *s = st->st[ST_SPECTRUM];
	int n4 = sp->npix * 4;
	bind_id(s, 1, sp->sweep_id);
	bind_id(s, 2, sp->point_id);
	bind_text(s, 3, sp->kind);
	bind_id(s, 4, sp->spectrometer_id);
	sqlite3_bind_double(s, 5, sp->integration_ms);
	sqlite3_bind_int(s, 6, sp->averages);
	sqlite3_bind_int(s, 7, sp->npix);
	/* float32 host order: every supported target (x86-64, aarch64) is little-endian, as the schema says. */
	sqlite3_bind_blob(s, 8, sp->counts, n4, SQLITE_STATIC);
	if (sp->stddev)
		sqlite3_bind_blob(s, 9, sp->stddev, n4, SQLITE_STATIC);
	else
		sqlite3_bind_null(s, 9);
	sqlite3_bind_int(s, 10, sp->saturated_count);
	if (sp->saturated && sp->saturated_count > 0)
		sqlite3_bind_blob(s, 11, sp->saturated, sp->npix, SQLITE_STATIC);
	else
		sqlite3_bind_null(s, 11);
	bind_real(s, 12, sp->temperature_c);
	sqlite3_bind_double(s, 13, sp->taken_at);
	if (step_done(st, s, err, "inserting spectrum"))
		goto fail;
	int64_t sid = sqlite3_last_insert_rowid(st->db);
	if (sp->completes_point) {
		s = st->st[ST_POINT_DONE];
		sqlite3_bind_double(s, 1, sp->taken_at);
		bind_real(s, 2, sp->laser_theta);
		bind_real(s, 3, sp->detector_theta);
		bind_real(s, 4, sp->detector_phi);
		bind_real(s, 5, sp->theta_i);
		bind_real(s, 6, sp->phi_i);
		bind_real(s, 7, sp->theta_o);
		bind_real(s, 8, sp->phi_o);
		sqlite3_bind_int64(s, 9, sp->point_id);
		if (step_done(st, s, err, "completing point"))
			goto fail;
		if (sqlite3_changes(st->db) != 1) {
			acq_errf(err, ACQ_E_STATE, "store: point %lld is not pending", (long long)sp->point_id);
			goto fail;
		}
	}
	if (exec(st, "COMMIT", err))
		goto fail;
	if (id)
		*id = sid;
	return 0;
fail:
	exec(st, "ROLLBACK", NULL);
	return -1;
}

int64_t store_spectrum_count(struct store *st, int64_t sweep_id, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, sweep_id ? "SELECT count(*) FROM spectra WHERE sweep_id = ?"
					    : "SELECT count(*) FROM spectra", err);
	if (!s)
		return -1;
	if (sweep_id)
		sqlite3_bind_int64(s, 1, sweep_id);
	int64_t n = sqlite3_step(s) == SQLITE_ROW ? sqlite3_column_int64(s, 0) : -1;
	if (n < 0)
		db_err(st, err, "counting spectra");
	sqlite3_finalize(s);
	return n;
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
	sqlite3_stmt *s = prep(st, "INSERT OR IGNORE INTO spectrometers (model, serial, firmware, npix, c0, c1, c2, c3, c4, "
				   "nonlinearity, first_seen) VALUES (?,?,?,?,?,?,?,?,?,?,?)", err);
	if (!s)
		return -1;
	bind_text(s, 1, info->model);
	bind_text(s, 2, info->serial);
	bind_text(s, 3, info->firmware);
	sqlite3_bind_int(s, 4, info->npix);
	for (int i = 0; i < 5; i++)
		sqlite3_bind_double(s, 5 + i, info->wl_coef[i]);
	bind_text(s, 10, nonlin[0] ? nonlin : NULL);
	sqlite3_bind_double(s, 11, at);
	if (run1(st, s, err, "recording spectrometer"))
		return -1;
	s = prep(st, "SELECT id FROM spectrometers WHERE model=? AND serial=? AND firmware=? AND npix=? AND c0=? AND c1=? "
		     "AND c2=? AND c3=? AND c4=?", err);
	if (!s)
		return -1;
	bind_text(s, 1, info->model);
	bind_text(s, 2, info->serial);
	bind_text(s, 3, info->firmware);
	sqlite3_bind_int(s, 4, info->npix);
	for (int i = 0; i < 5; i++)
		sqlite3_bind_double(s, 5 + i, info->wl_coef[i]);
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW && id)
		*id = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	return rc == SQLITE_ROW ? 0 : db_err(st, err, "finding spectrometer");
}

int store_device_put(struct store *st, const char *name, const char *vendor, const char *model,
		     const char *serial, const char *firmware, double at, int64_t *id, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "INSERT INTO devices (name, vendor, model, serial, firmware, first_seen, last_seen) "
				   "VALUES (?,?,?,?,?,?,?6) ON CONFLICT (name, vendor, model, serial, firmware) "
				   "DO UPDATE SET last_seen = excluded.last_seen RETURNING id", err);
	if (!s)
		return -1;
	bind_text(s, 1, name);
	bind_text(s, 2, vendor ? vendor : "");
	bind_text(s, 3, model ? model : "");
	bind_text(s, 4, serial ? serial : "");
	bind_text(s, 5, firmware ? firmware : "");
	sqlite3_bind_double(s, 6, at);
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW && id)
		*id = sqlite3_column_int64(s, 0);
	if (rc == SQLITE_ROW)
		rc = sqlite3_step(s);
	sqlite3_finalize(s);
	return rc == SQLITE_DONE ? 0 : db_err(st, err, "recording device");
}

int store_sweep_device(struct store *st, int64_t sweep_id, int64_t device_id, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "INSERT OR IGNORE INTO sweep_devices (sweep_id, device_id) VALUES (?,?)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	sqlite3_bind_int64(s, 2, device_id);
	return run1(st, s, err, "linking device to sweep");
}

int store_sweep_set_grid(struct store *st, int64_t sweep_id, const float *nm, int n, struct acq_err *err)
{
	if (n <= 0 || !nm)
		return acq_errf(err, ACQ_E_INVAL, "store: empty wavelength grid");
	for (int i = 0; i < n; i++)
		if (!isfinite(nm[i]) || nm[i] <= 0 || (i && nm[i] <= nm[i - 1]))
			return acq_errf(err, ACQ_E_INVAL, "store: wavelength grid must be positive and increasing");
	sqlite3_stmt *s = prep(st, "UPDATE sweeps SET wavelength_grid = ? WHERE id = ?", err);
	if (!s)
		return -1;
	sqlite3_bind_blob(s, 1, nm, n * 4, SQLITE_STATIC);
	sqlite3_bind_int64(s, 2, sweep_id);
	if (run1(st, s, err, "setting wavelength grid"))
		return -1;
	return sqlite3_changes(st->db) == 1 ? 0 : acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)sweep_id);
}

int store_calibrated_put(struct store *st, int64_t sweep_id, int64_t point_id, const float *brdf,
			 const float *sigma, int n, struct acq_err *err)
{
	if (n <= 0 || !brdf || !sigma)
		return acq_errf(err, ACQ_E_INVAL, "store: empty calibrated sample");
	sqlite3_stmt *s = prep(st, "INSERT OR REPLACE INTO calibrated (point_id, sweep_id, brdf, sigma) VALUES (?,?,?,?)",
			       err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, point_id);
	sqlite3_bind_int64(s, 2, sweep_id);
	sqlite3_bind_blob(s, 3, brdf, n * 4, SQLITE_STATIC);
	sqlite3_bind_blob(s, 4, sigma, n * 4, SQLITE_STATIC);
	return run1(st, s, err, "storing calibrated sample");
}

int store_recon_begin(struct store *st, int64_t sweep_id, const char *program, const char *args, double at,
		      int64_t *run_id, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "INSERT INTO recon_runs (sweep_id, state, program, args, started_at) "
				   "VALUES (?, 'running', ?, ?, ?)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	bind_text(s, 2, program);
	bind_text(s, 3, args ? args : "[]");
	sqlite3_bind_double(s, 4, at);
	if (run1(st, s, err, "starting reconstruction run"))
		return -1;
	*run_id = sqlite3_last_insert_rowid(st->db);
	return 0;
}

int store_recon_interrupted(struct store *st, double at, int *n, struct acq_err *err)
{
	*n = 0;
	sqlite3_stmt *s = prep(st, "UPDATE recon_runs SET state = 'failed', finished_at = ?, output = "
				   "'interrupted: the daemon stopped (crash or kill) during the run; its child died with it' "
				   "|| CASE WHEN output IS NULL THEN '' ELSE char(10) || output END WHERE state = 'running'", err);
	if (!s)
		return -1;
	sqlite3_bind_double(s, 1, at);
	if (run1(st, s, err, "marking interrupted reconstruction runs"))
		return -1;
	*n = sqlite3_changes(st->db);
	return 0;
}

int store_recon_end(struct store *st, int64_t run_id, const char *state, int exit_status, const char *output,
		    double at, struct acq_err *err)
{
	if (!in_list(state, (const char *const[]){ "succeeded", "failed", "cancelled", NULL }))
		return acq_errf(err, ACQ_E_INVAL, "store: unknown run state");
	sqlite3_stmt *s = prep(st, "UPDATE recon_runs SET state = ?, exit_status = ?, output = ?, finished_at = ? "
				   "WHERE id = ?", err);
	if (!s)
		return -1;
	bind_text(s, 1, state);
	sqlite3_bind_int(s, 2, exit_status);
	bind_text(s, 3, output);
	sqlite3_bind_double(s, 4, at);
	sqlite3_bind_int64(s, 5, run_id);
	return run1(st, s, err, "finishing reconstruction run");
}

int store_recon_output(struct store *st, int64_t run_id, const char *kind, const char *path, double at,
		       struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "INSERT INTO recon_outputs (run_id, kind, path, created_at) VALUES (?,?,?,?)", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, run_id);
	bind_text(s, 2, kind);
	bind_text(s, 3, path);
	sqlite3_bind_double(s, 4, at);
	return run1(st, s, err, "recording reconstruction output");
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
static json_t *rows_json(struct store *st, sqlite3_stmt *s, struct acq_err *err)
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
		db_err(st, err, "query");
		json_decref(arr);
		arr = NULL;
	}
	sqlite3_finalize(s);
	return arr;
}

json_t *store_recon_show(struct store *st, int64_t run_id, int64_t sweep_id, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, run_id ? "SELECT id, sweep_id, state, program, started_at, finished_at, exit_status, "
					   "substr(output, -2000) AS output_tail FROM recon_runs WHERE id = ?"
					 : "SELECT id, sweep_id, state, program, started_at, finished_at, exit_status, "
					   "substr(output, -2000) AS output_tail FROM recon_runs WHERE sweep_id = ? "
					   "ORDER BY id DESC LIMIT 1", err);
	if (!s)
		return NULL;
	sqlite3_bind_int64(s, 1, run_id ? run_id : sweep_id);
	json_t *rows = rows_json(st, s, err);
	if (!rows)
		return NULL;
	json_t *run = json_incref(json_array_get(rows, 0));
	json_decref(rows);
	if (!run) {
		acq_errf(err, ACQ_E_NOTFOUND, "no reconstruction run %s %lld", run_id ? "" : "for sweep",
			 (long long)(run_id ? run_id : sweep_id));
		return NULL;
	}
	s = prep(st, "SELECT kind, path, created_at FROM recon_outputs WHERE run_id = ? ORDER BY id", err);
	json_t *outs = s ? (sqlite3_bind_int64(s, 1, json_integer_value(json_object_get(run, "id"))), rows_json(st, s, err))
			 : NULL;
	if (!outs) {
		json_decref(run);
		return NULL;
	}
	json_object_set_new(run, "outputs", outs);
	return run;
}

int store_event(struct store *st, int64_t sweep_id, const char *kind, const char *device, const char *message,
		double at, struct acq_err *err)
{
	sqlite3_stmt *s = st->st[ST_EVENT];
	sqlite3_bind_double(s, 1, at);
	bind_id(s, 2, sweep_id);
	bind_text(s, 3, kind ? kind : "info");
	bind_text(s, 4, device);
	bind_text(s, 5, message ? message : "");
	return step_done(st, s, err, "logging event");
}

#define SWEEP_COLS "id, name, state, created_at, started_at, finished_at, software_version, calibration_method, " \
		   "points_total, (SELECT count(*) FROM points p WHERE p.sweep_id = sweeps.id AND p.state = 'done') " \
		   "AS points_done"

json_t *store_sweep_list(struct store *st, int limit, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "SELECT " SWEEP_COLS " FROM sweeps ORDER BY id DESC LIMIT ?", err);
	if (!s)
		return NULL;
	sqlite3_bind_int(s, 1, limit > 0 ? limit : 100);
	return rows_json(st, s, err);
}

json_t *store_sweep_show(struct store *st, int64_t id, bool with_points, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "SELECT " SWEEP_COLS ", plan_text, (SELECT count(*) FROM spectra WHERE "
				   "spectra.sweep_id = sweeps.id) AS spectra, (SELECT count(*) FROM calibrated c "
				   "WHERE c.sweep_id = sweeps.id) AS calibrated FROM sweeps WHERE id = ?", err);
	if (!s)
		return NULL;
	sqlite3_bind_int64(s, 1, id);
	json_t *rows = rows_json(st, s, err);
	if (!rows)
		return NULL;
	json_t *sw = json_incref(json_array_get(rows, 0));
	json_decref(rows);
	if (!sw) {
		acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)id);
		return NULL;
	}
	s = prep(st, "SELECT at, kind, device, message FROM events WHERE sweep_id = ? ORDER BY id DESC LIMIT 50", err);
	json_t *ev = s ? (sqlite3_bind_int64(s, 1, id), rows_json(st, s, err)) : NULL;
	if (!ev)
		goto fail;
	json_object_set_new(sw, "events", ev);
	if (with_points) {
		s = prep(st, "SELECT id, order_index, theta_i, phi_i, theta_o, phi_o, laser_theta, detector_theta, "
			     "detector_phi, state FROM points WHERE sweep_id = ? ORDER BY order_index", err);
		json_t *pts = s ? (sqlite3_bind_int64(s, 1, id), rows_json(st, s, err)) : NULL;
		if (!pts)
			goto fail;
		json_object_set_new(sw, "points", pts);
	}
	return sw;
fail:
	json_decref(sw);
	return NULL;
}

static void csv_num(FILE *out, double v)
{
	if (isfinite(v))
		fprintf(out, ",%.9g", v);
	else
		fputs(",", out); /* empty field: not measured */
}

int store_export_csv(struct store *st, int64_t sweep_id, FILE *out, int *nrows, struct acq_err *err)
{
	return store_export_csv_n(st, sweep_id, 0, out, nrows, err);
}

int store_export_csv_n(struct store *st, int64_t sweep_id, int limit, FILE *out, int *nrows, struct acq_err *err)
{
	*nrows = 0;
	sqlite3_stmt *s = prep(st, "SELECT wavelength_grid FROM sweeps WHERE id = ?", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	if (sqlite3_step(s) != SQLITE_ROW) {
		sqlite3_finalize(s);
		return acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)sweep_id);
	}
	int nb = sqlite3_column_bytes(s, 0);
	int n = nb / 4;
	float *grid = n > 0 && nb % 4 == 0 ? malloc((size_t)nb) : NULL;
	if (grid)
		memcpy(grid, sqlite3_column_blob(s, 0), (size_t)nb);
	sqlite3_finalize(s);
	if (!grid)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld has no calibrated samples yet (no wavelength grid)",
				(long long)sweep_id);
	int rc = -1;
	fprintf(out, "# acquisitiond sweep %lld: calibrated BRDF samples (sr^-1) with standard uncertainty\n",
		(long long)sweep_id);
	fputs("theta_i,phi_i,theta_o,phi_o", out);
	for (int i = 0; i < n; i++)
		fprintf(out, ",%.7g", (double)grid[i]);
	for (int i = 0; i < n; i++)
		fprintf(out, ",sigma_%.7g", (double)grid[i]);
	fputc('\n', out);
	s = prep(st, "SELECT theta_i, phi_i, theta_o, phi_o, brdf, sigma FROM calibrated_samples WHERE sweep_id = ? "
		     "ORDER BY order_index LIMIT ?", err);
	if (!s)
		goto out;
	sqlite3_bind_int64(s, 1, sweep_id);
	sqlite3_bind_int64(s, 2, limit > 0 ? limit : -1);
	int r;
	while ((r = sqlite3_step(s)) == SQLITE_ROW) {
		if (sqlite3_column_bytes(s, 4) != nb || sqlite3_column_bytes(s, 5) != nb) {
			acq_errf(err, ACQ_E_INVAL, "sweep %lld: calibrated sample length differs from the grid",
				 (long long)sweep_id);
			sqlite3_finalize(s);
			goto out;
		}
		if (sqlite3_column_type(s, 0) == SQLITE_NULL || sqlite3_column_type(s, 1) == SQLITE_NULL ||
		    sqlite3_column_type(s, 2) == SQLITE_NULL || sqlite3_column_type(s, 3) == SQLITE_NULL) {
			acq_errf(err, ACQ_E_INVAL, "sweep %lld: a point done without its measured angles", (long long)sweep_id);
			sqlite3_finalize(s);
			goto out;
		}
		const float *b = sqlite3_column_blob(s, 4), *sg = sqlite3_column_blob(s, 5);
		fprintf(out, "%.9g,%.9g,%.9g,%.9g", sqlite3_column_double(s, 0), sqlite3_column_double(s, 1),
			sqlite3_column_double(s, 2), sqlite3_column_double(s, 3));
		for (int i = 0; i < n; i++) {
			float v;
			memcpy(&v, (const char *)b + 4 * i, 4);
			csv_num(out, v);
		}
		for (int i = 0; i < n; i++) {
			float v;
			memcpy(&v, (const char *)sg + 4 * i, 4);
			csv_num(out, v);
		}
		fputc('\n', out);
		(*nrows)++;
	}
	sqlite3_finalize(s);
	if (r != SQLITE_DONE) {
		db_err(st, err, "exporting");
		goto out;
	}
	if (*nrows == 0) {
		acq_errf(err, ACQ_E_STATE, "sweep %lld has no calibrated samples", (long long)sweep_id);
		goto out;
	}
	rc = ferror(out) ? acq_errf(err, ACQ_E_IO, "writing the CSV: %s", strerror(errno)) : 0;
out:
	free(grid);
	return rc;
}

int store_export_csv_file(struct store *st, int64_t sweep_id, const char *path, int *nrows, struct acq_err *err)
{
	struct acq_out o;
	if (acq_out_open(&o, path, ACQ_OUT_STDIO, err))
		return -1;
	if (store_export_csv(st, sweep_id, o.f, nrows, err)) {
		acq_out_abort(&o);
		return -1;
	}
	return acq_out_commit(&o, err);
}

/* float32 blob of npix values into dst (double and/or float). 0, or -1 when the length differs. */
static int blob_floats(sqlite3_stmt *s, int col, int npix, double *dst_d, float *dst_f)
{
	const void *b = sqlite3_column_blob(s, col);
	int n = sqlite3_column_bytes(s, col);
	if (!b || n != 4 * npix)
		return -1;
	const float *f = b;
	for (int i = 0; i < npix; i++) {
		float v;
		memcpy(&v, f + i, sizeof v);
		if (dst_d)
			dst_d[i] = v;
		if (dst_f)
			dst_f[i] = v;
	}
	return 0;
}

int store_reference_each(struct store *st, int64_t sweep_id, double *detector_theta, store_reference_fn fn,
			 void *ctx, struct acq_err *err)
{
	long long lo = 0, hi = 0;
	sqlite3_stmt *s = prep(st, "SELECT message FROM events WHERE sweep_id = ? AND kind = 'reference' "
				   "ORDER BY id DESC LIMIT 1", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	if (sqlite3_step(s) == SQLITE_ROW) {
		const char *m = (const char *)sqlite3_column_text(s, 0);
		const char *p = m ? strstr(m, "spectra ") : NULL;
		if (!p || sscanf(p, "spectra %lld-%lld", &lo, &hi) != 2)
			lo = hi = 0;
		double lt, dt, dp;
		const char *q = m ? strstr(m, "at (") : NULL;
		if (q && sscanf(q, "at (%lf, %lf, %lf)", &lt, &dt, &dp) == 3 && detector_theta)
			*detector_theta = dt;
	}
	sqlite3_finalize(s);
	if (lo <= 0 || hi < lo)
		return 0;
	s = prep(st, "SELECT kind, integration_ms, averages, npix, counts, stddev, saturation_mask, temperature_c "
		     "FROM spectra WHERE sweep_id = ? AND id BETWEEN ? AND ? ORDER BY id", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	sqlite3_bind_int64(s, 2, lo);
	sqlite3_bind_int64(s, 3, hi);
	struct store_ref_spectrum *r = malloc(sizeof *r);
	if (!r) {
		sqlite3_finalize(s);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	int n = 0, rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		const char *kind = (const char *)sqlite3_column_text(s, 0);
		int npix = sqlite3_column_int(s, 3);
		if (!kind || npix <= 0 || npix > SPECTRO_MAX_PIXELS || strlen(kind) >= sizeof r->kind)
			continue;
		snprintf(r->kind, sizeof r->kind, "%s", kind);
		r->integration_ms = sqlite3_column_double(s, 1);
		r->averages = sqlite3_column_int(s, 2);
		r->npix = npix;
		if (blob_floats(s, 4, npix, r->counts, NULL))
			continue;
		if (sqlite3_column_type(s, 5) == SQLITE_NULL)
			memset(r->stddev, 0, sizeof(float) * (size_t)npix);
		else if (blob_floats(s, 5, npix, NULL, r->stddev))
			continue;
		memset(r->saturated, 0, (size_t)npix);
		if (sqlite3_column_type(s, 6) != SQLITE_NULL && sqlite3_column_bytes(s, 6) == npix)
			memcpy(r->saturated, sqlite3_column_blob(s, 6), (size_t)npix);
		r->temperature_c = sqlite3_column_type(s, 7) == SQLITE_NULL ? NAN : sqlite3_column_double(s, 7);
		n++;
		if (fn(ctx, r))
			break;
	}
	sqlite3_finalize(s);
	free(r);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return db_err(st, err, "reading the reference");
	return n;
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
		db_err(st, err, "open");
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

int64_t store_calibrated_count(struct store *st, int64_t sweep_id, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "SELECT (SELECT count(*) FROM calibrated WHERE sweep_id = ?1), "
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
		db_err(st, err, "counting samples");
	}
	sqlite3_finalize(s);
	return n;
}

static json_t *floats_json(const void *blob, int nbytes)
{
	json_t *a = json_array();
	for (int i = 0; a && i + 4 <= nbytes; i += 4) {
		float v;
		memcpy(&v, (const char *)blob + i, 4);
		json_array_append_new(a, isfinite(v) ? json_real(v) : json_null());
	}
	return a;
}

json_t *store_spectrum_json(struct store *st, int64_t id, struct acq_err *err)
{
	sqlite3_stmt *s = prep(st, "SELECT s.id, s.sweep_id, s.point_id, s.kind, s.integration_ms, s.averages, s.npix, "
				   "s.counts, s.stddev, s.saturated_count, s.temperature_c, s.taken_at, m.model, m.serial, "
				   "m.c0, m.c1, m.c2, m.c3, m.c4 FROM spectra s LEFT JOIN spectrometers m ON "
				   "m.id = s.spectrometer_id WHERE s.id = ?", err);
	if (!s)
		return NULL;
	sqlite3_bind_int64(s, 1, id);
	int r = sqlite3_step(s);
	if (r != SQLITE_ROW) {
		if (r == SQLITE_DONE)
			acq_errf(err, ACQ_E_NOTFOUND, "no spectrum %lld", (long long)id);
		else
			db_err(st, err, "reading a spectrum");
		sqlite3_finalize(s);
		return NULL;
	}
	int npix = sqlite3_column_int(s, 6);
	json_t *counts = floats_json(sqlite3_column_blob(s, 7), sqlite3_column_bytes(s, 7));
	double peak = 0;
	size_t i;
	json_t *v;
	json_array_foreach(counts, i, v)
		if (json_is_number(v) && json_number_value(v) > peak)
			peak = json_number_value(v);
	json_t *o = json_pack("{s:I,s:s,s:f,s:i,s:i,s:o,s:i,s:f,s:f}", "id", (json_int_t)sqlite3_column_int64(s, 0),
			      "kind", (const char *)sqlite3_column_text(s, 3), "integration_ms", sqlite3_column_double(s, 4),
			      "averages", sqlite3_column_int(s, 5), "npix", npix, "counts", counts, "saturated",
			      sqlite3_column_int(s, 9), "taken_at", sqlite3_column_double(s, 11), "peak", peak);
	if (o) {
		json_object_set_new(o, "sweep", sqlite3_column_type(s, 1) == SQLITE_NULL ? json_null()
								 : json_integer(sqlite3_column_int64(s, 1)));
		json_object_set_new(o, "point", sqlite3_column_type(s, 2) == SQLITE_NULL ? json_null()
								 : json_integer(sqlite3_column_int64(s, 2)));
		json_object_set_new(o, "temperature_c", sqlite3_column_type(s, 10) == SQLITE_NULL
								? json_null() : json_real(sqlite3_column_double(s, 10)));
		if (sqlite3_column_type(s, 8) != SQLITE_NULL)
			json_object_set_new(o, "stddev", floats_json(sqlite3_column_blob(s, 8), sqlite3_column_bytes(s, 8)));
		if (sqlite3_column_type(s, 12) != SQLITE_NULL) {
			/* The spectrometer's wavelength polynomial (AvaSpec: λ = Σ c_k · pixel^k, nm). */
			double c[5];
			for (int k = 0; k < 5; k++)
				c[k] = sqlite3_column_double(s, 14 + k);
			json_t *wl = json_array();
			for (int p = 0; wl && p < npix; p++)
				json_array_append_new(wl, json_real(c[0] + p * (c[1] + p * (c[2] + p * (c[3] + p * c[4])))));
			json_object_set_new(o, "wavelength_nm", wl);
			json_object_set_new(o, "spectrometer", json_pack("{s:s,s:s}", "model",
									  (const char *)sqlite3_column_text(s, 12), "serial",
									  (const char *)sqlite3_column_text(s, 13)));
		}
	}
	sqlite3_finalize(s);
	if (!o)
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
	return o;
}

int64_t store_recon_latest(struct store *st)
{
	sqlite3_stmt *s = prep(st, "SELECT coalesce(max(id), 0) FROM recon_runs", NULL);
	int64_t id = 0;
	if (s && sqlite3_step(s) == SQLITE_ROW)
		id = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	return id;
}
