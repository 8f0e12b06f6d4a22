/* Unit tests of export_file_name_ok(): the names a daemon-side export may create in the export folder. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "daemon/export.h"

static void test_names(void **state)
{
	(void)state;
	const char *db = "/var/lib/acquisitiond/acquisition.db";
	struct acq_err err = { 0 };
	static const char *const ok[] = { "samples.csv", "sweep-2_paper.csv", "a", "export", "acquisition.csv", NULL };
	static const char *const bad[] = { "", ".", "..", ".hidden", "-rf", "a/b", "../x", "/etc/passwd", "x\\y",
					   "acquisition.db", "acquisition.db-wal", "acquisition.db-shm",
					   "acquisition.db-journal", "other.db-wal", "x-journal", "a b", "é.csv", NULL };
	for (int i = 0; ok[i]; i++)
		assert_int_equal(export_file_name_ok(ok[i], db, &err), 0);
	for (int i = 0; bad[i]; i++) {
		memset(&err, 0, sizeof err);
		assert_int_equal(export_file_name_ok(bad[i], db, &err), -1);
		assert_int_equal(err.code, ACQ_E_INVAL);
		assert_non_null(strstr(err.msg, "path \""));
	}
	char longname[240];
	memset(longname, 'a', sizeof longname - 1);
	longname[sizeof longname - 1] = 0;
	assert_int_equal(export_file_name_ok(longname, db, &err), -1);
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(test_names) };
	return cmocka_run_group_tests(tests, NULL, NULL);
}
