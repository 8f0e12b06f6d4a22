/* Unit tests of the reconstruction's honesty at the extremes of issue 13, each on a truth of its own:
 *  - three samples, and one direction pair repeated 2000 times: the DHR's σ covers the truth at 8/30/60° (the
 *    prior on the unseen part of the hemisphere, recon_unseen) and the fit warns; also when the samples miss a
 *    specular lobe that holds most of the albedo (the energy-bounded prior, recon_prior_energy_sd);
 *  - normal incidence only (θi = 0, all θo and φo) of a rough diffuse with an opposition peak: no trend (a lobe
 *    seen at one incidence says nothing of other incidences), evaluations stay within 3× the truth, σ covers the
 *    DHR, the fit warns about the unseen hemisphere at grazing incidence;
 *  - a sharp Ward lobe (α = 0.01) over a 1e-8 sr⁻¹ floor, sampled at its mirror directions: the fit says which
 *    samples it does not honour, and σ covers the DHR that the smoothed model misses;
 *  - a matte diffuse on acq-sim's coarse 3 × 4 × 6 grid: σ not charged for the plan's holes (recon_prior_pockets);
 *  - log-uniform random values over 12 decades (1000 rows): the fit ends (the energy table's work budget; its
 *    time is measured by `make bench`), warns (leave-one-out RMS), and the bound still holds (recon_check), at
 *    ACQ_SEED and at 109 (a counter-example of the energy table's quadrature margin).
 * Before (main at the start of session 4): three samples |z| < 2 on 0-33 %, repeats nowhere (σ 1e-5), normal
 * incidence 900× the truth, the Ward lobe DHR 7e-5 with σ ~1e-4 and no warning, the random case 147 s. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>
#include <time.h>

#include "recon_test_util.h"

#define NWL 4
#define NTH 3
static const double th_deg[NTH] = { 8, 30, 60 };

typedef double (*truth_fn)(const double a[4], double wl);

static double t_phong(const double a[4], double wl)
{
	return rt_truth(a, wl, 1.0);
}

/* Oren-Nayar-like rough diffuse (σ = 0.5) with an opposition (backscatter) peak of 8° about ωi = ωo. */
static double t_oren(const double a[4], double wl)
{
	double rho = 0.3 + 0.2 * (wl - 450) / 650;
	double s2 = 0.25, A = 1 - 0.5 * s2 / (s2 + 0.33), B = 0.45 * s2 / (s2 + 0.09);
	double al = fmax(a[0], a[2]), be = fmin(a[0], a[2]), cph = cos(a[3] - a[1]);
	double on = A + B * fmax(0, cph) * sin(al) * tan(fmin(be, 1.5));
	double wi[3] = { sin(a[0]) * cos(a[1]), sin(a[0]) * sin(a[1]), cos(a[0]) };
	double wo[3] = { sin(a[2]) * cos(a[3]), sin(a[2]) * sin(a[3]), cos(a[2]) };
	double c = fmin(1, fmax(-1, wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2])), g = acos(c) / (8 * M_PI / 180);
	return rho / M_PI * on * (1 + exp(-g * g));
}

/* Ward's isotropic lobe, α = 0.01, k_s = 0.25, over a floor of 1e-8 sr⁻¹ (grey). */
static double t_ward(const double a[4], double wl)
{
	(void)wl;
	double wi[3] = { sin(a[0]) * cos(a[1]), sin(a[0]) * sin(a[1]), cos(a[0]) };
	double wo[3] = { sin(a[2]) * cos(a[3]), sin(a[2]) * sin(a[3]), cos(a[2]) };
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] }, hn = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	double ch = fmax(h[2] / hn, 1e-9), t2 = (1 - ch * ch) / (ch * ch), al = 0.01;
	double ci = fmax(wi[2], 1e-4), co = fmax(wo[2], 1e-4);
	return 1e-8 + 0.25 * exp(-t2 / (al * al)) / (4 * M_PI * al * al * sqrt(ci * co));
}

