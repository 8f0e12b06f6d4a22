/* dbload: calibrated samples of one sweep read from the daemon's SQLite database (schema version 2,
 * daemon/schema.sql) through its calibrated_samples view, as struct recon_samples. Read-only; no state kept. */
#include <math.h>
#include <sqlite3.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "recon/recon.h"

#define DB_APP_ID 0x42524446 /* "BRDF" */
#define DB_VERSION 2     /* the first with calibrated_samples; acquisitiond migrates older files when it opens them */
#define DB_VERSION_MAX 6 /* the newest this reader knows (3 changed only recon_runs, 4 added the adaptive tables, 5 sweep_samples,
			  * 6 sweeps.plan_kind) */

static int pragma_int(sqlite3 *db, const char *sql, long long *out)
{
	sqlite3_stmt *st;
	if (sqlite3_prepare_v2(db, sql, -1, &st, NULL) != SQLITE_OK)
		return -1;
	int rc = sqlite3_step(st) == SQLITE_ROW ? 0 : -1;
	if (!rc)
		*out = sqlite3_column_int64(st, 0);
	sqlite3_finalize(st);
	return rc;
}

/* float32 little-endian → double */
static double f32le(const unsigned char *p)
{
	uint32_t u = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
	float f;
	memcpy(&f, &u, 4);
	return (double)f;
}

/*
 * Which angles: those of the calibrated_samples view, the sample-frame angles measured when the point was
 * committed (zeniths in [0, 90], azimuths in [0, 360)) — the same the daemon's CSV export and its own
 * reconstruction use. Only points done are in the view; NaN values in the blobs mean "not measured"; ±Inf is an
 * error naming the point.
 */
