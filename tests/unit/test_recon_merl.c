/* Unit tests for recon/merl.c: exact format, cell convention ↔ reference index, round trip, errors. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cmocka.h>

#include "recon/merl.h"

static unsigned seed;
static char dir[512];

static double urand(void)
{
	seed = seed * 1103515245u + 12345u;
	return ((seed >> 8) & 0xffffff) / (double)0x1000000;
}

static void path_of(char *buf, size_t len, const char *name)
{
	snprintf(buf, len, "%s/%s", dir, name);
}

/* Analytic reciprocal, isotropic RGB BRDF: Lambert + Schlick-Fresnel Blinn-Phong lobe + a cosθi·cosθo term
 * (so that the value depends on θh, θd and φd). */
struct analytic {
	double kd[3], ks[3], q[3], n;
	int calls_to_fail; /* > 0: fail (return -1) on that call; < 0: return NaN on call -calls_to_fail */
	int calls;
};

static void analytic_eval(const struct analytic *a, const double wi[3], const double wo[3], double rgb[3])
{
	double h[3] = { wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2] };
	double l = sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
	double hz = h[2] / l, ih = (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) / l;
	double fr = 0.04 + 0.96 * pow(1 - ih, 5);
	double lobe = (a->n + 2) / (8 * M_PI) * pow(hz, a->n) * fr;
	for (int c = 0; c < 3; c++)
		rgb[c] = a->kd[c] / M_PI + a->ks[c] * lobe + a->q[c] * wi[2] * wo[2];
}

static int analytic_cb(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	struct analytic *a = ctx;
	a->calls++;
	if (a->calls_to_fail > 0 && a->calls == a->calls_to_fail)
		return -1;
	analytic_eval(a, wi, wo, rgb);
	if (a->calls_to_fail < 0 && a->calls == -a->calls_to_fail)
		rgb[1] = NAN;
	return 0;
}

static const struct analytic base = {
	.kd = { 0.20, 0.50, 0.10 }, .ks = { 0.6, 0.5, 0.4 }, .q = { 0.05, 0.02, 0.0 }, .n = 20,
};

/* Thread-safe (no counters): used with 2 threads. */
static int analytic_pure(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	analytic_eval(ctx, wi, wo, rgb);
	return 0;
}

/* f at angles (θh, θd, φd) with φh = 0. */
static void f_angles(double th, double td, double pd, double rgb[3])
{
	double wi[3], wo[3];
	merl_dirs_from_angles(th, td, pd, wi, wo);
	analytic_eval(&base, wi, wo, rgb);
}

static void random_dir(double w[3])
{
	double z = 0.02 + 0.98 * urand(), p = 2 * M_PI * urand(), r = sqrt(1 - z * z);
	w[0] = r * cos(p);
	w[1] = r * sin(p);
	w[2] = z;
}

