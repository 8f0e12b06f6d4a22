/* Unit tests of sim/sim_refdrift.c: the white standard's deviation from its certificate (off by default; a
 * smooth process with the configured standard deviation and correlation length, one draw per seed), the
 * source drift (1 at bench time 0, slow, of the configured size), their configuration, and their effect on the
 * simulated spectrometer's signal (sim/sim_physics.c). */
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
#include "sim/sim_refdrift.h"

#define NW 651

static void grid(double *wl)
{
	for (int l = 0; l < NW; l++)
		wl[l] = 450 + l;
}

static void test_off_by_default(void **state)
{
	(void)state;
	struct refdrift_cfg c;
	refdrift_defaults(&c);
	double wl[NW], d[NW];
	grid(wl);
	struct acq_err err = { 0 };
	assert_int_equal(refdrift_reference(&c, NW, wl, d, &err), 0);
	for (int l = 0; l < NW; l++)
		assert_true(d[l] == 0.0);
	assert_true(refdrift_source(&c, 1234.5, 600) == 1.0);
}

/* Over 400 standards (seeds): mean ~ 0 (|mean| < 0.2 u: 4 standard errors), standard deviation within 15 % of u
 * at 600 nm (4 standard errors of a 400-sample standard deviation are 14 %), correlation exp(-1/2) = 0.61 at one
 * correlation length (+-0.12) and ~0 at three (|r| < 0.15); smooth: 1 nm steps below 0.06 u (the process's
 * derivative has standard deviation u / L = 0.01 u per nm). */
static void test_reference_statistics(void **state)
{
	(void)state;
	struct refdrift_cfg c;
	refdrift_defaults(&c);
	c.ref_u = 0.002;
	c.ref_corr_nm = 100;
	double wl[NW], d[NW], s1 = 0, s2 = 0, sab = 0, sb2 = 0, sb = 0, sac = 0, sc = 0, sc2 = 0, step = 0;
	grid(wl);
	struct acq_err err = { 0 };
	const int n = 400;
	for (int k = 0; k < n; k++) {
		c.ref_seed = (uint64_t)k + 1;
		assert_int_equal(refdrift_reference(&c, NW, wl, d, &err), 0);
		double a = d[150], b = d[250], cc = d[450];
		s1 += a, s2 += a * a, sb += b, sb2 += b * b, sab += a * b, sc += cc, sc2 += cc * cc, sac += a * cc;
		for (int l = 1; l < NW; l++)
			step = fmax(step, fabs(d[l] - d[l - 1]));
	}
	double ma = s1 / n, sa = sqrt(s2 / n - ma * ma), mb = sb / n, sbb = sqrt(sb2 / n - mb * mb), mc = sc / n,
	       scc = sqrt(sc2 / n - mc * mc);
	double r1 = (sab / n - ma * mb) / (sa * sbb), r3 = (sac / n - ma * mc) / (sa * scc);
	printf("reference deviation at 600 nm over %d standards: mean %.2g, sd %.4g (u 0.002); corr at 100 nm %.3f, "
	       "at 300 nm %.3f; largest 1 nm step %.2g\n", n, ma, sa, r1, r3, step);
	assert_true(fabs(ma) < 0.2 * c.ref_u);
	assert_true(fabs(sa / c.ref_u - 1) < 0.15);
	assert_true(fabs(r1 - exp(-0.5)) < 0.12);
	assert_true(fabs(r3) < 0.15);
	assert_true(step < 0.06 * c.ref_u);
	/* the same seed draws the same standard, another seed another one */
	double d1[NW], d2[NW];
	c.ref_seed = 7;
	refdrift_reference(&c, NW, wl, d1, &err);
	refdrift_reference(&c, NW, wl, d2, &err);
	assert_memory_equal(d1, d2, sizeof d1);
	c.ref_seed = 8;
	refdrift_reference(&c, NW, wl, d2, &err);
	assert_true(fabs(d1[150] - d2[150]) > 0);
}

/* Drift: exactly 1 at bench time 0; over 100 periods its rms relative change is of the configured amplitude
 * (between 0.7 and 3 times: the oscillating part has rms 1, the offset making h(0) = 0 adds to it); it is slow
 * (over 10 s at a 3600 s period it changes by < 0.19 amplitude: the bound from the construction,
 * sqrt(6) 2 pi 2.9 10 / 3600 (1 + tilt)); the tilt makes blue and NIR differ. */
