/* nexus: NeXus/HDF5 export of a sweep through libhdf5 (streamed from the database, bounded memory): the sweep's
 * layout; the HDF5 objects are made by nexus_h5.c. */
#include "daemon/nexus.h"

#include <hdf5.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "acq_version.h"
#include "config/acq_out.h"
#include "daemon/nexus_h5.h"
#include "daemon/store_nexus.h"

static const char *const kinds[4] = { "sample", "dark", "reference", "beam" };

static void iso8601(double t, char *buf, size_t len)
{
	if (!isfinite(t)) {
		snprintf(buf, len, "%s", "");
		return;
	}
	time_t s = (time_t)floor(t);
	struct tm tm;
	gmtime_r(&s, &tm);
	char b[32];
	strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%S", &tm);
	snprintf(buf, len, "%s.%03dZ", b, (int)((t - floor(t)) * 1000));
}

/* ---- the sweep's parts ---- */
struct points_ctx {
	int64_t n, k;
	int64_t *id;
	int32_t *order;
	double *planned[4], *actual[3], *measured[4], *done;
	char **state;
	int64_t *cal_row; /* per point, the calibrated row or −1 (filled later) */
};

static int take_point(void *c, const struct storenx_point *p)
{
	struct points_ctx *x = c;
	if (x->k >= x->n)
		return 1;
	x->id[x->k] = p->id;
	x->order[x->k] = p->order_index;
	for (int a = 0; a < 4; a++) {
		x->planned[a][x->k] = p->planned[a];
		x->measured[a][x->k] = p->measured[a];
	}
	for (int a = 0; a < 3; a++)
		x->actual[a][x->k] = p->actual[a];
	x->done[x->k] = p->done_at;
	x->state[x->k] = strdup(p->state ? p->state : "");
	if (!x->state[x->k])
		return 1;
	x->k++;
	return 0;
}

struct spec_ctx {
	hid_t counts, stddev;
	int64_t n, k;
	int npix;
	int64_t *id, *point;
	double *tint, *temp, *taken;
	int32_t *avg, *sat;
	float *nanrow;
	int bad;
};

static int take_spectrum(void *c, const struct storenx_spectrum *s)
{
	struct spec_ctx *x = c;
	if (x->k >= x->n || s->npix != x->npix) {
		x->bad = 1;
		return 1;
	}
	if (nxh_write_row(x->counts, H5T_NATIVE_FLOAT, (hsize_t)x->k, (hsize_t)x->npix, s->counts) ||
	    nxh_write_row(x->stddev, H5T_NATIVE_FLOAT, (hsize_t)x->k, (hsize_t)x->npix, s->stddev ? s->stddev : x->nanrow))
		return 1;
	x->id[x->k] = s->id;
	x->point[x->k] = s->point_id;
	x->tint[x->k] = s->integration_ms;
	x->temp[x->k] = s->temperature_c;
	x->taken[x->k] = s->taken_at;
	x->avg[x->k] = s->averages;
	x->sat[x->k] = s->saturated_count;
	x->k++;
	return 0;
}

