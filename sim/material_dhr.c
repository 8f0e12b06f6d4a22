/* material_dhr: the DHR quadrature of the ground-truth materials (mat_dhr, see material.h): Lambertian parts
 * exactly, lobes by adaptive quadrature at two levels with their difference as the bound, MERL by the midpoint rule. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "sim/mat_lobes.h"
#include "sim/material.h"
#include "sim/material_int.h"

struct cone_ctx {
	const double *wi;
};

static double cone_backscatter(const void *ctx, const double wo[3])
{
	return mat_backscatter(((const struct cone_ctx *)ctx)->wi, wo) / M_PI;
}

static double cone_phong(const void *ctx, const double wo[3])
{
	const double *wi = ((const struct cone_ctx *)ctx)->wi;
	return mat_phong(2.0 * wi[2] * wo[2] - mat_dot3(wi, wo));
}

/* Achromatic quadrature part of the DHR at levels `level` (q[0]) and level + 1 (q[1]) for the materials whose
 * quadrature is achromatic; the factor it multiplies is applied by the caller. */
static void achromatic_parts(const struct mat *m, double mu_i, int level, double q[2])
{
	double wi[3] = { sqrt(fmax(0.0, 1.0 - mu_i * mu_i)), 0, mu_i };
	struct cone_ctx x = { wi };
	for (int k = 0; k < 2; k++) {
		int lv = level + k;
		switch (m->id) {
		case MAT_GREEN_PAINT:
		case MAT_CLEAR_COAT:
		case MAT_CLOTH_SHEEN:
			q[k] = lobe_hv_albedo(&m->lobe, mu_i, lv, 0, NULL);
			break;
		case MAT_ROUGH_BACKSCATTER:
			q[k] = lobe_cone_albedo(wi, 9.0 * BS_WIDTH_DEG * M_PI / 180.0, lv, cone_backscatter, &x);
			break;
		case MAT_SHARP_LOBE: {
			double wr[3] = { -wi[0], 0, mu_i };
			/* beyond gmax the lobe is below 1e-16 of its peak */
			q[k] = lobe_cone_albedo(wr, acos(pow(1e-16, 1.0 / PHONG_N)), lv, cone_phong, &x);
			break;
		}
		default:
			q[k] = 0;
		}
	}
}

/* A conductor lobe's albedo per wavelength at level + 1 into dhr, and its bound (largest relative difference
 * against level, over the wavelengths, x4, plus 2e-7) into sigma. */
static int conductor_part(const struct lobe_hv *L, double mu_i, int level, int nwl, double *dhr, double *sigma,
			  struct acq_err *err)
{
	double *coarse = malloc(sizeof(double) * (size_t)nwl);
	if (!coarse)
		return acq_errf(err, ACQ_E_NOMEM, "material: out of memory");
	lobe_hv_albedo(L, mu_i, level, 0, coarse);
	lobe_hv_albedo(L, mu_i, level + 1, 0, dhr);
	/* The error comes from the geometry, the Fresnel factor is smooth: use the largest relative difference
	 * over all wavelengths for each (robust to an accidental agreement at one wavelength). */
	double rel = 0;
	for (int l = 0; l < nwl; l++)
		if (dhr[l] > 0)
			rel = fmax(rel, fabs(dhr[l] - coarse[l]) / dhr[l]);
	for (int l = 0; l < nwl; l++)
		sigma[l] = (4.0 * rel + 2e-7) * dhr[l] + 1e-15;
	free(coarse);
	return 0;
}

/* The MERL material's channel albedos at mu_i by the midpoint rule on (90 x 360) 2^level cells of
 * (theta_o, phi_o) (the table is piecewise constant: no higher-order rule helps). */
static void merl_channels(const struct mat *m, double mu_i, int level, double a[3])
{
	int nt = 90 << level, np = 360 << level;
	double wi[3] = { sqrt(fmax(0.0, 1.0 - mu_i * mu_i)), 0, mu_i }, ht = M_PI / 2 / nt, hp = 2 * M_PI / np;
	a[0] = a[1] = a[2] = 0;
	for (int i = 0; i < nt; i++) {
		double to = (i + 0.5) * ht, w = sin(to) * cos(to) * ht * hp, row[3] = { 0, 0, 0 };
		for (int j = 0; j < np; j++) {
			double wo[3], rgb[3];
			mat_dir(to, (j + 0.5) * hp, wo);
			mat_merl_rgb(m, wi, wo, rgb);
			for (int k = 0; k < 3; k++)
				row[k] += rgb[k];
		}
		for (int k = 0; k < 3; k++)
			a[k] += w * row[k];
	}
}

