/* Unit tests of recon/csvio.c: the CSV interchange format, its missing values, and errors that name the
 * line and the column. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "recon/csvio.h"

static int parse(const char *text, struct recon_samples *s, struct acq_err *err)
{
	return csvio_parse_samples("t.csv", text, strlen(text), s, err);
}

static void test_valid_file(void **state)
{
	(void)state;
	struct recon_samples s;
	struct acq_err err = { 0 };
	const char *text = "\xEF\xBB\xBF# a comment\n#another\n\n"
			   "theta_i,phi_i,theta_o,phi_o,550.5,450,sigma_450,sigma_550.5\r\n"
			   "10,0,20,180,0.25,0.125,0.01,0.02\r\n"
			   " 0 , 0 , 90 , -45 , , nan, NaN,\n"
			   "\n"
			   "90,360,0,0,1e-3,2.5E+1,,0\n";
	assert_int_equal(parse(text, &s, &err), 0);
	assert_int_equal(s.n, 3);
	assert_int_equal(s.nwl, 2);
	assert_true(s.wl[0] == 450 && s.wl[1] == 550.5); /* sorted */
	assert_non_null(s.sig);
	assert_true(s.val[0] == 0.125 && s.val[1] == 0.25);
	assert_true(s.sig[0] == 0.01 && s.sig[1] == 0.02);
	assert_true(isnan(s.val[2]) && isnan(s.val[3]) && isnan(s.sig[2]) && isnan(s.sig[3]));
	assert_true(s.val[4] == 25 && s.val[5] == 1e-3 && isnan(s.sig[4]) && s.sig[5] == 0);
	assert_true(fabs(s.ang[0] - 10 * M_PI / 180) < 1e-15 && fabs(s.ang[3] - M_PI) < 1e-15);
	assert_true(s.deg[4 + 3] == -45);
	csvio_samples_free(&s);
	/* no sigma columns: sig is NULL; angle columns may come in any order */
	assert_int_equal(parse("phi_o,theta_o,phi_i,theta_i,700\n1,2,3,4,0.5\n", &s, &err), 0);
	assert_null(s.sig);
	assert_true(fabs(s.deg[0] - 4) < 1e-15 && fabs(s.deg[3] - 1) < 1e-15);
	csvio_samples_free(&s);
}

struct bad_case {
	const char *text;
	const char *expect1, *expect2;
};