static int write_spectra(struct storenx *h, int64_t sweep, hid_t entry, int kind, int npix, int64_t *count,
			 struct acq_err *err)
{
	int64_t n;
	if (storenx_count(h, sweep, kinds[kind], &n, err))
		return -1;
	*count = n;
	char name[32];
	snprintf(name, sizeof name, "raw_%s", kinds[kind]);
	hid_t g = nxh_group(entry, name, "NXdata");
	if (g < 0)
		return acq_errf(err, ACQ_E_IO, "nexus: cannot create /entry/%s", name);
	int rc = -1;
	struct spec_ctx x = { .counts = -1, .stddev = -1, .n = n, .npix = npix };
	size_t m = n ? (size_t)n : 1;
	x.id = malloc(m * sizeof *x.id);
	x.point = malloc(m * sizeof *x.point);
	x.tint = malloc(m * sizeof *x.tint);
	x.temp = malloc(m * sizeof *x.temp);
	x.taken = malloc(m * sizeof *x.taken);
	x.avg = malloc(m * sizeof *x.avg);
	x.sat = malloc(m * sizeof *x.sat);
	x.nanrow = malloc((size_t)(npix > 0 ? npix : 1) * sizeof *x.nanrow);
	if (!x.id || !x.point || !x.tint || !x.temp || !x.taken || !x.avg || !x.sat || !x.nanrow) {
		acq_errf(err, ACQ_E_NOMEM, "nexus: out of memory");
		goto out;
	}
	for (int i = 0; i < npix; i++)
		x.nanrow[i] = NAN;
	hsize_t d2[2] = { (hsize_t)n, (hsize_t)(npix > 0 ? npix : 0) }, d1 = (hsize_t)n, dp = d2[1];
	x.counts = nxh_dset_num(g, "counts", H5T_NATIVE_FLOAT, 2, d2, NULL, "counts");
	x.stddev = nxh_dset_num(g, "counts_errors", H5T_NATIVE_FLOAT, 2, d2, NULL, "counts");
	if (x.counts < 0 || x.stddev < 0)
		goto h5fail;
	if (n && npix > 0) {
		int r = storenx_spectra(h, sweep, kinds[kind], take_spectrum, &x, err);
		if (r < 0)
			goto out;
		if (r || x.bad || x.k != n) {
			acq_errf(err, ACQ_E_INVAL, "nexus: %s spectra: %lld rows, %lld written, pixel count not %d in all",
				 kinds[kind], (long long)n, (long long)x.k, npix);
			goto out;
		}
	} else if (n) {
		acq_errf(err, ACQ_E_INVAL, "nexus: %lld %s spectra but the sweep names no spectrometer", (long long)n,
			 kinds[kind]);
		goto out;
	}
	int32_t *pix = malloc((size_t)(npix > 0 ? npix : 1) * sizeof *pix);
	if (!pix) {
		acq_errf(err, ACQ_E_NOMEM, "nexus: out of memory");
		goto out;
	}
	for (int i = 0; i < npix; i++)
		pix[i] = i;
	int bad = nxh_close_ok(nxh_dset_num(g, "pixel", H5T_NATIVE_INT32, 1, &dp, pix, NULL)) ||
		  nxh_close_ok(nxh_dset_num(g, "spectrum_id", H5T_NATIVE_INT64, 1, &d1, x.id, NULL)) ||
		  nxh_close_ok(nxh_dset_num(g, "point_id", H5T_NATIVE_INT64, 1, &d1, x.point, NULL)) ||
		  nxh_close_ok(nxh_dset_num(g, "integration_time", H5T_NATIVE_DOUBLE, 1, &d1, x.tint, "ms")) ||
		  nxh_close_ok(nxh_dset_num(g, "averages", H5T_NATIVE_INT32, 1, &d1, x.avg, NULL)) ||
		  nxh_close_ok(nxh_dset_num(g, "saturated_pixels", H5T_NATIVE_INT32, 1, &d1, x.sat, NULL)) ||
		  nxh_close_ok(nxh_dset_num(g, "temperature", H5T_NATIVE_DOUBLE, 1, &d1, x.temp, "degC")) ||
		  nxh_close_ok(nxh_dset_num(g, "time", H5T_NATIVE_DOUBLE, 1, &d1, x.taken, "s")) || nxh_attr_str(g, "signal", "counts") ||
		  nxh_attr_strs(g, "axes", 2, (const char *const[]){ ".", "pixel" }) || nxh_attr_int(g, "pixel_indices", 1);
	free(pix);
	if (bad)
		goto h5fail;
	rc = 0;
	goto out;
h5fail:
	acq_errf(err, ACQ_E_IO, "nexus: writing /entry/%s failed", name);
out:
	if (x.counts >= 0)
		H5Dclose(x.counts);
	if (x.stddev >= 0)
		H5Dclose(x.stddev);
	H5Gclose(g);
	free(x.id);
	free(x.point);
	free(x.tint);
	free(x.temp);
	free(x.taken);
	free(x.avg);
	free(x.sat);
	free(x.nanrow);
	return rc;
}

struct cal_ctx {
	hid_t brdf, sigma;
	int64_t n, k;
	int nwl, bad;
	int64_t *point;
};

