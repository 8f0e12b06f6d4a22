/* rmodel: the versioned binary model file of brdf-recon (write, read, validate). */
#include "recon/recon.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "config/acq_out.h"
#include "recon/csvio.h"

/*
 * Model file, version 2, or 4 for a two-lobe trend (version 1 files, without the trend block, are still read: trend
 * none; version 3, session 7's coat basis, is refused: its coefficients mean other terms, refit the samples). All
 * integers unsigned little-endian, all reals IEEE-754 binary64 little-endian, no padding:
 *
 *   magic       8 bytes  "BRDFRBF\n"
 *   version     u32      2; 4 when the trend has two roughnesses (coat); a one-lobe model stays version 2
 *   kernel      u32      0 wendland, 1 exp, 2 gauss, 3 paper          (rbf.h)
 *   transform   u32      0 log, 1 sqrt                                 (recon.h)
 *   flags       u32      0 (reserved; bit 0 would mark an anisotropic model)
 *   n           u64      sample directions (1 .. 100000)
 *   nwl         u64      wavelengths (1 .. 100000), n·nwl ≤ 1e8
 *   ntab        u64      albedo-table nodes (2 .. 10000)
 *   shape, eta, alb_margin, loo_rms, rcond      5 × f64
 *   wl[nwl] eps[nwl] mu[nwl]                   f64 (nm strictly increasing; eps ≥ 0)
 *   ang[n·4]                                   f64 θi, φi, θo, φo radians (θ ∈ [0, π/2])
 *   lam[n]                                     f64 > 0, smoothing pattern
 *   w[nwl·n] g[nwl·n] gsig[nwl·n]              f64 channel-major: weights, data, uncertainties (≥ 0)
 *   tab_theta[ntab]                            f64 increasing, 0 to π/2
 *   tab_alb[(ntab−1)·nwl]                      f64 ≥ 0, albedo upper bounds
 *   trend       u32      0 none, 1 ggx, 2 phong, 3 sheen, 4 rough, 5 coat (trend.h; version ≥ 2; coat: 4 only)
 *   trend_alpha f64      the trend's roughness in [0.005, 1] (trend.h), 0 (none)
 *   trend_alpha2 f64     version 4 only: the coat's second (base) roughness, in [2·trend_alpha, 1]
 *   tcoef[nwl·5]                               f64 ≥ 0, trend coefficients (TREND_NB; all 0 for none)
 *   meta_len    u32      ≤ 65535, then meta_len bytes of UTF-8 "key=value\n" text (no NUL)
 *   checksum    u64      FNV-1a 64 of every preceding byte
 *
 * The file size must equal what the header implies. Every real must be finite. The canonical centres are
 * recomputed from ang with rbf_canon (bit-identical to the fit).
 */
#define MAGIC "BRDFRBF\n"
#define VERSION 2u
#define VERSION_2LOBE 4u /* written only for a trend with two roughnesses (3: session 7's coat basis, refused) */

static int little_endian(void)
{
	const uint16_t one = 1;
	unsigned char b;
	memcpy(&b, &one, 1);
	return b == 1;
}

static uint64_t fnv1a(uint64_t h, const void *p, size_t n)
{
	const unsigned char *c = p;
	for (size_t i = 0; i < n; i++) {
		h ^= c[i];
		h *= 0x100000001b3ull;
	}
	return h;
}
#define FNV_INIT 0xcbf29ce484222325ull

struct wr {
	FILE *f;
	uint64_t h;
	int bad;
};

static void put(struct wr *w, const void *p, size_t n)
{
	if (w->bad)
		return;
	if (n && fwrite(p, 1, n, w->f) != n)
		w->bad = 1;
	w->h = fnv1a(w->h, p, n);
}

static void put_u32(struct wr *w, uint32_t v)
{
	put(w, &v, 4);
}

static void put_u64(struct wr *w, uint64_t v)
{
	put(w, &v, 8);
}

static int all_finite(const double *v, size_t n)
{
	for (size_t i = 0; i < n; i++)
		if (!isfinite(v[i]))
			return 0;
	return 1;
}

