/* Unit tests for config/yconf.c and config/bench.c: located errors, unknown keys, typed getters. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "config/bench.h"
#include "config/yconf.h"

static struct yc_doc *load(const char *text, struct acq_err *err)
{
	struct yc_doc *doc = NULL;
	int rc = yc_load_string("t.yaml", text, strlen(text), &doc, err);
	return rc == 0 ? doc : NULL;
}

static void test_getters_and_positions(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct yc_doc *doc = load("a: 1.5\nb: 0x58\nc: yes\nname: hello\nmode: rtu\n", &err);
	assert_non_null(doc);
	struct yc_node *root = yc_root(doc);
	double a = 0;
	long long b = 0;
	bool c = false;
	const char *name = NULL;
	int mode = -1;
	static const char *const modes[] = { "tcp", "rtu", NULL };
	assert_int_equal(yc_double(root, "a", true, 0, 10, &a, &err), 0);
	assert_true(a == 1.5);
	assert_int_equal(yc_int(root, "b", true, 0, 65535, &b, &err), 0);
	assert_int_equal(b, 0x58);
	assert_int_equal(yc_bool(root, "c", true, &c, &err), 0);
	assert_true(c);
	assert_int_equal(yc_string(root, "name", true, &name, &err), 0);
	assert_string_equal(name, "hello");
	assert_int_equal(yc_enum(root, "mode", true, modes, &mode, &err), 0);
	assert_int_equal(mode, 1);
	assert_int_equal(yc_check_unknown(root, "root", &err), 0);
	yc_free(doc);
	/* bool, string and enum refuse a value that is not a single one, and leave an absent optional key alone */
	doc = load("c: [1, 2]\nname: {x: 1}\nmode:\n  - tcp\n", &err);
	assert_non_null(doc);
	root = yc_root(doc);
	c = false;
	name = NULL;
	mode = -1;
	assert_int_equal(yc_bool(root, "c", true, &c, &err), -1);
	assert_non_null(strstr(err.msg, "t.yaml:1:4: c: expected a single value"));
	assert_int_equal(yc_string(root, "name", true, &name, &err), -1);
	assert_non_null(strstr(err.msg, "name: expected a single value"));
	assert_int_equal(yc_enum(root, "mode", true, modes, &mode, &err), -1);
	assert_non_null(strstr(err.msg, "mode: expected a single value"));
	assert_true(!c && !name && mode == -1);
	assert_int_equal(yc_bool(root, "absent", false, &c, &err), 0);
	assert_int_equal(yc_string(root, "absent", false, &name, &err), 0);
	assert_int_equal(yc_enum(root, "absent", false, modes, &mode, &err), 0);
	assert_true(!c && !name && mode == -1);
	assert_int_equal(yc_bool(root, "absent", true, &c, &err), -1);
	assert_non_null(strstr(err.msg, "missing required key 'absent'"));
	yc_free(doc);
}

static void test_errors_name_line_and_column(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct yc_doc *doc = load("a: 1\nspeed: fast\n", &err);
	assert_non_null(doc);
	double v;
	assert_int_equal(yc_double(yc_root(doc), "speed", true, 0, 10, &v, &err), -1);
	assert_int_equal(err.code, ACQ_E_CONFIG);
	assert_non_null(strstr(err.msg, "t.yaml:2:8"));
	assert_non_null(strstr(err.msg, "finite number"));
	/* out of range */
	assert_int_equal(yc_double(yc_root(doc), "a", true, 2, 10, &v, &err), -1);
	assert_non_null(strstr(err.msg, "t.yaml:1:4"));
	/* missing required */
	assert_int_equal(yc_double(yc_root(doc), "zzz", true, 0, 1, &v, &err), -1);
	assert_non_null(strstr(err.msg, "missing required key 'zzz'"));
	yc_free(doc);
}

static void test_unknown_key_lists_expected(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct yc_doc *doc = load("alpha: 1\nbetta: 2\n", &err);
	double v;
	assert_int_equal(yc_double(yc_root(doc), "alpha", false, 0, 9, &v, &err), 0);
	assert_int_equal(yc_double(yc_root(doc), "beta", false, 0, 9, &v, &err), 0);
	assert_int_equal(yc_check_unknown(yc_root(doc), "section", &err), -1);
	assert_non_null(strstr(err.msg, "t.yaml:2:1: unknown key 'betta'"));
	assert_non_null(strstr(err.msg, "alpha, beta"));
	yc_free(doc);
}

static void test_syntax_duplicates_aliases(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	assert_null(load("a: [1, 2\n", &err));
	assert_non_null(strstr(err.msg, "YAML syntax error"));
	assert_null(load("a: 1\na: 2\n", &err));
	assert_non_null(strstr(err.msg, "duplicate key 'a'"));
	assert_null(load("a: &x 1\nb: *x\n", &err));
	assert_non_null(strstr(err.msg, "aliases"));
	assert_null(load("--- 1\n--- 2\n", &err));
	assert_non_null(strstr(err.msg, "one YAML document"));
	struct yc_doc *doc = load("", &err);
	assert_non_null(doc);
	assert_null(yc_root(doc));
	yc_free(doc);
}

