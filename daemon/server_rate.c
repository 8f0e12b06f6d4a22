/* server_rate: the per-observer request rate, a token bucket per observer (struct bucket, see server_int.h). */
#include <stdlib.h>
#include <string.h>

#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/server_int.h"

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

struct bucket *srv_rate_get(struct server *srv, const struct srv_peer *peer)
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

void srv_rate_put(struct server *srv, struct bucket *b)
{
	if (!b)
		return;
	b->refs--;
	buckets_prune(srv);
}

void srv_rate_free(struct server *srv)
{
	while (srv->buckets) {
		struct bucket *b = srv->buckets;
		srv->buckets = b->next;
		free(b);
	}
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
	srv_out_events(c);
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
		srv_input_arm(srv);
}

static bool metered(const struct server *srv, const struct client *c)
{
	return c->bucket && srv->d->observer_rate > 0;
}

bool srv_rate_hold(struct server *srv, struct client *c)
{
	if (!metered(srv, c))
		return false;
	bucket_refill(srv, c->bucket, srv_now(srv));
	if (c->bucket->tokens < 1 && line_pending(&c->in)) {
		hold(srv, c);
		return true;
	}
	return false;
}

void srv_rate_take(struct server *srv, struct client *c)
{
	if (metered(srv, c))
		c->bucket->tokens -= 1;
}
