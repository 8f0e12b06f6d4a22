/* Unit tests for sim/material.c: reciprocity, non-negativity and albedo <= 1 at 10^4 random direction pairs
 * per material; the DHR quadrature against analytic values and against a finer quadrature. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <cmocka.h>

#include "sim/material.c" /* reaches spec_quad (the GGX normalisation check) */
#include "sim/sim_rng.h"

#define NWL 8
static const double wls[NWL] = { 450, 500, 532.5, 600, 700, 850, 1064, 1100 };

static uint64_t seed(void)
{
	const char *s = getenv("ACQ_SEED");
	uint64_t v = s ? strtoull(s, NULL, 10) : 1;
	printf("ACQ_SEED=%llu\n", (unsigned long long)v);
	return v;
}

static void random_dir(struct sim_rng *r, double w[3])
{
	/* uniform on the hemisphere, with extra weight near grazing (1/3 of the draws at mu < 0.05) */
	double mu = sim_rng_uniform(r);
	if (sim_rng_uniform(r) < 1.0 / 3)
		mu *= 0.05;
	double phi = 2 * M_PI * sim_rng_uniform(r), s = sqrt(fmax(0, 1 - mu * mu));
	w[0] = s * cos(phi);
	w[1] = s * sin(phi);
	w[2] = mu;
}

/* Reciprocity (relative 1e-12) and non-negativity at 10^4 random pairs; finiteness. */
static void test_reciprocity_nonneg(void **state)
{
	(void)state;
	struct sim_rng r;
	sim_rng_seed(&r, seed());
	for (int id = 0; id < MAT__COUNT; id++) {
		struct acq_err err = { 0 };
		struct mat *m = mat_new(id, NWL, wls, &err);
		assert_non_null(m);
		double worst = 0;
		for (int t = 0; t < 10000; t++) {
			double wi[3], wo[3], a[NWL], b[NWL];
			random_dir(&r, wi);
			random_dir(&r, wo);
			mat_eval(m, wi, wo, a);
			mat_eval(m, wo, wi, b);
			for (int l = 0; l < NWL; l++) {
				assert_true(isfinite(a[l]));
				assert_true(a[l] >= 0);
				double d = fabs(a[l] - b[l]) / fmax(1e-300, fmax(a[l], b[l]));
				if (d > worst)
					worst = d;
			}
		}
		printf("%s: worst relative reciprocity error %.3g over 10^4 pairs\n", mat_name(id), worst);
		assert_true(worst <= 1e-12);
		mat_free(m);
	}
}

/* Albedo <= 1 at 10^4 random incidences per material (level 0 quadrature + its own bound), grazing included;
 * level 0 is coarse, so its bound is the level-1 difference. */
static void test_albedo_at_random_incidences(void **state)
{
	(void)state;
	struct sim_rng r;
	sim_rng_seed(&r, seed() + 1);
	for (int id = 0; id < MAT__COUNT; id++) {
		struct acq_err err = { 0 };
		static const double w4[4] = { 450, 600, 850, 1100 }; /* 4 wavelengths keep 10^4 quadratures quick */
		struct mat *m = mat_new(id, 4, w4, &err);
		assert_non_null(m);
		double amax = 0;
		int n = 10000;
		for (int t = 0; t < n; t++) {
			double wi[3];
			random_dir(&r, wi);
			double dhr[4], sig[4];
			assert_int_equal(mat_dhr(m, acos(wi[2]), 0, dhr, sig, &err), 0);
			for (int l = 0; l < 4; l++) {
				assert_true(dhr[l] >= 0);
				assert_true(dhr[l] - sig[l] <= 1.0);
				if (dhr[l] > amax)
					amax = dhr[l];
			}
		}
		printf("%s: largest albedo %.6f over %d random incidences\n", mat_name(id), amax, n);
		assert_true(amax <= 1.0);
		mat_free(m);
	}
}

/* White is Lambertian: DHR = rho exactly at every incidence. */
static void test_dhr_lambertian_analytic(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct mat *m = mat_new(MAT_WHITE, NWL, wls, &err);
	assert_non_null(m);
	for (double th = 0; th < 89.95; th += 8.9) {
		double dhr[NWL], sig[NWL];
		assert_int_equal(mat_dhr(m, th * M_PI / 180, 2, dhr, sig, &err), 0);
		for (int l = 0; l < NWL; l++) {
			double rho = mat_rho_d(MAT_WHITE, wls[l]);
			assert_true(fabs(dhr[l] - rho) < 1e-12);
			assert_true(rho > 0.96 && rho < 0.995);
			double wi[3], wo[3], f[NWL];
			mat_dir(th * M_PI / 180, 0, wi);
			mat_dir(0.3, 2.0, wo);
			mat_eval(m, wi, wo, f);
			assert_true(fabs(f[l] - rho / M_PI) < 1e-15);
		}
	}
	mat_free(m);
}

