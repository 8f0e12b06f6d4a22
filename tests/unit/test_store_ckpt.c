/* test_store_ckpt: the WAL's checkpoints run on the store's own thread (store_ckpt.c), not inside the commit on
 * the daemon's loop, and they keep the WAL bounded as SQLite's automatic checkpoint did. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>
#include "daemon/store.h"
#include "tests/unit/storefix.h"
#include "tests/unit/tmpdir.h"

#define NPIX 2048 /* 8 KiB of counts + 8 KiB of stddev: 4 pages a spectrum */

static long file_size(const char *path)
{
	struct stat sb;
	return stat(path, &sb) ? -1 : (long)sb.st_size;
}

/* 1100 spectra (~4400 pages, far past the threshold): the thread checkpointed (its count grew, which SQLite's own
 * checkpoint would not do) and the WAL restarted from its beginning instead of growing to ~18 MB. */
static void test_checkpoints_off_the_committing_thread(void **state)
{
	(void)state;
	char dir[256], path[300], wal[310];
	assert_int_equal(ut_tmpdir_make(dir, sizeof dir, "acq-test-ckpt"), 0);
	struct store *st = ut_store_new(path, sizeof path, dir, "a.db");
	snprintf(wal, sizeof wal, "%s-wal", path);
	int64_t sid = ut_sweep_create(st, 1, "ckpt", "name: ckpt");
	static float counts[NPIX], sd[NPIX];
	for (int i = 0; i < NPIX; i++) {
		counts[i] = (float)(i % 977);
		sd[i] = 1.0f;
	}
	struct acq_err err = { 0 };
	unsigned long runs = 0;
	double secs = 0, max_s = 0;
	long wal_max = 0;
	for (int k = 0; k < 1100; k++) {
		counts[0] = (float)k; /* no two alike */
		struct store_spectrum sp = { .sweep_id = sid, .kind = "dark", .integration_ms = 10, .averages = 1,
					     .npix = NPIX, .counts = counts, .stddev = sd, .temperature_c = NAN,
					     .taken_at = 1000 + k };
		assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), 0);
		/* as the sweep does: the next point only once this one is on disk (store_sync.c's fsync) */
		assert_int_equal(store_durable_wait(st, store_commit_mark(st), &err), 1);
		long w = file_size(wal);
		if (w > wal_max)
			wal_max = w;
		if (k % 100 == 99) /* the thread's turn (a real loop has gaps between commits) */
			usleep(20000);
	}
	store_ckpt_stats(st, &runs, &secs, &max_s);
	printf("checkpoints on the store's thread: %lu, %.1f ms in all, longest %.1f ms; WAL at most %.1f MB\n", runs,
	       1e3 * secs, 1e3 * max_s, wal_max / 1048576.0);
	assert_true(runs >= 2);
	assert_true(secs > 0 && max_s <= secs);
	/* Unchecked, 1100 × 4 pages of 4 KiB would make a WAL of ~18 MB. */
	assert_true(wal_max < 12L * 1048576);
	store_close(st);
	/* Closed: everything is in the database (the close's TRUNCATE checkpoint), all 1100 spectra there. */
	sqlite3 *db;
	sqlite3_stmt *s = ut_sql_open(path, "SELECT count(*) FROM spectra", &db);
	assert_int_equal(sqlite3_step(s), SQLITE_ROW);
	assert_int_equal(sqlite3_column_int(s, 0), 1100);
	ut_sql_close(db, s);
	assert_true(file_size(wal) <= 0);
	ut_tmpdir_remove(dir);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_checkpoints_off_the_committing_thread),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
