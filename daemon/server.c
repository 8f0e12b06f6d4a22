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
#include "daemon/sockprobe.h"

#define MAX_CLIENTS 256         /* hard bound of the client table (server_limits.max_clients is at most this) */
#define MAX_REFUSING 64         /* refused connections kept open briefly so their refusal can be read */
#define TIMEOUT_TICK_S 0.25     /* period of the timeout check (loop clock) */
#define ACCEPT_PER_TURN 64      /* connections accepted per loop turn */
#define LISTEN_BACKLOG 512
#define PROBE_WAIT_S 3.0        /* how long a socket that accepts but never answers is given to go away */

const struct server_limits server_default_limits = {
	.max_clients = 128,
	.controller_reserve = 16,
	.per_user = 32,
	.out_pause = 64 * 1024,
	.out_drop = 1024 * 1024,
	.stall_s = 30,
	.idle_s = 600,
	.partial_s = 10,
	.linger_s = 2,
};

/* Per-observer request rate: a token bucket per observer (a uid; all TCP peers together, they carry no
 * credentials), d->observer_burst tokens refilled at d->observer_rate a second, one token per complete line.
 * With the bucket empty the observer's lines wait: its connections are not read (the kernel's socket buffer
 * fills and the client's writes block) until a token comes, then its requests are answered in order.
 * Delayed rather than answered with an error: an excess request then costs the loop nothing (an error reply
 * is still a line parsed, answered and sent, at whatever rate the flood goes, and invites a retry loop), and
 * every request still gets its real reply. Controllers are never limited. */
struct bucket {
	uid_t uid;
	bool tcp;
	int refs;               /* clients holding it */
	double tokens, at;      /* tokens at server time at */
	struct bucket *next;
};

struct client {
	int fd;
	struct srv_peer peer;
	struct proto_lines in;
	char *out;
	size_t outlen, outcap;
	bool watch, closing;
	bool backlog;           /* complete lines left for the next turn */
	bool refusing;          /* refused: its refusal is queued, input is discarded until EOF or linger_s */
	bool limited;           /* lines wait for its observer's bucket (backlog set; not drained until a token) */
	struct bucket *bucket;  /* observers only */
	int inflight;           /* requests handed to the handler and not answered yet */
	double last_in;         /* server clock: last complete line received (or the connection) */
	double partial_since;   /* server clock: an incomplete line is buffered since (0: none) */
	double out_since;       /* server clock: output queued and nothing sent since (0: nothing queued) */
	double refused_at;
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
	int nclients, nrefusing;
	uint64_t next_serial;
	uint64_t drain_timer, timeout_timer, rate_timer;
	double rate_due;            /* server time the rate timer fires */
	struct bucket *buckets;
	int budget;                 /* lines left to handle in this loop turn */
	unsigned rotation;
	struct server_limits lim;
	double (*now)(void *ctx);   /* real monotonic time unless a test injects a clock */
	void *now_ctx;
	struct server_stats stats;
};

static double srv_now(const struct server *srv)
{
	return srv->now(srv->now_ctx);
}

/* ---- per-observer request rate (struct bucket) ---- */

static double rate_burst(const struct server *srv)
{
	return srv->d && srv->d->observer_burst > 1 ? srv->d->observer_burst : 1;
}

static void bucket_refill(const struct server *srv, struct bucket *b, double now)
{
	double rate = srv->d ? srv->d->observer_rate : 0;
	if (rate > 0 && now > b->at)
		b->tokens += (now - b->at) * rate;
	if (rate <= 0 || b->tokens > rate_burst(srv))
		b->tokens = rate_burst(srv);
	b->at = now;
}

/* Forget unused buckets that have refilled: reconnecting gives no fresh burst before that. */
static void buckets_prune(struct server *srv)
{
	double now = srv_now(srv);
	for (struct bucket **p = &srv->buckets; *p;) {
		struct bucket *b = *p;
		if (!b->refs)
			bucket_refill(srv, b, now);
		if (!b->refs && b->tokens >= rate_burst(srv)) {
			*p = b->next;
			free(b);
		} else {
			p = &b->next;
		}
	}
}

/* The bucket of an observer's connection (NULL: out of memory). */
static struct bucket *bucket_get(struct server *srv, const struct srv_peer *peer)
{
	buckets_prune(srv);
	for (struct bucket *b = srv->buckets; b; b = b->next)
		if (b->tcp == peer->tcp && (peer->tcp || b->uid == peer->uid)) {
			b->refs++;
			return b;
		}
	struct bucket *b = calloc(1, sizeof *b);
	if (!b)
		return NULL;
	*b = (struct bucket){ .uid = peer->uid, .tcp = peer->tcp, .refs = 1, .tokens = rate_burst(srv),
			      .at = srv_now(srv), .next = srv->buckets };
	srv->buckets = b;
	return b;
}

