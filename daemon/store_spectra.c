/* store_spectra: raw spectra (one transaction each, completing their point), the stored reference a resumed
 * sweep reloads, and the JSON view of one spectrum (part of the store module, store.h). */
#include "daemon/store.h"

#include <errno.h>
#include <math.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <string.h>

#include "daemon/store_int.h"
#include "drivers/spectro.h"

int store_spectrum_add(struct store *st, const struct store_spectrum *sp, int64_t *id, struct acq_err *err)
{
	static const char *const kinds[] = { "sample", "dark", "reference", "beam", NULL };
	if (!store_in_list(sp->kind, kinds))
		return acq_errf(err, ACQ_E_INVAL, "store: spectrum kind must be sample, dark, reference or beam");
	if (sp->npix <= 0 || sp->npix > SPECTRO_MAX_PIXELS || !sp->counts)
		return acq_errf(err, ACQ_E_INVAL, "store: spectrum without counts or with %d pixels", sp->npix);
	if (sp->completes_point && sp->point_id <= 0)
		return acq_errf(err, ACQ_E_INVAL, "store: completes_point without a point");
	if (store_tx_begin(st, err))
		return -1;
	int rc = -1;
	int64_t sid = 0;
	sqlite3_stmt *s = st->st[ST_SPECTRUM];
	int n4 = sp->npix * 4;
	store_bind_id(s, 1, sp->sweep_id);
	store_bind_id(s, 2, sp->point_id);
	store_bind_text(s, 3, sp->kind);
	store_bind_id(s, 4, sp->spectrometer_id);
	sqlite3_bind_double(s, 5, sp->integration_ms);
	sqlite3_bind_int(s, 6, sp->averages);
	sqlite3_bind_int(s, 7, sp->npix);
	/* float32 host order: every supported target (x86-64, aarch64) is little-endian, as the schema says. */
	sqlite3_bind_blob(s, 8, sp->counts, n4, SQLITE_STATIC);
	if (sp->stddev)
		sqlite3_bind_blob(s, 9, sp->stddev, n4, SQLITE_STATIC);
	else
		sqlite3_bind_null(s, 9);
	sqlite3_bind_int(s, 10, sp->saturated_count);
	if (sp->saturated && sp->saturated_count > 0)
		sqlite3_bind_blob(s, 11, sp->saturated, sp->npix, SQLITE_STATIC);
	else
		sqlite3_bind_null(s, 11);
	store_bind_real(s, 12, sp->temperature_c);
	sqlite3_bind_double(s, 13, sp->taken_at);
	if (store_step_done(st, s, err, "inserting spectrum"))
		goto end;
	sid = sqlite3_last_insert_rowid(st->db);
	if (sp->completes_point) {
		s = st->st[ST_POINT_DONE];
		sqlite3_bind_double(s, 1, sp->taken_at);
		store_bind_real(s, 2, sp->laser_theta);
		store_bind_real(s, 3, sp->detector_theta);
		store_bind_real(s, 4, sp->detector_phi);
		store_bind_real(s, 5, sp->theta_i);
		store_bind_real(s, 6, sp->phi_i);
		store_bind_real(s, 7, sp->theta_o);
		store_bind_real(s, 8, sp->phi_o);
		sqlite3_bind_int64(s, 9, sp->point_id);
		if (store_step_done(st, s, err, "completing point"))
			goto end;
		if (sqlite3_changes(st->db) != 1) {
			acq_errf(err, ACQ_E_STATE, "store: point %lld is not pending", (long long)sp->point_id);
			goto end;
		}
	}
	rc = 0;
end:
	return store_tx_end(st, rc, sid, id, err);
}

int64_t store_spectrum_count(struct store *st, int64_t sweep_id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, sweep_id ? "SELECT count(*) FROM spectra WHERE sweep_id = ?"
					          : "SELECT count(*) FROM spectra", err);
	if (!s)
		return -1;
	if (sweep_id)
		sqlite3_bind_int64(s, 1, sweep_id);
	int64_t n = sqlite3_step(s) == SQLITE_ROW ? sqlite3_column_int64(s, 0) : -1;
	if (n < 0)
		store_db_err(st, err, "counting spectra");
	sqlite3_finalize(s);
	return n;
}

