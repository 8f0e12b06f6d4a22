/* Unit tests for daemon/calib.c: recovered BRDF against known truth in z-scores (relative and absolute
 * methods, reference and angular terms), binning and its uncertainty combination, configuration. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "daemon/calib.h"
#include "tests/unit/synth.h"

static uint64_t seed;

enum { NPIX = 2048 };
static const struct synth_det det = { .npix = NPIX, .offset = 1500, .dc_per_ms = 0.3, .read_sigma = 10, .full = 65535 };
static double wl[NPIX];

static double f_true(double lam)
{
	double x = (lam - 530) / 40;
	return 0.05 + 0.2 * exp(-x * x); /* sr⁻¹, a green paint-like bump */
}

static double lamp(double lam)
{
	return 0.4 + 0.6 * exp(-0.5 * ((lam - 700) / 250) * ((lam - 700) / 250)); /* source × detector response */
}

/* One measured net rate: dark then signal at t with `scans` averages, through the production path. */
static void measure(struct synth_rng *r, const double *rate, double t, unsigned scans, struct exp_rate *out)
{
	static struct exp_avg avg;
	static struct exp_darks darks;
	static float sd[SPECTRO_MAX_PIXELS];
	struct exp_policy pol;
	exp_policy_defaults(&pol);
	exp_darks_clear(&darks);
	synth_take(r, &det, NULL, t, scans, &avg);
	const struct exp_dark *dk = exp_dark_store(&darks, &avg, 0);
	synth_take(r, &det, rate, t, scans, &avg);
	synth_frame(&avg, sd);
	assert_int_equal(exp_net_rate(&pol, avg.mean, sd, avg.n, avg.saturated, NPIX, t, dk, det.full, out, NULL), 0);
}

/* Truth of grid bin k: f at the bin's wavelength when the bin has valid pixels (binning estimates f at λ_k, exact
 * for a spectrum linear within the bin; f_true's curvature leaves < 1e-5 relative). */
static double bin_truth(const struct calib_cfg *c, const struct exp_rate *s, int k, double theta_scale)
{
	double lam = c->grid_min_nm + k * c->grid_step_nm, h = c->grid_step_nm / 2;
	int m = 0;
	for (int p = 0; p < NPIX; p++)
		if (wl[p] >= lam - h && wl[p] < lam + h && s->valid[p])
			m++;
	return m ? f_true(lam) * theta_scale : NAN;
}

struct zstat {
	double s, s2, s2_no_ref;
	long n;
};

static void z_add(struct zstat *z, const struct calib_spectrum *sp, int k, double truth)
{
	if (!isfinite(sp->f[k]) || !isfinite(truth))
		return;
	double e = sp->f[k] - truth;
	double zz = e / sp->u[k];
	double u_nr = sqrt(sp->u[k] * sp->u[k] - sp->u_ref[k] * sp->u_ref[k]);
	z->s += zz;
	z->s2 += zz * zz;
	z->s2_no_ref += (e / u_nr) * (e / u_nr);
	z->n++;
}

/* Relative method: f recovered from sample and white-reference spectra (each with its own dark, through the
 * averaging and net-rate path), while the reference's true reflectance is drawn around its nominal value
 * with its stated uncertainty. The z-scores of all bins over all draws must be standard normal; without the
 * reference term they would not be (checked, so the test can fail). */
static void test_relative_zscores(void **state)
{
	(void)state;
	struct calib_cfg c;
	calib_cfg_defaults(&c);
	c.rho_ref.val[0] = 0.95;
	c.rho_ref.u[0] = 0.001;
	c.ref_theta_o_deg = 45; /* the reference seen at θo = 45°, the sample at 30° (bench model: ∝ cos θo) */ /* comparable to the noise of one bin, so both terms are tested */
	static double rs[NPIX], rr[NPIX];
	static struct exp_rate es, eref;
	static struct calib_spectrum sp;
	struct synth_rng r = { .s = seed };
	struct zstat z = { 0 };
	const int draws = 100;
	const double K = 2500; /* counts/ms of the reference at the lamp's peak */
	const struct calib_geom g = { 50, 30 };
	for (int d = 0; d < draws; d++) {
		double rho = c.rho_ref.val[0] + c.rho_ref.u[0] * synth_gauss(&r);
		for (int p = 0; p < NPIX; p++) {
			rr[p] = K * lamp(wl[p]) * rho / M_PI * cos(45 * M_PI / 180);
			rs[p] = K * lamp(wl[p]) * f_true(wl[p]) * cos(g.theta_o * M_PI / 180);
		}
		measure(&r, rs, 40, 30, &es);
		measure(&r, rr, 10, 30, &eref);
		assert_int_equal(calib_spectrum(&c, wl, &es, &eref, &g, &sp, NULL), 0);
		assert_int_equal(sp.n, 651);
		for (int k = 0; k < sp.n; k++)
			z_add(&z, &sp, k, bin_truth(&c, &es, k, 1.0));
	}
	double mean = z.s / z.n, var = z.s2 / z.n - mean * mean, var_nr = z.s2_no_ref / z.n;
	print_message("relative: %ld z-scores, mean %.4f, var %.4f (var without the reference term %.3f)\n", z.n, mean,
		      var, var_nr);
	assert_true(z.n > draws * 600);
	assert_true(fabs(mean) < 0.2);
	assert_true(var > 0.75 && var < 1.3); /* the scale terms have one draw per spectrum */
	assert_true(var_nr > 1.5); /* the reference term matters in this setup */
	assert_int_equal(sp.method, CALIB_RELATIVE);
	assert_string_equal(calib_method_name(sp.method), "relative");
}

