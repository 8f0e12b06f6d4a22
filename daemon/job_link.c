/* job_link: the daemon's end of the job helper's socket (job_helper.c is the other): the helper started and restarted,
 * its children's starts and kills sent, their ends and the helper's loss reported to the jobs (job.c) through the
 * callbacks given to jobl_init. */
#include "daemon/job_link.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include "daemon/job_int.h"
#include "daemon/log.h"
#include "daemon/loop.h"

/* The helper (job_helper.c): its socket (-1: not running), process, the next child's id; the loop and the jobs'
 * callbacks (jobl_init). */
static int h_sock = -1;
static pid_t h_pid;
static pid_t h_shown; /* the latest helper's process id, for messages (h_pid is 0 once it is reaped) */
static uint64_t h_next = 1;
static unsigned h_starts;
static struct loop *l_loop;
static jobl_done_fn l_done;
static jobl_lost_fn l_lost;
static pid_t h_dead[8]; /* helpers gone but not reaped yet (job_reap) */

/* Reap h_pid if it has exited, else keep it for job_reap; h_pid is 0 after. */
static void helper_forget(void)
{
	if (h_pid <= 0)
		return;
	if (waitpid(h_pid, NULL, WNOHANG) != h_pid) {
		size_t i = 0;
		while (i < sizeof h_dead / sizeof h_dead[0] && h_dead[i])
			i++;
		if (i == sizeof h_dead / sizeof h_dead[0]) { /* full (unlikely): wait for the oldest, SIGKILLed */
			kill(h_dead[0], SIGKILL);
			waitpid(h_dead[0], NULL, 0);
			i = 0;
		}
		h_dead[i] = h_pid;
	}
	h_pid = 0;
}

void jobl_init(struct loop *lp, jobl_done_fn done, jobl_lost_fn lost)
{
	l_loop = lp;
	l_done = done;
	l_lost = lost;
}

static int helper_send(struct jobh_msg *m, const int *fds, int nfd)
{
	union {
		char buf[CMSG_SPACE(2 * sizeof(int))];
		struct cmsghdr align;
	} cb;
	struct iovec iov = { m, sizeof *m };
	struct msghdr mh = { .msg_iov = &iov, .msg_iovlen = 1 };
	if (nfd) {
		memset(&cb, 0, sizeof cb);
		mh.msg_control = cb.buf;
		mh.msg_controllen = CMSG_SPACE(nfd * sizeof(int));
		struct cmsghdr *c = CMSG_FIRSTHDR(&mh);
		c->cmsg_level = SOL_SOCKET;
		c->cmsg_type = SCM_RIGHTS;
		c->cmsg_len = CMSG_LEN(nfd * sizeof(int));
		memcpy(CMSG_DATA(c), fds, nfd * sizeof(int));
	}
	ssize_t n;
	do /* never waits: a helper that does not read its messages fails the request */
		n = sendmsg(h_sock, &mh, MSG_DONTWAIT | MSG_NOSIGNAL);
	while (n < 0 && errno == EINTR);
	return n == (ssize_t)sizeof *m ? 0 : -1;
}

void jobl_kill(uint64_t hid, int sig)
{
	struct jobh_msg m = { .type = JOBH_KILL, .sig_or_status = sig, .id = hid };
	if (h_sock >= 0 && helper_send(&m, NULL, 0) < 0)
		log_msg(LOG_WARNING, "job helper: the kill of child %llu not sent: %s", (unsigned long long)hid,
			strerror(errno));
}

/* The helper has gone (EOF, or kill: it hangs): its children die with it (PR_SET_PDEATHSIG); each running one
 * ends as killed, lost; the next job_fork_msg() starts a new helper. */
void jobl_lost(bool kill_it)
{
	if (h_sock < 0)
		return;
	loop_fd_del(l_loop, h_sock);
	close(h_sock);
	h_sock = -1;
	if (h_pid > 0 && kill_it)
		kill(h_pid, SIGKILL);
	helper_forget(); /* reaped now or by job_reap() */
	l_lost();
}

