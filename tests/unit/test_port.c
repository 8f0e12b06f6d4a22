/* test_port: a port's queue runs the sweep's requests ahead of the yielding ones (clients' status reads), each
 * kind first in, first out, and reports each request's wait in the queue. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/loop.h"
#include "daemon/port.h"

struct treq {
	struct port_req pr;
	char name;
	int gate;          /* >= 0: the first request waits until this fd is readable */
	char *log;         /* run order, one letter each (written on the port's thread) */
	int *done;
};

static void t_run(struct port_req *pr, struct port *p)
{
	struct treq *r = (struct treq *)pr;
	if (r->gate >= 0)
		port_wait_real(p, 10, r->gate); /* busy: the others queue behind it */
	size_t n = strlen(r->log);
	r->log[n] = r->name;
	r->log[n + 1] = 0;
}

static void t_done(struct port_req *pr)
{
	struct treq *r = (struct treq *)pr;
	++*r->done;
}

static void test_yielding_requests_go_last(void **state)
{
	(void)state;
	struct loop *lp = loop_new(NULL, NULL);
	struct port *p = NULL;
	assert_int_equal(port_new(lp, "test", &p, NULL), 0);
	int gate[2];
	assert_int_equal(pipe(gate), 0);
	char log[16] = "";
	int done = 0;
	/* '0' holds the thread; then client read a, sweep command X, client read b, sweep command Y */
	static const char names[] = "0aXbY";
	static const bool yields[] = { false, true, false, true, false };
	struct treq r[5];
	for (int i = 0; i < 5; i++) {
		r[i] = (struct treq){ .pr = { .run = t_run, .done = t_done, .yields = yields[i] }, .name = names[i],
				      .gate = i == 0 ? gate[0] : -1, .log = log, .done = &done };
		port_submit(p, &r[i].pr);
	}
	assert_int_equal(write(gate[1], "g", 1), 1);
	port_flush(p);
	assert_int_equal(done, 5);
	assert_string_equal(log, "0XYab");
	/* each one's time in the queue: the commands waited less than the reads queued before them */
	assert_true(r[2].pr.submitted_at > 0 && r[2].pr.ended_at >= r[2].pr.submitted_at);
	assert_true(r[1].pr.ended_at > r[4].pr.ended_at);
	port_free(p);
	close(gate[0]);
	close(gate[1]);
	loop_free(lp);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_yielding_requests_go_last),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
