/* Unit test of the DHR uncertainty's honesty (recon_dhr_ex) on the synthetic truth (Lambertian + cos²⁰ Phong
 * lobe, the paper's 10 × 10 × 10 sampling, 2 % noise), over NSEED independent noisy data sets × NWL wavelengths
 * (default fit, as a user gets it: on this lobe the leave-one-out choice takes the phong trend, see
 * test_recon_trend). z = (DHR − truth)/σ; its RMS over data sets and wavelengths (the spread about 0: the error
 * includes a deterministic interpolation bias, so the spread about the mean would hide it) must lie in
 * [Z_LO, Z_HI] at 8°, 30° and 60°, and the same σ scaled by 3 or by 1/3 must fall outside that band.
 *
 * The band and the design (session 8). The statistic is a sample RMS, so its spread over ACQ_SEED is set by how
 * many z values it pools: with 10 data sets × 3 wavelengths (30 values, sessions 3-7) the microfacet paint's 30°
 * value fell to 0.55, under that test's floor, at ACQ_SEED=364333693 (make check, session 7), and a bootstrap of
 * 52 data sets (156 z per incidence) put its 60° value below 0.55 in 0.25 % of seeds. Wavelengths are nearly free
 * (one factorisation for all channels: a data set costs ~0.55 s CPU with 3 and ~0.8 s with 24) and their noise is
 * independent, so the tests now pool 5 data sets × 24 wavelengths (120 values). Measured on this design (47 data
 * sets per truth from ACQ_SEED 2001-2009 / 3001-3009, 1128 z per incidence; scratch copy of these loops): pooled z
 * RMS at 8/30/60° microfacet paint 0.90 / 0.90 / 0.93, Phong lobe 0.90 / 0.94 / 0.88; the variance of a data
 * set's mean z² 0.6-1.1× what independent wavelengths give (so ≥ ~100 effective values per run) and kurtosis of
 * z 2.7-3.4 (Gaussian-like), so a run's RMS lies within ×0.75…×1.26 of its centre except with probability 1e-4
 * per side (χ², 100 degrees of freedom), i.e. in [0.66, 1.19]; the 20 runs measured (those 18 seeds, 1 and
 * 364333693) gave 0.76-1.02. The band [Z_LO, Z_HI] = [0.5, 1.45] holds that with margin, and its ratio (2.9 < 3)
 * makes σ × 3 (z RMS ≤ 1.19/3 = 0.40) and σ / 3 (≥ 3 × 0.66 = 1.98) fail at every seed.
 * The bench goal [0.7, 1.3] is for 1320 values (bench_dhr_honesty); 120 values cannot hold it at 1e-4. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "recon/recon_int.h"
#include "recon_test_util.h"
#include "sim/material.h"
#include "sim/sim_refdrift.h"
#include "sim/sim_truth.h"

#define NWL 24
#define NSEED 5
#define NTH 3
#define Z_LO 0.5
#define Z_HI 1.45

static double true_dhr(double ti, double wl)
{
	double x[128], w[128];
	rbf_gauss_legendre01(96, x, w);
	double s = 0;
	for (int i = 0; i < 96; i++)
		for (int j = 0; j < 384; j++) {
			double a[4] = { ti, 0, acos(x[i]), (j + 0.5) * 2 * M_PI / 384 };
			s += w[i] * x[i] * (2 * M_PI / 384) * rt_truth(a, wl, 1.0);
		}
	return s;
}

/* RMS over seeds and wavelengths of z = err/σ (σ scaled by k), per incidence. */
static double zrms(const double *err, const double *sig, int t, double k)
{
	double acc = 0;
	for (int s = 0; s < NSEED; s++)
		for (int l = 0; l < NWL; l++) {
			double z = err[(s * NTH + t) * NWL + l] / (k * sig[(s * NTH + t) * NWL + l]);
			acc += z * z;
		}
	return sqrt(acc / (NSEED * NWL));
}

/* Incidence t's z RMS lies in [Z_LO, Z_HI] and σ × 3 or σ / 3 would not (the header says why this band). */
static void assert_band(const char *what, const double *err, const double *sig, int t)
{
	static const int deg[NTH] = { 8, 30, 60 };
	double z = zrms(err, sig, t, 1.0), z3 = zrms(err, sig, t, 3.0), z13 = zrms(err, sig, t, 1.0 / 3.0);
	printf("%s θi = %2d°: RMS z %.2f over %d data sets × %d wavelengths (band [%.2f, %.2f]; σ×3: %.2f, σ/3: %.2f)\n",
	       what, deg[t], z, NSEED, NWL, Z_LO, Z_HI, z3, z13);
	assert_true(z >= Z_LO && z <= Z_HI);
	assert_false(z3 >= Z_LO && z3 <= Z_HI);
	assert_false(z13 >= Z_LO && z13 <= Z_HI);
}

