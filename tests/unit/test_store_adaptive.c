/* Unit tests for daemon/store_adaptive.c: a batch's decision, picks and points in one transaction (a refused batch
 * writes nothing), the decisions read back in order with their picks, NULLs for unknown figures, and the 3 → 4
 * migration (a version-3 database gains the two tables, with exactly a new database's schema). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sqlite3.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/store.h"
#include "daemon/store_adaptive.h"
#include "tests/unit/storefix.h"
#define UT_TMPDIR_NAME "test_store_adaptive"
#include "tests/unit/tmpdir.h"

static void test_batches(void **state)
{
	(void)state;
	char p[300];
	struct store *st = ut_store_new(p, sizeof p, ut_dir, "a.db");
	struct acq_err err = { 0 };
	int64_t sw = ut_sweep_create(st, 3, "a", "kind: adaptive");
	struct store_batch seed = { .batch = 0, .decided_at = 1000, .n_points = 3, .target_spec = "dhr:8:le=0.002",
				    .target_value = NAN, .target_met = -1, .predicted_value = NAN, .warm = -1,
				    .candidates = -1, .predicted_s = 30, .waited_s = NAN };
	assert_int_equal(store_adaptive_batch(st, sw, &seed, NULL, 0, NULL, 0, &err), 0);
	struct store_pick picks[3] = {
		{ 0, 17, 4, 40, 30, 200, 0.5, 3.2, 0.004 },
		{ 1, 3, 3, 40, 60, 10, 0.25, 2.1, 0.003 },
		{ 2, 99, -1, 0, 45, 90, 0.1, 9.9, 0.0029 }, /* left out by the budget */
	};
	struct store_point_new pts[2] = { { 3, 40, 0, 60, 10 }, { 4, 40, 0, 30, 200 } };
	struct store_batch b1 = { .batch = 1, .decided_at = 1100, .first_order_index = 3, .n_points = 2,
				  .target_spec = "dhr:8:le=0.002", .target_value = 0.005, .target_met = 0,
				  .predicted_value = 0.003, .model = "recon/sweep-1/batch-1/model.brdf", .criterion = "c",
				  .warm = 0, .candidates = 120, .predicted_s = 12.5, .waited_s = 1.5 };
	assert_int_equal(store_adaptive_batch(st, sw, &b1, picks, 3, pts, 2, &err), 0);
	/* the same batch again: refused, and nothing of it written (no third pick set, no points) */
	struct store_point_new more[1] = { { 5, 0, 0, 10, 10 } };
	assert_int_not_equal(store_adaptive_batch(st, sw, &b1, picks, 1, more, 1, &err), 0);
	assert_non_null(strstr(err.msg, "adaptive batch 1"));
	/* a batch whose point repeats an order index: refused whole (its row does not stay) */
	struct store_batch b2 = b1;
	b2.batch = 2;
	b2.first_order_index = 4;
	assert_int_not_equal(store_adaptive_batch(st, sw, &b2, picks, 1, &pts[1], 1, &err), 0);
	struct store_batch fin = { .batch = 2, .decided_at = 1200, .first_order_index = 5, .n_points = 0,
				   .target_spec = "dhr:8:le=0.002", .target_value = 0.0019, .target_met = 1,
				   .predicted_value = NAN, .warm = -1, .candidates = -1, .predicted_s = 0, .waited_s = 0.7,
				   .stop_reason = "target met" };
	assert_int_equal(store_adaptive_batch(st, sw, &fin, NULL, 0, NULL, 0, &err), 0);
	json_t *rows = store_adaptive_show(st, sw, &err);
	assert_non_null(rows);
	assert_int_equal(json_array_size(rows), 3);
	json_t *r0 = json_array_get(rows, 0), *r1 = json_array_get(rows, 1), *r2 = json_array_get(rows, 2);
	assert_true(json_is_null(json_object_get(r0, "target_value")) && json_is_null(json_object_get(r0, "warm")));
	assert_int_equal(json_array_size(json_object_get(r0, "picks")), 0);
	assert_int_equal(json_integer_value(json_object_get(r1, "first_order_index")), 3);
	assert_true(json_real_value(json_object_get(r1, "target_value")) == 0.005);
	json_t *pk = json_object_get(r1, "picks");
	assert_int_equal(json_array_size(pk), 3);
	for (int i = 0; i < 3; i++) {
		json_t *x = json_array_get(pk, (size_t)i);
		assert_int_equal(json_integer_value(json_object_get(x, "rank")), i);
		assert_int_equal(json_integer_value(json_object_get(x, "candidate_id")), picks[i].candidate_id);
		assert_true(json_real_value(json_object_get(x, "detector_phi")) == picks[i].detector_phi);
	}
	assert_true(json_is_null(json_object_get(json_array_get(pk, 2), "order_index")));
	assert_string_equal(json_string_value(json_object_get(r2, "stop_reason")), "target met");
	json_decref(rows);
	rows = store_adaptive_show(st, sw + 1, &err); /* no such sweep: no decisions */
	assert_non_null(rows);
	assert_int_equal(json_array_size(rows), 0);
	json_decref(rows);
	store_close(st);
	assert_int_equal(ut_sql_count(p, "SELECT points_total FROM sweeps"), 5);
	assert_int_equal(ut_sql_count(p, "SELECT count(*) FROM points"), 5);
	assert_int_equal(ut_sql_count(p, "SELECT count(*) FROM adaptive_picks"), 3);
	assert_int_equal(ut_sql_count(p, "SELECT count(*) FROM adaptive_batches"), 3);
}

static void test_migration_3_to_4(void **state)
{
	(void)state;
	char p[300], fresh[300];
	snprintf(p, sizeof p, "%s/v3.db", ut_dir);
	snprintf(fresh, sizeof fresh, "%s/fresh.db", ut_dir);
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(p, &st, &err), 0);
	int64_t sw = ut_sweep_create(st, 2, "a", "kind: adaptive");
	store_close(st);
	sqlite3 *db;
	assert_int_equal(sqlite3_open(p, &db), SQLITE_OK);
	/* version 3 had neither the adaptive tables nor version 5's sweep_samples nor version 6's sweeps.plan_kind; it
	 * migrates through 4 to the current */
	assert_int_equal(sqlite3_exec(db, "ALTER TABLE sweeps DROP COLUMN plan_kind; DROP TABLE sweep_samples; "
					  "DROP TABLE adaptive_picks; DROP TABLE adaptive_batches; PRAGMA user_version = 3;",
				      NULL, NULL, NULL), SQLITE_OK);
	sqlite3_close(db);
	assert_int_equal(store_open(p, &st, &err), 0);
	assert_int_equal(store_schema_version(st), STORE_SCHEMA_VERSION);
	struct store_batch seed = { .batch = 0, .decided_at = 1, .n_points = 2, .target_spec = "lnf", .target_value = NAN,
				    .target_met = -1, .predicted_value = NAN, .warm = -1, .candidates = -1, .predicted_s = 1,
				    .waited_s = NAN };
	assert_int_equal(store_adaptive_batch(st, sw, &seed, NULL, 0, NULL, 0, &err), 0);
	store_close(st);
	ut_assert_schema_of_new(p, fresh);
	assert_int_equal(ut_sql_count(p, "SELECT count(*) FROM points"), 2); /* the migration touched nothing else */
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_batches),
		cmocka_unit_test(test_migration_3_to_4),
	};
	return cmocka_run_group_tests(tests, ut_dir_setup, ut_dir_teardown);
}