int recon_load_db(const char *db_path, long long sweep_id, struct recon_samples *s, struct acq_err *err)
{
	memset(s, 0, sizeof *s);
	sqlite3 *db = NULL;
	sqlite3_stmt *st = NULL;
	int rc = -1;
	if (sqlite3_open_v2(db_path, &db, SQLITE_OPEN_READONLY, NULL) != SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: cannot open database: %s", db_path, db ? sqlite3_errmsg(db) : "no memory");
		goto out;
	}
	sqlite3_busy_timeout(db, 5000);
	long long app = 0, ver = 0;
	if (pragma_int(db, "PRAGMA application_id", &app) || pragma_int(db, "PRAGMA user_version", &ver)) {
		acq_errf(err, ACQ_E_IO, "%s: not a readable SQLite database: %s", db_path, sqlite3_errmsg(db));
		goto out;
	}
	if (app != DB_APP_ID) {
		acq_errf(err, ACQ_E_INVAL, "%s: not an acquisitiond database (application_id 0x%llx)", db_path,
			 (unsigned long long)app);
		goto out;
	}
	if (ver < DB_VERSION || ver > DB_VERSION_MAX) {
		acq_errf(err, ACQ_E_UNSUPPORTED, "%s: schema version %lld, this program reads versions %d to %d%s", db_path,
			 ver, DB_VERSION, DB_VERSION_MAX, ver < DB_VERSION ? " (start acquisitiond on it once to migrate it)" : "");
		goto out;
	}
	if (sqlite3_prepare_v2(db, "SELECT wavelength_grid, state FROM sweeps WHERE id = ?", -1, &st, NULL) !=
	    SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: %s", db_path, sqlite3_errmsg(db));
		goto out;
	}
	sqlite3_bind_int64(st, 1, sweep_id);
	if (sqlite3_step(st) != SQLITE_ROW) {
		acq_errf(err, ACQ_E_NOTFOUND, "%s: no sweep %lld", db_path, sweep_id);
		goto out;
	}
	int glen = sqlite3_column_bytes(st, 0);
	const unsigned char *grid = sqlite3_column_blob(st, 0);
	if (!grid || glen <= 0) {
		acq_errf(err, ACQ_E_STATE, "%s: sweep %lld has no calibrated wavelength grid (state %s)", db_path,
			 sweep_id, (const char *)sqlite3_column_text(st, 1));
		goto out;
	}
	if (glen % 4) {
		acq_errf(err, ACQ_E_INVAL, "%s: sweep %lld: wavelength grid of %d bytes is not float32", db_path, sweep_id,
			 glen);
		goto out;
	}
	size_t L = (size_t)glen / 4;
	s->nwl = L;
	s->wl = malloc(L * sizeof *s->wl);
	if (!s->wl) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto out;
	}
	for (size_t l = 0; l < L; l++) {
		s->wl[l] = f32le(grid + 4 * l);
		if (!isfinite(s->wl[l]) || !(s->wl[l] > 0) || (l && !(s->wl[l] > s->wl[l - 1]))) {
			acq_errf(err, ACQ_E_INVAL, "%s: sweep %lld: wavelength grid not positive and increasing at %zu",
				 db_path, sweep_id, l);
			goto out;
		}
	}
	sqlite3_finalize(st);
	st = NULL;
	if (sqlite3_prepare_v2(db,
			       "SELECT point_id, theta_i, phi_i, theta_o, phi_o, brdf, sigma FROM calibrated_samples "
			       "WHERE sweep_id = ? ORDER BY order_index",
			       -1, &st, NULL) != SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: %s", db_path, sqlite3_errmsg(db));
		goto out;
	}
	sqlite3_bind_int64(st, 1, sweep_id);
	size_t cap = 0;
	int step;
	while ((step = sqlite3_step(st)) == SQLITE_ROW) {
		long long pid = sqlite3_column_int64(st, 0);
		if (s->n == cap) {
			size_t nc = cap ? 2 * cap : 256;
			if (csvio_samples_grow(s, nc, true, true)) {
				acq_errf(err, ACQ_E_NOMEM, "out of memory");
				goto out;
			}
			cap = nc;
		}
		size_t r = s->n;
		for (int c = 0; c < 4; c++) {
			if (sqlite3_column_type(st, 1 + c) == SQLITE_NULL) {
				acq_errf(err, ACQ_E_INVAL, "%s: point %lld: angle missing", db_path, pid);
				goto out;
			}
			double v = sqlite3_column_double(st, 1 + c);
			int theta = c == 0 || c == 2;
			if (!isfinite(v) || (theta && (v < 0 || v > 90)) || fabs(v) > 1e6) {
				acq_errf(err, ACQ_E_RANGE, "%s: point %lld: angle %g out of range", db_path, pid, v);
				goto out;
			}
			s->deg[4 * r + c] = v;
			s->ang[4 * r + c] = v * (M_PI / 180.0);
		}
		const unsigned char *fb = sqlite3_column_blob(st, 5);
		int fl = sqlite3_column_bytes(st, 5);
		const unsigned char *sb = sqlite3_column_blob(st, 6);
		int sl = sqlite3_column_bytes(st, 6);
		if (!fb || !sb || (size_t)fl != 4 * L || (size_t)sl != 4 * L) {
			acq_errf(err, ACQ_E_INVAL, "%s: point %lld: brdf/sigma blobs of %d/%d bytes, grid has %zu wavelengths",
				 db_path, pid, fl, sl, L);
			goto out;
		}
		for (size_t l = 0; l < L; l++) {
			double v = f32le(fb + 4 * l), g = f32le(sb + 4 * l);
			if (isinf(v) || isinf(g) || g < 0) {
				acq_errf(err, ACQ_E_INVAL, "%s: point %lld: non-finite value or negative sigma at %g nm", db_path,
					 pid, s->wl[l]);
				goto out;
			}
			s->val[r * L + l] = v;
			s->sig[r * L + l] = g;
		}
		s->n++;
	}
	if (step != SQLITE_DONE) {
		acq_errf(err, ACQ_E_IO, "%s: %s", db_path, sqlite3_errmsg(db));
		goto out;
	}
	if (s->n == 0) {
		acq_errf(err, ACQ_E_STATE, "%s: sweep %lld has no calibrated samples", db_path, sweep_id);
		goto out;
	}
	rc = 0;
out:
	sqlite3_finalize(st);
	sqlite3_close(db);
	if (rc)
		csvio_samples_free(s);
	return rc;
}
