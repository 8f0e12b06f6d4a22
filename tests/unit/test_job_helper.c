/* Unit tests for the job helper (daemon/job_helper.c, job.c's job_fork_msg): its children are forked by the
 * helper, not by the caller, get their own copy of the payload, run at nice +10 within their memory bound and
 * report their status, output, deadline and kill (a start beyond the helper's 64 children fails alone, 126); a
 * helper killed while a child runs ends that job as lost (status 128 + 9, the child dead with it) and the next
 * job starts a new helper; a helper that hangs is killed when a SIGKILLed child is not reported within 2 s; the
 * payload's header-and-strings packing. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/job.h"
#include "daemon/loop.h"

static int calls, got_status;
static bool got_lost, got_timed_out;
static char got_out[4096];

static void done(struct job *j, int status, const char *out, size_t len, void *arg)
{
	(void)arg;
	calls++;
	got_status = status;
	got_lost = job_lost(j);
	got_timed_out = job_timed_out(j);
	memcpy(got_out, out, len < sizeof got_out ? len + 1 : sizeof got_out);
	got_out[sizeof got_out - 1] = 0;
}

/* Run the loop until a job finished or deadline (seconds); job_reap stands in for the SIGCHLD flag. */
static void run_until(struct loop *lp, double deadline)
{
	double t0 = loop_now(lp);
	while (!calls && loop_now(lp) - t0 < deadline) {
		loop_run_once(lp, 0.02);
		job_reap();
	}
}

/* The payload back (its NUL bytes as '0'), then its parent, nice value and pid; exit status 7. */
static int echo_child(const char *payload, size_t len, int fd)
{
	char buf[512];
	size_t n = 0;
	for (size_t i = 0; i < len && n < 200; i++)
		buf[n++] = payload[i] ? payload[i] : '0';
	errno = 0;
	int nv = getpriority(PRIO_PROCESS, 0);
	n += (size_t)snprintf(buf + n, sizeof buf - n, "|ppid=%d|nice=%d|pid=%d|", (int)getppid(), nv, (int)getpid());
	return write(fd, buf, n) == (ssize_t)n ? 7 : 2;
}

/* Writes its pid, then sleeps (killed by the test). */
static int sleeping_child(const char *payload, size_t len, int fd)
{
	(void)payload;
	(void)len;
	char buf[32];
	int n = snprintf(buf, sizeof buf, "%d", (int)getpid());
	if (write(fd, buf, (size_t)n) != n)
		return 2;
	sleep(30);
	return 0;
}

#if !defined(__SANITIZE_ADDRESS__) /* used only where the memory bound is set (below) */
/* 0 when 64 MiB can be allocated and touched, 9 when the memory bound refuses them. */
static int hungry_child(const char *payload, size_t len, int fd)
{
	(void)payload;
	(void)len;
	(void)fd;
	char *p = malloc(64u << 20);
	if (!p)
		return 9;
	memset(p, 1, 64u << 20);
	return p[12345] == 1 ? 0 : 3;
}
#endif

static void test_children_of_the_helper(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	assert_int_equal(job_helper_start(NULL), 0);
	pid_t hp = job_helper_pid();
	assert_true(hp > 0 && hp != getpid());
	static const char payload[] = "plan\0text";
	calls = 0;
	struct job *j = NULL;
	assert_int_equal(job_fork_msg(echo_child, payload, sizeof payload - 1, 0, 1024, 10, done, NULL, &j, NULL), 0);
	assert_int_equal(job_pid(j), 0); /* not a child of this process */
	assert_int_equal(job_count(), 1);
	run_until(lp, 10);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 7);
	assert_false(got_lost);
	print_message("child: %s\n", got_out);
	assert_memory_equal(got_out, "plan0text|", 10);
	char want[64];
	snprintf(want, sizeof want, "|ppid=%d|", (int)hp); /* the helper forked it */
	assert_non_null(strstr(got_out, want));
	int nv = getpriority(PRIO_PROCESS, 0) + 10;
	snprintf(want, sizeof want, "|nice=%d|", nv > 19 ? 19 : nv);
	assert_non_null(strstr(got_out, want));
	assert_int_equal(job_count(), 0);
#if !defined(__SANITIZE_ADDRESS__) /* job_child_limits sets no RLIMIT_AS under ASan (by design) */
	calls = 0;
	assert_int_equal(job_fork_msg(hungry_child, "", 0, 32u << 20, 1024, 10, done, NULL, NULL, NULL), 0);
	run_until(lp, 10);
	assert_int_equal(got_status, 9);
	calls = 0;
	assert_int_equal(job_fork_msg(hungry_child, "", 0, 0, 1024, 10, done, NULL, NULL, NULL), 0);
	run_until(lp, 10);
	assert_int_equal(got_status, 0);
