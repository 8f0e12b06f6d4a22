/* loop: one poll(2) loop with fd callbacks and timers on an injectable clock (see loop.h). */
#include "daemon/loop.h"

#include <errno.h>
#include <math.h>
#include <poll.h>
#include <stdlib.h>
#include <time.h>

#include "daemon/stall.h"

/* Real seconds of fd callbacks in one round before the due timers and the urgent fds get a turn in between. */
#define LOOP_SLICE_S 0.002

struct loop_fd {
	int fd;
	short events;
	bool dead;
	bool urgent;      /* loop_fd_urgent() */
	loop_fd_cb cb;
	void *arg;
};

struct loop_timer {
	uint64_t id;
	double due, period;
	loop_timer_cb cb;
	void *arg;
};

struct loop {
	struct loop_clock clk;
	struct loop_fd *fds;
	size_t nfds, capfds;
	struct pollfd *pfds;
	size_t cappfds;
	/* Timers: a small unsorted array; the daemon has a handful (device polls, watchdog, sweep step). */
	struct loop_timer *timers;
	size_t ntimers, captimers;
	uint64_t next_id;
	bool stop;
};

double loop_monotonic(void *ctx)
{
	(void)ctx;
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

double loop_scaled_now(void *ctx)
{
	struct loop_scaled_clock *sc = ctx;
	double real = loop_monotonic(NULL);
	if (sc->t0 == 0)
		sc->t0 = real;
	return sc->t0 + (real - sc->t0) * (sc->rate > 0 ? sc->rate : 1);
}

struct loop *loop_new(const struct loop_clock *clk, struct acq_err *err)
{
	struct loop *lp = calloc(1, sizeof *lp);
	if (!lp) {
		acq_errf(err, ACQ_E_NOMEM, "loop: out of memory");
		return NULL;
	}
	if (clk && clk->now)
		lp->clk = *clk;
	else
		lp->clk.now = loop_monotonic;
	if (!(lp->clk.rate > 0))
		lp->clk.rate = 1;
	lp->next_id = 1;
	return lp;
}

void loop_free(struct loop *lp)
{
	if (!lp)
		return;
	free(lp->fds);
	free(lp->pfds);
	free(lp->timers);
	free(lp);
}

double loop_rate(const struct loop *lp)
{
	return lp->clk.rate;
}

double loop_now(const struct loop *lp)
{
	return lp->clk.now(lp->clk.ctx);
}

static struct loop_fd *find_fd(struct loop *lp, int fd)
{
	for (size_t i = 0; i < lp->nfds; i++)
		if (lp->fds[i].fd == fd && !lp->fds[i].dead)
			return &lp->fds[i];
	return NULL;
}

int loop_fd_add(struct loop *lp, int fd, short events, loop_fd_cb cb, void *arg, struct acq_err *err)
{
	if (fd < 0 || !cb)
		return acq_errf(err, ACQ_E_INVAL, "loop: bad fd %d or callback", fd);
	if (find_fd(lp, fd))
		return acq_errf(err, ACQ_E_STATE, "loop: fd %d already registered", fd);
	if (lp->nfds == lp->capfds) {
		size_t c = lp->capfds ? lp->capfds * 2 : 16;
		struct loop_fd *n = realloc(lp->fds, c * sizeof *n);
		if (!n)
			return acq_errf(err, ACQ_E_NOMEM, "loop: out of memory");
		lp->fds = n;
		lp->capfds = c;
	}
	lp->fds[lp->nfds++] = (struct loop_fd){ .fd = fd, .events = events, .cb = cb, .arg = arg };
	return 0;
}

int loop_fd_events(struct loop *lp, int fd, short events)
{
	struct loop_fd *f = find_fd(lp, fd);
	if (!f)
		return -1;
	f->events = events;
	return 0;
}

void loop_fd_del(struct loop *lp, int fd)
{
	/* Marked dead, compacted after dispatch, so deleting from a callback never shifts the array in use. */
	struct loop_fd *f = find_fd(lp, fd);
	if (f)
		f->dead = true;
}

uint64_t loop_timer_add(struct loop *lp, double delay_s, double period_s, loop_timer_cb cb, void *arg)
{
	if (!cb || !isfinite(delay_s) || !isfinite(period_s))
		return 0;
	if (lp->ntimers == lp->captimers) {
		size_t c = lp->captimers ? lp->captimers * 2 : 16;
		struct loop_timer *n = realloc(lp->timers, c * sizeof *n);
		if (!n)
			return 0;
		lp->timers = n;
		lp->captimers = c;
	}
	uint64_t id = lp->next_id++;
	lp->timers[lp->ntimers++] = (struct loop_timer){
		.id = id, .due = loop_now(lp) + (delay_s > 0 ? delay_s : 0), .period = period_s > 0 ? period_s : 0,
		.cb = cb, .arg = arg };
	return id;
}

void loop_timer_cancel(struct loop *lp, uint64_t id)
{
	if (!id)
		return;
	for (size_t i = 0; i < lp->ntimers; i++)
		if (lp->timers[i].id == id) {
			lp->timers[i] = lp->timers[--lp->ntimers];
			return;
		}
}

double loop_next_timeout(const struct loop *lp)
{
	if (!lp->ntimers)
		return -1;
	double best = lp->timers[0].due;
	for (size_t i = 1; i < lp->ntimers; i++)
		if (lp->timers[i].due < best)
			best = lp->timers[i].due;
	double d = best - loop_now(lp);
	return d > 0 ? d : 0;
}

/* Run every timer due now, earliest first; a callback may add or cancel timers (looked up by id each time). */
static int run_timers(struct loop *lp)
{
	int ran = 0;
	double now = loop_now(lp);
	for (int guard = 0; guard < 10000; guard++) {
		size_t best = (size_t)-1;
		for (size_t i = 0; i < lp->ntimers; i++)
			if (lp->timers[i].due <= now && (best == (size_t)-1 || lp->timers[i].due < lp->timers[best].due))
				best = i;
		if (best == (size_t)-1)
			break;
		struct loop_timer t = lp->timers[best];
		if (t.period > 0) {
			/* Periodic: next due from the schedule, skipping missed periods rather than bursting. */
			double due = t.due + t.period;
			if (due <= now)
				due = now + t.period;
			lp->timers[best].due = due;
		} else {
			lp->timers[best] = lp->timers[--lp->ntimers];
		}
		double t0 = stall_now(), c0 = stall_cpu();
		stall_timer_late((loop_now(lp) - t.due) / lp->clk.rate);
		t.cb(lp, t.arg);
		stall_callback(stall_now() - t0, stall_cpu() - c0, (uintptr_t)t.cb);
		ran++;
	}
	return ran;
}

void loop_fd_urgent(struct loop *lp, int fd)
{
	struct loop_fd *f = find_fd(lp, fd);
	if (f)
		f->urgent = true;
}

/* In the middle of a round of fd callbacks: the timers due, then the urgent fds ready now (their own poll). */
static int run_urgent(struct loop *lp)
{
	int ran = run_timers(lp);
	for (size_t i = 0; i < lp->nfds; i++) {
		if (!lp->fds[i].urgent || lp->fds[i].dead)
			continue;
		struct pollfd p = { .fd = lp->fds[i].fd, .events = lp->fds[i].events };
		if (poll(&p, 1, 0) != 1 || !p.revents)
			continue;
		loop_fd_cb cb = lp->fds[i].cb; /* the callback may add fds (the array moves) */
		void *arg = lp->fds[i].arg;
		double t0 = stall_now(), c0 = stall_cpu();
		cb(lp, p.fd, p.revents, arg);
		stall_callback(stall_now() - t0, stall_cpu() - c0, (uintptr_t)cb);
		ran++;
	}
	return ran;
}

static void compact_fds(struct loop *lp)
{
	size_t j = 0;
	for (size_t i = 0; i < lp->nfds; i++)
		if (!lp->fds[i].dead)
			lp->fds[j++] = lp->fds[i];
	lp->nfds = j;
}

int loop_run_once(struct loop *lp, double max_wait_s)
{
	int ran = run_timers(lp);
	compact_fds(lp);
	double wait = loop_next_timeout(lp);
	if (ran)
		wait = 0; /* timers may have changed fd interest; poll without waiting once */
	if (max_wait_s >= 0 && (wait < 0 || max_wait_s < wait))
		wait = max_wait_s;
	/* Clock seconds to real milliseconds (a scaled clock waits less); at most a minute per poll. */
	double real_ms = wait < 0 ? -1 : ceil(wait / lp->clk.rate * 1000.0);
	int timeout_ms = real_ms < 0 ? -1 : real_ms > 60000 ? 60000 : (int)real_ms;
	if (lp->nfds > lp->cappfds) {
		struct pollfd *p = realloc(lp->pfds, lp->nfds * sizeof *p);
		if (!p)
			return -1;
		lp->pfds = p;
		lp->cappfds = lp->nfds;
	}
	size_t n = lp->nfds;
	for (size_t i = 0; i < n; i++)
		lp->pfds[i] = (struct pollfd){ .fd = lp->fds[i].fd, .events = lp->fds[i].events };
	int rc = poll(lp->pfds, (nfds_t)n, timeout_ms);
	if (rc < 0)
		return errno == EINTR ? ran : -1;
	double slice_from = stall_now();
	for (size_t i = 0; i < n && rc > 0; i++) {
		/* A long round (many clients) does not hold up the sweep's steps and the devices' completions. */
		if (stall_now() - slice_from > LOOP_SLICE_S) {
			ran += run_urgent(lp);
			slice_from = stall_now();
		}
		short re = lp->pfds[i].revents;
		if (!re)
			continue;
		rc--;
		/* The registration may have been deleted (and its fd number reused) by an earlier callback. */
		struct loop_fd *f = &lp->fds[i];
		if (f->dead || f->fd != lp->pfds[i].fd)
			continue;
		double t0 = stall_now(), c0 = stall_cpu();
		loop_fd_cb cb = f->cb;
		f->cb(lp, f->fd, re, f->arg);
		stall_callback(stall_now() - t0, stall_cpu() - c0, (uintptr_t)cb);
		ran++;
	}
	ran += run_timers(lp);
	return ran;
}

int loop_run(struct loop *lp)
{
	lp->stop = false;
	while (!lp->stop)
		if (loop_run_once(lp, -1) < 0)
			return -1;
	return 0;
}

void loop_stop(struct loop *lp)
{
	lp->stop = true;
}
