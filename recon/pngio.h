/* pngio: atomic PNG output of a cairo image surface (temp file in the target folder, fsync, rename). */
#ifndef RECON_PNGIO_H
#define RECON_PNGIO_H

#include <cairo.h>

#include "config/acq_err.h"

/* Write surface as PNG to path atomically; 0, or -1 with err (nothing left at path on failure). */
int pngio_write_surface(cairo_surface_t *surface, const char *path, struct acq_err *err);

#endif
