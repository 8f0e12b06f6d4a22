/* Unit tests for daemon/store.c: schema and ids, sweeps/points/spectra, point completion in the spectrum's
 * transaction, partial-point discard, JSON views, CSV export, and refusal of foreign/corrupt/newer files. */
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/executor.h"
#include "daemon/store.h"
#include "recon/csvio.h"
#include "recon/recon.h"
#include "tests/unit/storefix.h"
#define UT_TMPDIR_NAME "test_store"
#include "tests/unit/tmpdir.h"

static void path_of(char *out, size_t cap, const char *name)
{
	snprintf(out, cap, "%s/%s", ut_dir, name);
}

static void test_sweep_points_spectra(void **state)
{
	(void)state;
	char p[300];
	path_of(p, sizeof p, "a.db");
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	assert_int_equal(store_schema_version(st), STORE_SCHEMA_VERSION);
	int64_t sw = ut_sweep_create(st, 3, "t", "plan: 1");
	assert_int_equal(store_sweep_set_state(st, sw, "running", 1001, &err), 0);
	assert_int_equal(store_sweep_set_state(st, sw, "bogus", 1001, &err), -1);
	assert_int_equal(store_sweep_set_state(st, 999, "paused", 1001, &err), -1);
	assert_int_equal(err.code, ACQ_E_NOTFOUND);
	int order;
	int64_t pt;
	assert_int_equal(store_sweep_next_point(st, sw, &order, &pt, &err), 0);
	assert_int_equal(order, 0);
	float counts[8] = { 1, 2, 3, 4, 5, 6, 7, 8 }, sd[8] = { 0 };
	unsigned char sat[8] = { 0, 0, 0, 0, 0, 0, 1, 1 };
	struct store_spectrum sp = { .sweep_id = sw, .point_id = pt, .kind = "dark", .integration_ms = 10, .averages = 2,
				     .npix = 8, .counts = counts, .stddev = sd, .temperature_c = NAN, .taken_at = 1002 };
	assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), 0);
	sp.kind = "sample";
	sp.saturated = sat;
	sp.saturated_count = 2;
	sp.completes_point = true;
	sp.laser_theta = 0.01;
	sp.detector_theta = 20.02;
	sp.detector_phi = NAN;
	assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), 0);
	/* The point is done: completing it again fails and rolls the spectrum back. */
	assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), -1);
	assert_int_equal(err.code, ACQ_E_STATE);
	assert_int_equal(store_spectrum_count(st, sw, &err), 2);
	sp.kind = "nonsense";
	assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), -1);
	assert_int_equal(store_sweep_next_point(st, sw, &order, &pt, &err), 0);
	assert_int_equal(order, 1);
	/* A partial point (a dark without its sample) is discarded before a resume. */
	sp = (struct store_spectrum){ .sweep_id = sw, .point_id = pt, .kind = "dark", .integration_ms = 10,
				      .averages = 1, .npix = 8, .counts = counts, .temperature_c = 25, .taken_at = 1003 };
	assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), 0);
	assert_int_equal(store_spectrum_count(st, sw, &err), 3);
	assert_int_equal(store_point_discard_partial(st, pt, &err), 0);
	assert_int_equal(store_spectrum_count(st, sw, &err), 2);
	int64_t interrupted = 0;
	assert_int_equal(store_sweep_interrupted(st, &interrupted, &err), 0);
	assert_int_equal(interrupted, sw);
	json_t *list = store_sweep_list(st, 10, &err);
	assert_int_equal(json_array_size(list), 1);
	json_t *s0 = json_array_get(list, 0);
	assert_string_equal(json_string_value(json_object_get(s0, "state")), "running");
	assert_int_equal(json_integer_value(json_object_get(s0, "points_done")), 1);
	assert_int_equal(json_integer_value(json_object_get(s0, "points_total")), 3);
	json_decref(list);
	json_t *show = store_sweep_show(st, sw, true, &err);
	assert_non_null(show);
	assert_int_equal(json_array_size(json_object_get(show, "points")), 3);
	assert_int_equal(json_integer_value(json_object_get(show, "spectra")), 2);
	json_decref(show);
	assert_null(store_sweep_show(st, 12345, false, &err));
	assert_int_equal(err.code, ACQ_E_NOTFOUND);
	assert_int_equal(store_event(st, sw, "pause", "laser", "interlock open", 1004, &err), 0);
	store_close(st);
}

