/* material: ground-truth spectral BRDFs of the simulated samples and their DHR quadrature (see material.h). */
#include "sim/material.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NE 128               /* E(mu) table segments */
#define PAINT_ALPHA 0.12
#define PAINT_N 1.5
#define METAL_ALPHA 0.15

struct mat {
	enum mat_id id;
	int nwl;
	double *wl;
	double *rho;                 /* diffuse albedo per wavelength (paint, white) */
	double *n, *k;               /* complex index per wavelength (metal) */
	double alpha;                /* GGX roughness (0: no specular lobe) */
	double etab[NE + 1];         /* specular albedo at mu = j / NE (paint) */
	double eavg;                 /* 2 int E mu dmu */
};

static const char *const names[MAT__COUNT] = { "green-paint", "white", "metal" };

int mat_from_name(const char *name)
{
	if (!name)
		return -1;
	if (!strcmp(name, "paint"))
		return MAT_GREEN_PAINT;
	for (int i = 0; i < MAT__COUNT; i++)
		if (!strcmp(name, names[i]))
			return i;
	return -1;
}

const char *mat_name(enum mat_id id)
{
	return (id >= 0 && id < MAT__COUNT) ? names[id] : "?";
}

void mat_dir(double theta, double phi, double out[3])
{
	out[0] = sin(theta) * cos(phi);
	out[1] = sin(theta) * sin(phi);
	out[2] = cos(theta);
}

static double clamp_wl(double wl)
{
	return wl < MAT_WL_MIN ? MAT_WL_MIN : wl > MAT_WL_MAX ? MAT_WL_MAX : wl;
}

double mat_rho_d(enum mat_id id, double wl)
{
	wl = clamp_wl(wl);
	switch (id) {
	case MAT_GREEN_PAINT: {
		/* green pigment: reflectance peak at 530 nm, absorbing red, NIR red edge near 720 nm */
		double g = (wl - 530.0) / 38.0;
		return 0.05 + 0.40 * exp(-0.5 * g * g) + 0.60 / (1.0 + exp(-(wl - 720.0) / 22.0));
	}
	case MAT_WHITE: {
		double x = (wl - MAT_WL_MIN) / (MAT_WL_MAX - MAT_WL_MIN);
		return 0.99 - 0.015 * exp(-(wl - MAT_WL_MIN) / 30.0) - 0.012 * x * x * x * x;
	}
	default:
		return 0.0;
	}
}

/* Gold-like complex refractive index (smoothed from published optical constants of gold). */
static const double au_wl[] = { 450, 500, 550, 600, 650, 700, 800, 900, 1000, 1100 };
static const double au_n[] = { 1.47, 0.97, 0.43, 0.25, 0.17, 0.16, 0.15, 0.17, 0.22, 0.27 };
static const double au_k[] = { 1.95, 1.87, 2.45, 3.00, 3.50, 3.95, 4.90, 5.70, 6.40, 7.10 };

static void metal_index(double wl, double *n, double *k)
{
	wl = clamp_wl(wl);
	int m = (int)(sizeof au_wl / sizeof au_wl[0]);
	int i = 0;
	while (i < m - 2 && wl > au_wl[i + 1])
		i++;
	double t = (wl - au_wl[i]) / (au_wl[i + 1] - au_wl[i]);
	*n = au_n[i] + t * (au_n[i + 1] - au_n[i]);
	*k = au_k[i] + t * (au_k[i + 1] - au_k[i]);
}

/* Exact unpolarised Fresnel reflectance from air onto an interface of complex index n + ik (k = 0: dielectric)
 * at incidence cosine c in (0, 1]. */
static double fresnel(double c, double n, double k)
{
	double c2 = c * c, s2 = 1.0 - c2;
	double t0 = n * n - k * k - s2;
	double a2b2 = sqrt(t0 * t0 + 4.0 * n * n * k * k);
	double a = sqrt(fmax(0.0, 0.5 * (a2b2 + t0)));
	double t1 = a2b2 + c2, t2 = 2.0 * a * c;
	double rs = (t1 - t2) / (t1 + t2);
	double t3 = c2 * a2b2 + s2 * s2, t4 = t2 * s2;
	double rp = rs * (t3 - t4) / (t3 + t4);
	double r = 0.5 * (rs + rp);
	return r < 0 ? 0 : r > 1 ? 1 : r;
}

static double ggx_d(double alpha, double ch)
{
	double a2 = alpha * alpha, t = ch * ch * (a2 - 1.0) + 1.0;
	return a2 / (M_PI * t * t);
}

