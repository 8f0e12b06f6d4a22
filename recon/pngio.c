/* pngio: file output through config/acq_out (temp file, fsync, rename): PNG of a cairo surface, or a byte buffer. */
#include "recon/pngio.h"

#include <errno.h>
#include <png.h>
#include <setjmp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "config/acq_out.h"

struct sink {
	int fd;
	int err; /* errno of the first failed write, 0 if none */
};

static int sink_write(void *closure, const unsigned char *data, size_t length)
{
	struct sink *s = closure;
	while (length > 0) {
		ssize_t w = write(s->fd, data, length);
		if (w < 0 && errno == EINTR)
			continue;
		if (w <= 0) {
			s->err = w < 0 ? errno : EIO;
			return -1;
		}
		data += w;
		length -= (size_t)w;
	}
	return 0;
}

/* Write through emit() to path (config/acq_out: a temporary file beside it, fsync, rename; a device or FIFO in
 * place); 0, or -1 with err. */
static int write_atomic(const char *path, const char *what, int (*emit)(struct sink *s, void *ctx), void *ctx,
			struct acq_err *err)
{
	struct acq_out o;
	if (acq_out_open(&o, path, 0, err))
		return acq_err_prefix(err, "%s: ", what);
	struct sink s = { .fd = o.fd, .err = 0 };
	if (emit(&s, ctx) != 0) {
		acq_errf(err, ACQ_E_IO, "%s: writing %s: %s", what, path, s.err ? strerror(s.err) : "encoder failed");
		acq_out_abort(&o);
		return -1;
	}
	return acq_out_commit(&o, err) ? acq_err_prefix(err, "%s: ", what) : 0;
}

struct membuf {
	unsigned char *p;
	size_t len, cap;
	int oom;
};

static void mem_write(png_structp png, png_bytep data, png_size_t n)
{
	struct membuf *b = png_get_io_ptr(png);
	if (b->oom)
		return;
	if (b->len + n > b->cap) {
		size_t cap = b->cap ? b->cap : 65536;
		while (cap < b->len + n)
			cap *= 2;
		unsigned char *q = realloc(b->p, cap);
		if (!q) {
			b->oom = 1;
			return;
		}
		b->p = q;
		b->cap = cap;
	}
	memcpy(b->p + b->len, data, n);
	b->len += n;
}

static void mem_flush(png_structp png)
{
	(void)png;
}

/* Encode 8-bit sRGB rows (3 bytes per pixel) as PNG in memory with the sRGB chunk (perceptual intent) and the
 * gAMA and cHRM values the PNG specification pairs with it, for readers that do not know sRGB. */
static int encode_rgb8(const unsigned char *rgb, int w, int h, struct membuf *b)
{
	png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
	png_infop info = png ? png_create_info_struct(png) : NULL;
	if (!png || !info) {
		png_destroy_write_struct(&png, NULL);
		return -1;
	}
	if (setjmp(png_jmpbuf(png))) {
		png_destroy_write_struct(&png, &info);
		return -1;
	}
	png_set_write_fn(png, b, mem_write, mem_flush);
	png_set_IHDR(png, info, (png_uint_32)w, (png_uint_32)h, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
		     PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
	png_set_sRGB_gAMA_and_cHRM(png, info, PNG_sRGB_INTENT_PERCEPTUAL);
	png_write_info(png, info);
	for (int j = 0; j < h; j++)
		png_write_row(png, (png_const_bytep)(rgb + (size_t)j * (size_t)w * 3));
	png_write_end(png, info);
	png_destroy_write_struct(&png, &info);
	return b->oom ? -1 : 0;
}

int pngio_write_rgb8(const char *path, const unsigned char *rgb, int w, int h, struct acq_err *err)
{
	if (!path || !*path || !rgb || w < 1 || h < 1)
		return acq_errf(err, ACQ_E_INVAL, "png: no image or no path");
	struct membuf b = { 0 };
	if (encode_rgb8(rgb, w, h, &b) != 0) {
		free(b.p);
		return acq_errf(err, ACQ_E_NOMEM, "png: %s: encoding failed (out of memory)", path);
	}
	int rc = pngio_write_bytes(path, b.p, b.len, err);
	free(b.p);
	return rc;
}

int pngio_write_surface(cairo_surface_t *surface, const char *path, struct acq_err *err)
{
	if (!surface || !path || !*path)
		return acq_errf(err, ACQ_E_INVAL, "png: no surface or no path");
	if (cairo_surface_status(surface) != CAIRO_STATUS_SUCCESS)
		return acq_errf(err, ACQ_E_NOMEM, "png: %s: drawing failed: %s", path,
				cairo_status_to_string(cairo_surface_status(surface)));
	cairo_format_t fmt = cairo_image_surface_get_format(surface);
	if (fmt != CAIRO_FORMAT_RGB24 && fmt != CAIRO_FORMAT_ARGB32)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "png: %s: surface format %d (RGB24 or ARGB32 expected)", path, fmt);
	cairo_surface_flush(surface);
	int w = cairo_image_surface_get_width(surface), h = cairo_image_surface_get_height(surface);
	int stride = cairo_image_surface_get_stride(surface);
	const unsigned char *data = cairo_image_surface_get_data(surface);
	unsigned char *rgb = malloc((size_t)w * (size_t)h * 3);
	if (!rgb)
		return acq_errf(err, ACQ_E_NOMEM, "png: out of memory for %d x %d", w, h);
	/* cairo: native-endian 32-bit pixels (premultiplied in ARGB32: the plots are opaque, alpha is dropped) */
	for (int j = 0; j < h; j++)
		for (int i = 0; i < w; i++) {
			uint32_t px;
			memcpy(&px, data + (size_t)j * (size_t)stride + 4 * (size_t)i, 4);
			unsigned char *q = rgb + ((size_t)j * (size_t)w + (size_t)i) * 3;
			q[0] = (unsigned char)(px >> 16);
			q[1] = (unsigned char)(px >> 8);
			q[2] = (unsigned char)px;
		}
	int rc = pngio_write_rgb8(path, rgb, w, h, err);
	free(rgb);
	return rc;
}

struct bytes {
	const void *data;
	size_t len;
};

static int emit_bytes(struct sink *s, void *ctx)
{
	const struct bytes *b = ctx;
	const unsigned char *p = b->data;
	return sink_write(s, p, b->len);
}

int pngio_write_bytes(const char *path, const void *data, size_t len, struct acq_err *err)
{
	if (!path || !*path)
		return acq_errf(err, ACQ_E_INVAL, "write: no path");
	struct bytes b = { data, len };
	return write_atomic(path, "write", emit_bytes, &b, err);
}