/* Mark point pt done with one sample spectrum, the arms' angles and the sample-frame angles they make. */
static int complete(struct store *st, int64_t sw, int64_t pt, double lt, double dt, double dp, double ti, double pi,
		    double to, double po)
{
	float counts[4] = { 1, 2, 3, 4 };
	struct store_spectrum sp = { .sweep_id = sw, .point_id = pt, .kind = "sample", .integration_ms = 10,
				     .averages = 1, .npix = 4, .counts = counts, .temperature_c = NAN, .taken_at = 1001,
				     .completes_point = true, .laser_theta = lt, .detector_theta = dt, .detector_phi = dp,
				     .theta_i = ti, .phi_i = pi, .theta_o = to, .phi_o = po };
	struct acq_err err = { 0 };
	return store_spectrum_add(st, &sp, NULL, &err);
}

static void test_export_csv(void **state)
{
	(void)state;
	char p[300];
	path_of(p, sizeof p, "b.db");
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	int64_t sw = ut_sweep_create(st, 2, "t", "plan: 1");
	FILE *f = tmpfile();
	int rows = -1;
	assert_int_equal(store_export_csv(st, sw, f, &rows, &err), -1);
	assert_int_equal(err.code, ACQ_E_STATE);
	float grid[3] = { 450, 450.5f, 451 };
	assert_int_equal(store_sweep_set_grid(st, sw, grid, 3, &err), 0);
	float bad[2] = { 500, 400 };
	assert_int_equal(store_sweep_set_grid(st, sw, bad, 2, &err), -1);
	int order;
	int64_t pt;
	assert_int_equal(store_sweep_next_point(st, sw, &order, &pt, &err), 0);
	float b[3] = { 0.1f, NAN, 0.3f }, s[3] = { 0.01f, 0.02f, 0.03f };
	assert_int_equal(store_calibrated_put(st, sw, pt, b, s, 3, &err), 0);
	/* Not done yet: not a sample. */
	assert_int_equal(store_export_csv(st, sw, f, &rows, &err), -1);
	assert_int_equal(err.code, ACQ_E_STATE);
	rewind(f);
	assert_int_equal(complete(st, sw, pt, 0, 20, 180, 0, 0, 20, 180), 0);
	assert_int_equal(store_export_csv(st, sw, f, &rows, &err), 0);
	assert_int_equal(rows, 1);
	rewind(f);
	char line[512];
	assert_non_null(fgets(line, sizeof line, f));
	assert_int_equal(line[0], '#');
	assert_non_null(fgets(line, sizeof line, f));
	assert_string_equal(line, "theta_i,phi_i,theta_o,phi_o,450,450.5,451,sigma_450,sigma_450.5,sigma_451\n");
	assert_non_null(fgets(line, sizeof line, f));
	assert_string_equal(line, "0,0,20,180,0.100000001,,0.300000012,0.00999999978,0.0199999996,0.0299999993\n");
	fclose(f);
	f = tmpfile();
	assert_int_equal(store_export_csv(st, 777, f, &rows, &err), -1);
	assert_int_equal(err.code, ACQ_E_NOTFOUND);
	fclose(f);
	store_close(st);
}

static char *slurp(const char *p, size_t *n)
{
	FILE *f = fopen(p, "rb");
	assert_non_null(f);
	char *buf = malloc(1 << 20);
	*n = fread(buf, 1, 1 << 20, f);
	fclose(f);
	return buf;
}

static void assert_refused_unchanged(const char *p, int code)
{
	size_t n0, n1;
	char *before = slurp(p, &n0);
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), -1);
	assert_null(st);
	assert_int_equal(err.code, code);
	assert_non_null(strstr(err.msg, p));
	char *after = slurp(p, &n1);
	assert_int_equal(n0, n1);
	assert_memory_equal(before, after, n0);
	char side[320];
	snprintf(side, sizeof side, "%s-wal", p);
	assert_int_equal(access(side, F_OK), -1);
	free(before);
	free(after);
}