static double ggx_lambda(double alpha, double mu)
{
	double t2 = (1.0 - mu * mu) / (mu * mu);
	return 0.5 * (sqrt(1.0 + alpha * alpha * t2) - 1.0);
}

static const double gx[8] = { -0.9602898564975363, -0.7966664774136267, -0.5255324099163290,
			       -0.1834346424956498, 0.1834346424956498,  0.5255324099163290,
			       0.7966664774136267,  0.9602898564975363 };
static const double gw[8] = { 0.1012285362903763, 0.2223810344533745, 0.3137066458778873,
			       0.3626837833783620, 0.3626837833783620, 0.3137066458778873,
			       0.2223810344533745, 0.1012285362903763 };

/* Gauss-Legendre over s in [a, b] (np panels of 8 nodes) on the phi_h line of cosine cph (weight wphi). */
static double s_segment(const struct mat *m, double mu_i, double si, double cph, double wphi, double a, double b,
			int np, int flags, double *out)
{
	double alpha = m->alpha, hs = (b - a) / np, total = 0;
	for (int p = 0; p < np; p++)
		for (int q = 0; q < 8; q++) {
			double s = a + hs * (p + 0.5 + 0.5 * gx[q]);
			double cs = cos(s), ss = sin(s);
			double th = atan(alpha * tan(s));
			double jac = alpha / (cs * cs + alpha * alpha * ss * ss);
			double ch = cos(th), sh = sin(th);
			double dval = ggx_d(alpha, ch) * sh * jac * 0.5 * hs * gw[q] * wphi;
			if (flags & 1) {
				total += dval * ch;
				continue;
			}
			double c = si * sh * cph + mu_i * ch;
			double mu_o = 2.0 * c * ch - mu_i;
			if (c <= 0 || mu_o <= 0)
				continue;
			double g2 = 1.0 / (1.0 + ggx_lambda(alpha, mu_i) + ggx_lambda(alpha, mu_o));
			double base = dval * g2 * c / mu_i;
			if (out) {
				for (int l = 0; l < m->nwl; l++)
					out[l] += base * fresnel(c, m->n[l], m->k[l]);
			} else {
				total += base * fresnel(c, PAINT_N, 0.0);
			}
		}
	return total;
}

/* One phi_h line of the half-vector quadrature (weight wphi), theta_h from 0 to the horizon cut-off. */
static double spec_line(const struct mat *m, double mu_i, double si, double ph, double wphi, int panels, int flags,
			double *out)
{
	double alpha = m->alpha, cph = cos(ph), smax = M_PI / 2, total = 0;
	if (!(flags & 1)) {
		/* mu_o > 0 exactly for theta_h < atan2(sin(theta_i) cos(phi_h), mu_i) / 2 + pi/4: integrate up to
		 * there, so the integrand is smooth on the interval (it vanishes at the end, through G2) */
		double thmax = 0.5 * atan2(si * cph, mu_i) + M_PI / 4;
		smax = thmax >= M_PI / 2 ? M_PI / 2 : atan(tan(thmax) / alpha);
	}
	/* At grazing incidence (mu_i < alpha) the integrand also changes on the scale theta_h ~ mu_i near 0
	 * (where wi.h turns from mu_i to sin(theta_h)) and near the cut-off (where G2 turns at mu_o ~ mu_i):
	 * [0, smax/2] is graded geometrically towards 0 and [smax/2, smax] towards smax, down to that scale. */
	int ng = 0;
	while (!(flags & 1) && ng < 30 && smax * ldexp(1.0, -ng) * alpha > mu_i)
		ng++;
	for (int g = 1; g <= ng + 1; g++) {
		double a = g == ng + 1 ? 0.0 : smax * ldexp(1.0, -(g + 1)), b = smax * ldexp(1.0, -g);
		int np = g == 1 ? panels / 2 : (panels + 3) / 4;
		total += s_segment(m, mu_i, si, cph, wphi, a, b, np, flags, out);
		total += s_segment(m, mu_i, si, cph, wphi, smax - b, smax - a, np, flags, out);
	}
	return total;
}

/* Specular albedo at incidence cosine mu_i by the half-vector quadrature (wi in the xz plane).
 * If out (nwl values) is NULL, the Fresnel term is the paint's (achromatic) and the scalar result returned;
 * otherwise per-wavelength conductor Fresnel is accumulated into out. flags: 1 = F = 1 and G = 1 and no
 * horizon cut (the GGX normalisation int D cos(theta_h) dwh = 1, a check of the quadrature).
 * phi_h: see the substitution below and material.h. */
