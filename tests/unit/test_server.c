/* Unit tests for daemon/server.c on an injected clock: incomplete-line and idle timeouts (watchers exempt),
 * reading paused while replies are unread, drops past the output bound and after a stall, per-user limits
 * with the refusal readable after the banner even when the client writes first, bounded loop turns. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <pwd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <sys/un.h>
#include <unistd.h>
#include <cmocka.h>

#include "daemon/log.h"
#include "daemon/loop.h"
#include "daemon/server.h"

static double fake_now;
static double fake_clock(void *ctx)
{
	(void)ctx;
	return fake_now;
}

struct fx {
	char dir[64], path[128];
	struct conf_daemon d;
	struct loop *lp;
	struct server *srv;
	long handled;
	long ctl_at;  /* handled when a controller's request was last handled */
	long by_uid[3]; /* handled for root, the "daemon" user and the "bin" user (test_observer_rate_limited) */
	uid_t uid_daemon, uid_bin;
};

static char pad[1001];

/* Every request gets a reply of ~1 KiB. */
static void on_req(void *ctx, const struct srv_peer *peer, struct proto_req *req)
{
	struct fx *f = ctx;
	f->handled++;
	if (peer->role == PROTO_CONTROLLER)
		f->ctl_at = f->handled;
	f->by_uid[peer->uid == 0 ? 0 : peer->uid == f->uid_daemon ? 1 : peer->uid == f->uid_bin ? 2 : 0] +=
		peer->uid == 0 || peer->uid == f->uid_daemon || peer->uid == f->uid_bin;
	server_reply(f->srv, peer->serial, req->id, json_pack("{s:s}", "pad", pad));
}

static int setup(void **state)
{
	struct fx *f = calloc(1, sizeof *f);
	memset(pad, 'p', sizeof pad - 1);
	snprintf(f->dir, sizeof f->dir, "/tmp/test_server.XXXXXX");
	assert_non_null(mkdtemp(f->dir));
	snprintf(f->path, sizeof f->path, "%s/s.sock", f->dir);
	/* observers: the "daemon" and "bin" users (test_controller_first and test_observer_rate_limited connect as
	 * them; the other tests as root); no request rate limit unless a test sets one */
	f->d = (struct conf_daemon){ .state_dir = f->dir, .socket_path = f->path, .socket_mode = 0666,
				     .observers = { "daemon", "bin" }, .nobservers = 2 };
	struct passwd *pw = getpwnam("daemon");
	f->uid_daemon = pw ? pw->pw_uid : (uid_t)-2;
	pw = getpwnam("bin");
	f->uid_bin = pw ? pw->pw_uid : (uid_t)-2;
	chmod(f->dir, 0755);
	fake_now = 1000;
	struct loop_clock clk = { .now = fake_clock };
	struct acq_err err = { 0 };
	f->lp = loop_new(&clk, &err);
	assert_non_null(f->lp);
	if (server_init(f->lp, &f->d, "test", on_req, f, &f->srv, &err))
		fail_msg("%s", err.msg);
	server_set_clock(f->srv, fake_clock, NULL);
	*state = f;
	return 0;
}

static int teardown(void **state)
{
	struct fx *f = *state;
	server_finish(f->srv);
	loop_free(f->lp);
	rmdir(f->dir);
	free(f);
	return 0;
}

/* n loop turns, each 0.2 ms later on the fake clock (the server's next turn is a timer 0.1 ms ahead). */
static void pump(struct fx *f, int n)
{
	for (int i = 0; i < n; i++) {
		fake_now += 2e-4;
		loop_run_once(f->lp, 0);
	}
}

/* Advance the fake clock by s in steps of 0.25 s (the period of the timeout check), without drift. */
static void advance(struct fx *f, double s)
{
	double t0 = fake_now;
	for (int k = 1; k * 0.25 <= s + 1e-9; k++) {
		fake_now = t0 + k * 0.25;
		pump(f, 2);
	}
}

static int connect_client(struct fx *f)
{
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	snprintf(sa.sun_path, sizeof sa.sun_path, "%s", f->path);
	assert_int_equal(connect(fd, (struct sockaddr *)&sa, sizeof sa), 0);
	pump(f, 3);
	return fd;
}