static void test_foreign_and_corrupt_refused(void **state)
{
	(void)state;
	char p[300];
	/* Another application's SQLite database. */
	path_of(p, sizeof p, "foreign.db");
	sqlite3 *db;
	assert_int_equal(sqlite3_open(p, &db), SQLITE_OK);
	assert_int_equal(sqlite3_exec(db, "CREATE TABLE t(x); INSERT INTO t VALUES (1);", NULL, NULL, NULL), SQLITE_OK);
	sqlite3_close(db);
	assert_refused_unchanged(p, ACQ_E_INVAL);
	/* Not SQLite at all. */
	path_of(p, sizeof p, "garbage.db");
	FILE *f = fopen(p, "wb");
	for (int i = 0; i < 5000; i++)
		fputc((i * 7919) & 0xff, f);
	fclose(f);
	assert_refused_unchanged(p, ACQ_E_IO);
	/* Ours, from a newer acquisitiond. */
	path_of(p, sizeof p, "newer.db");
	assert_int_equal(sqlite3_open(p, &db), SQLITE_OK);
	char sql[128];
	snprintf(sql, sizeof sql, "PRAGMA application_id=%d; PRAGMA user_version=%d; CREATE TABLE z(x);",
		 STORE_APPLICATION_ID, STORE_SCHEMA_VERSION + 1);
	assert_int_equal(sqlite3_exec(db, sql, NULL, NULL, NULL), SQLITE_OK);
	sqlite3_close(db);
	assert_refused_unchanged(p, ACQ_E_UNSUPPORTED);
	/* An empty file is initialised; reopening our own database works. */
	path_of(p, sizeof p, "empty.db");
	f = fopen(p, "wb");
	fclose(f);
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	store_close(st);
	assert_int_equal(store_open(p, &st, &err), 0);
	assert_int_equal(store_schema_version(st), STORE_SCHEMA_VERSION);
	store_close(st);
}

/* The three readers of calibrated samples — the CSV export (`export`), the file the daemon's reconstruction
 * reads (store_export_csv_file, recon_chain.c) and brdf-recon's --db (recon/dbload.c) — give the same samples:
 * the sample-frame angles measured at commit (an arm at -0.003° is θi 0.003° at φi + 180°, which the CSV reader
 * accepts), the same values, and no sample of a point not done. */
static void test_three_readers_same_samples(void **state)
{
	(void)state;
	char p[300], csvp[300];
	path_of(p, sizeof p, "three.db");
	path_of(csvp, sizeof csvp, "samples.csv");
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	int64_t sw = ut_sweep_create(st, 4, "t", "plan: 1");
	float grid[3] = { 450, 500, 550 };
	assert_int_equal(store_sweep_set_grid(st, sw, grid, 3, &err), 0);
	struct bench_geom g = { .laser_phi_deg = 0 };
	const double arms[4][3] = { { -0.003, 30, -90 }, { 20, -15, 10 }, { 40, 60, 350 }, { 50, 50, 50 } };
	for (int k = 0; k < 4; k++) {
		int order;
		int64_t pt;
		assert_int_equal(store_sweep_next_point(st, sw, &order, &pt, &err), 0);
		float b[3] = { 0.1f * (float)(k + 1), NAN, 0.3f / (float)(k + 1) }, sg[3] = { 0.01f, 0.02f, 1e-3f * (float)k };
		assert_int_equal(store_calibrated_put(st, sw, pt, b, sg, 3, &err), 0);
		if (k == 3)
			break; /* calibrated but not done (a crash before the commit): no sample */
		struct plan_pos pos = { arms[k][0], arms[k][1], arms[k][2] };
		double ti, pi, to, po;
		ex_pos_angles(&g, &pos, &ti, &pi, &to, &po);
		assert_int_equal(complete(st, sw, pt, arms[k][0], arms[k][1], arms[k][2], ti, pi, to, po), 0);
	}
	struct recon_samples a = { 0 }, b = { 0 }, c = { 0 };
	char *text = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&text, &len);
	int rows = 0;
	assert_int_equal(store_export_csv(st, sw, f, &rows, &err), 0);
	fclose(f);
	assert_int_equal(rows, 3);
	assert_int_equal(csvio_parse_samples("export", text, len, &a, &err), 0);
	free(text);
	assert_int_equal(store_export_csv_file(st, sw, csvp, &rows, &err), 0);
	assert_int_equal(csvio_read_samples(csvp, &b, &err), 0);
	store_close(st);
	assert_int_equal(recon_load_db(p, sw, &c, &err), 0);
	const struct recon_samples *r[3] = { &a, &b, &c };
	for (int m = 0; m < 3; m++) {
		assert_int_equal(r[m]->n, 3);
		assert_int_equal(r[m]->nwl, 3);
		/* point 0: the arm at -0.003° is on the other side */
		assert_true(fabs(r[m]->deg[0] - 0.003) < 1e-9 && fabs(r[m]->deg[1] - 180) < 1e-9);
		assert_true(fabs(r[m]->deg[2] - 30) < 1e-9 && fabs(r[m]->deg[3] - 270) < 1e-9);
		/* point 1: detector zenith -15 at φ 10 is 15 at 190 */
		assert_true(fabs(r[m]->deg[6] - 15) < 1e-9 && fabs(r[m]->deg[7] - 190) < 1e-9);
		for (size_t i = 0; i < 12; i++) /* the CSV prints 9 significant digits: angles agree to 1e-9 relative */
			assert_true(fabs(r[m]->deg[i] - c.deg[i]) <= 1e-9 * fmax(1, fabs(c.deg[i])));
		for (size_t i = 0; i < 9; i++) {
			/* float32 values printed with 9 digits read back within 1e-8 relative of the stored float */
			double x = r[m]->val[i], y = c.val[i];
			assert_true((isnan(x) && isnan(y)) || fabs(x - y) <= 1e-8 * fabs(y));
			x = r[m]->sig[i];
			y = c.sig[i];
			assert_true(fabs(x - y) <= 1e-8 * fabs(y));
		}
	}
	csvio_samples_free(&a);
	csvio_samples_free(&b);
	csvio_samples_free(&c);
}

