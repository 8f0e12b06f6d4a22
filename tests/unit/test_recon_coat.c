/* Unit tests of the two-lobe trend kind (recon/trend.c, RECON_TREND_COAT: a narrow coat lobe over a broad base
 * lobe, issue 13): its basis is reciprocal bit for bit, invariant, finite, non-negative and energy-bounded; on an
 * independent clear-coat truth written here (exact dielectric Fresnel, separable Smith masking: not the trend's
 * formulas) sampled on the paper's plan the default fit chooses it, recovers both roughnesses, and its DHR at
 * 8/30/60° is accurate with an honest σ over noise seeds; a one-lobe glossy material does not take it. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "recon/rbf.h"
#include "recon/recon_int.h"
#include "recon/trend.h"
#include "recon_test_util.h"

static void dir(double th, double ph, double v[3])
{
	v[0] = sin(th) * cos(ph);
	v[1] = sin(th) * sin(ph);
	v[2] = cos(th);
}

/* out[0..k) = ∫ fn(ωi, ωo)[j] cosθo dωo at θi by a fine rule: Gauss-Legendre 256 in cosθo × 2048 azimuths. */
static void fine_albedo(double ti, void (*fn)(const double wi[3], const double wo[3], double *f), int k, double *out)
{
	static double x[256], w[256];
	rbf_gauss_legendre01(256, x, w);
	double wi[3], f[TREND_NB + 8];
	dir(ti, 0, wi);
	for (int j = 0; j < k; j++)
		out[j] = 0;
	for (int i = 0; i < 256; i++)
		for (int q = 0; q < 2048; q++) {
			double wo[3];
			dir(acos(x[i]), (q + 0.5) * 2 * M_PI / 2048, wo);
			fn(wi, wo, f);
			for (int j = 0; j < k; j++)
				out[j] += w[i] * x[i] * (2 * M_PI / 2048) * f[j];
		}
}

/* The coat kind's basis at α 0.05, α2 0.3 (the simulator's clear coat). */
static void coat_basis_at(const double wi[3], const double wo[3], double *b)
{
	double c6[6] = { wi[0], wi[1], wi[2], wo[0], wo[1], wo[2] };
	trend_eval_basis2(RECON_TREND_COAT, 0.05, 0.3, c6, b);
}

static void test_coat_basis_properties(void **state)
{
	(void)state;
	static const double ab[][2] = { { TREND_ALPHA_MIN, 0.01 }, { 0.05, 0.3 }, { 0.2, TREND_ALPHA_MAX } };
	for (int t = 0; t < 3000; t++) {
		const double *a = ab[t % 3];
		double ti = acos(rt_unif()), to = acos(rt_unif()), pi = 2 * M_PI * rt_unif(), po = 2 * M_PI * rt_unif();
		switch (t % 12) {
		case 0: ti = 0; break;
		case 1: to = M_PI / 2; break;
		case 2: to = ti; po = pi + M_PI; break; /* the mirror: both lobes' peak */
		default: break;
		}
		double wi[3], wo[3], c1[6], c2[6], c3[6], b1[TREND_NB], b2[TREND_NB], b3[TREND_NB], r = 2 * M_PI * rt_unif();
		dir(ti, pi, wi);
		dir(to, po, wo);
		memcpy(c1, wi, sizeof wi);
		memcpy(c1 + 3, wo, sizeof wo);
		memcpy(c2, wo, sizeof wo);
		memcpy(c2 + 3, wi, sizeof wi);
		dir(ti, pi + r, c3);
		dir(to, po + r, c3 + 3);
		trend_eval_basis2(RECON_TREND_COAT, a[0], a[1], c1, b1);
		trend_eval_basis2(RECON_TREND_COAT, a[0], a[1], c2, b2);
		trend_eval_basis2(RECON_TREND_COAT, a[0], a[1], c3, b3);
		for (int j = 0; j < TREND_NB; j++) {
			assert_true(isfinite(b1[j]) && b1[j] >= 0);
			assert_true(b1[j] == b2[j]); /* reciprocity, bit for bit */
			assert_true(fabs(b3[j] - b1[j]) <= 1e-9 * fmax(b1[j], 1e-20 * (1 + b1[1] + b1[2])));
		}
	}
	/* each term's albedo ≤ 1 (fine rule: its error on an α = 0.05 lobe is ~1e-4); the Lambertian term exactly 1 */
	static const double thetas[] = { 0, 30, 60, 85 };
	for (int t = 0; t < 4; t++) {
		double alb[TREND_NB];
		fine_albedo(thetas[t] * M_PI / 180, coat_basis_at, TREND_NB, alb);
		printf("coat basis albedo at %2.0f°: %.6f %.6f %.6f %.6f %.6f\n", thetas[t], alb[0], alb[1], alb[2], alb[3],
		       alb[4]);
		assert_true(fabs(alb[0] - 1.0) < 1e-9);
		for (int j = 1; j < TREND_NB; j++)
			assert_true(alb[j] <= 1.0 + 1e-3);
	}
	/* the quadrature helpers see both lobes: the narrow one over half vectors, the broad one on the hemisphere rule */
	assert_true(trend_hv_alpha(RECON_TREND_COAT, 0.05) == 0.05);
	assert_true(trend_base_step(RECON_TREND_COAT, 0.3) == 0.15 && isinf(trend_base_step(RECON_TREND_GGX, 0.3)));
	assert_true(trend_two_lobes(RECON_TREND_COAT) && !trend_two_lobes(RECON_TREND_GGX));
	assert_int_equal(trend_from_name("coat"), RECON_TREND_COAT);
}

