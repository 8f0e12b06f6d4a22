/* Unit tests of recon/trend.c and of the trend in the fit: the basis is symmetric, invariant, finite and
 * non-negative everywhere (pole, horizon, every roughness); its lobes conserve energy; the fit recovers the
 * roughness and coefficients of data from its own family; on microfacet data the default fit keeps the
 * trend and gets the DHR at 60° right where the plain interpolant cannot (a lobe narrower than the 36°
 * azimuth step); on a Phong lobe (not a microfacet lobe) the leave-one-out choice drops it. */
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

static void basis_dirs(double alpha, const double wi[3], const double wo[3], double b[TREND_NB])
{
	double c6[6] = { wi[0], wi[1], wi[2], wo[0], wo[1], wo[2] };
	trend_basis(alpha, c6, b);
}

static void test_basis_symmetric_invariant_finite(void **state)
{
	(void)state;
	static const double alphas[] = { TREND_ALPHA_MIN, 0.05, 0.3, TREND_ALPHA_MAX };
	for (int t = 0; t < 4000; t++) {
		double a = alphas[t % 4];
		/* a quarter of the pairs at the extremes: pole, horizon, coincident, mirror */
		double ti = acos(rt_unif()), to = acos(rt_unif()), pi = 2 * M_PI * rt_unif(), po = 2 * M_PI * rt_unif();
		switch (t % 16) {
		case 0: ti = 0; break;
		case 1: to = M_PI / 2; break;
		case 2: ti = to = M_PI / 2; po = pi + M_PI; break; /* both on the horizon, opposite: h = 0 */
		case 3: to = ti; po = pi; break;                     /* coincident */
		case 4: to = ti; po = pi + M_PI; break;              /* mirror: the lobe's peak */
		default: break;
		}
		double wi[3], wo[3], b1[TREND_NB], b2[TREND_NB], b3[TREND_NB];
		dir(ti, pi, wi);
		dir(to, po, wo);
		basis_dirs(a, wi, wo, b1);
		basis_dirs(a, wo, wi, b2);
		double r = 2 * M_PI * rt_unif(), wir[3], wor[3];
		dir(ti, pi + r, wir);
		dir(to, po + r, wor);
		basis_dirs(a, wir, wor, b3);
		for (int j = 0; j < TREND_NB; j++) {
			assert_true(isfinite(b1[j]) && b1[j] >= 0);
			assert_true(b1[j] == b2[j]); /* reciprocity: the same arithmetic, bit for bit */
			/* rotation only reorders the rounding; at h = 0 (opposite horizon directions) h's direction is
			 * undefined and the Fresnel factor takes it from rounding (measured 4e-8 relative) */
			double tol = t % 16 == 2 ? 1e-6 : 1e-9;
			/* at coincident directions (1 − cosθd)^k is 0 or rounding (≈ 1e-32 for k = 2): a floor relative to the lobe */
			assert_true(fabs(b3[j] - b1[j]) <= tol * fmax(b1[j], 1e-20 * (1 + b1[TREND_LOBE])));
		}
	}
}

/* Albedo of each basis function at θi by a fine rule (Gauss-Legendre 256 in cosθo × 2048 azimuths). */
static void basis_albedo(double alpha, double ti, double alb[TREND_NB])
{
	static double x[256], w[256];
	rbf_gauss_legendre01(256, x, w);
	double wi[3];
	dir(ti, 0, wi);
	for (int j = 0; j < TREND_NB; j++)
		alb[j] = 0;
	for (int i = 0; i < 256; i++)
		for (int k = 0; k < 2048; k++) {
			double wo[3], b[TREND_NB];
			dir(acos(x[i]), (k + 0.5) * 2 * M_PI / 2048, wo);
			basis_dirs(alpha, wi, wo, b);
			for (int j = 0; j < TREND_NB; j++)
				alb[j] += w[i] * x[i] * (2 * M_PI / 2048) * b[j];
		}
}

static void test_basis_conserves_energy(void **state)
{
	(void)state;
	static const double alphas[] = { 0.1, 0.4, 1.0 };
	static const double thetas[] = { 0, 30, 60, 85 };
	for (int a = 0; a < 3; a++)
		for (int t = 0; t < 4; t++) {
			double alb[TREND_NB];
			basis_albedo(alphas[a], thetas[t] * M_PI / 180, alb);
			printf("alpha %.2f theta %2.0f: albedo %.6f %.6f %.6f %.6f %.6f\n", alphas[a], thetas[t], alb[0], alb[1],
			       alb[2], alb[3], alb[4]);
			/* quadrature error of the fine rule on the narrowest lobe ≈ 1e-4 */
			assert_true(fabs(alb[0] - 1.0) < 1e-9);
			for (int j = 1; j < TREND_NB; j++)
				assert_true(alb[j] <= 1.0 + 1e-3);
			/* a narrow GGX lobe loses only its shadowed part: near 1 at normal incidence (0.79 at α = 0.4:
			 * single scattering) */
			if (thetas[t] == 0 && alphas[a] <= 0.1)
				assert_true(alb[TREND_LOBE] > 0.9);
		}
}

