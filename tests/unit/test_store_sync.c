/* test_store_sync: a commit returns before its fsync, which the store's own thread runs (store_sync.c): while that
 * fsync is held (a test hook standing for a slow disk) the committed point is readable, not yet durable, and the
 * caller hears through store_durable_fd once it is; a failed fsync is reported and stays failed; close syncs what
 * is committed. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sqlite3.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>
#include "daemon/store.h"
#include "tests/unit/storefix.h"
#include "tests/unit/tmpdir.h"

/* The hook: counts its calls and holds each fsync until the test opens the gate (at most 5 s), or fails it. */
static struct gate {
	pthread_mutex_t mu;
	pthread_cond_t cv;
	bool open, fail;
	int entered;
} G = { PTHREAD_MUTEX_INITIALIZER, PTHREAD_COND_INITIALIZER, false, false, 0 };

static int gate_hook(void *ctx, char *why, size_t n)
{
	struct gate *g = ctx;
	struct timespec until;
	clock_gettime(CLOCK_REALTIME, &until);
	until.tv_sec += 5;
	pthread_mutex_lock(&g->mu);
	g->entered++;
	pthread_cond_broadcast(&g->cv);
	while (!g->open && pthread_cond_timedwait(&g->cv, &g->mu, &until) == 0) {
	}
	bool fail = g->fail;
	pthread_mutex_unlock(&g->mu);
	if (fail)
		snprintf(why, n, "injected I/O error");
	return fail ? -1 : 0;
}

static void gate_set(bool open, bool fail)
{
	pthread_mutex_lock(&G.mu);
	G.open = open;
	G.fail = fail;
	pthread_cond_broadcast(&G.cv);
	pthread_mutex_unlock(&G.mu);
}

/* Wait (at most 5 s) until the hook has been entered n times. */
static void gate_wait_entered(int n)
{
	struct timespec until;
	clock_gettime(CLOCK_REALTIME, &until);
	until.tv_sec += 5;
	pthread_mutex_lock(&G.mu);
	while (G.entered < n && pthread_cond_timedwait(&G.cv, &G.mu, &until) == 0) {
	}
	int e = G.entered;
	pthread_mutex_unlock(&G.mu);
	assert_true(e >= n);
}

static float counts[16];

/* One point of sweep sid committed in a group (a sample spectrum completing it). */
static void commit_point(struct store *st, int64_t sid)
{
	struct acq_err err = { 0 };
	int oi = -1;
	int64_t pid = 0;
	assert_int_equal(store_sweep_next_point(st, sid, &oi, &pid, &err), 0);
	struct store_spectrum sp = { .sweep_id = sid, .point_id = pid, .kind = "sample", .integration_ms = 10,
				     .averages = 1, .npix = 16, .counts = counts, .temperature_c = NAN, .taken_at = 1,
				     .completes_point = true, .theta_i = NAN, .phi_i = NAN, .theta_o = NAN,
				     .phi_o = NAN, .laser_theta = NAN, .detector_theta = NAN, .detector_phi = NAN };
	assert_int_equal(store_group_begin(st, &err), 0);
	assert_int_equal(store_spectrum_add(st, &sp, NULL, &err), 0);
	assert_int_equal(store_group_end(st, 0, &err), 0);
}

/* As the daemon's loop: wait for store_durable_fd to be readable, drain it, ask again, until mark is durable or
 * failed (at most 5 s in all); store_durable's answer. */
static int wait_durable(struct store *st, uint64_t mark, struct acq_err *err)
{
	struct pollfd p = { .fd = store_durable_fd(st), .events = POLLIN };
	assert_true(p.fd >= 0);
	int r;
	for (int i = 0; (r = store_durable(st, mark, err)) == 0; i++) {
		assert_true(i < 100);
		assert_int_equal(poll(&p, 1, 5000), 1);
		store_durable_drain(st);
	}
	return r;
}

/* A new store in a new folder (dir[256], path[300]) with a sweep of 3 points (*sid), its commits so far on disk,
 * and the gate's hook on it: shut and failing as asked, its count of calls at 0. */