/* Everything readable now (no wait); *eof set when the server closed. Returns bytes read into buf. */
static size_t drain(int fd, char *buf, size_t cap, bool *eof)
{
	size_t len = 0;
	*eof = false;
	for (;;) {
		char tmp[65536];
		ssize_t n = recv(fd, tmp, sizeof tmp, MSG_DONTWAIT);
		if (n == 0 || (n < 0 && errno == ECONNRESET)) {
			*eof = true;
			break;
		}
		if (n < 0)
			break;
		size_t k = (size_t)n < cap - 1 - len ? (size_t)n : cap - 1 - len;
		memcpy(buf + len, tmp, k);
		len += k;
	}
	buf[len] = 0;
	return len;
}

static long count_lines(const char *buf, size_t len)
{
	long n = 0;
	for (size_t i = 0; i < len; i++)
		n += buf[i] == '\n';
	return n;
}

static void test_partial_line_times_out(void **state)
{
	struct fx *f = *state;
	int fd = connect_client(f);
	char buf[4096];
	bool eof;
	drain(fd, buf, sizeof buf, &eof); /* banner */
	assert_int_equal(send(fd, "{\"cmd\":\"sta", 11, 0), 11);
	pump(f, 3);
	advance(f, 9);
	drain(fd, buf, sizeof buf, &eof);
	assert_false(eof);
	assert_int_equal(strlen(buf), 0);
	advance(f, 2);
	pump(f, 3);
	drain(fd, buf, sizeof buf, &eof);
	assert_non_null(strstr(buf, "incomplete line"));
	assert_true(eof);
	close(fd);
}

static void test_idle_times_out_but_not_watchers(void **state)
{
	struct fx *f = *state;
	int idle = connect_client(f), watcher = connect_client(f);
	char buf[4096];
	bool eof;
	assert_int_equal(send(watcher, "{\"cmd\":\"watch\",\"id\":1}\n", 23, 0), 23);
	pump(f, 3);
	advance(f, 599);
	drain(idle, buf, sizeof buf, &eof);
	assert_false(eof);
	advance(f, 2);
	pump(f, 3);
	drain(idle, buf, sizeof buf, &eof);
	assert_non_null(strstr(buf, "no request for 600 s"));
	assert_true(eof);
	drain(watcher, buf, sizeof buf, &eof);
	if (eof)
		fail_msg("watcher closed: %s", buf);
	int clients, watchers;
	server_counts(f->srv, &clients, &watchers);
	assert_int_equal(clients, 1);
	assert_int_equal(watchers, 1);
	close(idle);
	close(watcher);
}

/* A client that pipelines requests without reading: the server stops handling its lines once out_pause bytes
 * of replies wait, and resumes as the client reads; none is lost. */
static void test_reading_paused_while_replies_unread(void **state)
{
	struct fx *f = *state;
	int fd = connect_client(f);
	char *buf = malloc(8 << 20);
	bool eof;
	drain(fd, buf, 8 << 20, &eof);
	fcntl(fd, F_SETFL, O_NONBLOCK);
	static const char req[] = "{\"cmd\":\"status\",\"id\":1}\n";
	const size_t rl = sizeof req - 1;
	char batch[100 * sizeof req];
	for (int i = 0; i < 100; i++)
		memcpy(batch + i * rl, req, rl);
	long sent = 0;
	size_t part = 0; /* bytes of a partly sent request */
	for (int turn = 0; turn < 400; turn++) {
		ssize_t n;
		while ((n = send(fd, batch + part, 100 * rl - part, 0)) > 0) {
			sent += ((long)part + n) / (long)rl;
			part = (part + (size_t)n) % rl;
		}
		pump(f, 2);
	}
	/* a partly sent last request stays an incomplete line: not counted */
	print_message("  sent %ld requests, %ld handled without reading\n", sent, f->handled);
	/* Handled: what fits in out_pause (64 KiB) plus the sockets' buffers, a few hundred replies of 1 KiB;
	 * without the pause every request received would be answered into memory. */
	assert_true(sent > 2000);
	assert_true(f->handled * 1000 < (64 << 10) + (1 << 20));
	assert_true(f->handled < sent / 2);
	long got = 0;
	for (int i = 0; i < 100000 && got < sent; i++) {
		size_t n = drain(fd, buf, 8 << 20, &eof);
		got += count_lines(buf, n);
		pump(f, 1);
	}
	assert_int_equal(got, sent);
	assert_int_equal(f->handled, sent);
	free(buf);
	close(fd);
}