/* Samples on the paper's grid of a member of the trend's family (coefficients per channel), with noise. */
static void family_samples(struct recon_samples *s, double alpha, const double *coef, size_t nwl, double noise)
{
	rt_samples_grid(s, 10, 10, 10, nwl, 0, 1.0);
	for (size_t k = 0; k < s->n; k++) {
		double c6[6], b[TREND_NB];
		const double *a = s->ang + 4 * k;
		rbf_canon(a[0], a[1], a[2], a[3], c6);
		trend_basis(alpha, c6, b);
		for (size_t l = 0; l < nwl; l++) {
			double f = 0;
			for (int j = 0; j < TREND_NB; j++)
				f += coef[l * TREND_NB + j] * b[j];
			double sg = noise * f + 1e-6;
			s->val[k * nwl + l] = f + sg * rt_normal();
			s->sig[k * nwl + l] = sg;
		}
	}
}

static void test_fit_recovers_its_family(void **state)
{
	(void)state;
	enum { L = 3 };
	const double alpha = 0.05 + 0.3 * rt_unif();
	/* Lambert, coated diffuse, lobe, lobe·(1 − cosθd)², lobe·(1 − cosθd)⁵ */
	const double coef[L * TREND_NB] = { 0.5, 0.0, 0.2, 0.1, 0.8, 0.1, 0.3, 0.05, 0.0, 0.0, 0.02, 0.4, 0.0, 0.5, 2.0 };
	struct recon_samples s;
	family_samples(&s, alpha, coef, L, 0);
	size_t n = s.n, chan[L] = { 0, 1, 2 };
	double *val = malloc(n * L * sizeof *val), *c6 = malloc(n * 6 * sizeof *c6), eps[L] = { 1e-3, 1e-3, 1e-3 };
	for (size_t k = 0; k < n; k++) {
		const double *a = s.ang + 4 * k;
		rbf_canon(a[0], a[1], a[2], a[3], c6 + 6 * k);
		for (size_t l = 0; l < L; l++)
			val[l * n + k] = s.val[k * L + l];
	}
	double got_alpha, got[L * TREND_NB], rms;
	struct acq_err err = { 0 };
	assert_int_equal(trend_fit(n, L, val, eps, c6, chan, L, &got_alpha, got, &rms, &err), 0);
	printf("alpha %.6f (true %.6f), rms %.3g\n", got_alpha, alpha, rms);
	/* noiseless data of the family: the golden-section search resolves log α to ~1e-5 */
	assert_true(fabs(got_alpha / alpha - 1) < 1e-3);
	assert_true(rms < 1e-3);
	for (int i = 0; i < L * TREND_NB; i++) {
		printf("coef %d: %.6f (true %.6f)\n", i, got[i], coef[i]);
		assert_true(got[i] >= 0);
		assert_true(fabs(got[i] - coef[i]) < 2e-3 * fmax(coef[i], 0.1));
	}
	free(val);
	free(c6);
	csvio_samples_free(&s);
}

/* Exact DHR of a family member at θi (fine rule of basis_albedo). */
static double family_dhr(double alpha, const double *c, double ti)
{
	double alb[TREND_NB], d = 0;
	basis_albedo(alpha, ti, alb);
	for (int j = 0; j < TREND_NB; j++)
		d += c[j] * alb[j];
	return d;
}

