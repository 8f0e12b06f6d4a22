/* Unit test of the energy verdict at grazing incidence (issue 13, session 8): `recon_check` must see an albedo
 * above 1 at θi = 90°, where the interpolant's lobe about the mirror hugs the horizon.
 * The counter-example: 200 rows of log-uniform random values over 12 decades (4 wavelengths, the generator at the
 * fixed seed 8, whatever ACQ_SEED) fitted with a GGX trend (forced: session 9's admission leaves such noise without
 * a trend, but the check must also be right on the models a forced trend makes) of α ≈ 0.09; at θi = 90° the unscaled interpolant's
 * channel 3 puts most of its albedo (2.268) within cosθo < 0.1 of the horizon. The test lowers that channel's
 * energy bound to truth / 1.03 (every interval above it), so that the evaluated BRDF's albedo at 90° is 1.03,
 * and asks the check for a violation there. Before (Gauss-Legendre in cos²θo, 48 × 96 doubled up to 192 × 384)
 * the check read 2.195 ± 0.26 for the unscaled 2.268, i.e. 0.997 for the broken model: it passed.
 * And the table's room rule (energy.c, TAB_ROOM_K; session 15): it closes a bent interval of a smooth model with
 * room under 1, not of a spiky one nor near 1, and its widened bound bounds (the table rebuilt without the rule by
 * recon_energy_table_room to count the nodes it saves). And a spiky model's table on the path of the nodes past the
 * work budget (session 16: every node there, no bisection) still bounds its albedo, near the pole too. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "recon/rbf.h"
#include "recon/recon_int.h"
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



/* Ground truth of the room-rule tests: rho/π + ks · Schlick(F0 0.04) · GGX(α 0.2) with separable Smith masking:
 * its albedo climbs towards grazing by the Fresnel term (a bend of the albedo curve near 80-90°). */
static double room_truth(const double a[4], double rho, double ks)
{
	const double al = 0.2, a2 = al * al;
	double wi[3] = { sin(a[0]) * cos(a[1]), sin(a[0]) * sin(a[1]), cos(a[0]) };
	double wo[3] = { sin(a[2]) * cos(a[3]), sin(a[2]) * sin(a[3]), cos(a[2]) };
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] };
	double hn = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	double mi = fmax(wi[2], 1e-6), mo = fmax(wo[2], 1e-6), ch = h[2] / hn;
	double cd = fmin(1.0, (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) / hn);
	double t = ch * ch * (a2 - 1) + 1, D = a2 / (M_PI * t * t);
	double g1i = 2 * mi / (mi + sqrt(a2 + (1 - a2) * mi * mi)), g1o = 2 * mo / (mo + sqrt(a2 + (1 - a2) * mo * mo));
	double F = 0.04 + 0.96 * pow(1 - cd, 5);
	return rho / M_PI + ks * F * D * g1i * g1o / (4 * mi * mo);
}

/* The paper's 10 × 10 × 10 sampling (rt_samples_grid's directions) of room_truth on NWL wavelengths (rho ramped
 * by ±10 % over them), 1 % noise; spike > 0 multiplies each value by e^(spike·N(0,1)): a spiky data set. */
static void room_samples(struct recon_samples *s, double rho, double ks, double spike)
{
	rt_samples_grid(s, 10, 10, 10, NWL, 0.0, 1.0);
	for (size_t k = 0; k < s->n; k++)
		for (size_t l = 0; l < NWL; l++) {
			double r = rho * (0.9 + 0.2 * (double)l / (NWL - 1));
			double f = room_truth(s->ang + 4 * k, r, ks), sg = 0.01 * f;
			double v = f + sg * rt_normal();
			if (spike > 0) {
				double x = exp(spike * rt_normal());
				v *= x;
				sg *= x;
			}
			s->val[k * NWL + l] = v;
			s->sig[k * NWL + l] = sg;
		}
}