/* A metal-like truth: Ward's isotropic lobe, α = 0.08, k_s 0.6 → 0.9 over 450-1100 nm (its DHR 0.6-0.9, almost all
 * within ~10° of the mirror direction), over a grey diffuse of albedo 0.02. */
static double t_metal(const double a[4], double wl)
{
	double wi[3] = { sin(a[0]) * cos(a[1]), sin(a[0]) * sin(a[1]), cos(a[0]) };
	double wo[3] = { sin(a[2]) * cos(a[3]), sin(a[2]) * sin(a[3]), cos(a[2]) };
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] }, hn = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	double ch = fmax(h[2] / hn, 1e-9), t2 = (1 - ch * ch) / (ch * ch), al = 0.08, ks = 0.6 + 0.3 * (wl - 450) / 650;
	double ci = fmax(wi[2], 1e-4), co = fmax(wo[2], 1e-4);
	return 0.02 / M_PI + ks * exp(-t2 / (al * al)) / (4 * M_PI * al * al * sqrt(ci * co));
}

/* A diffuse whose DHR bends near the normal: ρ/π·(1 + 3 cosθi cosθo), DHR = ρ(1 + 2 cosθi): even in θi, its
 * curvature at 8° (between samples at 4° and 12°) 0.0024·2ρ from the line through them, its θ⁴ part 1 % of that. */
static double t_even(const double a[4], double wl)
{
	double rho = 0.25 + 0.05 * (wl - 450) / 650;
	return rho / M_PI * (1 + 3 * cos(a[0]) * cos(a[2]));
}

/* Samples of truth f at n direction pairs ang (radians), relative noise rel + floor. */
static void make_samples_noise(struct recon_samples *s, size_t n, const double *ang, truth_fn f, double rel,
			       double floor)
{
	rt_samples_alloc(s, n, NWL, 1);
	for (size_t l = 0; l < NWL; l++)
		s->wl[l] = 450 + 650.0 * (double)l / (NWL - 1);
	for (size_t k = 0; k < n; k++) {
		memcpy(s->ang + 4 * k, ang + 4 * k, 4 * sizeof *ang);
		for (int c = 0; c < 4; c++)
			s->deg[4 * k + c] = ang[4 * k + c] * 180 / M_PI;
		for (size_t l = 0; l < NWL; l++) {
			double v = f(ang + 4 * k, s->wl[l]), sg = rel * v + floor;
			s->val[k * NWL + l] = v + sg * rt_normal();
			s->sig[k * NWL + l] = sg;
		}
	}
}

/* Samples with 1 % noise + floor. */
static void make_samples(struct recon_samples *s, size_t n, const double *ang, truth_fn f, double floor)
{
	make_samples_noise(s, n, ang, f, 0.01, floor);
}

/* DHR of truth f at θi by Gauss-Legendre nmu in cosθo × nphi azimuth midpoints over [0, 2π). */
static double true_dhr(truth_fn f, double ti, double wl, int nmu, int nphi)
{
	double x[256], w[256];
	rbf_gauss_legendre01(nmu, x, w);
	double s = 0;
	for (int i = 0; i < nmu; i++)
		for (int j = 0; j < nphi; j++) {
			double a[4] = { ti, 0, acos(x[i]), (j + 0.5) * 2 * M_PI / nphi };
			s += w[i] * x[i] * (2 * M_PI / nphi) * f(a, wl);
		}
	return s;
}

/* Fit, DHR at 8/30/60°: the largest |z| over incidences and wavelengths against truth f (quadrature nmu × nphi);
 * *m the model (caller frees). */
