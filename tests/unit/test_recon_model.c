/* Unit tests of recon/rmodel.c: the model file round trip (bit-identical evaluation) and the rejection of
 * truncated, corrupted, hand-edited and foreign files with clear messages. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>
#include <unistd.h>

#include "recon_test_util.h"

static struct recon_model *M, *MG; /* without trend; with the GGX trend */
static char path[64];

/* The samples and the fixed fit options of this file's models (shape and smoothing fixed: quick fits). */
static void fixture(struct recon_samples *s, struct recon_fit_opts *o)
{
	rt_samples(s, 3, 0.02, 1.0);
	recon_fit_opts_default(o);
	o->shape = 1.8;
	o->smoothing = 1e-3;
}

static int setup(void **state)
{
	(void)state;
	struct recon_samples s;
	struct recon_fit_opts o;
	fixture(&s, &o);
	o.source = "unit test";
	o.trend = RECON_TREND_NONE;
	struct acq_err err = { 0 };
	int rc = recon_fit(&s, &o, &M, &err);
	o.trend = RECON_TREND_GGX;
	if (!rc)
		rc = recon_fit(&s, &o, &MG, &err);
	csvio_samples_free(&s);
	snprintf(path, sizeof path, "/tmp/recon_model_%ld.bin", (long)getpid());
	return rc;
}

static int teardown(void **state)
{
	(void)state;
	recon_model_free(M);
	recon_model_free(MG);
	unlink(path);
	return 0;
}

static unsigned char *slurp(const char *p, size_t *len)
{
	char *b;
	struct acq_err err = { 0 };
	if (csvio_slurp(p, &b, len, &err))
		return NULL;
	return (unsigned char *)b;
}

static void test_round_trip(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	assert_int_equal(recon_model_save(M, path, &err), 0);
	struct recon_model *m2;
	assert_int_equal(recon_model_load(path, &m2, &err), 0);
	assert_int_equal(m2->n, M->n);
	assert_int_equal(m2->nwl, M->nwl);
	assert_int_equal(m2->kernel, M->kernel);
	assert_true(m2->shape == M->shape && m2->eta == M->eta);
	assert_string_equal(m2->meta, M->meta);
	assert_non_null(strstr(m2->meta, "source=unit test"));
	const int nq = 300;
	double ang[4 * 300], f1[3 * 300], f2[3 * 300];
	for (int q = 0; q < nq; q++)
		rt_random_pair(ang + 4 * q);
	assert_int_equal(recon_eval(M, nq, ang, f1, &err), 0);
	assert_int_equal(recon_eval(m2, nq, ang, f2, &err), 0);
	assert_memory_equal(f1, f2, sizeof f1);
	recon_model_free(m2);
}

static void expect_reject(const unsigned char *b, size_t len, const char *what)
{
	struct recon_model *m = (struct recon_model *)&m;
	struct acq_err err = { 0 };
	int rc = recon_model_load_mem("bad", b, len, &m, &err);
	if (rc != -1 || !strstr(err.msg, what))
		printf("expected '%s', got rc %d: %s\n", what, rc, err.msg);
	assert_int_equal(rc, -1);
	assert_null(m);
	assert_non_null(strstr(err.msg, what));
}

static uint64_t fnv(const unsigned char *p, size_t n)
{
	uint64_t h = 0xcbf29ce484222325ull;
	for (size_t i = 0; i < n; i++) {
		h ^= p[i];
		h *= 0x100000001b3ull;
	}
	return h;
}

/* Re-seal a patched buffer with a valid checksum, to reach the semantic checks. */
static void reseal(unsigned char *b, size_t len)
{
	uint64_t h = fnv(b, len - 8);
	memcpy(b + len - 8, &h, 8);
}