/* The unscaled albedo of every channel at θ by the checker's cubature (quad.c, independent of the table's nested
 * rules) to 1e-4 absolute below 1; est[NWL] its error estimates. */
static void cub_albedo(const struct recon_model *m, struct albedo_ws *ws, double theta, double *out, double *est)
{
	int cmu = 48, cphi = 96;
	size_t cq, un = 0;
	struct acq_err e = { 0 };
	recon_lobe_rule(m, ALB_NMU_MAX, 0, &cmu, &cphi, &cq);
	assert_int_equal(recon_albedo_cubature(m, theta, (cmu + 2) / 3, (cphi + 2) / 3, 0, 1e-4, 1.0, 1 << 16, ws, out,
						est, &un, &e), 0);
	assert_int_equal(un, 0);
}

#define ROOM_STEPS 90 /* the fine θ grid: every 1° */

/* What the room-rule tests read of a fitted model: its unscaled albedo a[t·NWL + l] on the fine grid (θ = t°,
 * the cubature), the largest value, the largest second difference over the table's starting 10° intervals
 * (a(lo) − 2a(mid) + a(hi), what the curvature test compares with TAB_CURV_TOL) and the table's node count
 * with the room rule (as fitted) and without it (rebuilt by recon_energy_table_room), in all and inside
 * (80°, 90°). Asserts that the fitted table bounds the albedo on every interval holding a grid point (the
 * cubature's 2·error estimate + 1e-4 allowed) and that `check` passes. */
struct room_probe {
	double amax, bend;
	size_t on, off, on_8090, off_8090;
};

static size_t nodes_inside(const struct recon_model *m, double lo, double hi)
{
	size_t c = 0;
	for (size_t t = 0; t < m->ntab; t++)
		c += m->tab_theta[t] > lo + 1e-9 && m->tab_theta[t] < hi - 1e-9;
	return c;
}

static void room_probe(double rho, double ks, double spike, struct room_probe *p)
{
	struct recon_samples s;
	room_samples(&s, rho, ks, spike);
	struct recon_model *m;
	struct acq_err e = { 0 };
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	assert_int_equal(recon_fit(&s, &o, &m, &e), 0);
	struct albedo_ws ws = { 0 };
	assert_int_equal(recon_albedo_ws_init(&ws, m, 4096, &e), 0);
	double *a = malloc((ROOM_STEPS + 1) * NWL * sizeof *a), est[NWL];
	assert_non_null(a);
	memset(p, 0, sizeof *p);
	double worst = -HUGE_VAL;
	for (int t = 0; t <= ROOM_STEPS; t++) {
		double th = (M_PI / 2) * t / ROOM_STEPS, *at = a + (size_t)t * NWL;
		cub_albedo(m, &ws, th, at, est);
		for (size_t i = 0; i + 1 < m->ntab; i++) {
			if (th < m->tab_theta[i] - 1e-12 || th > m->tab_theta[i + 1] + 1e-12)
				continue;
			for (size_t l = 0; l < NWL; l++) /* a bound: ≥ the albedo, the cubature's error allowed */
				worst = fmax(worst, at[l] - 2 * fabs(est[l]) - 1e-4 - m->tab_alb[i * NWL + l]);
		}
		for (size_t l = 0; l < NWL; l++)
			p->amax = fmax(p->amax, at[l]);
	}
	for (int t = 0; t + 10 <= ROOM_STEPS; t += 10)
		for (size_t l = 0; l < NWL; l++)
			p->bend = fmax(p->bend, fabs(a[t * NWL + l] - 2 * a[(t + 5) * NWL + l] + a[(t + 10) * NWL + l]));
	struct recon_check_report r;
	assert_int_equal(recon_check(m, 200, 8, 1, &r, NULL, NULL, &e), 0);
	p->on = m->ntab;
	p->on_8090 = nodes_inside(m, 80 * M_PI / 180, M_PI / 2);
	assert_int_equal(recon_energy_table_room(m, 0, -1, &e, NULL, NULL), 0);
	p->off = m->ntab;
	p->off_8090 = nodes_inside(m, 80 * M_PI / 180, M_PI / 2);
	printf("rho %g ks %g spike %g: trend %s, leave-one-out RMS %.3g; albedo max %.4f, largest bend over 10 deg "
	       "%.4f; bound - albedo >= %.4g; check max albedo %.4f excess %.4f; nodes %zu with the room rule, %zu "
	       "without (%zu, %zu inside 80-90 deg)\n",
	       rho, ks, spike, trend_name(m->trend), m->loo_rms, p->amax, p->bend, -worst, r.max_albedo,
	       r.energy_excess, p->on, p->off, p->on_8090, p->off_8090);
	assert_true(worst <= 0);
	assert_true(r.energy_excess <= 0 && r.alb_unresolved == 0 && r.nonfinite == 0);
	double loo = m->loo_rms;
	recon_albedo_ws_free(&ws);
	free(a);
	recon_model_free(m);
	csvio_samples_free(&s);
	assert_true(spike > 0 ? loo > 1.0 : loo <= 1.0);
}