/* float32 blob of npix values into dst (double and/or float). 0, or -1 when the length differs. */
static int blob_floats(sqlite3_stmt *s, int col, int npix, double *dst_d, float *dst_f)
{
	const void *b = sqlite3_column_blob(s, col);
	int n = sqlite3_column_bytes(s, col);
	if (!b || n != 4 * npix)
		return -1;
	const float *f = b;
	for (int i = 0; i < npix; i++) {
		float v;
		memcpy(&v, f + i, sizeof v);
		if (dst_d)
			dst_d[i] = v;
		if (dst_f)
			dst_f[i] = v;
	}
	return 0;
}

int store_reference_each(struct store *st, int64_t sweep_id, double *detector_theta, store_reference_fn fn,
			 void *ctx, struct acq_err *err)
{
	long long lo = 0, hi = 0;
	sqlite3_stmt *s = store_prep(st, "SELECT message FROM events WHERE sweep_id = ? AND kind = 'reference' "
				         "ORDER BY id DESC LIMIT 1", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	if (sqlite3_step(s) == SQLITE_ROW) {
		const char *m = (const char *)sqlite3_column_text(s, 0);
		const char *p = m ? strstr(m, "spectra ") : NULL;
		if (!p || sscanf(p, "spectra %lld-%lld", &lo, &hi) != 2)
			lo = hi = 0;
		double lt, dt, dp;
		const char *q = m ? strstr(m, "at (") : NULL;
		if (q && sscanf(q, "at (%lf, %lf, %lf)", &lt, &dt, &dp) == 3 && detector_theta)
			*detector_theta = dt;
	}
	sqlite3_finalize(s);
	if (lo <= 0 || hi < lo)
		return 0;
	s = store_prep(st, "SELECT kind, integration_ms, averages, npix, counts, stddev, saturation_mask, temperature_c "
		           "FROM spectra WHERE sweep_id = ? AND id BETWEEN ? AND ? ORDER BY id", err);
	if (!s)
		return -1;
	sqlite3_bind_int64(s, 1, sweep_id);
	sqlite3_bind_int64(s, 2, lo);
	sqlite3_bind_int64(s, 3, hi);
	struct store_ref_spectrum *r = malloc(sizeof *r);
	if (!r) {
		sqlite3_finalize(s);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	int n = 0, rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		const char *kind = (const char *)sqlite3_column_text(s, 0);
		int npix = sqlite3_column_int(s, 3);
		if (!kind || npix <= 0 || npix > SPECTRO_MAX_PIXELS || strlen(kind) >= sizeof r->kind)
			continue;
		snprintf(r->kind, sizeof r->kind, "%s", kind);
		r->integration_ms = sqlite3_column_double(s, 1);
		r->averages = sqlite3_column_int(s, 2);
		r->npix = npix;
		if (blob_floats(s, 4, npix, r->counts, NULL))
			continue;
		if (sqlite3_column_type(s, 5) == SQLITE_NULL)
			memset(r->stddev, 0, sizeof(float) * (size_t)npix);
		else if (blob_floats(s, 5, npix, NULL, r->stddev))
			continue;
		memset(r->saturated, 0, (size_t)npix);
		if (sqlite3_column_type(s, 6) != SQLITE_NULL && sqlite3_column_bytes(s, 6) == npix)
			memcpy(r->saturated, sqlite3_column_blob(s, 6), (size_t)npix);
		r->temperature_c = sqlite3_column_type(s, 7) == SQLITE_NULL ? NAN : sqlite3_column_double(s, 7);
		n++;
		if (fn(ctx, r))
			break;
	}
	sqlite3_finalize(s);
	free(r);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return store_db_err(st, err, "reading the reference");
	return n;
}

static json_t *floats_json(const void *blob, int nbytes)
{
	json_t *a = json_array();
	for (int i = 0; a && i + 4 <= nbytes; i += 4) {
		float v;
		memcpy(&v, (const char *)blob + i, 4);
		json_array_append_new(a, isfinite(v) ? json_real(v) : json_null());
	}
	return a;
}

json_t *store_spectrum_json(struct store *st, int64_t id, struct acq_err *err)
{
	sqlite3_stmt *s = store_prep(st, "SELECT s.id, s.sweep_id, s.point_id, s.kind, s.integration_ms, s.averages, s.npix, "
				         "s.counts, s.stddev, s.saturated_count, s.temperature_c, s.taken_at, m.model, m.serial, "
				         "m.c0, m.c1, m.c2, m.c3, m.c4 FROM spectra s LEFT JOIN spectrometers m ON "
				         "m.id = s.spectrometer_id WHERE s.id = ?", err);
	if (!s)
		return NULL;
	sqlite3_bind_int64(s, 1, id);
	int r = sqlite3_step(s);
	if (r != SQLITE_ROW) {
		if (r == SQLITE_DONE)
			acq_errf(err, ACQ_E_NOTFOUND, "no spectrum %lld", (long long)id);
		else
			store_db_err(st, err, "reading a spectrum");
		sqlite3_finalize(s);
		return NULL;
	}
	int npix = sqlite3_column_int(s, 6);
	json_t *counts = floats_json(sqlite3_column_blob(s, 7), sqlite3_column_bytes(s, 7));
	double peak = 0;
	size_t i;
	json_t *v;
	json_array_foreach(counts, i, v)
		if (json_is_number(v) && json_number_value(v) > peak)
			peak = json_number_value(v);
	json_t *o = json_pack("{s:I,s:s,s:f,s:i,s:i,s:o,s:i,s:f,s:f}", "id", (json_int_t)sqlite3_column_int64(s, 0),
			      "kind", (const char *)sqlite3_column_text(s, 3), "integration_ms", sqlite3_column_double(s, 4),
			      "averages", sqlite3_column_int(s, 5), "npix", npix, "counts", counts, "saturated",
			      sqlite3_column_int(s, 9), "taken_at", sqlite3_column_double(s, 11), "peak", peak);
	if (o) {
		json_object_set_new(o, "sweep", sqlite3_column_type(s, 1) == SQLITE_NULL ? json_null()
								 : json_integer(sqlite3_column_int64(s, 1)));
		json_object_set_new(o, "point", sqlite3_column_type(s, 2) == SQLITE_NULL ? json_null()
								 : json_integer(sqlite3_column_int64(s, 2)));
		json_object_set_new(o, "temperature_c", sqlite3_column_type(s, 10) == SQLITE_NULL
								? json_null() : json_real(sqlite3_column_double(s, 10)));
		if (sqlite3_column_type(s, 8) != SQLITE_NULL)
			json_object_set_new(o, "stddev", floats_json(sqlite3_column_blob(s, 8), sqlite3_column_bytes(s, 8)));
		if (sqlite3_column_type(s, 12) != SQLITE_NULL) {
			/* The spectrometer's wavelength polynomial (AvaSpec: λ = Σ c_k · pixel^k, nm). */
			double c[5];
			for (int k = 0; k < 5; k++)
				c[k] = sqlite3_column_double(s, 14 + k);
			json_t *wl = json_array();
			for (int p = 0; wl && p < npix; p++)
				json_array_append_new(wl, json_real(c[0] + p * (c[1] + p * (c[2] + p * (c[3] + p * c[4])))));
			json_object_set_new(o, "wavelength_nm", wl);
			json_object_set_new(o, "spectrometer", json_pack("{s:s,s:s}", "model",
									  (const char *)sqlite3_column_text(s, 12), "serial",
									  (const char *)sqlite3_column_text(s, 13)));
		}
	}
	sqlite3_finalize(s);
	if (!o)
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
	return o;
}
