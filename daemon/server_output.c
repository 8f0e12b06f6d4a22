/* server_output: a client's reply queue: back-pressure (reading paused, slow readers dropped), sending from the
 * loop, a descriptor passed along with a reply (SCM_RIGHTS), buffer memory given back after a burst. */
#include <errno.h>
#include <poll.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/server_int.h"

/* Reading stops while replies are queued beyond out_pause: a client that does not read its replies cannot
 * make the daemon produce more of them. */
bool srv_out_paused(const struct client *c)
{
	return c->outlen >= c->srv->lim.out_pause;
}

void srv_out_events(struct client *c)
{
	short ev = 0;
	if (c->outlen || (c->closing && !c->refusing))
		ev |= POLLOUT; /* a closing client is closed from its next (writable) event */
	if (c->refusing || (!c->closing && !c->backlog && !srv_out_paused(c)))
		ev |= POLLIN;
	loop_fd_events(c->srv->lp, c->fd, ev);
}

/* Give back buffer memory a burst left behind (a client holds at most a few KiB while quiet). */
void srv_out_trim(struct client *c)
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

void srv_out_flush(struct client *c)
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

/* Queue a line (consumed); past out_drop the client is dropped instead (closing, its queue emptied). */
void srv_out_send(struct client *c, char *line)
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
		srv_out_events(c);
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
		srv_out_flush(c);
	srv_out_events(c);
}

void srv_out_error(struct client *c, json_t *id, const char *code, const char *msg)
{
	srv_out_send(c, proto_reply_err(id, code, msg));
}