/* The room rule (energy.c, TAB_ROOM_K): a smooth model (leave-one-out RMS ≤ 1 in ln f) whose albedo curve bends
 * past TAB_CURV_TOL well below 1 (Fresnel's climb to grazing: 0.26 → 0.75, bend 0.023 over 80-90°) closes its
 * intervals without bisecting them: fewer nodes than without the rule, and the widened bound still bounds the
 * albedo on a 1° grid (the cubature's), `check` clean. */
static void test_room_rule_closes_smooth_bend(void **state)
{
	(void)state;
	rt_seed();
	struct room_probe p;
	room_probe(0.2, 2.0, 0, &p);
	assert_true(p.bend > 1.5 * 0.01); /* TAB_CURV_TOL: the curvature test alone bisects */
	assert_true(p.amax < 0.8);        /* room under 1 for twice the bend */
	assert_true(p.on < p.off);
}

/* A spiky model (leave-one-out RMS > 1: every value times e^(1.5 N(0,1))) far below 1 (0.32) still bisects where
 * it bends past TAB_CURV_TOL: the rule is for smooth models only (the same node count with it as without; 31
 * instead of 33 without the guard, session 15; 41 = 41 since session 16's graded nodes near the pole, 39 without
 * the guard). The data at the fixed seed 1, whatever ACQ_SEED: spikes are random, and at other
 * seeds one can lift the curve's top to 0.7-0.9 (seeds 7 and 23), where the guard-less rule need not fire. */
static void test_room_rule_spiky_bisects(void **state)
{
	(void)state;
	rt_seed_value(1); /* the counter-example */
	struct room_probe p;
	room_probe(0.1, 4.0, 1.5, &p);
	assert_true(p.amax < 0.5 && p.bend > 1.5 * 0.01); /* room under 1, and bent */
	assert_int_equal(p.on, p.off);
}

/* A smooth model whose curve climbs close to 1 (0.99 at 90°; max + 2·bend > 1 over 80-90°) still bisects 80-90°:
 * there no room for the widened bound (s = 1/max(1, A) would scale the BRDF for nothing). */
static void test_room_rule_near_one_bisects(void **state)
{
	(void)state;
	rt_seed();
	struct room_probe p;
	room_probe(0.2, 2.9, 0, &p);
	assert_true(p.amax > 0.9 && p.bend > 1.5 * 0.01);
	assert_true(p.off_8090 > 1); /* bisected past its midpoint */
	assert_int_equal(p.on_8090, p.off_8090);
}

