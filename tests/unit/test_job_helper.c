/* Unit tests for the job helper (daemon/job_helper.c, job.c's job_fork_msg): its children are forked by the
 * helper, not by the caller, get their own copy of the payload, run at nice +10 within their memory bound and
 * report their status, output, deadline and kill (a start beyond the helper's 64 children fails alone, 126); a
 * helper killed while a child runs ends that job as lost (status 128 + 9, the child dead with it) and the next
 * job starts a new helper; a helper that hangs is killed when a SIGKILLed child is not reported within 2 s; a
 * restarted helper is this program run again, holding none of the caller's descriptors, mappings or threads; the
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
#include <fcntl.h>
#include <pthread.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>
#include <cmocka.h>

#include "tests/unit/tmpdir.h"

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

/* Burns CPU until stopped. */
static int spinning_child(const char *payload, size_t len, int fd)
{
	(void)payload;
	(void)len;
	(void)fd;
	for (volatile unsigned long i = 0;; i++)
		;
	return 0;
}

static const struct job_kind spinning_kind = { "spinning", spinning_child };
static const struct job_kind echo_kind = { "echo", echo_child }, sleeping_kind = { "sleeping", sleeping_child };
#if !defined(__SANITIZE_ADDRESS__)
static const struct job_kind hungry_kind = { "hungry", hungry_child };
#endif
static const struct job_kind unlisted_kind = { "unlisted", echo_child };
static const struct job_kind *const kinds[] = { &echo_kind, &sleeping_kind, &spinning_kind,
#if !defined(__SANITIZE_ADDRESS__)
						&hungry_kind,
#endif
};

/* The CPU bound (job_fork_msg_cpu; the `plan` command's, commands_plan.c): a child burning CPU ends with SIGXCPU at
 * its bound, long before its real-time deadline; a child that waits (a loaded machine gives it no CPU: here it
 * sleeps) is not ended by it: only its work is bounded. */
static void test_cpu_bound(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	calls = 0;
	double t0 = loop_now(lp);
	assert_int_equal(job_fork_msg_cpu(&spinning_kind, "", 0, 0, 1, 1024, 120, done, NULL, NULL, NULL), 0);
	run_until(lp, 60);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 128 + SIGXCPU);
	assert_false(got_timed_out);
	printf("a spinning child with 1 s of CPU ended after %.1f s real\n", loop_now(lp) - t0);
	/* a child that waits (sleeping_child: 30 s) with 1 s of CPU allowed and a 3 s deadline: the deadline ends it
	 * (128 + SIGTERM, after 3 s), not the CPU bound at 1 s */
	calls = 0;
	t0 = loop_now(lp);
	assert_int_equal(job_fork_msg_cpu(&sleeping_kind, "", 0, 0, 1, 1024, 3, done, NULL, NULL, NULL), 0);
	run_until(lp, 60);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 128 + SIGTERM);
	assert_true(got_timed_out);
	assert_true(loop_now(lp) - t0 >= 3);
	job_finish();
	loop_free(lp);
}

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
	assert_int_equal(job_fork_msg(&echo_kind, payload, sizeof payload - 1, 0, 1024, 10, done, NULL, &j, NULL), 0);
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
	assert_int_equal(job_fork_msg(&hungry_kind, "", 0, 32u << 20, 1024, 10, done, NULL, NULL, NULL), 0);
	run_until(lp, 10);
	assert_int_equal(got_status, 9);
	calls = 0;
	assert_int_equal(job_fork_msg(&hungry_kind, "", 0, 0, 1024, 10, done, NULL, NULL, NULL), 0);
	run_until(lp, 10);
	assert_int_equal(got_status, 0);
#endif
	/* the deadline, then a kill, both through the helper */
	calls = 0;
	double t0 = loop_now(lp);
	assert_int_equal(job_fork_msg(&sleeping_kind, "", 0, 0, 1024, 0.2, done, NULL, NULL, NULL), 0);
	run_until(lp, 10);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 128 + SIGTERM);
	assert_true(got_timed_out);
	assert_true(loop_now(lp) - t0 < 3);
	calls = 0;
	assert_int_equal(job_fork_msg(&sleeping_kind, "", 0, 0, 1024, 0, done, NULL, &j, NULL), 0);
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
		assert_int_equal(job_fork_msg(&sleeping_kind, "", 0, 0, 1024, 0, done, NULL, &many[i], NULL), 0);
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
	assert_int_equal(job_fork_msg(&sleeping_kind, "", 0, 0, 1024, timeout_s, done, NULL, &j, NULL), 0);
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

/* An echo job of word, run by a new helper (not old): its pid. */
static pid_t echo_on_new_helper(struct loop *lp, pid_t old, const char *word)
{
	calls = 0;
	assert_int_equal(job_fork_msg(&echo_kind, word, strlen(word), 0, 1024, 10, done, NULL, NULL, NULL), 0);
	pid_t hp = job_helper_pid();
	assert_true(hp > 0 && hp != old);
	run_until(lp, 10);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 7);
	assert_false(got_lost);
	assert_memory_equal(got_out, word, strlen(word));
	assert_int_equal(got_out[strlen(word)], '|');
	return hp;
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
	pid_t hp2 = echo_on_new_helper(lp, hp, "again");

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
	assert_int_equal(job_fork_msg(&echo_kind, "third", 5, 0, 1024, 10, done, NULL, NULL, NULL), 0);
	run_until(lp, 10);
	assert_int_equal(got_status, 7);
	assert_true(job_helper_pid() != hp2);
	job_finish();
	assert_int_equal(job_helper_pid(), 0);
	loop_free(lp);
}

