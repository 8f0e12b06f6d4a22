/* Unit tests of sim/sim_physics.c directly: the nonlinearity (and that the identity's coefficients undo it),
 * the statistics of many averages, the blind-zone bits, the direct beam's geometry, the 16-bit ceiling. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "sim/material.h"
#include "sim/sim_physics.h"

struct fix {
	struct phys *p;
	struct sim_world w;
	struct sim_rng r;
	struct phys_frame f;
	double rate[PHYS_MAX_PIXELS];
};

static int setup(void **state)
{
	struct fix *x = calloc(1, sizeof *x);
	struct phys_cfg c;
	phys_defaults(&c);
	struct acq_err err = { 0 };
	x->p = phys_new(&c, &err);
	assert_non_null(x->p);
	bench_defaults(&x->w.geom);
	x->w.sensor_temp_c = 5;
	x->w.laser_power_pct = 100;
	x->w.laser_emission = true;
	x->w.sample = SIM_SAMPLE_WHITE;
	const char *s = getenv("ACQ_SEED");
	uint64_t seed = s ? strtoull(s, NULL, 10) : 1;
	printf("ACQ_SEED=%llu\n", (unsigned long long)seed);
	sim_rng_seed(&x->r, seed);
	*state = x;
	return 0;
}

static int teardown(void **state)
{
	struct fix *x = *state;
	phys_free(x->p);
	free(x);
	return 0;
}

static void pose(struct fix *x, double lt, double dt, double dp)
{
	x->w.laser_theta_deg = lt;
	x->w.detector_theta_deg = dt;
	x->w.detector_phi_deg = dp;
}

/* Raw counts are compressed as x / (1 + b x / 65535); the identity's polynomial P(raw) = sum c_i raw^i undoes
 * it: raw / P(raw) is the linear signal. */
static void test_nonlinearity(void **state)
{
	struct fix *x = *state;
	const struct phys_cfg *c = phys_config(x->p);
	pose(x, 20, 40, 150);
	phys_signal(x->p, &x->w, x->rate);
	int px = 1200;
	double it = 40000.0 / x->rate[px]; /* about 40000 linear counts above bias at pixel px */
	struct acq_err err = { 0 };
	assert_int_equal(phys_measure(x->p, &x->w, it, 50, 1.0, &x->r, &x->f, &err), 0);
	double lin = c->bias_counts + phys_dark_cps(c, 5) * it * 1e-3 + x->rate[px] * it;
	double raw = x->f.counts[px], coef[8];
	phys_nonlin_coef(c, coef);
	double pv = 0;
	for (int i = 7; i >= 0; i--)
		pv = pv * raw + coef[i];
	printf("pixel %d: linear %.0f, raw %.0f (%.2f %% low), corrected %.0f\n", px, lin, raw, 100 * (1 - raw / lin), raw / pv);
	assert_true(raw < lin * 0.98);                       /* visibly nonlinear */
	assert_true(fabs(raw / pv - lin) < 0.002 * lin);     /* undone by the identity's coefficients */
	assert_true(x->f.nsat == 0);
}

/* Above 100 averages the mean and standard deviation come from their distributions: check both. */
static void test_many_averages(void **state)
{
	struct fix *x = *state;
	const struct phys_cfg *c = phys_config(x->p);
	x->w.laser_emission = false;
	struct acq_err err = { 0 };
	for (unsigned avg = 50; avg <= 5000; avg *= 100) {
		assert_int_equal(phys_measure(x->p, &x->w, 1000, avg, 1.0, &x->r, &x->f, &err), 0);
		double e = c->bias_counts + phys_dark_cps(c, 5);
		double sd = sqrt(phys_dark_cps(c, 5) / c->electrons_per_count + c->read_noise_counts * c->read_noise_counts);
		double m = 0, s = 0;
		for (int i = 0; i < x->f.npix; i++) {
			m += x->f.counts[i] / (1.0 - c->nonlinearity * x->f.counts[i] / PHYS_FULL_SCALE);
			s += x->f.std[i];
		}
		m /= x->f.npix;
		s /= x->f.npix;
		printf("%u averages: mean %.3f (expected %.3f), scan sd %.3f (expected ~%.3f after linearisation)\n", avg, m, e,
		       s, sd);
		assert_true(fabs(m - e) < 0.5);
		assert_true(s > 0.9 * sd && s < 1.1 * sd);
	}
	assert_int_equal(phys_measure(x->p, &x->w, 0, 1, 1.0, &x->r, &x->f, &err), -1);
	assert_int_equal(phys_measure(x->p, &x->w, 10, 0, 1.0, &x->r, &x->f, &err), -1);
}

/* Blind zones: both bits inside the detector-body + beam cone; only the laser-arm bit between that and the
 * laser-body + fov cone; none beyond. The direct beam reaches the detector only facing the laser. */