static void test_dhr_zscores_calibrated(void **state)
{
	(void)state;
	rt_seed();
	double th[NTH] = { 8 * M_PI / 180, 30 * M_PI / 180, 60 * M_PI / 180 };
	static double err[NSEED * NTH * NWL], sig[NSEED * NTH * NWL], sn[NSEED * NTH * NWL], sm[NSEED * NTH * NWL];
	double truth[NTH * NWL];
	for (int s = 0; s < NSEED; s++) {
		struct recon_samples smp;
		rt_samples(&smp, NWL, 0.02, 1.0);
		if (s == 0)
			for (int t = 0; t < NTH; t++)
				for (int l = 0; l < NWL; l++)
					truth[t * NWL + l] = true_dhr(th[t], smp.wl[l]);
		struct recon_model *m;
		struct acq_err e = { 0 };
		struct recon_fit_opts o;
		recon_fit_opts_default(&o);
		assert_int_equal(recon_fit(&smp, &o, &m, &e), 0);
		double d[NTH * NWL], sq[NTH * NWL], sf[NTH * NWL], sr[NTH * NWL];
		size_t at = (size_t)s * NTH * NWL;
		struct recon_dhr_parts parts = { .noise = sn + at, .model = sm + at, .quad = sq, .misfit = sf, .res = sr };
		assert_int_equal(recon_dhr_parts(m, NTH, th, 32, (uint64_t)s + 1, d, sig + at, &parts, NULL, NULL, &e), 0);
		for (int i = 0; i < NTH * NWL; i++) {
			err[at + i] = d[i] - truth[i];
			assert_true(sig[at + i] > 0);
			assert_true(sq[i] >= 0 && sq[i] <= 2e-3 * d[i]); /* smooth truth: the rule converges at once */
			/* σ² = max(σ_noise, σ_model)² + σ_quad² + σ_misfit² + σ_res² */
			double sb = fmax(sn[at + i], sm[at + i]);
			assert_true(sf[i] >= 0 && sf[i] <= 1 && sr[i] >= 0);
			assert_true(fabs(sig[at + i] * sig[at + i] - sb * sb - sq[i] * sq[i] - sf[i] * sf[i] - sr[i] * sr[i]) <=
				    1e-9 * sig[at + i] * sig[at + i]);
		}
		recon_model_free(m);
		csvio_samples_free(&smp);
	}
	for (int t = 0; t < NTH; t++)
		printf("θi = %2.0f°: RMS of z with the noise-only σ: %.2f\n", th[t] * 180 / M_PI, zrms(err, sn, t, 1.0));
	/* Session 5: the mirror-Phong lobe now takes the phong trend (issue 13 item 4), which removes the 36° azimuth
	 * step's bias at 30° and 60° (plain interpolant: noise-only z RMS > 2 at 30°; now 0.9-1.1, ACQ_SEED 1-30), so
	 * σ is calibrated at every incidence, not only at 8°. */
	for (int t = 0; t < NTH; t++)
		assert_band("Phong lobe", err, sig, t);
}

/* A microfacet paint (Lambertian + GGX lobe, α = 0.15, Smith masking, Schlick Fresnel F0 = 0.04): the kind of
 * material the simulator's paint and metal are, in the trend's family. */
static double ggx_truth(const double a[4], double wl)
{
	double rho = 0.1 + 0.5 * exp(-(wl - 600) * (wl - 600) / (2 * 80.0 * 80.0)), al = 0.15, a2 = al * al;
	double wi[3] = { sin(a[0]) * cos(a[1]), sin(a[0]) * sin(a[1]), cos(a[0]) };
	double wo[3] = { sin(a[2]) * cos(a[3]), sin(a[2]) * sin(a[3]), cos(a[2]) };
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] }, hn = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	double ch = h[2] / hn, d = (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) / hn;
	double D = a2 / (M_PI * pow(ch * ch * (a2 - 1) + 1, 2)), ci = fmax(wi[2], 1e-4), co = fmax(wo[2], 1e-4);
	double G = 2 * ci / (ci + sqrt(a2 + (1 - a2) * ci * ci)) * 2 * co / (co + sqrt(a2 + (1 - a2) * co * co));
	double F = 0.04 + 0.96 * pow(1 - fmax(d, 0), 5);
	return rho / M_PI * 0.95 + D * G * F / (4 * ci * co);
}

