/* acq_file: reading a whole file whose path a user gave (a configuration, a plan, a CSV table, a model) into
 * memory, with a size limit and errors that name the path. */
#ifndef ACQ_FILE_H
#define ACQ_FILE_H

#include <stddef.h>

#include "config/acq_err.h"

enum {
	ACQ_FILE_STDIN = 1, /* the path "-" reads standard input (named "standard input" in errors) */
};

/* Read path (flags: ACQ_FILE_*) whole into a NUL-terminated heap buffer *out (free()); *len (if len is not NULL)
 * gets its bytes without the NUL (NUL bytes inside are kept). At most max bytes. 0, or -1 with *out NULL and err
 * naming the path: ACQ_E_NOTFOUND (no such file), ACQ_E_IO (cannot open or read, e.g. a directory), ACQ_E_RANGE
 * (larger than max), ACQ_E_NOMEM. */
int acq_file_read(const char *path, size_t max, int flags, char **out, size_t *len, struct acq_err *err);

#endif