/* Unread replies for stall_s: dropped. */
static void test_stalled_reader_dropped(void **state)
{
	struct fx *f = *state;
	int fd = connect_client(f);
	fcntl(fd, F_SETFL, O_NONBLOCK);
	static const char req[] = "{\"cmd\":\"status\",\"id\":1}\n";
	for (int turn = 0; turn < 200; turn++) {
		while (send(fd, req, sizeof req - 1, 0) > 0)
			;
		pump(f, 2);
	}
	struct server_stats st;
	server_get_stats(f->srv, &st);
	assert_int_equal(st.dropped_stalled, 0);
	advance(f, 31);
	server_get_stats(f->srv, &st);
	assert_int_equal(st.dropped_stalled, 1);
	int clients, watchers;
	server_counts(f->srv, &clients, &watchers);
	assert_int_equal(clients, 0);
	close(fd);
}

/* A watcher that never reads its events is dropped once out_drop bytes wait. */
static void test_output_bound_drops_watcher(void **state)
{
	struct fx *f = *state;
	int fd = connect_client(f);
	assert_int_equal(send(fd, "{\"cmd\":\"watch\",\"id\":1}\n", 23, 0), 23);
	pump(f, 3);
	char big[4000];
	memset(big, 'x', sizeof big - 1);
	big[sizeof big - 1] = 0;
	struct server_stats st;
	for (int i = 0; i < 2000; i++) {
		server_broadcast(f->srv, "test", json_pack("{s:s}", "x", big));
		if (i % 16 == 0)
			pump(f, 1);
	}
	server_get_stats(f->srv, &st);
	assert_int_equal(st.dropped_output, 1);
	close(fd);
}

/* Over the per-user limit: the client writes its request first, then reads the banner and the refusal. */
static void test_refusal_readable_after_write(void **state)
{
	struct fx *f = *state;
	struct server_limits lim = server_default_limits;
	lim.per_user = 2;
	server_set_limits(f->srv, &lim);
	int a = connect_client(f), b = connect_client(f), c = connect_client(f);
	static const char req[] = "{\"cmd\":\"status\",\"id\":5}\n";
	assert_int_equal(send(c, req, sizeof req - 1, MSG_NOSIGNAL), (ssize_t)(sizeof req - 1));
	pump(f, 5);
	char buf[4096];
	bool eof;
	drain(c, buf, sizeof buf, &eof);
	assert_non_null(strstr(buf, "\"protocol\""));
	assert_non_null(strstr(buf, "too many clients"));
	assert_ptr_equal(strstr(buf, "\"id\":5"), NULL); /* not handled */
	assert_true(eof);
	assert_int_equal(f->handled, 0);
	/* the refused connection is gone after linger_s even if the client keeps it open */
	advance(f, 3);
	int clients, watchers;
	server_counts(f->srv, &clients, &watchers);
	assert_int_equal(clients, 2);
	close(a);
	close(b);
	close(c);
}

/* Many clients with many requests each: one loop turn handles at most 64 lines in all (the sweep's timers and
 * the devices' fds wait no longer), every client is served in rotation, and everything is answered. */
static void test_bounded_turns(void **state)
{
	struct fx *f = *state;
	enum { NC = 10, NREQ = 50 };
	int fd[NC];
	static const char req[] = "{\"cmd\":\"version\",\"id\":1}\n";
	char batch[NREQ * sizeof req];
	for (int i = 0; i < NREQ; i++)
		memcpy(batch + i * (sizeof req - 1), req, sizeof req - 1);
	for (int c = 0; c < NC; c++)
		fd[c] = connect_client(f);
	for (int c = 0; c < NC; c++)
		assert_int_equal(send(fd[c], batch, NREQ * (sizeof req - 1), 0), (ssize_t)(NREQ * (sizeof req - 1)));
	long before = f->handled, max_turn = 0;
	int turns = 0;
	char *buf = malloc(1 << 20);
	long got[NC] = { 0 };
	bool eof;
	while (f->handled < before + NC * NREQ && turns < 10000) {
		long h = f->handled;
		fake_now += 1e-3; /* the next turn's timer is due */
		loop_run_once(f->lp, 0);
		turns++;
		if (f->handled - h > max_turn)
			max_turn = f->handled - h;
		for (int c = 0; c < NC; c++)
			got[c] += count_lines(buf, drain(fd[c], buf, 1 << 20, &eof));
	}
	print_message("  %d requests in %d loop turns, at most %ld in one turn\n", NC * NREQ, turns, max_turn);
	assert_int_equal(f->handled - before, NC * NREQ);
	assert_true(max_turn <= 64);
	pump(f, 5);
	for (int c = 0; c < NC; c++) {
		got[c] += count_lines(buf, drain(fd[c], buf, 1 << 20, &eof));
		assert_int_equal(got[c], NREQ + 1); /* the banner and every reply */
		close(fd[c]);
	}
	free(buf);
}

