/* job: the daemon's side of its child processes — started through the helper (its socket's end: job_link.c) or the
 * exec mode (job_helper.c), their output captured, timed out and reaped without blocking the loop (see job.h). */
#include "daemon/job.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <unistd.h>

#include "daemon/job_int.h"
#include "daemon/job_link.h"
#include "daemon/log.h"
#include "daemon/loop.h"

struct job {
	pid_t pid;              /* 0 for a helper's child (job_fork_msg): hid names it */
	uint64_t hid;
	bool lost;              /* the helper died while it ran */
	int fd;                 /* read end of the output pipe, -1 once drained */
	bool exited;
	int status;
	char *out;              /* the last cap bytes (job_start), or the first (job_fork_msg: truncated then) */
	size_t len, cap, alloc; /* alloc: the buffer's size (+ 1 for the NUL), cap: what it may grow to */
	bool keep_head, truncated;
	uint64_t timer;
	bool killed, timed_out;
	bool hkilled;           /* a helper's child: SIGKILL asked for (its timer then checks the helper) */
	job_done_fn done;
	void *arg;
	struct job *next;
};

static struct loop *job_loop;
static struct job *job_list;

static void job_free(struct job *j)
{
	for (struct job **p = &job_list; *p; p = &(*p)->next)
		if (*p == j) {
			*p = j->next;
			break;
		}
	if (j->fd >= 0) {
		loop_fd_del(job_loop, j->fd);
		close(j->fd);
	}
	loop_timer_cancel(job_loop, j->timer);
	free(j->out);
	free(j);
}

static void maybe_done(struct job *j)
{
	if (!j->exited || j->fd >= 0)
		return;
	j->out[j->len] = 0;
	if (j->done)
		j->done(j, j->status, j->out, j->len, j->arg);
	job_free(j);
}

/* The helper's report that child hid ended with status (job_link.c). */
static void on_hid_done(uint64_t hid, int status)
{
	for (struct job *j = job_list; j; j = j->next)
		if (j->hid == hid && !j->exited) {
			j->exited = true;
			j->status = status;
			loop_timer_cancel(job_loop, j->timer);
			j->timer = 0;
			maybe_done(j);
			break;
		}
}

/* The helper has gone (job_link.c): each running child of it ends as killed, lost. */
static void on_hid_lost(void)
{
	for (struct job *j = job_list, *next; j; j = next) {
		next = j->next;
		if (!j->hid || j->exited)
			continue;
		j->exited = j->lost = true;
		j->status = 128 + SIGKILL;
		loop_timer_cancel(job_loop, j->timer);
		j->timer = 0;
		maybe_done(j); /* once its pipe has drained: the child died with the helper */
	}
}

void job_init(struct loop *lp)
{
	job_loop = lp;
	job_list = NULL;
	jobl_init(lp, on_hid_done, on_hid_lost);
}

/* Append up to 4 reads (of at most 64 KiB) of the child's output: a large output (a plan with every step) costs
 * few loop turns, each bounded. */
static void on_output(struct loop *lp, int fd, short revents, void *arg)
{
	(void)lp;
	(void)revents;
	struct job *j = arg;
	char buf[8192];
	_Static_assert(sizeof buf < JOB_OUTPUT_MAX, "one read fits in the kept output");
	for (int turn = 0; turn < 4; turn++) {
		if (j->keep_head && j->alloc - j->len < 65536 && j->alloc < j->cap) {
			/* job_fork_msg(): the buffer grows with the output, up to its cap */
			size_t a = j->alloc;
			while (a < j->len + 65536 && a < j->cap)
				a = a * 2 < j->cap ? a * 2 : j->cap;
			char *o = realloc(j->out, a + 1);
			if (o) {
				j->out = o;
				j->alloc = a;
			}
		}
		bool direct = j->keep_head && j->alloc > j->len; /* into the kept output itself */
		size_t room = direct ? j->alloc - j->len : sizeof buf;
		ssize_t n = read(fd, direct ? j->out + j->len : buf, room < 65536 ? room : 65536);
		if (n < 0 && (errno == EINTR || errno == EAGAIN))
			return;
		if (n <= 0) {
			loop_fd_del(job_loop, fd);
			close(fd);
			j->fd = -1;
			maybe_done(j);
			return;
		}
		size_t k = (size_t)n;
		if (direct) {
			j->len += k;
			continue;
		}
		if (j->keep_head) { /* past the bound: dropped */
			j->truncated = true;
			continue;
		}
		if (j->len + k > j->cap) { /* job_start(): the last cap bytes */
			size_t drop = j->len + k - j->cap;
			memmove(j->out, j->out + drop, j->len - drop);
			j->len -= drop;
		}
		memcpy(j->out + j->len, buf, k);
		j->len += k;
	}
}

static void signal_job(struct job *j, int sig)
{
	if (!j->hid) {
		kill(j->pid, sig);
		return;
	}
	jobl_kill(j->hid, sig);
}

