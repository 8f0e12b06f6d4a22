/* acqd_signals: signals through a self-pipe — the handlers only write the signal's number, the loop does the work
 * (stop, reload, reap). */
#include "daemon/acquisitiond/acqd.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <string.h>
#include <unistd.h>

#include "daemon/job.h"
#include "daemon/log.h"
#include "daemon/loop.h"

static int sig_pipe[2] = { -1, -1 };
static bool want_stop;

static void on_signal(int sig)
{
	int e = errno;
	unsigned char b = (unsigned char)sig;
	ssize_t w = write(sig_pipe[1], &b, 1);
	(void)w;
	errno = e;
}

static void on_sigpipe(struct loop *lp, int fd, short revents, void *arg)
{
	(void)revents;
	struct app *app = arg;
	unsigned char b[64];
	ssize_t n;
	while ((n = read(fd, b, sizeof b)) > 0)
		for (ssize_t i = 0; i < n; i++) {
			switch (b[i]) {
			case SIGTERM:
			case SIGINT:
				log_msg(LOG_NOTICE, "signal %d: stopping", b[i]);
				want_stop = true;
				loop_stop(lp);
				break;
			case SIGHUP: {
				struct acq_err err = { 0 };
				if (app_reload(app, NULL, &err))
					log_msg(LOG_WARNING, "SIGHUP: %s", err.msg);
				break;
			}
			case SIGCHLD:
				job_reap();
				break;
			}
		}
}

int acqd_signals_init(struct app *app, struct acq_err *err)
{
	if (pipe2(sig_pipe, O_CLOEXEC | O_NONBLOCK) < 0)
		return acq_errf(err, ACQ_E_IO, "pipe: %s", strerror(errno));
	struct sigaction sa = { .sa_handler = on_signal, .sa_flags = SA_RESTART };
	sigemptyset(&sa.sa_mask);
	int sigs[] = { SIGTERM, SIGINT, SIGHUP, SIGCHLD };
	for (size_t i = 0; i < sizeof sigs / sizeof sigs[0]; i++)
		if (sigaction(sigs[i], &sa, NULL) < 0)
			return acq_errf(err, ACQ_E_IO, "sigaction: %s", strerror(errno));
	signal(SIGPIPE, SIG_IGN);
	return loop_fd_add(app->lp, sig_pipe[0], POLLIN, on_sigpipe, app, err);
}

void acqd_signals_finish(void)
{
	if (sig_pipe[0] < 0)
		return;
	signal(SIGTERM, SIG_DFL);
	signal(SIGINT, SIG_DFL);
	signal(SIGHUP, SIG_DFL);
	signal(SIGCHLD, SIG_DFL);
	close(sig_pipe[0]);
	close(sig_pipe[1]);
	sig_pipe[0] = sig_pipe[1] = -1;
}

bool acqd_stop_wanted(void)
{
	return want_stop;
}
