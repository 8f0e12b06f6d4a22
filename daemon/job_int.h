/* job_int: what job.c (the daemon's side) and job_helper.c (the helper process) share: the helper's messages
 * and its start. Not for other modules. */
#ifndef DAEMON_JOB_INT_H
#define DAEMON_JOB_INT_H

#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "config/acq_err.h"
#include "daemon/job.h"

/* One message on the helper's socket (SOCK_SEQPACKET, both directions). The helper is this program run again
 * (job_kinds_main): a start names its kind by its index in the program's table of kinds, the same on both ends. */
enum jobh_type {
	JOBH_START = 1, /* daemon → helper: fork a child running kind (id, kind, mem_bytes); SCM_RIGHTS: the payload
			 * (a memfd), the output pipe's write end */
	JOBH_KILL,      /* daemon → helper: signal sig to child id (ignored once it has ended) */
	JOBH_DONE,      /* helper → daemon: child id ended with status (exit code or 128 + signal) */
};

struct jobh_msg {
	uint32_t type;
	int32_t sig_or_status;
	uint64_t id;
	uint64_t mem_bytes;
	uint32_t kind;
	uint32_t cpu_s;          /* JOBH_START: the child's CPU seconds (0: unbounded) */
};

/* The kinds' table given to job_kinds_main: kind's index in it, or -1 when it is not there. */
int jobh_kind_index(const struct job_kind *kind);

/* Start the helper process (this program run again in its helper mode, never a fork of the caller's memory):
 * *sock is the caller's end of its socket (close-on-exec), *pid its process. The helper keeps no descriptor of
 * the caller's but its end of the socket and the standard output and error. 0 or -1 with err. */
int jobh_spawn(int *sock, pid_t *pid, struct acq_err *err);

/* posix_spawn of this program (/proc/self/exe) with argv (vfork and exec: no copy of the caller's memory, threads
 * or descriptors survives): descriptor fds[i] becomes first + i (i < n), then standard input is /dev/null and
 * every descriptor from first + n on is closed; signals unmasked and at their defaults. 0 with *pid, or an errno
 * value. */
int jobh_spawn_self(char *const argv[], const int *fds, int n, int first, pid_t *pid);

#endif