/* Turn a current (version 3) database into version 2 as version 2 created it: recon_runs without the
 * 'interrupted' state (the CREATE text of version 2's schema.sql). */
static void downgrade_to_v2(const char *p)
{
	sqlite3 *db;
	assert_int_equal(sqlite3_open(p, &db), SQLITE_OK);
	assert_int_equal(sqlite3_exec(db, "PRAGMA foreign_keys = OFF; PRAGMA legacy_alter_table = ON; BEGIN;"
					  "ALTER TABLE sweeps DROP COLUMN plan_kind;" /* version 6's */
					  "DROP TABLE sweep_samples;" /* version 5's */
					  "DROP TABLE adaptive_picks; DROP TABLE adaptive_batches;" /* version 4's */
					  "ALTER TABLE recon_runs RENAME TO r3;"
					  "CREATE TABLE recon_runs (\n"
					  "  id INTEGER PRIMARY KEY,\n"
					  "  sweep_id INTEGER NOT NULL REFERENCES sweeps(id),\n"
					  "  state TEXT NOT NULL CHECK (state IN ('running', 'succeeded', 'failed', 'cancelled')),\n"
					  "  program TEXT NOT NULL, args TEXT NOT NULL,   -- args: JSON array\n"
					  "  started_at REAL NOT NULL, finished_at REAL,\n"
					  "  exit_status INTEGER,                         -- exit code, or 128 + signal\n"
					  "  output TEXT                                  -- captured stdout+stderr (bounded)\n"
					  ");"
					  "INSERT INTO recon_runs SELECT * FROM r3; DROP TABLE r3; PRAGMA user_version = 2; COMMIT;",
				     NULL, NULL, NULL),
			 SQLITE_OK);
	/* really version 2: the state does not exist there */
	assert_int_not_equal(sqlite3_exec(db, "INSERT INTO recon_runs (sweep_id, state, program, args, started_at) "
					      "SELECT id, 'interrupted', 'x', '[]', 0 FROM sweeps LIMIT 1", NULL, NULL, NULL),
			     SQLITE_OK);
	sqlite3_close(db);
}

/* A migrated database has exactly the schema of a new one (hence of daemon/schema.sql, which
 * test_store_schema.py compares with a new one), and passes SQLite's integrity and foreign-key checks. */
