/* material: ground-truth spectral BRDFs of the simulated samples: the catalogue, their spectra and evaluation (see
 * material.h; their DHR quadrature: material_dhr.c). */
#include "sim/material.h"

#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "recon/colour.h"
#include "recon/merl.h"
#include "sim/mat_lobes.h"
#include "sim/material_int.h"

static const char *const names[MAT__COUNT] = { "green-paint", "white", "metal", "clear-coat", "rough-backscatter",
					       "cloth-sheen", "sharp-lobe", "narrow-lines", "merl" };

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
	return ((int)id >= 0 && id < MAT__COUNT) ? names[id] : "?";
}

const char *mat_names_list(void)
{
	return "green-paint, white, metal, clear-coat, rough-backscatter, cloth-sheen, sharp-lobe, narrow-lines, "
	       "merl (from a MERL file)";
}

enum mat_id mat_id_of(const struct mat *m)
{
	return m->id;
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

static double gauss(double x, double mu, double s)
{
	double g = (x - mu) / s;
	return exp(-0.5 * g * g);
}

static double logistic(double x, double mu, double s)
{
	return 1.0 / (1.0 + exp(-(x - mu) / s));
}

/* Holmium-oxide-like absorption lines: centre nm, Gaussian sigma nm, depth. */
static const double lines[][3] = { { 468, 2.5, 0.35 }, { 485, 3.0, 0.30 }, { 537, 3.5, 0.55 },
				   { 641, 4.0, 0.50 }, { 890, 5.0, 0.40 }, { 1015, 6.0, 0.45 } };

double mat_rho_d(enum mat_id id, double wl)
{
	wl = clamp_wl(wl);
	switch (id) {
	case MAT_GREEN_PAINT:
		/* green pigment: reflectance peak at 530 nm, absorbing red, NIR red edge near 720 nm */
		return 0.05 + 0.40 * gauss(wl, 530.0, 38.0) + 0.60 / (1.0 + exp(-(wl - 720.0) / 22.0));
	case MAT_WHITE: {
		double x = (wl - MAT_WL_MIN) / (MAT_WL_MAX - MAT_WL_MIN);
		return 0.99 - 0.015 * exp(-(wl - MAT_WL_MIN) / 30.0) - 0.012 * x * x * x * x;
	}
	case MAT_ROUGH_BACKSCATTER: /* terracotta: iron-oxide red edge near 580 nm */
		return 0.10 + 0.42 * logistic(wl, 585.0, 28.0) + 0.08 * logistic(wl, 850.0, 60.0);
	case MAT_CLOTH_SHEEN: /* red dye on a fabric, bright NIR */
		return 0.04 + 0.36 * logistic(wl, 610.0, 18.0) + 0.15 * logistic(wl, 780.0, 40.0);
	case MAT_SHARP_LOBE: /* blue pigment under a glossy varnish */
		return 0.05 + 0.42 * gauss(wl, 465.0, 45.0) + 0.40 * logistic(wl, 760.0, 30.0) - 0.02 * logistic(wl, 1000, 40);
	case MAT_NARROW_LINES: {
		double r = 0.90 + 0.03 * (wl - MAT_WL_MIN) / (MAT_WL_MAX - MAT_WL_MIN);
		for (size_t j = 0; j < sizeof lines / sizeof lines[0]; j++)
			r *= 1.0 - lines[j][2] * gauss(wl, lines[j][0], lines[j][1]);
		return r;
	}
	default:
		return 0.0;
	}
}

/* The second fixed spectrum: the cloth's sheen colour, the sharp lobe's k_s. */
static double fix2_at(enum mat_id id, double wl)
{
	wl = clamp_wl(wl);
	if (id == MAT_CLOTH_SHEEN)
		return 0.62 + 0.10 * logistic(wl, 640.0, 60.0);
	if (id == MAT_SHARP_LOBE)
		return PHONG_KS;
	return 0.0;
}

/* Complex refractive indices (smoothed from published optical constants): gold-like (metal), copper-like
 * (clear coat base). */
static const double ix_wl[] = { 450, 500, 550, 600, 650, 700, 800, 900, 1000, 1100 };
static const double au_n[] = { 1.47, 0.97, 0.43, 0.25, 0.17, 0.16, 0.15, 0.17, 0.22, 0.27 };
static const double au_k[] = { 1.95, 1.87, 2.45, 3.00, 3.50, 3.95, 4.90, 5.70, 6.40, 7.10 };
static const double cu_n[] = { 1.24, 1.12, 1.02, 0.30, 0.21, 0.21, 0.26, 0.29, 0.32, 0.36 };
static const double cu_k[] = { 2.40, 2.56, 2.58, 3.35, 3.67, 4.20, 5.00, 5.70, 6.40, 7.00 };

static void conductor_index(enum mat_id id, double wl, double *n, double *k)
{
	const double *tn = id == MAT_METAL ? au_n : cu_n, *tk = id == MAT_METAL ? au_k : cu_k;
	wl = clamp_wl(wl);
	int m = (int)(sizeof ix_wl / sizeof ix_wl[0]);
	int i = 0;
	while (i < m - 2 && wl > ix_wl[i + 1])
		i++;
	double t = (wl - ix_wl[i]) / (ix_wl[i + 1] - ix_wl[i]);
	*n = tn[i] + t * (tn[i + 1] - tn[i]);
	*k = tk[i] + t * (tk[i + 1] - tk[i]);
}

/* The common part of a new material: validation and the per-wavelength arrays. */
static struct mat *mat_alloc(enum mat_id id, int nwl, const double *wl, struct acq_err *err)
{
	if ((int)id < 0 || id >= MAT__COUNT) {
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
	size_t sz = sizeof(double) * (size_t)nwl;
	struct mat *m = calloc(1, sizeof *m);
	if (!m || !(m->wl = malloc(sz)) || !(m->rho = calloc(1, sz)) || !(m->fix2 = calloc(1, sz)) ||
	    !(m->n = calloc(1, sz)) || !(m->k = calloc(1, sz))) {
		mat_free(m);
		acq_errf(err, ACQ_E_NOMEM, "material: out of memory");
		return NULL;
	}
	m->id = id;
	m->nwl = nwl;
	memcpy(m->wl, wl, sz);
	return m;
}

/* The MERL upsampling basis before its correction: a partition of unity of Gaussians (material.h). */
static void merl_g(double wl, double g[3])
{
	static const double c[3] = { 640.0, 540.0, 450.0 };
	double sum = 0;
	for (int k = 0; k < 3; k++) {
		double x = (wl - c[k]) / 20.0;
		g[k] = (k == 0 && wl > c[0]) || (k == 2 && wl < c[2]) ? 1.0 : exp(-0.5 * x * x);
		sum += g[k];
	}
	for (int k = 0; k < 3; k++)
		g[k] /= sum;
}

/* B = G M^-1 at the material's wavelengths (material.h); checks B >= 0 on the 1 nm grid. */
static int merl_basis(struct mat *m, struct acq_err *err)
{
	enum { NF = 651 };
	double wl[NF], M[3][3] = { { 0 } }, Mi[3][3];
	for (int i = 0; i < NF; i++)
		wl[i] = MAT_WL_MIN + i;
	struct colour_opts o;
	colour_opts_brdf(&o);
	double *W = malloc(sizeof(double) * 3 * NF);
	if (!W)
		return acq_errf(err, ACQ_E_NOMEM, "material: out of memory");
	if (colour_weights(&o, wl, NF, W, err)) {
		free(W);
		return -1;
	}
	for (int k = 0; k < 3; k++) {
		double col[NF], rgb[3];
		for (int i = 0; i < NF; i++) {
			double g[3];
			merl_g(wl[i], g);
			col[i] = g[k];
		}
		colour_apply_weights(W, NF, col, rgb);
		for (int j = 0; j < 3; j++)
			M[j][k] = rgb[j];
	}
	free(W);
	double det = M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) - M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
		     M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0]);
	if (!(fabs(det) > 1e-12))
		return acq_errf(err, ACQ_E_NUMERIC, "material: MERL basis: singular colour matrix");
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++) {
			int i1 = (j + 1) % 3, i2 = (j + 2) % 3, j1 = (i + 1) % 3, j2 = (i + 2) % 3;
			Mi[i][j] = (M[i1][j1] * M[i2][j2] - M[i1][j2] * M[i2][j1]) / det;
		}
	for (int i = 0; i < NF + m->nwl; i++) {
		double x = i < NF ? wl[i] : m->wl[i - NF], g[3];
		merl_g(x, g);
		for (int k = 0; k < 3; k++) {
			double b = g[0] * Mi[0][k] + g[1] * Mi[1][k] + g[2] * Mi[2][k];
			if (i < NF && b < 0)
				return acq_errf(err, ACQ_E_NUMERIC, "material: MERL basis negative (%g) at %g nm", b, x);
			if (i >= NF)
				m->basis[k][i - NF] = fmax(0.0, b);
		}
	}
	return 0;
}