/* The half-vector quadrature integrates the GGX normalisation int D cos dwh = 1 to 1e-10. */
static void test_quadrature_ggx_normalisation(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct mat *m = mat_new(MAT_GREEN_PAINT, NWL, wls, &err);
	assert_non_null(m);
	for (int level = 0; level <= 3; level++) {
		double v = spec_quad(m, 0.7, level, 1, NULL);
		printf("GGX normalisation, level %d: 1 %+.3g\n", level, v - 1);
		assert_true(fabs(v - 1) < 1e-10);
	}
	mat_free(m);
}

/* DHR error bound: against a quadrature 4x finer in each direction, |Q - Q_ref| <= sigma; the paint's
 * DHR = E + rho_d (1 - E) (energy-aware diffuse) is below 1 at grazing. */
static void test_dhr_against_finer(void **state)
{
	(void)state;
	for (int id = 0; id < MAT__COUNT; id++) {
		struct acq_err err = { 0 };
		struct mat *m = mat_new(id, NWL, wls, &err);
		assert_non_null(m);
		static const double ths[] = { 0, 8, 30, 60, 80, 89.9 };
		double worst = 0, worst_sig = 0;
		for (size_t t = 0; t < sizeof ths / sizeof ths[0]; t++) {
			double th = ths[t] * M_PI / 180, dhr[NWL], sig[NWL], ref[NWL], rsig[NWL];
			assert_int_equal(mat_dhr(m, th, 2, dhr, sig, &err), 0);
			assert_int_equal(mat_dhr(m, th, 4, ref, rsig, &err), 0);
			double e_th = 0;
			for (int l = 0; l < NWL; l++)
				e_th = fmax(e_th, fabs(dhr[l] - ref[l]));
			assert_true(e_th < 1e-6); /* the quadrature is far better than its bound, grazing included */
			printf("  %s theta_i %5.1f: DHR(532.5 nm) %.8f, |error| %.2g, bound %.2g\n", mat_name(id), ths[t], dhr[2],
			       e_th, sig[2]);
			for (int l = 0; l < NWL; l++) {
				double e = fabs(dhr[l] - ref[l]);
				if (e > worst)
					worst = e;
				if (sig[l] > worst_sig)
					worst_sig = sig[l];
				assert_true(e <= sig[l] + rsig[l]);
				assert_true(dhr[l] <= 1.0);
			}
		}
		printf("%s: DHR level 2 vs level 4: max |error| %.3g, max stated bound %.3g\n", mat_name(id), worst, worst_sig);
		assert_true(worst < 1e-6);
		mat_free(m);
	}
}

/* Physical sanity of the spectra: green paint is green (peak near 530 nm, low in the red), gold-like metal
 * reflects little in the blue and most in the NIR. */
static void test_spectral_shapes(void **state)
{
	(void)state;
	assert_true(mat_rho_d(MAT_GREEN_PAINT, 530) > 3 * mat_rho_d(MAT_GREEN_PAINT, 650));
	assert_true(mat_rho_d(MAT_GREEN_PAINT, 530) > 2 * mat_rho_d(MAT_GREEN_PAINT, 460));
	struct acq_err err = { 0 };
	double wl2[2] = { 450, 900 };
	struct mat *m = mat_new(MAT_METAL, 2, wl2, &err);
	assert_non_null(m);
	double dhr[2], sig[2];
	assert_int_equal(mat_dhr(m, 0.1, 2, dhr, sig, &err), 0);
	assert_true(dhr[0] < 0.5 && dhr[1] > 0.9);
	/* bad arguments: clear errors */
	assert_int_equal(mat_dhr(m, 2.0, 2, dhr, sig, &err), -1);
	assert_non_null(strstr(err.msg, "outside"));
	assert_int_equal(mat_dhr(m, 0.1, 9, dhr, sig, &err), -1);
	mat_free(m);
	assert_null(mat_new(MAT_WHITE, 0, wl2, &err));
	assert_int_equal(mat_from_name("paint"), MAT_GREEN_PAINT);
	assert_int_equal(mat_from_name("velvet"), -1);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_reciprocity_nonneg),
		cmocka_unit_test(test_albedo_at_random_incidences),
		cmocka_unit_test(test_dhr_lambertian_analytic),
		cmocka_unit_test(test_quadrature_ggx_normalisation),
		cmocka_unit_test(test_dhr_against_finer),
		cmocka_unit_test(test_spectral_shapes),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
