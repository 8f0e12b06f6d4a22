/* job_link: what job.c (the jobs) asks of job_link.c (the daemon's end of the job helper's socket). Not for other
 * modules: job.h is the API. */
#ifndef DAEMON_JOB_LINK_H
#define DAEMON_JOB_LINK_H

#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "daemon/loop.h"

/* The helper reports child hid ended with status (exit code or 128 + signal). */
typedef void (*jobl_done_fn)(uint64_t hid, int status);
/* The helper has gone: every running child of it died with it. */
typedef void (*jobl_lost_fn)(void);

/* Remember the loop (for the helper's socket) and the jobs' callbacks; no helper runs until jobl_start's caller starts
 * one (job_helper_start). */
void jobl_init(struct loop *lp, jobl_done_fn done, jobl_lost_fn lost);
/* Ask the running helper to fork a child of kind (its index in the kinds' table) with fds[0] its payload (a memfd)
 * and fds[1] its output pipe's write end; *hid names it in later reports. 0, or -1 with err: the helper did not take
 * the request and is restarted (jobl_lost(true)). */
int jobl_start(uint32_t kind, uint64_t mem_bytes, unsigned cpu_s, const int fds[2], uint64_t *hid,
	       struct acq_err *err);
/* Send signal sig to the helper's child hid (logged when it cannot be sent; nothing without a helper). */
void jobl_kill(uint64_t hid, int sig);
/* Drop the helper (SIGKILL it first when kill_it: it hangs), its children reported lost; a no-op without one. */
void jobl_lost(bool kill_it);
/* Reap helpers that have exited (a live helper's exit reads as its socket's EOF). */
void jobl_reap(void);
/* End the helper (its socket's EOF; SIGKILL after 2 s) and reap every earlier one: at the daemon's exit. */
void jobl_finish(void);

#endif
