/* Unit tests for daemon/loop.c: timers on an injected clock (order, periodic, cancel from a callback), fds. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/loop.h"

static double fake_now;
static double fake_clock(void *ctx)
{
	(void)ctx;
	return fake_now;
}

static char trace[64];
static int ntrace;
static void mark(struct loop *lp, void *arg)
{
	(void)lp;
	trace[ntrace++] = *(const char *)arg;
}

static void test_timer_order_and_period(void **state)
{
	(void)state;
	fake_now = 100;
	ntrace = 0;
	struct loop_clock clk = { .now = fake_clock };
	struct loop *lp = loop_new(&clk, NULL);
	assert_non_null(lp);
	assert_true(loop_next_timeout(lp) < 0);
	loop_timer_add(lp, 2.0, 0, mark, "b");
	loop_timer_add(lp, 1.0, 0, mark, "a");
	loop_timer_add(lp, 1.5, 1.0, mark, "p");
	assert_true(loop_next_timeout(lp) == 1.0);
	loop_run_once(lp, 0);
	assert_int_equal(ntrace, 0);
	fake_now = 101.6;
	loop_run_once(lp, 0);
	assert_int_equal(ntrace, 2);
	assert_memory_equal(trace, "ap", 2);
	fake_now = 102.6;
	loop_run_once(lp, 0);
	assert_memory_equal(trace, "apbp", 4);
	/* Missed periods are skipped, not burst: ten seconds later only one more "p". */
	fake_now = 112.6;
	loop_run_once(lp, 0);
	assert_int_equal(ntrace, 5);
	loop_free(lp);
}

static uint64_t self_id;
static int self_count;
static void cancel_self(struct loop *lp, void *arg)
{
	(void)arg;
	self_count++;
	loop_timer_cancel(lp, self_id);
}

static void test_cancel_inside_callback(void **state)
{
	(void)state;
	fake_now = 0;
	struct loop_clock clk = { .now = fake_clock };
	struct loop *lp = loop_new(&clk, NULL);
	self_count = 0;
	self_id = loop_timer_add(lp, 0.1, 0.1, cancel_self, NULL);
	assert_true(self_id > 0);
	for (int i = 1; i <= 5; i++) {
		fake_now = i;
		loop_run_once(lp, 0);
	}
	assert_int_equal(self_count, 1);
	assert_true(loop_next_timeout(lp) < 0);
	loop_timer_cancel(lp, 0);        /* ignored */
	loop_timer_cancel(lp, 123456);   /* ignored */
	loop_free(lp);
}

static int fd_hits;
static void on_read(struct loop *lp, int fd, short re, void *arg)
{
	(void)arg;
	assert_true(re & POLLIN);
	char c;
	assert_int_equal(read(fd, &c, 1), 1);
	fd_hits++;
	if (c == 'q')
		loop_fd_del(lp, fd);
}

static void test_fd_callbacks(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	int p[2];
	assert_int_equal(pipe(p), 0);
	fd_hits = 0;
	assert_int_equal(loop_fd_add(lp, p[0], POLLIN, on_read, NULL, NULL), 0);
	assert_int_equal(loop_fd_add(lp, p[0], POLLIN, on_read, NULL, NULL), -1); /* duplicate */
	assert_int_equal(loop_run_once(lp, 0), 0);
	assert_int_equal(write(p[1], "x", 1), 1);
	assert_int_equal(loop_run_once(lp, 1.0), 1);
	assert_int_equal(fd_hits, 1);
	assert_int_equal(write(p[1], "qz", 2), 2);
	loop_run_once(lp, 1.0);
	assert_int_equal(fd_hits, 2);
	loop_run_once(lp, 0); /* deleted: "z" stays unread */
	assert_int_equal(fd_hits, 2);
	close(p[0]);
	close(p[1]);
	loop_free(lp);
}