static int take_cal(void *c, const struct storenx_calibrated *s)
{
	struct cal_ctx *x = c;
	if (x->k >= x->n || s->n != x->nwl) {
		x->bad = 1;
		return 1;
	}
	if (nxh_write_row(x->brdf, H5T_NATIVE_FLOAT, (hsize_t)x->k, (hsize_t)x->nwl, s->brdf) ||
	    nxh_write_row(x->sigma, H5T_NATIVE_FLOAT, (hsize_t)x->k, (hsize_t)x->nwl, s->sigma))
		return 1;
	x->point[x->k++] = s->point_id;
	return 0;
}

struct ev_ctx {
	int64_t n, k;
	double *at;
	char **kind, **device, **msg;
};

static int take_event(void *c, const struct storenx_event *e)
{
	struct ev_ctx *x = c;
	if (x->k >= x->n)
		return 1;
	x->at[x->k] = e->at;
	x->kind[x->k] = strdup(e->kind ? e->kind : "");
	x->device[x->k] = strdup(e->device ? e->device : "");
	x->msg[x->k] = strdup(e->message ? e->message : "");
	if (!x->kind[x->k] || !x->device[x->k] || !x->msg[x->k])
		return 1;
	x->k++;
	return 0;
}

struct dev_ctx {
	int64_t n, k;
	char **f[5];
};

static int take_device(void *c, const struct storenx_device *d)
{
	struct dev_ctx *x = c;
	if (x->k >= x->n)
		return 1;
	const char *v[5] = { d->name, d->vendor, d->model, d->serial, d->firmware };
	for (int i = 0; i < 5; i++)
		if (!(x->f[i][x->k] = strdup(v[i] ? v[i] : "")))
			return 1;
	x->k++;
	return 0;
}

static void free_strs(char **v, int64_t n)
{
	if (!v)
		return;
	for (int64_t i = 0; i < n; i++)
		free(v[i]);
	free(v);
}

static int h5_failed(struct acq_err *err)
{
	return acq_errf(err, ACQ_E_IO, "nexus: writing the HDF5 file failed (libhdf5)");
}

/* Close group g (if open) after its writes; 0, or -1 with err when a write (bad) or the close failed. */
static int group_done(hid_t g, int bad, struct acq_err *err)
{
	if (g >= 0 && H5Gclose(g) < 0)
		bad = 1;
	return bad ? h5_failed(err) : 0;
}

/* The file's root attributes and /entry with the sweep's identity, sample, configuration and plan; *entry open
 * on success (the caller closes it). The groups follow daemon/nexus.md in order, here and in the writers below. */
static int write_entry(hid_t file, int64_t sweep, const struct storenx_sweep *sw, hid_t *entry, struct acq_err *err)
{
	char t0[64], t1[64], tc[64];
	iso8601(sw->started_at, t0, sizeof t0);
	iso8601(sw->finished_at, t1, sizeof t1);
	iso8601(sw->created_at, tc, sizeof tc);
	hid_t e = -1, g = -1;
	if (nxh_attr_str(file, "NX_class", "NXroot") || nxh_attr_str(file, "creator", "acquisitiond acq-nexus " ACQ_VERSION) ||
	    nxh_attr_str(file, "HDF5_Version", H5_VERS_INFO) || (e = *entry = nxh_group(file, "entry", "NXentry")) < 0 ||
	    nxh_attr_str(file, "default", "entry") || nxh_attr_str(e, "default", "data") ||
	    nxh_dset_str(e, "title", sw->name) || nxh_dset_str(e, "start_time", t0[0] ? t0 : tc) ||
	    nxh_dset_str(e, "end_time", t1) || nxh_dset_str(e, "created_time", tc) || nxh_dset_str(e, "state", sw->state) ||
	    nxh_dset_str(e, "program_name", sw->software_version) ||
	    nxh_dset_str(e, "calibration_method", sw->calibration_method))
		return acq_errf(err, ACQ_E_IO, "nexus: writing /entry failed");
	int64_t sid = sweep;
	hsize_t one = 1;
	if (nxh_close_ok(nxh_dset_num(e, "sweep_id", H5T_NATIVE_INT64, 1, &one, &sid, NULL)))
		return h5_failed(err);
	/* sample, configuration and plan */
	if ((g = nxh_group(e, "sample", "NXsample")) < 0 || nxh_dset_str(g, "name", sw->name) || H5Gclose(g) < 0)
		goto h5fail;
	g = -1;
	if ((g = nxh_group(e, "configuration", "NXnote")) < 0 || nxh_dset_str(g, "type", "text/yaml") ||
	    nxh_dset_str(g, "description", "the daemon's configuration file when the sweep started") ||
	    nxh_dset_str(g, "data", sw->config_snapshot) || H5Gclose(g) < 0)
		goto h5fail;
	g = -1;
	if ((g = nxh_group(e, "plan", "NXnote")) < 0 || nxh_dset_str(g, "type", "text/yaml") ||
	    nxh_dset_str(g, "description", "the sampling plan as submitted") || nxh_dset_str(g, "data", sw->plan_text) ||
	    H5Gclose(g) < 0)
		goto h5fail;
	return 0;
h5fail:
	if (g >= 0)
		H5Gclose(g);
	return h5_failed(err);
}

