/* client: the client side of the protocol — connect, read a framed JSON line, write (acqctl, tests). */
#include "proto/proto.h"

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

int proto_client_connect(const char *where, struct acq_err *err)
{
	int fd;
	if (!strncmp(where, "tcp:", 4)) {
		char *end;
		long port = strtol(where + 4, &end, 10);
		if (*end || port < 1 || port > 65535)
			return acq_errf(err, ACQ_E_INVAL, "%s: expected tcp:PORT", where);
		struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port),
					  .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
		fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
		if (fd < 0 || connect(fd, (struct sockaddr *)&sa, sizeof sa) < 0)
			goto fail;
		return fd;
	}
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	if (strlen(where) >= sizeof sa.sun_path)
		return acq_errf(err, ACQ_E_INVAL, "%s: socket path too long", where);
	strcpy(sa.sun_path, where);
	fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0 || connect(fd, (struct sockaddr *)&sa, sizeof sa) < 0)
		goto fail;
	return fd;
fail:
	acq_errf(err, ACQ_E_IO, "%s: %s", where, strerror(errno));
	if (fd >= 0)
		close(fd);
	return -1;
}

json_t *proto_client_read(int fd, struct proto_lines *pl, int timeout_ms, struct acq_err *err)
{
	return proto_client_read_fd(fd, pl, timeout_ms, NULL, err);
}

/* recv() that keeps a file descriptor passed along (see proto_client_read_fd). */
static ssize_t recv_fds(int fd, char *buf, size_t cap, int *passed)
{
	union {
		char b[CMSG_SPACE(4 * sizeof(int))];
		struct cmsghdr align;
	} ctl;
	struct iovec iov = { .iov_base = buf, .iov_len = cap };
	struct msghdr mh = { .msg_iov = &iov, .msg_iovlen = 1, .msg_control = ctl.b, .msg_controllen = sizeof ctl.b };
	ssize_t n = recvmsg(fd, &mh, MSG_CMSG_CLOEXEC);
	if (n < 0 && errno == ENOTSOCK)
		return read(fd, buf, cap);
	for (struct cmsghdr *c = n >= 0 ? CMSG_FIRSTHDR(&mh) : NULL; c; c = CMSG_NXTHDR(&mh, c)) {
		if (c->cmsg_level != SOL_SOCKET || c->cmsg_type != SCM_RIGHTS)
			continue;
		size_t k = (c->cmsg_len - CMSG_LEN(0)) / sizeof(int);
		for (size_t i = 0; i < k; i++) {
			int x;
			memcpy(&x, CMSG_DATA(c) + i * sizeof(int), sizeof x);
			if (passed && *passed < 0)
				*passed = x;
			else
				close(x);
		}
	}
	return n;
}

json_t *proto_client_read_fd(int fd, struct proto_lines *pl, int timeout_ms, int *passed, struct acq_err *err)
{
	for (;;) {
		char *line;
		size_t len;
		int k = proto_lines_next(pl, &line, &len);
		if (k == PROTO_LINE_TOO_LONG) {
			acq_errf(err, ACQ_E_PROTO, "reply longer than %zu bytes", pl->max ? pl->max : (size_t)PROTO_MAX_LINE);
			return NULL;
		}
		if (k == PROTO_LINE_OK) {
			json_error_t je;
			json_t *v = json_loadb(line, len, 0, &je);
			if (!v)
				acq_errf(err, ACQ_E_PROTO, "bad reply: %s", je.text);
			return v;
		}
		struct pollfd p = { .fd = fd, .events = POLLIN };
		int r = poll(&p, 1, timeout_ms);
		if (r == 0) {
			acq_errf(err, ACQ_E_TIMEOUT, "no reply within %d ms", timeout_ms);
			return NULL;
		}
		if (r < 0 && errno != EINTR) {
			acq_errf(err, ACQ_E_IO, "poll: %s", strerror(errno));
			return NULL;
		}
		if (r < 0)
			continue;
		char buf[16384];
		ssize_t n = recv_fds(fd, buf, sizeof buf, passed);
		if (n < 0 && (errno == EINTR || errno == EAGAIN))
			continue;
		if (n <= 0) {
			acq_errf(err, n == 0 ? ACQ_E_DISCONNECTED : ACQ_E_IO, "connection %s",
				 n == 0 ? "closed by the daemon" : strerror(errno));
			return NULL;
		}
		if (proto_lines_feed(pl, buf, (size_t)n)) {
			acq_errf(err, ACQ_E_NOMEM, "out of memory");
			return NULL;
		}
	}
}

int proto_write_all(int fd, const char *buf, size_t len, struct acq_err *err)
{
	while (len) {
		ssize_t n = send(fd, buf, len, MSG_NOSIGNAL);
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0 && errno == ENOTSOCK)
			n = write(fd, buf, len);
		if (n < 0)
			return acq_errf(err, ACQ_E_IO, "write: %s", strerror(errno));
		buf += n;
		len -= (size_t)n;
	}
	return 0;
}
