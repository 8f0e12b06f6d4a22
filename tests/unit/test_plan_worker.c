/* Unit tests for daemon/plan_worker.c and the job.c pieces it uses: a child's binary output of megabytes comes
 * back whole (job_fork_msg) or flagged truncated past its bound; job_kill ends a child with status 128 + 9; a
 * sweep planned in the worker equals the same plan made in process (steps, waypoints, predicted times); the
 * deadline and abort end it with a message; a damaged reply is refused with a message, never used. */
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "config/bench.h"
#include "daemon/job.h"
#include "daemon/loop.h"
#include "daemon/plan_worker.h"

static int calls, got_status;
static size_t got_len;
static char *got_out;
static bool got_trunc;

static void done(struct job *j, int status, const char *out, size_t len, void *arg)
{
	(void)arg;
	calls++;
	got_status = status;
	got_len = len;
	got_trunc = job_output_truncated(j);
	free(got_out);
	got_out = malloc(len + 1);
	memcpy(got_out, out, len + 1);
}

static void run_until(struct loop *lp, int *n, double deadline)
{
	double t0 = loop_now(lp);
	while (!*n && loop_now(lp) - t0 < deadline) {
		loop_run_once(lp, 0.02);
		job_reap();
	}
}

#define BIG (3u << 20)

/* A byte pattern that shows a lost, repeated or reordered chunk. */
static unsigned char pat(size_t i)
{
	return (unsigned char)((i * 2654435761u) >> 13);
}

static int big_child(const char *payload, size_t len, int fd)
{
	(void)payload;
	(void)len;
	static unsigned char buf[BIG];
	for (size_t i = 0; i < BIG; i++)
		buf[i] = pat(i);
	for (size_t off = 0; off < BIG;) {
		ssize_t w = write(fd, buf + off, BIG - off);
		if (w <= 0)
			return 2;
		off += (size_t)w;
	}
	return 0;
}

static int sleeping_child(const char *payload, size_t len, int fd)
{
	(void)payload;
	(void)len;
	(void)fd;
	sleep(30);
	return 0;
}

static const struct job_kind big_kind = { "big", big_child }, sleeping_kind = { "sleeping", sleeping_child };

static void test_fork_out_big_and_kill(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	calls = 0;
	assert_int_equal(job_fork_msg(&big_kind, "", 0, 0, 8u << 20, 10, done, NULL, NULL, NULL), 0);
	run_until(lp, &calls, 10);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 0);
	assert_false(got_trunc);
	assert_int_equal(got_len, BIG);
	for (size_t i = 0; i < BIG; i++)
		if ((unsigned char)got_out[i] != pat(i))
			fail_msg("byte %zu differs", i);
	/* past its bound: the first out_max bytes, flagged */
	calls = 0;
	assert_int_equal(job_fork_msg(&big_kind, "", 0, 0, 1u << 20, 10, done, NULL, NULL, NULL), 0);
	run_until(lp, &calls, 10);
	assert_int_equal(calls, 1);
	assert_true(got_trunc);
	assert_int_equal(got_len, 1u << 20);
	assert_int_equal((unsigned char)got_out[12345], pat(12345));
	/* job_kill */
	calls = 0;
	struct job *j = NULL;
	assert_int_equal(job_fork_msg(&sleeping_kind, "", 0, 0, 1024, 0, done, NULL, &j, NULL), 0);
	job_kill(j);
	run_until(lp, &calls, 5);
	assert_int_equal(calls, 1);
	assert_int_equal(got_status, 128 + SIGKILL);
	job_finish();
	loop_free(lp);
	free(got_out);
	got_out = NULL;
}

static int pw_calls, pw_rc;
static struct plan_result *pw_plan;
static struct acq_err pw_err;

static void pw_done(void *ctx, int rc, const struct acq_err *err, struct plan_result *plan)
{
	(void)ctx;
	pw_calls++;
	pw_rc = rc;
	pw_plan = plan;
	if (err)
		pw_err = *err;
}

static const char *const PLAN = "name: t\nincidence:\n  theta_deg: [10, 35, 60]\nobservation:\n"
				"  fibonacci: {count: 40, max_theta_deg: 80}\nintegration: {mode: fixed, ms: 20}\n"
				"averages: 2\nblind_points: move\n";

static const char *const BIGPLAN = "name: big\nincidence:\n  theta_deg: [0, 8, 16, 24, 32, 40, 48, 56, 64, 72]\n"
				   "observation:\n  fibonacci: {count: 1000, max_theta_deg: 85}\n"
				   "integration: {mode: fixed, ms: 20}\naverages: 1\nblind_points: move\n";

static bool same_pos(const struct plan_pos *a, const struct plan_pos *b)
{
	return a->laser_theta == b->laser_theta && a->det_theta == b->det_theta && a->det_phi == b->det_phi;
}