static void test_blind_zones_and_beam(void **state)
{
	struct fix *x = *state;
	pose(x, 30, 33, 0); /* 3 deg: < 5 + 0.5 */
	assert_int_equal(phys_signal(x->p, &x->w, x->rate), PHYS_OCC_DETECTOR_IN_BEAM | PHYS_OCC_LASER_HIDES_VIEW);
	assert_true(x->rate[1000] == 0);
	pose(x, 30, 37, 0); /* 7 deg: < 6 + 1.5 only */
	assert_int_equal(phys_signal(x->p, &x->w, x->rate), PHYS_OCC_LASER_HIDES_VIEW);
	pose(x, 30, 38, 0);
	assert_int_equal(phys_signal(x->p, &x->w, x->rate), 0);
	assert_true(x->rate[1000] > 0);
	for (int i = 0; i < PHYS_NDARK; i++)
		assert_true(x->rate[i] == 0); /* black pixels */
	x->w.sample = SIM_SAMPLE_NONE;
	pose(x, 90, 90, 180);
	phys_signal(x->p, &x->w, x->rate);
	double full = x->rate[1000];
	assert_true(full > 0);
	pose(x, 90, 88.5, 180); /* 1.5 deg off: half the beam (fov 1.5 +- beam 0.5) */
	phys_signal(x->p, &x->w, x->rate);
	assert_true(fabs(x->rate[1000] / full - 0.5) < 1e-6);
	pose(x, 90, 87.9, 180); /* beyond fov + beam */
	phys_signal(x->p, &x->w, x->rate);
	assert_true(x->rate[1000] == 0);
	/* absolute relation of brdf-reconstruction.md: S = f * S_beam * Omega_det * cos(theta_o) */
	x->w.sample = SIM_SAMPLE_WHITE;
	pose(x, 20, 40, 150);
	phys_signal(x->p, &x->w, x->rate);
	double omega = 2 * M_PI * (1 - cos(1.5 * M_PI / 180));
	double f = x->rate[1000] / (full * omega * cos(40 * M_PI / 180));
	printf("white from the absolute relation: f = %.6f, rho/pi = %.6f\n", f,
	       0.99 / M_PI);
	assert_true(f > 0.96 / M_PI && f < 0.995 / M_PI);
}

/* 16-bit ceiling: counts never exceed 65535; saturated pixels are flagged. */
static void test_ceiling(void **state)
{
	struct fix *x = *state;
	x->w.sample = SIM_SAMPLE_METAL;
	pose(x, 30, 30, 180);
	struct acq_err err = { 0 };
	assert_int_equal(phys_measure(x->p, &x->w, 500, 3, 1.0, &x->r, &x->f, &err), 0);
	int n = 0;
	for (int i = 0; i < x->f.npix; i++) {
		assert_true(x->f.counts[i] <= PHYS_FULL_SCALE && x->f.counts[i] >= 0);
		if (x->f.counts[i] >= PHYS_SATURATED)
			assert_true(x->f.sat[i]);
		n += x->f.sat[i];
	}
	assert_int_equal(n, x->f.nsat);
	assert_true(n > 1000);
}

/* Every material can be put on the stage by name (config `sim.sample`, control `sample`), and the signal is
 * K s(l) QE(l) f cos(theta_o) Omega with f from that material's truth (ratio to the white's signal = f / f_white,
 * relative 1e-12). */
static void test_every_sample(void **state)
{
	struct fix *x = *state;
	const struct phys_cfg *c = phys_config(x->p);
	double wl[PHYS_MAX_PIXELS], white[PHYS_MAX_PIXELS], wi[3], wo[3];
	for (int i = 0; i < c->npix; i++)
		wl[i] = phys_wavelength(c, i);
	pose(x, 30, 35, 150);
	mat_dir(30 * M_PI / 180, x->w.geom.laser_phi_deg * M_PI / 180, wi);
	mat_dir(35 * M_PI / 180, 150 * M_PI / 180, wo);
	x->w.sample = SIM_SAMPLE_WHITE;
	phys_signal(x->p, &x->w, white);
	struct acq_err err = { 0 };
	struct mat *mw = mat_new(MAT_WHITE, c->npix, wl, &err);
	double *fw = malloc(sizeof(double) * (size_t)c->npix), *f = malloc(sizeof(double) * (size_t)c->npix);
	mat_eval(mw, wi, wo, fw);
	assert_int_equal(phys_sample_from_name("none"), SIM_SAMPLE_NONE);
	assert_int_equal(phys_sample_from_name("velvet"), -1);
	for (int s = 0; s < SIM_SAMPLE_NONE; s++) {
		assert_int_equal(phys_sample_from_name(phys_sample_name(s)), s);
		if (s == SIM_SAMPLE_MERL) { /* no sim.merl_file: nothing reflects */
			x->w.sample = s;
			phys_signal(x->p, &x->w, x->rate);
			for (int i = 0; i < c->npix; i++)
				assert_true(x->rate[i] == 0.0);
			continue;
		}
		x->w.sample = s;
		phys_signal(x->p, &x->w, x->rate);
		struct mat *m = mat_new((enum mat_id)s, c->npix, wl, &err);
		assert_non_null(m);
		mat_eval(m, wi, wo, f);
		double worst = 0;
		for (int i = PHYS_NDARK; i < c->npix; i++)
			worst = fmax(worst, fabs(x->rate[i] / white[i] - f[i] / fw[i]) / fmax(1e-300, f[i] / fw[i]));
		printf("%s: signal / white signal vs f / f_white: worst relative difference %.2g\n", phys_sample_name(s), worst);
		assert_true(worst < 1e-12);
		mat_free(m);
	}
	mat_free(mw);
	free(fw);
	free(f);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(test_nonlinearity, setup, teardown),
		cmocka_unit_test_setup_teardown(test_many_averages, setup, teardown),
		cmocka_unit_test_setup_teardown(test_blind_zones_and_beam, setup, teardown),
		cmocka_unit_test_setup_teardown(test_ceiling, setup, teardown),
		cmocka_unit_test_setup_teardown(test_every_sample, setup, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