/*
 * The fast version of bench_dhr_honesty for make check: the microfacet paint on an ni × no × np plan, 1 % noise,
 * NSEED data sets × NWL wavelengths, z against the truth (bias included) at 8, 30 and 60°. Each incidence's z RMS
 * must lie in [Z_LO, Z_HI], and the same σ scaled by 3 or by 1/3 must fall outside that band (the test fails for a
 * σ three times too large or too small; the file's header gives the measured spread).
 */
static void paint_band(const char *what, int ni, int no, int np)
{
	rt_seed();
	double th[NTH] = { 8 * M_PI / 180, 30 * M_PI / 180, 60 * M_PI / 180 }, truth[NTH * NWL];
	static double err[NSEED * NTH * NWL], sig[NSEED * NTH * NWL];
	for (int s = 0; s < NSEED; s++) {
		struct recon_samples smp;
		rt_samples_grid(&smp, ni, no, np, NWL, 0.01, 1.0);
		for (size_t k = 0; k < smp.n; k++) /* the same plan and noise draws, the microfacet values */
			for (int l = 0; l < NWL; l++) {
				double f = ggx_truth(smp.ang + 4 * k, smp.wl[l]), sg = 0.01 * f + 1e-5;
				smp.val[k * NWL + l] = f + sg * rt_normal();
				smp.sig[k * NWL + l] = sg;
			}
		if (s == 0)
			for (int t = 0; t < NTH; t++)
				for (int l = 0; l < NWL; l++) {
					double x[128], w[128], acc = 0;
					rbf_gauss_legendre01(128, x, w);
					for (int i = 0; i < 128; i++)
						for (int j = 0; j < 512; j++) {
							double a[4] = { th[t], 0, acos(x[i]), (j + 0.5) * 2 * M_PI / 512 };
							acc += w[i] * x[i] * (2 * M_PI / 512) * ggx_truth(a, smp.wl[l]);
						}
					truth[t * NWL + l] = acc;
				}
		struct recon_model *m;
		struct acq_err e = { 0 };
		assert_int_equal(recon_fit(&smp, NULL, &m, &e), 0);
		double *A = malloc(m->n * m->n * sizeof *A), *Ai = malloc(m->n * m->n * sizeof *Ai), al[NWL];
		assert_int_equal(recon_gp_setup(m, "test", A, Ai, al, &e), 0);
		double a = recon_edge_size(m, Ai, al); /* the trend extrapolates this truth: no extrapolation term */
		printf("%s, data set %d: the last ring's held-out size a %.3f\n", what, s, a);
		assert_true(a >= 0 && a < RECON_EDGE_A0);
		free(A);
		free(Ai);
		double d[NTH * NWL];
		size_t at = (size_t)s * NTH * NWL;
		assert_int_equal(recon_dhr(m, NTH, th, 32, (uint64_t)s + 1, d, sig + at, NULL, NULL, &e), 0);
		for (int i = 0; i < NTH * NWL; i++)
			err[at + i] = d[i] - truth[i];
		recon_model_free(m);
		csvio_samples_free(&smp);
	}
	for (int t = 0; t < NTH; t++)
		assert_band(what, err, sig, t);
}

/* The paper's 10 × 10 × 10 plan. */
static void test_microfacet_paint_calibrated(void **state)
{
	(void)state;
	paint_band("microfacet paint", 10, 10, 10);
}

/* An intermediate plan, 5 × 6 × 8 (240 samples): the GP's own kriging σ carries the interpolation error there
 * (U = 0, no unseen part; session 11 measured acq-sim's materials on such plans over 20 seeds: z RMS 0.71–1.02
 * wherever the plan's zenith range holds the material's structure, reconstruction.md). */
static void test_microfacet_paint_intermediate(void **state)
{
	(void)state;
	paint_band("microfacet paint 5x6x8", 5, 6, 8);
}

/*
 * The clear coat to the horizon (sessions 12-14, recon/reconstruction.md): acq-sim's clear coat on its grids (θ at
 * cell centres, blind zones dropped: exactly `acq-sim truth clear-coat --grid G`), 1 % noise, CC_NWL wavelengths,
 * DHR at 30° against the simulator's exact DHR. Sessions 12-13: the coat kind's base transmission, Schlick's
 * 1 − (1 − μ)⁵, fell to 0 at grazing while a rough coat's 1 − E_c stays near 0.5, so the model was 27-32 % low
 * beyond θo 82° (no sample there); the last ring's misfit size a (0.37-0.52) switched on the extrapolation σ_X, and
 * K = 0.17 left 5 × 6 × 8 at z RMS 1.70 (main before session 14: 1.70-1.74 on these pools). Session 14: the coat
 * kind fits the base's transmission shape (tS or tE = 1 − E_c, trend.c) and both roughnesses to convergence, so
 * the form holds the edge: a < RECON_EDGE_A0 (measured 0.03-0.08 on seeds 1-3 of the bench's draws; main read
 * 0.34-0.41 here, which fails) and z RMS in [CC_ZLO, CC_ZHI] = [0.6, 1.45] on 5 × 6 × 8 over CC_SEED data sets
 * (ratio 2.4 < 3: σ × 3 and σ / 3 fall outside; main's 1.70-1.74 fails the top) and on the paper plan over
 * CC_PSEED (main: 0.71 with the cancelling errors of session 13, now without them).
 */