static void test_rejects_corrupt_files(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	assert_int_equal(recon_model_save(M, path, &err), 0);
	size_t len;
	unsigned char *b = slurp(path, &len), *c = malloc(len);
	assert_non_null(b);
	/* truncations at many lengths */
	size_t cuts[] = { 0, 3, 8, 20, 60, 100, len / 2, len - 9, len - 1 };
	for (size_t i = 0; i < sizeof cuts / sizeof cuts[0]; i++) {
		struct recon_model *m;
		assert_int_equal(recon_model_load_mem("cut", b, cuts[i], &m, &err), -1);
		assert_null(m);
	}
	/* one flipped bit anywhere in the body: checksum */
	for (int i = 0; i < 20; i++) {
		memcpy(c, b, len);
		size_t at = 96 + (size_t)(rt_unif() * (double)(len - 96 - 8));
		c[at] ^= (unsigned char)(1u << (int)(rt_unif() * 8));
		expect_reject(c, len, "checksum");
	}
	/* bad magic, version, kernel, sizes */
	memcpy(c, b, len);
	c[0] = 'X';
	expect_reject(c, len, "bad magic");
	memcpy(c, b, len);
	c[8] = 5; /* version 4: two-lobe trends (session 14's coat basis) */
	expect_reject(c, len, "version 5");
	memcpy(c, b, len);
	c[8] = 3; /* session 7's coat basis: its coefficients mean other terms */
	expect_reject(c, len, "refit the samples");
	memcpy(c, b, len);
	c[12] = 9;
	expect_reject(c, len, "unknown kernel");
	memcpy(c, b, len);
	c[24 + 7] = 0x7f; /* n huge */
	expect_reject(c, len, "sizes out of range");
	/* trailing garbage */
	unsigned char *d = malloc(len + 5);
	memcpy(d, b, len);
	memset(d + len, 0, 5);
	expect_reject(d, len + 5, "size mismatch");
	free(d);
	/* a well-sealed file with a NaN weight, or decreasing wavelengths */
	size_t off_w = 96 + 3 * M->nwl * 8 + 5 * M->n * 8;
	memcpy(c, b, len);
	double nan = NAN;
	memcpy(c + off_w, &nan, 8);
	reseal(c, len);
	expect_reject(c, len, "invalid weights");
	memcpy(c, b, len);
	double big = 1e9;
	memcpy(c + 96, &big, 8);
	reseal(c, len);
	expect_reject(c, len, "invalid wavelengths");
	/* not a file */
	struct recon_model *m;
	assert_int_equal(recon_model_load("/nonexistent/model", &m, &err), -1);
	assert_int_equal(err.code, ACQ_E_NOTFOUND); /* no such file (config/acq_file.h) */
	free(b);
	free(c);
}

/* Evaluations of two models at the same random pairs are bit-identical. */
static void assert_same_model(const struct recon_model *a, const struct recon_model *b)
{
	enum { NQ = 200 };
	double ang[4 * NQ], f1[3 * NQ], f2[3 * NQ];
	struct acq_err err = { 0 };
	assert_int_equal(a->nwl, 3);
	for (int q = 0; q < NQ; q++)
		rt_random_pair(ang + 4 * q);
	assert_int_equal(recon_eval(a, NQ, ang, f1, &err), 0);
	assert_int_equal(recon_eval(b, NQ, ang, f2, &err), 0);
	assert_memory_equal(f1, f2, sizeof f1);
}

/* Offset of the trend block (version 2) in a saved file of model m of length len. */
static size_t trend_block_at(const struct recon_model *m, size_t len)
{
	return len - 8 - strnlen(m->meta, sizeof m->meta) - 4 - (4 + 8 + m->nwl * TREND_NB * 8);
}

static void test_trend_block(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	assert_int_equal(M->trend, RECON_TREND_NONE);
	assert_int_equal(MG->trend, RECON_TREND_GGX);
	/* the GGX model round-trips bit for bit */
	assert_int_equal(recon_model_save(MG, path, &err), 0);
	struct recon_model *m2;
	assert_int_equal(recon_model_load(path, &m2, &err), 0);
	assert_int_equal(m2->trend, RECON_TREND_GGX);
	assert_true(m2->trend_alpha == MG->trend_alpha);
	assert_same_model(MG, m2);
	recon_model_free(m2);
	size_t len;
	unsigned char *b = slurp(path, &len), *c = malloc(len);
	assert_non_null(b);
	size_t at = trend_block_at(MG, len);
	uint32_t v;
	memcpy(&v, b + at, 4);
	assert_int_equal(v, RECON_TREND_GGX);
	/* unknown trend, roughness out of range, a negative coefficient: named */
	memcpy(c, b, len);
	v = 7;
	memcpy(c + at, &v, 4);
	reseal(c, len);
	expect_reject(c, len, "invalid trend");
	memcpy(c, b, len);
	double x = 3.0;
	memcpy(c + at + 4, &x, 8);
	reseal(c, len);
	expect_reject(c, len, "invalid trend roughness");
	memcpy(c, b, len);
	x = -0.5;
	memcpy(c + at + 12 + 8, &x, 8);
	reseal(c, len);
	expect_reject(c, len, "invalid trend coefficients");
	free(b);
	free(c);
	/* a version-1 file (no trend block) is still read, as a model without trend */
	assert_int_equal(recon_model_save(M, path, &err), 0);
	b = slurp(path, &len);
	assert_non_null(b);
	at = trend_block_at(M, len);
	size_t blk = 4 + 8 + M->nwl * TREND_NB * 8, len1 = len - blk;
	unsigned char *d = malloc(len1);
	memcpy(d, b, at);
	memcpy(d + at, b + at + blk, len - at - blk);
	v = 1;
	memcpy(d + 8, &v, 4);
	reseal(d, len1);
	assert_int_equal(recon_model_load_mem("v1", d, len1, &m2, &err), 0);
	assert_int_equal(m2->trend, RECON_TREND_NONE);
	assert_same_model(M, m2);
	recon_model_free(m2);
	/* a model without trend must not carry coefficients */
	memcpy(c = malloc(len), b, len);
	x = 0.25;
	memcpy(c + at + 12, &x, 8);
	reseal(c, len);
	expect_reject(c, len, "invalid trend coefficients");
	free(b);
	free(c);
	free(d);
}

