/* mat_lobes: Fresnel, half-vector lobes, albedo tables and lobe quadratures of the simulator's materials
 * (see mat_lobes.h). */
#include "sim/mat_lobes.h"

#include <math.h>
#include <string.h>

static const double gx[8] = { -0.9602898564975363, -0.7966664774136267, -0.5255324099163290,
			       -0.1834346424956498, 0.1834346424956498,  0.5255324099163290,
			       0.7966664774136267,  0.9602898564975363 };
static const double gw[8] = { 0.1012285362903763, 0.2223810344533745, 0.3137066458778873,
			       0.3626837833783620, 0.3626837833783620, 0.3137066458778873,
			       0.2223810344533745, 0.1012285362903763 };

double lobe_fresnel(double c, double n, double k)
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

/* GGX distribution D(cos theta_h) of roughness alpha. */
static double lobe_ggx_d(double alpha, double ch)
{
	double a2 = alpha * alpha, t = ch * ch * (a2 - 1.0) + 1.0;
	return a2 / (M_PI * t * t);
}

/* Smith Lambda of GGX at direction cosine mu. */
static double lobe_ggx_lambda(double alpha, double mu)
{
	double t2 = (1.0 - mu * mu) / (mu * mu);
	return 0.5 * (sqrt(1.0 + alpha * alpha * t2) - 1.0);
}

/* Charlie sheen distribution (2 + 1/r) sin(theta_h)^(1/r) / (2 pi): normalised, int D cos dwh = 1. */
static double charlie_d(double r, double ch)
{
	double sh2 = fmax(0.0, 1.0 - ch * ch);
	return (2.0 + 1.0 / r) * pow(sh2, 0.5 / r) / (2.0 * M_PI);
}

static double lobe_d(const struct lobe_hv *L, double ch)
{
	return L->kind == LOBE_GGX ? lobe_ggx_d(L->alpha, ch) : charlie_d(L->alpha, ch);
}

/* The angle substitution's scale: GGX's own roughness; the broad sheen lobe is integrated in theta_h itself. */
static double sub_alpha(const struct lobe_hv *L)
{
	return L->kind == LOBE_GGX ? L->alpha : 1.0;
}

double lobe_etab_at(const double *e, double mu)
{
	double x = mu * LOBE_NE;
	if (x <= 0)
		return e[0];
	if (x >= LOBE_NE)
		return e[LOBE_NE];
	int j = (int)x;
	double t = x - j;
	return e[j] + t * (e[j + 1] - e[j]);
}

double lobe_etab_moment(const double *e, int which)
{
	const double x = 0.5773502691896257;
	double sum = 0;
	for (int j = 0; j < LOBE_NE; j++)
		for (int q = -1; q <= 1; q += 2) {
			double mu = (j + 0.5 + 0.5 * q * x) / LOBE_NE;
			double v = lobe_etab_at(e, mu);
			sum += 0.5 / LOBE_NE * (which ? 1.0 - v : v) * mu;
		}
	return sum;
}

double lobe_hv_geom(const struct lobe_hv *L, double mi, double mo, double ch)
{
	if (!(mi > 0) || !(mo > 0))
		return 0.0;
	double v;
	if (L->kind == LOBE_GGX) {
		double g2 = 1.0 / (1.0 + lobe_ggx_lambda(L->alpha, mi) + lobe_ggx_lambda(L->alpha, mo));
		v = lobe_ggx_d(L->alpha, ch) * g2 / (4.0 * mi * mo);
	} else {
		v = L->scale * charlie_d(L->alpha, ch) / (4.0 * (mi + mo - mi * mo));
	}
	if (L->ttab)
		v *= lobe_etab_at(L->ttab, mi) * lobe_etab_at(L->ttab, mo);
	return v;
}