#define CC_SEED 3
#define CC_PSEED 2
#define CC_ZLO 0.6
#define CC_ZHI 1.45
#define CC_NWL 24
/* The fit of acq-sim's material mt on its ni × no × np grid (`acq-sim truth MAT --grid`: θ at cell centres, blind
 * zones dropped), 1 % noise, noise seed seed, CC_NWL wavelengths 450 + 25 l nm. */
static struct recon_model *sim_grid_fit(struct mat *mt, int ni, int no, int np, uint64_t seed)
{
	double wl[CC_NWL];
	for (int l = 0; l < CC_NWL; l++)
		wl[l] = 450 + 25.0 * l;
	char path[] = "/tmp/test_recon_honesty_XXXXXX";
	int fd = mkstemp(path);
	assert_true(fd >= 0);
	FILE *f = fdopen(fd, "w");
	struct truth_grid g = { .ni = ni, .no = no, .np = np, .rel = 0.01, .seed = seed, .point_s = 20 };
	refdrift_defaults(&g.cal);
	int rows, dropped;
	struct acq_err e = { 0 };
	assert_int_equal(truth_write_grid(f, mt, &g, wl, CC_NWL, &rows, &dropped, &e), 0);
	fclose(f);
	struct recon_samples smp;
	assert_int_equal(csvio_read_samples(path, &smp, &e), 0);
	unlink(path);
	struct recon_model *m;
	assert_int_equal(recon_fit(&smp, NULL, &m, &e), 0);
	csvio_samples_free(&smp);
	return m;
}

static void coat_dhr30(struct mat *mt, int ni, int no, int np, uint64_t seed, double te, double *d, double *sig)
{
	const double th = 30 * M_PI / 180;
	struct acq_err e = { 0 };
	struct recon_model *m = sim_grid_fit(mt, ni, no, np, seed);
	assert_true(fabs(recon_last_zenith(m) - te) < 1e-6);
	double *A = malloc(m->n * m->n * sizeof *A), *Ai = malloc(m->n * m->n * sizeof *Ai), al[CC_NWL];
	assert_int_equal(recon_gp_setup(m, "test", A, Ai, al, &e), 0);
	double a = recon_edge_size(m, Ai, al);
	printf("clear coat %dx%dx%d: the last ring's held-out size a %.3f\n", ni, no, np, a);
	assert_true(a >= 0 && a < RECON_EDGE_A0); /* the form holds the edge: the extrapolation σ stays off */
	/* acq-sim's coat is seen through 1 − E_coat: the fit takes that transmission (b2) and not Schlick's (b1) */
	assert_int_equal(m->trend, RECON_TREND_COAT);
	for (size_t l = 0; l < m->nwl; l++)
		assert_true(m->tcoef[l * TREND_NB + 1] == 0 && m->tcoef[l * TREND_NB + 2] > 0);
	free(A);
	free(Ai);
	assert_int_equal(recon_dhr(m, 1, &th, 32, seed + 1, d, sig, NULL, NULL, &e), 0);
	recon_model_free(m);
}

/* z RMS of err/(k σ) over n values. */
static double coat_zrms(const double *err, const double *sig, int n, double k)
{
	double acc = 0;
	for (int i = 0; i < n; i++)
		acc += err[i] * err[i] / (k * k * sig[i] * sig[i]);
	return sqrt(acc / n);
}