/* /entry/instrument: the spectrometer (with its wavelength calibration) and the devices used (read into D). */
static int write_instrument(struct storenx *h, int64_t sweep, hid_t entry, const struct storenx_sweep *sw,
			    struct dev_ctx *D, struct acq_err *err)
{
	int rc = -1;
	hid_t g = -1, sub = -1;
	if ((g = nxh_group(entry, "instrument", "NXinstrument")) < 0 || (sub = nxh_group(g, "spectrometer", "NXdetector")) < 0)
		goto h5fail;
	if (sw->has_spectrometer) {
		hsize_t five = 5, np = (hsize_t)sw->npix, one = 1;
		double *lam = malloc((size_t)(sw->npix > 0 ? sw->npix : 1) * sizeof *lam);
		if (!lam) {
			acq_errf(err, ACQ_E_NOMEM, "nexus: out of memory");
			goto out;
		}
		for (int p = 0; p < sw->npix; p++) {
			double x = p, v = 0;
			for (int k = 4; k >= 0; k--)
				v = v * x + sw->sp_coef[k];
			lam[p] = v;
		}
		int32_t npix = sw->npix;
		hid_t cd = nxh_dset_num(sub, "wavelength_calibration", H5T_NATIVE_DOUBLE, 1, &five, sw->sp_coef, NULL);
		int bad = cd < 0 || nxh_attr_str(cd, "description", "lambda(p) = c0 + c1 p + c2 p^2 + c3 p^3 + c4 p^4 (nm)") ||
			  nxh_close_ok(cd) || nxh_close_ok(nxh_dset_num(sub, "pixel_wavelength", H5T_NATIVE_DOUBLE, 1, &np, lam, "nm")) ||
			  nxh_close_ok(nxh_dset_num(sub, "number_of_pixels", H5T_NATIVE_INT32, 1, &one, &npix, NULL)) ||
			  nxh_dset_str(sub, "model", sw->sp_model) || nxh_dset_str(sub, "serial_number", sw->sp_serial) ||
			  nxh_dset_str(sub, "firmware", sw->sp_firmware) || nxh_dset_str(sub, "nonlinearity", sw->sp_nonlinearity);
		free(lam);
		if (bad)
			goto h5fail;
	}
	H5Gclose(sub);
	sub = -1;
	if (storenx_count(h, sweep, "devices", &D->n, err))
		goto out;
	for (int i = 0; i < 5; i++)
		if (!(D->f[i] = calloc((size_t)(D->n ? D->n : 1), sizeof(char *)))) {
			acq_errf(err, ACQ_E_NOMEM, "nexus: out of memory");
			goto out;
		}
	if (storenx_devices(h, sweep, take_device, D, err) < 0)
		goto out;
	if ((sub = nxh_group(g, "devices", "NXcollection")) < 0 ||
	    nxh_dset_strs(sub, "name", (size_t)D->k, (const char *const *)D->f[0]) ||
	    nxh_dset_strs(sub, "vendor", (size_t)D->k, (const char *const *)D->f[1]) ||
	    nxh_dset_strs(sub, "model", (size_t)D->k, (const char *const *)D->f[2]) ||
	    nxh_dset_strs(sub, "serial_number", (size_t)D->k, (const char *const *)D->f[3]) ||
	    nxh_dset_strs(sub, "firmware", (size_t)D->k, (const char *const *)D->f[4]))
		goto h5fail;
	rc = 0;
	goto out;
h5fail:
	h5_failed(err);
out:
	if (sub >= 0)
		H5Gclose(sub);
	if (g >= 0)
		H5Gclose(g);
	return rc;
}