static void test_microfacet_data_keep_the_trend(void **state)
{
	(void)state;
	enum { L = 2 };
	/* a glossy paint: coated diffuse 0.3 / 0.6, GGX α = 0.12 with a Fresnel rise, 1 % noise */
	const double alpha = 0.12, coef[L * TREND_NB] = { 0.0, 0.3, 0.04, 0.3, 0.7, 0.0, 0.6, 0.04, 0.3, 0.7 };
	struct recon_samples s;
	family_samples(&s, alpha, coef, L, 0.01);
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	struct recon_model *m = NULL, *m0 = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(recon_fit(&s, &o, &m, &err), 0);
	o.trend = RECON_TREND_NONE;
	assert_int_equal(recon_fit(&s, &o, &m0, &err), 0);
	assert_int_equal(m->trend, RECON_TREND_GGX);
	assert_true(fabs(m->trend_alpha / alpha - 1) < 0.05);
	double th = 60 * M_PI / 180, d[L], sg[L], d0[L], sg0[L];
	assert_int_equal(recon_dhr(m, 1, &th, 8, 3, d, sg, NULL, NULL, &err), 0);
	assert_int_equal(recon_dhr(m0, 1, &th, 8, 3, d0, sg0, NULL, NULL, &err), 0);
	for (int l = 0; l < L; l++) {
		double ref = family_dhr(alpha, coef + l * TREND_NB, th);
		printf("DHR(60°) channel %d: trend %.5f ± %.5f, none %.5f ± %.5f, true %.5f\n", l, d[l], sg[l], d0[l], sg0[l],
		       ref);
		/* 1 % noise on ~500 directions: the DHR to a few 1e-3 with the right lobe shape */
		assert_true(fabs(d[l] - ref) < 0.005);
		assert_true(fabs(d[l] - ref) < 0.5 * fabs(d0[l] - ref));
	}
	recon_model_free(m);
	recon_model_free(m0);
	csvio_samples_free(&s);
}

static void test_phong_lobe_takes_the_phong_trend(void **state)
{
	(void)state;
	/* rt_truth: Lambertian + a normalised cos²⁰ lobe about the mirror direction. Session 3 measured leave-one-out
	 * scores over 12 seeds: plain 0.0257-0.0274, GGX trend 0.0272-0.0292 (always worse), so the plain interpolant
	 * was chosen. The phong trend (session 5) is that family: it must be chosen, with an exponent near 20
	 * (n = 2/α² − 2), and a score below the plain interpolant's and GGX's (metadata trend_loo). */
	struct recon_samples s;
	rt_samples(&s, 4, 0.02, 1.0);
	struct recon_model *m = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(recon_fit(&s, NULL, &m, &err), 0);
	assert_int_equal(m->trend, RECON_TREND_PHONG);
	double n = 2.0 / (m->trend_alpha * m->trend_alpha) - 2.0;
	printf("phong trend exponent %.2f (truth 20)\n", n);
	assert_true(n > 16 && n < 25);
	assert_non_null(strstr(m->meta, "trend=phong"));
	double sc[3] = { 0 };
	const char *names[3] = { "none:", "ggx:", "phong:" };
	for (int i = 0; i < 3; i++) {
		const char *p = strstr(m->meta, names[i]);
		assert_non_null(p);
		sc[i] = atof(p + strlen(names[i]));
	}
	assert_true(sc[2] < sc[0] && sc[2] < sc[1]);
	recon_model_free(m);
	csvio_samples_free(&s);
}

/* The energy table integrates the trend's GGX lobe over half vectors (recon_hv_nodes): the lobe terms' albedo by
 * that rule (64 × 64) agrees with a fine hemisphere rule (256 × 2048) to 2e-3 for α = 0.03-0.3 at θi = 5-85°,
 * and the coarse starting rule (16 × 16) to 5 % relative (measured 9.2e-4, at 85° where the horizon cuts the
 * lobe, and 2.5 %); the table refines it per channel and keeps the last difference as a margin. */
#ifndef HV_TOL
#define HV_TOL 2e-3
#define HV_TOL_COARSE 0.05
#endif
static void test_half_vector_rule(void **state)
{
	(void)state;
	static double c6[256 * 2048 * 6], wt[256 * 2048];
	const double alphas[] = { 0.03, 0.1, 0.3 }, ths[] = { 5, 45, 70, 85 };
	double worst = 0, worstc = 0;
	for (int ia = 0; ia < 3; ia++)
		for (int it = 0; it < 4; it++) {
			double ti = ths[it] * M_PI / 180, al = alphas[ia], ref[TREND_NB] = { 0 }, hv[TREND_NB] = { 0 },
			       co[TREND_NB] = { 0 }, b[TREND_NB];
			assert_int_equal(recon_hemi_nodes(ti, 256, 2048, 0, c6, wt), 0);
			for (size_t q = 0; q < 256 * 2048; q++) {
				trend_basis(al, c6 + 6 * q, b);
				for (int j = TREND_LOBE; j < TREND_NB; j++)
					ref[j] += wt[q] * b[j];
			}
			assert_int_equal(recon_hv_nodes(ti, al, 64, 64, c6, wt), 0);
			for (size_t q = 0; q < 64 * 64; q++) {
				trend_basis(al, c6 + 6 * q, b);
				for (int j = TREND_LOBE; j < TREND_NB; j++)
					hv[j] += wt[q] * b[j];
			}
			assert_int_equal(recon_hv_nodes(ti, al, 16, 16, c6, wt), 0);
			for (size_t q = 0; q < 16 * 16; q++) {
				trend_basis(al, c6 + 6 * q, b);
				for (int j = TREND_LOBE; j < TREND_NB; j++)
					co[j] += wt[q] * b[j];
			}
			for (int j = TREND_LOBE; j < TREND_NB; j++) {
				printf("α %.2f θi %2.0f° term %d: hemisphere %.6f half-vector %.6f (coarse %.6f)\n", al, ths[it], j,
				       ref[j], hv[j], co[j]);
				worst = fmax(worst, fabs(hv[j] - ref[j]));
				worstc = fmax(worstc, fabs(co[j] - ref[j]) / fmax(ref[j], 0.01));
			}
		}
	printf("half-vector rule: largest difference %.2g (64 × 64), %.2g relative (16 × 16)\n", worst, worstc);
	assert_true(worst <= HV_TOL);
	assert_true(worstc <= HV_TOL_COARSE);
}