static double spec_quad(const struct mat *m, double mu_i, int level, int flags, double *out)
{
	if (out)
		memset(out, 0, sizeof(double) * (size_t)m->nwl);
	if (!(m->alpha > 0) || !(mu_i > 1e-9))
		return 0.0;
	double si = sqrt(fmax(0.0, 1.0 - mu_i * mu_i));
	int panels = 2 << level;
	/* phi_h = pi/2 + (pi/2) sinh(k t) / sinh(k), t in [-1, 1]: nodes cluster at pi/2 where, at grazing
	 * incidence, the cut-off theta_max(phi_h) turns from ~pi/2 to ~0 within |cos phi_h| < mu_i / sin(theta_i) */
	double k = asinh(fmax(1.0, (M_PI / 2) * si / mu_i));
	double sk = sinh(k), total = 0.0, ht = 2.0 / panels;
	for (int p = 0; p < panels; p++)
		for (int q = 0; q < 8; q++) {
			double t = -1.0 + ht * (p + 0.5 + 0.5 * gx[q]);
			double ph = M_PI / 2 + (M_PI / 2) * sinh(k * t) / sk;
			double w = 0.5 * ht * gw[q] * (M_PI / 2) * k * cosh(k * t) / sk * 2.0; /* x2: mirror half */
			total += spec_line(m, mu_i, si, ph, w, panels, flags, out);
		}
	return total;
}

static double etab_at(const struct mat *m, double mu)
{
	double x = mu * NE;
	if (x <= 0)
		return m->etab[0];
	if (x >= NE)
		return m->etab[NE];
	int j = (int)x;
	double t = x - j;
	return m->etab[j] + t * (m->etab[j + 1] - m->etab[j]);
}

/* int_0^1 g(mu) mu dmu for g = E_table (which = 0) or 1 - E_table (which = 1): 2-point Gauss-Legendre on
 * every table segment, exact for the piecewise-quadratic integrand. */
static double etab_moment(const struct mat *m, int which)
{
	const double x = 0.5773502691896257;
	double sum = 0;
	for (int j = 0; j < NE; j++)
		for (int q = -1; q <= 1; q += 2) {
			double mu = (j + 0.5 + 0.5 * q * x) / NE;
			double e = etab_at(m, mu);
			sum += 0.5 / NE * (which ? 1.0 - e : e) * mu;
		}
	return sum;
}

struct mat *mat_new(enum mat_id id, int nwl, const double *wl, struct acq_err *err)
{
	if (id < 0 || id >= MAT__COUNT) {
		acq_errf(err, ACQ_E_INVAL, "material: unknown material id %d", (int)id);
		return NULL;
	}
	if (nwl < 1 || nwl > 1000000) {
		acq_errf(err, ACQ_E_INVAL, "material: wavelength count %d out of range [1, 1000000]", nwl);
		return NULL;
	}
	for (int l = 0; l < nwl; l++)
		if (!isfinite(wl[l])) {
			acq_errf(err, ACQ_E_INVAL, "material: wavelength %d is not finite", l);
			return NULL;
		}
	struct mat *m = calloc(1, sizeof *m);
	if (!m || !(m->wl = malloc(sizeof(double) * (size_t)nwl)) || !(m->rho = calloc((size_t)nwl, sizeof(double))) ||
	    !(m->n = calloc((size_t)nwl, sizeof(double))) || !(m->k = calloc((size_t)nwl, sizeof(double)))) {
		mat_free(m);
		acq_errf(err, ACQ_E_NOMEM, "material: out of memory");
		return NULL;
	}
	m->id = id;
	m->nwl = nwl;
	memcpy(m->wl, wl, sizeof(double) * (size_t)nwl);
	for (int l = 0; l < nwl; l++) {
		m->rho[l] = mat_rho_d(id, wl[l]);
		if (id == MAT_METAL)
			metal_index(wl[l], &m->n[l], &m->k[l]);
	}
	m->alpha = id == MAT_GREEN_PAINT ? PAINT_ALPHA : id == MAT_METAL ? METAL_ALPHA : 0.0;
	if (id == MAT_GREEN_PAINT) {
		for (int j = 0; j <= NE; j++)
			m->etab[j] = spec_quad(m, fmax((double)j / NE, 1e-3), 2, 0, NULL);
		m->eavg = 2.0 * etab_moment(m, 0);
	}
	return m;
}

void mat_free(struct mat *m)
{
	if (!m)
		return;
	free(m->wl);
	free(m->rho);
	free(m->n);
	free(m->k);
	free(m);
}

int mat_nwl(const struct mat *m)
{
	return m->nwl;
}