/* /entry/events: the sweep's event log (read into E). */
static int write_events(struct storenx *h, int64_t sweep, hid_t entry, struct ev_ctx *E, struct acq_err *err)
{
	if (storenx_count(h, sweep, "events", &E->n, err))
		return -1;
	size_t en = E->n ? (size_t)E->n : 1;
	E->at = malloc(en * sizeof *E->at);
	E->kind = calloc(en, sizeof *E->kind);
	E->device = calloc(en, sizeof *E->device);
	E->msg = calloc(en, sizeof *E->msg);
	if (!E->at || !E->kind || !E->device || !E->msg)
		return acq_errf(err, ACQ_E_NOMEM, "nexus: out of memory");
	if (storenx_events(h, sweep, take_event, E, err) < 0)
		return -1;
	hsize_t d1 = (hsize_t)E->k;
	hid_t g = nxh_group(entry, "events", "NXcollection");
	int bad = g < 0 || nxh_close_ok(nxh_dset_num(g, "time", H5T_NATIVE_DOUBLE, 1, &d1, E->at, "s")) ||
		  nxh_dset_strs(g, "kind", (size_t)E->k, (const char *const *)E->kind) ||
		  nxh_dset_strs(g, "device", (size_t)E->k, (const char *const *)E->device) ||
		  nxh_dset_strs(g, "message", (size_t)E->k, (const char *const *)E->msg);
	return group_done(g, bad, err);
}

/* /entry/points: planned, measured and actual angles, state and time of every point (read into P). */
static int write_points(struct storenx *h, int64_t sweep, hid_t entry, struct points_ctx *P, struct acq_err *err)
{
	if (storenx_count(h, sweep, "points", &P->n, err))
		return -1;
	size_t pn = P->n ? (size_t)P->n : 1;
	P->id = malloc(pn * sizeof *P->id);
	P->order = malloc(pn * sizeof *P->order);
	P->done = malloc(pn * sizeof *P->done);
	P->state = calloc(pn, sizeof *P->state);
	int okp = P->id && P->order && P->done && P->state;
	for (int a = 0; a < 4; a++)
		okp = okp && (P->planned[a] = malloc(pn * sizeof(double))) && (P->measured[a] = malloc(pn * sizeof(double)));
	for (int a = 0; a < 3; a++)
		okp = okp && (P->actual[a] = malloc(pn * sizeof(double)));
	if (!okp)
		return acq_errf(err, ACQ_E_NOMEM, "nexus: out of memory");
	if (storenx_points(h, sweep, take_point, P, err) < 0)
		return -1;
	hsize_t d1 = (hsize_t)P->k;
	static const char *const pn_[4] = { "theta_i", "phi_i", "theta_o", "phi_o" };
	static const char *const an_[3] = { "laser_theta", "detector_theta", "detector_phi" };
	hid_t g = nxh_group(entry, "points", "NXcollection");
	int bad = g < 0 || nxh_close_ok(nxh_dset_num(g, "point_id", H5T_NATIVE_INT64, 1, &d1, P->id, NULL)) ||
		  nxh_close_ok(nxh_dset_num(g, "order_index", H5T_NATIVE_INT32, 1, &d1, P->order, NULL)) ||
		  nxh_close_ok(nxh_dset_num(g, "done_time", H5T_NATIVE_DOUBLE, 1, &d1, P->done, "s")) ||
		  nxh_dset_strs(g, "state", (size_t)P->k, (const char *const *)P->state);
	for (int a = 0; a < 4 && !bad; a++) {
		char nm[32];
		snprintf(nm, sizeof nm, "planned_%s", pn_[a]);
		bad = nxh_close_ok(nxh_dset_num(g, nm, H5T_NATIVE_DOUBLE, 1, &d1, P->planned[a], "deg"));
		snprintf(nm, sizeof nm, "measured_%s", pn_[a]);
		bad = bad || nxh_close_ok(nxh_dset_num(g, nm, H5T_NATIVE_DOUBLE, 1, &d1, P->measured[a], "deg"));
	}
	for (int a = 0; a < 3 && !bad; a++) {
		char nm[32];
		snprintf(nm, sizeof nm, "actual_%s", an_[a]);
		bad = nxh_close_ok(nxh_dset_num(g, nm, H5T_NATIVE_DOUBLE, 1, &d1, P->actual[a], "deg"));
	}
	return group_done(g, bad, err);
}