static void bucket_put(struct server *srv, struct bucket *b)
{
	if (!b)
		return;
	b->refs--;
	buckets_prune(srv);
}

static void client_close(struct client *c)
{
	struct server *srv = c->srv;
	for (struct client **p = &srv->clients; *p; p = &(*p)->next)
		if (*p == c) {
			*p = c->next;
			break;
		}
	if (c->refusing)
		srv->nrefusing--;
	else
		srv->nclients--;
	loop_fd_del(srv->lp, c->fd);
	close(c->fd);
	if (c->has_fd)
		close(c->pass_fd);
	bucket_put(srv, c->bucket);
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

/* Reading stops while replies are queued beyond out_pause: a client that does not read its replies cannot
 * make the daemon produce more of them. */
static bool reading_paused(const struct client *c)
{
	return c->outlen >= c->srv->lim.out_pause;
}

static void update_events(struct client *c)
{
	short ev = 0;
	if (c->outlen || (c->closing && !c->refusing))
		ev |= POLLOUT; /* a closing client is closed from its next (writable) event */
	if (c->refusing || (!c->closing && !c->backlog && !reading_paused(c)))
		ev |= POLLIN;
	loop_fd_events(c->srv->lp, c->fd, ev);
}

/* Give back buffer memory a burst left behind (a client holds at most a few KiB while quiet). */
static void trim_buffers(struct client *c)
{
	if (!c->outlen && c->outcap > 65536) {
		free(c->out);
		c->out = NULL;
		c->outcap = 0;
	}
	if (c->in.len <= c->in.taken && !c->in.discarding && c->in.cap > 16384) {
		proto_lines_free(&c->in);
		proto_lines_init(&c->in);
	}
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
		c->out_since = c->outlen ? srv_now(c->srv) : 0;
	}
	if (c->refusing && !c->outlen)
		shutdown(c->fd, SHUT_WR); /* the refusal is out: EOF for the client, whose writes still succeed */
}

/* Queue a line (consumed); returns false if the client was dropped. */
static void client_send(struct client *c, char *line)
{
	if (!line)
		return;
	size_t n = strlen(line);
	if (c->closing) {
		free(line);
		return;
	}
	if (c->outlen + n > c->srv->lim.out_drop) {
		log_msg(LOG_WARNING, "client %llu (uid %u) does not read its replies (%zu bytes queued); dropping it",
			(unsigned long long)c->peer.serial, (unsigned)c->peer.uid, c->outlen);
		c->srv->stats.dropped_output++;
		c->outlen = 0;
		c->closing = true;
		free(line);
		update_events(c);
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
	if (!c->outlen)
		c->out_since = srv_now(c->srv);
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
		char words[64];
		snprintf(msg, sizeof msg, "%s needs a controller; uid %u is an observer",
			 proto_cmd_words(req.cmd, words, sizeof words), (unsigned)c->peer.uid);
		send_error(c, req.id, PROTO_E_FORBIDDEN, msg);
	} else if (!strcmp(req.cmd, "watch")) {
		c->watch = true;
		client_send(c, proto_reply_ok(req.id, json_pack("{s:b}", "watching", 1)));
	} else {
		c->inflight++;
		c->srv->fn(c->srv->ctx, &c->peer, &req);
	}
	proto_req_free(&req);
}

/* Requests are handled in bounded turns so the sweep's timers and the devices' fds never wait behind clients:
 * at most LINES_PER_TURN lines per loop turn for all clients together, at most LINES_PER_CLIENT of them from
 * one client, the clients with lines left served in rotation at the next turn (drain_cb). */
#define LINES_PER_TURN 64
#define LINES_PER_CLIENT 8

static void drain_cb(struct loop *lp, void *arg);

/* The next turn: a timer just after now, so that it runs at the loop's next pass over its timers (a timer
 * due at once would run again within the same pass, and the turns would not be bounded). */
#define DRAIN_DELAY_S 1e-4

static void arm_drain(struct server *srv)
{
	if (!srv->drain_timer)
		srv->drain_timer = loop_timer_add(srv->lp, DRAIN_DELAY_S, 0, drain_cb, srv);
}

static void rate_cb(struct loop *lp, void *arg);

