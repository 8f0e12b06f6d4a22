/* port: one I/O thread per device port, as EPICS asyn gives each port a thread. The loop submits requests to
 * the port's FIFO queue; the port's thread runs them (the only place where a device call may block); finished
 * requests come back through a completion queue whose eventfd the loop polls, and their done() runs on the
 * loop. So a device that times out delays its own requests, never the loop. A port may also have a periodic job
 * of its own (port_set_tick: the laser's keep-alive) that takes precedence over queued requests. */
#ifndef PORT_H
#define PORT_H

#include <stdbool.h>

#include "config/acq_err.h"

struct loop;
struct port;

struct port_req {
	/* On the port's thread: the device I/O (may block, may call port_wait()). */
	void (*run)(struct port_req *r, struct port *p);
	/* On the loop after run; the request belongs to done() from then on. */
	void (*done)(struct port_req *r);
	/* Filled by the port's thread around run(), for diagnostics (cputime.h): real seconds run() took, and of
	 * them those the thread ran on a CPU and those it waited for one (the rest it slept: device, timeout). */
	double took_s, on_cpu_s, cpu_wait_s;
	/* Real monotonic seconds it was submitted and its run ended (stall.h: its wait in the queue and for the
	 * loop). */
	double submitted_at, ended_at;
	/* Set by the submitter: a request others may overtake (a client's status read). The requests without it are
	 * queued ahead of those with it (each kind stays first in, first out), so a client's reads never delay the
	 * sweep's commands on a device's line. */
	bool yields;
	/* the port's: */
	unsigned long gen;
	struct port_req *next;
};

/* A port named name (for messages) on loop lp, its thread started and its eventfd registered. 0 or -1. */
int port_new(struct loop *lp, const char *name, struct port **out, struct acq_err *err);
/* Give the port's thread a periodic job: fn(arg, p) every period_s real seconds (0: none), run between requests
 * and before the next queued request when due, so queued requests never delay it (only the one running may).
 * The first run is due at once. Call from the loop's thread; fn runs on the port's thread. */
void port_set_tick(struct port *p, double period_s, void (*fn)(void *arg, struct port *p), void *arg);
/* Queue r (first in, first out; ahead of the yielding ones unless r yields too). Never blocks. */
void port_submit(struct port *p, struct port_req *r);
/* Ask the request running now (and those queued before this call) to end early: port_wait() returns at once
 * and port_interrupted() is true for them. Requests submitted afterwards run normally. */
void port_interrupt(struct port *p);
/* On the port's thread: true when the running request was interrupted. */
bool port_interrupted(struct port *p);
/* On the port's thread: wait clock_s seconds of the loop's clock (scaled like the loop), or until interrupted
 * or until fd (if >= 0) is readable. */
void port_wait(struct port *p, double clock_s, int fd);
/* The same in real seconds. */
void port_wait_real(struct port *p, double real_s, int fd);
/* The loop's clock (monotonic seconds), callable from the port's thread. */
double port_now(const struct port *p);
/* Block until everything queued so far has run, then complete it (done() on the caller, the loop's thread).
 * For start-up and reloads only: it waits as long as the device takes. */
void port_flush(struct port *p);
/* Run what is queued (so a final safe stop reaches the device), stop and join the thread, complete what is
 * left, unregister, free. NULL is fine. */
void port_free(struct port *p);

#endif
