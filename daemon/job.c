/* job: child processes with captured output, reaped without blocking the loop (see job.h). */
#include "daemon/job.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include "daemon/loop.h"

struct job {
	pid_t pid;
	int fd;                 /* read end of the output pipe, -1 once drained */
	bool exited;
	int status;
	char *out;              /* the last cap bytes (job_start), or the first (job_fork: truncated then) */
	size_t len, cap, alloc; /* alloc: the buffer's size (+ 1 for the NUL), cap: what it may grow to */
	bool keep_head, truncated;
	uint64_t timer;
	bool killed, timed_out;
	job_done_fn done;
	void *arg;
	struct job *next;
};

static struct loop *job_loop;
static struct job *job_list;

void job_init(struct loop *lp)
{
	job_loop = lp;
	job_list = NULL;
}

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

static void on_output(struct loop *lp, int fd, short revents, void *arg)
{
	(void)lp;
	(void)revents;
	struct job *j = arg;
	char buf[8192];
	ssize_t n = read(fd, buf, sizeof buf);
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
	_Static_assert(sizeof buf < JOB_OUTPUT_MAX, "one read fits in the kept output");
	if (j->keep_head && j->len + k > j->alloc && j->alloc < j->cap) {
		/* job_fork_out(): the buffer grows with the output, up to its cap */
		size_t a = j->alloc;
		while (a < j->len + k && a < j->cap)
			a = a * 2 < j->cap ? a * 2 : j->cap;
		char *o = realloc(j->out, a + 1);
		if (o) {
			j->out = o;
			j->alloc = a;
		}
	}
	if (j->keep_head && j->len + k > j->alloc) {
		k = j->alloc - j->len;
		j->truncated = true;
	} else if (j->len + k > j->cap) {
		size_t drop = j->len + k - j->cap;
		memmove(j->out, j->out + drop, j->len - drop);
		j->len -= drop;
	}
	memcpy(j->out + j->len, buf, k);
	j->len += k;
}

static void on_timeout(struct loop *lp, void *arg)
{
	(void)lp;
	struct job *j = arg;
	j->timer = 0;
	if (j->exited)
		return;
	j->timed_out = true;
	/* First SIGTERM, then SIGKILL two seconds later if it is still there. */
	kill(j->pid, j->killed ? SIGKILL : SIGTERM);
	if (!j->killed) {
		j->killed = true;
		j->timer = loop_timer_add(job_loop, 2.0, 0, on_timeout, j);
	}
}

/* In the child: default signal handling, and death with the daemon (a SIGKILLed daemon leaves no child
 * writing its files: PR_SET_PDEATHSIG survives exec). Only async-signal-safe calls. */
static void child_setup(pid_t parent)
{
	sigset_t all;
	sigemptyset(&all);
	sigprocmask(SIG_SETMASK, &all, NULL);
	signal(SIGPIPE, SIG_DFL);
	signal(SIGTERM, SIG_DFL);
	signal(SIGINT, SIG_DFL);
	signal(SIGHUP, SIG_DFL);
	signal(SIGCHLD, SIG_DFL);
	prctl(PR_SET_PDEATHSIG, SIGKILL);
	if (getppid() != parent) /* the daemon died before prctl */
		_exit(137);
}