/* calib_ref_noise: a noiseless sample against a noisy white reference carries only the reference's error, the
 * error one reference spectrum shares with every sample of a sweep; relative to the truth, in units of the
 * u_rel it states per bin, it must be standard normal over many reference draws (u_rel 0.8× as large: var 1.6).
 * With 4 scans per spectrum (make demo's reference) the per-pixel std is a noisy estimate: unpooled, the
 * variance read 1.235; pooled over ±CALIB_REFN_POOL_NM it must be 1 as with 30 scans. */
static void ref_noise_case(unsigned scans)
{
	struct calib_cfg c;
	calib_cfg_defaults(&c);
	c.rho_ref.u[0] = 0; /* the scale term is another matter (the certificate) */
	static double rr[NPIX];
	static double u_rel[CALIB_MAX_GRID];
	static struct exp_rate es, eref;
	static struct calib_spectrum sp;
	struct synth_rng r = { .s = seed + 7 };
	const double K = 2500;
	const struct calib_geom g = { 20, 30 };
	es.npix = NPIX;
	es.ninvalid = 0;
	for (int p = 0; p < NPIX; p++) {
		rr[p] = K * lamp(wl[p]) * c.rho_ref.val[0] / M_PI;
		es.rate[p] = rr[p] * f_true(wl[p]) * M_PI / c.rho_ref.val[0]; /* exact: f = R_s/R_ref · ρ/π */
		es.u_noise[p] = es.u_dark[p] = 0;
		es.t_ms[p] = 40;
		es.valid[p] = 1;
	}
	double s2 = 0, umin = INFINITY, umax = 0;
	long n = 0;
	for (int d = 0; d < 60; d++) {
		measure(&r, rr, 10, scans, &eref);
		assert_int_equal(calib_spectrum(&c, wl, &es, &eref, &g, &sp, NULL), 0);
		assert_int_equal(calib_ref_noise(&c, wl, &eref, u_rel, NULL), 0);
		for (int k = 0; k < sp.n; k++) {
			double t = bin_truth(&c, &eref, k, 1.0);
			if (!isfinite(sp.f[k]) || !isfinite(t))
				continue;
			assert_true(isfinite(u_rel[k]) && u_rel[k] > 0);
			double z = (sp.f[k] / t - 1) / u_rel[k];
			s2 += z * z;
			n++;
			umin = fmin(umin, u_rel[k]);
			umax = fmax(umax, u_rel[k]);
		}
	}
	double var = s2 / n;
	print_message("reference noise, %u scans: %ld bins, u_rel %.2g..%.2g, var of the relative error / u_rel %.3f\n",
		      scans, n, umin, umax, var);
	assert_true(n > 60 * 600);
	assert_true(umax > 1e-3); /* large enough to matter against the sample noise of this file's other tests */
	assert_true(var > 0.85 && var < 1.15); /* 39k values: the variance's own scatter ~1 %; f's slope in a bin ~0.1 % */
	/* no usable pixel: NaN */
	for (int p = 0; p < NPIX; p++)
		eref.valid[p] = 0;
	assert_int_equal(calib_ref_noise(&c, wl, &eref, u_rel, NULL), 0);
	assert_true(isnan(u_rel[0]) && isnan(u_rel[sp.n - 1]));
}

static void test_ref_noise(void **state)
{
	(void)state;
	ref_noise_case(30);
	ref_noise_case(4);
}