static double max_z(const struct recon_samples *s, truth_fn f, int nmu, int nphi, struct recon_model **m)
{
	struct acq_err e = { 0 };
	assert_int_equal(recon_fit(s, NULL, m, &e), 0);
	double th[NTH], d[NTH * NWL], sg[NTH * NWL], worst = 0;
	for (int t = 0; t < NTH; t++)
		th[t] = th_deg[t] * M_PI / 180;
	assert_int_equal(recon_dhr(*m, NTH, th, 16, 1, d, sg, NULL, NULL, &e), 0);
	for (int t = 0; t < NTH; t++)
		for (int l = 0; l < NWL; l++) {
			double tr = true_dhr(f, th[t], s->wl[l], nmu, nphi), z = (d[t * NWL + l] - tr) / sg[t * NWL + l];
			printf("  θi %2.0f° %4.0f nm: DHR %.4f truth %.4f σ %.4f z %+.2f\n", th_deg[t], s->wl[l], d[t * NWL + l], tr,
			       sg[t * NWL + l], z);
			assert_true(isfinite(z));
			worst = fmax(worst, fabs(z));
		}
	return worst;
}

static int has_warning(const struct recon_model *m, const char *what)
{
	for (const char *p = strstr(m->meta, "warning="); p; p = strstr(p + 1, "warning="))
		if (strstr(p, what) && (!strchr(p, '\n') || strstr(p, what) < strchr(p, '\n')))
			return 1;
	return 0;
}

static void test_three_samples(void **state)
{
	(void)state;
	rt_seed();
	const double ang[] = { 10, 0, 30, 180, 40, 0, 50, 0, 60, 0, 20, 90 };
	double a[12];
	for (int i = 0; i < 12; i++)
		a[i] = ang[i] * M_PI / 180;
	struct recon_samples s;
	make_samples(&s, 3, a, t_phong, 1e-4);
	struct recon_model *m;
	double z = max_z(&s, t_phong, 96, 384, &m);
	printf("three samples: max |z| %.2f\n", z);
	assert_true(z < 2);
	assert_true(has_warning(m, "distinct directions"));
	assert_true(has_warning(m, "no sample within 20 deg"));
	recon_model_free(m);
	csvio_samples_free(&s);
}

static void test_one_direction_repeated(void **state)
{
	(void)state;
	rt_seed();
	size_t n = 2000;
	double *a = malloc(n * 4 * sizeof *a);
	for (size_t k = 0; k < n; k++) {
		a[4 * k] = 30 * M_PI / 180;
		a[4 * k + 1] = 0;
		a[4 * k + 2] = 30 * M_PI / 180;
		a[4 * k + 3] = M_PI;
	}
	struct recon_samples s;
	make_samples(&s, n, a, t_phong, 1e-4);
	free(a);
	struct recon_model *m;
	double z = max_z(&s, t_phong, 96, 384, &m);
	printf("one direction × 2000: max |z| %.2f\n", z);
	assert_int_equal(m->n, 1);
	assert_true(z < 2);
	assert_true(has_warning(m, "only 1 distinct directions"));
	recon_model_free(m);
	csvio_samples_free(&s);
}

/* Few samples that miss a specular lobe (issue 13 item 3, session 9): three samples 20° and more off the mirror
 * directions, and one direction 60° off it repeated 2000 times, of t_metal (the samples read 0.006-0.07 sr⁻¹, the
 * DHR is 0.6-0.9): σ must cover the truth at 8/30/60°, over three noise seeds. The energy-bounded prior on the
 * unseen part (recon_prior_energy_sd) does; the factor-e prior about the model's own value alone (session 8) gave
 * σ a fraction of the model's dark DHR. */
