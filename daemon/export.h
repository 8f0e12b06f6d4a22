/* export: the `export` command — a sweep's CSV streamed to the client over a passed socket, or written as a
 * new file of the daemon's export folder, by a worker thread (see export.c). */
#ifndef EXPORT_H
#define EXPORT_H

#include "config/acq_err.h"
#include "daemon/server.h"

struct app;

/* Handle an authorised `export` request: replies now (stream, with the descriptor) or when the file is written. */
void export_handle(struct app *app, const struct srv_peer *peer, struct proto_req *req);
/* 0 if name may be created in the export folder: a plain name of letters, digits, '.', '_', '-', not starting
 * with '.' or '-', not the database's name (db_path's base) nor any name ending in -wal, -shm or -journal. */
int export_file_name_ok(const char *name, const char *db_path, struct acq_err *err);

#endif
