/* store checkpoints off the loop: the WAL is copied back into the database (a checkpoint: database writes and
 * their fsyncs) on a thread of its own with its own connection, when a commit has grown the WAL past
 * STORE_CKPT_PAGES (SQLite's automatic checkpoint would run it inside that commit, on the loop, at 1000 pages; the
 * store's WAL hook, store_sync.c, tells it). PASSIVE, as the automatic one: it never waits for the writer, which
 * keeps appending meanwhile. */
#include <pthread.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/stall.h"
#include "daemon/store_int.h"

/* Pages in the WAL that start a checkpoint: SQLite's default. Smaller checkpoints (64 pages) were meant to share
 * the disk less with the next commit's fsync (a 637 ms checkpoint of ~1000 pages held a commit 340 ms in a session-8
 * soak, on the loop then). They no longer break test_disk_full (a halt's state and event are one transaction now),
 * but they did not measurably help either: test_store_ckpt (1100 commits, each waited durable), 3 runs each at load
 * ~10: 64 pages 543-851 checkpoints, 1.5-1.8 s of checkpoints in all, longest 28-59 ms, 2.4-3.2 s wall; 1000 pages
 * 107-238 checkpoints, 0.5-0.6 s, longest 19-40 ms, 2.8-4.0 s wall. And the commit's fsync is off the loop now
 * (store_sync.c): a checkpoint sharing the disk delays the sweep's next point, not the loop. STORE_CKPT_PAGES is in
 * store_int.h (store_sync.c's WAL hook checkpoints at it too when this thread could not start). */

struct store_ckpt {
	pthread_t thread;
	pthread_mutex_t mu;
	pthread_cond_t cv;
	bool due, quit;
	bool running; /* a checkpoint is under way (due cleared, not yet counted) */
	sqlite3 *db; /* the thread's connection */
	unsigned long runs;
	double seconds, max_s;
};

void store_ckpt_note(struct store_ckpt *c, int pages)
{
	if (pages < STORE_CKPT_PAGES)
		return;
	pthread_mutex_lock(&c->mu);
	c->due = true;
	pthread_cond_signal(&c->cv);
	pthread_mutex_unlock(&c->mu);
}

static void *ckpt_main(void *arg)
{
	struct store_ckpt *c = arg;
	pthread_mutex_lock(&c->mu);
	for (;;) {
		while (!c->due && !c->quit)
			pthread_cond_wait(&c->cv, &c->mu);
		if (c->quit)
			break;
		c->due = false;
		c->running = true;
		pthread_mutex_unlock(&c->mu);
		double t0 = stall_now();
		sqlite3_wal_checkpoint_v2(c->db, NULL, SQLITE_CHECKPOINT_PASSIVE, NULL, NULL);
		double s = stall_now() - t0;
		pthread_mutex_lock(&c->mu);
		c->running = false;
		c->runs++;
		c->seconds += s;
		if (s > c->max_s)
			c->max_s = s;
	}
	pthread_mutex_unlock(&c->mu);
	return NULL;
}

int store_ckpt_start(struct store *st, struct acq_err *err)
{
	struct store_ckpt *c = calloc(1, sizeof *c);
	if (!c)
		return acq_errf(err, ACQ_E_NOMEM, "%s: checkpoint thread: out of memory", st->path);
	if (sqlite3_open_v2(st->path, &c->db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOFOLLOW, NULL) != SQLITE_OK ||
	    sqlite3_exec(c->db, "PRAGMA synchronous = FULL", NULL, NULL, NULL) != SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: checkpoint thread's connection: %s", st->path,
			 c->db ? sqlite3_errmsg(c->db) : "out of memory");
		sqlite3_close(c->db);
		free(c);
		return -1;
	}
	sqlite3_busy_timeout(c->db, 2000);
	pthread_mutex_init(&c->mu, NULL);
	pthread_cond_init(&c->cv, NULL);
	int e = pthread_create(&c->thread, NULL, ckpt_main, c);
	if (e) {
		acq_errf(err, ACQ_E_IO, "%s: checkpoint thread: %s", st->path, strerror(e));
		pthread_mutex_destroy(&c->mu);
		pthread_cond_destroy(&c->cv);
		sqlite3_close(c->db);
		free(c);
		return -1;
	}
	st->ckpt = c;
	return 0;
}

void store_ckpt_stats(const struct store *st, unsigned long *runs, double *seconds, double *max_s)
{
	struct store_ckpt *c = st->ckpt;
	*runs = 0;
	*seconds = *max_s = 0;
	if (!c)
		return;
	pthread_mutex_lock(&c->mu);
	*runs = c->runs;
	*seconds = c->seconds;
	*max_s = c->max_s;
	pthread_mutex_unlock(&c->mu);
}

bool store_ckpt_idle(const struct store *st)
{
	struct store_ckpt *c = st->ckpt;
	if (!c)
		return true;
	pthread_mutex_lock(&c->mu);
	bool idle = !c->due && !c->running;
	pthread_mutex_unlock(&c->mu);
	return idle;
}

void store_ckpt_stop(struct store *st)
{
	struct store_ckpt *c = st->ckpt;
	if (!c)
		return;
	pthread_mutex_lock(&c->mu);
	c->quit = true;
	pthread_cond_signal(&c->cv);
	pthread_mutex_unlock(&c->mu);
	pthread_join(c->thread, NULL);
	sqlite3_close(c->db);
	pthread_mutex_destroy(&c->mu);
	pthread_cond_destroy(&c->cv);
	free(c);
	st->ckpt = NULL;
}