/* Version 4 (session 14; version 3 was session 7's coat basis and is refused): a two-lobe trend (coat) carries its
 * second roughness after the first; the file round-trips bit for bit; a second roughness out of [2α, 1] or not
 * finite, a two-lobe trend in a version-2 layout, a one-lobe trend in a version-4 layout and an unknown version are
 * each rejected with a message naming what is wrong; a one-lobe model is still written as version 2. */
static void test_two_lobe_trend_v4(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct recon_samples s;
	struct recon_fit_opts o;
	fixture(&s, &o);
	o.trend = RECON_TREND_COAT;
	struct recon_model *mc = NULL, *m2 = NULL;
	assert_int_equal(recon_fit(&s, &o, &mc, &err), 0);
	csvio_samples_free(&s);
	assert_int_equal(mc->trend, RECON_TREND_COAT);
	assert_true(mc->trend_alpha2 >= 2 * mc->trend_alpha * 0.999 && mc->trend_alpha2 <= TREND_ALPHA_MAX);
	assert_non_null(strstr(mc->meta, "trend_alpha2="));
	assert_int_equal(recon_model_save(mc, path, &err), 0);
	assert_int_equal(recon_model_load(path, &m2, &err), 0);
	assert_int_equal(m2->trend, RECON_TREND_COAT);
	assert_true(m2->trend_alpha == mc->trend_alpha && m2->trend_alpha2 == mc->trend_alpha2);
	assert_same_model(mc, m2);
	recon_model_free(m2);
	size_t len;
	unsigned char *b = slurp(path, &len), *c = malloc(len + 8);
	assert_non_null(b);
	uint32_t v;
	memcpy(&v, b + 8, 4);
	assert_int_equal(v, 4);
	/* the same bytes labelled version 3: session 7's basis, its coefficients mean other terms */
	memcpy(c, b, len);
	v = 3;
	memcpy(c + 8, &v, 4);
	reseal(c, len);
	expect_reject(c, len, "refit the samples");
	/* the trend block: u32 kind, f64 α, f64 α2, tcoef */
	size_t at = len - 8 - strnlen(mc->meta, sizeof mc->meta) - 4 - (4 + 16 + mc->nwl * TREND_NB * 8);
	memcpy(&v, b + at, 4);
	assert_int_equal(v, RECON_TREND_COAT);
	double x;
	memcpy(&x, b + at + 12, 8);
	assert_true(x == mc->trend_alpha2);
	const double bad[] = { mc->trend_alpha, 1.5 * mc->trend_alpha, 2.0, NAN, -0.3 };
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		memcpy(c, b, len);
		memcpy(c + at + 12, &bad[i], 8);
		reseal(c, len);
		expect_reject(c, len, "invalid trend second roughness");
	}
	/* the same bytes without α2, labelled version 2: a two-lobe trend needs version 4 */
	memcpy(c, b, at + 12);
	memcpy(c + at + 12, b + at + 20, len - at - 20);
	v = 2;
	memcpy(c + 8, &v, 4);
	reseal(c, len - 8);
	expect_reject(c, len - 8, "needs model file version 4");
	/* a one-lobe trend (GGX) in the version-4 layout */
	memcpy(c, b, len);
	v = RECON_TREND_GGX;
	memcpy(c + at, &v, 4);
	reseal(c, len);
	expect_reject(c, len, "for a two-lobe trend only");
	/* a version this program does not know */
	memcpy(c, b, len);
	v = 5;
	memcpy(c + 8, &v, 4);
	reseal(c, len);
	expect_reject(c, len, "this program reads 1 to 4");
	free(b);
	/* a one-lobe model is still written as version 2 */
	assert_int_equal(recon_model_save(MG, path, &err), 0);
	b = slurp(path, &len);
	assert_non_null(b);
	memcpy(&v, b + 8, 4);
	assert_int_equal(v, 2);
	free(b);
	free(c);
	recon_model_free(mc);
}

static void test_save_refuses_nonfinite(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	unlink(path);
	double keep = M->w[5];
	M->w[5] = INFINITY;
	assert_int_equal(recon_model_save(M, path, &err), -1);
	assert_int_equal(err.code, ACQ_E_NUMERIC);
	assert_true(access(path, F_OK) != 0); /* nothing written */
	M->w[5] = keep;
	assert_int_equal(recon_model_save(M, "/nonexistent/dir/m.bin", &err), -1);
	assert_int_equal(err.code, ACQ_E_IO);
}

int main(void)
{
	rt_seed();
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_round_trip),
		cmocka_unit_test(test_rejects_corrupt_files),
		cmocka_unit_test(test_trend_block),
		cmocka_unit_test(test_two_lobe_trend_v4),
		cmocka_unit_test(test_save_refuses_nonfinite),
	};
	return cmocka_run_group_tests_name("recon_model", tests, setup, teardown);
}