static struct store *open_store(char *dir, char *path, const char *file, int64_t *sid, bool open, bool fail)
{
	assert_int_equal(ut_tmpdir_make(dir, 256, "acq-test-sync"), 0);
	struct store *st = ut_store_new(path, 300, dir, file);
	*sid = ut_sweep_create(st, 3, "sync", "name: sync");
	struct acq_err err = { 0 };
	gate_set(true, false);
	assert_int_equal(store_durable_wait(st, store_commit_mark(st), &err), 1);
	G.entered = 0;
	gate_set(open, fail);
	store_sync_set_hook(st, gate_hook, &G);
	return st;
}

static void test_commit_before_fsync(void **state)
{
	(void)state;
	char dir[256], path[300];
	int64_t sid = 0;
	struct store *st = open_store(dir, path, "s.db", &sid, false, false);
	assert_null(store_degraded(st)); /* both threads run */
	struct acq_err err = { 0 };
	/* The commit returns while its fsync is held on the store's thread: with the fsync in the commit, this
	 * thread would sit in the hook until the gate's 5 s ran out and find the point durable below. */
	commit_point(st, sid);
	uint64_t mark = store_commit_mark(st);
	assert_true(mark > 0);
	gate_wait_entered(1);
	assert_int_equal(store_durable(st, mark, &err), 0);
	/* committed: another connection reads the point done already */
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM points WHERE state = 'done'"), 1);
	gate_set(true, false);
	assert_int_equal(wait_durable(st, mark, &err), 1);
	/* An older mark is durable with it; a second point is synced after its own commit. */
	assert_int_equal(store_durable(st, mark - 1, &err), 1);
	commit_point(st, sid);
	assert_true(store_commit_mark(st) == mark + 1);
	assert_int_equal(store_durable_wait(st, mark + 1, &err), 1);
	assert_true(G.entered >= 2);
	store_close(st);
	ut_tmpdir_remove(dir);
}

static void test_fsync_failure_sticks(void **state)
{
	(void)state;
	char dir[256], path[300];
	int64_t sid = 0;
	struct store *st = open_store(dir, path, "f.db", &sid, true, true); /* every fsync fails */
	struct acq_err err = { 0 };
	commit_point(st, sid);
	uint64_t mark = store_commit_mark(st);
	assert_int_equal(wait_durable(st, mark, &err), -1);
	assert_int_equal(err.code, ACQ_E_IO);
	assert_non_null(strstr(err.msg, "injected I/O error"));
	/* Later fsyncs would succeed, but nothing since is known on disk: still failed, at once (no wait). */
	store_sync_set_hook(st, NULL, NULL);
	commit_point(st, sid);
	usleep(200000); /* time for a (wrongly) trusted fsync of the new commit; the answer must not change */
	memset(&err, 0, sizeof err);
	assert_int_equal(store_durable_wait(st, store_commit_mark(st), &err), -1);
	assert_non_null(strstr(err.msg, "injected I/O error"));
	store_close(st);
	ut_tmpdir_remove(dir);
}

static void *open_gate_later(void *arg)
{
	(void)arg;
	usleep(100000);
	gate_set(true, false);
	return NULL;
}

/* Closing lets the thread sync every commit made: a commit queued behind a held fsync is synced before the thread
 * ends (the hook entered for it too). */
static void test_close_syncs(void **state)
{
	(void)state;
	char dir[256], path[300];
	int64_t sid = 0;
	struct store *st = open_store(dir, path, "c.db", &sid, false, false);
	commit_point(st, sid);
	gate_wait_entered(1); /* the first commit's fsync is held */
	commit_point(st, sid);  /* the second waits behind it */
	pthread_t t;
	assert_int_equal(pthread_create(&t, NULL, open_gate_later, NULL), 0);
	store_close(st);
	pthread_join(t, NULL);
	assert_int_equal(G.entered, 2);
	assert_int_equal(ut_sql_count(path, "SELECT count(*) FROM points WHERE state = 'done'"), 2);
	ut_tmpdir_remove(dir);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_commit_before_fsync),
		cmocka_unit_test(test_fsync_failure_sticks),
		cmocka_unit_test(test_close_syncs),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
