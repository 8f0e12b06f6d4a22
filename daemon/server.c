/* server: listeners, clients, authorisation and dispatch of the control protocol (see server.h). */
#include "daemon/server.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <grp.h>
#include <netinet/in.h>
#include <poll.h>
#include <pwd.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "daemon/log.h"
#include "daemon/loop.h"

#define OUT_PAUSE_READ (1u << 20)   /* stop reading a client whose replies pile up beyond this */
#define OUT_DROP (16u << 20)        /* drop a watcher that does not read its events at all */
#define MAX_CLIENTS 256

struct client {
	int fd;
	struct srv_peer peer;
	struct proto_lines in;
	char *out;
	size_t outlen, outcap;
	bool watch, closing;
	bool backlog;           /* complete lines left for the next turn */
	bool has_fd;            /* pass_fd leaves with the byte at offset pass_at of out (SCM_RIGHTS) */
	int pass_fd;
	size_t pass_at;
	struct client *next;
	struct server *srv;
};

struct server {
	struct loop *lp;
	const struct conf_daemon *d;
	char version[64];
	server_req_fn fn;
	void *ctx;
	int ufd, tfd;
	char path[256];
	struct client *clients;
	int nclients;
	uint64_t next_serial;
	uint64_t drain_timer;
};

static void client_close(struct client *c)
{
	struct server *srv = c->srv;
	for (struct client **p = &srv->clients; *p; p = &(*p)->next)
		if (*p == c) {
			*p = c->next;
			break;
		}
	srv->nclients--;
	loop_fd_del(srv->lp, c->fd);
	close(c->fd);
	if (c->has_fd)
		close(c->pass_fd);
	proto_lines_free(&c->in);
	free(c->out);
	free(c);
}

static struct client *client_by_serial(struct server *srv, uint64_t serial)
{
	for (struct client *c = srv->clients; c; c = c->next)
		if (c->peer.serial == serial)
			return c;
	return NULL;
}

static void update_events(struct client *c)
{
	short ev = 0;
	if (c->outlen || c->closing)
		ev |= POLLOUT; /* a closing client is closed from its next (writable) event */
	if (!c->closing && !c->backlog && c->outlen < OUT_PAUSE_READ)
		ev |= POLLIN;
	loop_fd_events(c->srv->lp, c->fd, ev);
}

/* send() of the bytes before a passed descriptor, or of the rest with the descriptor attached. */
static ssize_t send_part(struct client *c)
{
	if (!c->has_fd || c->pass_at > 0)
		return send(c->fd, c->out, c->has_fd ? c->pass_at : c->outlen, MSG_NOSIGNAL | MSG_DONTWAIT);
	union {
		char b[CMSG_SPACE(sizeof(int))];
		struct cmsghdr align;
	} ctl;
	memset(&ctl, 0, sizeof ctl);
	struct iovec iov = { .iov_base = c->out, .iov_len = c->outlen };
	struct msghdr mh = { .msg_iov = &iov, .msg_iovlen = 1, .msg_control = ctl.b, .msg_controllen = sizeof ctl.b };
	struct cmsghdr *cm = CMSG_FIRSTHDR(&mh);
	cm->cmsg_level = SOL_SOCKET;
	cm->cmsg_type = SCM_RIGHTS;
	cm->cmsg_len = CMSG_LEN(sizeof(int));
	memcpy(CMSG_DATA(cm), &c->pass_fd, sizeof(int));
	ssize_t n = sendmsg(c->fd, &mh, MSG_NOSIGNAL | MSG_DONTWAIT);
	if (n > 0) {
		close(c->pass_fd);
		c->has_fd = false;
	}
	return n;
}

static void flush_out(struct client *c)
{
	while (c->outlen) {
		ssize_t n = send_part(c);
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))
			break;
		if (n <= 0) {
			c->outlen = 0;
			c->closing = true;
			break;
		}
		memmove(c->out, c->out + n, c->outlen - (size_t)n);
		c->outlen -= (size_t)n;
		if (c->has_fd)
			c->pass_at -= (size_t)n;
	}
}