/* 30 observers (another uid) each pipeline 50 requests; a controller (root) asking meanwhile is served at the
 * next turn, ahead of the rotation: at most one turn's worth of observer lines (64) is handled before its request.
 * In plain rotation it waited for up to four turns (31 clients x 8 lines / 64 a turn). */
static void test_controller_first(void **state)
{
	struct fx *f = *state;
	enum { NC = 30, NREQ = 50, NROOT = 8 };
	struct passwd *pw = getpwnam("daemon");
	if (!pw)
		skip();
	static const char req[] = "{\"cmd\":\"version\",\"id\":1}\n";
	char batch[NREQ * sizeof req];
	for (int i = 0; i < NREQ; i++)
		memcpy(batch + i * (sizeof req - 1), req, sizeof req - 1);
	int gate[2], go[2];
	assert_int_equal(pipe(gate), 0);
	assert_int_equal(pipe(go), 0);
	pid_t kids[NC];
	for (int c = 0; c < NC; c++) {
		kids[c] = fork();
		assert_true(kids[c] >= 0);
		if (kids[c] == 0) {
			close(gate[1]);
			close(go[1]);
			if (setgid(pw->pw_gid) || setuid(pw->pw_uid))
				_exit(3);
			int fd = socket(AF_UNIX, SOCK_STREAM, 0);
			struct sockaddr_un sa = { .sun_family = AF_UNIX };
			snprintf(sa.sun_path, sizeof sa.sun_path, "%s", f->path);
			char b;
			if (connect(fd, (struct sockaddr *)&sa, sizeof sa) || read(go[0], &b, 1) != 1 ||
			    send(fd, batch, NREQ * (sizeof req - 1), 0) != (ssize_t)(NREQ * (sizeof req - 1)))
				_exit(4);
			(void)!read(gate[0], &b, 1); /* hold the connection until the parent is done */
			_exit(0);
		}
	}
	close(gate[0]);
	close(go[0]);
	int nclients = 0, nwatch = 0;
	for (int t = 0; t < 20000 && nclients < NC; t++) { /* every observer accepted */
		fake_now += 1e-3;
		loop_run_once(f->lp, 1);
		server_counts(f->srv, &nclients, &nwatch);
	}
	assert_int_equal(nclients, NC);
	int root = connect_client(f);
	char *buf = malloc(1 << 16);
	bool eof;
	drain(root, buf, 1 << 16, &eof);
	char gobytes[NC];
	memset(gobytes, 'g', sizeof gobytes);
	assert_int_equal(write(go[1], gobytes, NC), NC);
	usleep(300000); /* their batches in the sockets */
	long before = f->handled, worst = 0;
	for (int k = 0; k < NROOT; k++) {
		long h0 = f->handled;
		assert_int_equal(send(root, req, sizeof req - 1, 0), (ssize_t)(sizeof req - 1));
		long got = 0;
		for (int t = 0; t < 1000 && !got; t++) {
			fake_now += 1e-3;
			loop_run_once(f->lp, 0);
			got = count_lines(buf, drain(root, buf, 1 << 16, &eof));
		}
		assert_int_equal(got, 1);
		if (f->ctl_at - h0 - 1 > worst)
			worst = f->ctl_at - h0 - 1;
	}
	print_message("  a controller's request waited for at most %ld observer requests (%d observers pipelining, "
		      "%ld of their requests handled meanwhile)\n", worst, NC, f->handled - before - NROOT);
	assert_true(f->handled - before - NROOT < NC * NREQ); /* the observers still had lines waiting throughout */
	assert_true(worst <= 64);
	close(root);
	close(gate[1]);
	close(go[1]);
	for (int c = 0; c < NC; c++) {
		int st;
		waitpid(kids[c], &st, 0);
		assert_true(WIFEXITED(st) && WEXITSTATUS(st) == 0);
	}
	free(buf);
}