int recon_model_save(const struct recon_model *m, const char *path, struct acq_err *err)
{
	if (!little_endian())
		return acq_errf(err, ACQ_E_UNSUPPORTED, "model: big-endian hosts are not supported");
	size_t n = m->n, L = m->nwl;
	const struct {
		const char *name;
		const double *p;
		size_t k;
	} arr[] = {
		{ "wl", m->wl, L }, { "eps", m->eps, L }, { "mu", m->mu, L }, { "ang", m->ang, n * 4 },
		{ "lam", m->lam, n }, { "w", m->w, n * L }, { "g", m->g, n * L }, { "gsig", m->gsig, n * L },
		{ "tab_theta", m->tab_theta, m->ntab }, { "tab_alb", m->tab_alb, (m->ntab - 1) * L },
	};
	double hdr[5] = { m->shape, m->eta, m->alb_margin, m->loo_rms, m->rcond };
	int v3 = trend_two_lobes(m->trend);
	if (!all_finite(hdr, 5) || !isfinite(m->trend_alpha) || !isfinite(m->trend_alpha2) || !m->tcoef)
		return acq_errf(err, ACQ_E_NUMERIC, "model: non-finite parameter, not written");
	if (!all_finite(m->tcoef, L * TREND_NB))
		return acq_errf(err, ACQ_E_NUMERIC, "model: non-finite value in tcoef, not written");
	for (size_t a = 0; a < sizeof arr / sizeof arr[0]; a++)
		if (!all_finite(arr[a].p, arr[a].k))
			return acq_errf(err, ACQ_E_NUMERIC, "model: non-finite value in %s, not written", arr[a].name);
	struct acq_out o;
	if (acq_out_open(&o, path, ACQ_OUT_STDIO, err))
		return -1;
	struct wr w = { o.f, FNV_INIT, 0 };
	put(&w, MAGIC, 8);
	put_u32(&w, v3 ? VERSION_2LOBE : VERSION);
	put_u32(&w, (uint32_t)m->kernel);
	put_u32(&w, (uint32_t)m->transform);
	put_u32(&w, 0);
	put_u64(&w, n);
	put_u64(&w, L);
	put_u64(&w, m->ntab);
	put(&w, hdr, sizeof hdr);
	for (size_t a = 0; a < sizeof arr / sizeof arr[0]; a++)
		put(&w, arr[a].p, arr[a].k * sizeof(double));
	put_u32(&w, (uint32_t)m->trend);
	put(&w, &m->trend_alpha, sizeof m->trend_alpha);
	if (v3)
		put(&w, &m->trend_alpha2, sizeof m->trend_alpha2);
	put(&w, m->tcoef, L * TREND_NB * sizeof(double));
	size_t ml = strnlen(m->meta, sizeof m->meta);
	put_u32(&w, (uint32_t)ml);
	put(&w, m->meta, ml);
	uint64_t h = w.h;
	put(&w, &h, 8);
	if (w.bad) {
		acq_out_abort(&o);
		return acq_errf(err, ACQ_E_IO, "%s: write failed", path);
	}
	return acq_out_commit(&o, err);
}

struct rd {
	const unsigned char *p;
	size_t len, pos;
};

static int get(struct rd *r, void *out, size_t n)
{
	if (r->len - r->pos < n)
		return -1;
	memcpy(out, r->p + r->pos, n);
	r->pos += n;
	return 0;
}

static double *get_arr(struct rd *r, size_t k)
{
	double *v = malloc((k ? k : 1) * sizeof *v);
	if (v && get(r, v, k * sizeof *v)) {
		free(v);
		return NULL;
	}
	return v;
}

