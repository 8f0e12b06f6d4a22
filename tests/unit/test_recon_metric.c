/* Unit tests of recon/rbf.c: the metric against closed forms, the canonical frame's invariances, positive
 * definiteness of the default kernels, exact reciprocity of the symmetrised kernel, Gauss-Legendre. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>
#include <lapacke.h>

#include "recon_test_util.h"

#define D2R (M_PI / 180)

static void test_gc_closed_forms(void **state)
{
	(void)state;
	/* coincident points */
	assert_true(rbf_gc_dist(0.7, 1.3, 0.7, 1.3) == 0.0);
	/* pole: the azimuth drops out */
	assert_true(rbf_gc_dist(0, 0.3, 0, 2.9) == 0.0);
	assert_true(fabs(rbf_gc_dist(0, 1.0, 0.6, 2.0) - 0.6) < 1e-15);
	/* horizon antipodes and quarter turns */
	assert_true(fabs(rbf_gc_dist(M_PI / 2, 0, M_PI / 2, M_PI) - M_PI) < 1e-15);
	assert_true(fabs(rbf_gc_dist(M_PI / 2, 0, M_PI / 2, M_PI / 2) - M_PI / 2) < 1e-15);
	/* azimuth wrap: 359° and 1° are 2° apart in azimuth */
	double th = 40 * D2R;
	double a = rbf_gc_dist(th, 359 * D2R, th, 1 * D2R), b = rbf_gc_dist(th, 10 * D2R, th, 12 * D2R);
	assert_true(fabs(a - b) < 1e-14);
	assert_true(fabs(rbf_gc_dist(th, -1 * D2R, th, 1 * D2R) - a) < 1e-14);
	assert_true(fabs(a - 2 * asin(sin(th) * sin(1 * D2R))) < 1e-14);
	/* small angles stay accurate (haversine form): 1e-9 rad apart in zenith */
	volatile double tz = 0.5 + 1e-9;
	assert_true(fabs(rbf_gc_dist(0.5, 0.2, tz, 0.2) - (tz - 0.5)) < 1e-12 * (tz - 0.5));
	/* random pairs: spherical law of cosines, symmetry, triangle inequality */
	for (int i = 0; i < 1000; i++) {
		double t1 = rt_unif() * M_PI / 2, p1 = rt_unif() * 2 * M_PI, t2 = rt_unif() * M_PI / 2,
		       p2 = rt_unif() * 2 * M_PI, t3 = rt_unif() * M_PI / 2, p3 = rt_unif() * 2 * M_PI;
		double d = rbf_gc_dist(t1, p1, t2, p2);
		double c = cos(t1) * cos(t2) + sin(t1) * sin(t2) * cos(p1 - p2);
		double ref = acos(fmax(-1, fmin(1, c)));
		if (ref > 1e-3)
			assert_true(fabs(d - ref) < 1e-9);
		assert_true(d == rbf_gc_dist(t2, p2, t1, p1));
		assert_true(d <= rbf_gc_dist(t1, p1, t3, p3) + rbf_gc_dist(t3, p3, t2, p2) + 1e-12);
		assert_true(d >= 0 && d <= M_PI);
	}
}

static void test_product_and_reciprocal_metric(void **state)
{
	(void)state;
	for (int i = 0; i < 500; i++) {
		double a[4], b[4];
		rt_random_pair(a);
		rt_random_pair(b);
		double di = rbf_gc_dist(a[0], a[1], b[0], b[1]), dout = rbf_gc_dist(a[2], a[3], b[2], b[3]);
		assert_true(fabs(rbf_prod_dist(a, b) - sqrt(di * di + dout * dout)) < 1e-15);
		double sb[4] = { b[2], b[3], b[0], b[1] }, sa[4] = { a[2], a[3], a[0], a[1] };
		double r = rbf_rec_dist(a, b);
		assert_true(r <= rbf_prod_dist(a, b));
		assert_true(fabs(r - rbf_rec_dist(a, sb)) < 1e-15); /* invariant under σ of either argument */
		assert_true(fabs(r - rbf_rec_dist(sa, b)) < 1e-15);
		assert_true(rbf_rec_dist(a, sa) == 0.0); /* a point and its reciprocal are at distance 0 */
	}
}

static void test_canonical_frame_invariances(void **state)
{
	(void)state;
	for (int i = 0; i < 2000; i++) {
		double a[4];
		rt_random_pair(a);
		double c0[6], c1[6], c2[6], c3[6], t[6];
		rbf_canon(a[0], a[1], a[2], a[3], c0);
		double rot = 2 * M_PI * rt_unif();
		rbf_canon(a[0], a[1] + rot, a[2], a[3] + rot, c1);  /* rotation about the normal */
		rbf_canon(a[0], -a[1], a[2], -a[3], c2);             /* mirror */
		rbf_canon(a[2], a[3], a[0], a[1], c3);               /* reciprocity: exactly the same point */
		for (int k = 0; k < 6; k++) {
			assert_true(fabs(c0[k] - c1[k]) < 1e-12);
			assert_true(fabs(c0[k] - c2[k]) < 1e-12);
			assert_true(c0[k] == c3[k]);
		}
		/* unit vectors, both above the horizon, azimuth difference preserved */
		assert_true(fabs(c0[0] * c0[0] + c0[1] * c0[1] + c0[2] * c0[2] - 1) < 1e-14);
		assert_true(c0[2] >= 0 && c0[5] >= 0);
		rbf_tau(c0, t);
		rbf_tau(t, c1);
		for (int k = 0; k < 6; k++)
			assert_true(c1[k] == c0[k]); /* τ is an involution */
	}
	/* continuity at normal incidence: the observation vector does not depend on the azimuths */
	double p[6], q[6];
	rbf_canon(0, 0.3, 0.7, 2.0, p);
	rbf_canon(0, 1.1, 0.7, -0.4, q);
	for (int k = 0; k < 6; k++)
		assert_true(fabs(p[k] - q[k]) < 1e-15);
	double r[6];
	rbf_canon(1e-7, 0.0, 0.7, 2.0, r); /* near the pole the point is near the pole's image */
	for (int k = 0; k < 6; k++)
		assert_true(fabs(p[k] - r[k]) < 1e-6);
}