/* A file with a NUL byte (a damaged file, binary junk) or bytes that are not UTF-8 is refused where the byte is,
 * not read up to the NUL (the rest silently lost) or reported at 1:1; a control character is located too. */
static void test_not_text_located(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct yc_doc *doc = NULL;
	static const char nul[] = "a: 1\nb: 2\0\0\0c: [\n";
	assert_int_equal(yc_load_string("t.yaml", nul, sizeof nul - 1, &doc, &err), -1);
	assert_null(doc);
	assert_string_equal(err.msg, "t.yaml:2:5: a NUL byte: not a text file (binary, or damaged)");
	static const char latin1[] = "# \xe9" "chantillon\na: 1\n";
	assert_int_equal(yc_load_string("t.yaml", latin1, sizeof latin1 - 1, &doc, &err), -1);
	assert_string_equal(err.msg, "t.yaml:1:3: byte 0xe9 is not UTF-8: save the file as UTF-8");
	static const char utf16[] = "\xff\xfe" "a\0:\0";
	assert_int_equal(yc_load_string("t.yaml", utf16, sizeof utf16 - 1, &doc, &err), -1);
	assert_string_equal(err.msg, "t.yaml: UTF-16 text: save the file as UTF-8");
	static const char overlong[] = "a: \xc0\xaf\n", surrogate[] = "a: \xed\xa0\x80\n", cut[] = "a: \xc3";
	assert_int_equal(yc_load_string("t.yaml", overlong, sizeof overlong - 1, &doc, &err), -1);
	assert_string_equal(err.msg, "t.yaml:1:4: byte 0xc0 is not UTF-8: save the file as UTF-8");
	assert_int_equal(yc_load_string("t.yaml", surrogate, sizeof surrogate - 1, &doc, &err), -1);
	assert_int_equal(yc_load_string("t.yaml", cut, sizeof cut - 1, &doc, &err), -1);
	/* columns count characters: "é" is one */
	static const char ctl[] = "n: \xc3\xa9t\xc3\xa9\nb: x\x01" "y\n";
	assert_int_equal(yc_load_string("t.yaml", ctl, sizeof ctl - 1, &doc, &err), -1);
	assert_string_equal(err.msg, "t.yaml:2:5: control characters are not allowed");
	/* UTF-8 text (a BOM, accents, 4-byte characters) is fine */
	static const char ok[] = "\xef\xbb\xbf" "name: \xc3\xa9t\xc3\xa9 \xf0\x9f\x99\x82\n";
	assert_int_equal(yc_load_string("t.yaml", ok, sizeof ok - 1, &doc, &err), 0);
	const char *name = NULL;
	assert_int_equal(yc_string(yc_root(doc), "name", true, &name, &err), 0);
	assert_string_equal(name, "\xc3\xa9t\xc3\xa9 \xf0\x9f\x99\x82");
	yc_free(doc);
}

static void test_bench_parse(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	struct bench_geom g;
	bench_defaults(&g);
	struct yc_doc *doc = load("laser_radius_mm: 500\nlaser.theta: {speed_dps: 4, accel_dps2: 8}\n", &err);
	assert_int_equal(bench_parse(yc_root(doc), &g, &err), 0);
	assert_true(g.laser_radius_mm == 500 && g.laser_theta.speed_dps == 4 && g.laser_theta.accel_dps2 == 8);
	assert_string_equal(g.deprecated, "");
	yc_free(doc);
	/* the old key names still work, and are listed for the caller's warning */
	doc = load("laser_theta: {speed_dps: 5}\ndetector_phi: {speed_dps: 6}\ndetector.theta: {speed_dps: 7}\n", &err);
	assert_int_equal(bench_parse(yc_root(doc), &g, &err), 0);
	assert_true(g.laser_theta.speed_dps == 5 && g.detector_phi.speed_dps == 6 && g.detector_theta.speed_dps == 7);
	assert_string_equal(g.deprecated, "bench.laser_theta is now bench.laser.theta; bench.detector_phi is now "
					  "bench.detector.phi");
	yc_free(doc);
	doc = load("laser_theta: {speed_dps: 5}\nlaser.theta: {speed_dps: 6}\n", &err);
	assert_int_equal(bench_parse(yc_root(doc), &g, &err), -1);
	assert_non_null(strstr(err.msg, "both given"));
	yc_free(doc);
	doc = load("laser.theta: {min_deg: 10, max_deg: 5}\n", &err);
	assert_int_equal(bench_parse(yc_root(doc), &g, &err), -1);
	assert_non_null(strstr(err.msg, "min_deg"));
	yc_free(doc);
	doc = load("detector.phi: {sped_dps: 4}\n", &err);
	assert_int_equal(bench_parse(yc_root(doc), &g, &err), -1);
	assert_non_null(strstr(err.msg, "unknown key 'sped_dps'"));
	yc_free(doc);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_getters_and_positions),
		cmocka_unit_test(test_errors_name_line_and_column),
		cmocka_unit_test(test_unknown_key_lists_expected),
		cmocka_unit_test(test_syntax_duplicates_aliases),
		cmocka_unit_test(test_bench_parse),
		cmocka_unit_test(test_not_text_located),
	};
	return cmocka_run_group_tests_name("yconf", tests, NULL, NULL);
}
