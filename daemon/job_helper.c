/* job_helper: the small process that forks the daemon's job_fork_msg() children (job.h), and the program's exec
 * mode that runs a job_start() program. It is the daemon's own
 * program run again (posix_spawn of /proc/self/exe in its helper mode, job_kinds_main), at start-up and after a
 * crash alike: it never holds the daemon's memory, threads, database or devices, and each child is a fork of it,
 * never of the daemon; the loop only writes a message. Each child's set-up (signals, death with its parent, limits)
 * is here too. Messages: job_int.h. */
#include "daemon/job_int.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/signalfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#define JOBH_MAX_CHILDREN 64 /* the daemon runs a few at once (2 plans, 1 sweep plan) */

struct hchild {
	uint64_t id;
	pid_t pid;
};

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

/* In a job child before its work: nice +10, the address space bounded to mem_bytes and the CPU time to cpu_s
 * seconds (0: unbounded). */
static void child_limits(size_t mem_bytes, unsigned cpu_s)
{
	if (cpu_s) { /* SIGXCPU at cpu_s (its default action dumps core: none), SIGKILL 2 s of CPU later */
		struct rlimit core = { 0, 0 }, cpu = { cpu_s, (rlim_t)cpu_s + 2 };
		setrlimit(RLIMIT_CORE, &core);
		setrlimit(RLIMIT_CPU, &cpu);
	}
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
}

static struct hchild kids[JOBH_MAX_CHILDREN];
static int n_kids;

/* The program's kinds (job_kinds_main): the same table in the daemon and in its helper. */
static const struct job_kind *const *kinds;
static size_t n_kinds;

int jobh_kind_index(const struct job_kind *kind)
{
	for (size_t i = 0; i < n_kinds; i++)
		if (kinds[i] == kind)
			return (int)i;
	return -1;
}

static void send_done(int sock, uint64_t id, int status)
{
	struct jobh_msg m = { .type = JOBH_DONE, .sig_or_status = status, .id = id };
	while (send(sock, &m, sizeof m, MSG_NOSIGNAL) < 0 && errno == EINTR)
		;
}

/* In the job's child: read the payload from its memfd, run fn with the output on fd 1. Never returns. */
static void run_child(pid_t helper, const struct jobh_msg *m, int payload, int out)
{
	child_setup(helper);
	prctl(PR_SET_NAME, "acq-job");
	int nul = open("/dev/null", O_RDONLY);
	if (nul >= 0)
		dup2(nul, 0);
	dup2(out, 1);
	dup2(out, 2);
	struct stat st;
	if (fstat(payload, &st) < 0)
		_exit(125);
	size_t len = (size_t)st.st_size;
	char *buf = malloc(len + 1);
	if (!buf)
		_exit(125);
	for (size_t off = 0; off < len;) {
		ssize_t r = pread(payload, buf + off, len - off, (off_t)off);
		if (r < 0 && errno == EINTR)
			continue;
		if (r <= 0)
			_exit(125);
		off += (size_t)r;
	}
	buf[len] = '\0';
	close_range(3, ~0U, 0);
	child_limits((size_t)m->mem_bytes, m->cpu_s);
	_exit(kinds[m->kind]->fn(buf, len, 1));
}

static void start_child(int sock, const struct jobh_msg *m, int payload, int out)
{
	pid_t helper = getpid();
	pid_t pid = n_kids < JOBH_MAX_CHILDREN ? fork() : -1;
	if (pid == 0)
		run_child(helper, m, payload, out);
	if (pid < 0) {
		send_done(sock, m->id, 126); /* the daemon's done() sees a failed job */
		return;
	}
	kids[n_kids++] = (struct hchild){ m->id, pid };
}