static void test_ggx_needs_log(void **state)
{
	(void)state;
	struct recon_samples s;
	rt_samples_grid(&s, 3, 3, 3, 2, 0.01, 1.0);
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	o.transform = RECON_T_SQRT;
	o.trend = RECON_TREND_GGX;
	struct recon_model *m = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(recon_fit(&s, &o, &m, &err), -1);
	assert_null(m);
	assert_non_null(strstr(err.msg, "log transform"));
	o.trend = -1; /* auto with sqrt: no trend */
	assert_int_equal(recon_fit(&s, &o, &m, &err), 0);
	assert_int_equal(m->trend, RECON_TREND_NONE);
	recon_model_free(m);
	assert_string_equal(trend_name(RECON_TREND_GGX), "ggx");
	assert_int_equal(trend_from_name("none"), RECON_TREND_NONE);
	assert_int_equal(trend_from_name("phong"), RECON_TREND_PHONG);
	assert_int_equal(trend_from_name("blinn"), -1);
	csvio_samples_free(&s);
}

/* The phong trend's lobe on the same half-vector rule at α/2 (trend_hv_alpha: the energy table splits it like GGX's,
 * session 5: the sharp-lobe fit 10.2 → 0.9 s CPU): against the 256 × 2048 hemisphere rule for n = 2/α² − 2 = 78–3998
 * (α 0.022–0.16), θi 5–85°; same tolerances as GGX's. */
static void test_half_vector_rule_phong(void **state)
{
	(void)state;
	static double c6[256 * 2048 * 6], wt[256 * 2048];
	const double alphas[] = { 0.0223, 0.0891, 0.16 }, ths[] = { 5, 45, 70, 85 };
	double worst = 0, worstc = 0, worst85 = 0;
	for (int ia = 0; ia < 3; ia++)
		for (int it = 0; it < 4; it++) {
			double ti = ths[it] * M_PI / 180, al = alphas[ia], ref[TREND_NB] = { 0 }, hv[TREND_NB] = { 0 },
			       co[TREND_NB] = { 0 }, b[TREND_NB], ha = trend_hv_alpha(RECON_TREND_PHONG, al);
			assert_true(ha > 0);
			assert_int_equal(recon_hemi_nodes(ti, 256, 2048, 0, c6, wt), 0);
			for (size_t q = 0; q < 256 * 2048; q++) {
				trend_eval_basis(RECON_TREND_PHONG, al, c6 + 6 * q, b);
				for (int j = TREND_LOBE; j < TREND_NB; j++)
					ref[j] += wt[q] * b[j];
			}
			assert_int_equal(recon_hv_nodes(ti, ha, 64, 64, c6, wt), 0);
			for (size_t q = 0; q < 64 * 64; q++) {
				trend_eval_basis(RECON_TREND_PHONG, al, c6 + 6 * q, b);
				for (int j = TREND_LOBE; j < TREND_NB; j++)
					hv[j] += wt[q] * b[j];
			}
			assert_int_equal(recon_hv_nodes(ti, ha, 16, 16, c6, wt), 0);
			for (size_t q = 0; q < 16 * 16; q++) {
				trend_eval_basis(RECON_TREND_PHONG, al, c6 + 6 * q, b);
				for (int j = TREND_LOBE; j < TREND_NB; j++)
					co[j] += wt[q] * b[j];
			}
			for (int j = TREND_LOBE; j < TREND_NB; j++) {
				assert_true(ref[j] <= 1.0 + 1e-3); /* the normalised lobe's albedo */
				worst = fmax(worst, fabs(hv[j] - ref[j]));
				if (ths[it] < 80)
					worstc = fmax(worstc, fabs(co[j] - ref[j]) / fmax(ref[j], 0.01));
				else /* the horizon cuts the lobe: the 16 × 16 start is 8-12 % off (0.008-0.011 absolute, at an
				      * albedo ≈ 0.09: the table only compares its bound, value + 2 × the last difference of the
				      * ladder, with 1) */
					worst85 = fmax(worst85, fabs(co[j] - ref[j]));
			}
			printf("phong α %.4f θi %2.0f°: hemisphere %.6f half-vector %.6f (coarse %.6f)\n", al, ths[it], ref[2],
			       hv[2], co[2]);
		}
	printf("phong half-vector rule: largest difference %.2g (64 × 64), %.2g relative (16 × 16, θi < 80°), %.2g "
	       "absolute (16 × 16, 85°)\n", worst, worstc, worst85);
	assert_true(worst <= HV_TOL);
	assert_true(worstc <= HV_TOL_COARSE);
	assert_true(worst85 <= 0.015);
	assert_true(trend_hv_alpha(RECON_TREND_SHEEN, 0.3) == 0 && trend_hv_alpha(RECON_TREND_ROUGH, 0.1) == 0);
}

