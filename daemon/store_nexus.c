/* store_nexus: read-only, streamed access to one sweep of the database for the NeXus export. */
#include "daemon/store_nexus.h"

#include <math.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/store.h"

#define STORENX_APP_ID 0x42524446 /* "BRDF", as the store writes it */

struct storenx {
	sqlite3 *db;
	char path[1024];
	float *buf;     /* decoding buffer for blobs */
	size_t cap;     /* floats */
};

static int db_fail(struct storenx *h, struct acq_err *err, const char *what)
{
	return acq_errf(err, ACQ_E_IO, "%s: %s: %s", h->path, what, sqlite3_errmsg(h->db));
}

static int64_t pragma(sqlite3 *db, const char *sql, int *ok)
{
	sqlite3_stmt *s = NULL;
	int64_t v = 0;
	*ok = sqlite3_prepare_v2(db, sql, -1, &s, NULL) == SQLITE_OK && sqlite3_step(s) == SQLITE_ROW;
	if (*ok)
		v = sqlite3_column_int64(s, 0);
	sqlite3_finalize(s);
	return v;
}

int storenx_open(const char *path, struct storenx **out, struct acq_err *err)
{
	*out = NULL;
	struct storenx *h = calloc(1, sizeof *h);
	if (!h)
		return acq_errf(err, ACQ_E_NOMEM, "export: out of memory");
	snprintf(h->path, sizeof h->path, "%s", path);
	if (sqlite3_open_v2(path, &h->db, SQLITE_OPEN_READONLY, NULL) != SQLITE_OK) {
		acq_errf(err, ACQ_E_IO, "%s: cannot open: %s", path, h->db ? sqlite3_errmsg(h->db) : "out of memory");
		storenx_close(h);
		return -1;
	}
	sqlite3_busy_timeout(h->db, 5000);
	int ok;
	int64_t app = pragma(h->db, "PRAGMA application_id", &ok);
	if (!ok) {
		acq_errf(err, ACQ_E_IO, "%s: not an SQLite database or corrupt (%s)", path, sqlite3_errmsg(h->db));
		storenx_close(h);
		return -1;
	}
	int64_t ver = pragma(h->db, "PRAGMA user_version", &ok);
	/* Version 2 differs from 3 only in recon_runs, which an export does not read. */
	if (app != STORENX_APP_ID || ver < 2 || ver > STORE_SCHEMA_VERSION) {
		acq_errf(err, app != STORENX_APP_ID ? ACQ_E_INVAL : ACQ_E_UNSUPPORTED,
			 "%s: not an acquisitiond database of schema version 2 to %d (application_id 0x%08llx, version %lld)",
			 path, STORE_SCHEMA_VERSION, (unsigned long long)(uint32_t)app, (long long)ver);
		storenx_close(h);
		return -1;
	}
	*out = h;
	return 0;
}

void storenx_close(struct storenx *h)
{
	if (!h)
		return;
	sqlite3_close(h->db);
	free(h->buf);
	free(h);
}

static char *dup_col(sqlite3_stmt *s, int c)
{
	const unsigned char *t = sqlite3_column_text(s, c);
	return t ? strdup((const char *)t) : NULL;
}

static double real_or_nan(sqlite3_stmt *s, int c)
{
	return sqlite3_column_type(s, c) == SQLITE_NULL ? NAN : sqlite3_column_double(s, c);
}

/* Decode a float32-LE blob of n values into dst. */
static void f32le(const unsigned char *p, int n, float *dst)
{
	for (int i = 0; i < n; i++) {
		uint32_t u = (uint32_t)p[4 * i] | (uint32_t)p[4 * i + 1] << 8 | (uint32_t)p[4 * i + 2] << 16 |
			     (uint32_t)p[4 * i + 3] << 24;
		memcpy(&dst[i], &u, 4);
	}
}

static float *room(struct storenx *h, size_t n)
{
	if (n > h->cap) {
		float *b = realloc(h->buf, n * sizeof *b);
		if (!b)
			return NULL;
		h->buf = b;
		h->cap = n;
	}
	return h->buf;
}

void storenx_sweep_free(struct storenx_sweep *s)
{
	free(s->name);
	free(s->state);
	free(s->plan_text);
	free(s->config_snapshot);
	free(s->software_version);
	free(s->calibration_method);
	free(s->grid);
	free(s->sp_model);
	free(s->sp_serial);
	free(s->sp_firmware);
	free(s->sp_nonlinearity);
	memset(s, 0, sizeof *s);
}