static void test_specular_lobe_missed(void **state)
{
	(void)state;
	uint64_t seed = rt_seed();
	const double three[] = { 10, 0, 30, 180, 40, 0, 50, 0, 60, 0, 20, 90 }, off[] = { 40, 0, 45, 120 };
	size_t nrep = 2000;
	double *a = malloc(nrep * 4 * sizeof *a), worst[2] = { 0, 0 };
	assert_non_null(a);
	for (int c = 0; c < 2; c++) {
		size_t n = c == 0 ? 3 : nrep;
		for (size_t k = 0; k < n; k++)
			for (int i = 0; i < 4; i++)
				a[4 * k + i] = (c == 0 ? three[4 * k + i] : off[i]) * M_PI / 180;
		for (uint64_t r = 0; r < 3; r++) {
			rt_seed_value(seed + r);
			struct recon_samples s;
			make_samples(&s, n, a, t_metal, 1e-4);
			struct recon_model *m;
			double z = max_z(&s, t_metal, 96, 384, &m);
			printf("%s, seed %llu: max |z| %.2f\n", c == 0 ? "three samples" : "one off-mirror direction × 2000",
			       (unsigned long long)(seed + r), z);
			worst[c] = fmax(worst[c], z);
			assert_true(has_warning(m, "distinct directions"));
			recon_model_free(m);
			csvio_samples_free(&s);
		}
	}
	free(a);
	printf("specular lobe missed: max |z| three samples %.2f, off-mirror repeat %.2f\n", worst[0], worst[1]);
	assert_true(worst[0] < 2);
	assert_true(worst[1] < 2);
}

/* A sharp lobe over a blue pigment, as acq-sim's sharp-lobe: normalised Phong n = 250 (ψ-width 1/√125 ≈ 5°), k_s 0.30,
 * over ρ 0.05-0.30; its DHR 0.35-0.6. */
static double t_sharp(const double a[4], double wl)
{
	double wi[3] = { sin(a[0]) * cos(a[1]), sin(a[0]) * sin(a[1]), cos(a[0]) };
	double wo[3] = { sin(a[2]) * cos(a[3]), sin(a[2]) * sin(a[3]), cos(a[2]) };
	double c = 2 * wi[2] * wo[2] - (wi[0] * wo[0] + wi[1] * wo[1] + wi[2] * wo[2]), n = 250;
	double rho = 0.05 + 0.25 * exp(-(wl - 460) * (wl - 460) / (2 * 80.0 * 80.0));
	return rho / M_PI + (c > 0 ? 0.30 * (n + 2) / (2 * M_PI) * pow(c, n) : 0);
}

/* acq-sim's 3 × 4 × 6 grid (θi 13.3/40/66.7°, θo 10-70° by 20°, φo by 60°): 72 direction pairs into a[]. */
static size_t grid_3x4x6(double *a)
{
	size_t n = 0;
	for (int i = 0; i < 3; i++)
		for (int o = 0; o < 4; o++)
			for (int p = 0; p < 6; p++, n++) {
				a[4 * n] = (40.0 / 3 + 80.0 / 3 * i) * M_PI / 180;
				a[4 * n + 1] = 0;
				a[4 * n + 2] = (10 + 20.0 * o) * M_PI / 180;
				a[4 * n + 3] = 60.0 * p * M_PI / 180;
			}
	return n;
}

/* Issue 13 item 3 on an intermediate plan (session 10): acq-sim's 3 × 4 × 6 grid (θi 13.3/40/66.7°, θo 10-70° by 20°,
 * φo by 60°) of t_sharp. At 30° the nearest sample to the mirror direction (30°, 30°, 180°) is (40°, 30°, 180°):
 * within RECON_PRIOR_R0 of it, so the distance rule alone counted the mirror as seen, but 10° off its own mirror
 * direction, twice the lobe's width: the lobe the model holds there is a guess. σ must cover the truth at 8/30/60°
 * over two noise seeds (recon_mirror_unseen: the sample must lie within the trend lobe's width of its mirror).
 * The distance rule alone (session 9) read max |z| 5.9 at 30° here (ACQ_SEED 1: FAILS); this rule 1.21. */