/* Every cell centre maps back to its own cell under the reference index functions. */
static void test_cell_convention_matches_reference_index(void **state)
{
	(void)state;
	long with_data = 0, mismatches = 0;
	for (int a = 0; a < MERL_N_THETA_H; a++)
		for (int b = 0; b < MERL_N_THETA_D; b++)
			for (int c = 0; c < MERL_N_PHI_D; c++) {
				double wi[3], wo[3], th, ph, td, pd;
				int ok = merl_cell_dirs(a, b, c, wi, wo);
				if (ok != 1)
					continue;
				with_data++;
				merl_half_diff(wi, wo, &th, &ph, &td, &pd);
				int i0, i1, i2;
				int flat = merl_index(th, td, pd, &i0, &i1, &i2);
				mismatches += i0 != a || i1 != b || i2 != c || flat != c + 180 * b + 180 * 90 * a;
				/* swapping wi and wo lands in the same cell (φd and φd + π fold together) */
				merl_half_diff(wo, wi, &th, &ph, &td, &pd);
				mismatches += merl_index(th, td, pd, NULL, NULL, NULL) != flat;
			}
	printf("cells with data: %ld of %d\n", with_data, MERL_N_CELLS);
	assert_int_equal(mismatches, 0);
	assert_true(with_data > MERL_N_CELLS / 2 && with_data < MERL_N_CELLS);
	assert_int_equal(merl_cell_dirs(90, 0, 0, (double[3]){ 0 }, (double[3]){ 0 }), -1);
	/* the documented centres: θh = ((i+0.5)/90)²·π/2, θd = (i+0.5)·π/180, φd = (i+0.5)·π/180 */
	double th, td, pd;
	merl_cell_angles(9, 44, 179, &th, &td, &pd);
	assert_true(fabs(th - (9.5 / 90) * (9.5 / 90) * M_PI / 2) < 1e-15);
	assert_true(fabs(td - 44.5 * M_PI / 180) < 1e-15);
	assert_true(fabs(pd - 179.5 * M_PI / 180) < 1e-15);
	/* reference details: θh ≤ 0 → 0, negative φd folded by +π, clamping at the top */
	int i0, i1, i2;
	merl_index(0, 0, -0.5 * M_PI / 180, &i0, &i1, &i2);
	assert_int_equal(i0, 0);
	assert_int_equal(i2, 179);
	merl_index(M_PI, M_PI, 2 * M_PI, &i0, &i1, &i2);
	assert_int_equal(i0, 89);
	assert_int_equal(i1, 89);
	assert_int_equal(i2, 179);
	merl_index(NAN, NAN, NAN, &i0, &i1, &i2);
	assert_int_equal(i0 + i1 + i2, 0);
}