static int merl_dhr(const struct mat *m, double mu_i, int level, double *dhr, double *sigma)
{
	double a0[3], a1[3];
	merl_channels(m, mu_i, level, a0);
	merl_channels(m, mu_i, level + 1, a1);
	for (int l = 0; l < m->nwl; l++) {
		double v = 0, e = 0;
		for (int k = 0; k < 3; k++) {
			v += m->basis[k][l] * a1[k];
			e += m->basis[k][l] * fabs(a1[k] - a0[k]);
		}
		dhr[l] = v;
		sigma[l] = 4.0 * e + 1e-15;
	}
	return 0;
}

int mat_dhr(const struct mat *m, double theta_i, int level, double *dhr, double *sigma, struct acq_err *err)
{
	if (!(theta_i >= 0 && theta_i <= M_PI / 2 + 1e-12))
		return acq_errf(err, ACQ_E_RANGE, "material: incidence zenith %g rad outside [0, pi/2]", theta_i);
	if (level < 0 || level > 6)
		return acq_errf(err, ACQ_E_RANGE, "material: quadrature level %d outside [0, 6]", level);
	double mu_i = cos(theta_i);
	int nwl = m->nwl;
	memset(dhr, 0, sizeof(double) * (size_t)nwl);
	memset(sigma, 0, sizeof(double) * (size_t)nwl);
	if (!(mu_i > 1e-9))
		return 0;
	if (m->id == MAT_MERL)
		return merl_dhr(m, mu_i, level, dhr, sigma);
	if (m->id == MAT_METAL || m->id == MAT_CLEAR_COAT) {
		/* the conductor lobe (metal; the coat's base through T(mu_i) T(mu_o)) */
		if (conductor_part(m->id == MAT_METAL ? &m->lobe : &m->base, mu_i, level, nwl, dhr, sigma, err))
			return -1;
		if (m->id == MAT_METAL)
			return 0;
	}
	/* diffuse factor: Lambertian 1 (2 int mu dmu, exact); Kelemen-coupled (1 - E_i) 2 int (1 - E) mu dmu /
	 * (1 - E_avg) by the exact segment rule; Oren-Nayar A + B I(theta_i) (analytic, material.h) */
	double dfac = 0;
	switch (m->id) {
	case MAT_WHITE:
	case MAT_NARROW_LINES:
	case MAT_SHARP_LOBE:
		dfac = 2.0 * 0.5;
		break;
	case MAT_GREEN_PAINT:
	case MAT_CLOTH_SHEEN:
		dfac = (1.0 - lobe_etab_at(m->et.e, mu_i)) * 2.0 * lobe_etab_moment(m->et.e, 1) / (1.0 - m->et.eavg);
		break;
	case MAT_ROUGH_BACKSCATTER: {
		double ti = theta_i, st = sin(ti);
		dfac = m->on_a + m->on_b * (2.0 / M_PI) * (st * (ti / 2 - sin(2 * ti) / 4) + tan(ti) * (1 - st * st * st) / 3);
		break;
	}
	default:
		break;
	}
	double q[2];
	achromatic_parts(m, mu_i, level, q);
	for (int l = 0; l < nwl; l++) {
		/* the quadrature part's spectral factor: Fresnel (inside q) or a fixed spectrum */
		double spec = m->id == MAT_ROUGH_BACKSCATTER ? m->rho[l] : m->id == MAT_CLOTH_SHEEN || m->id == MAT_SHARP_LOBE ?
			      m->fix2[l] : 1.0;
		double val = spec * q[1], bound = 4.0 * spec * fabs(q[1] - q[0]) + 2e-7 * val;
		dhr[l] += m->rho[l] * dfac + val;
		sigma[l] += bound + 1e-15 * (1.0 + dhr[l]);
	}
	return 0;
}