/* Absolute method: f = R_s / (R_beam Ω cos θo) with Ω's true value drawn around the nominal. */
static void test_absolute_zscores(void **state)
{
	(void)state;
	struct calib_cfg c;
	calib_cfg_defaults(&c);
	c.method = CALIB_ABSOLUTE;
	c.omega_det_sr = 2e-3;
	c.u_omega_rel = 0.0013;
	static double rs[NPIX], rb[NPIX];
	static struct exp_rate es, eb;
	static struct calib_spectrum sp;
	struct synth_rng r = { .s = seed ^ 0xabcdef };
	struct zstat z = { 0 };
	const int draws = 100;
	const struct calib_geom g = { 20, 60 };
	for (int d = 0; d < draws; d++) {
		double om = c.omega_det_sr * (1 + c.u_omega_rel * synth_gauss(&r));
		for (int p = 0; p < NPIX; p++) {
			rb[p] = 3e5 * lamp(wl[p]);
			rs[p] = rb[p] * f_true(wl[p]) * om * cos(g.theta_o * M_PI / 180);
		}
		measure(&r, rb, 0.15, 30, &eb);
		measure(&r, rs, 300, 30, &es);
		assert_int_equal(calib_spectrum(&c, wl, &es, &eb, &g, &sp, NULL), 0);
		for (int k = 0; k < sp.n; k++)
			z_add(&z, &sp, k, bin_truth(&c, &es, k, 1.0));
	}
	double mean = z.s / z.n, var = z.s2 / z.n - mean * mean;
	print_message("absolute: %ld z-scores, mean %.4f, var %.4f (without the Ω term %.3f)\n", z.n, mean, var,
		      z.s2_no_ref / z.n);
	assert_true(fabs(mean) < 0.25);
	assert_true(var > 0.75 && var < 1.3); /* the scale terms have one draw per spectrum */
	assert_true(z.s2_no_ref / z.n > 1.5);
	struct acq_err err = { 0 };
	const struct calib_geom bad = { 20, 95 };
	assert_int_equal(calib_spectrum(&c, wl, &es, &eb, &bad, &sp, &err), -1);
	assert_int_equal(err.code, ACQ_E_RANGE);
}

/* Angular term: the arm lands at θ + N(0, σ); with the configured relative sensitivity the z-scores of an
 * otherwise noiseless measurement are standard normal; the neighbour estimate finds the same slope. */
static void test_angular_term(void **state)
{
	(void)state;
	struct calib_cfg c;
	calib_cfg_defaults(&c);
	c.rho_ref.val[0] = 1.0;
	c.rho_ref.u[0] = 0.0;
	c.sigma_pos_deg = 0.3;
	const double s = 0.04; /* relative slope of f per degree at θo = 40° */
	c.angle_rel_per_deg = s;
	static struct exp_rate es, eref;
	static struct calib_spectrum sp;
	struct synth_rng r = { .s = seed ^ 0x77 };
	es.npix = eref.npix = NPIX;
	double sz2 = 0, s2n = 0;
	long n = 0;
	const int draws = 3000;
	const struct calib_geom g = { 10, 40 };
	for (int d = 0; d < draws; d++) {
		double dth = c.sigma_pos_deg * synth_gauss(&r);
		for (int p = 0; p < NPIX; p++) {
			eref.valid[p] = es.valid[p] = 1;
			eref.rate[p] = 1000 / M_PI;
			eref.u_noise[p] = eref.u_dark[p] = es.u_dark[p] = 0;
			es.rate[p] = 1000 * f_true(wl[p]) * (1 + s * dth);
			es.u_noise[p] = 1e-9;
		}
		assert_int_equal(calib_spectrum(&c, wl, &es, &eref, &g, &sp, NULL), 0);
		for (int k = 0; k < sp.n; k += 13) {
			double e = sp.f[k] - bin_truth(&c, &es, k, 1.0);
			sz2 += (e / sp.u[k]) * (e / sp.u[k]);
			s2n += (e / hypot(sp.u_noise[k], 1e-12)) * (e / hypot(sp.u_noise[k], 1e-12));
			n++;
		}
	}
	print_message("angle: var of z %.3f\n", sz2 / n);
	assert_true(sz2 / n > 0.85 && sz2 / n < 1.15);
	assert_true(s2n / n > 100); /* ignoring the term would be badly wrong */
}


