/* loop: the daemon's single poll(2) event loop — file-descriptor callbacks and one-shot/periodic timers on an
 * injectable monotonic clock, so tests and the simulator can drive time. */
#ifndef LOOP_H
#define LOOP_H

#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"

struct loop;

/* The loop's clock: now() returns monotonic seconds. NULL clock in loop_new() means CLOCK_MONOTONIC.
 * rate: clock seconds per real second while poll(2) waits (0 or 1: real time; 10: a simulated bench
 * running ten times faster). A fake clock that tests step by hand is used with loop_run_once(lp, 0). */
struct loop_clock {
	double (*now)(void *ctx);
	void *ctx;
	double rate;
};

/* A monotonic clock running rate times faster than real time from now on (for --sim time scales). */
struct loop_scaled_clock {
	double t0, rate;
};
/* now() of a struct loop_scaled_clock (ctx); t0 = 0 initialises it on first use. */
double loop_scaled_now(void *ctx);

typedef void (*loop_fd_cb)(struct loop *lp, int fd, short revents, void *arg);
typedef void (*loop_timer_cb)(struct loop *lp, void *arg);

/* Create a loop on clock clk (copied; NULL = real monotonic clock). NULL on failure with err. */
struct loop *loop_new(const struct loop_clock *clk, struct acq_err *err);
/* Free the loop (does not close registered fds). NULL is fine. */
void loop_free(struct loop *lp);
/* Current time of the loop's clock, monotonic seconds. */
double loop_now(const struct loop *lp);
/* Clock seconds per real second (1 for real time, the time scale with --sim). */
double loop_rate(const struct loop *lp);
/* Real CLOCK_MONOTONIC seconds (the default clock). */
double loop_monotonic(void *ctx);

/* Watch fd for events (POLLIN/POLLOUT); one registration per fd. 0 or -1 (duplicate, no memory). */
int loop_fd_add(struct loop *lp, int fd, short events, loop_fd_cb cb, void *arg, struct acq_err *err);
/* Change the events watched on a registered fd. 0 or -1 if fd is not registered. */
int loop_fd_events(struct loop *lp, int fd, short events);
/* Mark a registered fd urgent: when a round of fd callbacks runs long (many ready clients), the due timers run
 * and the urgent fds are polled again and served between two callbacks, not after the whole round. An urgent
 * fd's callback may then also see readiness the poll reported before it was served: it must read non-blocking. */
void loop_fd_urgent(struct loop *lp, int fd);
/* Stop watching fd (safe from inside callbacks). Unknown fd is ignored. */
void loop_fd_del(struct loop *lp, int fd);

/* Timer firing after delay_s, then every period_s if period_s > 0. Returns an id > 0, or 0 on failure. */
uint64_t loop_timer_add(struct loop *lp, double delay_s, double period_s, loop_timer_cb cb, void *arg);
/* Cancel a timer (safe from inside its own callback; unknown or 0 id ignored). */
void loop_timer_cancel(struct loop *lp, uint64_t id);
/* Seconds until the next timer is due (0 if overdue), or -1 when no timer is armed. */
double loop_next_timeout(const struct loop *lp);

/* Run due timers, poll fds at most max_wait_s (-1 = until the next timer or forever), dispatch ready fds.
 * Returns the number of callbacks run, or -1 on a poll error other than EINTR. */
int loop_run_once(struct loop *lp, double max_wait_s);
/* Run until loop_stop(). 0, or -1 on a poll error. */
int loop_run(struct loop *lp);
/* Make loop_run() return after the current iteration. */
void loop_stop(struct loop *lp);

#endif
