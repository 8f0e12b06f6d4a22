/* merl: MERL binary BRDF table, written from an RGB BRDF callback and read back with the reference lookup. */
#include "recon/merl.h"
#include "recon/pool.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "config/acq_out.h"

const double merl_scale[3] = { 1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0 };

void merl_write_opts_default(struct merl_write_opts *o)
{
	o->threads = 1;
	o->clamp_min = 0;
}

/* ---- geometry ------------------------------------------------------------------------------------ */

/* Rotate v about z by angle a (counter-clockwise seen from +z). */
static void rot_z(const double v[3], double a, double out[3])
{
	double c = cos(a), s = sin(a);
	double x = v[0] * c - v[1] * s, y = v[0] * s + v[1] * c;
	out[0] = x;
	out[1] = y;
	out[2] = v[2];
}

/* Rotate v about y by angle a (right-handed). */
static void rot_y(const double v[3], double a, double out[3])
{
	double c = cos(a), s = sin(a);
	double x = v[0] * c + v[2] * s, z = -v[0] * s + v[2] * c;
	out[0] = x;
	out[1] = v[1];
	out[2] = z;
}

static double clamp1(double v)
{
	return v > 1 ? 1 : v < -1 ? -1 : v;
}

void merl_half_diff(const double wi[3], const double wo[3], double *theta_h, double *phi_h, double *theta_d,
		    double *phi_d)
{
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] };
	double l = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	if (!(l > 0)) {
		h[0] = h[1] = 0;
		h[2] = l = 1;
	}
	for (int i = 0; i < 3; i++)
		h[i] /= l;
	double th = acos(clamp1(h[2])), ph = atan2(h[1], h[0]);
	double d[3];
	rot_z(wi, -ph, d);
	rot_y(d, -th, d);
	*theta_h = th;
	*phi_h = ph;
	*theta_d = acos(clamp1(d[2]));
	*phi_d = atan2(d[1], d[0]);
}

static int clampi(int v, int lo, int hi)
{
	return v < lo ? lo : v > hi ? hi : v;
}

/* floor(x) as int for finite x of any size, NaN → 0 (the reference casts; we must not overflow). */
static int index_of(double x, int hi)
{
	if (!(x > 0))
		return 0;
	if (x >= hi)
		return hi;
	return (int)x;
}

int merl_index(double theta_h, double theta_d, double phi_d, int *ith, int *itd, int *ipd)
{
	int a = theta_h <= 0 || !isfinite(theta_h) ? 0 : index_of(sqrt(theta_h / (M_PI / 2)) * MERL_N_THETA_H,
								   MERL_N_THETA_H - 1);
	int b = index_of(theta_d / (M_PI / 2) * MERL_N_THETA_D, MERL_N_THETA_D - 1);
	if (phi_d < 0)
		phi_d += M_PI;
	int c = index_of(phi_d / M_PI * MERL_N_PHI_D, MERL_N_PHI_D - 1);
	a = clampi(a, 0, MERL_N_THETA_H - 1);
	b = clampi(b, 0, MERL_N_THETA_D - 1);
	c = clampi(c, 0, MERL_N_PHI_D - 1);
	if (ith)
		*ith = a;
	if (itd)
		*itd = b;
	if (ipd)
		*ipd = c;
	return c + MERL_N_PHI_D * b + MERL_N_PHI_D * MERL_N_THETA_D * a;
}

int merl_dirs_from_trig(const double th_sc[2], const double td_sc[2], const double pd_sc[2], double wi[3],
			double wo[3])
{
	double d[3] = { td_sc[0] * pd_sc[1], td_sc[0] * pd_sc[0], td_sc[1] };
	double h[3] = { th_sc[0], 0, th_sc[1] }; /* φh = 0 */
	/* rot_y(d, θh): then Rz(φh = 0), the identity */
	double c = th_sc[1], sn = th_sc[0];
	wi[0] = d[0] * c + d[2] * sn;
	wi[1] = d[1];
	wi[2] = -d[0] * sn + d[2] * c;
	double k = 2 * (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]);
	for (int i = 0; i < 3; i++)
		wo[i] = k * h[i] - wi[i];
	return wi[2] > 0 && wo[2] > 0;
}

int merl_dirs_from_angles(double theta_h, double theta_d, double phi_d, double wi[3], double wo[3])
{
	double th[2] = { sin(theta_h), cos(theta_h) }, td[2] = { sin(theta_d), cos(theta_d) },
	       pd[2] = { sin(phi_d), cos(phi_d) };
	return merl_dirs_from_trig(th, td, pd, wi, wo);
}

