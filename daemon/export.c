/* export: the `export` command — a sweep's calibrated samples as CSV, written by a worker thread with its own
 * read-only database connection (the event loop never waits for it) either into a socket whose other end is
 * passed to the client (any size, memory bounded by the socket buffer) or into a NEW file of the daemon's
 * export folder (O_EXCL: nothing existing is ever overwritten; plain names only, so the database and its
 * -wal/-shm/-journal can never be reached). format=nexus: the whole sweep as NeXus/HDF5 (daemon/nexus.md);
 * HDF5 needs a seekable file, so the thread writes it to a hidden temporary file of the export folder, which
 * then becomes the NEW file, or is opened read-only, unlinked and its descriptor passed once complete (the
 * client copies it where it likes, as the operator). See export.h. */
#include "daemon/export.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdbool.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/time.h>
#include <unistd.h>

#include "daemon/app.h"
#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/nexus.h"
#include "daemon/store.h"

#define EXPORT_MAX_JOBS 2          /* exports running at once; more are refused (state), not queued */
#define EXPORT_STALL_S 30          /* a client that reads nothing for this long loses its stream */
#define EXPORT_HEADER_LINES 2      /* the comment line and the column names */

struct export_job {
	struct app *app;
	uint64_t serial;
	json_t *id;
	int64_t sweep;
	int rows_expected;
	char db[4096];
	char path[4096];          /* file mode: the new file; "" for a stream */
	int out;                  /* the thread's end */
	int note[2];              /* the thread writes one byte to note[1] when it is done */
	pthread_t th;
	int rc, nrows;
	long long bytes;
	struct acq_err err;
	bool nexus;               /* format=nexus */
	char tmp[4096];           /* nexus: the temporary file in the export folder */
	int done_fd;              /* nexus stream: the finished file, read-only, unlinked (-1 otherwise) */
	struct nexus_stats ns;
};

static atomic_int running;
static atomic_ullong nexus_seq; /* names the temporary files */
static atomic_bool nexus_swept; /* the export folder's stale temporary files removed (once per start) */
/* One NeXus file at a time: Debian's libhdf5 is built thread-safe (one global lock), but a build that is not
 * must never see two threads; the exports queue here at no cost (the library would serialise them anyway). */
static pthread_mutex_t nexus_lock = PTHREAD_MUTEX_INITIALIZER;

/* NeXus: the file in j->tmp, then renamed over our new (O_EXCL, empty) file j->path, or opened read-only and
 * unlinked for the client. */