static void test_coat_beyond_last_zenith(void **state)
{
	(void)state;
	uint64_t base = rt_seed();
	double wl[CC_NWL], truth[CC_NWL], qs[CC_NWL];
	for (int l = 0; l < CC_NWL; l++)
		wl[l] = 450 + 25.0 * l;
	struct acq_err e = { 0 };
	struct mat *mt = mat_new(MAT_CLEAR_COAT, CC_NWL, wl, &e);
	assert_non_null(mt);
	assert_int_equal(mat_dhr(mt, 30 * M_PI / 180, 2, truth, qs, &e), 0);
	double err[CC_SEED * CC_NWL], sig[CC_SEED * CC_NWL];
	for (int s = 0; s < CC_SEED; s++) {
		coat_dhr30(mt, 5, 6, 8, base * 16 + (uint64_t)s, 80.0 * 5.5 / 6 * M_PI / 180, err + s * CC_NWL, sig + s * CC_NWL);
		for (int l = 0; l < CC_NWL; l++)
			err[s * CC_NWL + l] -= truth[l];
	}
	int n = CC_SEED * CC_NWL;
	double z1 = coat_zrms(err, sig, n, 1), z3 = coat_zrms(err, sig, n, 3), z13 = coat_zrms(err, sig, n, 1.0 / 3);
	printf("clear coat 5x6x8, θi = 30°: RMS z %.2f (band [%.2f, %.2f]; σ×3: %.2f, σ/3: %.2f)\n", z1, CC_ZLO, CC_ZHI, z3,
	       z13);
	assert_true(z1 >= CC_ZLO && z1 <= CC_ZHI);
	assert_false(z3 >= CC_ZLO && z3 <= CC_ZHI);
	assert_false(z13 >= CC_ZLO && z13 <= CC_ZHI);
	double perr[CC_PSEED * CC_NWL], psig[CC_PSEED * CC_NWL];
	for (int s = 0; s < CC_PSEED; s++) {
		coat_dhr30(mt, 10, 10, 10, base * 16 + 8 + (uint64_t)s, 76.0 * M_PI / 180, perr + s * CC_NWL,
			   psig + s * CC_NWL);
		for (int l = 0; l < CC_NWL; l++)
			perr[s * CC_NWL + l] -= truth[l];
	}
	double zp = coat_zrms(perr, psig, CC_PSEED * CC_NWL, 1);
	printf("clear coat 10x10x10, θi = 30°: RMS z %.2f (band [%.2f, %.2f])\n", zp, CC_ZLO, CC_ZHI);
	assert_true(zp >= CC_ZLO && zp <= CC_ZHI);
	mat_free(mt);
}

/*
 * Issue 13's residual on coarse plans (session 17, recon/reconstruction.md): acq-sim's green paint on its 3 × 4 × 6
 * grid, GP_SEED data sets × CC_NWL wavelengths, DHR at 8° and 30° against the simulator's exact DHR. The fit's GGX
 * trend lobe (2α ≈ 0.24, so 2w ≈ 0.48) is wider than any hole the plan leaves at these incidences (the largest
 * distance of a DHR node from every sample: 0.40 at 8°, 0.47 at 30°), so no lobe of its kind can hide there; main
 * before session 17 still gave the pockets weight 0.84 (recon_prior_pockets' ramp ended at the constant 2 R0 = 0.70)
 * and σ_E 0.008-0.018 against errors ~0.001 (acq-sim's driver, 20 seeds: z RMS 0.64 / 0.16 at 8 / 30°).
 * The test: at each incidence σ is not more than GP_K = 3 times the error (pooled z RMS ≥ 1/3: the house's measure of
 * a σ "three times too large", which the σ × 3 checks of this file reject) and covers it (z RMS ≤ CC_ZHI); σ × 3
 * fails the floor at each incidence, σ / 3 the ceiling over both incidences pooled. The pooled z RMS varies from
 * data set to data set more than independent wavelengths would make it (the edge gate, a ≈ 0.22-0.33 about
 * RECON_EDGE_A0, charges some data sets' pockets and not others; the error is mostly a bias common to the
 * wavelengths), hence 12 data sets. Measured over ACQ_SEED 1, 2, 3, 5, 6, 7, 11, 23, 42, 77, 99, 123: z RMS 0.68-0.81 at 8°,
 * 0.50-0.91 at 30° (σ × 3: ≤ 0.30), pooled 0.61-0.85 (σ / 3: ≥ 1.84); ~1.6 s CPU. Main 4b2de69 reads 0.17 at 30°
 * (σ ~6× its error): FAILS.
 * 60° (session 17, honest4: the lobe criterion node by node): the plan's deepest hole there (0.517) is deeper than
 * the lobe's 2w, but only 4 % of the unseen share lies in holes that deep; the same band and σ × 3 / σ / 3 checks,
 * over the data sets whose edge gate is off (a < RECON_EDGE_A0: the gate's own charge of the pockets is honest3's
 * open question, and where it fires 60° reads 0.14-0.31 with this rule), drawing further data sets (up to GP_SMAX)
 * until GP_N60 of them. Measured over the 12 ACQ_SEEDs above: 0.59-0.71 (12-27 data sets drawn; 2.3-5.1 s CPU for
 * this test, load 4); main 30a33f4 (the lobe weighed against the deepest hole, g 0.24-0.29 on all of U) reads
 * 0.21-0.25 on the same data sets: FAILS. Over all data sets, gate on or off, 60° read 0.34-0.58 over 24 seeds: too
 * near 1/3 to assert. */