#endif
	/* the deadline, then a kill, both through the helper */
	calls = 0;
	double t0 = loop_now(lp);
	assert_int_equal(job_fork_msg(sleeping_child, "", 0, 0, 1024, 0.2, done, NULL, NULL, NULL), 0);
	run_until(lp, 10);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 128 + SIGTERM);
	assert_true(got_timed_out);
	assert_true(loop_now(lp) - t0 < 3);
	calls = 0;
	assert_int_equal(job_fork_msg(sleeping_child, "", 0, 0, 1024, 0, done, NULL, &j, NULL), 0);
	job_kill(j);
	run_until(lp, 10);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 128 + SIGKILL);
	assert_false(got_lost);
	assert_int_equal(job_helper_pid(), hp); /* the same helper all along */
	/* a start the helper cannot run (its 64 children running): that job fails with 126, the others go on */
	struct job *many[65];
	calls = 0;
	for (int i = 0; i < 65; i++)
		assert_int_equal(job_fork_msg(sleeping_child, "", 0, 0, 1024, 0, done, NULL, &many[i], NULL), 0);
	run_until(lp, 10);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 126);
	assert_false(got_lost);
	assert_int_equal(job_count(), 64);
	assert_int_equal(job_helper_pid(), hp);
	for (int i = 0; i < 64; i++)
		job_kill(many[i]);
	for (int i = 0; i < 1000 && calls < 65; i++) {
		loop_run_once(lp, 0.01);
		job_reap();
	}
	assert_int_equal(calls, 65);
	assert_int_equal(job_count(), 0);
	job_finish();
	loop_free(lp);
}

static bool gone_within(pid_t pid, double s)
{
	for (int i = 0; i < (int)(s * 100); i++) {
		job_reap(); /* a killed helper is reaped there (it is this process's child) */
		if (kill(pid, 0) < 0 && errno == ESRCH)
			return true;
		usleep(10000);
	}
	return false;
}

/* A sleeping job whose child has written its pid; that pid. */
static pid_t start_sleeper(struct loop *lp, double timeout_s)
{
	calls = 0;
	struct job *j = NULL;
	assert_int_equal(job_fork_msg(sleeping_child, "", 0, 0, 1024, timeout_s, done, NULL, &j, NULL), 0);
	for (int i = 0; i < 500 && !calls; i++) { /* until its pid has been read */
		loop_run_once(lp, 0.01);
		job_reap();
		if (job_count() == 1 && calls == 0) {
			/* the output is only seen in done(); poll the child list of the helper instead */
			char path[64], buf[256] = "";
			snprintf(path, sizeof path, "/proc/%d/task/%d/children", (int)job_helper_pid(), (int)job_helper_pid());
			FILE *f = fopen(path, "r");
			if (f) {
				if (!fgets(buf, sizeof buf, f))
					buf[0] = 0;
				fclose(f);
			}
			if (atoi(buf) > 0)
				return (pid_t)atoi(buf);
		}
	}
	fail_msg("the helper's child did not start");
	return 0;
}

static void test_helper_lost_and_restarted(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	assert_int_equal(job_helper_start(NULL), 0);
	pid_t hp = job_helper_pid();
	/* the helper killed while its child runs: the job ends lost, the child with the helper */
	pid_t kid = start_sleeper(lp, 30);
	assert_int_equal(kill(hp, SIGKILL), 0);
	run_until(lp, 10);
	assert_int_equal(calls, 1);
	assert_true(got_lost);
	assert_int_equal(got_status, 128 + SIGKILL);
	assert_true(gone_within(kid, 5));
	assert_int_equal(job_count(), 0);
	/* the next job starts a new helper and runs */
	calls = 0;
	assert_int_equal(job_fork_msg(echo_child, "again", 5, 0, 1024, 10, done, NULL, NULL, NULL), 0);
	pid_t hp2 = job_helper_pid();
	assert_true(hp2 > 0 && hp2 != hp);
	run_until(lp, 10);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 7);
	assert_false(got_lost);
	assert_memory_equal(got_out, "again|", 6);

	/* a helper that hangs (stopped): the deadline's SIGTERM and SIGKILL go unanswered, 2 s later it is killed */
	kid = start_sleeper(lp, 0.2);
	assert_int_equal(kill(hp2, SIGSTOP), 0);
	double t0 = loop_now(lp);
	run_until(lp, 15);
	assert_int_equal(calls, 1);
	assert_true(got_lost);
	print_message("hung helper: job ended after %.1f s\n", loop_now(lp) - t0);
	assert_true(gone_within(kid, 5));
	assert_true(gone_within(hp2, 5));
	calls = 0;
	assert_int_equal(job_fork_msg(echo_child, "third", 5, 0, 1024, 10, done, NULL, NULL, NULL), 0);
	run_until(lp, 10);
	assert_int_equal(got_status, 7);
	assert_true(job_helper_pid() != hp2);
	job_finish();
	assert_int_equal(job_helper_pid(), 0);
	loop_free(lp);
}

/* job_msg_pack/unpack: header and strings back; a short or inconsistent payload refused. */
static void test_msg_pack(void **state)
{
	(void)state;
	struct { double x; int k; } h = { 2.5, 7 }, back = { 0, 0 };
	size_t len = 0;
	char *m = job_msg_pack(&h, sizeof h, "path/a.yaml", "text: 1\n", &len);
	assert_non_null(m);
	char *a = NULL;
	const char *b = NULL;
	assert_int_equal(job_msg_unpack(m, len, &back, sizeof back, &a, &b), 0);
	assert_true(back.x == 2.5 && back.k == 7);
	assert_string_equal(a, "path/a.yaml");
	assert_memory_equal(b, "text: 1\n", 8);
	assert_int_equal((size_t)(b - m) + 8, len);
	free(a);
	assert_int_equal(job_msg_unpack(m, sizeof h + 3, &back, sizeof back, &a, &b), -1); /* shorter than its length */
	assert_int_equal(job_msg_unpack(m, sizeof h + 8 + 4, &back, sizeof back, &a, &b), -1); /* a cut */
	free(m);
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_msg_pack),
		cmocka_unit_test(test_children_of_the_helper),
		cmocka_unit_test(test_helper_lost_and_restarted),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
