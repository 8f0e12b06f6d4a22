/* Unit tests of config/acq_file: a file read whole up to the limit and refused one byte past it (at the first
 * buffer and after the buffer has grown), a missing file and a directory refused with the path in the message,
 * an empty file read as "", NUL bytes kept, "-" read from standard input only when asked. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "config/acq_file.h"

#define UT_TMPDIR_NAME "acq_file"
#include "tests/unit/tmpdir.h"


static void path_in(char *buf, size_t n, const char *name)
{
	snprintf(buf, n, "%s/%s", ut_dir, name);
}

/* A file of n bytes: byte i is 'a' + i % 26, a NUL every 1000th. */
static void put_bytes(const char *path, size_t n)
{
	FILE *f = fopen(path, "wb");
	assert_non_null(f);
	for (size_t i = 0; i < n; i++)
		fputc(i % 1000 == 999 ? 0 : 'a' + (int)(i % 26), f);
	assert_int_equal(fclose(f), 0);
}

static void assert_bytes(const char *buf, size_t n)
{
	for (size_t i = 0; i < n; i++)
		if (buf[i] != (i % 1000 == 999 ? 0 : 'a' + (int)(i % 26)))
			fail_msg("byte %zu differs", i);
	assert_int_equal(buf[n], 0);
}

/* Sizes at, below and past the limit, for a small limit (one buffer) and a large one (the buffer grows). */
static void test_limit(void **state)
{
	(void)state;
	char p[600];
	path_in(p, sizeof p, "limit");
	static const size_t maxes[] = { 0, 1, 100, 65535, 65536, 65537, 300000 };
	for (size_t k = 0; k < sizeof maxes / sizeof maxes[0]; k++) {
		size_t max = maxes[k];
		for (size_t n = max > 2 ? max - 2 : 0; n <= max + 2; n++) {
			put_bytes(p, n);
			struct acq_err err = { 0 };
			char *buf = (char *)1;
			size_t len = 12345;
			int rc = acq_file_read(p, max, 0, &buf, &len, &err);
			if (n <= max) {
				assert_int_equal(rc, 0);
				assert_int_equal(len, n);
				assert_bytes(buf, n);
				free(buf);
			} else {
				assert_int_equal(rc, -1);
				assert_null(buf);
				assert_int_equal(len, 0);
				assert_int_equal(err.code, ACQ_E_RANGE);
				assert_non_null(strstr(err.msg, p));
				assert_non_null(strstr(err.msg, "larger than"));
			}
		}
	}
	unlink(p);
}

static void test_limit_words(void **state)
{
	(void)state;
	char p[600];
	path_in(p, sizeof p, "words");
	put_bytes(p, (2u << 20) + 1);
	struct acq_err err = { 0 };
	char *buf;
	assert_int_equal(acq_file_read(p, 2u << 20, 0, &buf, NULL, &err), -1);
	char want[700];
	snprintf(want, sizeof want, "%s: larger than 2 MiB", p);
	assert_string_equal(err.msg, want);
	assert_int_equal(acq_file_read(p, 3000, 0, &buf, NULL, &err), -1);
	snprintf(want, sizeof want, "%s: larger than 3000 bytes", p);
	assert_string_equal(err.msg, want);
	unlink(p);
}

static void test_missing(void **state)
{
	(void)state;
	char p[600];
	path_in(p, sizeof p, "no-such-file");
	struct acq_err err = { 0 };
	char *buf = (char *)1;
	assert_int_equal(acq_file_read(p, 100, ACQ_FILE_STDIN, &buf, NULL, &err), -1);
	assert_null(buf);
	assert_int_equal(err.code, ACQ_E_NOTFOUND);
	char want[700];
	snprintf(want, sizeof want, "%s: cannot open: No such file or directory", p);
	assert_string_equal(err.msg, want);
}

static void test_directory(void **state)
{
	(void)state;
	struct acq_err err = { 0 };
	char *buf = (char *)1;
	assert_int_equal(acq_file_read(ut_dir, 100, 0, &buf, NULL, &err), -1);
	assert_null(buf);
	assert_int_equal(err.code, ACQ_E_IO);
	assert_non_null(strstr(err.msg, ut_dir));
	assert_non_null(strstr(err.msg, "Is a directory"));
}

static void test_empty(void **state)
{
	(void)state;
	char p[600];
	path_in(p, sizeof p, "empty");
	put_bytes(p, 0);
	struct acq_err err = { 0 };
	char *buf = NULL;
	size_t len = 99;
	assert_int_equal(acq_file_read(p, 100, 0, &buf, &len, &err), 0);
	assert_non_null(buf);
	assert_string_equal(buf, "");
	assert_int_equal(len, 0);
	assert_int_equal(err.code, 0);
	free(buf);
	unlink(p);
}

/* "-" with ACQ_FILE_STDIN reads standard input (here a file of 70,000 bytes on fd 0: the buffer grows; and past
 * a limit, named "standard input"); without the flag "-" is a file's name. */
static void test_stdin(void **state)
{
	(void)state;
	char p[600];
	path_in(p, sizeof p, "stdin");
	put_bytes(p, 70000);
	int saved = dup(0);
	assert_true(saved >= 0);
	for (int pass = 0; pass < 3; pass++) {
		int fd = open(p, O_RDONLY);
		assert_true(fd >= 0);
		assert_int_equal(dup2(fd, 0), 0);
		close(fd);
		rewind(stdin);
		struct acq_err err = { 0 };
		char *buf = NULL;
		size_t len = 0;
		if (pass == 0) {
			assert_int_equal(acq_file_read("-", 100000, ACQ_FILE_STDIN, &buf, &len, &err), 0);
			assert_int_equal(len, 70000);
			assert_bytes(buf, 70000);
			free(buf);
		} else if (pass == 1) {
			assert_int_equal(acq_file_read("-", 69999, ACQ_FILE_STDIN, &buf, &len, &err), -1);
			assert_int_equal(err.code, ACQ_E_RANGE);
			assert_string_equal(err.msg, "standard input: larger than 69999 bytes");
		} else {
			assert_int_equal(chdir(ut_dir), 0);
			assert_int_equal(acq_file_read("-", 100000, 0, &buf, &len, &err), -1);
			assert_int_equal(err.code, ACQ_E_NOTFOUND);
			assert_string_equal(err.msg, "-: cannot open: No such file or directory");
		}
	}
	assert_int_equal(dup2(saved, 0), 0);
	close(saved);
	unlink(p);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_limit),   cmocka_unit_test(test_limit_words), cmocka_unit_test(test_missing),
		cmocka_unit_test(test_directory), cmocka_unit_test(test_empty),     cmocka_unit_test(test_stdin),
	};
	return cmocka_run_group_tests(tests, ut_dir_setup, ut_dir_teardown);
}
