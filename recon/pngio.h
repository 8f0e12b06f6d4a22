/* pngio: atomic file output (temp file in the target folder, fsync, rename): PNG surfaces and byte buffers. */
#ifndef RECON_PNGIO_H
#define RECON_PNGIO_H

#include <cairo.h>
#include <stddef.h>

#include "config/acq_err.h"

/* Write an RGB24/ARGB32 surface as PNG (sRGB-tagged, as pngio_write_rgb8; alpha dropped) to path atomically;
 * 0, or -1 with err (nothing left at path on failure). */
int pngio_write_surface(cairo_surface_t *surface, const char *path, struct acq_err *err);

/* Write w×h 8-bit sRGB pixels (3 bytes each, rows top first) as PNG with the sRGB, gAMA and cHRM chunks,
 * atomically. 0, or -1 with err. */
int pngio_write_rgb8(const char *path, const unsigned char *rgb, int w, int h, struct acq_err *err);
/* Write len bytes to path atomically (same rule); 0, or -1 with err. */
int pngio_write_bytes(const char *path, const void *data, size_t len, struct acq_err *err);

#endif