static void test_drift(void **state)
{
	(void)state;
	struct refdrift_cfg c;
	refdrift_defaults(&c);
	c.drift_amp = 0.005;
	c.drift_seed = 3;
	assert_true(refdrift_source(&c, 0, 450) == 1.0 && refdrift_source(&c, 0, 1100) == 1.0);
	double s2 = 0, dmax = 0, tiltmax = 0;
	int n = 20000;
	for (int k = 0; k < n; k++) {
		double t = 100.0 * 3600 * k / n, f = refdrift_source(&c, t, 775);
		s2 += (f - 1) * (f - 1);
		dmax = fmax(dmax, fabs(refdrift_source(&c, t + 10, 775) - f));
		tiltmax = fmax(tiltmax, fabs(refdrift_source(&c, t, 450) - refdrift_source(&c, t, 1100)));
	}
	double rms = sqrt(s2 / n) / c.drift_amp;
	printf("drift: rms %.3f x amplitude, largest change over 10 s %.3g x amplitude, largest blue-NIR difference "
	       "%.3g\n", rms, dmax / c.drift_amp, tiltmax);
	assert_true(rms > 0.7 && rms < 3);
	assert_true(dmax < 0.19 * c.drift_amp);
	assert_true(tiltmax > 0.2 * c.drift_amp);
}

static int parse(const char *yaml, struct refdrift_cfg *c, struct acq_err *err)
{
	struct yc_doc *doc = NULL;
	assert_int_equal(yc_load_string("t.yaml", yaml, strlen(yaml), &doc, err), 0);
	refdrift_defaults(c);
	int rc = refdrift_parse(yc_get(yc_root(doc), "sim"), c, err);
	yc_free(doc);
	return rc;
}

static void test_config(void **state)
{
	(void)state;
	struct refdrift_cfg c;
	struct acq_err err = { 0 };
	assert_int_equal(parse("sim:\n  reference_standard: {u: 0.002, correlation_nm: 80, seed: 9}\n"
			       "  source_drift: {amplitude: 0.004, tilt: 1, period_s: 1800, seed: 5}\n", &c, &err), 0);
	assert_true(c.ref_u == 0.002 && c.ref_corr_nm == 80 && c.ref_seed == 9 && c.drift_amp == 0.004 &&
		    c.drift_tilt == 1 && c.drift_period_s == 1800 && c.drift_seed == 5);
	assert_int_equal(parse("sim:\n  sample: white\n", &c, &err), 0);
	assert_true(c.ref_u == 0 && c.drift_amp == 0);
	assert_int_equal(parse("sim:\n  reference_standard: {u: 0.5}\n", &c, &err), -1);
	printf("%s\n", err.msg);
	assert_non_null(strstr(err.msg, "u"));
	assert_int_equal(parse("sim:\n  source_drift: {amplitude: 0.01, speed: 2}\n", &c, &err), -1);
	printf("%s\n", err.msg);
	assert_non_null(strstr(err.msg, "speed"));
}

/* The simulated spectrometer: the white standard's signal carries (rho_cert + d) / rho_cert, any signal the
 * drift factor at the bench time set (relative 1e-12). */
static void test_physics(void **state)
{
	(void)state;
	struct phys_cfg pc;
	phys_defaults(&pc);
	struct acq_err err = { 0 };
	struct phys *p0 = phys_new(&pc, &err);
	pc.cal.ref_u = 0.002;
	pc.cal.drift_amp = 0.005;
	struct phys *p1 = phys_new(&pc, &err);
	assert_non_null(p0);
	assert_non_null(p1);
	struct sim_world w = { 0 };
	bench_defaults(&w.geom);
	w.laser_power_pct = 100;
	w.laser_emission = true;
	w.sample = SIM_SAMPLE_WHITE;
	w.laser_theta_deg = 20, w.detector_theta_deg = 40, w.detector_phi_deg = 150;
	static double r0[PHYS_MAX_PIXELS], r1[PHYS_MAX_PIXELS];
	double t = 2000, worst = 0, dev = 0;
	phys_set_time(p1, t);
	phys_signal(p0, &w, r0);
	phys_signal(p1, &w, r1);
	for (int i = PHYS_NDARK; i < pc.npix; i++) {
		double wl = phys_wavelength(&pc, i), want = phys_reference_factor(p1, i) * refdrift_source(&pc.cal, t, wl);
		worst = fmax(worst, fabs(r1[i] / r0[i] / want - 1));
		dev = fmax(dev, fabs(phys_reference_factor(p1, i) - 1));
	}
	printf("white standard: largest |rho_true / rho_cert - 1| %.3g; signal ratio vs model: %.2g\n", dev, worst);
	assert_true(worst < 1e-12 && dev > 1e-4 && dev < 0.02);
	/* a sample carries the drift but not the standard's deviation */
	w.sample = SIM_SAMPLE_GREEN_PAINT;
	phys_signal(p0, &w, r0);
	phys_signal(p1, &w, r1);
	worst = 0;
	for (int i = PHYS_NDARK; i < pc.npix; i++)
		worst = fmax(worst, fabs(r1[i] / r0[i] / refdrift_source(&pc.cal, t, phys_wavelength(&pc, i)) - 1));
	assert_true(worst < 1e-12);
	phys_free(p0);
	phys_free(p1);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_off_by_default), cmocka_unit_test(test_reference_statistics),
		cmocka_unit_test(test_drift), cmocka_unit_test(test_config), cmocka_unit_test(test_physics),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