void merl_cell_angles(int ith, int itd, int ipd, double *theta_h, double *theta_d, double *phi_d)
{
	double u = (ith + 0.5) / MERL_N_THETA_H;
	*theta_h = u * u * (M_PI / 2);
	*theta_d = (itd + 0.5) * (M_PI / 2) / MERL_N_THETA_D;
	*phi_d = (ipd + 0.5) * M_PI / MERL_N_PHI_D;
}

int merl_cell_dirs(int ith, int itd, int ipd, double wi[3], double wo[3])
{
	if (ith < 0 || ith >= MERL_N_THETA_H || itd < 0 || itd >= MERL_N_THETA_D || ipd < 0 || ipd >= MERL_N_PHI_D)
		return -1;
	double th, td, pd;
	merl_cell_angles(ith, itd, ipd, &th, &td, &pd);
	return merl_dirs_from_angles(th, td, pd, wi, wo);
}

/* ---- writer -------------------------------------------------------------------------------------- */

struct merl_rows {
	merl_rgb_fn fn;
	void *ctx;
	double *data;
	double clamp_min;
};

/* One θh row of cells (a job of the pool): values scaled to the file's units; a callback failure or a
 * non-finite value stops the write with the cell and directions in the message. */
static int eval_row(void *arg, int worker, size_t row, struct acq_err *err)
{
	(void)worker;
	const struct merl_rows *j = arg;
	int a = (int)row;
	for (int b = 0; b < MERL_N_THETA_D; b++) {
		for (int c = 0; c < MERL_N_PHI_D; c++) {
			size_t flat = (size_t)c + MERL_N_PHI_D * (size_t)b + MERL_N_PHI_D * MERL_N_THETA_D * (size_t)a;
			double wi[3], wo[3], rgb[3] = { 0, 0, 0 };
			if (merl_cell_dirs(a, b, c, wi, wo) != 1) {
				for (int k = 0; k < 3; k++)
					j->data[k * (size_t)MERL_N_CELLS + flat] = MERL_NO_DATA;
				continue;
			}
			int rc = j->fn(j->ctx, wi, wo, rgb);
			double st[3];
			int bad = rc != 0 ? 1 : 0;
			for (int k = 0; k < 3 && !bad; k++) {
				double v = rgb[k] < j->clamp_min ? j->clamp_min : rgb[k];
				st[k] = v / merl_scale[k]; /* NaN stays NaN; a huge value overflows to Inf */
				if (!isfinite(rgb[k]) || !isfinite(st[k]))
					bad = 2;
			}
			if (bad == 1)
				return acq_errf(err, ACQ_E_NUMERIC,
						"merl: BRDF callback failed (%d) at cell (%d, %d, %d), wi (%.4f, %.4f, %.4f) wo "
						"(%.4f, %.4f, %.4f)",
						rc, a, b, c, wi[0], wi[1], wi[2], wo[0], wo[1], wo[2]);
			if (bad)
				return acq_errf(err, ACQ_E_NUMERIC,
						"merl: BRDF callback returned a non-finite or too large value (%g, %g, %g) at cell "
						"(%d, %d, %d), wi (%.4f, %.4f, %.4f) wo (%.4f, %.4f, %.4f)",
						rgb[0], rgb[1], rgb[2], a, b, c, wi[0], wi[1], wi[2], wo[0], wo[1], wo[2]);
			for (int k = 0; k < 3; k++)
				j->data[k * (size_t)MERL_N_CELLS + flat] = st[k];
		}
	}
	return 0;
}

static void put_le64(unsigned char *p, double v)
{
	uint64_t u;
	memcpy(&u, &v, 8);
	for (int i = 0; i < 8; i++)
		p[i] = (unsigned char)(u >> (8 * i));
}

static double get_le64(const unsigned char *p)
{
	uint64_t u = 0;
	for (int i = 0; i < 8; i++)
		u |= (uint64_t)p[i] << (8 * i);
	double v;
	memcpy(&v, &u, 8);
	return v;
}

static void put_le32(unsigned char *p, int32_t v)
{
	uint32_t u = (uint32_t)v;
	for (int i = 0; i < 4; i++)
		p[i] = (unsigned char)(u >> (8 * i));
}

