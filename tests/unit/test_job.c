/* Unit tests for daemon/job.c: a child's output is captured and its exit status reported through the loop
 * (SIGCHLD → job_reap), a timeout kills it, a missing program reports 127, the loop is never blocked; the program
 * runs through this program's exec mode (job_kinds_main): no fork of the caller, none of its descriptors, its
 * directory, one BLAS thread by default, death with the caller. */
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/job.h"
#include "daemon/loop.h"

static int got_status = -1000;
static char got_out[4096];

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

static int forks; /* fork() calls in this process (pthread_atfork: posix_spawn does not count) */
static void count_fork(void)
{
	forks++;
}

/* The output of `sh -c script` run by job_start in directory cwd; its status. */
static int run_script(struct loop *lp, const char *script, const char *cwd)
{
	int calls = 0;
	char *argv[] = { "/bin/sh", "-c", (char *)(uintptr_t)script, NULL };
	assert_int_equal(job_start(argv, cwd, 20, done, &calls, NULL, NULL), 0);
	run_until(lp, &calls, 20);
	assert_int_equal(calls, 1);
	return got_status;
}

/* The program starts without a fork of the caller (so no copy of its memory or threads), holds none of its
 * descriptors (one opened without close-on-exec here: a fork and exec kept it), runs in cwd, gets one BLAS
 * thread unless the caller's environment sets the number; a directory that cannot be entered is status 126. */
static void test_exec_mode(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	char dir[] = "/tmp/acq-test-job-XXXXXX", file[64];
	assert_non_null(mkdtemp(dir));
	snprintf(file, sizeof file, "%s/held", dir);
	int held = open(file, O_RDWR | O_CREAT, 0600); /* no O_CLOEXEC */
	assert_true(held >= 0);
	unsetenv("OPENBLAS_NUM_THREADS");
	forks = 0;
	assert_int_equal(run_script(lp, "ls -l /proc/$$/fd; echo \"cwd=$(pwd)\"; echo \"blas=$OPENBLAS_NUM_THREADS\"",
				    dir), 0);
	assert_int_equal(forks, 0);
	if (strstr(got_out, file))
		fail_msg("the program holds the caller's descriptor of %s:\n%s", file, got_out);
	char want[128];
	snprintf(want, sizeof want, "cwd=%s\n", dir);
	assert_non_null(strstr(got_out, want));
	assert_non_null(strstr(got_out, "blas=1\n"));
	setenv("OPENBLAS_NUM_THREADS", "3", 1); /* the caller's choice is kept */
	assert_int_equal(run_script(lp, "echo \"blas=$OPENBLAS_NUM_THREADS\"", NULL), 0);
	assert_non_null(strstr(got_out, "blas=3\n"));
	assert_int_equal(run_script(lp, "true", "/nonexistent/dir"), 126);
	assert_non_null(strstr(got_out, "cannot enter /nonexistent/dir"));
	assert_int_equal(forks, 0);
	close(held);
	unlink(file);
	rmdir(dir);
	job_finish();
	loop_free(lp);
}

/* Gone or a zombie (reparented: reaped by whoever adopted it) within s seconds. */
static bool gone_within(pid_t pid, double s)
{
	for (int i = 0; i < (int)(s * 100); i++) {
		char path[64], st[256] = "";
		snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
		FILE *f = fopen(path, "r");
		if (!f)
			return true;
		bool zombie = fgets(st, sizeof st, f) && strstr(st, ") Z ");
		fclose(f);
		if (zombie)
			return true;
		usleep(10000);
	}
	return false;
}

/* A program started by a process that is then SIGKILLed (no job_finish) dies with it (PR_SET_PDEATHSIG). */
static void test_dies_with_caller(void **state)
{
	(void)state;
	int p[2];
	assert_int_equal(pipe(p), 0);
	pid_t caller = fork();
	assert_true(caller >= 0);
	if (caller == 0) {
		close(p[0]);
		struct loop *lp = loop_new(NULL, NULL);
		job_init(lp);
		struct job *j = NULL;
		char *argv[] = { "/bin/sleep", "60", NULL };
		if (job_start(argv, NULL, 0, done, NULL, &j, NULL))
			_exit(1);
		pid_t pid = job_pid(j);
		if (write(p[1], &pid, sizeof pid) != sizeof pid)
			_exit(1);
		for (;;)
			pause();
	}
	close(p[1]);
	pid_t prog = 0;
	assert_int_equal(read(p[0], &prog, sizeof prog), (ssize_t)sizeof prog);
	close(p[0]);
	assert_true(prog > 0);
	for (int i = 0; i < 1000; i++) { /* until the exec mode has exec'd the program (the death signal set) */
		char exe[64], link[256] = "";
		snprintf(exe, sizeof exe, "/proc/%d/exe", (int)prog);
		ssize_t n = readlink(exe, link, sizeof link - 1);
		if (n > 0 && strstr(link, "sleep"))
			break;
		usleep(10000);
	}
	assert_false(gone_within(prog, 0.2)); /* it runs while its caller does */
	kill(caller, SIGKILL);
	waitpid(caller, NULL, 0);
	if (!gone_within(prog, 10)) {
		kill(prog, SIGKILL);
		fail_msg("the program %d outlived its caller by 10 s", (int)prog);
	}
}

int main(int argc, char **argv)
{
	job_kinds_main(argc, argv, NULL, 0); /* job_start's exec mode: this program run again */
	pthread_atfork(count_fork, NULL, NULL);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_output_and_status),
		cmocka_unit_test(test_timeout_and_missing),
		cmocka_unit_test(test_exec_mode),
		cmocka_unit_test(test_dies_with_caller),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