void mat_terms(const struct mat *m, const double wi[3], const double wo[3], double *diff, double *spec, double *c)
{
	double mi = wi[2], mo = wo[2];
	*diff = *spec = *c = 0;
	if (!(mi > 0) || !(mo > 0))
		return;
	if (m->id == MAT_WHITE)
		*diff = 1.0 / M_PI;
	else if (m->id == MAT_GREEN_PAINT)
		*diff = (1.0 - etab_at(m, mi)) * (1.0 - etab_at(m, mo)) / (M_PI * (1.0 - m->eavg));
	if (m->alpha > 0) {
		double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] };
		double hl = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
		if (hl > 1e-12) {
			for (int i = 0; i < 3; i++)
				h[i] /= hl;
			double cc = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2];
			double g2 = 1.0 / (1.0 + ggx_lambda(m->alpha, mi) + ggx_lambda(m->alpha, mo));
			if (cc > 0) {
				*spec = ggx_d(m->alpha, h[2]) * g2 / (4.0 * mi * mo);
				*c = cc;
			}
		}
	}
}

void mat_fresnel(const struct mat *m, double c, double *out)
{
	for (int l = 0; l < m->nwl; l++)
		out[l] = m->id == MAT_METAL ? fresnel(c, m->n[l], m->k[l]) :
			 m->id == MAT_GREEN_PAINT ? fresnel(c, PAINT_N, 0.0) : 0.0;
}

void mat_eval(const struct mat *m, const double wi[3], const double wo[3], double *out)
{
	double diff, spec, c;
	mat_terms(m, wi, wo, &diff, &spec, &c);
	if (m->id == MAT_METAL) {
		for (int l = 0; l < m->nwl; l++)
			out[l] = spec > 0 ? spec * fresnel(c, m->n[l], m->k[l]) : 0.0;
		return;
	}
	double fs = spec > 0 ? spec * fresnel(c, PAINT_N, 0.0) : 0.0;
	for (int l = 0; l < m->nwl; l++)
		out[l] = m->rho[l] * diff + fs;
}

int mat_dhr(const struct mat *m, double theta_i, int level, double *dhr, double *sigma, struct acq_err *err)
{
	if (!(theta_i >= 0 && theta_i <= M_PI / 2 + 1e-12))
		return acq_errf(err, ACQ_E_RANGE, "material: incidence zenith %g rad outside [0, pi/2]", theta_i);
	if (level < 0 || level > 6)
		return acq_errf(err, ACQ_E_RANGE, "material: quadrature level %d outside [0, 6]", level);
	double mu_i = cos(theta_i);
	int nwl = m->nwl;
	if (!(mu_i > 1e-9)) {
		memset(dhr, 0, sizeof(double) * (size_t)nwl);
		memset(sigma, 0, sizeof(double) * (size_t)nwl);
		return 0;
	}
	/* diffuse: rho (1 - E_i) * [2 int (1 - E) mu dmu / (1 - E_avg)], by the exact segment quadrature */
	double dfac = 0;
	if (m->id == MAT_WHITE)
		dfac = 2.0 * 0.5; /* 2 int_0^1 mu dmu by the same rule: exactly 1 */
	else if (m->id == MAT_GREEN_PAINT)
		dfac = (1.0 - etab_at(m, mu_i)) * 2.0 * etab_moment(m, 1) / (1.0 - m->eavg);
	if (m->id == MAT_METAL) {
		double *coarse = malloc(sizeof(double) * (size_t)nwl);
		if (!coarse)
			return acq_errf(err, ACQ_E_NOMEM, "material: out of memory");
		spec_quad(m, mu_i, level, 0, coarse);
		spec_quad(m, mu_i, level + 1, 0, dhr);
		/* The error comes from the geometry, the Fresnel factor is smooth: use the largest relative
		 * difference over all wavelengths for each (robust to an accidental agreement at one wavelength). */
		double rel = 0;
		for (int l = 0; l < nwl; l++)
			if (dhr[l] > 0)
				rel = fmax(rel, fabs(dhr[l] - coarse[l]) / dhr[l]);
		for (int l = 0; l < nwl; l++)
			sigma[l] = (4.0 * rel + 2e-7) * dhr[l] + 1e-15;
		free(coarse);
		return 0;
	}
	double s0 = 0, s1 = 0;
	if (m->alpha > 0) {
		s0 = spec_quad(m, mu_i, level, 0, NULL);
		s1 = spec_quad(m, mu_i, level + 1, 0, NULL);
	}
	for (int l = 0; l < nwl; l++) {
		dhr[l] = m->rho[l] * dfac + s1;
		sigma[l] = 4.0 * fabs(s1 - s0) + 2e-7 * s1 + 1e-15 * (1.0 + dhr[l]);
	}
	return 0;
}