static void test_write_read_roundtrip(void **state)
{
	(void)state;
	char p[600];
	path_of(p, sizeof(p), "analytic.binary");
	struct analytic a = base;
	struct acq_err err = { 0 };
	assert_int_equal(merl_write(p, analytic_cb, &a, &err), 0);
	/* only cells with data were evaluated */
	long with_data = 0;
	for (int i = 0; i < MERL_N_CELLS; i++) {
		double wi[3], wo[3];
		with_data += merl_cell_dirs(i / (180 * 90), (i / 180) % 90, i % 180, wi, wo) == 1;
	}
	assert_int_equal(a.calls, with_data);

	/* exact size and header */
	struct stat sb;
	assert_int_equal(stat(p, &sb), 0);
	assert_int_equal((long long)sb.st_size, 34992012LL);
	FILE *f = fopen(p, "rb");
	assert_non_null(f);
	unsigned char hdr[12];
	assert_int_equal(fread(hdr, 1, 12, f), 12);
	fclose(f);
	static const unsigned char want[12] = { 90, 0, 0, 0, 90, 0, 0, 0, 180, 0, 0, 0 };
	assert_memory_equal(hdr, want, 12);

	struct merl_table t;
	assert_int_equal(merl_read(p, &t, &err), 0);
	/* The stored values are f at the cell centre divided by the scales; no-data cells are negative. */
	long nodata = 0;
	for (int i = 0; i < MERL_N_CELLS; i++)
		nodata += t.data[i] < 0 && t.data[MERL_N_CELLS + i] < 0 && t.data[2 * MERL_N_CELLS + i] < 0;
	assert_int_equal(nodata, MERL_N_CELLS - with_data);

	/* Random directions, both orderings: (1) the lookup is exactly f at the centre of the cell it names;
	 * (2) it is within a first-order bound of f at the direction itself: Σ |∂f/∂x| · |x_centre − x| over
	 * x ∈ {θh, θd, φd} (finite differences), times 1.5 for curvature, + 1e-9. Cells are at most
	 * π/180 wide in θd and φd and ≤ 2·89.5/90²·π/2 ≈ 0.035 rad in θh. */
	double max_rel = 0, sum_rel = 0;
	int n = 4000, checked = 0;
	for (int s = 0; s < n; s++) {
		double wi[3], wo[3], got[3], got2[3], ref[3], ctr[3];
		random_dir(wi);
		random_dir(wo);
		int rc = merl_lookup(&t, wi, wo, got);
		int rc2 = merl_lookup(&t, wo, wi, got2);
		assert_int_equal(rc, rc2);
		for (int c = 0; c < 3; c++)
			assert_true(got[c] == got2[c]);
		double th, ph, td, pd;
		merl_half_diff(wi, wo, &th, &ph, &td, &pd);
		if (pd < 0)
			pd += M_PI;
		int i0, i1, i2;
		merl_index(th, td, pd, &i0, &i1, &i2);
		double cth, ctd, cpd;
		merl_cell_angles(i0, i1, i2, &cth, &ctd, &cpd);
		if (rc == 1) { /* the random pair is valid but its cell centre is below the horizon */
			double x[3], y[3];
			assert_int_equal(merl_dirs_from_angles(cth, ctd, cpd, x, y), 0);
			continue;
		}
		assert_int_equal(rc, 0);
		/* the centre and the direction share the cell: at most half a cell apart in θd and φd */
		assert_true(fabs(ctd - td) <= M_PI / 360 + 1e-12);
		assert_true(fabs(cpd - pd) <= M_PI / 360 + 1e-12);
		double lo = (i0 / 90.0) * (i0 / 90.0) * M_PI / 2, hi = ((i0 + 1) / 90.0) * ((i0 + 1) / 90.0) * M_PI / 2;
		assert_true(cth > lo && cth < hi && th >= lo - 1e-12 && th <= hi + 1e-12);
		f_angles(cth, ctd, cpd, ctr);
		analytic_eval(&base, wi, wo, ref);
		double x[3] = { th, td, pd }, cx[3] = { cth, ctd, cpd };
		for (int c = 0; c < 3; c++) {
			assert_true(fabs(got[c] - ctr[c]) <= 1e-12 * fabs(ctr[c]));
			/* mean value theorem along the segment x → centre in angle space: |f(c) − f(x)| ≤
			 * max_t Σ_k |∂_k f(x + t(c − x))|·|c_k − x_k|, t sampled at 0, ¼, ½, ¾, 1 */
			double bound = 0;
			for (int ti = 0; ti <= 4; ti++) {
				double tt = ti / 4.0, m[3], sum = 0;
				for (int k = 0; k < 3; k++)
					m[k] = x[k] + tt * (cx[k] - x[k]);
				for (int k = 0; k < 3; k++) {
					double e = 1e-6, xp[3] = { m[0], m[1], m[2] }, xm[3] = { m[0], m[1], m[2] }, fp[3], fm[3];
					xp[k] += e;
					xm[k] -= e;
					f_angles(xp[0], xp[1], xp[2], fp);
					f_angles(xm[0], xm[1], xm[2], fm);
					sum += fabs(fp[c] - fm[c]) / (2 * e) * fabs(cx[k] - x[k]);
				}
				bound = fmax(bound, sum);
			}
			bound = bound * 1.5 + 1e-9;
			if (!(fabs(got[c] - ref[c]) <= bound))
				fail_msg("seed %u sample %d ch %d: lookup %.6g direct %.6g bound %.3g", seed, s, c, got[c],
					 ref[c], bound);
			double rel = fabs(got[c] - ref[c]) / ref[c];
			max_rel = fmax(max_rel, rel);
			sum_rel += rel;
		}
		checked++;
	}
	printf("round trip: %d samples checked, relative error mean %.4f max %.4f\n", checked,
	       sum_rel / (3.0 * checked), max_rel);
	assert_true(checked > n * 9 / 10);
	assert_true(sum_rel / (3.0 * checked) < 0.02);

	/* invalid directions are refused, not looked up */
	double up[3] = { 0, 0, 1 }, down[3] = { 0, 0.5, -0.5 }, nan3[3] = { NAN, 0, 1 }, rgb[3];
	assert_int_equal(merl_lookup(&t, up, down, rgb), -1);
	assert_int_equal(merl_lookup(&t, nan3, up, rgb), -1);
	assert_int_equal(merl_lookup(NULL, up, up, rgb), -1);
	merl_free(&t);

	/* Two threads (pure callback) write the same bytes. */
	char p2[600];
	path_of(p2, sizeof(p2), "analytic2.binary");
	struct merl_write_opts o;
	merl_write_opts_default(&o);
	o.threads = 2;
	struct analytic b = base;
	assert_int_equal(merl_write_ex(p2, analytic_pure, &b, &o, &err), 0);
	FILE *f1 = fopen(p, "rb"), *f2 = fopen(p2, "rb");
	assert_true(f1 && f2);
	static unsigned char b1[1 << 16], b2[1 << 16];
	size_t n1, n2;
	long long diff = 0;
	while ((n1 = fread(b1, 1, sizeof(b1), f1)) > 0) {
		n2 = fread(b2, 1, sizeof(b2), f2);
		assert_int_equal(n1, n2);
		diff += memcmp(b1, b2, n1) != 0;
	}
	fclose(f1);
	fclose(f2);
	assert_int_equal(diff, 0);
	unlink(p);
	unlink(p2);
}