static void on_timeout(struct loop *lp, void *arg)
{
	(void)lp;
	struct job *j = arg;
	j->timer = 0;
	if (j->exited)
		return;
	j->timed_out = true;
	if (j->hid && j->hkilled) { /* SIGKILL sent 2 s ago and the helper reported nothing: it hangs */
		log_msg(LOG_WARNING, "job helper: no report of a killed child within 2 s: restarting the helper");
		jobl_lost(true);
		return;
	}
	/* First SIGTERM, then SIGKILL two seconds later if it is still there. */
	signal_job(j, j->killed ? SIGKILL : SIGTERM);
	if (!j->killed || j->hid) {
		j->hkilled = j->killed;
		j->killed = true;
		j->timer = loop_timer_add(job_loop, 2.0, 0, on_timeout, j);
	}
}

/* A new job reading its output from fd (taken), kept up to cap bytes (the first ones for a function's child:
 * keep_head), registered with the loop and its timeout. NULL with err (fd closed) on failure. */
static struct job *job_new(int fd, size_t cap, bool keep_head, double timeout_s, job_done_fn done, void *arg,
			   struct acq_err *err)
{
	struct job *j = calloc(1, sizeof *j);
	size_t alloc = keep_head && cap > JOB_FORK_OUTPUT_MAX ? JOB_FORK_OUTPUT_MAX : cap; /* grows up to cap */
	if (!j || !(j->out = malloc(alloc + 1))) {
		free(j);
		close(fd);
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		return NULL;
	}
	fcntl(fd, F_SETFL, O_NONBLOCK);
	j->fd = fd;
	j->cap = cap;
	j->alloc = alloc;
	j->keep_head = keep_head;
	j->done = done;
	j->arg = arg;
	if (loop_fd_add(job_loop, j->fd, POLLIN, on_output, j, err)) {
		close(fd);
		free(j->out);
		free(j);
		return NULL;
	}
	j->next = job_list;
	job_list = j;
	if (timeout_s > 0)
		j->timer = loop_timer_add(job_loop, timeout_s, 0, on_timeout, j);
	return j;
}

/* Run argv with the output pipe through the program's exec mode (job_kinds_main, JOB_EXEC_ARG): posix_spawn of
 * /proc/self/exe (vfork and exec: the loop never copies the daemon's page tables, and no copy of its memory,
 * threads or descriptors outlives the exec), which sets death with the daemon, enters cwd and execs argv; in
 * the parent, register the job (reaped by job_reap like any child). */
