/* port: a device's I/O thread with a request queue and a completion eventfd (port.h). */
#include "daemon/port.h"

#include <errno.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <time.h>
#include <unistd.h>

#include "daemon/cputime.h"
#include "daemon/loop.h"
#include "daemon/stall.h"

struct port {
	struct loop *lp;
	char name[64];
	pthread_t thread;
	pthread_mutex_t mu;
	pthread_cond_t cv;            /* work queued, interrupt or quit */
	struct port_req *head, *tail; /* queued */
	struct port_req *done_head, *done_tail;
	int npending;                 /* queued + running + completed not yet dispatched (loop side count) */
	unsigned long interrupt_gen;  /* bumped by port_interrupt() */
	unsigned long run_gen;        /* the generation the running request was submitted in */
	bool quit;
	bool running;                 /* the thread is running a request */
	pthread_cond_t idle;          /* the queue ran empty and nothing runs */
	int efd;
	void (*tick_fn)(void *arg, struct port *p); /* port_set_tick() */
	void *tick_arg;
	double tick_period, tick_next;              /* real (CLOCK_MONOTONIC) seconds */
	bool tick_yield;                            /* the job overran its period: a queued request goes first */
};

static double mono_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static struct timespec mono_at(double t)
{
	struct timespec ts;
	ts.tv_sec = (time_t)t;
	ts.tv_nsec = (long)((t - (double)ts.tv_sec) * 1e9);
	return ts;
}

static void push(struct port_req **head, struct port_req **tail, struct port_req *r)
{
	r->next = NULL;
	if (*tail)
		(*tail)->next = r;
	else
		*head = r;
	*tail = r;
}

static struct port_req *pop(struct port_req **head, struct port_req **tail)
{
	struct port_req *r = *head;
	if (r) {
		*head = r->next;
		if (!*head)
			*tail = NULL;
		r->next = NULL;
	}
	return r;
}

static void *thread_main(void *arg)
{
	struct port *p = arg;
	pthread_mutex_lock(&p->mu);
	for (;;) {
		/* The periodic job first whenever it is due, then the next request; idle, sleep until either. A job that
		 * overran its period (a device that does not answer: the laser's keep-alive refresh waits its timeout)
		 * lets one queued request run before it runs again, else it would starve the queue for good. */
		for (;;) {
			if (p->tick_fn && !p->quit && mono_now() >= p->tick_next && !(p->tick_yield && p->head)) {
				void (*fn)(void *, struct port *) = p->tick_fn;
				void *targ = p->tick_arg;
				pthread_mutex_unlock(&p->mu);
				double t0 = mono_now();
				fn(targ, p);
				double t1 = mono_now();
				pthread_mutex_lock(&p->mu);
				p->tick_next = t0 + p->tick_period;
				p->tick_yield = t1 >= p->tick_next;
				continue;
			}
			if (p->head || p->quit)
				break;
			if (p->tick_fn) {
				struct timespec ts = mono_at(p->tick_next);
				pthread_cond_timedwait(&p->cv, &p->mu, &ts);
			} else {
				pthread_cond_wait(&p->cv, &p->mu);
			}
		}
		struct port_req *r = pop(&p->head, &p->tail);
		if (!r)
			break; /* quit with an empty queue */
		p->tick_yield = false;
		p->run_gen = r->gen; /* queued before an interrupt: interrupted too */
		p->running = true;
		pthread_mutex_unlock(&p->mu);
		struct cputime c0, c1;
		cputime_thread(&c0);
		double t0 = mono_now();
		r->run(r, p);
		r->ended_at = mono_now();
		r->took_s = r->ended_at - t0;
		cputime_thread(&c1);
		r->on_cpu_s = c1.on_cpu - c0.on_cpu;
		r->cpu_wait_s = c1.waiting - c0.waiting;
		pthread_mutex_lock(&p->mu);
		push(&p->done_head, &p->done_tail, r);
		p->running = false;
		if (!p->head)
			pthread_cond_broadcast(&p->idle);
		uint64_t one = 1;
		if (write(p->efd, &one, sizeof one) < 0 && errno != EAGAIN) {
			/* cannot happen with a valid eventfd; the loop still finds the request at the next wake-up */
		}
	}
	pthread_mutex_unlock(&p->mu);
	return NULL;
}

static void dispatch(struct port *p)
{
	for (;;) {
		pthread_mutex_lock(&p->mu);
		struct port_req *r = pop(&p->done_head, &p->done_tail);
		if (r)
			p->npending--;
		pthread_mutex_unlock(&p->mu);
		if (!r)
			return;
		stall_port_req(p->name, r->ended_at - r->took_s - r->submitted_at, r->took_s, r->on_cpu_s,
			       r->cpu_wait_s, mono_now() - r->ended_at, r->yields);
		r->done(r);
	}
}

