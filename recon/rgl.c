/* rgl: spectral RGL tabulated BRDF (.bsdf) writer; every table is derived from the reconstructed model. */
#include "recon/rgl.h"

#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "acq_version.h"
#include "recon/cie_tables.h"
#include "recon/colour.h"
#include "recon/pngio.h"
#include "recon/pool.h"
#include "recon/warp2d.h"

#define NDF_FLOOR 1e-3   /* D += 1e-3·max D: positive everywhere, so spectra = f·cosθo·4σ/D stays finite */
#define NDF_ITERS 4      /* fixed-point iterations D ← f(ω,ω)·cosθ·σ(ω) (converged to < 1e-3 in 3 on GGX) */
#define RETRO_MAX (89.5 * M_PI / 180) /* retro-reflection evaluated no closer to the horizon than this */

void rgl_opts_default(struct rgl_opts *o)
{
	memset(o, 0, sizeof *o);
	o->res = 32;
	o->ndf_res = 128;
	o->ntheta = 30;
	o->threads = 1;
}

static double theta_of_u(double u)
{
	return u * u * M_PI / 2;
}

static double u_of_theta(double t)
{
	return sqrt(2 * t / M_PI);
}

/* ∫_0^{2π} max(0, a + b·cos φ) dφ for b >= 0. */
static double azim_clip(double a, double b)
{
	if (a >= b)
		return 2 * M_PI * a;
	if (a <= -b)
		return 0;
	double p0 = acos(-a / b);
	return 2 * (a * p0 + b * sin(p0));
}

/* 4-point Gauss-Legendre on [0, 1] */
static const double GL_X[4] = { 0.0694318442029737, 0.3300094782075719, 0.6699905217924281, 0.9305681557970263 };
static const double GL_W[4] = { 0.1739274225687269, 0.3260725774312731, 0.3260725774312731, 0.1739274225687269 };

/* Piecewise-linear-in-u 1-D table D[n] over u in [0, 1]: ∫ D(θm)·g dω for g = cosθm (proj = 0) or the clipped
 * cosine to θ (proj = 1, σ(θ)), per cell with Gauss-Legendre (the integrand is smooth within a cell). */
static double ndf_integral(const double *D, size_t n, int proj, double theta)
{
	double sum = 0, du = 1.0 / (double)(n - 1), ct = cos(theta), st = sin(theta);
	for (size_t c = 0; c + 1 < n; c++)
		for (int g = 0; g < 4; g++) {
			double t = GL_X[g], u = ((double)c + t) * du, tm = theta_of_u(u);
			double d = (1 - t) * D[c] + t * D[c + 1];
			double geo = proj ? azim_clip(ct * cos(tm), st * sin(tm)) : 2 * M_PI * cos(tm);
			sum += GL_W[g] * du * d * geo * sin(tm) * M_PI * u;
		}
	return sum;
}

static float to_f32(double v)
{
	return (float)v;
}