#define GP_SEED 12
#define GP_K 3.0
#define GP_N60 3
#define GP_SMAX 48
static void test_green_paint_coarse_not_overcovered(void **state)
{
	(void)state;
	uint64_t base = rt_seed();
	double wl[CC_NWL], th[3] = { 8 * M_PI / 180, 30 * M_PI / 180, 60 * M_PI / 180 };
	double truth[3 * CC_NWL], qs[3 * CC_NWL];
	for (int l = 0; l < CC_NWL; l++)
		wl[l] = 450 + 25.0 * l;
	struct acq_err e = { 0 };
	struct mat *mt = mat_new(MAT_GREEN_PAINT, CC_NWL, wl, &e);
	assert_non_null(mt);
	for (int t = 0; t < 3; t++)
		assert_int_equal(mat_dhr(mt, th[t], 2, truth + t * CC_NWL, qs + t * CC_NWL, &e), 0);
	static double err[3][GP_SMAX * CC_NWL], sig[3][GP_SMAX * CC_NWL];
	int n60 = 0; /* 60°: only the data sets whose edge gate is off, in err[2], sig[2] */
	int ns = 0;
	for (int s = 0; s < GP_SEED || (n60 < GP_N60 && s < GP_SMAX); s++, ns++) {
		struct recon_model *m = sim_grid_fit(mt, 3, 4, 6, base * 16 + (uint64_t)s);
		assert_int_equal(m->trend, RECON_TREND_GGX);
		double d[3 * CC_NWL], sg[3 * CC_NWL];
		assert_int_equal(recon_dhr(m, 3, th, 32, base * 16 + (uint64_t)s + 1, d, sg, NULL, NULL, &e), 0);
		double *A = malloc(m->n * m->n * sizeof *A), *Ai = malloc(m->n * m->n * sizeof *Ai), al[CC_NWL];
		assert_int_equal(recon_gp_setup(m, "test", A, Ai, al, &e), 0);
		double a = recon_edge_size(m, Ai, al);
		free(A);
		free(Ai);
		printf("green paint 3x4x6, data set %d: GGX α %.3f, edge misfit a %.3f\n", s, m->trend_alpha, a);
		if (a < RECON_EDGE_A0) {
			for (int l = 0; l < CC_NWL; l++) {
				err[2][n60 * CC_NWL + l] = d[2 * CC_NWL + l] - truth[2 * CC_NWL + l];
				sig[2][n60 * CC_NWL + l] = sg[2 * CC_NWL + l];
			}
			n60++;
		}
		for (int t = 0; t < 2 && s < GP_SEED; t++)
			for (int l = 0; l < CC_NWL; l++) {
				err[t][s * CC_NWL + l] = d[t * CC_NWL + l] - truth[t * CC_NWL + l];
				sig[t][s * CC_NWL + l] = sg[t * CC_NWL + l];
			}
		recon_model_free(m);
	}
	int n = GP_SEED * CC_NWL;
	double zz = 0;
	for (int t = 0; t < 2; t++) {
		double z1 = coat_zrms(err[t], sig[t], n, 1), z3 = coat_zrms(err[t], sig[t], n, 3);
		printf("green paint 3x4x6, θi = %.0f°: RMS z %.2f (band [1/%.0f, %.2f]; σ×3: %.2f, σ/3: %.2f)\n",
		       th[t] * 180 / M_PI, z1, GP_K, CC_ZHI, z3, 3 * z1);
		assert_true(z1 >= 1 / GP_K && z1 <= CC_ZHI);
		assert_false(z3 >= 1 / GP_K && z3 <= CC_ZHI); /* σ × 3 */
		zz += z1 * z1 / 2;
	}
	double z60 = coat_zrms(err[2], sig[2], n60 * CC_NWL, 1), z60x3 = coat_zrms(err[2], sig[2], n60 * CC_NWL, 3);
	printf("green paint 3x4x6, θi = 60°, the %d data sets with the edge gate off: RMS z %.2f "
	       "(band [1/%.0f, %.2f]; σ×3: %.2f, σ/3: %.2f; %d data sets drawn)\n",
	       n60, z60, GP_K, CC_ZHI, z60x3, 3 * z60, ns);
	assert_true(n60 >= GP_N60);
	assert_true(z60 >= 1 / GP_K && z60 <= CC_ZHI);
	assert_false(z60x3 >= 1 / GP_K && z60x3 <= CC_ZHI); /* σ × 3 */
	assert_false(3 * z60 <= CC_ZHI);                     /* σ / 3 */
	printf("green paint 3x4x6, 8° and 30° pooled: RMS z %.2f (σ/3: %.2f)\n", sqrt(zz), 3 * sqrt(zz));
	assert_false(3 * sqrt(zz) <= CC_ZHI); /* σ / 3 */
	mat_free(mt);
}

