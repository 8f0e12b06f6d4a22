/* Crash test of daemon/store.c: a child commits spectra as fast as it can and reports each committed id
 * through a pipe; the parent SIGKILLs it at a seeded random moment (ACQ_SEED), then checks that every
 * reported spectrum is in the database, intact, and that PRAGMA integrity_check says ok. Repeated. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <signal.h>
#include <sqlite3.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/store.h"
#include "tests/unit/tmpdir.h"

#define NPIX 2048

static void child(const char *path, int wfd)
{
	struct store *st = NULL;
	struct acq_err err = { 0 };
	if (store_open(path, &st, &err))
		_exit(2);
	static float counts[NPIX];
	for (int64_t k = 1;; k++) {
		for (int i = 0; i < NPIX; i++)
			counts[i] = (float)(k * 10000 + i);
		struct store_spectrum sp = { .kind = "sample", .integration_ms = 5, .averages = 1, .npix = NPIX,
					     .counts = counts, .temperature_c = NAN, .taken_at = (double)k };
		int64_t id;
		if (store_spectrum_add(st, &sp, &id, &err))
			_exit(3);
		/* Reported only after the commit returned. */
		if (write(wfd, &id, sizeof id) != sizeof id)
			_exit(4);
	}
}

static void test_sigkill_keeps_committed(void **state)
{
	(void)state;
	const char *seed_s = getenv("ACQ_SEED");
	unsigned seed = seed_s ? (unsigned)strtoul(seed_s, NULL, 10) : (unsigned)time(NULL);
	printf("seed %u (ACQ_SEED)\n", seed);
	srand(seed);
	char dir[64];
	assert_int_equal(ut_tmpdir_make(dir, sizeof dir, "test_store_crash"), 0);
	char path[300];
	snprintf(path, sizeof path, "%s/crash.db", dir);
	int64_t reported_total = 0;
	for (int round = 0; round < 5; round++) {
		int p[2];
		assert_int_equal(pipe(p), 0);
		pid_t pid = fork();
		assert_true(pid >= 0);
		if (pid == 0) {
			close(p[0]);
			child(path, p[1]);
		}
		close(p[1]);
		/* Wait for the first commit (slow under sanitizers), then kill at a random moment of the writing. */
		int64_t first;
		assert_int_equal(read(p[0], &first, sizeof first), sizeof first);
		usleep((useconds_t)(rand() % 150000));
		kill(pid, SIGKILL);
		int ws;
		waitpid(pid, &ws, 0);
		assert_true(WIFSIGNALED(ws) && WTERMSIG(ws) == SIGKILL);
		int64_t id = first, last = 0, n = 0;
		sqlite3 *db;
		assert_int_equal(sqlite3_open_v2(path, &db, SQLITE_OPEN_READONLY, NULL), SQLITE_OK);
		sqlite3_stmt *s;
		assert_int_equal(sqlite3_prepare_v2(db, "SELECT counts, npix FROM spectra WHERE id = ?", -1, &s, NULL),
				 SQLITE_OK);
		do {
			sqlite3_bind_int64(s, 1, id);
			assert_int_equal(sqlite3_step(s), SQLITE_ROW);
			assert_int_equal(sqlite3_column_int(s, 1), NPIX);
			assert_int_equal(sqlite3_column_bytes(s, 0), NPIX * 4);
			const float *c = sqlite3_column_blob(s, 0);
			for (int i = 0; i < NPIX; i += 97) /* the pattern the child wrote: k·10000 + pixel */
				assert_true(c[i] == c[0] + (float)i);
			sqlite3_reset(s);
			last = id;
			n++;
		} while (read(p[0], &id, sizeof id) == sizeof id);
		close(p[0]);
		sqlite3_finalize(s);
		assert_true(n > 0);
		assert_int_equal(sqlite3_prepare_v2(db, "PRAGMA integrity_check", -1, &s, NULL), SQLITE_OK);
		assert_int_equal(sqlite3_step(s), SQLITE_ROW);
		assert_string_equal((const char *)sqlite3_column_text(s, 0), "ok");
		sqlite3_finalize(s);
		sqlite3_close(db);
		printf("round %d: %lld spectra reported committed (last id %lld), all present\n", round, (long long)n,
		       (long long)last);
		reported_total += n;
	}
	assert_true(reported_total >= 5);
	/* The crashed database (its -wal still there) reopens through store_open and keeps everything. */
	struct store *st = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(store_open(path, &st, &err), 0);
	assert_true(store_spectrum_count(st, 0, &err) >= reported_total);
	store_close(st);
	assert_int_equal(ut_tmpdir_remove(dir), 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sigkill_keeps_committed),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
