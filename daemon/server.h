/* server: the control socket — Unix (and optional loopback TCP) listeners, per-client line framing with the
 * protocol's bound, SO_PEERCRED authorisation (controllers, observers, refused), replies, watch streams. */
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
/* Reply ok with data's fields (data consumed, may be NULL) to connection serial (gone: dropped). */
void server_reply(struct server *srv, uint64_t serial, json_t *id, json_t *data);
/* Reply ok with data (consumed) and pass fd (consumed: closed here once sent) along with the reply's first byte
 * (SCM_RIGHTS). -1, fd closed and nothing sent, for a TCP or gone client or one with a descriptor pending. */
int server_reply_fd(struct server *srv, uint64_t serial, json_t *id, json_t *data, int fd);
/* Reply an error {code, message} to connection serial. */
void server_reply_error(struct server *srv, uint64_t serial, json_t *id, const char *code, const char *msg);
/* Send an event to every watching client (data consumed). */
void server_broadcast(struct server *srv, const char *event, json_t *data);
/* Number of connected clients and of watchers. */
void server_counts(const struct server *srv, int *clients, int *watchers);
/* Role of a local user per the configuration (root and the daemon's own uid are controllers); 0 = refused. */
enum proto_role server_role_of(const struct conf_daemon *d, uid_t uid);

#endif