int rgl_parse_wavelengths(const char *spec, double *wl, size_t max, size_t *n, struct acq_err *err)
{
	*n = 0;
	char *end;
	if (strchr(spec, ':')) {
		double v[3];
		const char *p = spec;
		for (int k = 0; k < 3; k++) {
			errno = 0;
			v[k] = strtod(p, &end);
			if (end == p || errno || !isfinite(v[k]) || (k < 2 ? *end != ':' : *end != '\0'))
				return acq_errf(err, ACQ_E_INVAL, "wavelengths '%s': expected FIRST:LAST:STEP in nm", spec);
			p = end + 1;
		}
		if (!(v[0] > 0) || !(v[1] >= v[0]) || !(v[2] > 0))
			return acq_errf(err, ACQ_E_INVAL, "wavelengths '%s': needs 0 < FIRST <= LAST and STEP > 0", spec);
		double cnt = floor((v[1] - v[0]) / v[2] + 1e-9) + 1;
		if (cnt > (double)max)
			return acq_errf(err, ACQ_E_RANGE, "wavelengths '%s': %.0f values (at most %zu)", spec, cnt, max);
		for (size_t k = 0; k < (size_t)cnt; k++)
			wl[k] = v[0] + (double)k * v[2];
		*n = (size_t)cnt;
		return 0;
	}
	const char *p = spec;
	while (*p) {
		if (*n == max)
			return acq_errf(err, ACQ_E_RANGE, "wavelengths: more than %zu values", max);
		errno = 0;
		double v = strtod(p, &end);
		if (end == p || errno || !isfinite(v) || !(v > 0) || (*end && *end != ','))
			return acq_errf(err, ACQ_E_INVAL, "wavelengths '%s': bad value at position %zu", spec,
					(size_t)(p - spec) + 1);
		if (*n && !(v > wl[*n - 1]))
			return acq_errf(err, ACQ_E_INVAL, "wavelengths '%s': %g nm is not above %g nm (must increase)", spec,
					v, wl[*n - 1]);
		wl[(*n)++] = v;
		p = *end ? end + 1 : end;
	}
	if (!*n)
		return acq_errf(err, ACQ_E_INVAL, "wavelengths: empty list");
	return 0;
}

/* Output wavelength k is the model's spectrum read as piecewise linear between its channels. */
struct chan {
	size_t l0, l1;
	double t;
};

struct job {
	const struct recon_model *m;
	size_t nwl, res, nd, nth;
	const struct chan *ch;
	const double *yw;      /* [nwl] luminance weights (sum 1) */
	const double *wl;
	const double *ndf;     /* [nd*nd] table values as stored (float-rounded) */
	const double *sig;
	const double *theta;   /* [nth] */
	float *vndf, *lum, *spec;
	size_t *zero;          /* [nth] */
	struct scratch {
		double *dens, *ang, *val;
		size_t *idx;
	} ws[POOL_MAX_THREADS];
};