static int32_t get_le32(const unsigned char *p)
{
	uint32_t u = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
	return (int32_t)u;
}

/* Write data (3 × MERL_N_CELLS stored values) to fd with the header, little-endian. */
static int write_all(int fd, const double *data, const char *tmp, struct acq_err *err)
{
	enum { CHUNK = 8192 };
	unsigned char buf[CHUNK * 8];
	unsigned char hdr[12];
	put_le32(hdr, MERL_N_THETA_H);
	put_le32(hdr + 4, MERL_N_THETA_D);
	put_le32(hdr + 8, MERL_N_PHI_D);
	size_t total = 3 * (size_t)MERL_N_CELLS;
	for (size_t off = 0, first = 1; off < total || first; first = 0) {
		const unsigned char *p = hdr;
		size_t len = sizeof(hdr);
		if (!first) {
			size_t n = total - off < CHUNK ? total - off : CHUNK;
			for (size_t i = 0; i < n; i++)
				put_le64(buf + 8 * i, data[off + i]);
			off += n;
			p = buf;
			len = n * 8;
		}
		while (len > 0) {
			ssize_t w = write(fd, p, len);
			if (w < 0 && errno == EINTR)
				continue;
			if (w <= 0)
				return acq_errf(err, ACQ_E_IO, "merl: writing %s: %s", tmp,
						w < 0 ? strerror(errno) : "short write");
			p += w;
			len -= (size_t)w;
		}
	}
	return 0;
}

/* Write data (3 × MERL_N_CELLS stored values) to path through config/acq_out (temporary file in the same folder,
 * fsync, rename; a device or FIFO in place); the old file is left as it was on failure. */
static int write_atomic(const char *path, const double *data, struct acq_err *err)
{
	struct acq_out o;
	if (acq_out_open(&o, path, 0, err))
		return acq_err_prefix(err, "merl: ");
	if (write_all(o.fd, data, path, err) != 0) {
		acq_out_abort(&o);
		return -1;
	}
	return acq_out_commit(&o, err) ? acq_err_prefix(err, "merl: ") : 0;
}

int merl_write_table(const char *path, const struct merl_table *t, struct acq_err *err)
{
	if (!path || !*path || !t || !t->data)
		return acq_errf(err, ACQ_E_INVAL, "merl: no output path or no table");
	for (size_t i = 0; i < 3 * (size_t)MERL_N_CELLS; i++) {
		double v = t->data[i];
		if (!isfinite(v) || (v < 0 && v != MERL_NO_DATA))
			return acq_errf(err, ACQ_E_NUMERIC, "merl: table value %g at cell %zu of channel %zu is not finite, "
					"not >= 0 and not MERL_NO_DATA", v, i % MERL_N_CELLS, i / MERL_N_CELLS);
	}
	return write_atomic(path, t->data, err);
}

int merl_write_ex(const char *path, merl_rgb_fn fn, void *ctx, const struct merl_write_opts *o,
		  struct acq_err *err)
{
	struct merl_write_opts def;
	merl_write_opts_default(&def);
	if (!o)
		o = &def;
	if (!path || !*path || !fn)
		return acq_errf(err, ACQ_E_INVAL, "merl: no output path or no callback");
	if (o->threads < 1 || o->threads > 16 || !isfinite(o->clamp_min) || o->clamp_min < 0)
		return acq_errf(err, ACQ_E_INVAL, "merl: threads must be 1..16 (got %d) and clamp_min finite, >= 0 (got %g)",
				o->threads, o->clamp_min);
	double *data = malloc(3 * (size_t)MERL_N_CELLS * sizeof(*data));
	if (!data)
		return acq_errf(err, ACQ_E_NOMEM, "merl: out of memory for the table (%lld bytes)", MERL_FILE_SIZE);

	int rc = -1;
	struct merl_rows rows = { .fn = fn, .ctx = ctx, .data = data, .clamp_min = o->clamp_min };
	if (pool_run(o->threads, MERL_N_THETA_H, eval_row, &rows, NULL, err) != 0)
		goto out;
	if (write_atomic(path, data, err) != 0)
		goto out;
	rc = 0;
out:
	free(data);
	return rc;
}

int merl_write(const char *path, merl_rgb_fn fn, void *ctx, struct acq_err *err)
{
	return merl_write_ex(path, fn, ctx, NULL, err);
}

/* ---- reader -------------------------------------------------------------------------------------- */

