/* store_int: what the files of the store module share (daemon/store*.c only; users include store.h): the
 * handle, its prepared statements, and the SQLite helpers every file uses. */
#ifndef DAEMON_STORE_INT_H
#define DAEMON_STORE_INT_H

#include <sqlite3.h>
#include <stdbool.h>
#include <stdint.h>

#include "daemon/store.h"

/* Pages in the WAL that start a checkpoint (SQLite's default; store_ckpt.c says why not fewer). */
#define STORE_CKPT_PAGES 1000

/* Statements prepared once at store_open() (hot paths: a spectrum, its point's completion, an event). */
enum { ST_SPECTRUM, ST_POINT_DONE, ST_EVENT, ST__COUNT };

struct store {
	sqlite3 *db;
	char *path;
	sqlite3_stmt *st[ST__COUNT];
	bool reader;  /* store_open_reader(): read-only, no statements prepared, no checkpoint at close */
	struct store_ckpt *ckpt; /* the WAL's checkpoints off the committing thread (store_ckpt.c) */
	struct store_sync *sync; /* the commits' fsyncs off the committing thread (store_sync.c) */
	uint64_t mark;           /* the latest commit's mark (store_commit_mark) */
	char degraded[1200];     /* store_degraded(): what could not start ("" = nothing) */
	bool group, group_failed; /* store_group_begin(): the writes join its transaction; one of them failed */
	unsigned long completed_gen; /* sweeps set completed since the store was opened (store_completed_gen) */
};

/* err = "<path>: <what>: <SQLite's message>" (ACQ_E_IO); returns -1. */
int store_db_err(struct store *st, struct acq_err *err, const char *what);
/* Run SQL text (several statements allowed). 0 or -1 with err (err may be NULL). */
int store_exec(struct store *st, const char *sql, struct acq_err *err);
/* BEGIN IMMEDIATE, or nothing inside a group (store_group.c: the write joins the group's transaction). 0 or -1. */
int store_tx_begin(struct store *st, struct acq_err *err);
/* End the transaction begun with BEGIN (inside a group: only note a failure, the group ends it): COMMIT when rc is 0, then *id = row (id may be NULL); else, or when the
 * commit fails, ROLLBACK (err keeps the first failure's message). 0 or -1. */
int store_tx_end(struct store *st, int rc, int64_t row, int64_t *id, struct acq_err *err);
/* Prepare one statement; NULL with err. */
sqlite3_stmt *store_prep(struct store *st, const char *sql, struct acq_err *err);
/* First column of the first row of sql (a PRAGMA or a SELECT) on db; *ok = 0 when there is none. */
int64_t store_pragma_int(sqlite3 *db, const char *sql, int *ok);
/* Bind an id (<= 0: NULL), a real (non-finite: NULL) or a text (NULL: NULL; not copied). */
void store_bind_id(sqlite3_stmt *s, int i, int64_t v);
void store_bind_real(sqlite3_stmt *s, int i, double v);
void store_bind_text(sqlite3_stmt *s, int i, const char *v);
/* Step a statement expecting DONE, then reset it and clear its bindings (a constraint: ACQ_E_INVAL). 0 or -1. */
int store_step_done(struct store *st, sqlite3_stmt *s, struct acq_err *err, const char *what);
/* store_step_done() then finalize. 0 or -1. */
int store_run1(struct store *st, sqlite3_stmt *s, struct acq_err *err, const char *what);
/* Whether v is one of the NULL-terminated list. */
bool store_in_list(const char *v, const char *const *list);
/* Rows of a prepared statement as a JSON array of objects named by column (blobs: their size); finalizes s.
 * NULL with err. */
json_t *store_rows_json(struct store *st, sqlite3_stmt *s, struct acq_err *err);
/* Insert npts planned points of sweep_id (inside the caller's transaction; store_sweep.c). 0 or -1. */
int store_points_insert(struct store *st, int64_t sweep_id, const struct store_point_new *pts, int npts,
			struct acq_err *err);
/* Bring an open read-write store's schema to STORE_SCHEMA_VERSION (store_migrate.c): a new database from
 * daemon/schema.sql, an older one step by step, each step one transaction. 0 or -1. */
int store_migrate(struct store *st, struct acq_err *err);
/* Take over the WAL's checkpoints of a read-write store: a thread of its own runs them (store_ckpt.c), told by
 * store_wal_hook. 0, or -1 with err (nothing started: SQLite's own checkpoints stay). */
int store_ckpt_start(struct store *st, struct acq_err *err);
/* A commit left pages in the WAL: past the threshold, the thread checkpoints. */
void store_ckpt_note(struct store_ckpt *c, int pages);
/* Stop them (before the store's connection closes). */
void store_ckpt_stop(struct store *st);
/* Take over the commits' fsyncs of a read-write store (store_sync.c): a thread of its own runs them, told by
 * store_wal_hook. 0, or -1 with err (nothing started: the caller keeps synchronous=FULL). */
int store_sync_start(struct store *st, struct acq_err *err);
/* Stop it, after it synced every commit made (before the store's connection closes). */
void store_sync_stop(struct store *st);
/* The WAL hook of the write connection (arg: the store): after every commit, tell the sync and checkpoint
 * threads (without a checkpoint thread: SQLite's own automatic checkpoint). SQLITE_OK. */
int store_wal_hook(void *arg, sqlite3 *db, const char *name, int pages);

#endif