/* A child connected as user name: sends n requests at once, then reads until it has the banner and n replies or
 * the parent closes gate (its read end); writes the number of lines it got to report. Never returns. */
static void observer_child(struct fx *f, const char *name, int n, int gate, int report)
{
	struct passwd *pw = getpwnam(name);
	if (!pw || setgid(pw->pw_gid) || setuid(pw->pw_uid))
		_exit(3);
	int fd = socket(AF_UNIX, SOCK_STREAM, 0);
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	snprintf(sa.sun_path, sizeof sa.sun_path, "%s", f->path);
	if (connect(fd, (struct sockaddr *)&sa, sizeof sa))
		_exit(4);
	static const char req[] = "{\"cmd\":\"version\",\"id\":1}\n";
	char *batch = malloc((size_t)n * (sizeof req - 1));
	for (int i = 0; batch && i < n; i++)
		memcpy(batch + (size_t)i * (sizeof req - 1), req, sizeof req - 1);
	if (!batch || send(fd, batch, (size_t)n * (sizeof req - 1), 0) != (ssize_t)((size_t)n * (sizeof req - 1)))
		_exit(5);
	free(batch);
	long lines = 0;
	char buf[65536];
	while (lines < n + 1) {
		struct pollfd p[2] = { { .fd = fd, .events = POLLIN }, { .fd = gate, .events = POLLIN } };
		poll(p, 2, -1);
		if (p[0].revents) {
			ssize_t k = recv(fd, buf, sizeof buf, 0);
			if (k <= 0)
				break;
			lines += count_lines(buf, (size_t)k);
		}
		if (p[1].revents)
			break;
	}
	(void)!write(report, &lines, sizeof lines);
	_exit(0);
}

/* n loop turns of dt on the fake clock; with dt 0, 1 ms of real time between turns for the children's bytes
 * (the fixture's clock has no rate: a loop turn must not wait). */
static void turns(struct fx *f, int n, double dt)
{
	for (int i = 0; i < n; i++) {
		fake_now += dt;
		loop_run_once(f->lp, 0);
		if (dt == 0)
			usleep(1000);
	}
}

/* daemon.observer_rate 10/s, observer_burst 20 (the server reads them from the configuration it was given): an
 * observer ("daemon") pipelining 300 requests has 20 handled at once, then 10 per second of the (fake) clock, and
 * all 300 in the end (delayed, none refused); meanwhile another observer ("bin") is answered at once and a
 * controller (root) pipelining 300 requests is served in full within 0.1 s of the clock. */
