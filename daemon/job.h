/* job: slow work in child processes — programs run with stdout+stderr captured through a pipe watched by the loop
 * (the reconstruction; posix_spawn of the program's exec mode), and functions of the program run in children of
 * the job helper (plans, an adaptive sweep's inputs); reap on SIGCHLD, enforce a timeout; the loop never waits
 * for a child and never forks the daemon. */
#ifndef JOB_H
#define JOB_H

#include <stdbool.h>
#include <stddef.h>
#include <sys/types.h>

#include "config/acq_err.h"

struct loop;
struct job;

#define JOB_OUTPUT_MAX (64 * 1024)  /* captured output kept (the last bytes when longer) */
#define JOB_FORK_OUTPUT_MAX (64 * 1024)  /* a one-line reply's bound for job_fork_msg(): the first bytes kept */

/* Called once from the loop when the child has exited and its output is drained. status: exit code, or
 * 128 + signal number. output is NUL-terminated (len bytes), valid during the call only. */
typedef void (*job_done_fn)(struct job *j, int status, const char *output, size_t len, void *arg);

/* Start the job module on loop lp. */
void job_init(struct loop *lp);
/* Kill (SIGTERM, then SIGKILL after 2 s) and reap every running job; their callbacks are not called. */
void job_finish(void);
/* Run argv (argv[0] searched in PATH when it has no '/') in directory cwd (NULL: unchanged), stdin from
 * /dev/null, descriptors 3 and up closed, OPENBLAS_NUM_THREADS=1 unless the environment sets it, dying with the
 * daemon, killed after timeout_s (0: never); through the program's exec mode (job_kinds_main, JOB_EXEC_ARG):
 * the daemon is never forked. 0 or -1 (exec failure is reported as status 127, a cwd that cannot be entered
 * as 126). */
int job_start(char *const argv[], const char *cwd, double timeout_s, job_done_fn done, void *arg,
	      struct job **out, struct acq_err *err);
/* In a job_fork_msg() child: payload is its own copy of the request's bytes (len of them, NUL after); compute,
 * write the result to fd, return the exit status. */
typedef int (*job_msg_fn)(const char *payload, size_t len, int fd);
/* A kind of job_fork_msg() child: the helper runs fn on the request's payload (name: for messages). */
struct job_kind {
	const char *name;
	job_msg_fn fn;
};
/* The argument that makes a program the job helper (argv[1]; job_kinds_main). */
#define JOB_HELPER_ARG "--job-helper"
/* The argument that makes a program run a job_start() program (argv[1]; job_kinds_main). */
#define JOB_EXEC_ARG "--job-exec"
/* The program's job kinds, kinds[n] (kept: static storage). Call it first in main: the helper is this program
 * run again (/proc/self/exe, argv[1] JOB_HELPER_ARG), which then serves its daemon here and never returns; a
 * request names its kind by its place in this table. job_start() runs its program through this program run
 * again too (argv[1] JOB_EXEC_ARG: it execs the program here). Otherwise it returns. */
void job_kinds_main(int argc, char **argv, const struct job_kind *const *kinds, size_t n);
/* Start the job helper (job_helper.c): a small process forking the job_fork_msg() children, this program run
 * again in its helper mode (job_kinds_main), so it holds none of the daemon's memory, threads or descriptors
 * whenever it starts; job_fork_msg() starts it again when it has died. 0 or -1. */
int job_helper_start(struct acq_err *err);
/* The helper's process id (0: not running). */
pid_t job_helper_pid(void);
/* Run kind's fn(copy of payload, len, fd) in a child forked by the helper (so the loop never forks the daemon: it
 * writes the payload to a memfd and one message), with its output's first out_max bytes kept (the buffer grows
 * with it: a binary result may be large), at nice +10, its address space limited to mem_bytes (0: unlimited),
 * killed after timeout_s; children die with the helper, the helper with the daemon (PR_SET_PDEATHSIG); a helper
 * that dies ends its running children as killed and job_lost(). kind must be in job_kinds_main's table. 0 or -1
 * (the helper not answering: restarted). */
int job_fork_msg(const struct job_kind *kind, const void *payload, size_t len, size_t mem_bytes, size_t out_max, double timeout_s,
		 job_done_fn done, void *arg, struct job **out, struct acq_err *err);
/* job_fork_msg with the child's CPU time also bounded to cpu_s seconds (0: unbounded; RLIMIT_CPU: it ends with
 * status 128 + SIGXCPU, or SIGKILL 2 CPU seconds later, no core file): a bound on its work that a loaded machine
 * does not shorten, where timeout_s (real time) bounds its wait. */
int job_fork_msg_cpu(const struct job_kind *kind, const void *payload, size_t len, size_t mem_bytes, unsigned cpu_s,
		     size_t out_max, double timeout_s, job_done_fn done, void *arg, struct job **out, struct acq_err *err);
/* A job_fork_msg() payload: a fixed header (hdr_len bytes) and two strings, packed into a new buffer (free()) of
 * *len bytes; NULL when out of memory. */
char *job_msg_pack(const void *hdr, size_t hdr_len, const char *a, const char *b, size_t *len);
/* In the child: the header back into hdr, a as a new string, b pointing into the payload (NUL-terminated: the
 * payload's end). 0, or -1 when the payload is not such a message. */
int job_msg_unpack(const char *payload, size_t len, void *hdr, size_t hdr_len, char **a, const char **b);
/* True when the job's helper died while it ran (valid in its done callback: status 128 + 9 then). */
bool job_lost(const struct job *j);
/* SIGKILL a running job; its done() is called as usual (status 128 + 9). */
void job_kill(struct job *j);
/* True when a job_fork_msg() child wrote more than its output bound (out_max; the rest was discarded). */
bool job_output_truncated(const struct job *j);
/* True when the job was killed because its timeout expired (valid in its done callback). */
bool job_timed_out(const struct job *j);
/* Process id of a running job (0 for a job_fork_msg() child). */
pid_t job_pid(const struct job *j);
/* Reap exited children (call when SIGCHLD was seen; harmless otherwise). */
void job_reap(void);
/* Number of running jobs. */
int job_count(void);

#endif