/* One incidence node k: its VNDF table, the warp, the model at the warped nodes, spectra and luminance. */
static int do_node(struct job *j, size_t k, double *dens, double *ang, double *val, size_t *idx, struct acq_err *e)
{
	size_t R = j->res, N = R * R, L = j->nwl, ML = j->m->nwl;
	double ti = j->theta[k], wi[3] = { sin(ti), 0, cos(ti) };
	double step = 1.0 / (double)(R - 1);
	for (size_t r = 0; r < R; r++)
		for (size_t c = 0; c < R; c++) {
			double u[2] = { (double)c * step, (double)r * step };
			double tm = theta_of_u(u[0]), pm = (2 * u[1] - 1) * M_PI;
			double wm[3] = { sin(tm) * cos(pm), sin(tm) * sin(pm), cos(tm) };
			double dp = wi[0] * wm[0] + wi[1] * wm[1] + wi[2] * wm[2];
			double D = warp2d_bilerp(j->ndf, j->nd, j->nd, u);
			dens[r * R + c] = D * (dp > 0 ? dp : 0) * sin(tm) * M_PI * u[0] * 2 * M_PI;
		}
	struct warp2d wp;
	if (warp2d_init(&wp, dens, R, R, e))
		return acq_err_prefix(e, "rgl: VNDF at theta_i %.3g deg: ", ti * 180 / M_PI);
	double tot = wp.total;
	warp2d_free(&wp);
	float *vt = j->vndf + k * N;
	for (size_t q = 0; q < N; q++) {
		vt[q] = to_f32(dens[q] / tot);
		dens[q] = vt[q];
	}
	if (warp2d_init(&wp, dens, R, R, e))
		return acq_err_prefix(e, "rgl: VNDF at theta_i %.3g deg: ", ti * 180 / M_PI);
	double usig[2] = { u_of_theta(ti), 0.5 };
	double s4 = 4 * warp2d_bilerp(j->sig, j->nd, j->nd, usig);
	size_t nq = 0;
	/* [N] cosθo·4σ/D per node (val holds [N*ML] model values first). The renderers' rule is spectra·D/(4σ) =
	 * f·cosθo, the cosine-weighted BRDF (powitacq's eval "f_r * cos", Mitsuba 3's BSDF::eval, pbrt-v4's Sample_f
	 * dividing by the sampled direction's cosine), so the stored ratio carries cosθo. */
	double *scale = val + N * ML;
	for (size_t r = 0; r < R; r++)
		for (size_t c = 0; c < R; c++) {
			double s[2] = { (double)c * step, (double)r * step }, um[2];
			warp2d_sample(&wp, s, um, NULL);
			double tm = theta_of_u(um[0]), pm = (2 * um[1] - 1) * M_PI;
			double wm[3] = { sin(tm) * cos(pm), sin(tm) * sin(pm), cos(tm) };
			double dp = wi[0] * wm[0] + wi[1] * wm[1] + wi[2] * wm[2];
			double wo[3] = { 2 * dp * wm[0] - wi[0], 2 * dp * wm[1] - wi[1], 2 * dp * wm[2] - wi[2] };
			size_t q = r * R + c;
			if (!(dp > 0) || !(wo[2] > 1e-9)) {
				idx[q] = SIZE_MAX;
				continue;
			}
			ang[nq * 4] = ti;
			ang[nq * 4 + 1] = 0;
			ang[nq * 4 + 2] = atan2(hypot(wo[0], wo[1]), wo[2]);
			ang[nq * 4 + 3] = atan2(wo[1], wo[0]);
			scale[q] = s4 * wo[2] / warp2d_bilerp(j->ndf, j->nd, j->nd, um);
			idx[q] = nq++;
		}
	warp2d_free(&wp);
	if (nq && recon_eval(j->m, nq, ang, val, e))
		return -1;
	size_t zero = 0;
	for (size_t q = 0; q < N; q++) {
		double lum = 0;
		for (size_t l = 0; l < L; l++) {
			double v = 0;
			if (idx[q] != SIZE_MAX) {
				const double *f = val + idx[q] * ML;
				v = ((1 - j->ch[l].t) * f[j->ch[l].l0] + j->ch[l].t * f[j->ch[l].l1]) * scale[q];
			}
			if (!isfinite(v) || v < 0)
				return acq_errf(e, ACQ_E_NUMERIC, "rgl: non-finite table value at theta_i %.3g deg, node %zu, "
						"%g nm", ti * 180 / M_PI, q, j->wl[l]);
			j->spec[(k * L + l) * N + q] = to_f32(v);
			lum += j->yw[l] * v;
		}
		zero += idx[q] == SIZE_MAX;
		j->lum[k * N + q] = to_f32(lum);
	}
	j->zero[k] = zero;
	return 0;
}

static int node_job(void *ctx, int worker, size_t k, struct acq_err *e)
{
	struct job *j = ctx;
	struct scratch *w = &j->ws[worker];
	return do_node(j, k, w->dens, w->ang, w->val, w->idx, e);
}

/* CIE 1931 ȳ at wl nm (linear between the 1 nm nodes, 0 outside 360..830). */
static double ybar(double wl)
{
	double x = wl - CIE_CMF_FIRST_NM;
	if (x < 0 || x > CIE_CMF_N - 1)
		return 0;
	size_t i = (size_t)x;
	if (i >= CIE_CMF_N - 1)
		return cie_cmf_1931_2deg[CIE_CMF_N - 1][1];
	double t = x - (double)i;
	return (1 - t) * cie_cmf_1931_2deg[i][1] + t * cie_cmf_1931_2deg[i + 1][1];
}

/* ---- tensor file ---- */
enum { T_U8 = 1, T_F32 = 10 };
struct field {
	const char *name;
	int dtype;
	size_t ndim, shape[5];
	const void *data;
	size_t bytes;
	uint64_t offset;
};

static void put_le(unsigned char *p, uint64_t v, int n)
{
	for (int i = 0; i < n; i++)
		p[i] = (unsigned char)(v >> (8 * i));
}