static int count_entries(void)
{
	char cmd[700];
	snprintf(cmd, sizeof(cmd), "ls -A '%s' | wc -l", dir);
	FILE *f = popen(cmd, "r");
	int n = -1;
	if (f) {
		if (fscanf(f, "%d", &n) != 1)
			n = -1;
		pclose(f);
	}
	return n;
}

static int negative_cb(void *ctx, const double wi[3], const double wo[3], double rgb[3])
{
	(void)ctx;
	(void)wo;
	rgb[0] = -0.5;
	rgb[1] = wi[2] - 0.5; /* negative for θi > 60° */
	rgb[2] = 1e-3;
	return 0;
}

/* Negative callback values are written as clamp_min (0), never as negatives ("no data"). */
static void test_negative_values_are_clamped(void **state)
{
	(void)state;
	char p[600];
	snprintf(p, sizeof(p), "%s/neg.binary", dir);
	struct acq_err err = { 0 };
	assert_int_equal(merl_write(p, negative_cb, NULL, &err), 0);
	struct merl_table t;
	assert_int_equal(merl_read(p, &t, &err), 0);
	long bad = 0;
	for (int i = 0; i < MERL_N_CELLS; i++) {
		double wi[3], wo[3];
		int has = merl_cell_dirs(i / (180 * 90), (i / 180) % 90, i % 180, wi, wo) == 1;
		double r = t.data[i], g = t.data[MERL_N_CELLS + i], b = t.data[2 * MERL_N_CELLS + i];
		if (has)
			bad += !(r == 0 && g == fmax(0, wi[2] - 0.5) / merl_scale[1] && fabs(b * merl_scale[2] - 1e-3) < 1e-15);
		else
			bad += !(r == MERL_NO_DATA && g == MERL_NO_DATA && b == MERL_NO_DATA);
	}
	assert_int_equal(bad, 0);
	merl_free(&t);
	unlink(p);
}

