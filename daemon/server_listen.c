/* server_listen: the control socket's listeners: the Unix socket (a live daemon's refused, a killed one's
 * replaced; bound under a tight umask, then its group and mode set) and the optional loopback TCP port. */
#include <arpa/inet.h>
#include <errno.h>
#include <grp.h>
#include <netinet/in.h>
#include <poll.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "daemon/loop.h"
#include "daemon/server_int.h"
#include "daemon/sockprobe.h"

#define LISTEN_BACKLOG 512
#define PROBE_WAIT_S 3.0        /* how long a socket that accepts but never answers is given to go away */

int srv_listen_unix(struct server *srv, const struct conf_daemon *d, struct acq_err *err)
{
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	if (strlen(d->socket_path) >= sizeof sa.sun_path)
		return acq_errf(err, ACQ_E_CONFIG, "daemon.socket.path: longer than %zu bytes", sizeof sa.sun_path - 1);
	strcpy(sa.sun_path, d->socket_path);
	struct stat sb;
	if (lstat(d->socket_path, &sb) == 0) {
		if (!S_ISSOCK(sb.st_mode))
			return acq_errf(err, ACQ_E_IO, "%s exists and is not a socket; not touching it", d->socket_path);
		enum sockprobe st = sockprobe_unix(&sa, PROBE_WAIT_S);
		if (st != SOCKPROBE_STALE)
			return acq_errf(err, ACQ_E_STATE, "%s: %s", d->socket_path, st == SOCKPROBE_SERVING
				? "another acquisitiond is listening there"
				: "something accepts connections there but never answered (a stopped acquisitiond?)");
		unlink(d->socket_path); /* stale socket of a killed daemon (or of its child, now gone) */
	}
	srv->ufd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
	if (srv->ufd < 0)
		return acq_errf(err, ACQ_E_IO, "socket: %s", strerror(errno));
	/* Bind under a tight umask so the socket never exists with looser permissions than configured. */
	mode_t old = umask(0177);
	int rc = bind(srv->ufd, (struct sockaddr *)&sa, sizeof sa);
	umask(old);
	if (rc < 0)
		return acq_errf(err, ACQ_E_IO, "%s: bind: %s", d->socket_path, strerror(errno));
	snprintf(srv->path, sizeof srv->path, "%s", d->socket_path);
	if (d->socket_group) {
		struct group *gr = getgrnam(d->socket_group);
		if (!gr)
			return acq_errf(err, ACQ_E_CONFIG, "daemon.socket.group: no group '%s'", d->socket_group);
		if (chown(d->socket_path, (uid_t)-1, gr->gr_gid) < 0)
			return acq_errf(err, ACQ_E_IO, "%s: chown: %s", d->socket_path, strerror(errno));
	}
	if (chmod(d->socket_path, d->socket_mode) < 0)
		return acq_errf(err, ACQ_E_IO, "%s: chmod: %s", d->socket_path, strerror(errno));
	if (listen(srv->ufd, LISTEN_BACKLOG) < 0)
		return acq_errf(err, ACQ_E_IO, "%s: listen: %s", d->socket_path, strerror(errno));
	return loop_fd_add(srv->lp, srv->ufd, POLLIN, srv_admit_accept, srv, err);
}

int srv_listen_tcp(struct server *srv, int port, struct acq_err *err)
{
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port),
				  .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	srv->tfd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
	int one = 1;
	if (srv->tfd < 0 || setsockopt(srv->tfd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) < 0 ||
	    bind(srv->tfd, (struct sockaddr *)&sa, sizeof sa) < 0 || listen(srv->tfd, LISTEN_BACKLOG) < 0)
		return acq_errf(err, ACQ_E_IO, "127.0.0.1:%d: %s", port, strerror(errno));
	return loop_fd_add(srv->lp, srv->tfd, POLLIN, srv_admit_accept, srv, err);
}