/* Serialise the fields into one buffer (header, then each block 8-byte aligned, little-endian). */
static unsigned char *tensor_build(struct field *f, size_t nf, size_t *len, struct acq_err *err)
{
	size_t hdr = 12 + 2 + 4;
	for (size_t i = 0; i < nf; i++)
		hdr += 2 + strlen(f[i].name) + 2 + 1 + 8 + 8 * f[i].ndim;
	size_t pos = (hdr + 7) & ~(size_t)7;
	for (size_t i = 0; i < nf; i++) {
		f[i].offset = pos;
		pos = (pos + f[i].bytes + 7) & ~(size_t)7;
	}
	unsigned char *b = calloc(1, pos);
	if (!b) {
		acq_errf(err, ACQ_E_NOMEM, "rgl: out of memory for a %zu-byte file", pos);
		return NULL;
	}
	memcpy(b, "tensor_file", 12);
	b[12] = 1;
	b[13] = 0;
	put_le(b + 14, nf, 4);
	unsigned char *p = b + 18;
	for (size_t i = 0; i < nf; i++) {
		size_t nl = strlen(f[i].name);
		put_le(p, nl, 2);
		memcpy(p + 2, f[i].name, nl);
		p += 2 + nl;
		put_le(p, f[i].ndim, 2);
		p[2] = (unsigned char)f[i].dtype;
		put_le(p + 3, f[i].offset, 8);
		p += 11;
		for (size_t d = 0; d < f[i].ndim; d++, p += 8)
			put_le(p, f[i].shape[d], 8);
		if (f[i].dtype == T_F32) {
			const float *src = f[i].data;
			for (size_t q = 0; q < f[i].bytes / 4; q++) {
				uint32_t u;
				memcpy(&u, &src[q], 4);
				put_le(b + f[i].offset + 4 * q, u, 4);
			}
		} else {
			memcpy(b + f[i].offset, f[i].data, f[i].bytes);
		}
	}
	*len = pos;
	return b;
}

/* Provenance text: the writer, the model's own metadata, and the decisions of this file. */
static char *describe(const struct recon_model *m, const struct rgl_opts *o, const double *wl, size_t nwl)
{
	size_t cap = sizeof m->meta + 4096; /* the fixed text is ~1.7 KB with --rgb */
	char *d = malloc(cap);
	if (!d)
		return NULL;
	snprintf(d, cap,
		 "%s BRDF written by acquisitiond brdf-recon rgl %s from a reconstructed model (radial basis "
		 "functions on S2+ x S2+, non-negative, reciprocal, energy conserving).\n"
		 "model_file=%s\nmodel_directions=%zu\nmodel_wavelengths=%zu (%g..%g nm)\nkernel=%s shape=%.6g\n"
		 "transform=%s smoothing=%.6g trend=%s trend_alpha=%.6g loo_rms=%.6g\n%s"
		 "tables: isotropic (phi_i = 0), theta_i nodes=%d (k*90/%d deg), warped grid %dx%d, ndf/sigma %dx%d, "
		 "wavelengths=%zu (%g..%g nm, the model's spectrum read piecewise linear between its channels)\n"
		 "ndf: retro-reflection fixed point D <- f(w,w) cos(theta) sigma(w) (%d iterations, CIE Y weighted), "
		 "+%g of its maximum, normalised so that the integral of D cos = 1; densities on the unit square "
		 "include the sin(theta) Jacobian; spectra = f cos(theta_o) 4 sigma(w_i) / D(w_m) (jacobian = 1: a "
		 "renderer's spectra D / (4 sigma) is the cosine-weighted BRDF f cos(theta_o)); luminance: CIE 1931 Y "
		 "weights over the file's visible wavelengths (equal weights if none is visible)\n%s",
		 o->rgb ? "RGB" : "Spectral", ACQ_VERSION, o->source ? o->source : "(unknown)", m->n, m->nwl, m->wl[0],
		 m->wl[m->nwl - 1],
		 rbf_kernel_name(m->kernel), m->shape, recon_transform_name(m->transform), m->eta, trend_name(m->trend),
		 m->trend_alpha, m->loo_rms, m->meta, o->ntheta, o->ntheta, o->res, o->res, o->ndf_res, o->ndf_res, nwl,
		 wl[0], wl[nwl - 1], NDF_ITERS, NDF_FLOOR,
		 o->rgb ? "rgb: linear sRGB (Rec. 709 primaries, D65), 1/sr, from these spectra by CIE 1931 2 deg under "
			  "D65 with Bradford adaptation (brdf-recon merl's chain); negatives (out of gamut) written as 0; "
			  "no wavelengths field (an RGB file)\n" : "");
	return d;
}