/*
 * The independent truth: a clear dielectric coat (n = 1.5, GGX α 0.05) over a coloured metallic base (GGX α 0.30,
 * reflectance ρ_λ), the base seen through the coat: f = F(ωi·h) D_c G_c / (4μiμo) + ρ (1 − F(μi))(1 − F(μo))
 * D_b G_b / (4μiμo), F the exact unpolarised Fresnel of a dielectric, G the separable Smith masking G1(μi)G1(μo)
 * (the trend uses the height-correlated form and Schlick-like shapes: the fit must cope with the difference).
 */
#define COAT_A 0.05
#define BASE_A 0.30
#define NCH 4
static const double rho_ch[NCH] = { 0.35, 0.55, 0.75, 0.95 };

static double fresnel(double c)
{
	double n = 1.5, g2 = n * n - 1 + c * c;
	if (g2 <= 0)
		return 1.0;
	double g = sqrt(g2), a = (g - c) / (g + c), b = (c * (g + c) - 1) / (c * (g - c) + 1);
	return 0.5 * a * a * (1 + b * b);
}

static double g1(double alpha, double mu)
{
	return 2 * mu / (mu + sqrt(alpha * alpha + (1 - alpha * alpha) * mu * mu));
}

static double ggx_sep(double alpha, double mi, double mo, double ch)
{
	double a2 = alpha * alpha, t = ch * ch * (a2 - 1) + 1;
	return a2 / (M_PI * t * t) * g1(alpha, mi) * g1(alpha, mo) / (4 * mi * mo);
}

static int one_lobe; /* the one-lobe control: a glossy paint, GGX α 0.12 (exact Fresnel) over a Lambertian ρ_λ/π */

static void coat_truth(const double wi[3], const double wo[3], double f[NCH])
{
	double mi = wi[2], mo = wo[2], h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] };
	double hn = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	for (int l = 0; l < NCH; l++)
		f[l] = 0;
	if (!(mi > 0 && mo > 0 && hn > 0))
		return;
	double ch = h[2] / hn, cd = (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) / hn;
	if (one_lobe) {
		double lobe = fresnel(cd) * ggx_sep(0.12, mi, mo, ch);
		for (int l = 0; l < NCH; l++)
			f[l] = lobe + 0.9 * rho_ch[l] * (1 - fresnel(mi)) * (1 - fresnel(mo)) / M_PI;
		return;
	}
	double coat = fresnel(cd) * ggx_sep(COAT_A, mi, mo, ch);
	double base = (1 - fresnel(mi)) * (1 - fresnel(mo)) * ggx_sep(BASE_A, mi, mo, ch);
	for (int l = 0; l < NCH; l++)
		f[l] = coat + rho_ch[l] * base;
}


/* The paper's plan as acq-sim makes it: θ at the cell centres 4, 12, …, 76°, φo every 36°, φi = 0, pairs closer
 * than 7.5° (the bench's blind zone) dropped; 1 % relative noise. */