static void on_helper(struct loop *lp, int fd, short revents, void *arg)
{
	(void)lp;
	(void)revents;
	(void)arg;
	for (int k = 0; k < 64; k++) {
		struct jobh_msg m;
		ssize_t n = recv(fd, &m, sizeof m, MSG_DONTWAIT);
		if (n < 0 && (errno == EINTR || errno == EAGAIN))
			return;
		if (n <= 0) {
			log_msg(LOG_WARNING, "job helper (pid %d) has gone: its running children end as killed; a new "
				"one starts with the next job", (int)h_shown);
			jobl_lost(false);
			return;
		}
		if ((size_t)n != sizeof m || m.type != JOBH_DONE)
			continue;
		l_done(m.id, m.sig_or_status);
	}
}

int job_helper_start(struct acq_err *err)
{
	if (h_sock >= 0)
		return 0;
	if (!l_loop)
		return acq_errf(err, ACQ_E_INVAL, "job: not initialised");
	helper_forget();
	int sock;
	pid_t pid;
	if (jobh_spawn(&sock, &pid, err))
		return -1;
	fcntl(sock, F_SETFL, O_NONBLOCK);
	if (loop_fd_add(l_loop, sock, POLLIN, on_helper, NULL, err)) {
		close(sock);
		kill(pid, SIGKILL);
		waitpid(pid, NULL, 0);
		return -1;
	}
	if (h_starts++)
		log_msg(LOG_NOTICE, "job helper restarted (pid %d)", (int)pid);
	h_sock = sock;
	h_pid = h_shown = pid;
	return 0;
}

pid_t job_helper_pid(void)
{
	return h_sock >= 0 ? h_pid : 0;
}

int jobl_start(uint32_t kind, uint64_t mem_bytes, unsigned cpu_s, const int fds[2], uint64_t *hid,
	       struct acq_err *err)
{
	struct jobh_msg m = { .type = JOBH_START, .id = h_next++, .mem_bytes = mem_bytes, .kind = kind,
			      .cpu_s = cpu_s };
	if (helper_send(&m, fds, 2) < 0) {
		acq_errf(err, ACQ_E_UNSUPPORTED, "the job helper (pid %d) does not take the request: %s; it is restarted: "
			 "retry", (int)h_pid, strerror(errno));
		jobl_lost(true);
		return -1;
	}
	*hid = m.id;
	return 0;
}

void jobl_reap(void)
{
	for (size_t i = 0; i < sizeof h_dead / sizeof h_dead[0]; i++)
		if (h_dead[i] > 0 && waitpid(h_dead[i], NULL, WNOHANG) == h_dead[i])
			h_dead[i] = 0;
	if (h_pid > 0 && waitpid(h_pid, NULL, WNOHANG) == h_pid) { /* the helper: its socket's EOF tells the jobs */
		h_pid = 0;
		if (h_sock >= 0)
			on_helper(l_loop, h_sock, POLLHUP, NULL);
	}
}

void jobl_finish(void)
{
	if (h_sock >= 0) { /* the helper ends at its socket's EOF, its children with it (PR_SET_PDEATHSIG) */
		loop_fd_del(l_loop, h_sock);
		close(h_sock);
		h_sock = -1;
	}
	if (h_pid > 0) {
		bool gone = false;
		for (int i = 0; i < 200 && !(gone = waitpid(h_pid, NULL, WNOHANG) == h_pid); i++)
			usleep(10000);
		if (!gone) {
			kill(h_pid, SIGKILL);
			waitpid(h_pid, NULL, 0);
		}
		h_pid = 0;
	}
	for (size_t i = 0; i < sizeof h_dead / sizeof h_dead[0]; i++)
		if (h_dead[i] > 0) {
			kill(h_dead[i], SIGKILL);
			waitpid(h_dead[i], NULL, 0);
			h_dead[i] = 0;
		}
	h_starts = 0;
}
