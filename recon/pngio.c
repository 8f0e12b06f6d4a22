/* pngio: atomic PNG output of a cairo image surface, shared by plot and render. */
#include "recon/pngio.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

struct sink {
	int fd;
	int err; /* errno of the first failed write, 0 if none */
};

static cairo_status_t sink_write(void *closure, const unsigned char *data, unsigned int length)
{
	struct sink *s = closure;
	while (length > 0) {
		ssize_t w = write(s->fd, data, length);
		if (w < 0 && errno == EINTR)
			continue;
		if (w <= 0) {
			s->err = w < 0 ? errno : EIO;
			return CAIRO_STATUS_WRITE_ERROR;
		}
		data += w;
		length -= (unsigned int)w;
	}
	return CAIRO_STATUS_SUCCESS;
}

int pngio_write_surface(cairo_surface_t *surface, const char *path, struct acq_err *err)
{
	if (!surface || !path || !*path)
		return acq_errf(err, ACQ_E_INVAL, "png: no surface or no path");
	if (cairo_surface_status(surface) != CAIRO_STATUS_SUCCESS)
		return acq_errf(err, ACQ_E_NOMEM, "png: %s: drawing failed: %s", path,
				cairo_status_to_string(cairo_surface_status(surface)));
	size_t pl = strlen(path);
	char *tmp = malloc(pl + 16);
	if (!tmp)
		return acq_errf(err, ACQ_E_NOMEM, "png: out of memory");
	memcpy(tmp, path, pl);
	memcpy(tmp + pl, ".tmp.XXXXXX", 12);
	struct sink s = { .fd = mkstemp(tmp), .err = 0 };
	if (s.fd < 0) {
		acq_errf(err, ACQ_E_IO, "png: cannot create %s: %s", tmp, strerror(errno));
		free(tmp);
		return -1;
	}
	int rc = -1;
	cairo_status_t st = cairo_surface_write_to_png_stream(surface, sink_write, &s);
	if (st != CAIRO_STATUS_SUCCESS) {
		acq_errf(err, ACQ_E_IO, "png: writing %s: %s", tmp, s.err ? strerror(s.err) : cairo_status_to_string(st));
		goto out;
	}
	if (fchmod(s.fd, 0644) != 0 || fsync(s.fd) != 0) {
		acq_errf(err, ACQ_E_IO, "png: syncing %s: %s", tmp, strerror(errno));
		goto out;
	}
	int fd = s.fd;
	s.fd = -1;
	if (close(fd) != 0) {
		acq_errf(err, ACQ_E_IO, "png: closing %s: %s", tmp, strerror(errno));
		goto out;
	}
	if (rename(tmp, path) != 0) {
		acq_errf(err, ACQ_E_IO, "png: renaming %s to %s: %s", tmp, path, strerror(errno));
		goto out;
	}
	rc = 0;
out:
	if (s.fd >= 0)
		close(s.fd);
	if (rc != 0)
		unlink(tmp);
	free(tmp);
	return rc;
}