/* Queue a line (consumed); returns false if the client was dropped. */
static void client_send(struct client *c, char *line)
{
	if (!line)
		return;
	size_t n = strlen(line);
	if (c->outlen + n > OUT_DROP) {
		log_msg(LOG_WARNING, "client %llu (uid %u) does not read its replies; dropping it",
			(unsigned long long)c->peer.serial, (unsigned)c->peer.uid);
		c->outlen = 0;
		c->closing = true;
		free(line);
		return;
	}
	if (c->outlen + n > c->outcap) {
		size_t cap = c->outcap ? c->outcap : 4096;
		while (cap < c->outlen + n)
			cap *= 2;
		char *o = realloc(c->out, cap);
		if (!o) {
			free(line);
			c->closing = true;
			return;
		}
		c->out = o;
		c->outcap = cap;
	}
	memcpy(c->out + c->outlen, line, n);
	c->outlen += n;
	free(line);
	/* Replies to a burst of requests leave in one write, from the loop (POLLOUT), unless they pile up. */
	if (c->outlen >= 65536)
		flush_out(c);
	update_events(c);
}

static void send_error(struct client *c, json_t *id, const char *code, const char *msg)
{
	client_send(c, proto_reply_err(id, code, msg));
}

static void handle_line(struct client *c, const char *line, size_t len)
{
	struct proto_req req;
	const char *code;
	struct acq_err err = { 0 };
	if (proto_req_parse(line, len, &req, &code, &err)) {
		send_error(c, req.id, code, err.msg);
		proto_req_free(&req);
		return;
	}
	if (req.def->role > c->peer.role) {
		char msg[160];
		snprintf(msg, sizeof msg, "%s needs a controller; uid %u is an observer", req.cmd, (unsigned)c->peer.uid);
		send_error(c, req.id, PROTO_E_FORBIDDEN, msg);
	} else if (!strcmp(req.cmd, "watch")) {
		c->watch = true;
		client_send(c, proto_reply_ok(req.id, json_pack("{s:b}", "watching", 1)));
	} else {
		c->srv->fn(c->srv->ctx, &c->peer, &req);
	}
	proto_req_free(&req);
}

#define LINES_PER_TURN 128  /* lines handled per client per loop turn, so a flood cannot starve others */

static void drain_cb(struct loop *lp, void *arg);

/* Handle up to LINES_PER_TURN complete lines of client serial; true if more are buffered. The handler may
 * reply to this client or close others, so the client is looked up again after each line. */
static bool process_lines(struct server *srv, uint64_t serial)
{
	struct client *c;
	char *line;
	size_t len;
	int k;
	for (int n = 0; n < LINES_PER_TURN; n++) {
		if (!(c = client_by_serial(srv, serial)) || c->closing || !(k = proto_lines_next(&c->in, &line, &len)))
			return false;
		if (k == PROTO_LINE_TOO_LONG) {
			char msg[96];
			snprintf(msg, sizeof msg, "line longer than %d bytes: ignored up to its newline", PROTO_MAX_LINE);
			send_error(c, NULL, PROTO_E_TOO_LONG, msg);
		} else if (len) {
			handle_line(c, line, len);
		}
	}
	c = client_by_serial(srv, serial);
	if (!c || c->closing)
		return false;
	c->backlog = true;
	if (!srv->drain_timer)
		srv->drain_timer = loop_timer_add(srv->lp, 0, 0, drain_cb, srv);
	return true;
}

static void finish_turn(struct client *c)
{
	if (c->closing && !c->outlen) {
		client_close(c);
		return;
	}
	update_events(c);
}

/* Next turn for clients with buffered lines (after every other ready fd had its turn). */
static void drain_cb(struct loop *lp, void *arg)
{
	(void)lp;
	struct server *srv = arg;
	srv->drain_timer = 0;
	uint64_t serials[MAX_CLIENTS];
	int n = 0;
	for (struct client *c = srv->clients; c && n < MAX_CLIENTS; c = c->next)
		if (c->backlog) {
			c->backlog = false;
			serials[n++] = c->peer.serial;
		}
	for (int i = 0; i < n; i++) {
		process_lines(srv, serials[i]);
		struct client *c = client_by_serial(srv, serials[i]);
		if (c)
			finish_turn(c);
	}
}

static void on_client(struct loop *lp, int fd, short revents, void *arg)
{
	(void)lp;
	struct client *c = arg;
	struct server *srv = c->srv;
	uint64_t serial = c->peer.serial;
	if (revents & POLLOUT)
		flush_out(c);
	/* With lines still buffered, read nothing more until they are handled (bounded memory). */
	if ((revents & (POLLIN | POLLHUP | POLLERR)) && !c->closing && !c->backlog) {
		char buf[65536];
		ssize_t n = recv(fd, buf, sizeof buf, MSG_DONTWAIT);
		if (n < 0 && (errno == EINTR || errno == EAGAIN))
			return;
		if (n <= 0 || proto_lines_feed(&c->in, buf, (size_t)n)) {
			client_close(c);
			return;
		}
		process_lines(srv, serial);
		if (!(c = client_by_serial(srv, serial)))
			return;
	}
	finish_turn(c);
}

