/* Unit tests for daemon/conf_diff.c (what a reload reports): changed scalars by dotted path, a section removed or
 * added as one line with its size, keys in another order not a change, sequences item by item or by length, a
 * mapping that became a scalar, and the cap on listed lines (the rest counted). */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "daemon/conf_diff.h"

/* The lines conf_diff gives for texts a and b (listed up to max), joined by '\n', into buf; the count in *n. */
static const char *diff(const char *a, const char *b, int max, int *n)
{
	static char buf[4096];
	struct yc_doc *da = NULL, *db = NULL;
	struct acq_err err = { 0 };
	if (yc_load_string("a.yaml", a, strlen(a), &da, &err) || yc_load_string("b.yaml", b, strlen(b), &db, &err))
		fail_msg("%s", err.msg);
	json_t *lines = json_array();
	*n = conf_diff(yc_root(da), yc_root(db), max, lines);
	buf[0] = '\0';
	for (size_t i = 0; i < json_array_size(lines); i++)
		snprintf(buf + strlen(buf), sizeof buf - strlen(buf), "%s%s", i ? "\n" : "",
			 json_string_value(json_array_get(lines, i)));
	assert_true((int)json_array_size(lines) == (*n < max ? *n : max));
	json_decref(lines);
	yc_free(da);
	yc_free(db);
	return buf;
}

static void test_changes(void **state)
{
	(void)state;
	int n;
	static const char base[] =
		"bench: {readout_s: 0.01}\n"
		"devices:\n"
		"  laser_arm: {link: {type: tcp, host: 127.0.0.1, port: 5020}, response_timeout_ms: 500}\n"
		"  laser: {device: /dev/ttyUSB0, timeout_ms: 500}\n"
		"sweep: {averages: 4}\n";
	assert_string_equal(diff(base, base, 40, &n), "");
	assert_int_equal(n, 0);
	/* the same settings, keys in another order and another style */
	assert_string_equal(diff(base,
				 "sweep:\n  averages: 4\ndevices:\n  laser: {timeout_ms: 500, device: /dev/ttyUSB0}\n"
				 "  laser_arm:\n    response_timeout_ms: 500\n    link: {port: 5020, host: 127.0.0.1, type: tcp}\n"
				 "bench: {readout_s: 0.01}\n", 40, &n), "");
	/* an address and a port changed; a setting added, one removed */
	assert_string_equal(diff(base,
				 "bench: {readout_s: 0.01}\n"
				 "devices:\n"
				 "  laser_arm: {link: {type: tcp, host: 10.0.0.2, port: 5021}}\n"
				 "  laser: {device: /dev/ttyUSB0, timeout_ms: 500, keepalive_ms: 0}\n"
				 "sweep: {averages: 4}\n", 40, &n),
			    "devices.laser_arm.link.host: 127.0.0.1 → 10.0.0.2\n"
			    "devices.laser_arm.link.port: 5020 → 5021\n"
			    "devices.laser_arm.response_timeout_ms: removed (was 500)\n"
			    "devices.laser.keepalive_ms: added (0)");
	assert_int_equal(n, 4);
	/* every device section dropped (`bench: {}` and nothing else): one line per top-level section */
	assert_string_equal(diff(base, "bench: {}\n", 40, &n),
			    "bench.readout_s: removed (was 0.01)\n"
			    "devices: removed (was 6 settings)\n"
			    "sweep: removed (was 1 setting)");
	assert_string_equal(diff("bench: {}\n", base, 40, &n),
			    "bench.readout_s: added (0.01)\ndevices: added (6 settings)\nsweep: added (1 setting)");
	/* a mapping that became a scalar; an empty string shown as '' */
	assert_string_equal(diff(base, "bench: {readout_s: 0.01}\ndevices: x\nsweep: {averages: ''}\n", 40, &n),
			    "devices: 6 settings → x\nsweep.averages: 4 → ''");
}

static void test_sequences_and_cap(void **state)
{
	(void)state;
	int n;
	assert_string_equal(diff("a: [1, 2, 3]\n", "a: [1, 5, 3]\n", 40, &n), "a[1]: 2 → 5");
	assert_string_equal(diff("a: [1, 2, 3]\n", "a: [1, 2]\n", 40, &n), "a: 3 items → 2 items");
	assert_string_equal(diff("a: [{x: 1}]\n", "a: [{x: 2}]\n", 40, &n), "a[0].x: 1 → 2");
	/* 50 changes, 3 listed: the count says 50 */
	char a[2048] = "", b[2048] = "";
	for (int i = 0; i < 50; i++) {
		snprintf(a + strlen(a), sizeof a - strlen(a), "k%d: 1\n", i);
		snprintf(b + strlen(b), sizeof b - strlen(b), "k%d: 2\n", i);
	}
	assert_string_equal(diff(a, b, 3, &n), "k0: 1 → 2\nk1: 1 → 2\nk2: 1 → 2");
	assert_int_equal(n, 50);
	/* a long value is cut at 60 characters */
	char longv[200];
	snprintf(longv, sizeof longv, "p: %080d\n", 1);
	const char *out = diff("p: x\n", longv, 40, &n);
	assert_non_null(strstr(out, "p: x → 000000000000000000000000000000000000000000000000000000000000…"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_changes),
		cmocka_unit_test(test_sequences_and_cap),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
