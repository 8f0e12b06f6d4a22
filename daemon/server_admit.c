/* server_admit: who gets in: a new connection's peer credentials (SO_PEERCRED; loopback TCP carries none), its
 * role from the configuration's controllers and observers, the connection limits (in all, per user, the last
 * slots kept for controllers), and refusals that stay open long enough to be read. */
#include <grp.h>
#include <poll.h>
#include <pwd.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/server_int.h"

#define ACCEPT_PER_TURN 64      /* connections accepted per loop turn */

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

/* Role of a local user per the configuration (root and the daemon's own uid are controllers); 0 = refused. */
static enum proto_role role_of(const struct conf_daemon *d, uid_t uid)
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


static int user_connections(const struct server *srv, const struct srv_peer *peer)
{
	int n = 0;
	for (const struct client *c = srv->clients; c; c = c->next)
		n += !c->refusing && c->peer.tcp == peer->tcp && (peer->tcp || c->peer.uid == peer->uid);
	return n;
}

/* Keep a refused connection open for linger_s with its banner and refusal queued, reading and discarding
 * its input: a client that writes its request before reading gets the refusal, not a broken pipe. */
static void refuse(struct server *srv, int fd, const struct srv_peer *peer, const char *code, const char *msg)
{
	srv->stats.refused++;
	double now = srv_now(srv);
	if (now - srv->stats.refused_logged_at >= 10 || !strcmp(code, PROTO_E_FORBIDDEN)) {
		srv->stats.refused_logged_at = now;
		log_msg(LOG_NOTICE, "refused a client (uid %d%s): %s (%llu refused so far)", peer->tcp ? -1 : (int)peer->uid,
			peer->tcp ? ", TCP" : "", msg, (unsigned long long)srv->stats.refused);
	}
	char *banner = proto_banner(srv->version);
	char *err = proto_reply_err(NULL, code, msg);
	struct client *c = srv->nrefusing < MAX_REFUSING ? calloc(1, sizeof *c) : NULL;
	struct acq_err e = { 0 };
	if (!c || loop_fd_add(srv->lp, fd, POLLIN | POLLOUT, srv_input_event, c, &e)) {
		/* Too many refusals at once: best effort, then close. */
		if (banner)
			(void)!send(fd, banner, strlen(banner), MSG_NOSIGNAL | MSG_DONTWAIT);
		if (err)
			(void)!send(fd, err, strlen(err), MSG_NOSIGNAL | MSG_DONTWAIT);
		free(banner);
		free(err);
		free(c);
		close(fd);
		return;
	}
	c->fd = fd;
	c->srv = srv;
	c->peer = *peer;
	c->peer.serial = ++srv->next_serial;
	c->refusing = c->closing = true;
	c->refused_at = now;
	proto_lines_init(&c->in);
	c->next = srv->clients;
	srv->clients = c;
	srv->nrefusing++;
	c->closing = false; /* srv_out_send drops lines to closing clients */
	srv_out_send(c, banner);
	srv_out_send(c, err);
	c->closing = true;
	srv_out_events(c);
}

static void accept_one(struct server *srv, int lfd, int fd)
{
	struct loop *lp = srv->lp;
	struct srv_peer peer = { 0 };
	if (lfd == srv->ufd) {
		struct ucred cr;
		socklen_t l = sizeof cr;
		peer.uid = (uid_t)-1;
		if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cr, &l) == 0) {
			peer.uid = cr.uid;
			peer.pid = cr.pid;
			peer.role = role_of(srv->d, cr.uid);
		}
	} else {
		/* Loopback TCP carries no credentials: read-only, for whoever is on this machine (see server.h). */
		peer.tcp = true;
		peer.uid = (uid_t)-1;
		peer.role = PROTO_OBSERVER;
	}
	const struct server_limits *lim = &srv->lim;
	char msg[160];
	if (!peer.role) {
		snprintf(msg, sizeof msg, "uid %u is neither a controller nor an observer of this daemon", (unsigned)peer.uid);
		return refuse(srv, fd, &peer, PROTO_E_FORBIDDEN, msg);
	}
	if (srv->nclients >= lim->max_clients || srv->nclients >= MAX_CLIENTS) {
		snprintf(msg, sizeof msg, "too many clients (%d connected)", srv->nclients);
		return refuse(srv, fd, &peer, PROTO_E_UNAVAILABLE, msg);
	}
	if (peer.role < PROTO_CONTROLLER && srv->nclients >= lim->max_clients - lim->controller_reserve) {
		snprintf(msg, sizeof msg, "too many clients: the last %d of %d slots are kept for controllers",
			 lim->controller_reserve, lim->max_clients);
		return refuse(srv, fd, &peer, PROTO_E_UNAVAILABLE, msg);
	}
	if (user_connections(srv, &peer) >= lim->per_user) {
		if (peer.tcp)
			snprintf(msg, sizeof msg, "too many clients: %d TCP connections already (the limit)", lim->per_user);
		else
			snprintf(msg, sizeof msg, "too many clients: uid %u has %d connections already (the limit per user)",
				 (unsigned)peer.uid, lim->per_user);
		return refuse(srv, fd, &peer, PROTO_E_UNAVAILABLE, msg);
	}
	struct client *c = calloc(1, sizeof *c);
	if (!c) {
		close(fd);
		return;
	}
	c->fd = fd;
	c->srv = srv;
	c->peer = peer;
	c->peer.serial = ++srv->next_serial;
	c->last_in = srv_now(srv);
	proto_lines_init(&c->in);
	struct acq_err err = { 0 };
	if ((peer.role < PROTO_CONTROLLER && !(c->bucket = srv_rate_get(srv, &peer))) ||
	    loop_fd_add(lp, fd, POLLIN, srv_input_event, c, &err)) {
		srv_rate_put(srv, c->bucket);
		close(fd);
		free(c);
		return;
	}
	c->next = srv->clients;
	srv->clients = c;
	srv->nclients++;
	srv_out_send(c, proto_banner(srv->version));
}

/* Accept what is pending (a bounded number per turn): a connection flood must not fill the listen backlog,
 * where a controller's connection would wait or be refused by the kernel without an answer. */
void srv_admit_accept(struct loop *lp, int lfd, short revents, void *arg)
{
	(void)lp;
	(void)revents;
	struct server *srv = arg;
	for (int i = 0; i < ACCEPT_PER_TURN; i++) {
		int fd = accept4(lfd, NULL, NULL, SOCK_CLOEXEC | SOCK_NONBLOCK);
		if (fd < 0)
			return;
		accept_one(srv, lfd, fd);
	}
}