/* A message from the daemon; 0, or -1 when the daemon has gone (EOF). */
static int on_message(int sock)
{
	struct jobh_msg m;
	union {
		char buf[CMSG_SPACE(2 * sizeof(int))];
		struct cmsghdr align;
	} cb;
	struct iovec iov = { &m, sizeof m };
	struct msghdr mh = { .msg_iov = &iov, .msg_iovlen = 1, .msg_control = cb.buf, .msg_controllen = sizeof cb.buf };
	ssize_t n = recvmsg(sock, &mh, MSG_CMSG_CLOEXEC);
	if (n < 0)
		return errno == EINTR || errno == EAGAIN ? 0 : -1;
	if (n == 0)
		return -1;
	int fds[2] = { -1, -1 }, nfd = 0;
	for (struct cmsghdr *c = CMSG_FIRSTHDR(&mh); c; c = CMSG_NXTHDR(&mh, c))
		if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == SCM_RIGHTS) {
			int k = (int)((c->cmsg_len - CMSG_LEN(0)) / sizeof(int));
			for (int i = 0; i < k; i++) {
				int fd;
				memcpy(&fd, CMSG_DATA(c) + i * sizeof(int), sizeof fd);
				if (nfd < 2)
					fds[nfd++] = fd;
				else
					close(fd);
			}
		}
	if ((size_t)n == sizeof m && m.type == JOBH_START && nfd == 2 && m.kind < n_kinds)
		start_child(sock, &m, fds[0], fds[1]);
	else if ((size_t)n == sizeof m && m.type == JOBH_START)
		send_done(sock, m.id, 126); /* no such kind, or its descriptors did not arrive: the job fails, the helper
					     * goes on */
	else if ((size_t)n == sizeof m && m.type == JOBH_KILL)
		for (int i = 0; i < n_kids; i++)
			if (kids[i].id == m.id)
				kill(kids[i].pid, m.sig_or_status);
	for (int i = 0; i < nfd; i++)
		close(fds[i]);
	return 0;
}

static void reap(int sock)
{
	int st;
	pid_t pid;
	while ((pid = waitpid(-1, &st, WNOHANG)) > 0)
		for (int i = 0; i < n_kids; i++)
			if (kids[i].pid == pid) {
				int status = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + (WIFSIGNALED(st) ? WTERMSIG(st) : 0);
				send_done(sock, kids[i].id, status);
				kids[i] = kids[--n_kids];
				break;
			}
}

/* The helper's life: children started and reported until the daemon closes its end (then the children die
 * with the helper: PR_SET_PDEATHSIG). Its socket is descriptor 3 (jobh_spawn). */
static _Noreturn void helper_main(pid_t daemon)
{
	int sock = 3;
	child_setup(daemon);
	signal(SIGHUP, SIG_IGN); /* a terminal's hang-up is the daemon's to handle (reload), not a reason to die */
	prctl(PR_SET_NAME, "acq-helper");
	close_range(4, ~0U, 0);
	sigset_t chld;
	sigemptyset(&chld);
	sigaddset(&chld, SIGCHLD);
	sigprocmask(SIG_BLOCK, &chld, NULL);
	int sfd = signalfd(-1, &chld, SFD_CLOEXEC | SFD_NONBLOCK);
	if (sfd < 0)
		_exit(3);
	for (;;) {
		struct pollfd p[2] = { { sock, POLLIN, 0 }, { sfd, POLLIN, 0 } };
		if (poll(p, 2, -1) < 0 && errno != EINTR)
			_exit(3);
		if (p[1].revents) {
			struct signalfd_siginfo si;
			while (read(sfd, &si, sizeof si) > 0)
				;
			reap(sock);
		}
		if (p[0].revents && on_message(sock))
			_exit(0);
	}
}

/* job_start's program (job.c spawn): a[0] the daemon's process id, a[1] the directory ("": unchanged), a + 2 the
 * program's argv. Dies with the daemon (PR_SET_PDEATHSIG survives the exec; a daemon gone already: exit 137),
 * exit 126 when the directory cannot be entered, 127 when the program cannot be run. */