static void assert_schema_current(const char *p)
{
	char fresh[300];
	path_of(fresh, sizeof fresh, "fresh.db");
	ut_assert_schema_of_new(p, fresh);
	sqlite3 *db;
	assert_int_equal(sqlite3_open(p, &db), SQLITE_OK);
	sqlite3_stmt *s;
	assert_int_equal(sqlite3_prepare_v2(db, "PRAGMA integrity_check", -1, &s, NULL), SQLITE_OK);
	assert_int_equal(sqlite3_step(s), SQLITE_ROW);
	assert_string_equal((const char *)sqlite3_column_text(s, 0), "ok");
	sqlite3_finalize(s);
	assert_int_equal(sqlite3_prepare_v2(db, "PRAGMA foreign_key_check", -1, &s, NULL), SQLITE_OK);
	assert_int_equal(sqlite3_step(s), SQLITE_DONE);
	sqlite3_finalize(s);
	sqlite3_close(db);
}

/* The state of run id, read with SQLite directly, into buf. */
static const char *run_state(const char *p, int64_t id, char *buf, size_t cap)
{
	sqlite3 *db;
	sqlite3_stmt *s = ut_sql_open(p, "SELECT state FROM recon_runs WHERE id = ?", &db);
	sqlite3_bind_int64(s, 1, id);
	assert_int_equal(sqlite3_step(s), SQLITE_ROW);
	snprintf(buf, cap, "%s", (const char *)sqlite3_column_text(s, 0));
	ut_sql_close(db, s);
	return buf;
}

/* Version 2 → 3: recon_runs gains 'interrupted'. A run version 2 marked interrupted ('failed', "interrupted: ...")
 * becomes 'interrupted'; other runs, their outputs and the foreign keys stay; a run left 'running' by a dead
 * daemon is marked 'interrupted' by store_recon_interrupted(), after which a new run starts. */
static void test_migration_2_to_3(void **state)
{
	(void)state;
	char p[300], b[32];
	path_of(p, sizeof p, "v2.db");
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	int64_t sw = ut_sweep_create(st, 2, "t", "plan: 1"), run_ok, run_dead, run_old;
	assert_int_equal(store_recon_begin(st, sw, "brdf-recon", "[\"fit\"]", 1000, &run_ok, &err), 0);
	assert_int_equal(store_recon_output(st, run_ok, "model", "recon/1/model.json", 1001, &err), 0);
	assert_int_equal(store_recon_end(st, run_ok, "succeeded", 0, "fit done", 1002, &err), 0);
	assert_int_equal(store_recon_begin(st, sw, "brdf-recon", "[]", 1003, &run_old, &err), 0);
	assert_int_equal(store_recon_end(st, run_old, "failed", 0, "interrupted: the daemon stopped (crash or kill) "
							       "during the run; its child died with it\nfit: 10 %", 1004, &err), 0);
	assert_int_equal(store_recon_begin(st, sw, "brdf-recon", "[]", 1005, &run_dead, &err), 0);
	store_close(st);
	downgrade_to_v2(p);

	assert_int_equal(store_open(p, &st, &err), 0);
	assert_int_equal(store_schema_version(st), STORE_SCHEMA_VERSION);
	store_close(st);
	assert_schema_current(p);
	assert_string_equal(run_state(p, run_ok, b, sizeof b), "succeeded");
	assert_string_equal(run_state(p, run_old, b, sizeof b), "interrupted");
	assert_string_equal(run_state(p, run_dead, b, sizeof b), "running"); /* the migration does not guess */

	assert_int_equal(store_open(p, &st, &err), 0);
	json_t *r = store_recon_show(st, run_ok, 0, &err);
	assert_non_null(r);
	assert_int_equal(json_array_size(json_object_get(r, "outputs")), 1);
	assert_string_equal(json_string_value(json_object_get(r, "output_tail")), "fit done");
	json_decref(r);
	int n = -1;
	assert_int_equal(store_recon_interrupted(st, 2000, &n, &err), 0);
	assert_int_equal(n, 1);
	r = store_recon_show(st, 0, sw, &err);
	assert_non_null(r);
	assert_int_equal(json_integer_value(json_object_get(r, "id")), run_dead);
	assert_string_equal(json_string_value(json_object_get(r, "state")), "interrupted");
	assert_true(!strncmp(json_string_value(json_object_get(r, "output_tail")), "interrupted: ", 13));
	json_decref(r);
	assert_int_equal(store_recon_interrupted(st, 2001, &n, &err), 0);
	assert_int_equal(n, 0);
	int64_t run_new;
	assert_int_equal(store_recon_begin(st, sw, "brdf-recon", "[]", 2002, &run_new, &err), 0);
	assert_true(run_new > run_dead);
	store_close(st);
	assert_string_equal(run_state(p, run_new, b, sizeof b), "running");
}