/* rgl_write's options checked against the model; *wl and *L the wavelengths to write. 0, or -1 with err. */
static int check_opts(const struct recon_model *m, const struct rgl_opts *o, const double **wl, size_t *L,
		      struct acq_err *err)
{
	if (o->res < 4 || o->res > 256 || o->ndf_res < 8 || o->ndf_res > 1024 || o->ntheta < 2 || o->ntheta > 180 ||
	    o->threads < 1 || o->threads > 16)
		return acq_errf(err, ACQ_E_INVAL, "rgl: resolution %d (4..256), ndf %d (8..1024), theta nodes %d (2..180) "
				"or threads %d (1..16) out of range", o->res, o->ndf_res, o->ntheta, o->threads);
	*wl = o->wl ? o->wl : m->wl;
	*L = o->wl ? o->nwl : m->nwl;
	size_t ML = m->nwl;
	if (*L < 1 || *L > RGL_MAX_WL)
		return acq_errf(err, ACQ_E_INVAL, "rgl: %zu wavelengths (1..%d)", *L, RGL_MAX_WL);
	for (size_t l = 0; l < *L; l++) {
		const double *w = *wl;
		if (!(w[l] >= m->wl[0] - 1e-9 && w[l] <= m->wl[ML - 1] + 1e-9))
			return acq_errf(err, ACQ_E_RANGE, "rgl: wavelength %g nm is outside the model's range %g..%g nm", w[l],
					m->wl[0], m->wl[ML - 1]);
		if (l && !(w[l] > w[l - 1]))
			return acq_errf(err, ACQ_E_INVAL, "rgl: wavelengths must increase (%g after %g nm)", w[l], w[l - 1]);
	}
	return 0;
}

/* Every array rgl_write fills (sizes from the options: L wavelengths, nd NDF columns, nth incidences, N warped
 * nodes), the description and the serialised file. */
struct tables {
	struct chan *ch;
	double *yw, *theta, *D1, *S1, *rho, *ndf, *sig, *rang, *rval;
	float *fndf, *fsig, *fth, *fwl, *vndf, *lum, *spec, *rgb;
	size_t *zero;
	char *desc;
	unsigned char *file;
};

/* 0, or -1 if any allocation failed (what was allocated is for tables_free). */
static int tables_alloc(struct tables *t, size_t L, size_t ML, size_t nd, size_t nth, size_t N)
{
	t->ch = calloc(L, sizeof *t->ch);
	t->yw = calloc(L, sizeof *t->yw);
	t->theta = calloc(nth, sizeof *t->theta);
	t->D1 = calloc(nd, sizeof *t->D1);
	t->S1 = calloc(nd, sizeof *t->S1);
	t->rho = calloc(nd, sizeof *t->rho);
	t->ndf = calloc(nd * nd, sizeof *t->ndf);
	t->sig = calloc(nd * nd, sizeof *t->sig);
	t->rang = calloc(nd * 4, sizeof *t->rang);
	t->rval = calloc(nd * ML, sizeof *t->rval);
	t->fndf = calloc(nd * nd, sizeof *t->fndf);
	t->fsig = calloc(nd * nd, sizeof *t->fsig);
	t->fth = calloc(nth, sizeof *t->fth);
	t->fwl = calloc(L, sizeof *t->fwl);
	t->vndf = calloc(nth * N, sizeof *t->vndf);
	t->lum = calloc(nth * N, sizeof *t->lum);
	t->spec = calloc(nth * L * N, sizeof *t->spec);
	t->zero = calloc(nth, sizeof *t->zero);
	if (!t->ch || !t->yw || !t->theta || !t->D1 || !t->S1 || !t->rho || !t->ndf || !t->sig || !t->rang || !t->rval ||
	    !t->fndf || !t->fsig || !t->fth || !t->fwl || !t->vndf || !t->lum || !t->spec || !t->zero)
		return -1;
	return 0;
}