/* A complete (or overlong) line is buffered: proto_lines_next() has something to hand out. */
static bool line_pending(const struct proto_lines *pl)
{
	if (pl->len <= pl->taken)
		return false;
	size_t n = pl->len - pl->taken;
	return memchr(pl->buf + pl->taken, '\n', n) || n > (pl->max ? pl->max : PROTO_MAX_LINE);
}

/* Fire the rate timer by server time due (or earlier). */
static void arm_rate(struct server *srv, double due)
{
	if (srv->rate_timer && srv->rate_due <= due)
		return;
	loop_timer_cancel(srv->lp, srv->rate_timer);
	double now = srv_now(srv), lrate = loop_rate(srv->lp);
	double delay = due > now ? due - now : 0;
	srv->rate_due = due;
	/* the loop's clock may run faster than the server's (a simulated bench's time scale) */
	srv->rate_timer = loop_timer_add(srv->lp, (delay + DRAIN_DELAY_S) * (lrate > 0 ? lrate : 1), 0, rate_cb, srv);
}

/* An observer with lines waiting and an empty bucket: hold them until its next token. */
static void hold(struct server *srv, struct client *c)
{
	c->backlog = true;
	if (!c->limited) {
		c->limited = true;
		srv->stats.rate_limited++;
		double now = srv_now(srv);
		if (now - srv->stats.limited_logged_at >= 10) {
			srv->stats.limited_logged_at = now;
			log_msg(LOG_NOTICE, "observer uid %d%s is over its request rate (daemon.observer_rate %g/s, burst %g): "
				"its requests wait (%llu times so far)", c->peer.tcp ? -1 : (int)c->peer.uid,
				c->peer.tcp ? " (TCP)" : "", srv->d->observer_rate, rate_burst(srv),
				(unsigned long long)srv->stats.rate_limited);
		}
	}
	double rate = srv->d->observer_rate;
	arm_rate(srv, c->bucket->at + (1 - c->bucket->tokens) / rate);
	update_events(c);
}

/* Tokens came: the held observers whose bucket has one are drained again. */
static void rate_cb(struct loop *lp, void *arg)
{
	(void)lp;
	struct server *srv = arg;
	srv->rate_timer = 0;
	double now = srv_now(srv), rate = srv->d ? srv->d->observer_rate : 0;
	bool ready = false;
	for (struct client *c = srv->clients; c; c = c->next) {
		if (!c->limited)
			continue;
		bucket_refill(srv, c->bucket, now);
		if (c->bucket->tokens >= 1) {
			c->limited = false;
			ready = true;
		} else {
			arm_rate(srv, now + (1 - c->bucket->tokens) / rate);
		}
	}
	if (ready)
		arm_drain(srv);
}

/* Handle up to LINES_PER_CLIENT complete lines of client serial within the turn's budget; true if more may be
 * buffered. The handler may reply to this client or close others, so the client is looked up again after
 * each line. An observer's lines also wait for its bucket's tokens (struct bucket). */
