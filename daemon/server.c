/* server: the control socket's life cycle, its timeouts, replies and watch events (see server.h; the other
 * server_*.c files and server_int.h hold the listeners, admission, input, output and request rate). */
#include "daemon/server.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/server_int.h"

#define TIMEOUT_TICK_S 0.25     /* period of the timeout check (loop clock) */

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

void srv_client_close(struct client *c)
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
	srv_rate_put(srv, c->bucket);
	proto_lines_free(&c->in);
	free(c->out);
	free(c);
}

struct client *srv_client_by_serial(struct server *srv, uint64_t serial)
{
	for (struct client *c = srv->clients; c; c = c->next)
		if (c->peer.serial == serial)
			return c;
	return NULL;
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
				srv_client_close(c);
			continue;
		}
		if (c->outlen && c->out_since && now - c->out_since >= lim->stall_s) {
			log_msg(LOG_WARNING, "client %llu (uid %d): %zu bytes of replies unread for %.0f s; dropping it",
				(unsigned long long)c->peer.serial, c->peer.tcp ? -1 : (int)c->peer.uid, c->outlen, lim->stall_s);
			srv->stats.dropped_stalled++;
			srv_client_close(c);
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
		srv_out_error(c, NULL, PROTO_E_STATE, msg);
		c->closing = true;
		srv_input_finish(c);
	}
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
	if (srv_listen_unix(srv, d, err) || (d->tcp_port && srv_listen_tcp(srv, d->tcp_port, err))) {
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
		srv_out_flush(srv->clients);
		srv_client_close(srv->clients);
	}
	srv_rate_free(srv);
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
	struct client *c = srv_client_by_serial(srv, serial);
	if (!c) {
		json_decref(data);
		return;
	}
	if (c->inflight)
		c->inflight--;
	srv_out_send(c, proto_reply_ok(id, data));
}

void server_reply_raw(struct server *srv, uint64_t serial, json_t *id, const char *obj, size_t len)
{
	struct client *c = srv_client_by_serial(srv, serial);
	if (!c)
		return;
	if (c->inflight)
		c->inflight--;
	if (len < 2 || obj[0] != '{' || obj[len - 1] != '}' || memchr(obj, '\n', len)) {
		srv_out_error(c, id, PROTO_E_INTERNAL, "the daemon built a malformed reply");
		return;
	}
	char *ids = json_dumps(id ? id : json_null(), JSON_COMPACT | JSON_ENCODE_ANY | JSON_ENSURE_ASCII);
	size_t n = ids ? strlen(ids) : 0;
	char *line = ids ? malloc(n + len + 20) : NULL;
	if (line) { /* {"id":ID,"ok":true[,fields]}\n: proto_reply_ok's line */
		char *p = line;
		p += sprintf(p, "{\"id\":%s,\"ok\":true", ids);
		if (len > 2) {
			*p++ = ',';
			memcpy(p, obj + 1, len - 1);
			p += len - 1;
		} else {
			*p++ = '}';
		}
		*p++ = '\n';
		*p = '\0';
	}
	free(ids);
	srv_out_send(c, line);
}

int server_reply_fd(struct server *srv, uint64_t serial, json_t *id, json_t *data, int fd)
{
	struct client *c = srv_client_by_serial(srv, serial);
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
	srv_out_send(c, proto_reply_ok(id, data));
	if (!c->closing && c->has_fd && c->pass_at >= c->outlen) { /* the reply was not queued */
		close(fd);
		c->has_fd = false;
		return -1;
	}
	return 0;
}

void server_reply_error(struct server *srv, uint64_t serial, json_t *id, const char *code, const char *msg)
{
	struct client *c = srv_client_by_serial(srv, serial);
	if (!c)
		return;
	if (c->inflight)
		c->inflight--;
	srv_out_error(c, id, code, msg);
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
			srv_out_send(c, strdup(line));
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