/* A Lambertian takes no trend (session 9): on the paper's plan (θi 0–67.5° by 7.5°, θo 0–81° by 9°, φo by 36°: the
 * plan samples the mirror direction or within 1.5° of it at most incidences) with 1 % + 1e-4 sr⁻¹ noise, a GGX lobe
 * narrow enough to sit on those near-mirror samples alone fits their noise, and Rippa's leave-one-out, which does
 * not re-fit the trend, scored it a few 0.1 % below the plain interpolant: the lower score alone admitted it on
 * about half the noise draws (acq-sim's white at seed 1: α 0.0136, held-out log-RMSE 0.00034 against 0.00015
 * without it). A trend must now beat the plain interpolant by two standard errors of the score. NSETS data sets from
 * ACQ_SEED: with the old rule all of them keep the plain interpolant with probability ≈ 2⁻⁶. */
static void test_lambertian_takes_no_trend(void **state)
{
	(void)state;
	enum { NI = 10, NO = 10, NP = 10, L = 4, NSETS = 6 };
	int ntrend = 0;
	for (int set = 0; set < NSETS; set++) {
		struct recon_samples s;
		rt_samples_alloc(&s, NI * NO * NP, L, 1);
		for (size_t l = 0; l < L; l++)
			s.wl[l] = 450 + 200.0 * (double)l;
		size_t k = 0;
		for (int i = 0; i < NI; i++)
			for (int o = 0; o < NO; o++)
				for (int p = 0; p < NP; p++, k++) {
					double *a = s.ang + 4 * k;
					a[0] = 7.5 * i * M_PI / 180;
					a[1] = 0;
					a[2] = 9.0 * o * M_PI / 180;
					a[3] = 36.0 * p * M_PI / 180;
					for (int c = 0; c < 4; c++)
						s.deg[4 * k + c] = a[c] * 180 / M_PI;
					for (size_t l = 0; l < L; l++) {
						double f = (0.3 + 0.2 * (double)l) / M_PI, sg = 0.01 * f + 1e-4;
						s.val[k * L + l] = f + sg * rt_normal();
						s.sig[k * L + l] = sg;
					}
				}
		struct recon_model *m = NULL;
		struct acq_err err = { 0 };
		assert_int_equal(recon_fit(&s, NULL, &m, &err), 0);
		const char *sc = strstr(m->meta, "trend_loo=");
		assert_non_null(sc);
		printf("set %d: trend %s alpha %.4g, %.*s\n", set, trend_name(m->trend), m->trend_alpha,
		       (int)strcspn(sc, "\n"), sc);
		ntrend += m->trend != RECON_TREND_NONE;
		recon_model_free(m);
		csvio_samples_free(&s);
	}
	assert_int_equal(ntrend, 0);
}

int main(void)
{
	rt_seed();
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_basis_symmetric_invariant_finite),
		cmocka_unit_test(test_basis_conserves_energy),
		cmocka_unit_test(test_fit_recovers_its_family),
		cmocka_unit_test(test_microfacet_data_keep_the_trend),
		cmocka_unit_test(test_phong_lobe_takes_the_phong_trend),
		cmocka_unit_test(test_ggx_needs_log),
		cmocka_unit_test(test_half_vector_rule),
		cmocka_unit_test(test_half_vector_rule_phong),
		cmocka_unit_test(test_lambertian_takes_no_trend),
	};
	return cmocka_run_group_tests_name("recon_trend", tests, NULL, NULL);
}