static void test_callback_errors_propagate(void **state)
{
	(void)state;
	char p[600];
	path_of(p, sizeof(p), "fail.binary");
	struct acq_err err = { 0 };
	struct analytic a = base;
	a.calls_to_fail = 1 + (int)(urand() * 500000);
	assert_int_equal(merl_write(p, analytic_cb, &a, &err), -1);
	assert_int_equal(err.code, ACQ_E_NUMERIC);
	assert_non_null(strstr(err.msg, "callback failed"));
	assert_int_equal(a.calls, a.calls_to_fail); /* stopped at once */
	assert_int_equal(access(p, F_OK), -1);     /* nothing written, no temp file left */
	assert_int_equal(count_entries(), 0);

	struct analytic b = base;
	b.calls_to_fail = -(1 + (int)(urand() * 500000));
	assert_int_equal(merl_write(p, analytic_cb, &b, &err), -1);
	assert_int_equal(err.code, ACQ_E_NUMERIC);
	assert_non_null(strstr(err.msg, "non-finite"));
	assert_int_equal(access(p, F_OK), -1);
	assert_int_equal(count_entries(), 0);

	/* bad arguments, unwritable folder */
	assert_int_equal(merl_write(NULL, analytic_cb, &b, &err), -1);
	assert_int_equal(merl_write(p, NULL, &b, &err), -1);
	struct merl_write_opts o;
	merl_write_opts_default(&o);
	o.threads = 0;
	assert_int_equal(merl_write_ex(p, analytic_pure, &b, &o, &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
	o.threads = 1;
	o.clamp_min = -1; /* would let negative values pass for "no data" */
	assert_int_equal(merl_write_ex(p, analytic_pure, &b, &o, &err), -1);
	assert_int_equal(err.code, ACQ_E_INVAL);
	struct analytic c = base;
	assert_int_equal(merl_write("/nonexistent-dir/x.binary", analytic_cb, &c, &err), -1);
	assert_int_equal(err.code, ACQ_E_IO);
}

static void write_bytes(const char *p, const void *buf, size_t len)
{
	FILE *f = fopen(p, "wb");
	assert_non_null(f);
	assert_int_equal(fwrite(buf, 1, len, f), len);
	fclose(f);
}

static void test_read_rejects_bad_files(void **state)
{
	(void)state;
	char p[600];
	path_of(p, sizeof(p), "bad.binary");
	struct merl_table t;
	struct acq_err err = { 0 };
	assert_int_equal(merl_read(p, &t, &err), -1);
	assert_int_equal(err.code, ACQ_E_NOTFOUND);
	write_bytes(p, "\x5a\0\0", 3);
	assert_int_equal(merl_read(p, &t, &err), -1);
	assert_int_equal(err.code, ACQ_E_PROTO);
	assert_non_null(strstr(err.msg, "too short"));
	int32_t hdr[3] = { 90, 90, 360 }; /* the (wrong) full φd range */
	write_bytes(p, hdr, sizeof(hdr));
	assert_int_equal(merl_read(p, &t, &err), -1);
	assert_non_null(strstr(err.msg, "header"));
	hdr[2] = 180; /* right header, truncated body */
	write_bytes(p, hdr, sizeof(hdr));
	assert_int_equal(merl_read(p, &t, &err), -1);
	assert_non_null(strstr(err.msg, "size"));
	assert_null(t.data);
	/* right size, one NaN in the body (random position), then one byte too many */
	size_t len = (size_t)MERL_FILE_SIZE;
	unsigned char *buf = calloc(1, len + 1);
	assert_non_null(buf);
	memcpy(buf, hdr, sizeof(hdr));
	size_t at = (size_t)(urand() * 3 * MERL_N_CELLS);
	double nan = NAN;
	memcpy(buf + 12 + 8 * at, &nan, 8);
	write_bytes(p, buf, len);
	assert_int_equal(merl_read(p, &t, &err), -1);
	assert_int_equal(err.code, ACQ_E_PROTO);
	assert_non_null(strstr(err.msg, "non-finite"));
	assert_null(t.data);
	memset(buf + 12 + 8 * at, 0, 8);
	write_bytes(p, buf, len);
	assert_int_equal(merl_read(p, &t, &err), 0); /* all zeros: a valid (black) table */
	merl_free(&t);
	write_bytes(p, buf, len + 1);
	assert_int_equal(merl_read(p, &t, &err), -1);
	assert_non_null(strstr(err.msg, "size"));
	free(buf);
	unlink(p);
}

int main(void)
{
	const char *s = getenv("ACQ_SEED");
	seed = s ? (unsigned)strtoul(s, NULL, 10) : 1u;
	printf("test_recon_merl: ACQ_SEED=%u\n", seed);
	const char *tmp = getenv("TMPDIR");
	snprintf(dir, sizeof(dir), "%s/test_recon_merl.XXXXXX", tmp && *tmp ? tmp : "/tmp");
	if (!mkdtemp(dir)) {
		perror("mkdtemp");
		return 1;
	}
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_cell_convention_matches_reference_index),
		cmocka_unit_test(test_write_read_roundtrip),
		cmocka_unit_test(test_negative_values_are_clamped),
		cmocka_unit_test(test_callback_errors_propagate),
		cmocka_unit_test(test_read_rejects_bad_files),
	};
	int rc = cmocka_run_group_tests(tests, NULL, NULL);
	rmdir(dir);
	return rc;
}