static bool name_in_groups(const char *grname, const struct passwd *pw)
{
	struct group *gr = getgrnam(grname);
	if (!gr)
		return false;
	gid_t groups[256];
	int ng = 256;
	if (getgrouplist(pw->pw_name, pw->pw_gid, groups, &ng) < 0)
		return false;
	for (int i = 0; i < ng; i++)
		if (groups[i] == gr->gr_gid)
			return true;
	return false;
}

static bool listed(const char *const *list, int n, const struct passwd *pw)
{
	for (int i = 0; pw && i < n; i++) {
		if (list[i][0] == '@' ? name_in_groups(list[i] + 1, pw) : !strcmp(list[i], pw->pw_name))
			return true;
	}
	return false;
}

enum proto_role server_role_of(const struct conf_daemon *d, uid_t uid)
{
	if (uid == 0 || uid == geteuid())
		return PROTO_CONTROLLER;
	struct passwd *pw = getpwuid(uid);
	if (listed(d->controllers, d->ncontrollers, pw))
		return PROTO_CONTROLLER;
	if (listed(d->observers, d->nobservers, pw))
		return PROTO_OBSERVER;
	return 0;
}

static void on_accept(struct loop *lp, int lfd, short revents, void *arg)
{
	(void)revents;
	struct server *srv = arg;
	int fd = accept4(lfd, NULL, NULL, SOCK_CLOEXEC | SOCK_NONBLOCK);
	if (fd < 0)
		return;
	if (srv->nclients >= MAX_CLIENTS) {
		static const char msg[] = "{\"id\":null,\"ok\":false,\"error\":{\"code\":\"unavailable\",\"message\":"
					  "\"too many clients\"}}\n";
		ssize_t w = send(fd, msg, sizeof msg - 1, MSG_NOSIGNAL | MSG_DONTWAIT);
		(void)w;
		close(fd);
		return;
	}
	struct client *c = calloc(1, sizeof *c);
	if (!c) {
		close(fd);
		return;
	}
	c->fd = fd;
	c->srv = srv;
	c->peer.serial = ++srv->next_serial;
	proto_lines_init(&c->in);
	if (lfd == srv->ufd) {
		struct ucred cr;
		socklen_t l = sizeof cr;
		if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cr, &l) == 0) {
			c->peer.uid = cr.uid;
			c->peer.pid = cr.pid;
			c->peer.role = server_role_of(srv->d, cr.uid);
		}
	} else {
		/* Loopback TCP carries no credentials: read-only. */
		c->peer.tcp = true;
		c->peer.uid = (uid_t)-1;
		c->peer.role = PROTO_OBSERVER;
	}
	struct acq_err err = { 0 };
	if (loop_fd_add(lp, fd, POLLIN, on_client, c, &err)) {
		close(fd);
		free(c);
		return;
	}
	c->next = srv->clients;
	srv->clients = c;
	srv->nclients++;
	client_send(c, proto_banner(srv->version));
	if (!c->peer.role) {
		char msg[128];
		snprintf(msg, sizeof msg, "uid %u is neither a controller nor an observer of this daemon",
			 (unsigned)c->peer.uid);
		log_msg(LOG_NOTICE, "refused a client: %s", msg);
		send_error(c, NULL, PROTO_E_FORBIDDEN, msg);
		c->closing = true;
		update_events(c);
	}
}

