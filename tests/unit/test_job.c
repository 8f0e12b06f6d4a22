/* Unit tests for daemon/job.c: a child's output is captured and its exit status reported through the loop
 * (SIGCHLD → job_reap), a timeout kills it, a missing program reports 127, the loop is never blocked. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <cmocka.h>

#include "daemon/job.h"
#include "daemon/loop.h"

static int got_status = -1000;
static char got_out[256];

static void done(struct job *j, int status, const char *out, size_t len, void *arg)
{
	(void)j;
	(void)len;
	*(int *)arg += 1;
	got_status = status;
	snprintf(got_out, sizeof got_out, "%s", out);
}

/* Run the loop until the job finished or deadline (seconds); job_reap stands in for the SIGCHLD flag. */
static void run_until(struct loop *lp, int *calls, double deadline)
{
	double t0 = loop_now(lp);
	while (!*calls && loop_now(lp) - t0 < deadline) {
		loop_run_once(lp, 0.02);
		job_reap();
	}
}

static void test_output_and_status(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	int calls = 0;
	char *argv[] = { "/bin/sh", "-c", "echo to-out; echo to-err >&2; exit 3", NULL };
	struct job *j = NULL;
	assert_int_equal(job_start(argv, NULL, 10, done, &calls, &j, NULL), 0);
	assert_true(job_pid(j) > 0);
	assert_int_equal(job_count(), 1);
	run_until(lp, &calls, 5);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 3);
	assert_non_null(strstr(got_out, "to-out"));
	assert_non_null(strstr(got_out, "to-err"));
	assert_int_equal(job_count(), 0);
	job_finish();
	loop_free(lp);
}

static void test_timeout_and_missing(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	int calls = 0;
	char *argv[] = { "/bin/sh", "-c", "exec sleep 30", NULL };
	assert_int_equal(job_start(argv, NULL, 0.2, done, &calls, NULL, NULL), 0);
	double t0 = loop_now(lp);
	run_until(lp, &calls, 5);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 128 + SIGTERM);
	assert_true(loop_now(lp) - t0 < 3);
	calls = 0;
	char *missing[] = { "/nonexistent/brdf-recon", NULL };
	assert_int_equal(job_start(missing, NULL, 5, done, &calls, NULL, NULL), 0);
	run_until(lp, &calls, 5);
	assert_int_equal(got_status, 127);
	/* job_finish kills what is left without calling back. */
	calls = 0;
	char *slow[] = { "/bin/sleep", "30", NULL };
	assert_int_equal(job_start(slow, NULL, 0, done, &calls, NULL, NULL), 0);
	job_finish();
	assert_int_equal(calls, 0);
	assert_int_equal(job_count(), 0);
	loop_free(lp);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_output_and_status),
		cmocka_unit_test(test_timeout_and_missing),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