int merl_read(const char *path, struct merl_table *t, struct acq_err *err)
{
	if (!t)
		return acq_errf(err, ACQ_E_INVAL, "merl: no table");
	t->data = NULL;
	if (!path)
		return acq_errf(err, ACQ_E_INVAL, "merl: no path");
	int rc = -1;
	unsigned char *buf = NULL;
	FILE *f = fopen(path, "rb");
	if (!f)
		return acq_errf(err, errno == ENOENT ? ACQ_E_NOTFOUND : ACQ_E_IO, "merl: cannot open %s: %s", path,
				strerror(errno));
	struct stat sb;
	if (fstat(fileno(f), &sb) != 0) {
		acq_errf(err, ACQ_E_IO, "merl: %s: %s", path, strerror(errno));
		goto out;
	}
	unsigned char hdr[12];
	if (fread(hdr, 1, sizeof(hdr), f) != sizeof(hdr)) {
		acq_errf(err, ACQ_E_PROTO, "merl: %s: file too short for the header (%lld bytes)", path,
			 (long long)sb.st_size);
		goto out;
	}
	int32_t n0 = get_le32(hdr), n1 = get_le32(hdr + 4), n2 = get_le32(hdr + 8);
	if (n0 != MERL_N_THETA_H || n1 != MERL_N_THETA_D || n2 != MERL_N_PHI_D) {
		acq_errf(err, ACQ_E_PROTO, "merl: %s: header is %d %d %d, expected 90 90 180", path, (int)n0, (int)n1,
			 (int)n2);
		goto out;
	}
	if ((long long)sb.st_size != MERL_FILE_SIZE) {
		acq_errf(err, ACQ_E_PROTO, "merl: %s: size %lld bytes, expected %lld", path, (long long)sb.st_size,
			 MERL_FILE_SIZE);
		goto out;
	}
	size_t total = 3 * (size_t)MERL_N_CELLS, chunk = 65536;
	buf = malloc(chunk * 8);
	t->data = malloc(total * sizeof(double));
	if (!buf || !t->data) {
		acq_errf(err, ACQ_E_NOMEM, "merl: out of memory reading %s", path);
		goto out;
	}
	for (size_t off = 0; off < total; off += chunk) {
		size_t n = total - off < chunk ? total - off : chunk;
		if (fread(buf, 8, n, f) != n) {
			acq_errf(err, ACQ_E_PROTO, "merl: %s: truncated body", path);
			goto out;
		}
		for (size_t i = 0; i < n; i++) {
			double v = get_le64(buf + 8 * i);
			if (!isfinite(v)) {
				acq_errf(err, ACQ_E_PROTO, "merl: %s: non-finite value at channel %zu cell %zu", path,
					 (off + i) / MERL_N_CELLS, (off + i) % MERL_N_CELLS);
				goto out;
			}
			t->data[off + i] = v;
		}
	}
	rc = 0;
out:
	if (rc != 0) {
		free(t->data);
		t->data = NULL;
	}
	free(buf);
	fclose(f);
	return rc;
}

void merl_free(struct merl_table *t)
{
	if (!t)
		return;
	free(t->data);
	t->data = NULL;
}

static int unit_up(const double v[3], double out[3])
{
	if (!isfinite(v[0]) || !isfinite(v[1]) || !isfinite(v[2]))
		return -1;
	double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
	if (!(l > 0) || !isfinite(l))
		return -1;
	for (int i = 0; i < 3; i++)
		out[i] = v[i] / l;
	return out[2] > 0 ? 0 : -1;
}

int merl_lookup(const struct merl_table *t, const double wi[3], const double wo[3], double rgb[3])
{
	double a[3], b[3];
	rgb[0] = rgb[1] = rgb[2] = 0;
	if (!t || !t->data || unit_up(wi, a) != 0 || unit_up(wo, b) != 0)
		return -1;
	double th, ph, td, pd;
	merl_half_diff(a, b, &th, &ph, &td, &pd);
	size_t flat = (size_t)merl_index(th, td, pd, NULL, NULL, NULL);
	int nodata = 0;
	for (int c = 0; c < 3; c++) {
		double v = t->data[(size_t)c * MERL_N_CELLS + flat];
		if (v < 0)
			nodata = 1;
		rgb[c] = v * merl_scale[c];
	}
	return nodata;
}

int merl_table_fn(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	if (merl_lookup(ctx, wi, wo, rgb) != 0)
		rgb[0] = rgb[1] = rgb[2] = 0;
	return 0;
}