/*
 * The coat's width where the plan cannot measure it (session 18, recon/reconstruction.md; dhr.c width_sd): acq-sim's
 * clear coat on 4 × 4 × 6 samples every mirror direction exactly (θi and θo both at 10, 30, 50, 70°) and nothing
 * within 10° of one, so the fit's admissibility rule (three samples on the coat lobe's flank) sets the coat's
 * roughness at its bound, 0.0588, against the truth's 0.05 and the data's unrestricted optimum ≈ 0.054: the coat's
 * albedo (∝ peak × α²) puts the DHR at 30° +0.005…+0.012 high in every data set, where main's σ was 0.003 (the kriging
 * σ holds the trend fixed; 30° is a sampled incidence, σ_res 0): z RMS 2.38, |z| < 2 on 0.31 (acq-sim's driver, 10
 * seeds × 27 wavelengths). On 2 × 4 × 6 the core rule sets it at 0.0875 and the DHR at 60° reads −0.02 (0.70 / 1.82).
 * The test: CW_SEED data sets × CC_NWL wavelengths each; 4 × 4 × 6 at 30° in the coat test's band [CC_ZLO, CC_ZHI],
 * σ × 3 and σ / 3 fail; 2 × 4 × 6 at 60° in [1/GP_K, CC_ZHI] (σ at most 3× the error: the width's second reading,
 * from a flat profile there, is 1.1-2× the error), σ × 3 fails; σ / 3 fails on the two pooled. Measured over ACQ_SEED
 * 1, 2, 3, 5, 6, 7, 11, 23, 42, 77, 99, 123: 4 × 4 × 6 30° 1.20-1.31, 2 × 4 × 6 60° 0.51-0.92 (its σ / 3 alone:
 * 1.54-2.77, too near the ceiling to assert), pooled σ / 3 ≥ 2.8. Main 3b7510c: 4 × 4 × 6 30° 2.3-2.6: FAILS.
 */
#define CW_SEED 3
static void test_coat_width_unmeasured(void **state)
{
	(void)state;
	uint64_t base = rt_seed();
	static const int grid[2][3] = { { 4, 4, 6 }, { 2, 4, 6 } };
	static const double deg[2] = { 30, 60 }, zlo[2] = { CC_ZLO, 1 / GP_K };
	double wl[CC_NWL], truth[CC_NWL], qs[CC_NWL], zz = 0;
	for (int l = 0; l < CC_NWL; l++)
		wl[l] = 450 + 25.0 * l;
	struct acq_err e = { 0 };
	struct mat *mt = mat_new(MAT_CLEAR_COAT, CC_NWL, wl, &e);
	assert_non_null(mt);
	for (int p = 0; p < 2; p++) {
		double th = deg[p] * M_PI / 180, err[CW_SEED * CC_NWL], sig[CW_SEED * CC_NWL];
		assert_int_equal(mat_dhr(mt, th, 2, truth, qs, &e), 0);
		for (int s = 0; s < CW_SEED; s++) {
			struct recon_model *m = sim_grid_fit(mt, grid[p][0], grid[p][1], grid[p][2], base * 16 + (uint64_t)s);
			assert_int_equal(m->trend, RECON_TREND_COAT);
			printf("clear coat %dx%dx%d, data set %d: coat α %.4f\n", grid[p][0], grid[p][1], grid[p][2], s,
			       m->trend_alpha);
			assert_int_equal(recon_dhr(m, 1, &th, 32, base * 16 + (uint64_t)s + 1, err + s * CC_NWL,
						   sig + s * CC_NWL, NULL, NULL, &e), 0);
			for (int l = 0; l < CC_NWL; l++)
				err[s * CC_NWL + l] -= truth[l];
			recon_model_free(m);
		}
		int n = CW_SEED * CC_NWL;
		double z1 = coat_zrms(err, sig, n, 1), z3 = coat_zrms(err, sig, n, 3), z13 = coat_zrms(err, sig, n, 1.0 / 3);
		printf("clear coat %dx%dx%d, θi = %.0f°: RMS z %.2f (band [%.2f, %.2f]; σ×3: %.2f, σ/3: %.2f)\n", grid[p][0],
		       grid[p][1], grid[p][2], deg[p], z1, zlo[p], CC_ZHI, z3, z13);
		assert_true(z1 >= zlo[p] && z1 <= CC_ZHI);
		assert_false(z3 >= zlo[p] && z3 <= CC_ZHI); /* σ × 3 */
		if (p == 0)
			assert_false(z13 >= zlo[p] && z13 <= CC_ZHI); /* σ / 3 */
		zz += z1 * z1 / 2;
	}
	printf("clear coat, both plans pooled: RMS z %.2f (σ/3: %.2f)\n", sqrt(zz), 3 * sqrt(zz));
	assert_false(3 * sqrt(zz) <= CC_ZHI); /* σ / 3 */
	mat_free(mt);
}