/* /entry/data: calibrated f and sigma (read into C) with the planned angles of their points (from P). */
static int write_data(struct storenx *h, int64_t sweep, hid_t entry, const struct storenx_sweep *sw,
		      const struct points_ctx *P, struct cal_ctx *C, struct acq_err *err)
{
	if (storenx_count(h, sweep, "calibrated", &C->n, err))
		return -1;
	C->nwl = sw->ngrid;
	if (C->n && !sw->grid)
		return acq_errf(err, ACQ_E_INVAL, "nexus: sweep %lld has calibrated samples but no wavelength grid",
				(long long)sweep);
	C->point = malloc((size_t)(C->n ? C->n : 1) * sizeof *C->point);
	if (!C->point)
		return acq_errf(err, ACQ_E_NOMEM, "nexus: out of memory");
	int rc = -1;
	double *ang[4] = { NULL };
	hsize_t d2[2] = { (hsize_t)C->n, (hsize_t)C->nwl }, dw = (hsize_t)C->nwl, d1 = (hsize_t)C->n;
	hid_t g = nxh_group(entry, "data", "NXdata");
	if (g < 0 || nxh_attr_str(g, "signal", "brdf") || nxh_attr_strs(g, "axes", 2, (const char *const[]){ ".", "wavelength" }) ||
	    nxh_attr_int(g, "wavelength_indices", 1))
		goto h5fail;
	C->brdf = nxh_dset_num(g, "brdf", H5T_NATIVE_FLOAT, 2, d2, NULL, "1/sr");
	C->sigma = nxh_dset_num(g, "brdf_errors", H5T_NATIVE_FLOAT, 2, d2, NULL, "1/sr");
	if (C->brdf < 0 || C->sigma < 0 || nxh_attr_str(C->sigma, "description", "standard uncertainty (1 sigma)"))
		goto h5fail;
	if (C->n) {
		int r = storenx_calibrated(h, sweep, take_cal, C, err);
		if (r < 0)
			goto out;
		if (r || C->bad || C->k != C->n) {
			acq_errf(err, ACQ_E_INVAL, "nexus: calibrated rows do not all match the %d-wavelength grid", C->nwl);
			goto out;
		}
	}
	for (int a = 0; a < 4; a++)
		if (!(ang[a] = malloc((size_t)(C->n ? C->n : 1) * sizeof(double)))) {
			acq_errf(err, ACQ_E_NOMEM, "nexus: out of memory");
			goto out;
		}
	for (int64_t i = 0; i < C->n; i++) { /* the planned angles of each calibrated point */
		int64_t j = 0;
		while (j < P->k && P->id[j] != C->point[i])
			j++;
		for (int a = 0; a < 4; a++)
			ang[a][i] = j < P->k ? P->planned[a][j] : NAN;
	}
	static const char *const an[4] = { "theta_i", "phi_i", "theta_o", "phi_o" };
	float dummy = 0;
	int bad = nxh_close_ok(nxh_dset_num(g, "wavelength", H5T_NATIVE_FLOAT, 1, &dw,
				    sw->grid ? (void *)sw->grid : (void *)&dummy, "nm")) ||
		  nxh_close_ok(nxh_dset_num(g, "point_id", H5T_NATIVE_INT64, 1, &d1, C->point, NULL));
	for (int a = 0; a < 4 && !bad; a++)
		bad = nxh_close_ok(nxh_dset_num(g, an[a], H5T_NATIVE_DOUBLE, 1, &d1, ang[a], "deg"));
	if (bad)
		goto h5fail;
	rc = 0;
out:
	for (int a = 0; a < 4; a++)
		free(ang[a]);
	if (g >= 0)
		H5Gclose(g);
	return rc;
h5fail:
	h5_failed(err);
	goto out;
}