static bool process_lines(struct server *srv, uint64_t serial)
{
	struct client *c;
	char *line;
	size_t len;
	int k;
	for (int n = 0; n < LINES_PER_CLIENT && srv->budget > 0; n++) {
		if (!(c = client_by_serial(srv, serial)) || c->closing)
			return false;
		if (reading_paused(c)) {
			/* Lines stay buffered until the client reads its replies (POLLOUT brings it back). */
			c->backlog = true;
			return true;
		}
		bool metered = c->bucket && srv->d->observer_rate > 0;
		if (metered) {
			bucket_refill(srv, c->bucket, srv_now(srv));
			if (c->bucket->tokens < 1 && line_pending(&c->in)) {
				hold(srv, c);
				return true;
			}
		}
		if (!(k = proto_lines_next(&c->in, &line, &len))) {
			bool partial = c->in.len > c->in.taken || c->in.discarding;
			if (!partial)
				c->partial_since = 0;
			else if (!c->partial_since)
				c->partial_since = srv_now(srv);
			return false;
		}
		c->last_in = srv_now(srv);
		c->partial_since = 0;
		if (metered)
			c->bucket->tokens -= 1;
		srv->budget--;
		arm_drain(srv); /* refills the budget at the next turn */
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
	arm_drain(srv);
	return true;
}

static void finish_turn(struct client *c)
{
	if (c->closing && !c->refusing && !c->outlen) {
		client_close(c);
		return;
	}
	trim_buffers(c);
	update_events(c);
}

/* Next turn for clients with buffered lines (after every other ready fd had its turn). */
static void drain_cb(struct loop *lp, void *arg)
{
	(void)lp;
	struct server *srv = arg;
	srv->drain_timer = 0;
	srv->budget = LINES_PER_TURN;
	uint64_t serials[MAX_CLIENTS + MAX_REFUSING], ctl[MAX_CLIENTS + MAX_REFUSING];
	int n = 0, nctl = 0;
	for (struct client *c = srv->clients; c && n + nctl < MAX_CLIENTS + MAX_REFUSING; c = c->next)
		if (c->backlog && !c->limited && !reading_paused(c)) {
			if (c->peer.role == PROTO_CONTROLLER)
				ctl[nctl++] = c->peer.serial;
			else
				serials[n++] = c->peer.serial;
		}
	if (!n && !nctl)
		return;
	/* Controllers first (observers cannot delay the operator's requests by more than a turn), then the others
	 * in rotation: this turn starts where the last one's budget ran out. */
	int first = n ? (int)(srv->rotation++ % (unsigned)n) : 0;
	for (int j = 0; j < nctl + n && srv->budget > 0; j++) {
		uint64_t serial = j < nctl ? ctl[j] : serials[(first + j - nctl) % n];
		struct client *c = client_by_serial(srv, serial);
		if (!c)
			continue;
		c->backlog = false;
		process_lines(srv, serial);
		if ((c = client_by_serial(srv, serial)))
			finish_turn(c);
	}
	for (struct client *c = srv->clients; c; c = c->next)
		if (c->backlog && !c->limited && !reading_paused(c)) {
			arm_drain(srv);
			break;
		}
}

static void on_client(struct loop *lp, int fd, short revents, void *arg)
{
	(void)lp;
	struct client *c = arg;
	struct server *srv = c->srv;
	uint64_t serial = c->peer.serial;
	if (revents & POLLOUT) {
		bool was_paused = reading_paused(c);
		flush_out(c);
		if (was_paused && !reading_paused(c) && c->backlog) {
			c->backlog = false; /* its buffered lines get their turn again */
			process_lines(srv, serial);
			if (!(c = client_by_serial(srv, serial)))
				return;
		}
	}
	if (c->refusing) {
		/* Discard what it sends; close at EOF (or after linger_s, from the timeout check). */
		if (revents & (POLLIN | POLLHUP | POLLERR)) {
			char buf[4096];
			ssize_t n = recv(fd, buf, sizeof buf, MSG_DONTWAIT);
			if (n == 0 || (n < 0 && errno != EINTR && errno != EAGAIN)) {
				client_close(c);
				return;
			}
		}
		update_events(c);
		return;
	}
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

/* Role of a local user per the configuration (root and the daemon's own uid are controllers); 0 = refused. */
static enum proto_role server_role_of(const struct conf_daemon *d, uid_t uid)
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

static void on_client(struct loop *lp, int fd, short revents, void *arg);

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
	if (!c || loop_fd_add(srv->lp, fd, POLLIN | POLLOUT, on_client, c, &e)) {
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
	c->closing = false; /* client_send drops lines to closing clients */
	client_send(c, banner);
	client_send(c, err);
	c->closing = true;
	update_events(c);
}

static void accept_one(struct server *srv, int lfd, int fd);

/* Accept what is pending (a bounded number per turn): a connection flood must not fill the listen backlog,
 * where a controller's connection would wait or be refused by the kernel without an answer. */
static void on_accept(struct loop *lp, int lfd, short revents, void *arg)
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
			peer.role = server_role_of(srv->d, cr.uid);
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
	if ((peer.role < PROTO_CONTROLLER && !(c->bucket = bucket_get(srv, &peer))) ||
	    loop_fd_add(lp, fd, POLLIN, on_client, c, &err)) {
		bucket_put(srv, c->bucket);
		close(fd);
		free(c);
		return;
	}
	c->next = srv->clients;
	srv->clients = c;
	srv->nclients++;
	client_send(c, proto_banner(srv->version));
}

/* Every TIMEOUT_TICK_S: refused connections past linger_s, output not read for stall_s, an incomplete line
 * pending for partial_s, no request for idle_s (watchers and clients awaiting a reply are not idle). */
static void timeout_cb(struct loop *lp, void *arg)
{
	(void)lp;
	struct server *srv = arg;
	const struct server_limits *lim = &srv->lim;
	double now = srv_now(srv);
	for (struct client *c = srv->clients, *next; c; c = next) {
		next = c->next;
		if (c->refusing) {
			if (now - c->refused_at >= lim->linger_s)
				client_close(c);
			continue;
		}
		if (c->outlen && c->out_since && now - c->out_since >= lim->stall_s) {
			log_msg(LOG_WARNING, "client %llu (uid %d): %zu bytes of replies unread for %.0f s; dropping it",
				(unsigned long long)c->peer.serial, c->peer.tcp ? -1 : (int)c->peer.uid, c->outlen, lim->stall_s);
			srv->stats.dropped_stalled++;
			client_close(c);
			continue;
		}
		if (c->closing)
			continue;
		char msg[128];
		if (c->partial_since && now - c->partial_since >= lim->partial_s) {
			snprintf(msg, sizeof msg, "incomplete line for %.0f s (a request ends with a newline): closing",
				 lim->partial_s);
			srv->stats.timed_out++;
		} else if (!c->watch && !c->inflight && !c->outlen && !c->backlog && now - c->last_in >= lim->idle_s) {
			snprintf(msg, sizeof msg, "no request for %.0f s: closing", lim->idle_s);
			srv->stats.timed_out++;
		} else {
			continue;
		}
		log_msg(LOG_INFO, "client %llu (uid %d): %s", (unsigned long long)c->peer.serial,
			c->peer.tcp ? -1 : (int)c->peer.uid, msg);
		send_error(c, NULL, PROTO_E_STATE, msg);
		c->closing = true;
		finish_turn(c);
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
	return loop_fd_add(srv->lp, srv->ufd, POLLIN, on_accept, srv, err);
}

static int listen_tcp(struct server *srv, int port, struct acq_err *err)
{
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port),
				  .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	srv->tfd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
	int one = 1;
	if (srv->tfd < 0 || setsockopt(srv->tfd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) < 0 ||
	    bind(srv->tfd, (struct sockaddr *)&sa, sizeof sa) < 0 || listen(srv->tfd, LISTEN_BACKLOG) < 0)
		return acq_errf(err, ACQ_E_IO, "127.0.0.1:%d: %s", port, strerror(errno));
	return loop_fd_add(srv->lp, srv->tfd, POLLIN, on_accept, srv, err);
}

int server_init(struct loop *lp, const struct conf_daemon *d, const char *version, server_req_fn fn, void *ctx,
		struct server **out, struct acq_err *err)
{
	struct server *srv = calloc(1, sizeof *srv);
	if (!srv)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	*srv = (struct server){ .lp = lp, .d = d, .fn = fn, .ctx = ctx, .ufd = -1, .tfd = -1,
				.lim = server_default_limits, .now = loop_monotonic, .budget = LINES_PER_TURN };
	snprintf(srv->version, sizeof srv->version, "%s", version);
	if (listen_unix(srv, d, err) || (d->tcp_port && listen_tcp(srv, d->tcp_port, err))) {
		server_finish(srv);
		return -1;
	}
	srv->timeout_timer = loop_timer_add(lp, TIMEOUT_TICK_S, TIMEOUT_TICK_S, timeout_cb, srv);
	if (!srv->timeout_timer) {
		server_finish(srv);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	*out = srv;
	return 0;
}

void server_finish(struct server *srv)
{
	if (!srv)
		return;
	loop_timer_cancel(srv->lp, srv->drain_timer);
	loop_timer_cancel(srv->lp, srv->timeout_timer);
	loop_timer_cancel(srv->lp, srv->rate_timer);
	while (srv->clients) {
		flush_out(srv->clients);
		client_close(srv->clients);
	}
	while (srv->buckets) {
		struct bucket *b = srv->buckets;
		srv->buckets = b->next;
		free(b);
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

void server_set_limits(struct server *srv, const struct server_limits *lim)
{
	srv->lim = *lim;
	if (srv->lim.max_clients > MAX_CLIENTS)
		srv->lim.max_clients = MAX_CLIENTS;
}

void server_set_clock(struct server *srv, double (*now)(void *ctx), void *ctx)
{
	srv->now = now ? now : loop_monotonic;
	srv->now_ctx = now ? ctx : NULL;
}

void server_get_stats(const struct server *srv, struct server_stats *st)
{
	*st = srv->stats;
}

void server_reply(struct server *srv, uint64_t serial, json_t *id, json_t *data)
{
	struct client *c = client_by_serial(srv, serial);
	if (!c) {
		json_decref(data);
		return;
	}
	if (c->inflight)
		c->inflight--;
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
	if (c->inflight)
		c->inflight--;
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
	if (!c)
		return;
	if (c->inflight)
		c->inflight--;
	send_error(c, id, code, msg);
}

void server_broadcast(struct server *srv, const char *event, json_t *data)
{
	int n = 0;
	for (const struct client *c = srv->clients; c; c = c->next)
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
		*watchers += c->watch && !c->refusing;
}
