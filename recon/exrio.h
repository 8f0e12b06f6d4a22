/* exrio: linear RGB images as OpenEXR (scanline, float R/G/B, ZIP) through the OpenEXR 3 core C API. */
#ifndef RECON_EXRIO_H
#define RECON_EXRIO_H

#include "config/acq_err.h"

/* Write w×h linear RGB (rgb[(j*w + i)*3 + c], top row first) as 32-bit float R, G, B with the Rec. 709 / sRGB
 * chromaticities (D65 white) and `comments` (may be NULL). Encoded in memory, then written through config/acq_out
 * (a regular file atomically by temporary file + rename, a device or FIFO in place). Non-finite values are
 * refused. 0, or -1 with err. */
int exrio_write_rgb(const char *path, const float *rgb, int w, int h, const char *comments, struct acq_err *err);

/* Read an EXR's R, G, B channels (any compression, scanline storage; a Y-only image gives grey) into a new
 * float array *rgb (free()), size *w × *h. Non-finite or negative pixels are refused (named). 0, or -1. */
int exrio_read_rgb(const char *path, float **rgb, int *w, int *h, struct acq_err *err);

#endif