static void coat_samples(struct recon_samples *s)
{
	memset(s, 0, sizeof *s);
	s->nwl = NCH;
	s->wl = malloc(NCH * sizeof *s->wl);
	s->ang = malloc(1000 * 4 * sizeof *s->ang);
	s->deg = malloc(1000 * 4 * sizeof *s->deg);
	s->val = malloc(1000 * NCH * sizeof *s->val);
	s->sig = malloc(1000 * NCH * sizeof *s->sig);
	for (int l = 0; l < NCH; l++)
		s->wl[l] = 450 + 200.0 * l;
	size_t k = 0;
	for (int i = 0; i < 10; i++)
		for (int o = 0; o < 10; o++)
			for (int p = 0; p < 10; p++) {
				double a[4] = { (4 + 8 * i) * M_PI / 180, 0, (4 + 8 * o) * M_PI / 180, 36 * p * M_PI / 180 };
				double wi[3], wo[3], f[NCH];
				dir(a[0], a[1], wi);
				dir(a[2], a[3], wo);
				if (wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2] > cos(7.5 * M_PI / 180))
					continue;
				coat_truth(wi, wo, f);
				memcpy(s->ang + 4 * k, a, sizeof a);
				for (int c = 0; c < 4; c++)
					s->deg[4 * k + c] = a[c] * 180 / M_PI;
				for (int l = 0; l < NCH; l++) {
					double sg = 0.01 * f[l] + 1e-6;
					s->val[k * NCH + l] = f[l] + sg * rt_normal();
					s->sig[k * NCH + l] = sg;
				}
				k++;
			}
	s->n = k;
}

/* Samples of the truth (coat_samples) fitted with the defaults (--trend auto). */
static struct recon_model *fit_truth(struct recon_samples *s)
{
	coat_samples(s);
	struct recon_model *m = NULL;
	struct acq_err err = { 0 };
	int rc = recon_fit(s, NULL, &m, &err);
	if (rc)
		printf("fit failed: %s\n", err.msg);
	assert_int_equal(rc, 0);
	return m;
}

/*
 * Over NSEED noise seeds: the default fit (--trend auto) takes the coat kind, its roughnesses within 25 % of the
 * truth's, and the DHR at 8/30/60° within COAT_DHR_TOL of the truth's at every seed and channel; z = error/σ over all
 * seeds, channels and angles has an RMS in [COAT_Z_LO, COAT_Z_HI] (σ × 3 or σ / 3 would leave it). At the first
 * seed the one-lobe GGX trend (forced) errs at 60° by more than 5× the coat's error: the second lobe is what fixes it.
 */
#define NSEED 4
#ifndef COAT_DHR_TOL
#define COAT_DHR_TOL 0.008
#endif
#define COAT_Z_LO 0.45
#define COAT_Z_HI 1.6
static void test_coat_truth_recovered(void **state)
{
	(void)state;
	const double th[3] = { 8 * M_PI / 180, 30 * M_PI / 180, 60 * M_PI / 180 };
	double ref[3][NCH], zz = 0, worst = 0;
	int nz = 0;
	for (int t = 0; t < 3; t++)
		fine_albedo(th[t], coat_truth, NCH, ref[t]);
	for (int sd = 0; sd < NSEED; sd++) {
		struct recon_samples s;
		struct acq_err err = { 0 };
		struct recon_model *m = fit_truth(&s);
		printf("seed %d: trend %s alpha %.4f alpha2 %.4f (truth %.2f, %.2f)\n", sd, trend_name(m->trend), m->trend_alpha,
		       m->trend_alpha2, COAT_A, BASE_A);
		assert_int_equal(m->trend, RECON_TREND_COAT);
		assert_true(fabs(m->trend_alpha / COAT_A - 1) < 0.25 && fabs(m->trend_alpha2 / BASE_A - 1) < 0.25);
		/* one transmission shape (trend.c fit_coat), and this truth's base is seen through (1 − F)²: Schlick's */
		for (size_t l = 0; l < m->nwl; l++)
			assert_true(m->tcoef[l * TREND_NB + 2] == 0 && m->tcoef[l * TREND_NB + 1] > 0);
		double d[3 * NCH], sg[3 * NCH];
		assert_int_equal(recon_dhr(m, 3, th, 32, (uint64_t)sd + 1, d, sg, NULL, NULL, &err), 0);
		for (int t = 0; t < 3; t++)
			for (int l = 0; l < NCH; l++) {
				double e = d[t * NCH + l] - ref[t][l], z = e / sg[t * NCH + l];
				printf("  %2.0f° ch %d: DHR %.5f ± %.5f truth %.5f (z %+.2f)\n", th[t] * 180 / M_PI, l,
				       d[t * NCH + l], sg[t * NCH + l], ref[t][l], z);
				worst = fmax(worst, fabs(e));
				zz += z * z;
				nz++;
			}
		if (sd == 0) {
			struct recon_fit_opts o;
			recon_fit_opts_default(&o);
			o.trend = RECON_TREND_GGX;
			struct recon_model *mg = NULL;
			assert_int_equal(recon_fit(&s, &o, &mg, &err), 0);
			double dg[NCH], sgg[NCH], ec = 0, eg = 0;
			assert_int_equal(recon_dhr(mg, 1, th + 2, 0, 1, dg, sgg, NULL, NULL, &err), 0);
			for (int l = 0; l < NCH; l++) {
				ec = fmax(ec, fabs(d[2 * NCH + l] - ref[2][l]));
				eg = fmax(eg, fabs(dg[l] - ref[2][l]));
			}
			printf("60°: largest error coat %.5f, one GGX lobe %.5f\n", ec, eg);
			assert_true(eg > 5 * ec);
			recon_model_free(mg);
		}
		recon_model_free(m);
		csvio_samples_free(&s);
	}
	double zr = sqrt(zz / nz);
	printf("coat truth, %d seeds: largest DHR error %.5f (tolerance %.3g), z RMS %.2f (band [%.2f, %.2f])\n", NSEED,
	       worst, COAT_DHR_TOL, zr, COAT_Z_LO, COAT_Z_HI);
	assert_true(worst < COAT_DHR_TOL);
	assert_true(zr >= COAT_Z_LO && zr <= COAT_Z_HI);
}

