/* Unit tests for daemon/loop.c: timers on an injected clock (order, periodic, cancel from a callback), fds. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <poll.h>
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

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_timer_order_and_period),
		cmocka_unit_test(test_cancel_inside_callback),
		cmocka_unit_test(test_fd_callbacks),
		cmocka_unit_test(test_scaled_clock),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