static void on_efd(struct loop *lp, int fd, short revents, void *arg)
{
	(void)lp;
	(void)revents;
	uint64_t n;
	if (read(fd, &n, sizeof n) < 0 && errno != EAGAIN)
		return;
	double t0 = mono_now();
	dispatch(arg);
	stall_devices(mono_now() - t0);
}

int port_new(struct loop *lp, const char *name, struct port **out, struct acq_err *err)
{
	*out = NULL;
	struct port *p = calloc(1, sizeof *p);
	if (!p)
		return acq_errf(err, ACQ_E_NOMEM, "port %s: out of memory", name);
	p->lp = lp;
	snprintf(p->name, sizeof p->name, "%s", name);
	p->efd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
	if (p->efd < 0) {
		free(p);
		return acq_errf(err, ACQ_E_IO, "port %s: eventfd: %s", name, strerror(errno));
	}
	pthread_mutex_init(&p->mu, NULL);
	pthread_condattr_t ca; /* timed waits on the monotonic clock: a wall-clock step changes no period */
	pthread_condattr_init(&ca);
	pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
	pthread_cond_init(&p->cv, &ca);
	pthread_condattr_destroy(&ca);
	pthread_cond_init(&p->idle, NULL);
	if (loop_fd_add(lp, p->efd, POLLIN, on_efd, p, err)) {
		close(p->efd);
		free(p);
		return -1;
	}
	loop_fd_urgent(lp, p->efd); /* completions are the devices' answers the sweep waits for */
	int e = pthread_create(&p->thread, NULL, thread_main, p);
	if (e) {
		loop_fd_del(lp, p->efd);
		close(p->efd);
		free(p);
		return acq_errf(err, ACQ_E_IO, "port %s: thread: %s", name, strerror(e));
	}
	*out = p;
	return 0;
}

void port_set_tick(struct port *p, double period_s, void (*fn)(void *arg, struct port *p), void *arg)
{
	pthread_mutex_lock(&p->mu);
	p->tick_fn = period_s > 0 ? fn : NULL;
	p->tick_arg = arg;
	p->tick_period = period_s;
	p->tick_next = mono_now();
	pthread_cond_broadcast(&p->cv);
	pthread_mutex_unlock(&p->mu);
}

void port_submit(struct port *p, struct port_req *r)
{
	pthread_mutex_lock(&p->mu);
	r->gen = p->interrupt_gen;
	r->submitted_at = mono_now();
	if (r->yields || !p->tail || !p->tail->yields) {
		push(&p->head, &p->tail, r);
	} else { /* before the first yielding request */
		struct port_req **at = &p->head;
		while (*at && !(*at)->yields)
			at = &(*at)->next;
		r->next = *at;
		*at = r;
	}
	p->npending++;
	pthread_cond_signal(&p->cv);
	pthread_mutex_unlock(&p->mu);
}

void port_interrupt(struct port *p)
{
	pthread_mutex_lock(&p->mu);
	p->interrupt_gen++;
	pthread_cond_broadcast(&p->cv);
	pthread_mutex_unlock(&p->mu);
}

bool port_interrupted(struct port *p)
{
	struct port *q = p;
	pthread_mutex_lock(&q->mu);
	bool i = q->run_gen != q->interrupt_gen;
	pthread_mutex_unlock(&q->mu);
	return i;
}

double port_now(const struct port *p)
{
	return loop_now(p->lp);
}

void port_wait(struct port *p, double clock_s, int fd)
{
	port_wait_real(p, clock_s / loop_rate(p->lp), fd);
}

void port_wait_real(struct port *p, double real, int fd)
{
	if (!(real > 0))
		return;
	if (real > 60)
		real = 60;
	if (fd >= 0) {
		struct pollfd pfd = { .fd = fd, .events = POLLIN };
		poll(&pfd, 1, (int)ceil(real * 1e3));
		return;
	}
	struct timespec ts = mono_at(mono_now() + real);
	pthread_mutex_lock(&p->mu);
	while (p->run_gen == p->interrupt_gen && !p->quit)
		if (pthread_cond_timedwait(&p->cv, &p->mu, &ts) == ETIMEDOUT)
			break;
	pthread_mutex_unlock(&p->mu);
}

void port_flush(struct port *p)
{
	pthread_mutex_lock(&p->mu);
	while (p->head || p->running)
		pthread_cond_wait(&p->idle, &p->mu);
	pthread_mutex_unlock(&p->mu);
	dispatch(p);
}

void port_free(struct port *p)
{
	if (!p)
		return;
	pthread_mutex_lock(&p->mu);
	p->quit = true; /* the thread empties the queue first, then exits */
	pthread_cond_broadcast(&p->cv);
	pthread_mutex_unlock(&p->mu);
	pthread_join(p->thread, NULL);
	dispatch(p);
	loop_fd_del(p->lp, p->efd);
	close(p->efd);
	pthread_mutex_destroy(&p->mu);
	pthread_cond_destroy(&p->cv);
	pthread_cond_destroy(&p->idle);
	free(p);
}