/* The table of a spiky model on its cheapest path (session 16): rebuilt with a work budget of 0, every node takes the
 * rule of the nodes past the budget (the table's starting rule halved, one doubling, boxes at the data's bright
 * directions sized from the table's own starting rule: energy.c box_fine) and no interval is bisected, so only the
 * nodes' margins and the starting nodes hold the bound. The model: 300 rows of log-uniform random values over 12
 * decades (4 wavelengths, the fixed seed 3 whatever ACQ_SEED; leave-one-out RMS ≈ 6.5), whose albedo reaches ~10²
 * near the pole. Asserts the graded starting nodes near the pole (10°/2^k, k = 1 … 4: energy.c TAB_POLE; at the
 * paper size, log-uniform random seed 2, one channel's albedo rose 0.5 % over the bound of the nodes 0, 5 and 10°
 * between θi = 0 and 1.5° without them), that the table bounds the cubature's albedo every 0.25° over 0-3° and every
 * 2° beyond (its 2·error estimate + 1e-4 allowed), and `check` clean. */
static void test_capped_table_bounds(void **state)
{
	(void)state;
	struct recon_samples s;
	rt_seed_value(3); /* the data, whatever ACQ_SEED */
	rt_samples_log_uniform(&s, 300, NWL);
	struct recon_model *m;
	struct acq_err e = { 0 };
	struct recon_fit_opts o;
	recon_fit_opts_default(&o);
	assert_int_equal(recon_fit(&s, &o, &m, &e), 0);
	assert_true(m->loo_rms > 1.0);
	assert_int_equal(recon_energy_table_room(m, 1, 0, &e, NULL, NULL), 0);
	assert_true(m->tab_capped);
	size_t pole = 0;
	for (int k = 1; k <= 4; k++)
		for (size_t t = 0; t < m->ntab; t++)
			pole += fabs(m->tab_theta[t] - (M_PI / 18) / (1 << k)) < 1e-12;
	struct albedo_ws ws = { 0 };
	assert_int_equal(recon_albedo_ws_init(&ws, m, 4096, &e), 0);
	double a[NWL], est[NWL], worst = -HUGE_VAL, wth = 0, amax = 0;
	for (double td = 0; td <= 90.0 + 1e-9; td += td < 3.0 - 1e-9 ? 0.25 : 2.0) {
		double th = fmin(td, 90.0) * M_PI / 180;
		cub_albedo(m, &ws, th, a, est);
		for (size_t i = 0; i + 1 < m->ntab; i++) {
			if (th < m->tab_theta[i] - 1e-12 || th > m->tab_theta[i + 1] + 1e-12)
				continue;
			for (size_t l = 0; l < NWL; l++) {
				double w = a[l] - 2 * fabs(est[l]) - 1e-4 - m->tab_alb[i * NWL + l];
				if (w > worst) {
					worst = w;
					wth = td;
				}
				amax = fmax(amax, a[l]);
			}
		}
	}
	struct recon_check_report r;
	assert_int_equal(recon_check(m, 200, 8, 1, &r, NULL, NULL, &e), 0);
	printf("log-uniform 300 x %d, leave-one-out RMS %.3g, every node capped: %zu nodes (%zu of 4 graded near the "
	       "pole), albedo max %.4g, bound - albedo >= %.4g (at %.2f deg), check max albedo %.4f excess %.4f\n", NWL,
	       m->loo_rms, m->ntab, pole, amax, -worst, wth, r.max_albedo, r.energy_excess);
	assert_int_equal(pole, 4);
	assert_true(worst <= 0);
	assert_true(r.energy_excess <= 0 && r.alb_unresolved == 0 && r.nonfinite == 0);
	recon_albedo_ws_free(&ws);
	recon_model_free(m);
	csvio_samples_free(&s);
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(test_check_sees_grazing_violation),
					    cmocka_unit_test(test_room_rule_closes_smooth_bend),
					    cmocka_unit_test(test_room_rule_spiky_bisects),
					    cmocka_unit_test(test_room_rule_near_one_bisects),
					    cmocka_unit_test(test_capped_table_bounds) };
	return cmocka_run_group_tests(tests, NULL, NULL);
}