static void test_sharp_lobe_coarse_grid(void **state)
{
	(void)state;
	uint64_t seed = rt_seed();
	double a[3 * 4 * 6 * 4], worst = 0;
	size_t n = grid_3x4x6(a);
	for (uint64_t r = 0; r < 2; r++) {
		rt_seed_value(seed + r);
		struct recon_samples s;
		make_samples(&s, n, a, t_sharp, 1e-4);
		struct recon_model *m;
		double z = max_z(&s, t_sharp, 256, 1024, &m);
		printf("sharp lobe on a 3 × 4 × 6 grid, seed %llu: trend %s α %.3f, max |z| %.2f\n",
		       (unsigned long long)(seed + r), trend_name(m->trend), m->trend_alpha, z);
		worst = fmax(worst, z);
		recon_model_free(m);
		csvio_samples_free(&s);
	}
	printf("sharp lobe on a 3 × 4 × 6 grid: max |z| %.2f\n", worst);
	assert_true(worst < 2);
}

/* A smooth diffuse of moderate albedo (ρ 0.30 → 0.50 over 450-1100 nm), mildly brighter towards the normal:
 * ρ/π · (1 + 0.2 cosθi cosθo); DHR ρ (1 + 0.4/3 · cosθi). No lobe anywhere. */
static double t_matte(const double a[4], double wl)
{
	double rho = 0.30 + 0.20 * (wl - 450) / 650;
	return rho / M_PI * (1 + 0.2 * cos(a[0]) * cos(a[2]));
}


/* Issue 13 item 3, the other side (session 15): on the 3 × 4 × 6 grid a material whose data show no lobe the plan's
 * holes could hide (t_matte) must not be charged for them. The holes
 * (azimuth gaps beyond the last zenith 70°, 0.35-0.5 from every sample) are U ≈ 0.0002-0.014 of the hemisphere;
 * session 9's rule gave them p = U in σ_E = √p · s with s ~ R/√3 ≈ 0.3, σ 0.005-0.04 against errors ~1e-4 (acq-sim's
 * rough-backscatter on this grid, 20 seeds: z RMS 0.16/0.03/0.02 at 8/30/60°). recon_prior_pockets charges them only
 * where the data give a reason (a narrow trend lobe, the last ring's misfit, much of the hemisphere unseen).
 * Over 6 noise seeds × 16 wavelengths × 8/30/60°: z RMS in [0.35, 1.5], |z| < 2 on ≥ 85 %; σ × 3 and σ / 3 fail it.
 * Measured at ACQ_SEED 1, 2, 3, 7, 11, 23, 42, 77, 99, 123, 1000, 4242: z RMS 0.60-0.98 (some data sets read 0.13-0.4:
 * the edge gate's size a crosses RECON_EDGE_A0 on this truth without a trend, and charges the pockets), |z| < 2 on
 * 0.958-0.993; σ / 3 reads |z| < 2 on ≤ 0.82 (z RMS × 3 ≥ 1.80), σ × 3 z RMS ≤ 0.33. Session 9's
 * rule (recon_prior_pockets ≡ 1) reads z RMS 0.12 / 0.10 at ACQ_SEED 1 / 7: FAILS. */