struct mat *mat_new_merl(const char *path, int nwl, const double *wl, struct acq_err *err)
{
	struct mat *m = mat_alloc(MAT_MERL, nwl, wl, err);
	if (!m)
		return NULL;
	for (int k = 0; k < 3; k++)
		if (!(m->basis[k] = calloc((size_t)nwl, sizeof(double)))) {
			mat_free(m);
			acq_errf(err, ACQ_E_NOMEM, "material: out of memory");
			return NULL;
		}
	if (merl_read(path, &m->merl, err) || merl_basis(m, err)) {
		mat_free(m);
		return NULL;
	}
	return m;
}

struct mat *mat_new(enum mat_id id, int nwl, const double *wl, struct acq_err *err)
{
	if (id == MAT_MERL) {
		acq_errf(err, ACQ_E_INVAL, "material: merl is read from a MERL file (merl:FILE, sim.merl_file)");
		return NULL;
	}
	struct mat *m = mat_alloc(id, nwl, wl, err);
	if (!m)
		return NULL;
	for (int l = 0; l < nwl; l++) {
		m->rho[l] = mat_rho_d(id, wl[l]);
		m->fix2[l] = fix2_at(id, wl[l]);
		if (id == MAT_METAL || id == MAT_CLEAR_COAT)
			conductor_index(id, wl[l], &m->n[l], &m->k[l]);
	}
	struct lobe_hv ggx = { .kind = LOBE_GGX, .scale = 1.0, .nwl = nwl };
	switch (id) {
	case MAT_GREEN_PAINT:
		m->lobe = ggx;
		m->lobe.alpha = PAINT_ALPHA;
		m->lobe.n_diel = DIEL_N;
		lobe_etab_fill(&m->et, &m->lobe);
		break;
	case MAT_METAL:
		m->lobe = ggx;
		m->lobe.alpha = METAL_ALPHA;
		m->lobe.cn = m->n;
		m->lobe.ck = m->k;
		break;
	case MAT_CLEAR_COAT:
		m->lobe = ggx;
		m->lobe.alpha = COAT_ALPHA;
		m->lobe.n_diel = DIEL_N;
		lobe_etab_fill(&m->et, &m->lobe);
		for (int j = 0; j <= LOBE_NE; j++) /* the base sees the coat's transmission T = 1 - E_coat */
			m->et.e[j] = 1.0 - m->et.e[j];
		m->base = ggx;
		m->base.alpha = COAT_BASE_ALPHA;
		m->base.cn = m->n;
		m->base.ck = m->k;
		m->base.ttab = m->et.e;
		break;
	case MAT_CLOTH_SHEEN: {
		m->lobe = (struct lobe_hv){ .kind = LOBE_CHARLIE, .alpha = SHEEN_R, .scale = 1.0, .nwl = nwl };
		lobe_etab_fill(&m->et, &m->lobe);
		double emax = 0;
		for (int j = 0; j <= LOBE_NE; j++)
			emax = fmax(emax, m->et.e[j]);
		m->lobe.scale = SHEEN_EMAX / emax; /* the albedo is linear in the scale */
		for (int j = 0; j <= LOBE_NE; j++)
			m->et.e[j] *= m->lobe.scale;
		m->et.eavg *= m->lobe.scale;
		break;
	}
	case MAT_ROUGH_BACKSCATTER: {
		double s2 = ON_SIGMA * ON_SIGMA;
		m->on_a = 1.0 - 0.5 * s2 / (s2 + 0.33);
		m->on_b = 0.45 * s2 / (s2 + 0.09);
		break;
	}
	default:
		break;
	}
	return m;
}