static int listen_unix(struct server *srv, const struct conf_daemon *d, struct acq_err *err)
{
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	if (strlen(d->socket_path) >= sizeof sa.sun_path)
		return acq_errf(err, ACQ_E_CONFIG, "daemon.socket.path: longer than %zu bytes", sizeof sa.sun_path - 1);
	strcpy(sa.sun_path, d->socket_path);
	struct stat sb;
	if (lstat(d->socket_path, &sb) == 0) {
		if (!S_ISSOCK(sb.st_mode))
			return acq_errf(err, ACQ_E_IO, "%s exists and is not a socket; not touching it", d->socket_path);
		int probe = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
		bool alive = probe >= 0 && connect(probe, (struct sockaddr *)&sa, sizeof sa) == 0;
		if (probe >= 0)
			close(probe);
		if (alive)
			return acq_errf(err, ACQ_E_STATE, "%s: another acquisitiond is listening there", d->socket_path);
		unlink(d->socket_path); /* stale socket of a killed daemon */
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
	if (listen(srv->ufd, 64) < 0)
		return acq_errf(err, ACQ_E_IO, "%s: listen: %s", d->socket_path, strerror(errno));
	return loop_fd_add(srv->lp, srv->ufd, POLLIN, on_accept, srv, err);
}

static int listen_tcp(struct server *srv, int port, struct acq_err *err)
{
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port),
				  .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	srv->tfd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
	int one = 1;
	if (srv->tfd < 0 || setsockopt(srv->tfd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) < 0 ||
	    bind(srv->tfd, (struct sockaddr *)&sa, sizeof sa) < 0 || listen(srv->tfd, 64) < 0)
		return acq_errf(err, ACQ_E_IO, "127.0.0.1:%d: %s", port, strerror(errno));
	return loop_fd_add(srv->lp, srv->tfd, POLLIN, on_accept, srv, err);
}

int server_init(struct loop *lp, const struct conf_daemon *d, const char *version, server_req_fn fn, void *ctx,
		struct server **out, struct acq_err *err)
{
	struct server *srv = calloc(1, sizeof *srv);
	if (!srv)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	*srv = (struct server){ .lp = lp, .d = d, .fn = fn, .ctx = ctx, .ufd = -1, .tfd = -1 };
	snprintf(srv->version, sizeof srv->version, "%s", version);
	if (listen_unix(srv, d, err) || (d->tcp_port && listen_tcp(srv, d->tcp_port, err))) {
		server_finish(srv);
		return -1;
	}
	*out = srv;
	return 0;
}

void server_finish(struct server *srv)
{
	if (!srv)
		return;
	loop_timer_cancel(srv->lp, srv->drain_timer);
	while (srv->clients) {
		flush_out(srv->clients);
		client_close(srv->clients);
	}
	if (srv->ufd >= 0) {
		loop_fd_del(srv->lp, srv->ufd);
		close(srv->ufd);
		if (srv->path[0])
			unlink(srv->path);
	}
	if (srv->tfd >= 0) {
		loop_fd_del(srv->lp, srv->tfd);
		close(srv->tfd);
	}
	free(srv);
}

void server_set_conf(struct server *srv, const struct conf_daemon *d)
{
	srv->d = d;
}

void server_reply(struct server *srv, uint64_t serial, json_t *id, json_t *data)
{
	struct client *c = client_by_serial(srv, serial);
	if (!c) {
		json_decref(data);
		return;
	}
	client_send(c, proto_reply_ok(id, data));
}

int server_reply_fd(struct server *srv, uint64_t serial, json_t *id, json_t *data, int fd)
{
	struct client *c = client_by_serial(srv, serial);
	if (!c || c->closing || c->has_fd || c->peer.tcp) {
		json_decref(data);
		close(fd);
		return -1;
	}
	c->has_fd = true;
	c->pass_fd = fd;
	c->pass_at = c->outlen;
	client_send(c, proto_reply_ok(id, data));
	if (!c->closing && c->has_fd && c->pass_at >= c->outlen) { /* the reply was not queued */
		close(fd);
		c->has_fd = false;
		return -1;
	}
	return 0;
}

void server_reply_error(struct server *srv, uint64_t serial, json_t *id, const char *code, const char *msg)
{
	struct client *c = client_by_serial(srv, serial);
	if (c)
		send_error(c, id, code, msg);
}

void server_broadcast(struct server *srv, const char *event, json_t *data)
{
	int n = 0;
	for (struct client *c = srv->clients; c; c = c->next)
		n += c->watch && !c->closing;
	if (!n) {
		json_decref(data);
		return;
	}
	char *line = proto_event(event, data);
	if (!line)
		return;
	for (struct client *c = srv->clients, *next; c; c = next) {
		next = c->next;
		if (c->watch && !c->closing)
			client_send(c, strdup(line));
	}
	free(line);
}

void server_counts(const struct server *srv, int *clients, int *watchers)
{
	*clients = srv->nclients;
	*watchers = 0;
	for (const struct client *c = srv->clients; c; c = c->next)
		*watchers += c->watch;
}