static void test_errors_name_line_and_column(void **state)
{
	(void)state;
	static const struct bad_case cases[] = {
		{ "# c\ntheta_i,phi_i,theta_o,phi_o,500\n1,2,3,4,0.1\n1,2,3,4,inf\n", "t.csv:4:", "column 5" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n1,2,3,4,abc\n", "t.csv:2:", "'abc' is not a finite number" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n1,2,3,4,1e999\n", "t.csv:2:", "column 5" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n1,2,3,4,0x10\n", "t.csv:2:", "column 5" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n1,2,3,4,nan(1)\n", "t.csv:2:", "column 5" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n95,2,3,4,0.1\n", "t.csv:2:", "outside [0, 90]" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n5,2,-3,4,0.1\n", "t.csv:2:", "column 3" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n5,,3,4,0.1\n", "t.csv:2:", "phi_i is missing" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n5,2,3,4\n", "t.csv:2:", "expected 5 fields, found 4" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n5,2,3,4,1,2\n", "t.csv:2:", "expected 5 fields" },
		{ "theta_i,phi_i,theta_o,500\n", "t.csv:1:", "missing column phi_o" },
		{ "theta_i,phi_i,theta_o,phi_o,500,colour\n", "t.csv:1:", "column 6" },
		{ "theta_i,phi_i,theta_o,phi_o,500,sigma_600\n", "t.csv:1:", "sigma_600 has no wavelength" },
		{ "theta_i,phi_i,theta_o,phi_o,500,500.0\n", "t.csv:1:", "appears twice" },
		{ "theta_i,phi_i,theta_o,phi_o,500,sigma_500\n1,2,3,4,0.1,-0.01\n", "t.csv:2:", "negative uncertainty" },
		{ "theta_i,phi_i,theta_o,phi_o\n", "t.csv:1:", "no wavelength column" },
		{ "theta_i,phi_i,theta_o,phi_o,500\n", "t.csv", "no data rows" },
		{ "# only comments\n", "t.csv", "no header" },
		{ "", "t.csv", "no header" },
		{ "theta_i,theta_i,phi_i,theta_o,phi_o,500\n", "t.csv:1:", "duplicate column theta_i" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		struct recon_samples s;
		struct acq_err err = { 0 };
		int rc = parse(cases[i].text, &s, &err);
		if (rc != -1 || !strstr(err.msg, cases[i].expect1) || !strstr(err.msg, cases[i].expect2))
			printf("case %zu: rc %d, message: %s\n", i, rc, err.msg);
		assert_int_equal(rc, -1);
		assert_non_null(strstr(err.msg, cases[i].expect1));
		assert_non_null(strstr(err.msg, cases[i].expect2));
		assert_null(s.val);
		assert_int_equal(s.n, 0);
	}
}

static void test_queries_and_columns(void **state)
{
	(void)state;
	struct recon_samples q;
	struct acq_err err = { 0 };
	const char *t = "theta_i,phi_i,theta_o,phi_o,anything,else\n10,0,20,30,x,\n";
	assert_int_equal(csvio_parse_queries("q.csv", t, strlen(t), &q, &err), 0);
	assert_int_equal(q.n, 1);
	assert_int_equal(q.nwl, 0);
	assert_true(q.deg[3] == 30);
	csvio_samples_free(&q);
	char path[] = "/tmp/recon_csv_XXXXXX";
	int fd = mkstemp(path);
	assert_true(fd >= 0);
	const char *ref = "# reference\nwavelength_nm,dhr,sigma\n450,0.1,0.01\n500,0.2,0.02\n";
	assert_int_equal(write(fd, ref, strlen(ref)), (ssize_t)strlen(ref));
	close(fd);
	static const char *const names[3] = { "wavelength_nm", "dhr", "sigma" };
	size_t rows;
	double *d;
	assert_int_equal(csvio_read_columns(path, names, 3, &rows, &d, &err), 0);
	assert_int_equal(rows, 2);
	assert_true(d[3] == 500 && d[4] == 0.2 && d[5] == 0.02);
	free(d);
	/* column-major: the sigma column first in the request, each column's rows one after the other */
	static const char *const perm[2] = { "sigma", "wavelength_nm" };
	assert_int_equal(csvio_read_columns_cm(path, perm, 2, &rows, &d, &err), 0);
	assert_int_equal(rows, 2);
	assert_true(d[0] == 0.01 && d[1] == 0.02 && d[2] == 450 && d[3] == 500);
	free(d);
	static const char *const bad[1] = { "nope" };
	assert_int_equal(csvio_read_columns(path, bad, 1, &rows, &d, &err), -1);
	assert_non_null(strstr(err.msg, "missing column nope"));
	d = (double *)1;
	assert_int_equal(csvio_read_columns_cm(path, bad, 1, &rows, &d, &err), -1);
	assert_null(d);
	/* a header and no data row: refused, or 0 rows with CSVIO_EMPTY_OK (select's zero candidates); a missing
	 * column or a bad row is refused either way */
	fd = open(path, O_WRONLY | O_TRUNC);
	assert_true(fd >= 0);
	const char *hdr = "# none\nwavelength_nm,dhr,sigma\r\n\n";
	assert_int_equal(write(fd, hdr, strlen(hdr)), (ssize_t)strlen(hdr));
	close(fd);
	assert_int_equal(csvio_read_columns(path, names, 3, &rows, &d, &err), -1);
	assert_non_null(strstr(err.msg, "no data rows"));
	rows = 7;
	d = (double *)1;
	assert_int_equal(csvio_read_columns_ex(path, names, 3, CSVIO_EMPTY_OK, &rows, &d, &err), 0);
	assert_int_equal(rows, 0);
	assert_null(d);
	assert_int_equal(csvio_read_columns_ex(path, bad, 1, CSVIO_EMPTY_OK, &rows, &d, &err), -1);
	assert_non_null(strstr(err.msg, "missing column nope"));
	fd = open(path, O_WRONLY | O_APPEND);
	assert_true(fd >= 0);
	assert_int_equal(write(fd, "1,2\n", 4), 4);
	close(fd);
	assert_int_equal(csvio_read_columns_ex(path, names, 3, CSVIO_EMPTY_OK, &rows, &d, &err), -1);
	assert_non_null(strstr(err.msg, "expected 3 fields"));
	assert_null(d);
	unlink(path);
	assert_int_equal(csvio_read_samples("/nonexistent/x.csv", &q, &err), -1);
	assert_int_equal(err.code, ACQ_E_NOTFOUND); /* no such file (config/acq_file.h) */
	char buf[32];
	assert_int_equal(csvio_fmt(buf, sizeof buf, NAN), -1);
	assert_int_equal(csvio_fmt(buf, sizeof buf, INFINITY), -1);
	assert_int_equal(csvio_fmt(buf, sizeof buf, 0.5), 0);
	assert_string_equal(buf, "0.5");
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_valid_file),
		cmocka_unit_test(test_errors_name_line_and_column),
		cmocka_unit_test(test_queries_and_columns),
	};
	return cmocka_run_group_tests_name("recon_csv", tests, NULL, NULL);
}