static void test_scaled_clock(void **state)
{
	(void)state;
	struct loop_scaled_clock sc = { 0, 20 };
	struct loop_clock clk = { .now = loop_scaled_now, .ctx = &sc, .rate = 20 };
	struct loop *lp = loop_new(&clk, NULL);
	ntrace = 0;
	double real0 = loop_monotonic(NULL), t0 = loop_now(lp);
	loop_timer_add(lp, 2.0, 0, mark, "s"); /* two bench seconds = 0.1 s of real time at 20× */
	while (!ntrace && loop_monotonic(NULL) - real0 < 5)
		loop_run_once(lp, -1);
	double real = loop_monotonic(NULL) - real0;
	assert_int_equal(ntrace, 1);
	assert_true(loop_now(lp) - t0 >= 2.0);
	assert_true(real >= 0.09 && real < 1.0);
	loop_free(lp);
}

/* A long round of fd callbacks (12 ready clients, 1 ms each) lets a timer that falls due during it and an urgent fd
 * that becomes ready during it (a device's completion) run in between, not after the whole round. */
struct round {
	int order, clients, timer_at, urgent_at, efd;
	int pipes[12][2];
};

static void spin_ms(double ms)
{
	struct timespec a, b;
	clock_gettime(CLOCK_MONOTONIC, &a);
	do
		clock_gettime(CLOCK_MONOTONIC, &b);
	while ((b.tv_sec - a.tv_sec) * 1e3 + (b.tv_nsec - a.tv_nsec) * 1e-6 < ms);
}

static void busy_client(struct loop *lp, int fd, short re, void *arg)
{
	(void)lp;
	(void)re;
	struct round *r = arg;
	char c;
	assert_int_equal(read(fd, &c, 1), 1);
	++r->order;
	if (++r->clients == 2) { /* the completion arrives while the round runs */
		uint64_t one = 1;
		assert_int_equal(write(r->efd, &one, sizeof one), (ssize_t)sizeof one);
	}
	spin_ms(1.0);
}

static void due_timer(struct loop *lp, void *arg)
{
	(void)lp;
	struct round *r = arg;
	r->timer_at = ++r->order;
}

static void completion(struct loop *lp, int fd, short re, void *arg)
{
	(void)lp;
	(void)re;
	struct round *r = arg;
	uint64_t n;
	if (read(fd, &n, sizeof n) == (ssize_t)sizeof n && !r->urgent_at)
		r->urgent_at = ++r->order;
}

static void test_long_round_yields(void **state)
{
	(void)state;
	struct round r = { 0 };
	struct loop *lp = loop_new(NULL, NULL);
	assert_non_null(lp);
	r.efd = eventfd(0, EFD_NONBLOCK);
	assert_true(r.efd >= 0);
	assert_int_equal(loop_fd_add(lp, r.efd, POLLIN, completion, &r, NULL), 0);
	loop_fd_urgent(lp, r.efd);
	for (int i = 0; i < 12; i++) {
		assert_int_equal(pipe(r.pipes[i]), 0);
		assert_int_equal(write(r.pipes[i][1], "x", 1), 1);
		assert_int_equal(loop_fd_add(lp, r.pipes[i][0], POLLIN, busy_client, &r, NULL), 0);
	}
	assert_true(loop_timer_add(lp, 0.003, 0, due_timer, &r) > 0);
	loop_run_once(lp, 0);
	/* 12 callbacks + the timer + the completion = 14 turns; without slicing both would come last (13, 14) or
	 * the completion in the next round. */
	print_message("timer ran at turn %d, the completion at turn %d (of 14)\n", r.timer_at, r.urgent_at);
	assert_true(r.timer_at > 0 && r.timer_at < 12);
	assert_true(r.urgent_at > 0 && r.urgent_at < 12);
	for (int i = 0; i < 12; i++) {
		loop_fd_del(lp, r.pipes[i][0]);
		close(r.pipes[i][0]);
		close(r.pipes[i][1]);
	}
	loop_fd_del(lp, r.efd);
	close(r.efd);
	loop_free(lp);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_timer_order_and_period),
		cmocka_unit_test(test_cancel_inside_callback),
		cmocka_unit_test(test_fd_callbacks),
		cmocka_unit_test(test_scaled_clock),
		cmocka_unit_test(test_long_round_yields),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