static void nexus_job(struct export_job *j)
{
	pthread_mutex_lock(&nexus_lock);
	j->rc = nexus_export(j->db, j->sweep, j->tmp, &j->ns, &j->err);
	pthread_mutex_unlock(&nexus_lock);
	struct stat sb;
	if (!j->rc && j->path[0]) {
		if (stat(j->tmp, &sb) || rename(j->tmp, j->path))
			j->rc = acq_errf(&j->err, ACQ_E_IO, "%s: %s", j->path, strerror(errno));
	} else if (!j->rc) {
		j->done_fd = open(j->tmp, O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
		if (j->done_fd < 0 || fstat(j->done_fd, &sb))
			j->rc = acq_errf(&j->err, ACQ_E_IO, "%s: %s", j->tmp, strerror(errno));
	}
	if (!j->rc)
		j->bytes = (long long)sb.st_size;
	unlink(j->tmp); /* gone after the rename; else the passed descriptor keeps the data */
}

static void *job_thread(void *arg)
{
	struct export_job *j = arg;
	struct store *st = NULL;
	FILE *f = NULL;
	if (j->nexus) {
		nexus_job(j);
		goto note;
	}
	j->rc = store_open_reader(j->db, &st, &j->err);
	if (!j->rc && !(f = fdopen(j->out, "w")))
		j->rc = acq_errf(&j->err, ACQ_E_IO, "fdopen: %s", strerror(errno));
	if (!j->rc) {
		j->out = -1; /* f owns it */
		j->rc = store_export_csv_n(st, j->sweep, j->rows_expected, f, &j->nrows, &j->err);
		j->bytes = ftell(f);
	}
	if (f && fclose(f) && !j->rc)
		j->rc = acq_errf(&j->err, ACQ_E_IO, "writing the CSV: %s", strerror(errno));
	if (j->out >= 0)
		close(j->out);
	j->out = -1;
	store_close(st);
note:;
	char b = 1;
	while (write(j->note[1], &b, 1) < 0 && errno == EINTR)
		;
	return NULL;
}

static void job_free(struct export_job *j)
{
	if (j->note[0] >= 0)
		close(j->note[0]);
	if (j->note[1] >= 0)
		close(j->note[1]);
	if (j->out >= 0)
		close(j->out);
	if (j->done_fd >= 0)
		close(j->done_fd);
	json_decref(j->id);
	free(j);
}

/* The thread is done: join it, reply (file mode) or log (stream mode). */
static void job_done(struct loop *lp, int fd, short revents, void *arg)
{
	(void)revents;
	struct export_job *j = arg;
	loop_fd_del(lp, fd);
	pthread_join(j->th, NULL);
	atomic_fetch_sub(&running, 1);
	struct app *app = j->app;
	if (j->nexus && !j->rc) {
		json_t *r = json_pack("{s:I,s:s,s:I,s:I,s:I,s:i,s:i}", "sweep", (json_int_t)j->sweep, "format", "nexus",
				      "bytes", (json_int_t)j->bytes, "points", (json_int_t)j->ns.points, "calibrated",
				      (json_int_t)j->ns.calibrated, "wavelengths", j->ns.nwl, "pixels", j->ns.npix);
		if (j->path[0]) {
			log_msg(LOG_INFO, "sweep %lld exported as NeXus to %s (%lld bytes)", (long long)j->sweep, j->path,
				j->bytes);
			json_object_set_new(r, "path", json_string(j->path));
			server_reply(app->srv, j->serial, j->id, r);
		} else {
			json_object_set_new(r, "stream", json_true());
			int nfd = j->done_fd;
			j->done_fd = -1; /* consumed by server_reply_fd */
			if (server_reply_fd(app->srv, j->serial, j->id, r, nfd))
				log_msg(LOG_INFO, "NeXus export of sweep %lld: client %llu gone before its file",
					(long long)j->sweep, (unsigned long long)j->serial);
		}
	} else if (j->nexus && !j->path[0]) {
		server_reply_error(app->srv, j->serial, j->id, proto_code_of(&j->err), j->err.msg);
	} else if (j->path[0]) {
		if (j->rc) {
			unlink(j->path); /* our own new file, incomplete */
			server_reply_error(app->srv, j->serial, j->id, proto_code_of(&j->err), j->err.msg);
		} else {
			log_msg(LOG_INFO, "sweep %lld exported to %s (%d rows)", (long long)j->sweep, j->path, j->nrows);
			server_reply(app->srv, j->serial, j->id,
				     json_pack("{s:I,s:i,s:s,s:I}", "sweep", (json_int_t)j->sweep, "rows", j->nrows, "path",
					       j->path, "bytes", (json_int_t)j->bytes));
		}
	} else if (j->rc) {
		log_msg(LOG_WARNING, "export of sweep %lld to client %llu stopped after %d rows: %s", (long long)j->sweep,
			(unsigned long long)j->serial, j->nrows, j->err.msg);
	}
	job_free(j);
}

int export_file_name_ok(const char *name, const char *db_path, struct acq_err *err)
{
	size_t n = strlen(name);
	if (n == 0 || n > 200 || name[0] == '.' || name[0] == '-')
		return acq_errf(err, ACQ_E_INVAL, "path \"%s\": expected a plain file name (1-200 characters, not "
				"starting with '.' or '-') for the export folder", name);
	for (size_t i = 0; i < n; i++) {
		char c = name[i];
		if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' || c == '_' ||
		      c == '-'))
			return acq_errf(err, ACQ_E_INVAL, "path \"%s\": only letters, digits, '.', '_' and '-' are allowed "
					"(a name in the export folder, no directories)", name);
	}
	const char *base = strrchr(db_path, '/');
	base = base ? base + 1 : db_path;
	static const char *const sqlite_suffixes[] = { "-wal", "-shm", "-journal", NULL };
	size_t bl = strlen(base);
	if (!strncmp(name, base, bl) && (!name[bl] || name[bl] == '-'))
		return acq_errf(err, ACQ_E_INVAL, "path \"%s\": the database's name is reserved", name);
	for (int i = 0; sqlite_suffixes[i]; i++) {
		size_t sl = strlen(sqlite_suffixes[i]);
		if (n >= sl && !strcmp(name + n - sl, sqlite_suffixes[i]))
			return acq_errf(err, ACQ_E_INVAL, "path \"%s\": names ending in %s are reserved for SQLite", name,
					sqlite_suffixes[i]);
	}
	return 0;
}

