/* store sync: commits made durable off the committing thread. The write connection runs synchronous=NORMAL: a
 * commit appends its WAL frames and returns without an fsync (a process crash keeps it: the frames are in the
 * kernel); this thread fsyncs the WAL after the commits (the WAL hook wakes it) and counts the commits now on
 * disk, so the daemon's loop hands a point's durability to it and hears back through an eventfd, never waiting.
 * WAL recovery keeps a prefix of the commits (checksummed frames, each over all before it): a power loss can
 * lose the latest commits not yet synced, never an older one while a newer stays. An fsync that failed is
 * sticky: nothing committed since is known durable (a later fsync's success proves nothing, the kernel may have
 * dropped the pages). */
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <sys/stat.h>
#include <unistd.h>

#include "daemon/store_int.h"

struct store_sync {
	pthread_t thread;
	pthread_mutex_t mu;
	pthread_cond_t cv, done; /* cv: work for the thread; done: durable moved or the sync failed */
	bool quit;
	uint64_t committed, durable; /* commit marks: made so far, on disk so far */
	int efd;                     /* readable when durable moved or the sync failed */
	int wal_fd;                  /* the thread's own descriptor of the WAL file (an fsync flushes the file) */
	char wal_path[4200], dir_path[4200];
	char failed[512];            /* the first fsync failure ("" = none) */
	store_sync_hook_fn hook;
	void *hook_ctx;
};

/* fsync the WAL (opened, or opened again when the file was replaced); its directory once per opening, so a new
 * WAL's name is on disk too. 0, or -1 with why. */
static int sync_wal(struct store_sync *s, store_sync_hook_fn hook, void *hook_ctx, char *why, size_t n)
{
	if (hook && hook(hook_ctx, why, n))
		return -1;
	struct stat a, b;
	if (s->wal_fd >= 0 && (fstat(s->wal_fd, &a) || stat(s->wal_path, &b) || a.st_ino != b.st_ino ||
			       a.st_dev != b.st_dev)) {
		close(s->wal_fd);
		s->wal_fd = -1;
	}
	bool fresh = s->wal_fd < 0;
	if (fresh && (s->wal_fd = open(s->wal_path, O_RDONLY | O_CLOEXEC)) < 0) {
		snprintf(why, n, "%s: open for fsync: %s", s->wal_path, strerror(errno));
		return -1;
	}
	if (fsync(s->wal_fd)) {
		snprintf(why, n, "%s: fsync: %s", s->wal_path, strerror(errno));
		return -1;
	}
	if (fresh) {
		int d = open(s->dir_path, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
		int rc = d < 0 ? -1 : fsync(d);
		if (rc && errno != EINVAL) /* some file systems cannot sync a directory: nothing to do there */
			snprintf(why, n, "%s: fsync of the directory: %s", s->dir_path, strerror(errno));
		if (d >= 0)
			close(d);
		if (rc && errno != EINVAL)
			return -1;
	}
	return 0;
}

static void *sync_main(void *arg)
{
	struct store_sync *s = arg;
	pthread_mutex_lock(&s->mu);
	for (;;) {
		while (!s->quit && (s->durable == s->committed || s->failed[0]))
			pthread_cond_wait(&s->cv, &s->mu);
		if (s->durable == s->committed || s->failed[0])
			break; /* quitting, nothing left to sync */
		uint64_t target = s->committed;
		store_sync_hook_fn hook = s->hook;
		void *hook_ctx = s->hook_ctx;
		pthread_mutex_unlock(&s->mu);
		char why[512] = "";
		int rc = sync_wal(s, hook, hook_ctx, why, sizeof why);
		pthread_mutex_lock(&s->mu);
		if (rc)
			snprintf(s->failed, sizeof s->failed, "%s", why[0] ? why : "fsync failed");
		else
			s->durable = target;
		pthread_cond_broadcast(&s->done);
		uint64_t one = 1;
		if (write(s->efd, &one, sizeof one) < 0) { /* full counter: the loop has a wake-up pending anyway */
		}
	}
	pthread_mutex_unlock(&s->mu);
	return NULL;
}

int store_sync_start(struct store *st, struct acq_err *err)
{
	struct store_sync *s = calloc(1, sizeof *s);
	if (!s)
		return acq_errf(err, ACQ_E_NOMEM, "%s: durability thread: out of memory", st->path);
	s->wal_fd = -1;
	snprintf(s->wal_path, sizeof s->wal_path, "%s-wal", st->path);
	snprintf(s->dir_path, sizeof s->dir_path, "%s", st->path);
	char *slash = strrchr(s->dir_path, '/');
	if (!slash)
		snprintf(s->dir_path, sizeof s->dir_path, ".");
	else if (slash == s->dir_path)
		slash[1] = 0;
	else
		*slash = 0;
	if ((s->efd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC)) < 0) {
		acq_errf(err, ACQ_E_IO, "%s: durability thread: eventfd: %s", st->path, strerror(errno));
		free(s);
		return -1;
	}
	pthread_mutex_init(&s->mu, NULL);
	pthread_cond_init(&s->cv, NULL);
	pthread_cond_init(&s->done, NULL);
	int e = pthread_create(&s->thread, NULL, sync_main, s);
	if (e) {
		acq_errf(err, ACQ_E_IO, "%s: durability thread: %s", st->path, strerror(e));
		pthread_mutex_destroy(&s->mu);
		pthread_cond_destroy(&s->cv);
		pthread_cond_destroy(&s->done);
		close(s->efd);
		free(s);
		return -1;
	}
	st->sync = s;
	return 0;
}