static void test_coarse_grid_diffuse_not_overcharged(void **state)
{
	(void)state;
	enum { L = 16, NS = 6 };
	uint64_t seed = rt_seed();
	double a[3 * 4 * 6 * 4], z2 = 0;
	size_t n = grid_3x4x6(a), nz = 0, in2 = 0, in2_d3 = 0;
	double th[NTH], d[NTH * L], sg[NTH * L];
	for (int t = 0; t < NTH; t++)
		th[t] = th_deg[t] * M_PI / 180;
	for (uint64_t r = 0; r < NS; r++) {
		rt_seed_value(seed + r);
		struct recon_samples s; /* 16 wavelengths: the edge gate's size a is an RMS over them (4 leave it noisy) */
		rt_samples_alloc(&s, n, L, 1);
		for (size_t l = 0; l < L; l++)
			s.wl[l] = 450 + 650.0 * (double)l / (L - 1);
		for (size_t k = 0; k < n; k++) {
			memcpy(s.ang + 4 * k, a + 4 * k, 4 * sizeof *a);
			for (int c = 0; c < 4; c++)
				s.deg[4 * k + c] = a[4 * k + c] * 180 / M_PI;
			for (size_t l = 0; l < L; l++) {
				double v = t_matte(a + 4 * k, s.wl[l]), sgm = 0.01 * v;
				s.val[k * L + l] = v + sgm * rt_normal();
				s.sig[k * L + l] = sgm;
			}
		}
		struct recon_model *m;
		struct acq_err e = { 0 };
		assert_int_equal(recon_fit(&s, NULL, &m, &e), 0);
		assert_int_equal(recon_dhr(m, NTH, th, 16, 1, d, sg, NULL, NULL, &e), 0);
		double zs2 = 0;
		for (int t = 0; t < NTH; t++)
			for (size_t l = 0; l < L; l++) {
				double tr = true_dhr(t_matte, th[t], s.wl[l], 32, 48), z = (d[t * L + l] - tr) / sg[t * L + l];
				if (l == L / 2)
					printf("  seed %llu θi %2.0f° %4.0f nm: DHR %.5f truth %.5f σ %.5f z %+.2f\n",
					       (unsigned long long)(seed + r), th_deg[t], s.wl[l], d[t * L + l], tr, sg[t * L + l], z);
				assert_true(isfinite(z));
				z2 += z * z;
				zs2 += z * z;
				nz++;
				in2 += fabs(z) < 2;
				in2_d3 += fabs(3 * z) < 2;
			}
		printf("matte diffuse on a 3 × 4 × 6 grid, seed %llu: trend %s, z RMS %.2f\n", (unsigned long long)(seed + r),
		       trend_name(m->trend), sqrt(zs2 / (NTH * L)));
		recon_model_free(m);
		csvio_samples_free(&s);
	}
	double rms = sqrt(z2 / (double)nz), share = (double)in2 / (double)nz;
	printf("matte diffuse on a 3 × 4 × 6 grid: z RMS %.2f (σ × 3: %.2f, σ / 3: %.2f), |z| < 2 on %.3f (σ / 3: %.3f)\n",
	       rms, rms / 3, rms * 3, share, (double)in2_d3 / (double)nz);
	assert_true(share >= 0.85);
	assert_true(rms >= 0.35 && rms <= 1.5);
	assert_false(rms / 3 >= 0.35);                                       /* σ × 3: over-covered, fails */
	assert_false(rms * 3 <= 1.5 && (double)in2_d3 / (double)nz >= 0.85); /* σ / 3: fails */
}

static void test_normal_incidence_only(void **state)
{
	(void)state;
	rt_seed();
	double a[100 * 4];
	size_t k = 0;
	for (int o = 0; o < 10; o++)
		for (int p = 0; p < 10; p++, k++) {
			a[4 * k] = 0;
			a[4 * k + 1] = 0;
			a[4 * k + 2] = (5 + 75.0 * o / 9) * M_PI / 180;
			a[4 * k + 3] = 36.0 * p * M_PI / 180;
		}
	struct recon_samples s;
	make_samples(&s, 100, a, t_oren, 1e-5);
	struct recon_model *m;
	double z = max_z(&s, t_oren, 96, 384, &m);
	printf("normal incidence only: max |z| %.2f\n", z);
	assert_true(z < 2);
	assert_int_equal(m->trend, RECON_TREND_NONE); /* was: an invented GGX lobe, 900× the truth */
	assert_true(has_warning(m, "no sample within 20 deg"));
	double worst = 0, q[4], f[NWL];
	struct acq_err e = { 0 };
	for (int i = 0; i < 500; i++) {
		rt_random_pair(q);
		assert_int_equal(recon_eval(m, 1, q, f, &e), 0);
		for (int l = 0; l < NWL; l++)
			worst = fmax(worst, f[l] / t_oren(q, s.wl[l]));
	}
	printf("normal incidence only: largest model/truth at 500 random pairs %.2f\n", worst);
	assert_true(worst < 3); /* measured 1.9 */
	recon_model_free(m);
	csvio_samples_free(&s);
}