static void test_observer_rate_limited(void **state)
{
	struct fx *f = *state;
	if (!getpwnam("daemon") || !getpwnam("bin"))
		skip();
	f->d.observer_rate = 10;
	f->d.observer_burst = 20;
	enum { NREQ = 300 };
	int gate[2], rep[2];
	assert_int_equal(pipe(gate), 0);
	assert_int_equal(pipe(rep), 0);
	pid_t a = fork();
	assert_true(a >= 0);
	if (a == 0) {
		close(gate[1]);
		observer_child(f, "daemon", NREQ, gate[0], rep[1]);
	}
	/* its connection and lines (real time; the clock stands still meanwhile), then 0.1 s of the clock: the
	 * burst, at most one token more */
	for (int t = 0; t < 10000 && f->by_uid[1] < 20; t++)
		turns(f, 1, 0);
	turns(f, 500, 2e-4);
	print_message("  burst: %ld requests of the flooding observer handled in the first 0.1 s\n", f->by_uid[1]);
	assert_true(f->by_uid[1] >= 20 && f->by_uid[1] <= 21);
	struct server_stats st;
	server_get_stats(f->srv, &st);
	assert_true(st.rate_limited >= 1);
	/* another observer: answered at its next turns, while the first one still waits */
	pid_t b = fork();
	assert_true(b >= 0);
	if (b == 0) {
		close(gate[1]);
		observer_child(f, "bin", 1, gate[0], rep[1]);
	}
	for (int t = 0; t < 10000 && f->by_uid[2] < 1; t++)
		turns(f, 1, 0);
	assert_int_equal(f->by_uid[2], 1);
	assert_true(f->by_uid[1] <= 22);
	/* a controller pipelining NREQ: all served within 0.1 s of the clock (the observer's rate would take 30 s) */
	int root = connect_client(f);
	char *buf = malloc(1 << 20);
	bool eof;
	drain(root, buf, 1 << 20, &eof);
	static const char req[] = "{\"cmd\":\"version\",\"id\":1}\n";
	char batch[NREQ * (sizeof req - 1)];
	for (int i = 0; i < NREQ; i++)
		memcpy(batch + i * (sizeof req - 1), req, sizeof req - 1);
	assert_int_equal(send(root, batch, sizeof batch, 0), (ssize_t)sizeof batch);
	double t0 = fake_now;
	long got = 0;
	for (int t = 0; t < 500 && got < NREQ; t++) {
		turns(f, 1, 2e-4);
		got += count_lines(buf, drain(root, buf, 1 << 20, &eof));
	}
	print_message("  controller: %ld of %d requests answered in %.3f s of the clock; the observer meanwhile %ld\n", got,
		      NREQ, fake_now - t0, f->by_uid[1]);
	assert_int_equal(got, NREQ);
	assert_true(fake_now - t0 <= 0.1 + 1e-9);
	/* the flooding observer: 10 a second of the clock */
	long h0 = f->by_uid[1];
	double c0 = fake_now;
	turns(f, 2000, 1e-3);
	long dh = f->by_uid[1] - h0;
	print_message("  rate: %ld requests of the flooding observer in %.1f s of the clock\n", dh, fake_now - c0);
	assert_true(dh >= 18 && dh <= 21);
	/* and every request answered in the end */
	for (int t = 0; t < 20000 && f->by_uid[1] < NREQ; t++) {
		turns(f, 1, 0.02);
		usleep(500); /* the child reads its replies in real time (unread, they would pause its requests) */
	}
	assert_int_equal(f->by_uid[1], NREQ);
	/* the children report once they have every reply (the loop keeps sending meanwhile) */
	long lines[2] = { 0, 0 };
	int got_reports = 0;
	for (int t = 0; t < 20000 && got_reports < 2; t++) {
		turns(f, 1, 0);
		struct pollfd p = { .fd = rep[0], .events = POLLIN };
		if (poll(&p, 1, 0) == 1) {
			assert_int_equal(read(rep[0], &lines[got_reports], sizeof lines[0]), (ssize_t)sizeof lines[0]);
			got_reports++;
		}
	}
	close(gate[1]); /* a child still waiting reports what it got */
	int sts[2];
	waitpid(a, &sts[0], 0);
	waitpid(b, &sts[1], 0);
	for (; got_reports < 2; got_reports++)
		assert_int_equal(read(rep[0], &lines[got_reports], sizeof lines[0]), (ssize_t)sizeof lines[0]);
	assert_true(WIFEXITED(sts[0]) && WEXITSTATUS(sts[0]) == 0 && WIFEXITED(sts[1]) && WEXITSTATUS(sts[1]) == 0);
	/* banner + replies, in whichever order the children reported */
	assert_true((lines[0] == NREQ + 1 && lines[1] == 2) || (lines[0] == 2 && lines[1] == NREQ + 1));
	close(gate[0]);
	close(rep[0]);
	close(rep[1]);
	close(root);
	free(buf);
}

int main(void)
{
	log_init(LOG_ERR, false);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(test_partial_line_times_out, setup, teardown),
		cmocka_unit_test_setup_teardown(test_idle_times_out_but_not_watchers, setup, teardown),
		cmocka_unit_test_setup_teardown(test_reading_paused_while_replies_unread, setup, teardown),
		cmocka_unit_test_setup_teardown(test_stalled_reader_dropped, setup, teardown),
		cmocka_unit_test_setup_teardown(test_output_bound_drops_watcher, setup, teardown),
		cmocka_unit_test_setup_teardown(test_refusal_readable_after_write, setup, teardown),
		cmocka_unit_test_setup_teardown(test_bounded_turns, setup, teardown),
		cmocka_unit_test_setup_teardown(test_controller_first, setup, teardown),
		cmocka_unit_test_setup_teardown(test_observer_rate_limited, setup, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