void store_sync_stop(struct store *st)
{
	struct store_sync *s = st->sync;
	if (!s)
		return;
	pthread_mutex_lock(&s->mu);
	s->quit = true; /* the thread syncs what is committed, then ends */
	pthread_cond_signal(&s->cv);
	pthread_mutex_unlock(&s->mu);
	pthread_join(s->thread, NULL);
	if (s->wal_fd >= 0)
		close(s->wal_fd);
	close(s->efd);
	pthread_mutex_destroy(&s->mu);
	pthread_cond_destroy(&s->cv);
	pthread_cond_destroy(&s->done);
	free(s);
	st->sync = NULL;
}

int store_wal_hook(void *arg, sqlite3 *db, const char *name, int pages)
{
	struct store *st = arg;
	struct store_sync *s = st->sync;
	if (s) {
		pthread_mutex_lock(&s->mu);
		st->mark = ++s->committed;
		pthread_cond_signal(&s->cv);
		pthread_mutex_unlock(&s->mu);
	}
	if (st->ckpt)
		store_ckpt_note(st->ckpt, pages);
	else if (pages >= STORE_CKPT_PAGES) /* SQLite's own automatic checkpoint, which a WAL hook replaces */
		sqlite3_wal_checkpoint(db, name);
	return SQLITE_OK;
}

uint64_t store_commit_mark(const struct store *st)
{
	return st->mark;
}

int store_durable(struct store *st, uint64_t mark, struct acq_err *err)
{
	struct store_sync *s = st->sync;
	if (!s)
		return 1; /* synchronous=FULL: every commit was on disk when it returned */
	pthread_mutex_lock(&s->mu);
	int r = s->failed[0] ? -1 : s->durable >= mark ? 1 : 0;
	if (r < 0)
		acq_errf(err, ACQ_E_IO, "%s (what was committed since may be lost at a power failure)", s->failed);
	pthread_mutex_unlock(&s->mu);
	return r;
}

int store_durable_wait(struct store *st, uint64_t mark, struct acq_err *err)
{
	struct store_sync *s = st->sync;
	if (!s)
		return 1;
	pthread_mutex_lock(&s->mu);
	while (!s->failed[0] && s->durable < mark)
		pthread_cond_wait(&s->done, &s->mu);
	pthread_mutex_unlock(&s->mu);
	return store_durable(st, mark, err);
}

int store_durable_fd(const struct store *st)
{
	return st->sync ? st->sync->efd : -1;
}

void store_durable_drain(struct store *st)
{
	uint64_t v;
	if (st->sync && read(st->sync->efd, &v, sizeof v) < 0) { /* EAGAIN: nothing new */
	}
}

void store_sync_set_hook(struct store *st, store_sync_hook_fn fn, void *ctx)
{
	struct store_sync *s = st->sync;
	if (!s)
		return;
	pthread_mutex_lock(&s->mu);
	s->hook = fn;
	s->hook_ctx = ctx;
	pthread_mutex_unlock(&s->mu);
}
