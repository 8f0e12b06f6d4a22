/* store_export: a sweep's calibrated samples in the CSV interchange format (design.md), from the
 * calibrated_samples view, and the sweep's grid row they are binned on, handed on to the recon chain's reference
 * noise (store_export_csv_grid; part of the store module, store.h). */
#include "daemon/store.h"

#include <errno.h>
#include <math.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>

#include "config/acq_out.h"
#include "daemon/store_int.h"
#include "drivers/spectro.h"

static void csv_num(FILE *out, double v)
{
	if (isfinite(v))
		fprintf(out, ",%.9g", v);
	else
		fputs(",", out); /* empty field: not measured */
}

int store_export_csv(struct store *st, int64_t sweep_id, FILE *out, int *nrows, struct acq_err *err)
{
	return store_export_csv_n(st, sweep_id, 0, out, nrows, err);
}

/* The sweep's grid row, read here alone: its wavelength grid (*n float32 nm as stored, *grid malloc'd) and its
 * spectrometer's pixel count (*npix; -1: none recorded) and wavelength coefficients c0..c4. 0; 1 when the sweep
 * has no grid (nothing allocated); -1 with err (ACQ_E_NOTFOUND: no sweep). */
static int grid_row(struct store *st, int64_t sweep_id, float **grid, int *n, int *npix, double coef[5],
		    struct acq_err *err)
{
	*grid = NULL;
	*n = 0;
	*npix = -1;
	sqlite3_stmt *s = store_prep(st, "SELECT w.wavelength_grid, p.npix, p.c0, p.c1, p.c2, p.c3, p.c4 FROM sweeps w "
				         "LEFT JOIN spectrometers p ON p.id = w.spectrometer_id WHERE w.id = ?", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	int rc = sqlite3_step(s);
	if (rc != SQLITE_ROW) {
		sqlite3_finalize(s);
		return rc == SQLITE_DONE ? acq_errf(err, ACQ_E_NOTFOUND, "no sweep %lld", (long long)sweep_id)
					 : store_db_err(st, err, "reading the sweep's grid");
	}
	int nb = sqlite3_column_bytes(s, 0);
	if (nb <= 0 || nb % 4) {
		sqlite3_finalize(s);
		return 1;
	}
	*grid = malloc((size_t)nb);
	if (!*grid) {
		sqlite3_finalize(s);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	memcpy(*grid, sqlite3_column_blob(s, 0), (size_t)nb);
	*n = nb / 4;
	if (sqlite3_column_type(s, 1) != SQLITE_NULL)
		*npix = sqlite3_column_int(s, 1);
	for (int i = 0; i < 5; i++)
		coef[i] = sqlite3_column_double(s, 2 + i);
	sqlite3_finalize(s);
	return 0;
}

/* store_export_csv_n(); keep (may be NULL) receives the grid row it read when it succeeds (zeroed otherwise). */
static int export_n(struct store *st, int64_t sweep_id, int limit, FILE *out, int *nrows, struct store_grid *keep,
		    struct acq_err *err)
{
	*nrows = 0;
	float *grid;
	int n, npix;
	double coef[5];
	if (keep)
		*keep = (struct store_grid){ 0 };
	int g = grid_row(st, sweep_id, &grid, &n, &npix, coef, err);
	if (g < 0)
		return -1;
	if (g > 0)
		return acq_errf(err, ACQ_E_STATE, "sweep %lld has no calibrated samples yet (no wavelength grid)",
				(long long)sweep_id);
	int nb = 4 * n;
	sqlite3_stmt *s;
	int rc = -1;
	fprintf(out, "# acquisitiond sweep %lld: calibrated BRDF samples (sr^-1) with standard uncertainty\n",
		(long long)sweep_id);
	fputs("theta_i,phi_i,theta_o,phi_o", out);
	for (int i = 0; i < n; i++)
		fprintf(out, ",%.7g", (double)grid[i]);
	for (int i = 0; i < n; i++)
		fprintf(out, ",sigma_%.7g", (double)grid[i]);
	fputc('\n', out);
	s = store_prep(st, "SELECT theta_i, phi_i, theta_o, phi_o, brdf, sigma FROM calibrated_samples WHERE sweep_id = ? "
		           "ORDER BY order_index LIMIT ?", err);
	if (!s)
		goto out;
	sqlite3_bind_int64(s, 1, sweep_id);
	sqlite3_bind_int64(s, 2, limit > 0 ? limit : -1);
	int r;
	while ((r = sqlite3_step(s)) == SQLITE_ROW) {
		if (sqlite3_column_bytes(s, 4) != nb || sqlite3_column_bytes(s, 5) != nb) {
			acq_errf(err, ACQ_E_INVAL, "sweep %lld: calibrated sample length differs from the grid",
				 (long long)sweep_id);
			sqlite3_finalize(s);
			goto out;
		}
		if (sqlite3_column_type(s, 0) == SQLITE_NULL || sqlite3_column_type(s, 1) == SQLITE_NULL ||
		    sqlite3_column_type(s, 2) == SQLITE_NULL || sqlite3_column_type(s, 3) == SQLITE_NULL) {
			acq_errf(err, ACQ_E_INVAL, "sweep %lld: a point done without its measured angles", (long long)sweep_id);
			sqlite3_finalize(s);
			goto out;
		}
		const float *b = sqlite3_column_blob(s, 4), *sg = sqlite3_column_blob(s, 5);
		fprintf(out, "%.9g,%.9g,%.9g,%.9g", sqlite3_column_double(s, 0), sqlite3_column_double(s, 1),
			sqlite3_column_double(s, 2), sqlite3_column_double(s, 3));
		for (int i = 0; i < n; i++) {
			float v;
			memcpy(&v, (const char *)b + 4 * i, 4);
			csv_num(out, v);
		}
		for (int i = 0; i < n; i++) {
			float v;
			memcpy(&v, (const char *)sg + 4 * i, 4);
			csv_num(out, v);
		}
		fputc('\n', out);
		(*nrows)++;
	}
	sqlite3_finalize(s);
	if (r != SQLITE_DONE) {
		store_db_err(st, err, "exporting");
		goto out;
	}
	if (*nrows == 0) {
		acq_errf(err, ACQ_E_STATE, "sweep %lld has no calibrated samples", (long long)sweep_id);
		goto out;
	}
	rc = ferror(out) ? acq_errf(err, ACQ_E_IO, "writing the CSV: %s", strerror(errno)) : 0;
	if (!rc && keep) {
		*keep = (struct store_grid){ .nm = grid, .n = n, .npix = npix };
		memcpy(keep->coef, coef, sizeof coef);
		grid = NULL;
	}
out:
	free(grid);
	return rc;
}

int store_export_csv_n(struct store *st, int64_t sweep_id, int limit, FILE *out, int *nrows, struct acq_err *err)
{
	return export_n(st, sweep_id, limit, out, nrows, NULL, err);
}

int store_export_csv_grid(struct store *st, int64_t sweep_id, const char *path, int *nrows, struct store_grid *g,
			  struct acq_err *err)
{
	struct acq_out o;
	if (g)
		*g = (struct store_grid){ 0 };
	if (acq_out_open(&o, path, ACQ_OUT_STDIO, err))
		return -1;
	if (export_n(st, sweep_id, 0, o.f, nrows, g, err)) {
		acq_out_abort(&o);
		return -1;
	}
	if (acq_out_commit(&o, err)) {
		if (g) {
			free(g->nm);
			*g = (struct store_grid){ 0 };
		}
		return -1;
	}
	return 0;
}

int store_export_csv_file(struct store *st, int64_t sweep_id, const char *path, int *nrows, struct acq_err *err)
{
	return store_export_csv_grid(st, sweep_id, path, nrows, NULL, err);
}