static int spawn(char *const argv[], const char *cwd, size_t cap, double timeout_s, job_done_fn done, void *arg,
		 struct job **out, struct acq_err *err)
{
	if (!job_loop || !argv || !argv[0])
		return acq_errf(err, ACQ_E_INVAL, "job: not initialised or no program");
	size_t n = 0;
	while (argv[n])
		n++;
	char dpid[24], name[] = "acq-exec", arg1[] = JOB_EXEC_ARG, here[] = "";
	snprintf(dpid, sizeof dpid, "%d", (int)getpid());
	char **xargv = calloc(n + 5, sizeof *xargv), *dir = cwd ? strdup(cwd) : NULL;
	if (!xargv || (cwd && !dir)) {
		free(xargv);
		free(dir);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	xargv[0] = name;
	xargv[1] = arg1;
	xargv[2] = dpid;
	xargv[3] = dir ? dir : here;
	memcpy(xargv + 4, argv, n * sizeof *argv);
	int p[2];
	if (pipe2(p, O_CLOEXEC) < 0) {
		free(xargv);
		free(dir);
		return acq_errf(err, ACQ_E_IO, "pipe: %s", strerror(errno));
	}
	/* its output into the pipe; the daemon's descriptors without close-on-exec are not the program's */
	int ofd[2] = { p[1], p[1] };
	pid_t pid = 0;
	int rc = jobh_spawn_self(xargv, ofd, 2, 1, &pid);
	free(xargv);
	free(dir);
	close(p[1]);
	if (rc) {
		close(p[0]);
		return acq_errf(err, ACQ_E_IO, "job: cannot run /proc/self/exe %s for %s: %s", JOB_EXEC_ARG, argv[0],
				strerror(rc));
	}
	struct job *j = job_new(p[0], cap, false, timeout_s, done, arg, err);
	if (!j) {
		kill(pid, SIGKILL);
		waitpid(pid, NULL, 0);
		return -1;
	}
	j->pid = pid;
	if (out)
		*out = j;
	return 0;
}

int job_start(char *const argv[], const char *cwd, double timeout_s, job_done_fn done, void *arg,
	      struct job **out, struct acq_err *err)
{
	return spawn(argv, cwd, JOB_OUTPUT_MAX, timeout_s, done, arg, out, err);
}

int job_fork_msg(const struct job_kind *kind, const void *payload, size_t len, size_t mem_bytes, size_t out_max,
		 double timeout_s, job_done_fn done, void *arg, struct job **out, struct acq_err *err)
{
	return job_fork_msg_cpu(kind, payload, len, mem_bytes, 0, out_max, timeout_s, done, arg, out, err);
}

int job_fork_msg_cpu(const struct job_kind *kind, const void *payload, size_t len, size_t mem_bytes, unsigned cpu_s,
		     size_t out_max, double timeout_s, job_done_fn done, void *arg, struct job **out, struct acq_err *err)
{
	int k = kind ? jobh_kind_index(kind) : -1;
	if (k < 0 || out_max < 1)
		return acq_errf(err, ACQ_E_INVAL, "job: kind '%s' not in the program's table (job_kinds_main), or no output",
				kind && kind->name ? kind->name : "?");
	if (job_helper_start(err))
		return -1;
	int p[2] = { -1, -1 };
	int mfd = memfd_create("acq-job", MFD_CLOEXEC);
	if (mfd < 0)
		return acq_errf(err, ACQ_E_IO, "memfd_create: %s", strerror(errno));
	for (size_t off = 0; off < len;) {
		ssize_t w = write(mfd, (const char *)payload + off, len - off);
		if (w < 0 && errno == EINTR)
			continue;
		if (w <= 0) {
			acq_errf(err, ACQ_E_IO, "job payload: %s", w < 0 ? strerror(errno) : "short write");
			goto fail;
		}
		off += (size_t)w;
	}
	if (pipe2(p, O_CLOEXEC) < 0) {
		acq_errf(err, ACQ_E_IO, "pipe: %s", strerror(errno));
		goto fail;
	}
	uint64_t hid;
	int fds[2] = { mfd, p[1] };
	if (jobl_start((uint32_t)k, mem_bytes, cpu_s, fds, &hid, err))
		goto fail;
	close(mfd);
	close(p[1]);
	struct job *j = job_new(p[0], out_max, true, timeout_s, done, arg, err);
	if (!j) { /* its child writes into a closed pipe and ends; the helper's report then matches no job */
		return -1;
	}
	j->hid = hid;
	if (out)
		*out = j;
	return 0;
fail:
	close(mfd);
	if (p[0] >= 0) {
		close(p[0]);
		close(p[1]);
	}
	return -1;
}

char *job_msg_pack(const void *hdr, size_t hdr_len, const char *a, const char *b, size_t *len)
{
	uint64_t na = strlen(a);
	size_t nb = strlen(b);
	*len = hdr_len + sizeof na + na + nb;
	char *m = malloc(*len);
	if (m) {
		memcpy(m, hdr, hdr_len);
		memcpy(m + hdr_len, &na, sizeof na);
		memcpy(m + hdr_len + sizeof na, a, na);
		memcpy(m + hdr_len + sizeof na + na, b, nb);
	}
	return m;
}

int job_msg_unpack(const char *payload, size_t len, void *hdr, size_t hdr_len, char **a, const char **b)
{
	uint64_t na;
	if (len < hdr_len + sizeof na)
		return -1;
	memcpy(hdr, payload, hdr_len);
	memcpy(&na, payload + hdr_len, sizeof na);
	if (na > len - hdr_len - sizeof na || !(*a = strndup(payload + hdr_len + sizeof na, (size_t)na)))
		return -1;
	*b = payload + hdr_len + sizeof na + na;
	return 0;
}

void job_kill(struct job *j)
{
	if (j && !j->exited) {
		j->killed = true;
		signal_job(j, SIGKILL);
	}
}

bool job_lost(const struct job *j)
{
	return j->lost;
}

bool job_output_truncated(const struct job *j)
{
	return j->truncated;
}

bool job_timed_out(const struct job *j)
{
	return j->timed_out;
}

pid_t job_pid(const struct job *j)
{
	return j->pid;
}

int job_count(void)
{
	int n = 0;
	for (struct job *j = job_list; j; j = j->next)
		n += !j->exited;
	return n;
}

void job_reap(void)
{
	jobl_reap();
	for (struct job *j = job_list, *next; j; j = next) {
		next = j->next;
		if (j->exited || j->hid) /* a helper's child: the helper reports it */
			continue;
		int st;
		pid_t r = waitpid(j->pid, &st, WNOHANG);
		if (r != j->pid)
			continue;
		j->exited = true;
		j->status = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + (WIFSIGNALED(st) ? WTERMSIG(st) : 0);
		loop_timer_cancel(job_loop, j->timer);
		j->timer = 0;
		maybe_done(j);
	}
}

void job_finish(void)
{
	jobl_finish();
	for (struct job *j = job_list; j; j = j->next)
		if (j->hid)
			j->exited = true;
	for (struct job *j = job_list; j; j = j->next)
		if (!j->exited)
			kill(j->pid, SIGTERM);
	for (int i = 0; i < 200 && job_count(); i++) {
		for (struct job *j = job_list; j; j = j->next)
			if (!j->exited && waitpid(j->pid, NULL, WNOHANG) == j->pid)
				j->exited = true;
		if (job_count())
			usleep(10000);
	}
	for (struct job *j = job_list; j; j = j->next)
		if (!j->exited) {
			kill(j->pid, SIGKILL);
			waitpid(j->pid, NULL, 0);
			j->exited = true;
		}
	while (job_list) {
		job_list->done = NULL;
		job_free(job_list);
	}
}