/* Everything of daemon/nexus.md, group after group; the raw spectra through write_spectra. */
static int write_all(struct storenx *h, int64_t sweep, hid_t file, struct nexus_stats *st, struct acq_err *err)
{
	struct storenx_sweep sw;
	if (storenx_sweep_get(h, sweep, &sw, err))
		return -1;
	int rc = -1;
	hid_t entry = -1;
	struct points_ctx P = { 0 };
	struct cal_ctx C = { .brdf = -1, .sigma = -1 };
	struct ev_ctx E = { 0 };
	struct dev_ctx D = { 0 };
	if (write_entry(file, sweep, &sw, &entry, err) || write_instrument(h, sweep, entry, &sw, &D, err) ||
	    write_points(h, sweep, entry, &P, err))
		goto out;
	for (int k = 0; k < 4; k++) /* raw spectra by kind */
		if (write_spectra(h, sweep, entry, k, sw.has_spectrometer ? sw.npix : 0, &st->spectra[k], err))
			goto out;
	if (write_data(h, sweep, entry, &sw, &P, &C, err) || write_events(h, sweep, entry, &E, err))
		goto out;
	st->points = P.k;
	st->calibrated = C.k;
	st->events = E.k;
	st->devices = D.k;
	st->npix = sw.npix;
	st->nwl = sw.ngrid;
	rc = 0;
out:
	if (C.brdf >= 0)
		H5Dclose(C.brdf);
	if (C.sigma >= 0)
		H5Dclose(C.sigma);
	if (entry >= 0)
		H5Gclose(entry);
	free(P.id);
	free(P.order);
	free(P.done);
	free_strs(P.state, P.k);
	for (int a = 0; a < 4; a++) {
		free(P.planned[a]);
		free(P.measured[a]);
	}
	for (int a = 0; a < 3; a++)
		free(P.actual[a]);
	free(C.point);
	free(E.at);
	free_strs(E.kind, E.k);
	free_strs(E.device, E.k);
	free_strs(E.msg, E.k);
	for (int i = 0; i < 5; i++)
		free_strs(D.f[i], D.k);
	storenx_sweep_free(&sw);
	return rc;
}

int nexus_export(const char *db_path, int64_t sweep, const char *out_path, struct nexus_stats *st,
		 struct acq_err *err)
{
	struct nexus_stats dummy;
	if (!st)
		st = &dummy;
	memset(st, 0, sizeof *st);
	struct storenx *h = NULL;
	if (storenx_open(db_path, &h, err))
		return -1;
	H5Eset_auto2(H5E_DEFAULT, NULL, NULL); /* libhdf5 would print its error stack: errors come back here */
	struct acq_out o; /* HDF5 seeks: a regular file only, written beside the target and renamed at the end */
	int rc = -1;
	if (acq_out_open(&o, out_path, ACQ_OUT_SEEK, err)) {
		acq_err_prefix(err, "nexus: ");
		goto out;
	}
	hid_t f = H5Fcreate(o.name, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
	if (f < 0) {
		acq_errf(err, ACQ_E_IO, "nexus: cannot create %s", o.name);
		acq_out_abort(&o);
		goto out;
	}
	if (write_all(h, sweep, f, st, err)) {
		H5Fclose(f);
		acq_out_abort(&o);
		goto out;
	}
	if (H5Fclose(f) < 0) {
		acq_out_abort(&o);
		acq_errf(err, ACQ_E_IO, "nexus: cannot finish %s", out_path);
		goto out;
	}
	if (acq_out_commit(&o, err)) {
		acq_err_prefix(err, "nexus: ");
		goto out;
	}
	rc = 0;
out:
	storenx_close(h);
	return rc;
}