static void tables_free(struct tables *t)
{
	void *all[] = { t->ch, t->yw, t->theta, t->D1, t->S1, t->rho, t->ndf, t->sig, t->rang, t->rval, t->fndf, t->fsig,
			t->fth, t->fwl, t->vndf, t->lum, t->spec, t->rgb, t->zero, t->desc, t->file };
	for (size_t i = 0; i < sizeof all / sizeof all[0]; i++)
		free(all[i]);
}

/* Wavelength map (the model's channels each written wavelength lies between) and luminance weights (ȳ ×
 * trapezoid width; equal weights when none is visible). */
static void wavelength_map(const struct recon_model *m, const double *wl, size_t L, struct tables *t)
{
	size_t ML = m->nwl;
	struct chan *ch = t->ch;
	double ysum = 0;
	for (size_t l = 0; l < L; l++) {
		size_t a = 0;
		while (a + 1 < ML && m->wl[a + 1] <= wl[l])
			a++;
		size_t b = a + 1 < ML ? a + 1 : a;
		ch[l].l0 = a;
		ch[l].l1 = b;
		ch[l].t = b > a ? (wl[l] - m->wl[a]) / (m->wl[b] - m->wl[a]) : 0;
		if (ch[l].t < 0)
			ch[l].t = 0;
		if (ch[l].t > 1)
			ch[l].t = 1;
		double width = L == 1 ? 1 : 0.5 * (wl[l + 1 < L ? l + 1 : l] - wl[l ? l - 1 : 0]);
		t->yw[l] = ybar(wl[l]) * width;
		ysum += t->yw[l];
		t->fwl[l] = to_f32(wl[l]);
	}
	for (size_t l = 0; l < L; l++)
		t->yw[l] = ysum > 0 ? t->yw[l] / ysum : 1.0 / (double)L;
}

/* The NDF D1 and its projected area S1 over nd columns: retro-reflection luminance ρ(θ), then the fixed point
 * D ← ρ·cosθ·σ, floored and normalised (∫ D cos dω = 1). 0, or -1 with err (the model's evaluation). */
static int ndf_fit(const struct recon_model *m, size_t L, size_t nd, struct tables *t, struct acq_err *err)
{
	size_t ML = m->nwl;
	const struct chan *ch = t->ch;
	double *D1 = t->D1, *S1 = t->S1;
	for (size_t c = 0; c < nd; c++) {
		double th = theta_of_u((double)c / (double)(nd - 1));
		if (th > RETRO_MAX)
			th = RETRO_MAX;
		t->rang[c * 4] = t->rang[c * 4 + 2] = th;
	}
	if (recon_eval(m, nd, t->rang, t->rval, err))
		return -1;
	for (size_t c = 0; c < nd; c++) {
		double y = 0;
		for (size_t l = 0; l < L; l++)
			y += t->yw[l] * ((1 - ch[l].t) * t->rval[c * ML + ch[l].l0] + ch[l].t * t->rval[c * ML + ch[l].l1]);
		t->rho[c] = y;
		S1[c] = 1;
	}
	for (int it = 0; it < NDF_ITERS; it++) {
		double mx = 0;
		for (size_t c = 0; c < nd; c++) {
			D1[c] = t->rho[c] * cos(theta_of_u((double)c / (double)(nd - 1))) * S1[c];
			if (!(D1[c] > 0))
				D1[c] = 0;
			mx = D1[c] > mx ? D1[c] : mx;
		}
		if (!(mx > 0)) /* a black model: any D will do, the spectra carry the zeros */
			for (size_t c = 0; c < nd; c++)
				D1[c] = mx = 1;
		for (size_t c = 0; c < nd; c++)
			D1[c] += NDF_FLOOR * mx;
		double norm = ndf_integral(D1, nd, 0, 0);
		for (size_t c = 0; c < nd; c++)
			D1[c] /= norm;
		for (size_t c = 0; c < nd; c++)
			S1[c] = ndf_integral(D1, nd, 1, theta_of_u((double)c / (double)(nd - 1)));
	}
	return 0;
}