/* Whether /proc/PID/FILE holds needle (a file read whole, its NULs as newlines). */
static bool proc_has(pid_t pid, const char *file, const char *needle)
{
	char path[64], buf[65536];
	snprintf(path, sizeof path, "/proc/%d/%s", (int)pid, file);
	FILE *f = fopen(path, "r");
	assert_non_null(f);
	size_t n = fread(buf, 1, sizeof buf - 1, f);
	fclose(f);
	for (size_t i = 0; i < n; i++)
		if (!buf[i])
			buf[i] = '\n';
	buf[n] = 0;
	return strstr(buf, needle) != NULL;
}

/* The descriptors of process pid: their count, and whether one leads to path. */
static int proc_fds(pid_t pid, const char *path, bool *found)
{
	int n = 0;
	*found = false;
	for (int fd = 0; fd < 1024; fd++) {
		char link[64], to[4096];
		snprintf(link, sizeof link, "/proc/%d/fd/%d", (int)pid, fd);
		ssize_t k = readlink(link, to, sizeof to - 1);
		if (k < 0)
			continue;
		to[k] = 0;
		n++;
		if (!strcmp(to, path))
			*found = true;
	}
	return n;
}

static void *idle_thread(void *arg)
{
	int fd = *(int *)arg;
	char c;
	while (read(fd, &c, 1) < 0 && errno == EINTR)
		;
	return NULL;
}

/* A helper started again while the caller holds a database (an open file, not close-on-exec, and a shared mapping
 * of it as SQLite maps a WAL's -shm) and a device thread: the new helper is this program run again in its helper
 * mode (its command line, one thread), with none of them (a fork of the caller kept the mapping and the command
 * line); a kind outside the program's table is refused before anything is sent. */
static void test_restarted_helper_holds_nothing(void **state)
{
	(void)state;
	char dir[256], db[300];
	assert_int_equal(ut_tmpdir_make(dir, sizeof dir, "test_job_helper"), 0);
	snprintf(db, sizeof db, "%s/state.db-shm", dir);
	int dbfd = open(db, O_RDWR | O_CREAT, 0600); /* no O_CLOEXEC: as a careless library might */
	assert_true(dbfd >= 0);
	assert_int_equal(ftruncate(dbfd, 32768), 0);
	void *map = mmap(NULL, 32768, PROT_READ | PROT_WRITE, MAP_SHARED, dbfd, 0);
	assert_true(map != MAP_FAILED);
	int wake[2];
	assert_int_equal(pipe(wake), 0);
	pthread_t th;
	assert_int_equal(pthread_create(&th, NULL, idle_thread, &wake[0]), 0);

	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	assert_int_equal(job_helper_start(NULL), 0);
	pid_t hp = job_helper_pid();
	assert_int_equal(kill(hp, SIGKILL), 0);
	assert_true(gone_within(hp, 5));
	pid_t hp2 = echo_on_new_helper(lp, hp, "after");
	char want[64];
	snprintf(want, sizeof want, "|ppid=%d|", (int)hp2);
	assert_non_null(strstr(got_out, want));

	bool found = false;
	int nfd = proc_fds(hp2, db, &found);
	print_message("restarted helper %d: %d descriptors, the database's among them: %s\n", (int)hp2, nfd,
		      found ? "yes" : "no");
	assert_false(found);
	assert_true(nfd <= 5); /* 0-2, its socket, its signalfd */
	assert_true(proc_has(getpid(), "maps", db)); /* the check sees a mapping where there is one */
	assert_false(proc_has(hp2, "maps", db));
	assert_true(proc_has(hp2, "cmdline", "acq-helper\n" JOB_HELPER_ARG "\n"));
	assert_true(proc_has(hp2, "status", "\nThreads:\t1\n"));
	char exe[2][4096];
	snprintf(want, sizeof want, "/proc/%d/exe", (int)hp2);
	ssize_t k0 = readlink("/proc/self/exe", exe[0], sizeof exe[0] - 1), k1 = readlink(want, exe[1], sizeof exe[1] - 1);
	assert_true(k0 > 0 && k0 == k1 && !memcmp(exe[0], exe[1], (size_t)k0));

	struct acq_err err = { 0 };
	assert_int_equal(job_fork_msg(&unlisted_kind, "x", 1, 0, 1024, 10, done, NULL, NULL, &err), -1);
	print_message("a kind not in the table: %s\n", err.msg);
	assert_non_null(strstr(err.msg, "unlisted"));
	assert_int_equal(job_count(), 0);

	job_finish();
	loop_free(lp);
	close(wake[1]);
	pthread_join(th, NULL);
	close(wake[0]);
	munmap(map, 32768);
	close(dbfd);
	ut_tmpdir_remove(dir);
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

int main(int argc, char **argv)
{
	job_kinds_main(argc, argv, kinds, sizeof kinds / sizeof kinds[0]); /* the helper: this program run again */
	signal(SIGPIPE, SIG_IGN);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_msg_pack),
		cmocka_unit_test(test_children_of_the_helper),
		cmocka_unit_test(test_cpu_bound),
		cmocka_unit_test(test_helper_lost_and_restarted),
		cmocka_unit_test(test_restarted_helper_holds_nothing),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
