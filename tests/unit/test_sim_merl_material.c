/* Unit test of the MERL material (sim/material.h, issue 17): a MERL table written from a simulator truth
 * (truth_write_merl) and read back as a material: the spectral basis is a non-negative partition of unity whose
 * RGB is exactly the table's (so the upsampling preserves energy), the material reproduces the table at random
 * directions and the original truth at the cells' centres, is reciprocal, its DHR lies within its channels'
 * albedos and within 0.5 % of the original's, the simulated spectrometer serves it (sim.merl_file), and bad files
 * give clear errors. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "recon/colour.h"
#include "recon/merl.h"
#include "sim/sim_physics.h"
#include "sim/sim_rng.h"
#include "sim/sim_truth.h"

#define NW 651

static char dir[64], path[128];
static double wl[NW];

static uint64_t seed(void)
{
	const char *s = getenv("ACQ_SEED");
	uint64_t v = s ? strtoull(s, NULL, 10) : 1;
	printf("ACQ_SEED=%llu\n", (unsigned long long)v);
	return v;
}

static int setup(void **state)
{
	(void)state;
	snprintf(dir, sizeof dir, "/tmp/acq-test-merlmat.XXXXXX");
	if (!mkdtemp(dir))
		return -1;
	snprintf(path, sizeof path, "%s/paint.binary", dir);
	for (int l = 0; l < NW; l++)
		wl[l] = 450 + l;
	struct acq_err err = { 0 };
	struct mat *m = mat_new(MAT_GREEN_PAINT, NW, wl, &err);
	struct colour_opts o;
	struct colour_stats st;
	int rc = m && !truth_write_merl(path, m, wl, NW, &o, &st, &err) ? 0 : -1;
	mat_free(m);
	return rc;
}

static int teardown(void **state)
{
	(void)state;
	unlink(path);
	rmdir(dir);
	return 0;
}

static void random_dir(struct sim_rng *r, double w[3])
{
	double mu = 0.02 + 0.98 * sim_rng_uniform(r), phi = 2 * M_PI * sim_rng_uniform(r), s = sqrt(1 - mu * mu);
	w[0] = s * cos(phi), w[1] = s * sin(phi), w[2] = mu;
}

static void test_basis_and_round_trip(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct mat *m = mat_new_merl(path, NW, wl, &err);
	assert_non_null(m);
	double b[3][NW], worst = 0, bmin = 1;
	for (int k = 0; k < 3; k++)
		mat_spectrum(m, MAT_S_BASIS_R + k, 0, b[k]);
	for (int l = 0; l < NW; l++) {
		worst = fmax(worst, fabs(b[0][l] + b[1][l] + b[2][l] - 1));
		for (int k = 0; k < 3; k++)
			bmin = fmin(bmin, b[k][l]);
	}
	printf("basis: |sum - 1| <= %.2g, min %.4f\n", worst, bmin);
	assert_true(worst < 1e-6 && bmin >= 0); /* W 1 = (1, 1, 1) to 1e-7 (colour.h), so sum B = 1 to that */
	/* RGB of the upsampled spectrum = the table's RGB, at random directions (relative 1e-9) */
	struct colour_opts o;
	colour_opts_brdf(&o);
	double *W = malloc(sizeof(double) * 3 * NW), f[NW], g[NW];
	assert_int_equal(colour_weights(&o, wl, NW, W, &err), 0);
	struct merl_table t = { 0 };
	assert_int_equal(merl_read(path, &t, &err), 0);
	struct sim_rng r;
	sim_rng_seed(&r, seed());
	double rt = 0, recip = 0;
	for (int n = 0; n < 3000; n++) {
		double wi[3], wo[3], lin[3], tab[3];
		random_dir(&r, wi);
		random_dir(&r, wo);
		mat_eval(m, wi, wo, f);
		mat_eval(m, wo, wi, g);
		colour_apply_weights(W, NW, f, lin);
		if (merl_lookup(&t, wi, wo, tab) != 0)
			tab[0] = tab[1] = tab[2] = 0;
		for (int k = 0; k < 3; k++)
			rt = fmax(rt, fabs(lin[k] - tab[k]) / (fabs(tab[k]) + 1e-12));
		for (int l = 0; l < NW; l += 50)
			recip = fmax(recip, fabs(f[l] - g[l]) / fmax(1e-300, fmax(f[l], g[l])));
	}
	printf("round trip spectrum -> RGB vs the table: worst relative %.2g; reciprocity: worst relative %.2g\n", rt,
	       recip);
	assert_true(rt < 1e-9);
	assert_true(recip < 1e-12);
	/* at the cells' centres: the original truth's RGB (the table's content, 1e-5 as test_sim_truth_merl) */
	struct mat *p = mat_new(MAT_GREEN_PAINT, NW, wl, &err);
	double cw = 0;
	for (int n = 0; n < 2000;) {
		int a = (int)(sim_rng_uniform(&r) * 90), b2 = (int)(sim_rng_uniform(&r) * 90), c = (int)(sim_rng_uniform(&r) * 180);
		double wi[3], wo[3], l1[3], l2[3];
		if (merl_cell_dirs(a, b2, c, wi, wo) != 1)
			continue;
		mat_eval(m, wi, wo, f);
		mat_eval(p, wi, wo, g);
		colour_apply_weights(W, NW, f, l1);
		colour_apply_weights(W, NW, g, l2);
		for (int k = 0; k < 3; k++)
			cw = fmax(cw, fabs(l1[k] - l2[k]) / (fabs(l2[k]) + 1e-6));
		n++;
	}
	printf("at cell centres: RGB vs the original truth's: worst relative %.2g\n", cw);
	assert_true(cw < 1e-5);
	merl_free(&t);
	free(W);
	mat_free(p);
	mat_free(m);
}

