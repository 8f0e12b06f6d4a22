/* stall: where the real time between two committed points went, so a slow point explains itself (issue 15's
 * soak). The loop, the ports, the store and the executor add what they measured (real CLOCK_MONOTONIC seconds,
 * whatever the loop's clock); the executor takes the totals when it commits a point and logs them at debug
 * level. Process-wide totals, touched on the loop's thread only (a port's figures are added when its completion
 * is dispatched there). */
#ifndef STALL_H
#define STALL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define STALL_MAX_PORTS 8

struct stall_port {
	char name[24];
	int requests;
	double queued;     /* submitted → its thread took it (behind the running request or the keep-alive) */
	double run;        /* the thread ran it (the device's answer included) */
	double run_cpu;    /* of run: on a CPU */
	double run_wait;   /* of run: waiting for a CPU */
	double dispatch;   /* finished → its completion ran on the loop (the loop busy or not scheduled) */
	double yielding;   /* of run: the requests that yield (clients' status reads, port.h) */
	double max_run, max_queued, max_dispatch;
};

struct stall_acc {
	double callbacks, max_callback;     /* loop callbacks (fd and timer), all of them */
	uintptr_t max_callback_fn;          /* the longest one's function (stall_fn_offset names it) */
	double max_callback_cpu;            /* of the longest one: on the loop thread's CPU (stall_cpu_on) */
	double max_cpu;                     /* the largest CPU time of one callback, and its function */
	uintptr_t max_cpu_fn;
	double devices;                     /* of which the ports' completions (the executor's steps they kick not) */
	double executor;                    /* of which the executor's own steps (commits included); the rest is
					     * the clients', the server's timers', plans' and the reconstruction's */
	double store, max_store;            /* the executor's writes to the database (fsync included) */
	double timer_late, max_timer_late;  /* timers run later than due (the loop busy or not scheduled) */
	struct stall_port port[STALL_MAX_PORTS];
	int nports;
};

/* Real monotonic seconds (CLOCK_MONOTONIC). */
double stall_now(void);
/* A loop callback (function fn, cast) took s seconds, cpu_s of them on the CPU. */
void stall_callback(double s, double cpu_s, uintptr_t fn);
/* Measure the loop's callbacks' CPU time too (on while the per-point stall report is logged). */
void stall_cpu_on(bool on);
/* The calling thread's CPU seconds, or NAN while off. */
double stall_cpu(void);
/* fn's address in its executable (what `addr2line -f -e acquisitiond 0x...` names), 0 if unknown. */
uintptr_t stall_fn_offset(uintptr_t fn);
/* Of the callbacks: dispatching a port's completions took s seconds. */
void stall_devices(double s);
/* Of the callbacks: an executor step took s seconds. */
void stall_executor(double s);
/* The executor's database writes took s seconds. */
void stall_store(double s);
/* A timer ran late_s seconds after it was due (real seconds). */
void stall_timer_late(double late_s);
/* A request of port name: queued, ran (cpu, cpu_wait of it), then waited dispatch_s for the loop; yields: a
 * client's read (port.h). */
void stall_port_req(const char *name, double queued_s, double run_s, double cpu_s, double cpu_wait_s,
		    double dispatch_s, bool yields);
/* Copy the totals since the last take into out and start again. */
void stall_take(struct stall_acc *out);
/* The ports' part of acc as text ("spectrometer: n=3 queued=0.1 queued_max=0.1 run=40.2 ... loop=0.2
 * loop_max=0.1; laser: ...", milliseconds), into buf of size n. */
void stall_ports_text(const struct stall_acc *acc, char *buf, size_t n);

#endif
