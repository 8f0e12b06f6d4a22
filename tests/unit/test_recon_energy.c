/* Unit test of the energy verdict at grazing incidence (issue 13, session 8): `recon_check` must see an albedo
 * above 1 at θi = 90°, where the interpolant's lobe about the mirror hugs the horizon.
 * The counter-example: 200 rows of log-uniform random values over 12 decades (4 wavelengths, the generator at the
 * fixed seed 8, whatever ACQ_SEED) fitted with a GGX trend (forced: session 9's admission leaves such noise without
 * a trend, but the check must also be right on the models a forced trend makes) of α ≈ 0.09; at θi = 90° the unscaled interpolant's
 * channel 3 puts most of its albedo (2.268) within cosθo < 0.1 of the horizon. The test lowers that channel's
 * energy bound to truth / 1.03 (every interval above it), so that the evaluated BRDF's albedo at 90° is 1.03,
 * and asks the check for a violation there. Before (Gauss-Legendre in cos²θo, 48 × 96 doubled up to 192 × 384)
 * the check read 2.195 ± 0.26 for the unscaled 2.268, i.e. 0.997 for the broken model: it passed. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "recon/rbf.h"
#include "recon_test_util.h"

#define NWL 4
#define CH 3

/* The unscaled albedo of channel ch at θi = 90° by a brute-force rule independent of librecon's quadrature: Gauss-Legendre
 * with ng nodes on panels of cosθo graded towards the horizon × ng nodes on panels of azimuth graded towards 0 and π
 * (the plane of incidence, where the lobe about the mirror lies), mirror doubled. */
static double brute_albedo90(const struct recon_model *m, size_t ch, int ng)
{
	static const double em[] = { 0, 1e-4, 1e-3, 3e-3, 0.01, 0.02, 0.04, 0.07, 0.1, 0.15, 0.2, 0.3, 0.5, 0.75, 1 };
	static const double ep[] = { 0, 0.003, 0.01, 0.03, 0.1, 0.3, 1 }; /* and π minus these */
	int nm = (int)(sizeof em / sizeof *em), nh = (int)(sizeof ep / sizeof *ep), np = 2 * nh - 1;
	double x[64], w[64], ph[2 * 7], acc = 0;
	for (int j = 0; j < nh; j++) {
		ph[j] = ep[j];
		ph[np - 1 - j] = M_PI - ep[j];
	}
	assert_int_equal(rbf_gauss_legendre01(ng, x, w), 0);
	size_t B = RECON_EVAL_BLOCK, q = 0, L = m->nwl;
	double *c6 = malloc(B * 6 * sizeof *c6), *wt = malloc(B * sizeof *wt), *out = malloc(B * L * sizeof *out);
	double *work = malloc(recon_eval_work_size(m) * sizeof *work);
	assert_non_null(c6 && wt && out && work);
	for (int p = 0; p + 1 < nm; p++)
		for (int i = 0; i < ng; i++)
			for (int r = 0; r + 1 < np; r++)
				for (int j = 0; j < ng; j++) {
					double h = em[p + 1] - em[p], mu = em[p] + h * x[i], hp = ph[r + 1] - ph[r];
					rbf_canon(M_PI / 2, 0, acos(mu), ph[r] + hp * x[j], c6 + 6 * q);
					wt[q++] = h * w[i] * mu * hp * w[j] * 2;
					if (q == B || (p + 2 == nm && i + 1 == ng && r + 2 == np && j + 1 == ng)) {
						recon_eval_canon(m, q, c6, 0, out, work);
						for (size_t k = 0; k < q; k++)
							acc += wt[k] * out[k * L + ch];
						q = 0;
					}
				}
	free(c6);
	free(wt);
	free(out);
	free(work);
	return acc;
}

static void test_check_sees_grazing_violation(void **state)
{
	(void)state;
	size_t n = 200;
	struct recon_samples s;
	rt_seed_value(8); /* the counter-example, whatever ACQ_SEED */
	rt_samples_log_uniform(&s, n, NWL);
	struct recon_model *m;
	struct acq_err e = { 0 };
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	o.trend = RECON_TREND_GGX;
	assert_int_equal(recon_fit(&s, &o, &m, &e), 0);
	printf("fit: trend %s alpha %.4g, leave-one-out RMS %.3g\n", trend_name(m->trend), m->trend_alpha, m->loo_rms);
	/* the truth at 90°: two brute-force rules agree (measured 2.26776 / 2.26776, the check's cubature 2.2678) */
	double a1 = brute_albedo90(m, CH, 12), a2 = brute_albedo90(m, CH, 20);
	printf("unscaled albedo at 90 deg, channel %d: %.6f (12 x 12 per panel), %.6f (20 x 20)\n", CH, a1, a2);
	assert_true(fabs(a1 - a2) <= 1e-4 * a2);
	assert_true(a2 > 1.5); /* the counter-example still is one: a bound below it scales the BRDF */
	/* the model as fitted: its bound holds (the check finds no violation, at 0 and 90° only) */
	struct recon_check_report r;
	assert_int_equal(recon_check(m, 100, 0, 1, &r, NULL, NULL, &e), 0);
	printf("as fitted: check max albedo %.5f +- %.2g at %.1f deg\n", r.max_albedo, r.max_albedo_qerr,
	       r.max_albedo_theta * 180 / M_PI);
	assert_true(r.energy_excess <= 0);
	/* the bound of channel CH lowered to truth / 1.03 wherever it is above: at θi = 90° every s = 1.03 / truth,
	 * the albedo there 1.03; at θi = 0 (unscaled 0.40) still below 1 */
	for (size_t t = 0; t + 1 < m->ntab; t++) {
		double *b = m->tab_alb + t * NWL + CH;
		*b = fmin(*b, a2 / 1.03);
	}
	assert_int_equal(recon_check(m, 100, 0, 1, &r, NULL, NULL, &e), 0);
	printf("bound lowered: check max albedo %.5f +- %.2g at %.1f deg, %g nm, excess %.4f, unresolved %zu\n",
	       r.max_albedo, r.max_albedo_qerr, r.max_albedo_theta * 180 / M_PI, r.max_albedo_wl, r.energy_excess,
	       r.alb_unresolved);
	/* the check's cubature within its 1e-3 target of the exact 1.03 (old rule: 0.997 ± 0.12, no violation) */
	assert_true(fabs(r.max_albedo - 1.03) <= 2e-3);
	assert_true(r.max_albedo_theta == M_PI / 2 && r.max_albedo_wl == s.wl[CH]);
	assert_true(r.energy_excess > 0.02 && r.alb_unresolved == 0);
	recon_model_free(m);
	csvio_samples_free(&s);
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(test_check_sees_grazing_violation) };
	return cmocka_run_group_tests(tests, NULL, NULL);
}