int storenx_sweep_get(struct storenx *h, int64_t id, struct storenx_sweep *s, struct acq_err *err)
{
	memset(s, 0, sizeof *s);
	sqlite3_stmt *st = NULL;
	int rc = -1;
	if (sqlite3_prepare_v2(h->db, "SELECT w.name, w.state, w.plan_text, w.config_snapshot, w.software_version, "
			       "w.calibration_method, w.created_at, w.started_at, w.finished_at, w.points_total, "
			       "w.wavelength_grid, p.model, p.serial, p.firmware, p.npix, p.c0, p.c1, p.c2, p.c3, p.c4, "
			       "p.nonlinearity FROM sweeps w LEFT JOIN spectrometers p ON p.id = w.spectrometer_id "
			       "WHERE w.id = ?", -1, &st, NULL) != SQLITE_OK)
		return db_fail(h, err, "reading the sweep");
	sqlite3_bind_int64(st, 1, id);
	int r = sqlite3_step(st);
	if (r != SQLITE_ROW) {
		if (r == SQLITE_DONE)
			acq_errf(err, ACQ_E_NOTFOUND, "%s: no sweep %lld", h->path, (long long)id);
		else
			db_fail(h, err, "reading the sweep");
		goto out;
	}
	s->id = id;
	s->name = dup_col(st, 0);
	s->state = dup_col(st, 1);
	s->plan_text = dup_col(st, 2);
	s->config_snapshot = dup_col(st, 3);
	s->software_version = dup_col(st, 4);
	s->calibration_method = dup_col(st, 5);
	s->created_at = real_or_nan(st, 6);
	s->started_at = real_or_nan(st, 7);
	s->finished_at = real_or_nan(st, 8);
	s->points_total = sqlite3_column_int64(st, 9);
	int glen = sqlite3_column_bytes(st, 10);
	if (glen > 0) {
		if (glen % 4) {
			acq_errf(err, ACQ_E_INVAL, "%s: sweep %lld: wavelength_grid of %d bytes (not float32)", h->path,
				 (long long)id, glen);
			goto out;
		}
		s->ngrid = glen / 4;
		s->grid = malloc((size_t)glen);
		if (!s->grid) {
			acq_errf(err, ACQ_E_NOMEM, "export: out of memory");
			goto out;
		}
		f32le(sqlite3_column_blob(st, 10), s->ngrid, s->grid);
	}
	if (sqlite3_column_type(st, 11) != SQLITE_NULL) {
		s->has_spectrometer = 1;
		s->sp_model = dup_col(st, 11);
		s->sp_serial = dup_col(st, 12);
		s->sp_firmware = dup_col(st, 13);
		s->npix = sqlite3_column_int(st, 14);
		for (int k = 0; k < 5; k++)
			s->sp_coef[k] = sqlite3_column_double(st, 15 + k);
		s->sp_nonlinearity = dup_col(st, 20);
	}
	if (!s->name || !s->state) {
		acq_errf(err, ACQ_E_NOMEM, "export: out of memory");
		goto out;
	}
	rc = 0;
out:
	sqlite3_finalize(st);
	if (rc)
		storenx_sweep_free(s);
	return rc;
}

static const char *const kinds[] = { "sample", "dark", "reference", "beam" };

static int is_kind(const char *k)
{
	for (size_t i = 0; i < sizeof kinds / sizeof kinds[0]; i++)
		if (!strcmp(k, kinds[i]))
			return 1;
	return 0;
}

int storenx_count(struct storenx *h, int64_t id, const char *what, int64_t *n, struct acq_err *err)
{
	const char *sql = !strcmp(what, "points")       ? "SELECT count(*) FROM points WHERE sweep_id = ?1"
			  : !strcmp(what, "calibrated") ? "SELECT count(*) FROM calibrated WHERE sweep_id = ?1"
			  : !strcmp(what, "events")     ? "SELECT count(*) FROM events WHERE sweep_id = ?1"
			  : !strcmp(what, "devices")    ? "SELECT count(*) FROM sweep_devices WHERE sweep_id = ?1"
			  : is_kind(what)               ? "SELECT count(*) FROM spectra WHERE sweep_id = ?1 AND kind = ?2"
							: NULL;
	if (!sql)
		return acq_errf(err, ACQ_E_INVAL, "export: unknown row kind '%s'", what);
	sqlite3_stmt *st = NULL;
	if (sqlite3_prepare_v2(h->db, sql, -1, &st, NULL) != SQLITE_OK)
		return db_fail(h, err, "counting rows");
	sqlite3_bind_int64(st, 1, id);
	if (is_kind(what))
		sqlite3_bind_text(st, 2, what, -1, SQLITE_STATIC);
	int ok = sqlite3_step(st) == SQLITE_ROW;
	*n = ok ? sqlite3_column_int64(st, 0) : 0;
	sqlite3_finalize(st);
	return ok ? 0 : db_fail(h, err, "counting rows");
}