/* The value of a bin is f at the bin's wavelength, not at its pixels' centroid: on the simulated spectrometer's
 * pixel grid (450–1100 nm over pixels 4–2047 with grating curvature, 2.9–3.3 pixels per 1 nm bin) a plain mean sits
 * up to ±0.17 nm off λ_k, a relative error (f'/f)·x̄ shared by every sample of a sweep (1.6e-3 rms at 450–600 nm on
 * green paint; test_dhr_refnoise / make demo). Noiseless, on this test's green bump: every bin within 1e-4
 * relative of f(λ_k) (the bump's curvature, |f''/f| ≤ 1e-3 nm⁻², times Σ w x² ≤ ~0.1 nm²: 5.3e-5 measured).
 * Seen failing with the plain mean: max 4.55e-3 here, and test_ref_noise's variance 1.54 (30 scans). */
static void test_bin_centre(void **state)
{
	(void)state;
	struct calib_cfg c;
	calib_cfg_defaults(&c);
	static struct calib_px px;
	static struct calib_spectrum sp;
	static double wls[NPIX];
	double p0 = 4, p1 = NPIX - 1, c2 = -1.5e-5, c1 = (650.0 - c2 * (p1 * p1 - p0 * p0)) / (p1 - p0),
	       c0 = 450.0 - c1 * p0 - c2 * p0 * p0; /* sim/sim_physics.c default_coef */
	px.npix = NPIX;
	for (int p = 0; p < NPIX; p++) {
		wls[p] = c0 + c1 * p + c2 * p * p;
		px.valid[p] = p >= p0;
		px.f[p] = f_true(wls[p]);
		px.u_noise[p] = px.u_dark[p] = px.u_refn[p] = px.u_refs[p] = px.u_angle[p] = 0;
	}
	assert_int_equal(calib_resample(&c, wls, &px, &sp, NULL), 0);
	double worst = 0;
	for (int k = 0; k < sp.n; k++) {
		assert_true(sp.npix[k] >= 2);
		worst = fmax(worst, fabs(sp.f[k] / f_true(sp.wl[k]) - 1));
	}
	print_message("bin centre: max relative error %.2e over %d bins\n", worst, sp.n);
	assert_true(worst < 1e-4);
}

/* Binning: pixels in each bin averaged with independent terms in quadrature and common terms linearly;
 * invalid (saturated) pixels never used; interpolation when pixels are coarser than the grid. */
static void test_resample(void **state)
{
	(void)state;
	struct calib_cfg c;
	calib_cfg_defaults(&c);
	static struct calib_px px;
	static struct calib_spectrum sp;
	px.npix = NPIX;
	for (int p = 0; p < NPIX; p++) {
		px.valid[p] = 1;
		px.f[p] = 0.1 + 0.001 * wl[p];
		px.u_noise[p] = 0.01;
		px.u_dark[p] = 0.002;
		px.u_refn[p] = 0.0;
		px.u_refs[p] = 0.02;
		px.u_angle[p] = 0.003;
	}
	/* a saturated pixel with a wild value in bin 600 nm, and a bin with only invalid pixels (700 nm) */
	int wild = -1;
	for (int p = 0; p < NPIX; p++) {
		if (wild < 0 && wl[p] >= 599.6 && wl[p] < 600.5)
			wild = p;
		if (wl[p] >= 699.5 && wl[p] < 700.5)
			px.valid[p] = 0, px.f[p] = 1e30;
	}
	px.valid[wild] = 0;
	px.f[wild] = 1e30;
	assert_int_equal(calib_resample(&c, wl, &px, &sp, NULL), 0);
	for (int k = 0; k < sp.n; k++) {
		double lam = sp.wl[k];
		if (fabs(lam - 700) < 1e-9) {
			assert_true(isnan(sp.f[k]));
			continue;
		}
		int m = 0;
		double sx = 0, sxx = 0;
		for (int p = 0; p < NPIX; p++)
			if (wl[p] >= lam - 0.5 && wl[p] < lam + 0.5 && px.valid[p])
				m++, sx += wl[p] - lam, sxx += (wl[p] - lam) * (wl[p] - lam);
		assert_int_equal(sp.npix[k], m);
		assert_true(m >= 2);
		/* a line through the bin's pixels at λ_k: exact for this linear f; the variance of independent terms is
		 * 1/m + x̄²/Σ(x − x̄)² per unit (the plain mean's 1/m when the pixels' centroid x̄ sits on λ_k) */
		double xm = sx / m, vfac = 1.0 / m + xm * xm / (sxx - m * xm * xm);
		assert_true(fabs(sp.f[k] - (0.1 + 0.001 * lam)) < 1e-12);
		assert_true(fabs(sp.vfac[k] - vfac) < 1e-12);
		assert_true(fabs(sp.u_noise[k] - 0.01 * sqrt(vfac)) < 1e-12);
		assert_true(fabs(sp.u_ref[k] - 0.02) < 1e-12);
		assert_true(fabs(sp.u_angle[k] - 0.003) < 1e-12);
		double u = sqrt((0.0001 + 0.000004) * vfac + 0.0004 + 0.000009);
		assert_true(fabs(sp.u[k] - u) < 1e-12);
	}
	/* coarse pixels (3 nm apart): grid points between pixels interpolate */
	static double wl3[NPIX];
	for (int p = 0; p < NPIX; p++) {
		wl3[p] = 400.2 + 3.0 * p;
		px.valid[p] = 1;
		px.f[p] = 0.5 + 0.002 * wl3[p];
	}
	assert_int_equal(calib_resample(&c, wl3, &px, &sp, NULL), 0);
	int interpolated = 0;
	for (int k = 0; k < sp.n; k++) {
		if (sp.npix[k] == 0) { /* interpolated: exact for a linear f; independent terms shrink, common do not */
			interpolated++;
			assert_true(fabs(sp.f[k] - (0.5 + 0.002 * sp.wl[k])) < 1e-9);
			assert_true(sp.u_noise[k] < 0.01 && fabs(sp.u_angle[k] - 0.003) < 1e-12);
		} else { /* one pixel in the bin: its own value */
			assert_int_equal(sp.npix[k], 1);
			assert_true(fabs(sp.f[k] - (0.5 + 0.002 * sp.wl[k])) <= 0.002 * 0.5 + 1e-12);
			assert_true(fabs(sp.u_noise[k] - 0.01) < 1e-12);
		}
	}
	assert_true(interpolated > sp.n / 2);
	/* a grid beyond the detector is NaN */
	c.grid_min_nm = 300;
	c.grid_max_nm = 320;
	assert_int_equal(calib_resample(&c, wl, &px, &sp, NULL), 0);
	for (int k = 0; k < sp.n; k++)
		assert_true(isnan(sp.f[k]) && isnan(sp.u[k]));
}

