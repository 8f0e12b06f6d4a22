/* stall: totals of where the loop's real time went between two committed points (stall.h). */
#include "daemon/stall.h"

#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

static struct stall_acc acc;
static bool cpu_on;

double stall_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static void add_max(double *sum, double *max, double s)
{
	*sum += s;
	if (max && s > *max)
		*max = s;
}

void stall_cpu_on(bool on)
{
	cpu_on = on;
}

double stall_cpu(void)
{
	struct timespec ts;
	if (!cpu_on || clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts))
		return NAN; /* a difference with it is NAN: not counted (e.g. a callback across the switch on) */
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

void stall_callback(double s, double cpu_s, uintptr_t fn)
{
	if (s > acc.max_callback) {
		acc.max_callback_fn = fn;
		acc.max_callback_cpu = cpu_s;
	}
	if (cpu_s > acc.max_cpu) {
		acc.max_cpu = cpu_s;
		acc.max_cpu_fn = fn;
	}
	add_max(&acc.callbacks, &acc.max_callback, s);
}

uintptr_t stall_fn_offset(uintptr_t fn)
{
	Dl_info info;
	if (!fn || !dladdr((void *)fn, &info) || !info.dli_fbase)
		return 0;
	return fn - (uintptr_t)info.dli_fbase;
}

void stall_devices(double s)
{
	acc.devices += s;
}

void stall_executor(double s)
{
	acc.executor += s;
}

void stall_store(double s)
{
	add_max(&acc.store, &acc.max_store, s);
}

void stall_timer_late(double late_s)
{
	if (late_s > 0)
		add_max(&acc.timer_late, &acc.max_timer_late, late_s);
}

void stall_port_req(const char *name, double queued_s, double run_s, double cpu_s, double cpu_wait_s,
		    double dispatch_s, bool yields)
{
	struct stall_port *p = NULL;
	for (int i = 0; i < acc.nports && !p; i++)
		if (!strcmp(acc.port[i].name, name))
			p = &acc.port[i];
	if (!p) {
		if (acc.nports >= STALL_MAX_PORTS)
			return;
		p = &acc.port[acc.nports++];
		snprintf(p->name, sizeof p->name, "%s", name);
	}
	p->requests++;
	add_max(&p->queued, &p->max_queued, queued_s > 0 ? queued_s : 0);
	add_max(&p->run, &p->max_run, run_s > 0 ? run_s : 0);
	p->run_cpu += cpu_s;
	p->run_wait += cpu_wait_s;
	add_max(&p->dispatch, &p->max_dispatch, dispatch_s > 0 ? dispatch_s : 0);
	if (yields)
		p->yielding += run_s > 0 ? run_s : 0;
}

void stall_take(struct stall_acc *out)
{
	*out = acc;
	/* The ports stay listed (in the same order from point to point), their figures start again. */
	struct stall_acc next = { .nports = acc.nports };
	for (int i = 0; i < acc.nports; i++)
		snprintf(next.port[i].name, sizeof next.port[i].name, "%s", acc.port[i].name);
	acc = next;
}

void stall_ports_text(const struct stall_acc *a, char *buf, size_t n)
{
	size_t len = 0;
	buf[0] = 0;
	for (int i = 0; i < a->nports && len < n; i++) {
		const struct stall_port *p = &a->port[i];
		int w = snprintf(buf + len, n - len,
				 "%s%s: n=%d queued=%.1f queued_max=%.1f run=%.1f run_max=%.1f cpu=%.1f cpu_wait=%.1f "
				 "loop=%.1f loop_max=%.1f clients=%.1f",
				 i ? "; " : "", p->name, p->requests, 1e3 * p->queued, 1e3 * p->max_queued, 1e3 * p->run,
				 1e3 * p->max_run, 1e3 * p->run_cpu, 1e3 * p->run_wait, 1e3 * p->dispatch,
				 1e3 * p->max_dispatch, 1e3 * p->yielding);
		if (w < 0)
			break;
		len += (size_t)w;
	}
}