/* Step through a prepared statement; row() turns each row into a callback call. */
static int scan(struct storenx *h, sqlite3_stmt *st, int (*row)(struct storenx *, sqlite3_stmt *, void *, void *,
							 struct acq_err *),
		void *fn, void *ctx, struct acq_err *err)
{
	int r, rc = 0;
	while ((r = sqlite3_step(st)) == SQLITE_ROW)
		if ((rc = row(h, st, fn, ctx, err)) != 0)
			break;
	if (!rc && r != SQLITE_DONE)
		rc = db_fail(h, err, "reading rows");
	sqlite3_finalize(st);
	return rc;
}

static int point_row(struct storenx *h, sqlite3_stmt *st, void *fn, void *ctx, struct acq_err *err)
{
	(void)h;
	(void)err;
	struct storenx_point p;
	p.id = sqlite3_column_int64(st, 0);
	p.order_index = sqlite3_column_int(st, 1);
	for (int k = 0; k < 4; k++)
		p.planned[k] = sqlite3_column_double(st, 2 + k);
	for (int k = 0; k < 3; k++)
		p.actual[k] = real_or_nan(st, 6 + k);
	p.state = (const char *)sqlite3_column_text(st, 9);
	p.done_at = real_or_nan(st, 10);
	for (int k = 0; k < 4; k++)
		p.measured[k] = real_or_nan(st, 11 + k);
	return ((int (*)(void *, const struct storenx_point *))fn)(ctx, &p);
}

int storenx_points(struct storenx *h, int64_t id, int (*fn)(void *, const struct storenx_point *), void *ctx,
		   struct acq_err *err)
{
	sqlite3_stmt *st = NULL;
	if (sqlite3_prepare_v2(h->db, "SELECT id, order_index, theta_i, phi_i, theta_o, phi_o, laser_theta, "
			       "detector_theta, detector_phi, state, done_at, m_theta_i, m_phi_i, m_theta_o, m_phi_o "
			       "FROM points WHERE sweep_id = ? "
			       "ORDER BY order_index", -1, &st, NULL) != SQLITE_OK)
		return db_fail(h, err, "reading points");
	sqlite3_bind_int64(st, 1, id);
	return scan(h, st, point_row, (void *)fn, ctx, err);
}

static int spectrum_row(struct storenx *h, sqlite3_stmt *st, void *fn, void *ctx, struct acq_err *err)
{
	struct storenx_spectrum sp;
	sp.id = sqlite3_column_int64(st, 0);
	sp.point_id = sqlite3_column_type(st, 1) == SQLITE_NULL ? -1 : sqlite3_column_int64(st, 1);
	sp.kind = (const char *)sqlite3_column_text(st, 2);
	sp.integration_ms = sqlite3_column_double(st, 3);
	sp.averages = sqlite3_column_int(st, 4);
	sp.npix = sqlite3_column_int(st, 5);
	int cl = sqlite3_column_bytes(st, 6), sl = sqlite3_column_bytes(st, 7);
	if (sp.npix <= 0 || cl != 4 * sp.npix || (sl && sl != 4 * sp.npix))
		return acq_errf(err, ACQ_E_INVAL, "%s: spectrum %lld: %d pixels but %d/%d blob bytes", h->path,
				(long long)sp.id, sp.npix, cl, sl);
	float *b = room(h, 2 * (size_t)sp.npix);
	if (!b)
		return acq_errf(err, ACQ_E_NOMEM, "export: out of memory");
	f32le(sqlite3_column_blob(st, 6), sp.npix, b);
	sp.counts = b;
	sp.stddev = NULL;
	if (sl) {
		f32le(sqlite3_column_blob(st, 7), sp.npix, b + sp.npix);
		sp.stddev = b + sp.npix;
	}
	sp.saturated_count = sqlite3_column_int(st, 8);
	sp.temperature_c = real_or_nan(st, 9);
	sp.taken_at = sqlite3_column_double(st, 10);
	return ((int (*)(void *, const struct storenx_spectrum *))fn)(ctx, &sp);
}

