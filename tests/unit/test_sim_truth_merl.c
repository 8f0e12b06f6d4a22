/* Unit test of `acq-sim truth MATERIAL --merl` (its library part, truth_write_merl): the table read back with the reference reader matches the
 * spectral ground truth reduced to RGB directly (unfolded: W . f(lambda) from mat_eval) at random cells. */
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
#include "sim/material.h"
#include "sim/sim_truth.h"
#include "sim/sim_rng.h"

static void check_material(const char *name, uint64_t seed)
{
	char dir[64] = "/tmp/acq-test-merl.XXXXXX", path[128];
	assert_non_null(mkdtemp(dir));
	snprintf(path, sizeof path, "%s/t.binary", dir);
	struct merl_table t = { 0 };
	struct acq_err err = { 0 };
	int nwl = 326;
	double wl[326], f[326], *W = malloc(sizeof(double) * 3 * 326);
	for (int l = 0; l < nwl; l++)
		wl[l] = 450 + 2 * l;
	struct mat *m = mat_new(mat_from_name(name), nwl, wl, &err);
	assert_non_null(m);
	struct colour_opts o;
	struct colour_stats st;
	assert_int_equal(truth_write_merl(path, m, wl, nwl, &o, &st, &err), 0);
	assert_int_equal(merl_read(path, &t, &err), 0);
	colour_opts_brdf(&o);
	assert_int_equal(colour_weights(&o, wl, (size_t)nwl, W, &err), 0);
	struct sim_rng r;
	sim_rng_seed(&r, seed);
	double worst = 0;
	int cells = 0;
	while (cells < 3000) {
		int ith = (int)(sim_rng_uniform(&r) * 90), itd = (int)(sim_rng_uniform(&r) * 90),
		    ipd = (int)(sim_rng_uniform(&r) * 180);
		double wi[3], wo[3], lin[3], want[3], got[3];
		if (merl_cell_dirs(ith, itd, ipd, wi, wo) != 1)
			continue;
		mat_eval(m, wi, wo, f);
		colour_apply_weights(W, (size_t)nwl, f, lin);
		colour_finish(&o, lin, want, NULL);
		assert_int_equal(merl_lookup(&t, wi, wo, got), 0);
		for (int k = 0; k < 3; k++) {
			double e = fabs(got[k] - want[k]) / (fabs(want[k]) + 1e-6);
			worst = fmax(worst, e);
		}
		cells++;
	}
	printf("%s: MERL read back vs direct spectral->RGB at %d random cells: worst relative error %.2g\n", name, cells,
	       worst);
	assert_true(worst < 1e-5);
	mat_free(m);
	free(W);
	merl_free(&t);
	unlink(path);
	rmdir(dir);
}

static void test_merl_matches_truth(void **state)
{
	(void)state;
	const char *s = getenv("ACQ_SEED");
	uint64_t seed = s ? strtoull(s, NULL, 10) : 1;
	printf("ACQ_SEED=%llu\n", (unsigned long long)seed);
	check_material("green-paint", seed);
	check_material("metal", seed + 1);
	check_material("clear-coat", seed + 2);
	check_material("cloth-sheen", seed + 3);
	check_material("rough-backscatter", seed + 4);
	check_material("sharp-lobe", seed + 5);
}

/* --grid NIxNOxNP: decimal counts in range, nothing else; a count past INT_MAX is refused, not wrapped (sscanf %d
 * read 4294967297x1x1 as 1x1x1, session 18). */
static void test_grid_size(void **state)
{
	(void)state;
	struct truth_grid g = { 0 };
	struct acq_err e = { 0 };
	assert_int_equal(truth_grid_size("10x9x360", &g, &e), 0);
	assert_int_equal(g.ni, 10);
	assert_int_equal(g.no, 9);
	assert_int_equal(g.np, 360);
	const char *bad[] = { "4294967297x1x1", "1x4294967297x1", "1x1x4294967656", "0x1x1", "91x1x1", "1x1x361",
			      " 1x1x1", "+1x1x1", "-1x1x1", "1x1x1x", "1x1", "1x1x1 ", "1X1X1", "", "x1x1" };
	for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
		e.msg[0] = 0;
		assert_int_equal(truth_grid_size(bad[i], &g, &e), -1);
		assert_non_null(strstr(e.msg, "--grid"));
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_merl_matches_truth),
		cmocka_unit_test(test_grid_size),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
