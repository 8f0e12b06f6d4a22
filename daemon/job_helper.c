/* job_helper: the small process that forks the daemon's job_fork_msg() children (job.h). It is forked once,
 * early at start-up (no device thread, no database yet: a few MB), so each child is a fork of it, never of the
 * daemon with its threads and memory: the loop only writes a message. Messages: job_int.h. */
#include "daemon/job_int.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
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

static struct hchild kids[JOBH_MAX_CHILDREN];
static int n_kids;

static void send_done(int sock, uint64_t id, int status)
{
	struct jobh_msg m = { .type = JOBH_DONE, .sig_or_status = status, .id = id };
	while (send(sock, &m, sizeof m, MSG_NOSIGNAL) < 0 && errno == EINTR)
		;
}

/* In the job's child: read the payload from its memfd, run fn with the output on fd 1. Never returns. */
static void run_child(pid_t helper, const struct jobh_msg *m, int payload, int out)
{
	job_child_setup(helper);
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
	job_child_limits((size_t)m->mem_bytes);
	_exit(m->fn(buf, len, 1));
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
	if ((size_t)n == sizeof m && m.type == JOBH_START && nfd == 2 && m.fn)
		start_child(sock, &m, fds[0], fds[1]);
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
 * with the helper: PR_SET_PDEATHSIG). */
static _Noreturn void helper_main(int sock, pid_t daemon)
{
	job_child_setup(daemon);
	signal(SIGHUP, SIG_IGN); /* a terminal's hang-up is the daemon's to handle (reload), not a reason to die */
	prctl(PR_SET_NAME, "acq-helper");
	if (sock != 3) {
		dup2(sock, 3);
		sock = 3;
	}
	close_range(4, ~0U, 0);
	int nul = open("/dev/null", O_RDWR);
	if (nul >= 0) {
		dup2(nul, 0); /* the daemon's stdout/stderr (its log, a terminal) stay the children's only by the pipe */
		if (nul > 3)
			close(nul);
	}
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

int jobh_spawn(int *sock, pid_t *pid, struct acq_err *err)
{
	int sv[2];
	if (socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) < 0)
		return acq_errf(err, ACQ_E_IO, "job helper: socketpair: %s", strerror(errno));
	pid_t daemon = getpid();
	pid_t p = fork();
	if (p < 0) {
		close(sv[0]);
		close(sv[1]);
		return acq_errf(err, ACQ_E_IO, "job helper: fork: %s", strerror(errno));
	}
	if (p == 0) {
		close(sv[0]);
		helper_main(sv[1], daemon);
	}
	close(sv[1]);
	*sock = sv[0];
	*pid = p;
	return 0;
}
