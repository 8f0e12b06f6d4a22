/* sockprobe: tells a serving daemon from a socket file that only looks alive (see sockprobe.h).
 *
 * A connect() that succeeds does not prove a daemon: the kernel completes it from the listen backlog for
 * any process that holds the listening descriptor. A daemon SIGKILLed just after fork() leaves its child
 * holding that descriptor until the child reaches exec/close_range or dies of PR_SET_PDEATHSIG, which on a
 * loaded machine can take a few hundred milliseconds. A daemon always writes its banner at accept, so a
 * connection that brings bytes is a daemon; one that stays mute is probed again until the holder is gone
 * (connect refused) or the wait ends. */
#include "daemon/sockprobe.h"

#include <errno.h>
#include <poll.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#define PROBE_REPLY_MS 200 /* wait for the banner on one connection */
#define PROBE_PAUSE_MS 50  /* between two connections */

static double mono_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

/* One connection: 1 bytes came, 0 connected but mute (or closed without a word), -1 refused/unreachable. */
static int probe_once(const struct sockaddr_un *sa)
{
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0)
		return 0; /* cannot tell: counts as mute, so the caller never replaces a file it could not probe */
	if (connect(fd, (const struct sockaddr *)sa, sizeof *sa) < 0) {
		close(fd);
		return -1;
	}
	struct pollfd p = { .fd = fd, .events = POLLIN };
	int n;
	do
		n = poll(&p, 1, PROBE_REPLY_MS);
	while (n < 0 && errno == EINTR);
	char c;
	int got = n > 0 && recv(fd, &c, 1, MSG_DONTWAIT) == 1;
	close(fd);
	return got;
}

enum sockprobe sockprobe_unix(const struct sockaddr_un *sa, double wait_s)
{
	double end = mono_s() + wait_s;
	for (;;) {
		int r = probe_once(sa);
		if (r < 0)
			return SOCKPROBE_STALE;
		if (r > 0)
			return SOCKPROBE_SERVING;
		if (mono_s() >= end)
			return SOCKPROBE_SILENT;
		struct timespec pause = { 0, PROBE_PAUSE_MS * 1000000L };
		nanosleep(&pause, NULL);
	}
}
