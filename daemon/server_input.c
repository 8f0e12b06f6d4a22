/* server_input: a client's requests: reading its socket, the protocol's line framing and bound, role checks,
 * and dispatch to the handler in bounded turns (controllers first, observers in rotation). */
#include <errno.h>
#include <poll.h>
#include <string.h>
#include <sys/socket.h>

#include "daemon/loop.h"
#include "daemon/server_int.h"
#include "daemon/stall.h"

static void handle_line(struct client *c, const char *line, size_t len)
{
	struct proto_req req;
	const char *code;
	struct acq_err err = { 0 };
	if (proto_req_parse(line, len, &req, &code, &err)) {
		srv_out_error(c, req.id, code, err.msg);
		proto_req_free(&req);
		return;
	}
	if (req.def->role > c->peer.role) {
		char msg[160];
		char words[64];
		snprintf(msg, sizeof msg, "%s needs a controller; uid %u is an observer",
			 proto_cmd_words(req.cmd, words, sizeof words), (unsigned)c->peer.uid);
		srv_out_error(c, req.id, PROTO_E_FORBIDDEN, msg);
	} else if (!strcmp(req.cmd, "watch")) {
		c->watch = true;
		srv_out_send(c, proto_reply_ok(req.id, json_pack("{s:b}", "watching", 1)));
	} else {
		c->inflight++;
		c->srv->fn(c->srv->ctx, &c->peer, &req);
	}
	proto_req_free(&req);
}

static void drain_cb(struct loop *lp, void *arg);

void srv_input_arm(struct server *srv)
{
	if (!srv->drain_timer)
		srv->drain_timer = loop_timer_add(srv->lp, DRAIN_DELAY_S, 0, drain_cb, srv);
}

/* Handle up to LINES_PER_CLIENT complete lines of client serial within the turn's budget; true if more may be
 * buffered. The handler may reply to this client or close others, so the client is looked up again after
 * each line. An observer's lines also wait for its bucket's tokens (server_rate.c). */
static bool process_lines(struct server *srv, uint64_t serial)
{
	struct client *c;
	char *line;
	size_t len;
	int k;
	for (int n = 0; n < LINES_PER_CLIENT && srv->budget > 0; n++) {
		if (!(c = srv_client_by_serial(srv, serial)) || c->closing)
			return false;
		if (n > 0 && stall_now() > srv->turn_until)
			break; /* the callback's time is up: the rest at the next turn (soak: 20 ms of CPU in one) */
		if (srv_out_paused(c)) {
			/* Lines stay buffered until the client reads its replies (POLLOUT brings it back). */
			c->backlog = true;
			return true;
		}
		if (srv_rate_hold(srv, c))
			return true;
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
		srv_rate_take(srv, c);
		srv->budget--;
		srv_input_arm(srv); /* refills the budget at the next turn */
		if (k == PROTO_LINE_TOO_LONG) {
			char msg[96];
			snprintf(msg, sizeof msg, "line longer than %d bytes: ignored up to its newline", PROTO_MAX_LINE);
			srv_out_error(c, NULL, PROTO_E_TOO_LONG, msg);
		} else if (len) {
			handle_line(c, line, len);
		}
	}
	c = srv_client_by_serial(srv, serial);
	if (!c || c->closing)
		return false;
	c->backlog = true;
	srv_input_arm(srv);
	return true;
}

void srv_input_finish(struct client *c)
{
	if (c->closing && !c->refusing && !c->outlen) {
		srv_client_close(c);
		return;
	}
	srv_out_trim(c);
	srv_out_events(c);
}

/* Next turn for clients with buffered lines (after every other ready fd had its turn). */
static void drain_cb(struct loop *lp, void *arg)
{
	(void)lp;
	struct server *srv = arg;
	srv->drain_timer = 0;
	srv->budget = LINES_PER_TURN;
	srv->turn_until = stall_now() + TURN_REAL_S;
	uint64_t serials[MAX_CLIENTS + MAX_REFUSING], ctl[MAX_CLIENTS + MAX_REFUSING];
	int n = 0, nctl = 0;
	for (struct client *c = srv->clients; c && n + nctl < MAX_CLIENTS + MAX_REFUSING; c = c->next)
		if (c->backlog && !c->limited && !srv_out_paused(c)) {
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
	for (int j = 0; j < nctl + n && srv->budget > 0 && (j == 0 || stall_now() <= srv->turn_until); j++) {
		uint64_t serial = j < nctl ? ctl[j] : serials[(first + j - nctl) % n];
		struct client *c = srv_client_by_serial(srv, serial);
		if (!c)
			continue;
		c->backlog = false;
		process_lines(srv, serial);
		if ((c = srv_client_by_serial(srv, serial)))
			srv_input_finish(c);
	}
	for (struct client *c = srv->clients; c; c = c->next)
		if (c->backlog && !c->limited && !srv_out_paused(c)) {
			srv_input_arm(srv);
			break;
		}
}

void srv_input_event(struct loop *lp, int fd, short revents, void *arg)
{
	(void)lp;
	struct client *c = arg;
	struct server *srv = c->srv;
	uint64_t serial = c->peer.serial;
	srv->turn_until = stall_now() + TURN_REAL_S;
	if (revents & POLLOUT) {
		bool was_paused = srv_out_paused(c);
		srv_out_flush(c);
		if (was_paused && !srv_out_paused(c) && c->backlog) {
			c->backlog = false; /* its buffered lines get their turn again */
			process_lines(srv, serial);
			if (!(c = srv_client_by_serial(srv, serial)))
				return;
		}
	}
	if (c->refusing) {
		/* Discard what it sends; close at EOF (or after linger_s, from the timeout check). */
		if (revents & (POLLIN | POLLHUP | POLLERR)) {
			char buf[4096];
			ssize_t n = recv(fd, buf, sizeof buf, MSG_DONTWAIT);
			if (n == 0 || (n < 0 && errno != EINTR && errno != EAGAIN)) {
				srv_client_close(c);
				return;
			}
		}
		srv_out_events(c);
		return;
	}
	/* With lines still buffered, read nothing more until they are handled (bounded memory). */
	if ((revents & (POLLIN | POLLHUP | POLLERR)) && !c->closing && !c->backlog) {
		char buf[65536];
		ssize_t n = recv(fd, buf, sizeof buf, MSG_DONTWAIT);
		if (n < 0 && (errno == EINTR || errno == EAGAIN))
			return;
		if (n <= 0 || proto_lines_feed(&c->in, buf, (size_t)n)) {
			srv_client_close(c);
			return;
		}
		process_lines(srv, serial);
		if (!(c = srv_client_by_serial(srv, serial)))
			return;
	}
	srv_input_finish(c);
}
