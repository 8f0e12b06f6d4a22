/* pngio: atomic file output (temp file, fsync, rename): PNG of a cairo surface, or a byte buffer. */
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

/* Write through emit() into a temporary file beside path, fsync, rename; 0, or -1 with err. */
static int write_atomic(const char *path, const char *what, int (*emit)(struct sink *s, void *ctx), void *ctx,
			struct acq_err *err)
{
	size_t pl = strlen(path);
	char *tmp = malloc(pl + 16);
	if (!tmp)
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", what);
	memcpy(tmp, path, pl);
	memcpy(tmp + pl, ".tmp.XXXXXX", 12);
	struct sink s = { .fd = mkstemp(tmp), .err = 0 };
	if (s.fd < 0) {
		acq_errf(err, ACQ_E_IO, "%s: cannot create %s: %s", what, tmp, strerror(errno));
		free(tmp);
		return -1;
	}
	int rc = -1;
	if (emit(&s, ctx) != 0) {
		acq_errf(err, ACQ_E_IO, "%s: writing %s: %s", what, tmp, s.err ? strerror(s.err) : "encoder failed");
		goto out;
	}
	if (fchmod(s.fd, 0644) != 0 || fsync(s.fd) != 0) {
		acq_errf(err, ACQ_E_IO, "%s: syncing %s: %s", what, tmp, strerror(errno));
		goto out;
	}
	int fd = s.fd;
	s.fd = -1;
	if (close(fd) != 0) {
		acq_errf(err, ACQ_E_IO, "%s: closing %s: %s", what, tmp, strerror(errno));
		goto out;
	}
	if (rename(tmp, path) != 0) {
		acq_errf(err, ACQ_E_IO, "%s: renaming %s to %s: %s", what, tmp, path, strerror(errno));
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

static int emit_png(struct sink *s, void *ctx)
{
	return cairo_surface_write_to_png_stream(ctx, sink_write, s) == CAIRO_STATUS_SUCCESS ? 0 : -1;
}

int pngio_write_surface(cairo_surface_t *surface, const char *path, struct acq_err *err)
{
	if (!surface || !path || !*path)
		return acq_errf(err, ACQ_E_INVAL, "png: no surface or no path");
	if (cairo_surface_status(surface) != CAIRO_STATUS_SUCCESS)
		return acq_errf(err, ACQ_E_NOMEM, "png: %s: drawing failed: %s", path,
				cairo_status_to_string(cairo_surface_status(surface)));
	return write_atomic(path, "png", emit_png, surface, err);
}

struct bytes {
	const void *data;
	size_t len;
};

static int emit_bytes(struct sink *s, void *ctx)
{
	const struct bytes *b = ctx;
	const unsigned char *p = b->data;
	for (size_t off = 0; off < b->len;) {
		size_t n = b->len - off > (1u << 30) ? (1u << 30) : b->len - off;
		if (sink_write(s, p + off, (unsigned int)n) != CAIRO_STATUS_SUCCESS)
			return -1;
		off += n;
	}
	return 0;
}

int pngio_write_bytes(const char *path, const void *data, size_t len, struct acq_err *err)
{
	if (!path || !*path)
		return acq_errf(err, ACQ_E_INVAL, "write: no path");
	struct bytes b = { data, len };
	return write_atomic(path, "write", emit_bytes, &b, err);
}