/*
 * acq-sim's sharp lobe (phong n = 250, ψ-width 5°) on 4 × 4 × 6: θi = θo = 10, 30, 50, 70°, every mirror direction
 * sampled exactly and only two samples on the lobe's flank (10° off the mirror at θ 10°), so the fit's admissibility
 * rule rejects the phong kind at the data's width (α 0.089: score 4e-5, the noise) and leaves a GGX lobe (α 0.034,
 * score 0.22) that holds the peak and is too narrow beside it: the DHR read 0.17 low at 8°, 0.11 at 30°, with σ 0.02
 * (z RMS 9.4 / 6.3: session 18). dhr's second reading (width_sd: the data's best kind and width without the rule)
 * holds it. The z RMS at 8° and 30° (2 data sets × 24 wavelengths) in [CC_ZLO, CC_ZHI]; σ × 3 and σ / 3 fail.
 */
#define SL_SEED 2
static void test_sharp_lobe_form_unmeasured(void **state)
{
	(void)state;
	uint64_t base = rt_seed();
	double wl[CC_NWL], truth[2][CC_NWL], qs[CC_NWL], th[2] = { 8 * M_PI / 180, 30 * M_PI / 180 };
	for (int l = 0; l < CC_NWL; l++)
		wl[l] = 450 + 25.0 * l;
	struct acq_err e = { 0 };
	struct mat *mt = mat_new(MAT_SHARP_LOBE, CC_NWL, wl, &e);
	assert_non_null(mt);
	for (int t = 0; t < 2; t++)
		assert_int_equal(mat_dhr(mt, th[t], 2, truth[t], qs, &e), 0);
	double err[SL_SEED * 2 * CC_NWL], sig[SL_SEED * 2 * CC_NWL];
	for (int s = 0; s < SL_SEED; s++) {
		struct recon_model *m = sim_grid_fit(mt, 4, 4, 6, base * 16 + (uint64_t)s);
		printf("sharp lobe 4x4x6, data set %d: trend %s α %.4f\n", s, trend_name(m->trend), m->trend_alpha);
		double *d = err + s * 2 * CC_NWL;
		assert_int_equal(recon_dhr(m, 2, th, 32, base * 16 + (uint64_t)s + 1, d, sig + s * 2 * CC_NWL, NULL, NULL, &e), 0);
		for (int t = 0; t < 2; t++)
			for (int l = 0; l < CC_NWL; l++)
				d[t * CC_NWL + l] -= truth[t][l];
		recon_model_free(m);
	}
	int n = SL_SEED * 2 * CC_NWL;
	double z1 = coat_zrms(err, sig, n, 1), z3 = coat_zrms(err, sig, n, 3), z13 = coat_zrms(err, sig, n, 1.0 / 3);
	printf("sharp lobe 4x4x6, θi = 8°, 30°: RMS z %.2f (band [%.2f, %.2f]; σ×3: %.2f, σ/3: %.2f)\n", z1, CC_ZLO, CC_ZHI,
	       z3, z13);
	assert_true(z1 >= CC_ZLO && z1 <= CC_ZHI);
	assert_false(z3 >= CC_ZLO && z3 <= CC_ZHI); /* σ × 3 */
	assert_false(z13 >= CC_ZLO && z13 <= CC_ZHI); /* σ / 3 */
	mat_free(mt);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_dhr_zscores_calibrated),
		cmocka_unit_test(test_microfacet_paint_calibrated),
		cmocka_unit_test(test_microfacet_paint_intermediate),
		cmocka_unit_test(test_coat_beyond_last_zenith),
		cmocka_unit_test(test_green_paint_coarse_not_overcovered),
		cmocka_unit_test(test_coat_width_unmeasured),
		cmocka_unit_test(test_sharp_lobe_form_unmeasured),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