static void test_sharp_lobe_over_floor(void **state)
{
	(void)state;
	rt_seed();
	double a[10 * 10 * 10 * 4];
	size_t k = 0; /* θi and θo on the same grid: every incidence has a sample at its mirror direction */
	for (int i = 0; i < 10; i++)
		for (int o = 0; o < 10; o++)
			for (int p = 0; p < 10; p++, k++) {
				a[4 * k] = (5 + 75.0 * i / 9) * M_PI / 180;
				a[4 * k + 1] = 0;
				a[4 * k + 2] = (5 + 75.0 * o / 9) * M_PI / 180;
				a[4 * k + 3] = 36.0 * p * M_PI / 180;
			}
	struct recon_samples s;
	make_samples(&s, 1000, a, t_ward, 1e-12);
	double peak = 0;
	for (size_t i = 0; i < s.n * NWL; i++)
		peak = fmax(peak, s.val[i]);
	printf("sharp lobe: brightest sample %.4g sr⁻¹\n", peak);
	assert_true(peak > 100);
	struct recon_model *m;
	double z = max_z(&s, t_ward, 256, 4096, &m);
	printf("sharp lobe over a floor: max |z| %.2f\n", z);
	assert_true(z < 2);
	assert_true(has_warning(m, "not honoured"));
	recon_model_free(m);
	csvio_samples_free(&s);
}

/*
 * σ_res near the normal (dhr.c `resolution`): the DHR is even in θi, so at 8°, with sampled incidences 4° and 12°
 * only, the mirror images −4°, −12° are nodes too and the cubic through them follows the curve's even curvature;
 * the line through 4° and 12° alone counts that curvature as unresolved structure (session 5: cloth-sheen at 8°,
 * σ_res 2.1e-4 against an error of 2.6e-4). On a truth whose DHR bends like cosθi, σ_res at 8° must be far below
 * the model's own distance from that line (which the rule without the mirror images reports), while the line's
 * distance is large enough to tell them apart.
 */
static void test_res_mirrored_incidence(void **state)
{
	(void)state;
	rt_seed();
	static const double ti[] = { 4, 12, 20, 36, 52, 68 }, to[] = { 4, 12, 20, 36, 52, 68 };
	enum { NI = 6, NO = 6, NP = 6 };
	double a[NI * NO * NP * 4];
	size_t k = 0;
	for (int i = 0; i < NI; i++)
		for (int o = 0; o < NO; o++)
			for (int p = 0; p < NP; p++, k++) {
				a[4 * k] = ti[i] * M_PI / 180;
				a[4 * k + 1] = 0;
				a[4 * k + 2] = to[o] * M_PI / 180;
				a[4 * k + 3] = 60.0 * p * M_PI / 180;
			}
	struct recon_samples s;
	make_samples_noise(&s, k, a, t_even, 1e-4, 1e-6);
	struct recon_model *m;
	struct acq_err e = { 0 };
	assert_int_equal(recon_fit(&s, NULL, &m, &e), 0);
	double th[3] = { 4 * M_PI / 180, 8 * M_PI / 180, 12 * M_PI / 180 }, d[3 * NWL], sg[3 * NWL], res[3 * NWL];
	struct recon_dhr_parts parts = { .res = res };
	assert_int_equal(recon_dhr_parts(m, 3, th, 16, 1, d, sg, &parts, NULL, NULL, &e), 0);
	for (int l = 0; l < NWL; l++) {
		double line = fabs(d[NWL + l] - 0.5 * (d[l] + d[2 * NWL + l]));
		double tr = true_dhr(t_even, th[1], s.wl[l], 64, 64), z = (d[NWL + l] - tr) / sg[NWL + l];
		printf("  %4.0f nm: DHR 4/8/12° %.5f %.5f %.5f, 8° from the line %.2e, σ_res %.2e (ratio %.3f), σ %.2e, z %+.2f\n",
		       s.wl[l], d[l], d[NWL + l], d[2 * NWL + l], line, res[NWL + l], res[NWL + l] / line, sg[NWL + l], z);
		assert_true(res[l] == 0 && res[2 * NWL + l] == 0); /* sampled incidences */
		assert_true(line > 5e-4);                         /* the truth's curvature: 0.0024·2ρ = 1.2e-3-1.4e-3 */
		assert_true(res[NWL + l] < 0.3 * line); /* measured 0.06-0.13 (ACQ_SEED 1-40); 1 without the mirror images */
	}
	recon_model_free(m);
	csvio_samples_free(&s);
}

