/* server internals: the state shared by the control socket's files. server.c (life cycle, timeouts, replies,
 * watch events), server_listen.c (the Unix and loopback TCP listeners), server_admit.c (accepting: peer
 * credentials, roles, connection limits, refusals), server_input.c (reading, line framing, dispatch in bounded
 * turns), server_output.c (the reply queue, descriptor passing, back-pressure) and server_rate.c (the
 * per-observer request rate). Not for other modules: they use server.h. */
#ifndef SERVER_INT_H
#define SERVER_INT_H

#include "daemon/server.h"

#define MAX_CLIENTS 256         /* hard bound of the client table (server_limits.max_clients is at most this) */
#define MAX_REFUSING 64         /* refused connections kept open briefly so their refusal can be read */

/* Requests are handled in bounded turns so the sweep's timers and the devices' fds never wait behind clients:
 * at most LINES_PER_TURN lines per loop turn for all clients together, at most LINES_PER_CLIENT of them from
 * one client, the clients with lines left served in rotation at the next turn (server_input.c). */
#define LINES_PER_TURN 64
#define LINES_PER_CLIENT 8
#define TURN_REAL_S 0.002   /* a loop callback handles lines for this long (real s; at least one line) */

/* The next turn: a timer just after now, so that it runs at the loop's next pass over its timers (a timer
 * due at once would run again within the same pass, and the turns would not be bounded). */
#define DRAIN_DELAY_S 1e-4

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
	double turn_until;          /* real (monotonic) seconds: this callback handles no further line after it */
	unsigned rotation;
	struct server_limits lim;
	double (*now)(void *ctx);   /* real monotonic time unless a test injects a clock */
	void *now_ctx;
	struct server_stats stats;
};

/* The server's clock (seconds; injectable, server_set_clock). */
static inline double srv_now(const struct server *srv)
{
	return srv->now(srv->now_ctx);
}

/* server.c */
/* Unlink c from the client table, close its socket (and a descriptor still to pass) and free it. */
void srv_client_close(struct client *c);
/* The connection serial, or NULL if it is gone. */
struct client *srv_client_by_serial(struct server *srv, uint64_t serial);

/* server_listen.c */
/* Listen on d->socket_path (stale socket replaced, live daemon refused; group and mode set). 0 or -1. */
int srv_listen_unix(struct server *srv, const struct conf_daemon *d, struct acq_err *err);
/* Listen on 127.0.0.1:port. 0 or -1. */
int srv_listen_tcp(struct server *srv, int port, struct acq_err *err);

/* server_admit.c */
/* The listeners' loop callback (arg: the server): accepts pending connections, admits or refuses each. */
void srv_admit_accept(struct loop *lp, int lfd, short revents, void *arg);

/* server_input.c */
/* A client's loop callback (arg: the client): output flushed, input read and handled, refusals discarded. */
void srv_input_event(struct loop *lp, int fd, short revents, void *arg);
/* Close c if it is closing and its output is out, else trim its buffers and update its events. */
void srv_input_finish(struct client *c);
/* Have buffered lines handled at the loop's next turn (idempotent). */
void srv_input_arm(struct server *srv);

/* server_output.c */
/* Reading c stops while its queued replies reach out_pause. */
bool srv_out_paused(const struct client *c);
/* The loop events c waits for, from its output, refusal, backlog and pause. */
void srv_out_events(struct client *c);
/* Give back buffer memory a burst left behind. */
void srv_out_trim(struct client *c);
/* Send what the socket takes now; a failed send closes c (closing set). */
void srv_out_flush(struct client *c);
/* Queue a line (consumed, may be NULL); a client past out_drop is dropped (closing set). */
void srv_out_send(struct client *c, char *line);
/* Queue an error reply {code, message}. */
void srv_out_error(struct client *c, json_t *id, const char *code, const char *msg);

/* server_rate.c */
/* A new observer connection's bucket (shared per uid, one for all TCP peers); NULL: out of memory. */
struct bucket *srv_rate_get(struct server *srv, const struct srv_peer *peer);
/* Release a connection's bucket (NULL is fine). */
void srv_rate_put(struct server *srv, struct bucket *b);
/* Free every bucket (server_finish). */
void srv_rate_free(struct server *srv);
/* True if observer c's next buffered line must wait for a token: c is then held and the rate timer armed. */
bool srv_rate_hold(struct server *srv, struct client *c);
/* One of c's lines was taken: its token is spent (controllers and an unlimited rate spend nothing). */
void srv_rate_take(struct server *srv, struct client *c);

#endif