/* Fork with the output pipe; in the child, run fn (exec) or child_fn; in the parent, register the job. */
static int spawn(char *const argv[], const char *cwd, job_child_fn child_fn, void *child_arg, size_t mem_bytes,
		 size_t cap, double timeout_s, job_done_fn done, void *arg, struct job **out, struct acq_err *err)
{
	if (!job_loop || (!child_fn && (!argv || !argv[0])))
		return acq_errf(err, ACQ_E_INVAL, "job: not initialised or no program");
	struct job *j = calloc(1, sizeof *j);
	size_t alloc = cap < JOB_FORK_OUTPUT_MAX ? cap : JOB_FORK_OUTPUT_MAX; /* job_fork_out(): grows up to cap */
	if (!child_fn)
		alloc = cap;
	if (!j || !(j->out = malloc(alloc + 1))) {
		free(j);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	int p[2];
	if (pipe2(p, O_CLOEXEC) < 0) {
		free(j->out);
		free(j);
		return acq_errf(err, ACQ_E_IO, "pipe: %s", strerror(errno));
	}
	pid_t parent = getpid();
	pid_t pid = fork();
	if (pid < 0) {
		close(p[0]);
		close(p[1]);
		free(j->out);
		free(j);
		return acq_errf(err, ACQ_E_IO, "fork: %s", strerror(errno));
	}
	if (pid == 0) {
		child_setup(parent);
		int nul = open("/dev/null", O_RDONLY);
		if (nul >= 0)
			dup2(nul, 0);
		dup2(p[1], 1);
		dup2(p[1], 2);
		if (cwd && chdir(cwd) < 0)
			_exit(126);
		if (child_fn) {
			/* The daemon's descriptors (its listening sockets, the database) are not this child's: one
			 * that outlived a killed daemon for a moment would keep its socket answering, and the
			 * restarted daemon would find it "in use". (exec'd children lose them by O_CLOEXEC.) */
			close_range(3, ~0U, 0);
			/* Work done for a client (a dry-run plan) yields the CPU to the daemon and the bench. */
			if (nice(10) < 0) {
				/* unchanged priority: still bounded by the deadline */
			}
#if !defined(__SANITIZE_ADDRESS__) /* ASan reserves terabytes of address space: only the deadline then */
			if (mem_bytes) {
				struct rlimit rl = { mem_bytes, mem_bytes };
				setrlimit(RLIMIT_AS, &rl);
			}
#else
			(void)mem_bytes;
#endif
			_exit(child_fn(child_arg, 1));
		}
		execvp(argv[0], argv);
		static const char msg[] = "job: exec failed\n";
		ssize_t w = write(2, msg, sizeof msg - 1);
		(void)w;
		_exit(127);
	}
	close(p[1]);
	fcntl(p[0], F_SETFL, O_NONBLOCK);
	j->pid = pid;
	j->fd = p[0];
	j->cap = cap;
	j->alloc = alloc;
	j->keep_head = child_fn != NULL;
	j->done = done;
	j->arg = arg;
	j->next = job_list;
	job_list = j;
	if (loop_fd_add(job_loop, j->fd, POLLIN, on_output, j, err)) {
		kill(pid, SIGKILL);
		waitpid(pid, NULL, 0);
		j->done = NULL;
		job_free(j);
		return -1;
	}
	if (timeout_s > 0)
		j->timer = loop_timer_add(job_loop, timeout_s, 0, on_timeout, j);
	if (out)
		*out = j;
	return 0;
}

int job_start(char *const argv[], const char *cwd, double timeout_s, job_done_fn done, void *arg,
	      struct job **out, struct acq_err *err)
{
	return spawn(argv, cwd, NULL, NULL, 0, JOB_OUTPUT_MAX, timeout_s, done, arg, out, err);
}

int job_fork(job_child_fn fn, void *fn_arg, size_t mem_bytes, double timeout_s, job_done_fn done, void *arg,
	     struct job **out, struct acq_err *err)
{
	return job_fork_out(fn, fn_arg, mem_bytes, JOB_FORK_OUTPUT_MAX, timeout_s, done, arg, out, err);
}

int job_fork_out(job_child_fn fn, void *fn_arg, size_t mem_bytes, size_t out_max, double timeout_s, job_done_fn done,
		 void *arg, struct job **out, struct acq_err *err)
{
	if (!fn || out_max < 1)
		return acq_errf(err, ACQ_E_INVAL, "job: no function or no output");
	return spawn(NULL, NULL, fn, fn_arg, mem_bytes, out_max, timeout_s, done, arg, out, err);
}

void job_kill(struct job *j)
{
	if (j && !j->exited) {
		j->killed = true;
		kill(j->pid, SIGKILL);
	}
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
	for (struct job *j = job_list, *next; j; j = next) {
		next = j->next;
		if (j->exited)
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