void mat_free(struct mat *m)
{
	if (!m)
		return;
	free(m->wl);
	free(m->rho);
	free(m->fix2);
	free(m->n);
	free(m->k);
	for (int k = 0; k < 3; k++)
		free(m->basis[k]);
	merl_free(&m->merl);
	free(m);
}

double mat_dot3(const double a[3], const double b[3])
{
	return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* Cosine between wi and the half vector, and the half vector's cosine with the normal; 0 when undefined. */
static double half_cos(const double wi[3], const double wo[3], double *ch)
{
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] };
	double hl = sqrt(mat_dot3(h, h));
	*ch = 0;
	if (!(hl > 1e-12))
		return 0;
	*ch = h[2] / hl;
	double c = mat_dot3(wi, h) / hl;
	return c > 0 ? c : 0;
}

/* Oren-Nayar (qualitative) factor A + B max(0, cos dphi) sin(alpha) tan(beta), symmetric in wi, wo. */
static double oren_nayar(const struct mat *m, const double wi[3], const double wo[3])
{
	double si = sqrt(fmax(0.0, 1.0 - wi[2] * wi[2])), so = sqrt(fmax(0.0, 1.0 - wo[2] * wo[2]));
	if (si < 1e-12 || so < 1e-12)
		return m->on_a;
	double cphi = (wi[0] * wo[0] + wi[1] * wo[1]) / (si * so);
	double mmin = fmin(wi[2], wo[2]), mmax = fmax(wi[2], wo[2]);
	double sa = sqrt(fmax(0.0, 1.0 - mmin * mmin)), tb = sqrt(fmax(0.0, 1.0 - mmax * mmax)) / mmax;
	return m->on_a + m->on_b * fmax(0.0, cphi) * sa * tb;
}

