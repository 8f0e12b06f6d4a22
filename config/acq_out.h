/* acq_out: writing a file whose path a user gave. A regular or absent target is written to a temporary file
 * beside it, fsync'ed and renamed over it at commit, so a failed write leaves the old file as it was; an existing
 * file that is not regular (a device such as /dev/null, a FIFO, a terminal) is written in place, because renaming
 * over it would replace the device (as root, /dev/null once became a regular file); a directory is refused. */
#ifndef ACQ_OUT_H
#define ACQ_OUT_H

#include <stdio.h>

#include "config/acq_err.h"

enum {
	ACQ_OUT_STDIO = 1, /* also open a stdio stream (o->f) on the descriptor */
	ACQ_OUT_SEEK = 2,  /* the writer needs a regular file (it seeks, or opens o->name itself): refuse other targets */
};

struct acq_out {
	int fd;           /* the descriptor to write; -1 once committed or aborted */
	FILE *f;          /* with ACQ_OUT_STDIO: a stream on fd (write through it, not through fd) */
	char *path;       /* the target (a symbolic link resolved to the file it names) */
	char *tmp;        /* the temporary file beside the target, NULL when written in place */
	const char *name; /* the file being written: tmp, or path in place (for libraries that open by name) */
};

/* Open path for writing as described above (flags: ACQ_OUT_*). 0 with o ready, or -1 with err naming the path
 * (a directory, a non-regular target with ACQ_OUT_SEEK, a missing folder, no permission). */
int acq_out_open(struct acq_out *o, const char *path, int flags, struct acq_err *err);
/* Finish: flush and close, then (temporary) fsync and rename over the target. 0, or -1 with err (the temporary
 * file removed, the old target untouched). */
int acq_out_commit(struct acq_out *o, struct acq_err *err);
/* Give up: close, remove the temporary file (the target keeps its old content). Idempotent. */
void acq_out_abort(struct acq_out *o);

#endif