/* The stored tables (rows along u_φ identical: isotropic), what the reader will interpolate, and the
 * incidence nodes. */
static void ndf_tables(size_t nd, size_t nth, struct tables *t)
{
	double *D1 = t->D1, *S1 = t->S1;
	for (size_t c = 0; c < nd; c++)
		D1[c] = (double)to_f32(D1[c]);
	for (size_t c = 0; c < nd; c++)
		S1[c] = (double)to_f32(ndf_integral(D1, nd, 1, theta_of_u((double)c / (double)(nd - 1))));
	for (size_t r = 0; r < nd; r++)
		for (size_t c = 0; c < nd; c++) {
			t->ndf[r * nd + c] = D1[c];
			t->sig[r * nd + c] = S1[c];
			t->fndf[r * nd + c] = to_f32(D1[c]);
			t->fsig[r * nd + c] = to_f32(S1[c]);
		}
	for (size_t k = 0; k < nth; k++) {
		t->fth[k] = to_f32((double)k * (M_PI / 2) / (double)nth);
		t->theta[k] = t->fth[k];
	}
}

/* RGB file: t->rgb [nth, 3, N] = the spectra table reduced to linear sRGB by colour_opts_brdf's weights (linear,
 * so it commutes with the renderer's D/(4σ) factor), negatives set to 0 and counted in *clamped. 0, or -1. */
static int rgb_tables(struct tables *t, const double *wl, size_t L, size_t N, size_t nth, size_t *clamped,
		      struct acq_err *err)
{
	struct colour_opts co;
	colour_opts_brdf(&co);
	double *W = malloc(3 * L * sizeof *W);
	t->rgb = calloc(nth * 3 * N, sizeof *t->rgb);
	if (!W || !t->rgb) {
		free(W);
		return acq_errf(err, ACQ_E_NOMEM, "rgl: out of memory for the RGB table");
	}
	if (colour_weights(&co, wl, L, W, err)) {
		free(W);
		return acq_err_prefix(err, "rgl: ");
	}
	for (size_t k = 0; k < nth; k++)
		for (size_t c = 0; c < 3; c++)
			for (size_t q = 0; q < N; q++) {
				double v = 0;
				for (size_t l = 0; l < L; l++)
					v += W[c * L + l] * (double)t->spec[(k * L + l) * N + q];
				if (v < 0) {
					v = 0;
					(*clamped)++;
				}
				t->rgb[(k * 3 + c) * N + q] = to_f32(v);
			}
	free(W);
	return 0;
}