/* A one-lobe glossy paint (the independent formulas above with one GGX lobe, α 0.12, over a Lambertian) must not
 * take the two-lobe kind: the leave-one-out admission (fit.c) needs it to beat the one-lobe choice by two standard
 * errors. Over NSEED noise seeds. */
static void test_one_lobe_not_coat(void **state)
{
	(void)state;
	one_lobe = 1;
	for (int sd = 0; sd < NSEED; sd++) {
		struct recon_samples s;
		struct recon_model *m = fit_truth(&s);
		const char *p = strstr(m->meta, "trend_loo=");
		printf("one-lobe paint, seed %d: trend %s alpha %.4f; %.*s\n", sd, trend_name(m->trend), m->trend_alpha,
		       p ? (int)strcspn(p, "\n") : 0, p ? p : "");
		assert_true(m->trend != RECON_TREND_COAT);
		recon_model_free(m);
		csvio_samples_free(&s);
	}
	one_lobe = 0;
}

/* The energy table of a coat model bounds its albedo (session 15: the base lobe, GGX of α2, integrated over its own
 * half vectors, recon_hv_nodes, apart from the smooth rest and the narrow lobe; energy.c): on a 1° grid of θ the
 * unscaled albedo by the checker's cubature (to 1e-4 absolute below 1, independent of the table's rules) is at most
 * the bound of every table interval holding θ, the cubature's error estimate (doubled) allowed. Seen failing with
 * the base part left out of the table's sum (albedo − bound up to 0.74; the other coat tests passed: the bound
 * stayed below 1, s = 1). */
static void test_coat_energy_table_bounds(void **state)
{
	(void)state;
	struct recon_samples s;
	struct recon_model *m = fit_truth(&s);
	assert_int_equal(m->trend, RECON_TREND_COAT);
	struct albedo_ws ws = { 0 };
	struct acq_err e = { 0 };
	assert_int_equal(recon_albedo_ws_init(&ws, m, 4096, &e), 0);
	int cmu = 48, cphi = 96;
	size_t cq, un = 0;
	recon_lobe_rule(m, ALB_NMU_MAX, 0, &cmu, &cphi, &cq);
	double worst = -HUGE_VAL, top = 0, a[NCH], est[NCH];
	for (int t = 0; t <= 90; t++) {
		double th = t * M_PI / 180;
		assert_int_equal(recon_albedo_cubature(m, th, (cmu + 2) / 3, (cphi + 2) / 3, 0, 1e-4, 1.0, 1 << 16, &ws, a,
							est, &un, &e), 0);
		assert_int_equal(un, 0);
		for (size_t i = 0; i + 1 < m->ntab; i++)
			if (th >= m->tab_theta[i] - 1e-12 && th <= m->tab_theta[i + 1] + 1e-12)
				for (int l = 0; l < NCH; l++) {
					worst = fmax(worst, a[l] - 2 * fabs(est[l]) - m->tab_alb[i * NCH + l]);
					top = fmax(top, a[l]);
				}
	}
	printf("coat model (alpha %.4f, alpha2 %.4f): %zu table nodes, largest albedo %.4f, albedo - bound <= %.2g\n",
	       m->trend_alpha, m->trend_alpha2, m->ntab, top, worst);
	assert_true(worst <= 0);
	recon_albedo_ws_free(&ws);
	recon_model_free(m);
	csvio_samples_free(&s);
}

int main(void)
{
	rt_seed();
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_coat_basis_properties),
		cmocka_unit_test(test_coat_truth_recovered),
		cmocka_unit_test(test_one_lobe_not_coat),
		cmocka_unit_test(test_coat_energy_table_bounds),
	};
	return cmocka_run_group_tests_name("recon_coat", tests, NULL, NULL);
}