double mat_backscatter(const double wi[3], const double wo[3])
{
	double x[3] = { wi[1] * wo[2] - wi[2] * wo[1], wi[2] * wo[0] - wi[0] * wo[2], wi[0] * wo[1] - wi[1] * wo[0] };
	double g = atan2(sqrt(mat_dot3(x, x)), mat_dot3(wi, wo)) / (BS_WIDTH_DEG * M_PI / 180.0);
	return BS_AMP * exp(-0.5 * g * g);
}

double mat_phong(double wrwo)
{
	return wrwo > 0 ? (PHONG_N + 2.0) / (2.0 * M_PI) * pow(wrwo, PHONG_N) : 0.0;
}

void mat_merl_rgb(const struct mat *m, const double wi[3], const double wo[3], double rgb[3])
{
	if (merl_lookup(&m->merl, wi, wo, rgb) != 0)
		rgb[0] = rgb[1] = rgb[2] = 0;
}

int mat_terms(const struct mat *m, const double wi[3], const double wo[3], struct mat_term *t)
{
	double mi = wi[2], mo = wo[2], ch = 0, c = 0;
	t[0] = (struct mat_term){ 0, MAT_S_RHO, 0 };
	t[1] = (struct mat_term){ 0, MAT_S_FIX2, 0 };
	bool up = mi > 0 && mo > 0;
	switch (m->id) {
	case MAT_MERL: {
		double rgb[3];
		mat_merl_rgb(m, wi, wo, rgb);
		for (int k = 0; k < 3; k++)
			t[k] = (struct mat_term){ up ? rgb[k] : 0, MAT_S_BASIS_R + k, 0 };
		return 3;
	}
	case MAT_WHITE:
	case MAT_NARROW_LINES:
		t[0].w = up ? 1.0 / M_PI : 0;
		return 1;
	case MAT_GREEN_PAINT:
	case MAT_CLOTH_SHEEN:
		if (up) {
			t[0].w = (1.0 - lobe_etab_at(m->et.e, mi)) * (1.0 - lobe_etab_at(m->et.e, mo)) /
				 (M_PI * (1.0 - m->et.eavg));
			c = half_cos(wi, wo, &ch);
		}
		t[1] = (struct mat_term){ c > 0 ? lobe_hv_geom(&m->lobe, mi, mo, ch) : 0,
					  m->id == MAT_CLOTH_SHEEN ? MAT_S_FIX2 : MAT_S_DIEL, c };
		return 2;
	case MAT_METAL:
		if (up)
			c = half_cos(wi, wo, &ch);
		t[0] = (struct mat_term){ c > 0 ? lobe_hv_geom(&m->lobe, mi, mo, ch) : 0, MAT_S_COND, c };
		return 1;
	case MAT_CLEAR_COAT:
		if (up)
			c = half_cos(wi, wo, &ch);
		t[0] = (struct mat_term){ c > 0 ? lobe_hv_geom(&m->lobe, mi, mo, ch) : 0, MAT_S_DIEL, c };
		t[1] = (struct mat_term){ c > 0 ? lobe_hv_geom(&m->base, mi, mo, ch) : 0, MAT_S_COND, c };
		return 2;
	case MAT_ROUGH_BACKSCATTER:
		t[0].w = up ? (oren_nayar(m, wi, wo) + mat_backscatter(wi, wo)) / M_PI : 0;
		return 1;
	case MAT_SHARP_LOBE:
		t[0].w = up ? 1.0 / M_PI : 0;
		t[1].w = up ? mat_phong(2.0 * mi * mo - mat_dot3(wi, wo)) : 0;
		return 2;
	default:
		return 0;
	}
}