/* DHR: between the smallest and largest channel albedo at every wavelength (energy), <= 1, and within 0.5 % of
 * the original truth's DHR projected on the same basis (the table's cells are coarse near the lobe: measured
 * 0.05-0.18 % at 8/30/60 deg). */
static void test_dhr(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	static double w4[4] = { 450, 550, 650, 900 };
	struct mat *m = mat_new_merl(path, 4, w4, &err), *p = mat_new(MAT_GREEN_PAINT, NW, wl, &err);
	assert_non_null(m);
	double *W = malloc(sizeof(double) * 3 * NW);
	struct colour_opts o;
	colour_opts_brdf(&o);
	assert_int_equal(colour_weights(&o, wl, NW, W, &err), 0);
	double b[3][4];
	for (int k = 0; k < 3; k++)
		mat_spectrum(m, MAT_S_BASIS_R + k, 0, b[k]);
	for (int a = 0; a < 3; a++) {
		double th = (a == 0 ? 8 : a == 1 ? 30 : 60) * M_PI / 180, d[4], s[4], dp[NW], sp[NW], rgb[3];
		assert_int_equal(mat_dhr(m, th, 1, d, s, &err), 0);
		assert_int_equal(mat_dhr(p, th, 2, dp, sp, &err), 0);
		colour_apply_weights(W, NW, dp, rgb); /* the original's DHR in RGB = its channel albedos */
		double worst = 0;
		for (int l = 0; l < 4; l++) {
			double want = b[0][l] * rgb[0] + b[1][l] * rgb[1] + b[2][l] * rgb[2];
			worst = fmax(worst, fabs(d[l] - want) / want);
			assert_true(d[l] <= 1 && d[l] >= 0 && s[l] < 0.01 * d[l]);
			assert_true(d[l] <= fmax(rgb[0], fmax(rgb[1], rgb[2])) * 1.02);
		}
		printf("theta_i %.0f: DHR from the table vs the original's projected: worst relative %.3g (bound %.2g)\n",
		       th * 180 / M_PI, worst, s[2] / d[2]);
		assert_true(worst < 0.005);
	}
	free(W);
	mat_free(m);
	mat_free(p);
}

/* The simulated spectrometer serves the table as sample `merl` (sim.merl_file); bad files: clear errors. */
static void test_physics_and_errors(void **state)
{
	(void)state;
	struct phys_cfg pc;
	phys_defaults(&pc);
	snprintf(pc.merl_file, sizeof pc.merl_file, "%s", path);
	struct acq_err err = { 0 };
	struct phys *p = phys_new(&pc, &err);
	assert_non_null(p);
	struct sim_world w = { 0 };
	bench_defaults(&w.geom);
	w.laser_power_pct = 100, w.laser_emission = true;
	w.laser_theta_deg = 30, w.detector_theta_deg = 35, w.detector_phi_deg = 150;
	static double rw[PHYS_MAX_PIXELS], rm[PHYS_MAX_PIXELS], wlp[PHYS_MAX_PIXELS], f[PHYS_MAX_PIXELS],
		fw[PHYS_MAX_PIXELS];
	w.sample = SIM_SAMPLE_WHITE;
	phys_signal(p, &w, rw);
	w.sample = phys_sample_from_name("merl");
	assert_int_equal(w.sample, SIM_SAMPLE_MERL);
	phys_signal(p, &w, rm);
	for (int i = 0; i < pc.npix; i++)
		wlp[i] = phys_wavelength(&pc, i);
	struct mat *m = mat_new_merl(path, pc.npix, wlp, &err), *mw = mat_new(MAT_WHITE, pc.npix, wlp, &err);
	double wi[3], wo[3], worst = 0;
	mat_dir(30 * M_PI / 180, 0, wi);
	mat_dir(35 * M_PI / 180, 150 * M_PI / 180, wo);
	mat_eval(m, wi, wo, f);
	mat_eval(mw, wi, wo, fw);
	for (int i = PHYS_NDARK; i < pc.npix; i++)
		worst = fmax(worst, fabs(rm[i] / rw[i] - f[i] / fw[i]) / (f[i] / fw[i]));
	printf("spectrometer on the MERL sample: signal ratio vs f ratio, worst relative %.2g\n", worst);
	assert_true(worst < 1e-12);
	mat_free(m);
	mat_free(mw);
	phys_free(p);
	/* errors say what and where */
	assert_null(mat_new_merl("/nonexistent/x.binary", 4, wl, &err));
	printf("%s\n", err.msg);
	assert_non_null(strstr(err.msg, "/nonexistent/x.binary"));
	char bad[160];
	snprintf(bad, sizeof bad, "%s/short.binary", dir);
	FILE *fh = fopen(bad, "w");
	fputs("not a merl table", fh);
	fclose(fh);
	assert_null(mat_new_merl(bad, 4, wl, &err));
	printf("%s\n", err.msg);
	unlink(bad);
	assert_null(mat_new(MAT_MERL, 4, wl, &err));
	assert_non_null(strstr(err.msg, "MERL file"));
	snprintf(pc.merl_file, sizeof pc.merl_file, "/nonexistent/y.binary");
	assert_null(phys_new(&pc, &err));
	printf("%s\n", err.msg);
	assert_non_null(strstr(err.msg, "sim.merl_file"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_basis_and_round_trip),
		cmocka_unit_test(test_dhr),
		cmocka_unit_test(test_physics_and_errors),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