static void test_cfg_parse(void **state)
{
	(void)state;
	struct calib_cfg c;
	calib_cfg_defaults(&c);
	struct acq_err err = { 0 };
	const char *ok = "calibration:\n  method: absolute\n  omega_det_sr: 0.002\n"
			 "  reference:\n    table: [[400, 0.98, 0.01], [800, 0.99, 0.005]]\n"
			 "  grid: {min_nm: 500, max_nm: 600, step_nm: 2}\n";
	struct yc_doc *doc = NULL;
	assert_int_equal(yc_load_string("c.yaml", ok, strlen(ok), &doc, &err), 0);
	assert_int_equal(calib_cfg_parse(yc_get(yc_root(doc), "calibration"), &c, &err), 0);
	assert_int_equal(c.method, CALIB_ABSOLUTE);
	assert_int_equal(calib_grid_size(&c), 51);
	double v, u;
	calib_table_eval(&c.rho_ref, 600, &v, &u);
	assert_true(fabs(v - 0.985) < 1e-12 && fabs(u - 0.0075) < 1e-12);
	calib_table_eval(&c.rho_ref, 1000, &v, &u);
	assert_true(v == 0.99);
	yc_free(doc);
	const char *bad = "calibration:\n  method: magic\n";
	assert_int_equal(yc_load_string("d.yaml", bad, strlen(bad), &doc, &err), 0);
	assert_int_equal(calib_cfg_parse(yc_get(yc_root(doc), "calibration"), &c, &err), -1);
	assert_non_null(strstr(err.msg, "d.yaml:2:"));
	yc_free(doc);
	const char *bad2 = "calibration:\n  reference:\n    table: [[800, 0.98, 0.01], [400, 0.99, 0.005]]\n";
	assert_int_equal(yc_load_string("e.yaml", bad2, strlen(bad2), &doc, &err), 0);
	assert_int_equal(calib_cfg_parse(yc_get(yc_root(doc), "calibration"), &c, &err), -1);
	assert_non_null(strstr(err.msg, "increase"));
	yc_free(doc);
}

int main(void)
{
	seed = synth_seed("test_calib");
	for (int p = 0; p < NPIX; p++)
		wl[p] = 440 + 0.33 * p;
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_relative_zscores),
		cmocka_unit_test(test_absolute_zscores),
		cmocka_unit_test(test_angular_term),
		cmocka_unit_test(test_resample),
		cmocka_unit_test(test_bin_centre),
		cmocka_unit_test(test_ref_noise),
		cmocka_unit_test(test_cfg_parse),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
