/* cputime: where a thread's time went, from the kernel's scheduler statistics, to tell a thread that waited for
 * a CPU (an overloaded machine) from one that waited for a device, a lock or a client (the daemon's own). */
#ifndef CPUTIME_H
#define CPUTIME_H

#include <stdbool.h>

struct cputime {
	double on_cpu;   /* seconds the thread ran */
	double waiting;  /* seconds it was runnable but waited for a CPU (run queue) */
};

/* The calling thread's totals since it started (/proc/thread-self/schedstat). false (and zeros) where the kernel
 * keeps no such statistics. */
bool cputime_thread(struct cputime *out);

#endif