/* Cholesky of the plain kernel matrix (no smoothing) succeeds on random point sets: positive definite. */
static void test_default_kernels_positive_definite(void **state)
{
	(void)state;
	const int n = 80;
	double *c = malloc(n * 6 * sizeof *c), *t = malloc(n * 6 * sizeof *t), *K = malloc(n * n * sizeof *K);
	int kernels[3] = { RBF_K_WENDLAND, RBF_K_EXP, RBF_K_GAUSS };
	double shapes[3][3] = { { 0.5, 1.5, 4.0 }, { 0.3, 1.0, 3.0 }, { 0.3, 0.5, 0.7 } };
	for (int trial = 0; trial < 4; trial++) {
		for (int i = 0; i < n; i++) {
			double a[4];
			rt_random_pair(a);
			rbf_canon(a[0], a[1], a[2], a[3], c + 6 * i);
			rbf_tau(c + 6 * i, t + 6 * i);
		}
		for (int k = 0; k < 3; k++)
			for (int s = 0; s < 3; s++) {
				rbf_kmatrix(kernels[k], shapes[k][s], n, c, n, c, t, K);
				for (int i = 0; i < n; i++)
					for (int j = 0; j < n; j++)
						assert_true(K[i * n + j] == K[j * n + i]); /* symmetric */
				int info = LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', n, K, n);
				if (info != 0)
					printf("kernel %s shape %g: dpotrf info %d\n", rbf_kernel_name(kernels[k]), shapes[k][s],
					       info);
				assert_int_equal(info, 0);
			}
	}
	free(c);
	free(t);
	free(K);
}

/* K(c(σx), y) == K(c(x), y) bit for bit, and K(τa, τb) == K(a, b). */
static void test_kernel_reciprocity_exact(void **state)
{
	(void)state;
	for (int i = 0; i < 2000; i++) {
		double a[4], b[4], ca[6], cs[6], cb[6], tb[6], ta[6], ttb[6];
		rt_random_pair(a);
		rt_random_pair(b);
		rbf_canon(a[0], a[1], a[2], a[3], ca);
		rbf_canon(a[2], a[3], a[0], a[1], cs);
		rbf_canon(b[0], b[1], b[2], b[3], cb);
		rbf_tau(cb, tb);
		rbf_tau(ca, ta);
		rbf_tau(tb, ttb);
		for (int k = 0; k < RBF_K__COUNT; k++) {
			double v = rbf_kernel(k, 1.0, ca, cb, tb);
			assert_true(v == rbf_kernel(k, 1.0, cs, cb, tb));
			assert_true(fabs(v - rbf_kernel(k, 1.0, ta, tb, ttb)) <= 1e-15 * fabs(v) + 1e-300);
			assert_true(v >= 0 && isfinite(v));
		}
	}
	assert_int_equal(rbf_kernel_from_name("wendland"), RBF_K_WENDLAND);
	assert_int_equal(rbf_kernel_from_name("nope"), -1);
}

/* The vectorised row (SoA centres, possibly an AVX2 clone) gives the same bits as the scalar kernel. */
static void test_krow_matches_kernel(void **state)
{
	(void)state;
	const int n = 37;
	double c[37 * 6], t[37 * 6], soa[37 * 6], row[37];
	for (int j = 0; j < n; j++) {
		double a[4];
		rt_random_pair(a);
		rbf_canon(a[0], a[1], a[2], a[3], c + 6 * j);
		rbf_tau(c + 6 * j, t + 6 * j);
	}
	rbf_soa(n, c, soa);
	for (int i = 0; i < 200; i++) {
		double a[4], q[6];
		rt_random_pair(a);
		rbf_canon(a[0], a[1], a[2], a[3], q);
		for (int k = 0; k < RBF_K__COUNT; k++) {
			double shape = 0.3 + 3 * rt_unif();
			rbf_krow(k, shape, q, n, soa, row);
			for (int j = 0; j < n; j++)
				assert_true(row[j] == rbf_kernel(k, shape, q, c + 6 * j, t + 6 * j));
		}
	}
}

static void test_gauss_legendre(void **state)
{
	(void)state;
	double x[256], w[256];
	for (int n = 1; n <= 64; n += 7) {
		assert_int_equal(rbf_gauss_legendre01(n, x, w), 0);
		for (int k = 0; k <= 2 * n - 1; k++) {
			double s = 0;
			for (int i = 0; i < n; i++)
				s += w[i] * pow(x[i], k);
			assert_true(fabs(s - 1.0 / (k + 1)) < 1e-13);
		}
	}
	assert_int_equal(rbf_gauss_legendre01(0, x, w), -1);
	assert_int_equal(rbf_gauss_legendre01(257, x, w), -1);
}

int main(void)
{
	rt_seed();
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_gc_closed_forms),
		cmocka_unit_test(test_product_and_reciprocal_metric),
		cmocka_unit_test(test_canonical_frame_invariances),
		cmocka_unit_test(test_default_kernels_positive_definite),
		cmocka_unit_test(test_kernel_reciprocity_exact),
		cmocka_unit_test(test_krow_matches_kernel),
		cmocka_unit_test(test_gauss_legendre),
	};
	return cmocka_run_group_tests_name("recon_metric", tests, NULL, NULL);
}