/* <state_dir>/export into dir (created 0750 if missing). */
static int export_dir(const struct conf *c, char *dir, size_t cap, struct acq_err *err)
{
	snprintf(dir, cap, "%s/export", c->d.state_dir);
	if (mkdir(dir, 0750) && errno != EEXIST)
		return acq_errf(err, ACQ_E_IO, "%s: %s", dir, strerror(errno));
	return 0;
}

/* The hidden temporary files (.nexus-*) that a daemon stopped in the middle of a NeXus export left in the
 * export folder dir: removed at the first NeXus export after a start (no request can name them). */
static void sweep_stale_nexus(const char *dir)
{
	bool was = false;
	if (!atomic_compare_exchange_strong(&nexus_swept, &was, true))
		return;
	DIR *d = opendir(dir);
	if (!d)
		return;
	struct dirent *e;
	int n = 0;
	while ((e = readdir(d)))
		if (!strncmp(e->d_name, ".nexus-", 7) && !unlinkat(dirfd(d), e->d_name, 0))
			n++;
	closedir(d);
	if (n)
		log_msg(LOG_NOTICE, "%s: removed %d temporary file(s) of an interrupted NeXus export", dir, n);
}

/* A new file name in <state_dir>/export (created 0750 if missing): O_EXCL, never following a link. */
static int open_new_export(const struct conf *c, const char *name, char *path, size_t cap, struct acq_err *err)
{
	char dir[4096];
	if (export_dir(c, dir, sizeof dir, err))
		return -1;
	int dfd = open(dir, O_PATH | O_DIRECTORY | O_NOFOLLOW | O_CLOEXEC);
	if (dfd < 0)
		return acq_errf(err, ACQ_E_IO, "%s: %s (must be a directory, not a link)", dir, strerror(errno));
	int fd = openat(dfd, name, O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0640);
	int e = errno;
	close(dfd);
	snprintf(path, cap, "%s/%s", dir, name);
	if (fd < 0)
		return acq_errf(err, e == EEXIST ? ACQ_E_STATE : ACQ_E_IO, "%s: %s%s", path, strerror(e),
				e == EEXIST ? " (exports never overwrite: choose another name)" : "");
	return fd;
}