/* The tensor file's fields serialised into t->file (*len bytes). 0, or -1 with err. */
static int build_file(struct tables *t, size_t L, size_t R, size_t nd, size_t nth, size_t *len, struct acq_err *err)
{
	size_t N = R * R, nf = 10;
	float phi0 = 0;
	unsigned char jac = 1;
	struct field f[] = {
		{ "description", T_U8, 1, { strlen(t->desc) }, t->desc, strlen(t->desc), 0 },
		{ "jacobian", T_U8, 1, { 1 }, &jac, 1, 0 },
		{ "ndf", T_F32, 2, { nd, nd }, t->fndf, nd * nd * 4, 0 },
		{ "sigma", T_F32, 2, { nd, nd }, t->fsig, nd * nd * 4, 0 },
		{ "theta_i", T_F32, 1, { nth }, t->fth, nth * 4, 0 },
		{ "phi_i", T_F32, 1, { 1 }, &phi0, 4, 0 },
		{ "wavelengths", T_F32, 1, { L }, t->fwl, L * 4, 0 },
		{ "vndf", T_F32, 4, { 1, nth, R, R }, t->vndf, nth * N * 4, 0 },
		{ "luminance", T_F32, 4, { 1, nth, R, R }, t->lum, nth * N * 4, 0 },
		{ "spectra", T_F32, 5, { 1, nth, L, R, R }, t->spec, nth * L * N * 4, 0 },
	};
	if (t->rgb) { /* an RGB file: `rgb` in place of `spectra`, and no `wavelengths` (how readers tell them apart) */
		f[6] = f[7];
		f[7] = f[8];
		f[8] = (struct field){ "rgb", T_F32, 5, { 1, nth, 3, R, R }, t->rgb, nth * 3 * N * 4, 0 };
		nf = 9;
	}
	t->file = tensor_build(f, nf, len, err);
	return t->file ? 0 : -1;
}

int rgl_write(const struct recon_model *m, const struct rgl_opts *o, const char *path, struct rgl_stats *st,
	      struct acq_err *err)
{
	const double *wl = NULL;
	size_t L = 0;
	if (check_opts(m, o, &wl, &L, err) != 0)
		return -1;
	size_t ML = m->nwl, R = (size_t)o->res, N = R * R, nd = (size_t)o->ndf_res, nth = (size_t)o->ntheta;
	int rc = -1;
	struct tables t = { 0 };
	struct job j = { 0 };
	int nomem = tables_alloc(&t, L, ML, nd, nth, N);
	t.desc = describe(m, o, wl, L);
	if (nomem || !t.desc) {
		acq_errf(err, ACQ_E_NOMEM, "rgl: out of memory (%zu incidences x %zu wavelengths x %zu nodes)", nth, L, N);
		goto out;
	}
	wavelength_map(m, wl, L, &t);
	if (ndf_fit(m, L, nd, &t, err))
		goto out;
	ndf_tables(nd, nth, &t);
	j = (struct job){ .m = m, .nwl = L, .res = R, .nd = nd, .nth = nth, .ch = t.ch, .yw = t.yw, .wl = wl,
			  .ndf = t.ndf, .sig = t.sig, .theta = t.theta, .vndf = t.vndf, .lum = t.lum, .spec = t.spec,
			  .zero = t.zero };
	for (int k = 0; k < o->threads; k++) {
		struct scratch *w = &j.ws[k];
		w->dens = malloc(N * sizeof *w->dens);
		w->ang = malloc(N * 4 * sizeof *w->ang);
		w->val = malloc(N * (ML + 1) * sizeof *w->val);
		w->idx = malloc(N * sizeof *w->idx);
		if (!w->dens || !w->ang || !w->val || !w->idx) {
			acq_errf(err, ACQ_E_NOMEM, "rgl: out of memory");
			goto out;
		}
	}
	if (pool_run(o->threads, nth, node_job, &j, NULL, err))
		goto out;
	size_t clamped = 0;
	if (o->rgb && rgb_tables(&t, wl, L, N, nth, &clamped, err))
		goto out;
	size_t len = 0;
	if (build_file(&t, L, R, nd, nth, &len, err) || pngio_write_bytes(path, t.file, len, err))
		goto out;
	if (st) {
		memset(st, 0, sizeof *st);
		st->bytes = len;
		st->nwl = L;
		st->ntheta = nth;
		st->res = R;
		st->ndf_res = nd;
		st->ndf_floor = NDF_FLOOR;
		st->rgb_clamped = clamped;
		for (size_t k = 0; k < nth; k++)
			st->zero_nodes += t.zero[k];
	}
	rc = 0;
out:
	for (int k = 0; k < POOL_MAX_THREADS; k++) {
		free(j.ws[k].dens);
		free(j.ws[k].ang);
		free(j.ws[k].val);
		free(j.ws[k].idx);
	}
	tables_free(&t);
	return rc;
}