/* A version-1 database (before the measured sample-frame angles) is migrated when opened, through 2 to 3: its
 * done points get their arm angles in the sample frame, the readers' view appears, and the schema is the
 * current one. */
static void test_migration_1_to_3(void **state)
{
	(void)state;
	char p[300];
	path_of(p, sizeof p, "v1.db");
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	int64_t sw = ut_sweep_create(st, 2, "t", "plan: 1"); /* planned (0, 0, 20, 180) and (10, 0, 21, 180) */
	int64_t run;
	assert_int_equal(store_recon_begin(st, sw, "brdf-recon", "[]", 1000, &run, &err), 0);
	float grid[1] = { 500 };
	assert_int_equal(store_sweep_set_grid(st, sw, grid, 1, &err), 0);
	int order;
	int64_t pt;
	assert_int_equal(store_sweep_next_point(st, sw, &order, &pt, &err), 0);
	float b[1] = { 0.5f }, sg[1] = { 0.05f };
	assert_int_equal(store_calibrated_put(st, sw, pt, b, sg, 1, &err), 0);
	assert_int_equal(complete(st, sw, pt, -0.003, -20, 170, NAN, NAN, NAN, NAN), 0);
	store_close(st);
	downgrade_to_v2(p);
	sqlite3 *db;
	assert_int_equal(sqlite3_open(p, &db), SQLITE_OK);
	assert_int_equal(sqlite3_exec(db, "DROP VIEW calibrated_samples; ALTER TABLE points DROP COLUMN m_theta_i; "
					  "ALTER TABLE points DROP COLUMN m_phi_i; ALTER TABLE points DROP COLUMN m_theta_o; "
					  "ALTER TABLE points DROP COLUMN m_phi_o; PRAGMA user_version = 1;",
				     NULL, NULL, NULL),
			 SQLITE_OK);
	sqlite3_close(db);
	assert_int_equal(store_open(p, &st, &err), 0);
	assert_int_equal(store_schema_version(st), STORE_SCHEMA_VERSION);
	store_close(st);
	assert_schema_current(p);
	struct recon_samples c = { 0 };
	assert_int_equal(recon_load_db(p, sw, &c, &err), 0);
	assert_int_equal(c.n, 1);
	assert_true(fabs(c.deg[0] - 0.003) < 1e-12 && fabs(c.deg[1] - 180) < 1e-12);
	assert_true(fabs(c.deg[2] - 20) < 1e-12 && fabs(c.deg[3] - 350) < 1e-12);
	csvio_samples_free(&c);
}

/* Version 4 → 5: sweep_samples appears (the sample a sweep measured, for exposure priors). The sweeps of a version-4
 * database keep everything and have no sample (so no prior); a sweep created after the migration records its. */
static void test_migration_4_to_5(void **state)
{
	(void)state;
	char p[300];
	path_of(p, sizeof p, "v4.db");
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	int64_t old = ut_sweep_create(st, 2, "t", "plan: 1");
	store_close(st);
	sqlite3 *db;
	assert_int_equal(sqlite3_open(p, &db), SQLITE_OK);
	assert_int_equal(sqlite3_exec(db, "ALTER TABLE sweeps DROP COLUMN plan_kind; DROP TABLE sweep_samples; "
				      "PRAGMA user_version = 4;", NULL, NULL, NULL),
			 SQLITE_OK);
	sqlite3_close(db);
	assert_int_equal(store_open(p, &st, &err), 0);
	assert_int_equal(store_schema_version(st), STORE_SCHEMA_VERSION);
	assert_int_equal(store_sweep_set_state(st, old, "completed", 1100, &err), 0);
	json_t *show = store_sweep_show(st, old, true, &err);
	assert_non_null(show);
	assert_int_equal(json_array_size(json_object_get(show, "points")), 2);
	json_decref(show);
	int64_t id = 0;
	assert_int_equal(store_prior_each(st, "paint", 0, &id, NULL, NULL, &err), 0);
	assert_int_equal(id, 0);
	struct store_sweep_new nw = { .name = "n", .plan_text = "name: n", .config_snapshot = "{}",
				      .software_version = "test", .created_at = 2000, .sample = "paint", .auto_exposure = true };
	int64_t now = 0;
	assert_int_equal(store_sweep_create(st, &nw, NULL, 0, &now, &err), 0);
	assert_int_equal(store_sweep_set_state(st, now, "completed", 2100, &err), 0);
	store_close(st);
	assert_schema_current(p);
	sqlite3_stmt *s = ut_sql_open(p, "SELECT group_concat(sweep_id || ':' || sample || ':' || auto_exposure) "
					 "FROM sweep_samples", &db);
	assert_int_equal(sqlite3_step(s), SQLITE_ROW);
	char want[64];
	snprintf(want, sizeof want, "%lld:paint:1", (long long)now);
	assert_string_equal((const char *)sqlite3_column_text(s, 0), want);
	ut_sql_close(db, s);
}