/* Log-uniform random values over 12 decades, 1000 rows, from the generator's state: the fit ends (the energy
 * table's work budget), warns, and the bound holds (recon_check). */
static void log_uniform_case(void)
{
	size_t n = 1000;
	struct recon_samples s;
	rt_samples_log_uniform(&s, n, NWL);
	struct recon_model *m;
	struct acq_err e = { 0 };
	clock_t c0 = clock();
	assert_int_equal(recon_fit(&s, NULL, &m, &e), 0);
	double cpu = (double)(clock() - c0) / CLOCKS_PER_SEC;
	printf("log-uniform random: fit %.2f s CPU, leave-one-out RMS %.3g, table capped %d, trend %s (alpha %.3g)\n", cpu,
	       m->loo_rms, m->tab_capped, trend_name(m->trend), m->trend_alpha);
	/* The time itself is a benchmark figure (`make bench`, bench_recon.py's random input), not a test: a
	 * sanitizer build or a loaded machine moves it. What bounds it is the energy table's work budget. */
	assert_true(has_warning(m, "leave-one-out RMS")); /* no sigma columns: "not honoured" cannot be judged */
	struct recon_check_report rep;
	assert_int_equal(recon_check(m, 2000, 8, 1, &rep, NULL, NULL, &e), 0);
	printf("log-uniform random: check max albedo %.5f +- %.2g (its quadrature) at %.2f deg, min f %g, reciprocity %g\n",
	       rep.max_albedo, rep.max_albedo_qerr, rep.max_albedo_theta * 180 / M_PI, rep.min_value, rep.max_recip_abs);
	/* ≤ 1 within the check's own quadrature uncertainty (2 × its last rule difference): the energy table's
	 * margin covers its own rule's tolerance (energy.c albtab_margin) */
	assert_true(rep.energy_excess <= 0 && rep.min_value >= 0 && rep.max_recip_abs == 0 && rep.nonfinite == 0);
	recon_model_free(m);
	csvio_samples_free(&s);
}

/* The case at ACQ_SEED, and at 109 whatever the seed: there the energy table's node at θ = 0 was 2.8 times its
 * rules' difference off (two coarse rules agreeing by both missing the same part), its bound (quadrature margin
 * 2d only) was 2e-4 low and the check read 1.0002 ± 5e-5 (fails without the TAB_TOL part of the margin). */
static void test_log_uniform_random(void **state)
{
	(void)state;
	uint64_t seed = rt_seed();
	log_uniform_case();
	if (seed != 109) {
		printf("the counter-example, ACQ_SEED=109:\n");
		rt_seed_value(109);
		log_uniform_case();
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_three_samples),         cmocka_unit_test(test_one_direction_repeated),
		cmocka_unit_test(test_normal_incidence_only), cmocka_unit_test(test_sharp_lobe_over_floor),
		cmocka_unit_test(test_log_uniform_random),    cmocka_unit_test(test_res_mirrored_incidence),
		cmocka_unit_test(test_specular_lobe_missed),  cmocka_unit_test(test_sharp_lobe_coarse_grid),
		cmocka_unit_test(test_coarse_grid_diffuse_not_overcharged),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
