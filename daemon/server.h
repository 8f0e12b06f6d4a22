/* server: the control socket — Unix (and optional loopback TCP) listeners, per-client line framing with the
 * protocol's bound, SO_PEERCRED authorisation (controllers, observers, refused), replies, watch streams.
 * No client can hold the loop or its memory: reading stops while a client's replies are unread (out_pause)
 * and it is dropped past out_drop or stall_s; incomplete lines and idle connections time out; connections
 * are limited per user with the last slots kept for controllers; a refused client gets the banner and the
 * refusal before the connection closes. Each observer's requests are limited to daemon.observer_rate a second
 * (bursts of daemon.observer_burst): beyond, its lines wait unread until the rate allows them (server_rate.c,
 * struct bucket); controllers are never limited. Loopback TCP (daemon.tcp_port, off by default) gives observer
 * access to every local user: it carries no credentials. */
#ifndef SERVER_H
#define SERVER_H

#include <jansson.h>
#include <stdint.h>
#include <sys/types.h>

#include "config/acq_err.h"
#include "daemon/conf.h"
#include "proto/proto.h"

struct loop;
struct server;

/* Bounds on clients (server_default_limits; tests and the soak may change them). Times in seconds of the
 * server's clock (real monotonic time, not the simulated bench's). */
struct server_limits {
	int max_clients;         /* connections at once (at most 256) */
	int controller_reserve;  /* of which the last ones only controllers may take */
	int per_user;            /* connections of one uid (all TCP peers count as one user) */
	size_t out_pause;        /* queued reply bytes from which a client's further requests wait */
	size_t out_drop;         /* queued reply bytes beyond which the client is dropped */
	double stall_s;          /* queued replies and nothing read by the client for this long: dropped */
	double idle_s;           /* no request for this long (not watching, nothing pending): closed */
	double partial_s;        /* an incomplete line pending for this long: refused and closed */
	double linger_s;         /* a refused connection stays open this long for its refusal to be read */
};
extern const struct server_limits server_default_limits;

/* Counters since start (status, soak). */
struct server_stats {
	unsigned long long refused, dropped_output, dropped_stalled, timed_out;
	unsigned long long rate_limited;  /* times an observer's lines were held for its request rate */
	double refused_logged_at, limited_logged_at;
};

struct srv_peer {
	uint64_t serial;       /* identifies the connection for later replies (never reused) */
	enum proto_role role;
	uid_t uid;
	pid_t pid;
	bool tcp;
};

/* A validated, authorised request (everything but `watch`); reply now or later with server_reply*(). The
 * handler owns nothing: req is freed after it returns (keep json_incref(req->id) for a later reply). */
typedef void (*server_req_fn)(void *ctx, const struct srv_peer *peer, struct proto_req *req);

/* Listen on d->socket_path (and 127.0.0.1:d->tcp_port). Refuses if another daemon answers there. 0 or -1. */
int server_init(struct loop *lp, const struct conf_daemon *d, const char *version, server_req_fn fn, void *ctx,
		struct server **out, struct acq_err *err);
/* Close every client and listener, remove the socket file. NULL is fine. */
void server_finish(struct server *srv);
/* New authorisation lists after a reload (d must outlive the server or the next call). */
void server_set_conf(struct server *srv, const struct conf_daemon *d);
/* Replace the limits (max_clients capped at 256). */
void server_set_limits(struct server *srv, const struct server_limits *lim);
/* Clock of the timeouts (NULL: real monotonic time); for tests. */
void server_set_clock(struct server *srv, double (*now)(void *ctx), void *ctx);
/* Counters of refusals, drops and timeouts. */
void server_get_stats(const struct server *srv, struct server_stats *st);
/* Reply ok with data's fields (data consumed, may be NULL) to connection serial (gone: dropped). */
void server_reply(struct server *srv, uint64_t serial, json_t *id, json_t *data);
/* Reply ok with the fields of obj, a compact one-line JSON object's text (len bytes, ASCII), passed as it is
 * (a reply built elsewhere, e.g. in a job's child: not parsed again on the loop); a malformed one is replied as an
 * internal error. */
void server_reply_raw(struct server *srv, uint64_t serial, json_t *id, const char *obj, size_t len);
/* Reply ok with data (consumed) and pass fd (consumed: closed here once sent) along with the reply's first byte
 * (SCM_RIGHTS). -1, fd closed and nothing sent, for a TCP or gone client or one with a descriptor pending. */
int server_reply_fd(struct server *srv, uint64_t serial, json_t *id, json_t *data, int fd);
/* Reply an error {code, message} to connection serial. */
void server_reply_error(struct server *srv, uint64_t serial, json_t *id, const char *code, const char *msg);
/* Send an event to every watching client (data consumed). */
void server_broadcast(struct server *srv, const char *event, json_t *data);
/* Number of connected clients and of watchers. */
void server_counts(const struct server *srv, int *clients, int *watchers);

#endif