void mat_spectrum(const struct mat *m, enum mat_spec s, double c, double *out)
{
	double fd = s == MAT_S_DIEL ? lobe_fresnel(c, DIEL_N, 0.0) : 0.0;
	bool has_cond = m->id == MAT_METAL || m->id == MAT_CLEAR_COAT;
	const double *b = s >= MAT_S_BASIS_R && s <= MAT_S_BASIS_B ? m->basis[s - MAT_S_BASIS_R] : NULL;
	for (int l = 0; l < m->nwl; l++)
		out[l] = s == MAT_S_RHO ? m->rho[l] : s == MAT_S_FIX2 ? m->fix2[l] : s == MAT_S_DIEL ? fd :
			 s == MAT_S_COND && has_cond ? lobe_fresnel(c, m->n[l], m->k[l]) : b ? b[l] : 0.0;
}

void mat_eval(const struct mat *m, const double wi[3], const double wo[3], double *out)
{
	struct mat_term t[MAT_MAX_TERMS];
	int nt = mat_terms(m, wi, wo, t);
	memset(out, 0, sizeof(double) * (size_t)m->nwl);
	for (int j = 0; j < nt; j++) {
		double w = t[j].w;
		if (!(w > 0))
			continue;
		switch (t[j].spec) {
		case MAT_S_RHO:
			for (int l = 0; l < m->nwl; l++)
				out[l] += w * m->rho[l];
			break;
		case MAT_S_FIX2:
			for (int l = 0; l < m->nwl; l++)
				out[l] += w * m->fix2[l];
			break;
		case MAT_S_DIEL: {
			double f = w * lobe_fresnel(t[j].c, DIEL_N, 0.0);
			for (int l = 0; l < m->nwl; l++)
				out[l] += f;
			break;
		}
		case MAT_S_BASIS_R:
		case MAT_S_BASIS_G:
		case MAT_S_BASIS_B: {
			const double *b = m->basis[t[j].spec - MAT_S_BASIS_R];
			for (int l = 0; l < m->nwl; l++)
				out[l] += w * b[l];
			break;
		}
		default:
			for (int l = 0; l < m->nwl; l++)
				out[l] += w * lobe_fresnel(t[j].c, m->n[l], m->k[l]);
			break;
		}
	}
}