void export_handle(struct app *app, const struct srv_peer *peer, struct proto_req *req)
{
	struct acq_err err = { 0 };
	json_t *sv = json_object_get(req->root, "sweep");
	int64_t sweep = sv ? (int64_t)json_integer_value(sv) : 0;
	const char *name = json_string_value(json_object_get(req->root, "path"));
	const char *format = json_string_value(json_object_get(req->root, "format"));
	bool nexus = format && !strcmp(format, "nexus");
	if (format && !nexus && strcmp(format, "csv")) {
		acq_errf(&err, ACQ_E_INVAL, "format \"%s\": expected csv or nexus", format);
		goto fail;
	}
	if (name && peer->role < PROTO_CONTROLLER) {
		server_reply_error(app->srv, peer->serial, req->id, PROTO_E_FORBIDDEN,
				   "export to a daemon-side file needs a controller; observers get the stream");
		return;
	}
	if (!name && peer->tcp) {
		server_reply_error(app->srv, peer->serial, req->id, PROTO_E_UNAVAILABLE,
				   "export streams over the Unix socket only (a TCP connection cannot carry the stream)");
		return;
	}
	if (name && export_file_name_ok(name, app->conf->d.database, &err))
		goto fail;
	int64_t rows = store_calibrated_count(app->store, sweep, &err);
	if (rows < 0)
		goto fail;
	if (rows == 0 && !nexus) {
		acq_errf(&err, ACQ_E_STATE, "sweep %lld has no calibrated samples", (long long)sweep);
		goto fail;
	}
	if (atomic_load(&running) >= EXPORT_MAX_JOBS) {
		acq_errf(&err, ACQ_E_STATE, "%d exports are running: try again when one is done", EXPORT_MAX_JOBS);
		goto fail;
	}
	struct export_job *j = calloc(1, sizeof *j);
	if (!j) {
		acq_errf(&err, ACQ_E_NOMEM, "out of memory");
		goto fail;
	}
	*j = (struct export_job){ .app = app, .serial = peer->serial, .id = json_incref(req->id), .sweep = sweep,
				  .rows_expected = (int)rows, .out = -1, .note = { -1, -1 }, .nexus = nexus,
				  .done_fd = -1 };
	snprintf(j->db, sizeof j->db, "%s", app->db_path[0] ? app->db_path : app->conf->d.database);
	int client_end = -1;
	if (pipe2(j->note, O_CLOEXEC)) {
		acq_errf(&err, ACQ_E_IO, "pipe: %s", strerror(errno));
		goto fail_job;
	}
	if (nexus) {
		char dir[4096];
		if (export_dir(app->conf, dir, sizeof dir, &err))
			goto fail_job;
		sweep_stale_nexus(dir);
		/* a hidden name: export names never start with '.', so no request can reach it */
		snprintf(j->tmp, sizeof j->tmp, "%s/.nexus-%llu.nxs", dir, atomic_fetch_add(&nexus_seq, 1) + 1);
		if (name && (j->out = open_new_export(app->conf, name, j->path, sizeof j->path, &err)) < 0)
			goto fail_job;
	} else if (name) {
		if ((j->out = open_new_export(app->conf, name, j->path, sizeof j->path, &err)) < 0)
			goto fail_job;
	} else {
		int sv2[2];
		if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv2)) {
			acq_errf(&err, ACQ_E_IO, "socketpair: %s", strerror(errno));
			goto fail_job;
		}
		struct timeval tv = { .tv_sec = EXPORT_STALL_S };
		setsockopt(sv2[0], SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
		shutdown(sv2[1], SHUT_WR);
		j->out = sv2[0];
		client_end = sv2[1];
	}
	if (loop_fd_add(app->lp, j->note[0], POLLIN, job_done, j, &err))
		goto fail_job;
	if (pthread_create(&j->th, NULL, job_thread, j)) {
		loop_fd_del(app->lp, j->note[0]);
		acq_errf(&err, ACQ_E_NOMEM, "cannot start the export thread");
		goto fail_job;
	}
	atomic_fetch_add(&running, 1);
	if (client_end >= 0 &&
	    server_reply_fd(app->srv, peer->serial, req->id,
			    json_pack("{s:I,s:I,s:i,s:b}", "sweep", (json_int_t)sweep, "rows", (json_int_t)rows,
				      "header_lines", EXPORT_HEADER_LINES, "stream", 1),
			    client_end))
		/* the client is gone: the thread's writes fail and it ends by itself */
		log_msg(LOG_INFO, "export of sweep %lld: client %llu gone before its stream", (long long)sweep,
			(unsigned long long)peer->serial);
	return;
fail_job:
	if (j->path[0] && j->out >= 0)
		unlink(j->path);
	if (client_end >= 0)
		close(client_end);
	job_free(j);
fail:
	server_reply_error(app->srv, peer->serial, req->id, proto_code_of(&err), err.msg);
}
