/* test_store_group: a point's writes in one group are one transaction (a reader sees none of them until the end,
 * one commit), stored whole, or rolled back whole when one fails. */
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
#include "tests/unit/storefix.h"
#include "tests/unit/tmpdir.h"

static float counts[16], brdf[4] = { 0.1f, 0.2f, 0.3f, 0.4f }, sig[4] = { 0.01f, 0.01f, 0.01f, 0.01f };

static int point_rows(struct store *st, int64_t sid, int64_t pid, bool pending_ok)
{
	struct acq_err err = { 0 };
	struct store_spectrum dark = { .sweep_id = sid, .point_id = pid, .kind = "dark", .integration_ms = 10,
				       .averages = 1, .npix = 16, .counts = counts, .temperature_c = NAN, .taken_at = 1 };
	struct store_spectrum sample = dark;
	sample.kind = "sample";
	sample.completes_point = true;
	sample.point_id = pending_ok ? pid : pid + 1000; /* no such pending point: the completion fails */
	if (store_spectrum_add(st, &dark, NULL, &err) || store_calibrated_put(st, sid, pid, brdf, sig, 4, &err))
		return -1;
	return store_spectrum_add(st, &sample, NULL, &err);
}

static void test_point_in_one_transaction(void **state)
{
	(void)state;
	char dir[256], path[300];
	assert_int_equal(ut_tmpdir_make(dir, sizeof dir, "acq-test-group"), 0);
	struct store *st = ut_store_new(path, sizeof path, dir, "g.db");
	int64_t sid = ut_sweep_create(st, 2, "group", "name: group");
	struct acq_err err = { 0 };
	int oi = -1;
	int64_t pid = 0;
	assert_int_equal(store_sweep_next_point(st, sid, &oi, &pid, &err), 0);
	assert_int_equal(oi, 0);
	/* 1. a good point: nothing visible to another connection until the group ends, then all of it */
	assert_int_equal(store_group_begin(st, &err), 0);
	assert_int_equal(store_group_begin(st, &err), -1); /* no nesting */
	assert_int_equal(point_rows(st, sid, pid, true), 0);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM spectra"), 0);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM calibrated"), 0);
	assert_int_equal(store_group_end(st, 0, &err), 0);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM spectra"), 2);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM calibrated"), 1);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM points WHERE state = 'done'"), 1);
	/* 2. a point whose completion fails: its dark and calibrated sample are rolled back with it */
	assert_int_equal(store_sweep_next_point(st, sid, &oi, &pid, &err), 0);
	assert_int_equal(oi, 1);
	assert_int_equal(store_group_begin(st, &err), 0);
	assert_int_equal(point_rows(st, sid, pid, false), -1);
	assert_int_equal(store_group_end(st, 0, &err), -1); /* a write failed: the group is not committed */
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM spectra"), 2);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM calibrated"), 1);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM points WHERE state = 'done'"), 1);
	assert_int_equal(store_group_end(st, 0, &err), -1); /* none open */
	/* 3. outside a group every write is its own transaction again */
	struct store_spectrum one = { .sweep_id = sid, .kind = "dark", .integration_ms = 10, .averages = 1, .npix = 16,
				      .counts = counts, .temperature_c = NAN, .taken_at = 2 };
	assert_int_equal(store_spectrum_add(st, &one, NULL, &err), 0);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM spectra"), 3);
	store_close(st);
	ut_tmpdir_remove(dir);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_point_in_one_transaction),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