static _Noreturn void exec_main(char **a)
{
	child_setup((pid_t)strtol(a[0], NULL, 10));
	if (a[1][0] && chdir(a[1]) < 0) {
		fprintf(stderr, "job: cannot enter %s: %s\n", a[1], strerror(errno));
		_exit(126);
	}
	/* one BLAS thread unless the daemon's environment says otherwise: a program's parallelism is its own option
	 * (brdf-recon --threads, recon.threads), and OpenBLAS's threads wait for each other on a busy machine */
	setenv("OPENBLAS_NUM_THREADS", "1", 0);
	execvp(a[2], a + 2);
	fprintf(stderr, "job: exec failed: %s: %s\n", a[2], strerror(errno));
	_exit(127);
}

void job_kinds_main(int argc, char **argv, const struct job_kind *const *table, size_t n)
{
	kinds = table;
	n_kinds = n;
	if (argc >= 5 && !strcmp(argv[1], JOB_EXEC_ARG))
		exec_main(argv + 2);
	if (argc < 3 || strcmp(argv[1], JOB_HELPER_ARG))
		return;
	/* the daemon's process id: a helper whose daemon has gone already (or run by hand) ends at once */
	helper_main((pid_t)strtol(argv[2], NULL, 10));
}

extern char **environ;

int jobh_spawn_self(char *const argv[], const int *fds, int n, int first, pid_t *pid)
{
	posix_spawn_file_actions_t fa;
	posix_spawnattr_t at;
	sigset_t none, all;
	sigemptyset(&none);
	sigfillset(&all);
	posix_spawn_file_actions_init(&fa);
	posix_spawnattr_init(&at);
	int rc = 0;
	for (int i = 0; i < n && !rc; i++) /* clears close-on-exec, also when fds[i] is first + i already */
		rc = posix_spawn_file_actions_adddup2(&fa, fds[i], first + i);
	if (!rc) /* after the dups: a descriptor 0 among fds is copied first */
		rc = posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
	if (!rc)
		rc = posix_spawn_file_actions_addclosefrom_np(&fa, first + n);
	if (!rc)
		rc = posix_spawnattr_setsigmask(&at, &none);
	if (!rc) /* the daemon's ignored SIGPIPE is not the child's */
		rc = posix_spawnattr_setsigdefault(&at, &all);
	if (!rc)
		rc = posix_spawnattr_setflags(&at, POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
	if (!rc)
		rc = posix_spawn(pid, "/proc/self/exe", &fa, &at, argv, environ);
	posix_spawn_file_actions_destroy(&fa);
	posix_spawnattr_destroy(&at);
	return rc;
}

int jobh_spawn(int *sock, pid_t *pid, struct acq_err *err)
{
	int sv[2];
	if (socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) < 0)
		return acq_errf(err, ACQ_E_IO, "job helper: socketpair: %s", strerror(errno));
	/* posix_spawn (vfork and exec): the loop neither copies the daemon's page tables nor leaves a copy of its
	 * memory, threads' state or descriptors in the helper; the helper's socket becomes its descriptor 3, its
	 * standard input /dev/null (its standard output and error stay the daemon's: its children write theirs into
	 * their pipes). */
	char dpid[24], name[] = "acq-helper", arg[] = JOB_HELPER_ARG;
	snprintf(dpid, sizeof dpid, "%d", (int)getpid());
	char *argv[] = { name, arg, dpid, NULL };
	pid_t p = 0;
	int rc = jobh_spawn_self(argv, &sv[1], 1, 3, &p);
	close(sv[1]);
	if (rc) {
		close(sv[0]);
		return acq_errf(err, ACQ_E_IO, "job helper: cannot run /proc/self/exe %s: %s", JOB_HELPER_ARG,
				strerror(rc));
	}
	*sock = sv[0];
	*pid = p;
	return 0;
}