int storenx_spectra(struct storenx *h, int64_t id, const char *kind, int (*fn)(void *, const struct storenx_spectrum *),
		    void *ctx, struct acq_err *err)
{
	if (!is_kind(kind))
		return acq_errf(err, ACQ_E_INVAL, "export: unknown spectrum kind '%s'", kind);
	sqlite3_stmt *st = NULL;
	if (sqlite3_prepare_v2(h->db, "SELECT id, point_id, kind, integration_ms, averages, npix, counts, stddev, "
			       "saturated_count, temperature_c, taken_at FROM spectra WHERE sweep_id = ? AND kind = ? "
			       "ORDER BY id", -1, &st, NULL) != SQLITE_OK)
		return db_fail(h, err, "reading spectra");
	sqlite3_bind_int64(st, 1, id);
	sqlite3_bind_text(st, 2, kind, -1, SQLITE_STATIC);
	return scan(h, st, spectrum_row, (void *)fn, ctx, err);
}

static int calibrated_row(struct storenx *h, sqlite3_stmt *st, void *fn, void *ctx, struct acq_err *err)
{
	struct storenx_calibrated c;
	c.point_id = sqlite3_column_int64(st, 0);
	int bl = sqlite3_column_bytes(st, 1), sl = sqlite3_column_bytes(st, 2);
	if (bl <= 0 || bl % 4 || sl != bl)
		return acq_errf(err, ACQ_E_INVAL, "%s: calibrated point %lld: blobs of %d/%d bytes", h->path,
				(long long)c.point_id, bl, sl);
	c.n = bl / 4;
	float *b = room(h, 2 * (size_t)c.n);
	if (!b)
		return acq_errf(err, ACQ_E_NOMEM, "export: out of memory");
	f32le(sqlite3_column_blob(st, 1), c.n, b);
	f32le(sqlite3_column_blob(st, 2), c.n, b + c.n);
	c.brdf = b;
	c.sigma = b + c.n;
	return ((int (*)(void *, const struct storenx_calibrated *))fn)(ctx, &c);
}

int storenx_calibrated(struct storenx *h, int64_t id, int (*fn)(void *, const struct storenx_calibrated *), void *ctx,
		       struct acq_err *err)
{
	sqlite3_stmt *st = NULL;
	if (sqlite3_prepare_v2(h->db, "SELECT c.point_id, c.brdf, c.sigma FROM calibrated c JOIN points p ON "
			       "p.id = c.point_id WHERE c.sweep_id = ? ORDER BY p.order_index", -1, &st, NULL) != SQLITE_OK)
		return db_fail(h, err, "reading calibrated samples");
	sqlite3_bind_int64(st, 1, id);
	return scan(h, st, calibrated_row, (void *)fn, ctx, err);
}

static int event_row(struct storenx *h, sqlite3_stmt *st, void *fn, void *ctx, struct acq_err *err)
{
	(void)h;
	(void)err;
	struct storenx_event e;
	e.id = sqlite3_column_int64(st, 0);
	e.at = sqlite3_column_double(st, 1);
	e.kind = (const char *)sqlite3_column_text(st, 2);
	e.device = (const char *)sqlite3_column_text(st, 3);
	e.message = (const char *)sqlite3_column_text(st, 4);
	return ((int (*)(void *, const struct storenx_event *))fn)(ctx, &e);
}

int storenx_events(struct storenx *h, int64_t id, int (*fn)(void *, const struct storenx_event *), void *ctx,
		   struct acq_err *err)
{
	sqlite3_stmt *st = NULL;
	if (sqlite3_prepare_v2(h->db, "SELECT id, at, kind, device, message FROM events WHERE sweep_id = ? ORDER BY id",
			       -1, &st, NULL) != SQLITE_OK)
		return db_fail(h, err, "reading events");
	sqlite3_bind_int64(st, 1, id);
	return scan(h, st, event_row, (void *)fn, ctx, err);
}

static int device_row(struct storenx *h, sqlite3_stmt *st, void *fn, void *ctx, struct acq_err *err)
{
	(void)h;
	(void)err;
	struct storenx_device d;
	const char **f[5] = { &d.name, &d.vendor, &d.model, &d.serial, &d.firmware };
	for (int k = 0; k < 5; k++)
		*f[k] = (const char *)sqlite3_column_text(st, k);
	return ((int (*)(void *, const struct storenx_device *))fn)(ctx, &d);
}

int storenx_devices(struct storenx *h, int64_t id, int (*fn)(void *, const struct storenx_device *), void *ctx,
		    struct acq_err *err)
{
	sqlite3_stmt *st = NULL;
	if (sqlite3_prepare_v2(h->db, "SELECT d.name, d.vendor, d.model, d.serial, d.firmware FROM sweep_devices s "
			       "JOIN devices d ON d.id = s.device_id WHERE s.sweep_id = ? ORDER BY d.name", -1, &st,
			       NULL) != SQLITE_OK)
		return db_fail(h, err, "reading devices");
	sqlite3_bind_int64(st, 1, id);
	return scan(h, st, device_row, (void *)fn, ctx, err);
}