int recon_model_load_mem(const char *name, const unsigned char *buf, size_t len, struct recon_model **out,
			 struct acq_err *err)
{
	*out = NULL;
	if (!little_endian())
		return acq_errf(err, ACQ_E_UNSUPPORTED, "model: big-endian hosts are not supported");
	struct rd r = { buf, len, 0 };
	char magic[8];
	uint32_t version, kernel, transform, flags;
	uint64_t n, L, ntab;
	double hdr[5];
	if (len < 8 || get(&r, magic, 8) || memcmp(magic, MAGIC, 8))
		return acq_errf(err, ACQ_E_INVAL, "%s: not a brdf-recon model file (bad magic)", name);
	if (get(&r, &version, 4) || get(&r, &kernel, 4) || get(&r, &transform, 4) || get(&r, &flags, 4) ||
	    get(&r, &n, 8) || get(&r, &L, 8) || get(&r, &ntab, 8) || get(&r, hdr, sizeof hdr))
		return acq_errf(err, ACQ_E_INVAL, "%s: truncated header", name);
	if (version < 1 || version > VERSION_2LOBE)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: model format version %u, this program reads 1 to %u", name,
				version, VERSION_2LOBE);
	if (version == 3)
		return acq_errf(err, ACQ_E_UNSUPPORTED,
				"%s: model format version 3 (a coat trend in session 7's basis, replaced in session 14): "
				"refit the samples", name);
	if (kernel >= RBF_K__COUNT)
		return acq_errf(err, ACQ_E_INVAL, "%s: unknown kernel %u", name, kernel);
	if (transform >= RECON_T__COUNT)
		return acq_errf(err, ACQ_E_INVAL, "%s: unknown transform %u", name, transform);
	if (flags != 0)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "%s: unsupported flags 0x%x", name, flags);
	if (n < 1 || n > 100000 || L < 1 || L > 100000 || n * L > 100000000ull || ntab < 2 || ntab > 10000)
		return acq_errf(err, ACQ_E_INVAL, "%s: sizes out of range (n=%llu, nwl=%llu, ntab=%llu)", name,
				(unsigned long long)n, (unsigned long long)L, (unsigned long long)ntab);
	uint64_t reals = 3 * L + 5 * n + 3 * n * L + ntab + (ntab - 1) * L;
	if (version >= 2)
		reals += 1 + TREND_NB * L + (version >= 3);
	uint64_t fixed = 8 + 16 + 24 + 40 + reals * 8 + 4 + (version >= 2 ? 4 : 0);
	if (len < fixed + 8)
		return acq_errf(err, ACQ_E_INVAL, "%s: truncated (%zu bytes, header implies at least %llu)", name, len,
				(unsigned long long)(fixed + 8));
	if (!all_finite(hdr, 5) || !(hdr[0] > 0) || hdr[1] < 0 || hdr[2] < 0 || hdr[3] < 0 || hdr[4] < 0)
		return acq_errf(err, ACQ_E_INVAL, "%s: bad header parameters (shape, smoothing, margin)", name);
	struct recon_model *m = calloc(1, sizeof *m);
	if (!m)
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", name);
	m->kernel = (int)kernel;
	m->transform = (int)transform;
	m->n = n;
	m->nwl = L;
	m->ntab = ntab;
	m->shape = hdr[0];
	m->eta = hdr[1];
	m->alb_margin = hdr[2];
	m->loo_rms = hdr[3];
	m->rcond = hdr[4];
	const char *bad = NULL;
	if (!(m->wl = get_arr(&r, L)) || !(m->eps = get_arr(&r, L)) || !(m->mu = get_arr(&r, L)) ||
	    !(m->ang = get_arr(&r, n * 4)) || !(m->lam = get_arr(&r, n)) || !(m->w = get_arr(&r, n * L)) ||
	    !(m->g = get_arr(&r, n * L)) || !(m->gsig = get_arr(&r, n * L)) ||
	    !(m->tab_theta = get_arr(&r, ntab)) || !(m->tab_alb = get_arr(&r, (ntab - 1) * L))) {
		recon_model_free(m);
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory or truncated", name);
	}
	uint32_t trend = RECON_TREND_NONE;
	if (version >= 2) {
		if (get(&r, &trend, 4) || get(&r, &m->trend_alpha, 8) || (version >= 3 && get(&r, &m->trend_alpha2, 8)) ||
		    !(m->tcoef = get_arr(&r, L * TREND_NB))) {
			recon_model_free(m);
			return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory or truncated", name);
		}
	} else if (!(m->tcoef = calloc(L * TREND_NB, sizeof *m->tcoef))) {
		recon_model_free(m);
		return acq_errf(err, ACQ_E_NOMEM, "%s: out of memory", name);
	}
	m->trend = (int)trend;
	uint32_t ml;
	if (get(&r, &ml, 4) || ml >= sizeof m->meta || get(&r, m->meta, ml)) {
		recon_model_free(m);
		return acq_errf(err, ACQ_E_INVAL, "%s: bad metadata block", name);
	}
	m->meta[ml] = '\0';
	uint64_t h = fnv1a(FNV_INIT, buf, r.pos), stored;
	if (get(&r, &stored, 8) || r.pos != len) {
		recon_model_free(m);
		return acq_errf(err, ACQ_E_INVAL, "%s: size mismatch (%zu bytes, expected %zu)", name, len, r.pos + 8);
	}
	if (h != stored) {
		recon_model_free(m);
		return acq_errf(err, ACQ_E_INVAL, "%s: checksum mismatch (file corrupt)", name);
	}
	/* semantic validation: a file with a good checksum can still be hand-made */
	if (!all_finite(m->wl, L) || !all_finite(m->eps, L) || !all_finite(m->mu, L))
		bad = "wavelength block";
	for (size_t l = 0; !bad && l < L; l++)
		if (!(m->wl[l] > 0) || (l && !(m->wl[l] > m->wl[l - 1])) || m->eps[l] < 0)
			bad = "wavelengths (must be positive, increasing) or transform offsets";
	if (!bad && !all_finite(m->ang, n * 4))
		bad = "sample directions";
	for (size_t k = 0; !bad && k < n; k++)
		if (!(m->ang[4 * k] >= 0 && m->ang[4 * k] <= M_PI / 2 + 1e-12) ||
		    !(m->ang[4 * k + 2] >= 0 && m->ang[4 * k + 2] <= M_PI / 2 + 1e-12) || !(m->lam[k] > 0) ||
		    !isfinite(m->lam[k]))
			bad = "sample directions or smoothing pattern";
	if (!bad && (!all_finite(m->w, n * L) || !all_finite(m->g, n * L) || !all_finite(m->gsig, n * L)))
		bad = "weights or data";
	for (size_t i = 0; !bad && i < n * L; i++)
		if (m->gsig[i] < 0)
			bad = "uncertainties";
	if (!bad && (m->tab_theta[0] != 0.0 || !(fabs(m->tab_theta[ntab - 1] - M_PI / 2) <= 1e-12)))
		bad = "albedo table nodes";
	for (size_t t = 1; !bad && t < ntab; t++)
		if (!(m->tab_theta[t] > m->tab_theta[t - 1])) /* also catches NaN */
			bad = "albedo table nodes";
	for (size_t i = 0; !bad && i < (ntab - 1) * L; i++)
		if (!isfinite(m->tab_alb[i]) || m->tab_alb[i] < 0)
			bad = "albedo table";
	if (!bad && (trend >= RECON_TREND__COUNT || (trend != RECON_TREND_NONE && m->transform != RECON_T_LOG)))
		bad = "trend (unknown, or not with the log transform)";
	if (!bad && !isfinite(m->trend_alpha))
		bad = "trend roughness";
	if (!bad && trend != RECON_TREND_NONE &&
	    !(m->trend_alpha >= TREND_ALPHA_MIN * 0.999 && m->trend_alpha <= TREND_ALPHA_MAX * 1.001))
		bad = "trend roughness";
	/* the second roughness: exactly the two-lobe kinds carry one (version 4), in [2α, TREND_ALPHA_MAX] */
	if (!bad && trend < RECON_TREND__COUNT && trend_two_lobes((int)trend) != (version >= 3))
		bad = version >= 3 ? "trend (version 4 carries a second roughness for a two-lobe trend only)"
				   : "trend (a two-lobe trend needs model file version 4)";
	if (!bad && version >= 3 &&
	    !(isfinite(m->trend_alpha2) && m->trend_alpha2 >= 2.0 * m->trend_alpha * 0.999 &&
	      m->trend_alpha2 <= TREND_ALPHA_MAX * 1.001))
		bad = "trend second roughness (must be finite, in [2·trend_alpha, 1])";
	for (size_t i = 0; !bad && i < L * TREND_NB; i++)
		if (!isfinite(m->tcoef[i]) || m->tcoef[i] < 0 || (trend == RECON_TREND_NONE && m->tcoef[i] != 0))
			bad = "trend coefficients";
	for (size_t i = 0; !bad && i < ml; i++)
		if (m->meta[i] == '\0')
			bad = "metadata (embedded NUL)";
	if (bad) {
		recon_model_free(m);
		return acq_errf(err, ACQ_E_INVAL, "%s: invalid %s", name, bad);
	}
	if (recon_model_derive(m, err)) {
		recon_model_free(m);
		return -1;
	}
	*out = m;
	return 0;
}

int recon_model_load(const char *path, struct recon_model **out, struct acq_err *err)
{
	char *buf;
	size_t len;
	*out = NULL;
	if (csvio_slurp(path, &buf, &len, err))
		return -1;
	int rc = recon_model_load_mem(path, (const unsigned char *)buf, len, out, err);
	free(buf);
	return rc;
}