/* Version 5 → 6: sweeps gains plan_kind. The sweeps of a version-5 database keep everything and have no kind (NULL:
 * they time plans of any kind); a sweep created after the migration records its kind, and the latest completed
 * sweep of a kind is found by it. */
static void test_migration_5_to_6(void **state)
{
	(void)state;
	char p[300];
	path_of(p, sizeof p, "v5.db");
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	int64_t old = ut_sweep_create(st, 2, "t", "plan: 1");
	assert_int_equal(store_sweep_set_state(st, old, "completed", 1100, &err), 0);
	store_close(st);
	sqlite3 *db;
	assert_int_equal(sqlite3_open(p, &db), SQLITE_OK);
	assert_int_equal(sqlite3_exec(db, "ALTER TABLE sweeps DROP COLUMN plan_kind; PRAGMA user_version = 5;", NULL, NULL,
				      NULL), SQLITE_OK);
	sqlite3_close(db);
	assert_int_equal(store_open(p, &st, &err), 0);
	assert_int_equal(store_schema_version(st), STORE_SCHEMA_VERSION);
	json_t *show = store_sweep_show(st, old, true, &err);
	assert_non_null(show);
	assert_int_equal(json_array_size(json_object_get(show, "points")), 2);
	json_decref(show);
	int64_t id = -1;
	assert_int_equal(store_latest_completed(st, 0, NULL, &id, &err), 0);
	assert_int_equal(id, old);
	assert_int_equal(store_latest_completed(st, 0, "grid/auto", &id, &err), 0);
	assert_int_equal(id, 0); /* the old sweep has no kind */
	struct store_sweep_new nw = { .name = "n", .plan_text = "name: n", .config_snapshot = "{}",
				      .software_version = "test", .created_at = 2000, .plan_kind = "grid/auto" };
	int64_t now = 0;
	assert_int_equal(store_sweep_create(st, &nw, NULL, 0, &now, &err), 0);
	assert_int_equal(store_sweep_set_state(st, now, "completed", 2100, &err), 0);
	assert_int_equal(store_latest_completed(st, 0, "grid/auto", &id, &err), 0);
	assert_int_equal(id, now);
	assert_int_equal(store_latest_completed(st, 0, "fibonacci/auto", &id, &err), 0);
	assert_int_equal(id, 0);
	store_close(st);
	assert_schema_current(p);
	sqlite3_stmt *s = ut_sql_open(p, "SELECT group_concat(id || ':' || ifnull(plan_kind, '-')) FROM sweeps", &db);
	assert_int_equal(sqlite3_step(s), SQLITE_ROW);
	char want[64];
	snprintf(want, sizeof want, "%lld:-,%lld:grid/auto", (long long)old, (long long)now);
	assert_string_equal((const char *)sqlite3_column_text(s, 0), want);
	ut_sql_close(db, s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sweep_points_spectra),
		cmocka_unit_test(test_export_csv),
		cmocka_unit_test(test_three_readers_same_samples),
		cmocka_unit_test(test_migration_1_to_3),
		cmocka_unit_test(test_migration_2_to_3),
		cmocka_unit_test(test_migration_4_to_5),
		cmocka_unit_test(test_migration_5_to_6),
		cmocka_unit_test(test_foreign_and_corrupt_refused),
	};
	return cmocka_run_group_tests(tests, ut_dir_setup, ut_dir_teardown);
}