/* Gauss-Legendre over s in [a, b] (np panels of 8 nodes) on the phi_h line of cosine cph (weight wphi). */
static double s_segment(const struct lobe_hv *L, double mu_i, double si, double cph, double wphi, double a, double b,
			int np, int flags, double *out)
{
	double alpha = sub_alpha(L), hs = (b - a) / np, total = 0;
	double ti = L->ttab ? lobe_etab_at(L->ttab, mu_i) : 1.0;
	for (int p = 0; p < np; p++)
		for (int q = 0; q < 8; q++) {
			double s = a + hs * (p + 0.5 + 0.5 * gx[q]);
			double cs = cos(s), ss = sin(s);
			double th = atan(alpha * tan(s));
			double jac = alpha / (cs * cs + alpha * alpha * ss * ss);
			double ch = cos(th), sh = sin(th);
			double dval = lobe_d(L, ch) * sh * jac * 0.5 * hs * gw[q] * wphi;
			if (flags & 1) {
				total += dval * ch;
				continue;
			}
			double c = si * sh * cph + mu_i * ch;
			double mu_o = 2.0 * c * ch - mu_i;
			if (c <= 0 || mu_o <= 0)
				continue;
			double base;
			if (L->kind == LOBE_GGX) {
				double g2 = 1.0 / (1.0 + lobe_ggx_lambda(L->alpha, mu_i) + lobe_ggx_lambda(L->alpha, mu_o));
				base = dval * g2 * c / mu_i;
			} else {
				base = dval * L->scale * c * mu_o / (mu_i + mu_o - mu_i * mu_o);
			}
			if (L->ttab)
				base *= ti * lobe_etab_at(L->ttab, mu_o);
			if (out) {
				for (int l = 0; l < L->nwl; l++)
					out[l] += base * lobe_fresnel(c, L->cn[l], L->ck[l]);
			} else {
				total += L->n_diel > 0 ? base * lobe_fresnel(c, L->n_diel, 0.0) : base;
			}
		}
	return total;
}

/* One phi_h line of the half-vector quadrature (weight wphi), theta_h from 0 to the horizon cut-off. */
static double spec_line(const struct lobe_hv *L, double mu_i, double si, double ph, double wphi, int panels,
			int flags, double *out)
{
	double alpha = sub_alpha(L), cph = cos(ph), smax = M_PI / 2, total = 0;
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
		total += s_segment(L, mu_i, si, cph, wphi, a, b, np, flags, out);
		total += s_segment(L, mu_i, si, cph, wphi, smax - b, smax - a, np, flags, out);
	}
	return total;
}

double lobe_hv_albedo(const struct lobe_hv *L, double mu_i, int level, int flags, double *out)
{
	if (out)
		memset(out, 0, sizeof(double) * (size_t)L->nwl);
	if (!(L->alpha > 0) || !(mu_i > 1e-9))
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
			total += spec_line(L, mu_i, si, ph, w, panels, flags, out);
		}
	return total;
}

void lobe_etab_fill(struct lobe_etab *t, const struct lobe_hv *L)
{
	for (int j = 0; j <= LOBE_NE; j++)
		t->e[j] = lobe_hv_albedo(L, fmax((double)j / LOBE_NE, 1e-3), 2, 0, NULL);
	t->eavg = 2.0 * lobe_etab_moment(t->e, 0);
}

double lobe_cone_albedo(const double c[3], double gmax, int level, lobe_fn g, const void *ctx)
{
	/* u, v: an orthonormal pair perpendicular to c */
	double u[3], v[3];
	if (fabs(c[2]) < 0.9) {
		double n = sqrt(c[0] * c[0] + c[1] * c[1]);
		u[0] = c[0] * c[2] / n, u[1] = c[1] * c[2] / n, u[2] = -n; /* in the plane of c and z */
	} else {
		double n = sqrt(c[2] * c[2] + c[0] * c[0]);
		u[0] = c[2] / n, u[1] = 0, u[2] = -c[0] / n;
	}
	v[0] = c[1] * u[2] - c[2] * u[1];
	v[1] = c[2] * u[0] - c[0] * u[2];
	v[2] = c[0] * u[1] - c[1] * u[0];
	int panels = 4 << level;
	double hp = 2.0 * M_PI / panels, total = 0;
	for (int p = 0; p < panels; p++)
		for (int q = 0; q < 8; q++) {
			double psi = hp * (p + 0.5 + 0.5 * gx[q]), cp = cos(psi), sp = sin(psi);
			double t = u[2] * cp + v[2] * sp;
			/* mu_o(gamma) = c_z cos(gamma) + t sin(gamma) vanishes at gamma_h = atan2(c_z, -t) */
			double gend = fmin(gmax, atan2(c[2], -t));
			double line = 0, hx = 1.0 / panels;
			for (int a = 0; a < panels; a++)
				for (int b = 0; b < 8; b++) {
					double x = hx * (a + 0.5 + 0.5 * gx[b]), gam = gend * x * x;
					double sg = sin(gam), cg = cos(gam), wo[3];
					for (int i = 0; i < 3; i++)
						wo[i] = cg * c[i] + sg * (cp * u[i] + sp * v[i]);
					double mu = wo[2];
					if (!(mu > 0))
						continue;
					line += 0.5 * hx * gw[b] * 2.0 * gend * x * sg * mu * g(ctx, wo);
				}
			total += 0.5 * hp * gw[q] * line;
		}
	return total;
}
