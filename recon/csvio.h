/* csvio: the CSV interchange format of sparse spectral BRDF samples (design.md), read and written with
 * errors that name the line and the column. */
#ifndef RECON_CSVIO_H
#define RECON_CSVIO_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>

#include "config/acq_err.h"

/* Sparse spectral samples. Angles in radians; values in sr⁻¹; NAN marks "not measured". */
struct recon_samples {
	size_t n;      /* number of sample directions (rows) */
	size_t nwl;    /* number of wavelengths */
	double *wl;    /* [nwl] wavelengths in nm, strictly increasing */
	double *ang;   /* [n*4] θi, φi, θo, φo in radians (θ ∈ [0, π/2]) */
	double *val;   /* [n*nwl] row-major values; NAN = not measured */
	double *sig;   /* [n*nwl] standard uncertainties (NAN = not given), or NULL when the file has none */
	double *deg;   /* [n*4] the angles as written in the file (degrees), echoed by eval */
};

/* Grow s's row arrays to cap rows (values/sigmas: also val/sig, nwl wide); s stays valid on failure. 0 or -1. */
int csvio_samples_grow(struct recon_samples *s, size_t cap, bool values, bool sigmas);
/* Parse CSV text of samples (name is used in messages); fills *s (free with csvio_samples_free). */
int csvio_parse_samples(const char *name, const char *text, size_t len, struct recon_samples *s,
			struct acq_err *err);
/* Read a samples CSV file. */
int csvio_read_samples(const char *path, struct recon_samples *s, struct acq_err *err);
/* Parse CSV text of query directions: only the four angle columns are read (nwl = 0, no values). */
int csvio_parse_queries(const char *name, const char *text, size_t len, struct recon_samples *s,
			struct acq_err *err);
/* Read a query CSV file. */
int csvio_read_queries(const char *path, struct recon_samples *s, struct acq_err *err);
/* Free the arrays of *s and zero it. */
void csvio_samples_free(struct recon_samples *s);
/* Read a whole file into a NUL-terminated heap buffer (max 1 GiB; config/acq_file.h); *len excludes the NUL. */
int csvio_slurp(const char *path, char **out, size_t *len, struct acq_err *err);
/* Read the named numeric columns (k ≤ 16) of a CSV table with a header (# comments before it); *data gets
 * rows × k values row-major (free()); empty fields and nan are errors. */
int csvio_read_columns(const char *path, const char *const *names, size_t k, size_t *rows, double **data,
		       struct acq_err *err);
/* csvio_read_columns_ex() flag: a table with its header and no data row is read as 0 rows (*data NULL), not refused. */
#define CSVIO_EMPTY_OK 1u
/* csvio_read_columns() with flags (CSVIO_EMPTY_OK). */
int csvio_read_columns_ex(const char *path, const char *const *names, size_t k, unsigned flags, size_t *rows,
			  double **data, struct acq_err *err);
/* csvio_read_columns() with *data column-major: column c is the *rows values at *data + c × *rows (free()). */
int csvio_read_columns_cm(const char *path, const char *const *names, size_t k, size_t *rows, double **data,
			  struct acq_err *err);
/* Format a double with 10 significant digits; -1 (and nothing written) if it is not finite. */
int csvio_fmt(char *buf, size_t size, double v);

#endif
