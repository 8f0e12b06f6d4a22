/* storefix: the store tests' sweep of a few points and direct SQLite reads of its file (include after cmocka.h,
 * sqlite3.h and daemon/store.h). */
#ifndef TESTS_STOREFIX_H
#define TESTS_STOREFIX_H

#include <stdbool.h>
#include <stdlib.h>
#include <unistd.h>

/* Open (creating) the store of dir/file; its path into path[cap]. Fails the test unless it opens. */
static inline struct store *ut_store_new(char *path, size_t cap, const char *dir, const char *file)
{
	struct store *st = NULL;
	struct acq_err err = { 0 };
	snprintf(path, cap, "%s/%s", dir, file);
	assert_int_equal(store_open(path, &st, &err), 0);
	return st;
}

/* Create a sweep named name with plan_text and npts points (≤ 16; θi = 10·i, φi = 0, θo = 20 + i, φo = 180) in st;
 * fails the test unless it is stored with an id > 0. */
static inline int64_t ut_sweep_create(struct store *st, int npts, const char *name, const char *plan_text)
{
	struct store_point_new pts[16];
	assert_true(npts >= 0 && npts <= 16);
	for (int i = 0; i < npts; i++)
		pts[i] = (struct store_point_new){ i, 10.0 * i, 0, 20.0 + i, 180 };
	struct store_sweep_new sw = { .name = name, .plan_text = plan_text, .config_snapshot = "bench: {}",
				      .software_version = "test", .created_at = 1000 };
	int64_t id = 0;
	struct acq_err err = { 0 };
	assert_int_equal(store_sweep_create(st, &sw, pts, npts, &id, &err), 0);
	assert_true(id > 0);
	return id;
}

/* The database at path opened with SQLite directly (beside the store) and sql prepared on it, into *db; the test
 * fails unless both succeed. ut_sql_close finalises and closes. */
static inline sqlite3_stmt *ut_sql_open(const char *path, const char *sql, sqlite3 **db)
{
	sqlite3_stmt *s = NULL;
	assert_int_equal(sqlite3_open(path, db), SQLITE_OK);
	assert_int_equal(sqlite3_prepare_v2(*db, sql, -1, &s, NULL), SQLITE_OK);
	return s;
}

static inline void ut_sql_close(sqlite3 *db, sqlite3_stmt *s)
{
	sqlite3_finalize(s);
	sqlite3_close(db);
}

/* The single integer a query returns (a count) from the database at path; fails the test without a row. */
static inline int64_t ut_sql_count(const char *path, const char *sql)
{
	sqlite3 *db;
	sqlite3_stmt *s = ut_sql_open(path, sql, &db);
	assert_int_equal(sqlite3_step(s), SQLITE_ROW);
	int64_t v = sqlite3_column_int64(s, 0);
	ut_sql_close(db, s);
	return v;
}

/* The schema of the database at path as text: a line per entry of sqlite_master (type, name, SQL with whitespace
 * runs collapsed), sorted; caller frees. */
static inline char *ut_schema_text(const char *path)
{
	sqlite3 *db;
	sqlite3_stmt *s = ut_sql_open(path, "SELECT type || ' ' || name || ': ' || ifnull(sql, '') FROM sqlite_master "
					    "ORDER BY type, name", &db);
	size_t cap = 1 << 16, n = 0;
	char *out = calloc(cap, 1);
	assert_non_null(out);
	while (sqlite3_step(s) == SQLITE_ROW) {
		const char *r = (const char *)sqlite3_column_text(s, 0);
		bool space = false;
		for (; *r; r++) {
			bool ws = *r == ' ' || *r == '\n' || *r == '\t';
			if (ws && space)
				continue;
			space = ws;
			assert_true(n + 2 < cap);
			out[n++] = ws ? ' ' : *r;
		}
		out[n++] = '\n';
	}
	ut_sql_close(db, s);
	return out;
}

/* The database at path has exactly the schema of a new store, made at fresh (removed first) to compare. */
static inline void ut_assert_schema_of_new(const char *path, const char *fresh)
{
	struct store *st = NULL;
	struct acq_err err = { 0 };
	unlink(fresh);
	assert_int_equal(store_open(fresh, &st, &err), 0);
	store_close(st);
	char *a = ut_schema_text(path), *b = ut_schema_text(fresh);
	assert_string_equal(a, b);
	free(a);
	free(b);
}

#endif
