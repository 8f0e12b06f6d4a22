/* acq_out: one writer for user-given output paths (temporary file + fsync + rename; devices and FIFOs in place;
 * directories refused). */
#include "config/acq_out.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static void out_reset(struct acq_out *o)
{
	free(o->path);
	free(o->tmp);
	memset(o, 0, sizeof *o);
	o->fd = -1;
}

int acq_out_open(struct acq_out *o, const char *path, int flags, struct acq_err *err)
{
	memset(o, 0, sizeof *o);
	o->fd = -1;
	if (!path || !*path)
		return acq_errf(err, ACQ_E_INVAL, "output: no path given");
	struct stat st;
	int exists = stat(path, &st) == 0;
	if (!exists && errno != ENOENT)
		return acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(errno));
	if (exists && S_ISDIR(st.st_mode))
		return acq_errf(err, ACQ_E_IO, "%s: is a directory, not a file to write", path);
	if (exists && !S_ISREG(st.st_mode) && (flags & ACQ_OUT_SEEK))
		return acq_errf(err, ACQ_E_IO, "%s: not a regular file (this output needs one: it is written by seeking)",
				path);
	/* a symbolic link to a file: write the file it names, and keep the link */
	struct stat lst;
	if (exists && lstat(path, &lst) == 0 && S_ISLNK(lst.st_mode))
		o->path = realpath(path, NULL);
	else
		o->path = strdup(path);
	if (!o->path) {
		int e = errno;
		out_reset(o);
		return acq_errf(err, e == ENOMEM ? ACQ_E_NOMEM : ACQ_E_IO, "%s: %s", path, strerror(e));
	}
	if (exists && !S_ISREG(st.st_mode)) { /* a device, FIFO or terminal: in place */
		o->fd = open(o->path, O_WRONLY | O_CLOEXEC | O_NOCTTY);
		if (o->fd < 0) {
			int e = errno;
			out_reset(o);
			return acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(e));
		}
		o->name = o->path;
	} else {
		size_t pl = strlen(o->path);
		o->tmp = malloc(pl + 16);
		if (!o->tmp) {
			out_reset(o);
			return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", path);
		}
		memcpy(o->tmp, o->path, pl);
		memcpy(o->tmp + pl, ".tmp.XXXXXX", 12);
		o->fd = mkostemp(o->tmp, O_CLOEXEC);
		if (o->fd < 0) {
			int e = errno;
			acq_errf(err, ACQ_E_IO, "%s: cannot create a temporary file beside it: %s", path, strerror(e));
			free(o->tmp);
			o->tmp = NULL;
			out_reset(o);
			return -1;
		}
		/* the old file's permissions, or those of a new file (0644: mkstemp's 0600 would hide the output) */
		if (fchmod(o->fd, exists ? (st.st_mode & 07777) : 0644) != 0) {
			int e = errno;
			acq_out_abort(o);
			return acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(e));
		}
		o->name = o->tmp;
	}
	if (flags & ACQ_OUT_STDIO) {
		o->f = fdopen(o->fd, "w");
		if (!o->f) {
			int e = errno;
			acq_out_abort(o);
			return acq_errf(err, ACQ_E_IO, "%s: %s", path, strerror(e));
		}
	}
	return 0;
}

int acq_out_commit(struct acq_out *o, struct acq_err *err)
{
	if (o->fd < 0) {
		out_reset(o);
		return acq_errf(err, ACQ_E_STATE, "output: not open");
	}
	int e = 0;
	errno = 0;
	if (o->f && (fflush(o->f) != 0 || ferror(o->f)))
		e = errno ? errno : EIO;
	if (!e && o->tmp && fsync(o->fd) != 0)
		e = errno;
	int c = o->f ? fclose(o->f) : close(o->fd);
	if (!e && c != 0)
		e = errno;
	o->f = NULL;
	o->fd = -1;
	if (!e && o->tmp && rename(o->tmp, o->path) != 0)
		e = errno;
	if (e) {
		if (o->tmp)
			unlink(o->tmp);
		acq_errf(err, ACQ_E_IO, "%s: write failed: %s", o->path, strerror(e));
		out_reset(o);
		return -1;
	}
	out_reset(o);
	return 0;
}

void acq_out_abort(struct acq_out *o)
{
	if (o->f)
		fclose(o->f);
	else if (o->fd >= 0)
		close(o->fd);
	if (o->tmp)
		unlink(o->tmp);
	out_reset(o);
}