static void test_worker_equals_in_process(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	job_init(lp);
	struct bench_geom g;
	bench_defaults(&g);
	struct plan_timing tm;
	plan_timing_defaults(&tm);
	struct acq_err err = { 0 };
	struct plan_spec *spec = NULL;
	assert_int_equal(plan_load_string("t.yaml", PLAN, &spec, &err), 0);
	struct plan_result *ref = NULL;
	assert_int_equal(plan_make(spec, &g, &ref, &err), 0);
	plan_time_apply(spec, &g, &tm, ref);
	assert_true(ref->n_steps > 50 && ref->n_wps >= ref->n_steps);

	pw_calls = 0;
	assert_int_equal(plan_worker_start("t.yaml", PLAN, &g, &tm, (size_t)1 << 30, 30, 30, pw_done, NULL, NULL, &err), 0);
	run_until(lp, &pw_calls, 30);
	assert_int_equal(pw_calls, 1);
	assert_int_equal(pw_rc, 0);
	struct plan_result *r = pw_plan;
	assert_int_equal(r->n_req, ref->n_req);
	assert_int_equal(r->n_steps, ref->n_steps);
	assert_int_equal(r->n_wps, ref->n_wps);
	/* field by field: padding bytes are not part of the plan */
	for (size_t i = 0; i < ref->n_req; i++) {
		const struct plan_req *a = &r->req[i], *b = &ref->req[i];
		assert_true(same_pos(&a->req, &b->req) && same_pos(&a->pos, &b->pos) && a->status == b->status &&
			    a->reason == b->reason && a->moved_deg == b->moved_deg && a->role == b->role &&
			    a->partner == b->partner && a->same_as == b->same_as && a->psi_deg == b->psi_deg);
	}
	for (size_t i = 0; i < ref->n_steps; i++) {
		const struct plan_step *a = &r->steps[i], *b = &ref->steps[i];
		assert_true(a->req == b->req && same_pos(&a->pos, &b->pos) && a->first_wp == b->first_wp &&
			    a->n_wp == b->n_wp && a->move_s == b->move_s && a->settle_s == b->settle_s &&
			    a->dwell_s == b->dwell_s && a->t_start_s == b->t_start_s &&
			    a->predicted_start_s == b->predicted_start_s && a->predicted_s == b->predicted_s &&
			    a->detour == b->detour);
	}
	for (size_t i = 0; i < ref->n_wps; i++)
		assert_true(same_pos(&r->wps[i].pos, &ref->wps[i].pos) && r->wps[i].duration_s == ref->wps[i].duration_s);
	assert_true(r->predicted_s == ref->predicted_s && r->duration_s == ref->duration_s);
	assert_true(r->predicted_s > 0);
	plan_result_free(r);

	/* the deadline: a plan that takes longer is refused with the bound in the message */
	struct plan_spec *big = NULL;
	assert_int_equal(plan_load_string("big.yaml", BIGPLAN, &big, &err), 0);
	pw_calls = 0;
	assert_int_equal(plan_worker_start("big.yaml", BIGPLAN, &g, &tm, (size_t)1 << 30, 0.05, 7, pw_done, NULL, NULL, &err), 0);
	run_until(lp, &pw_calls, 30);
	assert_int_equal(pw_calls, 1);
	assert_int_equal(pw_rc, -1);
	assert_null(pw_plan);
	print_message("deadline: %s\n", pw_err.msg);
	assert_non_null(strstr(pw_err.msg, "not planned within 7 s"));
	plan_spec_free(big);

	/* abort: done() says so */
	pw_calls = 0;
	struct plan_worker *w = NULL;
	assert_int_equal(plan_worker_start("t.yaml", PLAN, &g, &tm, (size_t)1 << 30, 30, 30, pw_done, NULL, &w, &err), 0);
	plan_worker_abort(w);
	run_until(lp, &pw_calls, 10);
	assert_int_equal(pw_calls, 1);
	assert_int_equal(pw_rc, -1);
	assert_non_null(strstr(pw_err.msg, "aborted while planning"));

	/* damaged replies: encode in process, then break it */
	int p[2];
	assert_int_equal(pipe(p), 0);
	size_t n = 0, cap = 64u << 20;
	char *buf = malloc(cap);
	if (fork() == 0) {
		close(p[0]);
		_exit(plan_worker_encode(ref, p[1]) ? 1 : 0);
	}
	close(p[1]);
	for (ssize_t k; (k = read(p[0], buf + n, cap - n)) > 0;)
		n += (size_t)k;
	close(p[0]);
	struct plan_result *back = NULL;
	assert_int_equal(plan_worker_decode(buf, n, &back, &err), 0);
	assert_int_equal(back->n_steps, ref->n_steps);
	plan_result_free(back);
	assert_int_equal(plan_worker_decode(buf, n - 1, &back, &err), -1); /* one byte short */
	assert_null(back);
	print_message("short reply: %s\n", err.msg);
	assert_int_equal(plan_worker_decode(buf, 10, &back, &err), -1);
	char *bad = malloc(n);
	memcpy(bad, buf, n);
	bad[0] ^= 1; /* magic */
	assert_int_equal(plan_worker_decode(bad, n, &back, &err), -1);
	/* a step that refers past the points */
	memcpy(bad, buf, n);
	size_t off = n - ref->n_wps * sizeof *ref->wps - ref->n_steps * sizeof *ref->steps;
	struct plan_step st;
	memcpy(&st, bad + off, sizeof st);
	st.req = ref->n_req;
	memcpy(bad + off, &st, sizeof st);
	assert_int_equal(plan_worker_decode(bad, n, &back, &err), -1);
	assert_non_null(strstr(err.msg, "refers outside"));
	free(bad);
	free(buf);
	plan_result_free(ref);
	plan_spec_free(spec);
	job_finish();
	loop_free(lp);
}

int main(int argc, char **argv)
{
	static const struct job_kind *const kinds[] = { &plan_worker_kind, &big_kind, &sleeping_kind };
	job_kinds_main(argc, argv, kinds, sizeof kinds / sizeof kinds[0]); /* the helper: this program run again */
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_fork_out_big_and_kill),
		cmocka_unit_test(test_worker_equals_in_process),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
