/* Laser driver (drivers/laser_serial.c) against the simulated laser (sim/sim_laser.c) on a real pty served by
 * a forked child, plus scripted peers for malformed replies and a dead line. The world lives in shared memory
 * so the test sees what the service writes and injects the interlock and fault. */
#include <fcntl.h>
#include <math.h>
#include <poll.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "drivers/laser.h"
#include "drivers/laser_backend.h"
#include "sim/sim.h"

struct shared {
	struct sim_world world;
	int nlines;
	char lines[32][160];  /* what a scripted peer received */
	char desc[256];       /* the served laser's endpoint (its describe()) */
};

static struct shared *sh;

static double mono(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static struct laser_cfg *make_cfg(const char *device, int timeout_ms)
{
	char text[512];
	snprintf(text, sizeof text, "device: %s\nbaud: 115200\ntimeout_ms: %d\nmax_power_pct: 80\n", device, timeout_ms);
	struct yc_doc *doc = NULL;
	struct laser_cfg *cfg = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(yc_load_string("laser.yaml", text, strlen(text), &doc, &err), 0);
	if (laser_cfg_parse(yc_root(doc), &cfg, &err))
		fail_msg("%s", err.msg);
	yc_free(doc);
	return cfg;
}

/* ---- the simulated laser in a child --------------------------------------------------------------- */

struct served {
	pid_t pid;
	char path[128];
	struct laser_cfg *cfg;
};

/* The simulator's laser on its link (pty: sim.laser.link pty; else the default, a Unix socket). */
static struct sim_service *sim_laser_on(bool pty)
{
	struct yc_doc *doc = NULL;
	struct acq_err err = { 0 };
	static const char text[] = "laser: {link: pty}\n";
	if (pty)
		assert_int_equal(yc_load_string("sim.yaml", text, strlen(text), &doc, &err), 0);
	struct sim_service *svc = sim_laser_new(&sh->world, NULL, pty ? yc_root(doc) : NULL, &err);
	if (!svc)
		fail_msg("sim_laser_new: %s", err.msg);
	yc_free(doc);
	return svc;
}

/* The simulated laser served by a forked child (which owns its link: a socket's file goes with it). */
static void serve_sim_on(struct served *sv, bool pty)
{
	memset(&sh->world, 0, sizeof sh->world);
	sh->desc[0] = 0;
	int ready[2];
	assert_int_equal(pipe(ready), 0);
	sv->pid = fork();
	assert_true(sv->pid >= 0);
	if (sv->pid == 0) {
		prctl(PR_SET_PDEATHSIG, SIGKILL);
		close(ready[0]);
		struct sim_service *svc = sim_laser_on(pty);
		svc->describe(svc->self, sh->desc, sizeof sh->desc);
		(void)!write(ready[1], "r", 1);
		for (;;) {
			struct pollfd fds[4];
			int n = svc->pollfds(svc->self, fds, 4);
			int r = poll(fds, (nfds_t)n, 5);
			if (r > 0)
				svc->handle(svc->self, fds, n, 0);
			svc->tick(svc->self, 0);
		}
	}
	close(ready[1]);
	char b;
	assert_int_equal(read(ready[0], &b, 1), 1);
	close(ready[0]);
	assert_int_equal(sscanf(sh->desc, "\"laser\": {\"device\": \"%127[^\"]\"}", sv->path), 1);
	/* the default link is a socket: no tty in the way (sim_laser.c: a pty's bytes wait for a kernel worker) */
	assert_non_null(strstr(sv->path, pty ? "/dev/pts/" : "unix:/"));
	sv->cfg = make_cfg(sv->path, 500);
}

static void stop_child(pid_t pid)
{
	kill(pid, SIGKILL);
	waitpid(pid, NULL, 0);
}

/* serve_sim_on, then the driver opened on the served line; the test fails if it does not open. */
static struct laser *open_served_on(struct served *sv, bool pty)
{
	serve_sim_on(sv, pty);
	struct acq_err err = { 0 };
	struct laser *l = NULL;
	if (laser_open(sv->cfg, &l, &err))
		fail_msg("%s", err.msg);
	return l;
}

static struct laser *open_served(struct served *sv)
{
	return open_served_on(sv, false);
}

/* The driver against the simulator on both links (the default socket and sim.laser.link: pty). */
static void test_sim_identity_emission_power(void **state)
{
	(void)state;
	for (int pty = 0; pty < 2; pty++) {
		struct served sv;
		struct laser *l = open_served_on(&sv, pty);
		struct acq_err err = { 0 };
		assert_string_equal(laser_identity(l)->model, "SIM-SC450");
		assert_string_equal(laser_identity(l)->serial, "SIM0001");
		assert_int_equal(laser_set_power(l, 42.5, &err), 0);
		assert_true(fabs(sh->world.laser_power_pct - 42.5) < 1e-9);
		assert_int_equal(laser_set_emission(l, true, &err), 0);
		assert_true(sh->world.laser_emission);
		struct laser_status st;
		assert_int_equal(laser_status(l, &st, &err), 0);
		assert_true(st.emission && st.interlock_ok && !st.fault);
		assert_true(fabs(st.power_pct - 42.5) < 1e-9);
		/* above the configured maximum: refused before sending, emission switched off */
		assert_int_equal(laser_set_power(l, 90, &err), -1);
		assert_int_equal(err.code, ACQ_E_RANGE);
		assert_false(sh->world.laser_emission);
		assert_int_equal(laser_set_emission(l, true, &err), 0);
		laser_close(l); /* switches emission off */
		assert_false(sh->world.laser_emission);
		stop_child(sv.pid);
		laser_cfg_free(sv.cfg);
	}
}

/* One turn of the simulator's loop for svc (as acq-sim's: poll its fds up to 5 ms, handle, tick). */
static void sim_turn(struct sim_service *svc)
{
	struct pollfd fds[4];
	int n = svc->pollfds(svc->self, fds, 4);
	if (poll(fds, (nfds_t)n, 5) > 0)
		svc->handle(svc->self, fds, n, 0);
	svc->tick(svc->self, 0);
}

static int connect_laser(const char *path)
{
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	snprintf(sa.sun_path, sizeof sa.sun_path, "%s", path);
	assert_true(fd >= 0);
	assert_int_equal(connect(fd, (struct sockaddr *)&sa, sizeof sa), 0);
	return fd;
}

/* Send cmd on fd and run the simulator until its reply line arrives (at most 2000 turns): the reply. */
static const char *sim_ask(struct sim_service *svc, int fd, const char *cmd)
{
	static char line[160];
	size_t len = 0;
	char out[160];
	int n = snprintf(out, sizeof out, "%s\n", cmd);
	assert_int_equal(send(fd, out, (size_t)n, MSG_NOSIGNAL), n);
	for (int t = 0; t < 2000; t++) {
		sim_turn(svc);
		char c;
		while (recv(fd, &c, 1, MSG_DONTWAIT) == 1) {
			if (c == '\n') {
				line[len] = 0;
				return line;
			}
			if (len < sizeof line - 1)
				line[len++] = c;
		}
	}
	fail_msg("no reply to '%s'", cmd);
	return NULL;
}

/* The simulated laser's socket link: the latest connection gets the line (the earlier one sees EOF), and the
 * keep-alive counts a command already waiting on the link as arrived (a laser's UART receives it on arrival;
 * the simulator may read it late), then expires when nothing comes. In process, on real time. */
static void test_sim_socket_link_and_keepalive(void **state)
{
	(void)state;
	memset(&sh->world, 0, sizeof sh->world);
	struct sim_service *svc = sim_laser_on(false);
	char desc[256] = "", path[128];
	svc->describe(svc->self, desc, sizeof desc);
	assert_int_equal(sscanf(desc, "\"laser\": {\"device\": \"unix:%127[^\"]\"}", path), 1);
	int a = connect_laser(path);
	assert_string_equal(sim_ask(svc, a, "KEEPALIVE 1000"), "OK");
	assert_string_equal(sim_ask(svc, a, "EMISSION ON"), "OK");
	assert_true(sh->world.laser_emission);
	int b = connect_laser(path);
	bool eof = false;
	for (int t = 0; t < 2000 && !eof; t++) {
		sim_turn(svc);
		char c;
		eof = recv(a, &c, 1, MSG_DONTWAIT) == 0;
	}
	assert_true(eof);
	assert_string_equal(sim_ask(svc, b, "EMISSION?"), "EMISSION 1");
	/* a refresh sent in time but not read before the period ends: emission stays on */
	assert_int_equal(send(b, "KEEPALIVE\n", 10, MSG_NOSIGNAL), 10);
	usleep(1300 * 1000);
	svc->tick(svc->self, 0);
	assert_true(sh->world.laser_emission);
	char got[8] = "";
	for (int t = 0; t < 2000 && !strchr(got, '\n'); t++) {
		sim_turn(svc);
		(void)!recv(b, got + strlen(got), sizeof got - 1 - strlen(got), MSG_DONTWAIT);
	}
	assert_string_equal(got, "OK\n");
	/* nothing more: expired */
	usleep(1300 * 1000);
	svc->tick(svc->self, 0);
	assert_false(sh->world.laser_emission);
	close(a);
	close(b);
	svc->destroy(svc->self);
	assert_int_equal(access(path, F_OK), -1); /* the socket file goes with the service */
}

static void test_sim_interlock_and_fault(void **state)
{
	(void)state;
	struct served sv;
	struct laser *l = open_served(&sv);
	struct acq_err err = { 0 };
	assert_int_equal(laser_set_emission(l, true, &err), 0);
	assert_true(sh->world.laser_emission);
	sh->world.faults.laser_interlock_open = true;
	struct laser_status st;
	assert_int_equal(laser_status(l, &st, &err), 0);
	assert_false(st.emission);
	assert_false(st.interlock_ok);
	assert_false(sh->world.laser_emission);
	assert_int_equal(laser_set_emission(l, true, &err), -1);
	assert_int_equal(err.code, ACQ_E_DEVICE);
	assert_int_equal(err.detail, 3);
	assert_non_null(strstr(err.msg, "interlock open"));
	assert_false(sh->world.laser_emission);
	sh->world.faults.laser_interlock_open = false;
	sh->world.faults.laser_fault = true;
	assert_int_equal(laser_status(l, &st, &err), 0);
	assert_true(st.fault && st.interlock_ok && !st.emission);
	assert_int_equal(st.fault_code, 1);
	assert_int_equal(laser_set_emission(l, true, &err), -1);
	assert_non_null(strstr(err.msg, "fault active"));
	sh->world.faults.laser_fault = false;
	assert_int_equal(laser_set_emission(l, true, &err), 0);
	assert_true(sh->world.laser_emission);
	laser_close(l);
	assert_false(sh->world.laser_emission);
	stop_child(sv.pid);
	laser_cfg_free(sv.cfg);
}

/* ---- scripted peers ----------------------------------------------------------------------------------- */

/* A raw pty; its slave stays open (in *keep) so the master never reads EIO before the driver opens it. */
static int open_pty(char *path, size_t len, int *keep)
{
	int m = posix_openpt(O_RDWR | O_NOCTTY);
	assert_true(m >= 0);
	assert_int_equal(grantpt(m), 0);
	assert_int_equal(unlockpt(m), 0);
	snprintf(path, len, "%s", ptsname(m));
	int s = open(path, O_RDWR | O_NOCTTY);
	struct termios t;
	assert_int_equal(tcgetattr(s, &t), 0);
	cfmakeraw(&t);
	assert_int_equal(tcsetattr(s, TCSANOW, &t), 0);
	*keep = s;
	return m;
}

/* A child answering each command line with the next scripted reply (sent verbatim; NULL = stay silent);
 * "EMISSION OFF" and "KEEPALIVE..." are always answered "OK\n". Received lines are recorded in shared memory. */
/* How long the driver waits for a scripted peer's reply that does come (tests of what the reply says). */
#define PEER_PATIENCE_MS 2000

static pid_t script_peer(int master, const char *const *script)
{
	sh->nlines = 0;
	pid_t pid = fork();
	assert_true(pid >= 0);
	if (pid)
		return pid;
	prctl(PR_SET_PDEATHSIG, SIGKILL); /* never outlive a failed test */
	char line[160];
	size_t len = 0;
	int k = 0;
	for (;;) {
		char c;
		if (read(master, &c, 1) != 1)
			for (;;)
				pause(); /* the parent kills us; exiting here would run the sanitizers' exit checks */
		if (c != '\n') {
			if (len < sizeof line - 1)
				line[len++] = c;
			continue;
		}
		line[len] = 0;
		len = 0;
		if (sh->nlines < 32)
			snprintf(sh->lines[sh->nlines++], sizeof sh->lines[0], "%s", line);
		const char *r = !strcmp(line, "EMISSION OFF") || !strncmp(line, "KEEPALIVE", 9) ? "OK\n"
				: script[k] ? script[k++] : NULL;
		if (r && write(master, r, strlen(r)) < 0)
			for (;;)
				pause();
	}
}

static void expect_open_error(const char *const *script, int code, const char *needle)
{
	char path[128];
	int keep, m = open_pty(path, sizeof path, &keep);
	pid_t pid = script_peer(m, script);
	/* the reply comes: the timeout is only patience (a pty's bytes wait for a kernel worker, and the forked peer
	 * for a CPU: on a loaded machine 200 ms was not always enough) */
	struct laser_cfg *cfg = make_cfg(path, PEER_PATIENCE_MS);
	struct laser *l = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(laser_open(cfg, &l, &err), -1);
	assert_null(l);
	print_message("  -> %s\n", err.msg);
	assert_int_equal(err.code, code);
	assert_non_null(strstr(err.msg, needle));
	stop_child(pid);
	close(m);
	close(keep);
	laser_cfg_free(cfg);
}

static void test_malformed_identity(void **state)
{
	(void)state;
	static const char *const s1[] = { "HELLO\n", NULL };
	expect_open_error(s1, ACQ_E_PROTO, "expected 'ID <model> <serial> <firmware>'");
	static const char *const s2[] = { "ID a b c d\n", NULL };
	expect_open_error(s2, ACQ_E_PROTO, "more than three words (reply 'ID a b c d'");
	char longline[300];
	memset(longline, 'A', 250);
	strcpy(longline + 250, "\n");
	const char *const s3[] = { longline, NULL };
	expect_open_error(s3, ACQ_E_PROTO, "longer than 128 bytes");
	static const char *const s4[] = { "ID x\001y z w\n", NULL };
	expect_open_error(s4, ACQ_E_PROTO, "non-printable byte 0x01");
	static const char *const s5[] = { "ERR 1 unknown command\n", NULL };
	expect_open_error(s5, ACQ_E_DEVICE, "unknown command");
	/* a word longer than the identity's 63 characters: refused (sscanf's %63s split it into the next field) */
	char longword[160];
	snprintf(longword, sizeof longword, "ID %070d b c\n", 7);
	const char *const s6[] = { longword, NULL };
	expect_open_error(s6, ACQ_E_PROTO, "'ID?': the model is 70 characters, more than 63 (reply 'ID 0000");
	snprintf(longword, sizeof longword, "ID %070d b\n", 7);
	const char *const s7[] = { longword, NULL };
	expect_open_error(s7, ACQ_E_PROTO, "the model is 70 characters");
}

/* A scripted peer on a fresh pty with the driver opened on it and emission switched on ("ID M S F" and an "OK"
 * first in its script). */
struct scripted {
	char path[128];
	int m, keep;
	pid_t pid;
	struct laser_cfg *cfg;
	struct laser *l;
};

static void scripted_on(struct scripted *p, const char *const *script)
{
	p->m = open_pty(p->path, sizeof p->path, &p->keep);
	p->pid = script_peer(p->m, script);
	p->cfg = make_cfg(p->path, PEER_PATIENCE_MS);
	p->l = NULL;
	struct acq_err err = { 0 };
	if (laser_open(p->cfg, &p->l, &err))
		fail_msg("%s", err.msg);
	assert_int_equal(laser_set_emission(p->l, true, &err), 0);
}

static void scripted_close(struct scripted *p)
{
	laser_close(p->l);
	stop_child(p->pid);
	close(p->m);
	close(p->keep);
	laser_cfg_free(p->cfg);
}

static void test_malformed_status_switches_emission_off(void **state)
{
	(void)state;
	static const char *const bad[][2] = {
		{ "STATUS emission=2 interlock=1 fault=0\n", NULL },
		{ "STATUS emission=1 interlock=1\n", NULL },
		{ "STATUS emission=1 interlock=1 fault=0 extra\n", NULL },
		{ "STATUS emission=1 interlock=1 fault=0\n", "POWER nan\n" },
		{ "STATUS emission=1 interlock=1 fault=0\n", "POWER 120\n" },
		{ "STATUS emission=1 interlock=1 fault=0\n", "OK\n" },
		/* numbers past int's range: sscanf's %d wrapped them (2^32 + 1 read as 1, 2^32 as 0: no fault) */
		{ "STATUS emission=4294967297 interlock=1 fault=0\n", NULL },
		{ "STATUS emission=1 interlock=4294967297 fault=0\n", NULL },
		{ "STATUS emission=1 interlock=1 fault=4294967296\n", NULL },
		{ "STATUS emission=1 interlock=1 fault=99999999999999999999999\n", NULL },
		{ "STATUS emission=+1 interlock=1 fault=0\n", NULL },
		{ "STATUS emission= 1 interlock=1 fault=0\n", NULL },
		{ "STATUS emission=1 interlock=1 fault=0\n", "POWER 0x2A\n" },
		{ "STATUS emission=1 interlock=1 fault=0\n", "POWER  42\n" },
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		const char *script[] = { "ID M S F\n", "OK\n", bad[i][0], bad[i][1], NULL };
		struct scripted p;
		scripted_on(&p, script);
		struct acq_err err = { 0 };
		struct laser_status st;
		assert_int_equal(laser_status(p.l, &st, &err), -1);
		print_message("  -> %s\n", err.msg);
		assert_int_equal(err.code, ACQ_E_PROTO);
		/* the laser first, then the command, then what is wrong, and the reply as it came */
		char head[200], line[160];
		const char *rl = bad[i][1] ? bad[i][1] : bad[i][0]; /* a second reply: the status was good */
		snprintf(head, sizeof head, "laser %s: '%s': ", p.path, bad[i][1] ? "POWER?" : "STATUS?");
		assert_true(!strncmp(err.msg, head, strlen(head)));
		snprintf(line, sizeof line, "(reply '%.*s'", (int)strcspn(rl, "\n"), rl);
		assert_non_null(strstr(err.msg, line));
		/* the driver switched emission off after the bad reply */
		assert_true(sh->nlines >= 4);
		assert_string_equal(sh->lines[sh->nlines - 1], "EMISSION OFF");
		scripted_close(&p);
	}
	/* what the refusal says about a wrapped number */
	const char *script[] = { "ID M S F\n", "OK\n", "STATUS emission=4294967297 interlock=1 fault=0\n", NULL };
	struct scripted p;
	scripted_on(&p, script);
	struct acq_err err = { 0 };
	struct laser_status st;
	assert_int_equal(laser_status(p.l, &st, &err), -1);
	assert_non_null(strstr(err.msg, "'STATUS?': emission='4294967297' is not 0 or 1 (reply 'STATUS emission="));
	scripted_close(&p);
}

/* A line that hangs up: the error names the laser, then the command, then what happened (it read
 * "'POWER 10.00': laser /dev/pts/N: write: ..."). */
static void test_hangup_error_order(void **state)
{
	(void)state;
	const char *script[] = { "ID M S F\n", "OK\n", NULL };
	struct scripted p;
	scripted_on(&p, script);
	stop_child(p.pid);
	close(p.m); /* the pty's master gone: the line is hung up */
	struct acq_err err = { 0 };
	assert_int_equal(laser_set_power(p.l, 10, &err), -1);
	print_message("  -> %s\n", err.msg);
	char head[200];
	snprintf(head, sizeof head, "laser %s: 'POWER 10.00': ", p.path);
	assert_true(!strncmp(err.msg, head, strlen(head)));
	assert_int_equal(err.code, ACQ_E_DISCONNECTED);
	laser_close(p.l);
	close(p.keep);
	laser_cfg_free(p.cfg);
}

/* The driver reads what arrives in blocks: a stray line after a reply (here in the same write as the reply, so
 * one read takes both) must be dropped with the unread input before the next command, not taken for its reply. */
static void test_stray_line_after_reply_dropped(void **state)
{
	(void)state;
	const char *script[] = { "ID M S F\n", "OK\nPOWER 99.0\n", "STATUS emission=1 interlock=1 fault=0\n",
				 "POWER 42.0\n", NULL };
	struct scripted p;
	scripted_on(&p, script);
	struct acq_err err = { 0 };
	struct laser_status st;
	if (laser_status(p.l, &st, &err))
		fail_msg("%s", err.msg);
	assert_true(st.emission);
	assert_true(fabs(st.power_pct - 42.0) < 1e-9);
	scripted_close(&p);
}

static void test_dead_line_times_out(void **state)
{
	(void)state;
	char path[128];
	int keep, m = open_pty(path, sizeof path, &keep); /* nobody answers */
	struct laser_cfg *cfg = make_cfg(path, 150);
	struct laser *l = NULL;
	struct acq_err err = { 0 };
	double t0 = mono();
	assert_int_equal(laser_open(cfg, &l, &err), -1);
	double dt = mono() - t0;
	print_message("  -> %s (%.3f s)\n", err.msg, dt);
	assert_int_equal(err.code, ACQ_E_TIMEOUT);
	assert_non_null(strstr(err.msg, "no reply to 'ID?' within 150 ms"));
	/* the ID? wait plus the best-effort EMISSION OFF wait */
	assert_true(dt >= 0.14 && dt < 1.0);
	/* a silent peer after a good start: a command times out, emission off attempted. First drop the
	 * commands the dead line never read, so the peer does not answer them. */
	int fl = fcntl(m, F_GETFL);
	fcntl(m, F_SETFL, fl | O_NONBLOCK);
	char junk[256];
	while (read(m, junk, sizeof junk) > 0)
		;
	fcntl(m, F_SETFL, fl);
	static const char *const script[] = { "ID M S F\n", NULL };
	pid_t pid = script_peer(m, script);
	/* the forked peer must answer the good start: on a saturated machine 150 ms was not always enough */
	struct laser_cfg *slow = make_cfg(path, 1000);
	assert_int_equal(laser_open(slow, &l, &err), 0);
	assert_int_equal(laser_set_power(l, 10, &err), -1);
	assert_int_equal(err.code, ACQ_E_TIMEOUT);
	assert_non_null(strstr(err.msg, "POWER 10.00"));
	laser_close(l);
	stop_child(pid);
	close(m);
	close(keep);
	laser_cfg_free(cfg);
	laser_cfg_free(slow);
}

/* Open arms the laser's keep-alive with the configured period; laser_keepalive() refreshes it; 0 disarms;
 * a period the daemon's 250 ms refresh cannot hold is a configuration error. */
static void test_keepalive(void **state)
{
	(void)state;
	char path[128];
	int keep, m = open_pty(path, sizeof path, &keep);
	static const char *const script[] = { "ID M S F\n", NULL };
	pid_t pid = script_peer(m, script);
	struct laser_cfg *cfg = make_cfg(path, 1000);
	struct laser *l = NULL;
	struct acq_err err = { 0 };
	if (laser_open(cfg, &l, &err))
		fail_msg("%s", err.msg);
	assert_int_equal(laser_cfg_keepalive_ms(cfg), 1000);
	assert_int_equal(laser_keepalive(l, &err), 0);
	assert_true(sh->nlines >= 4);
	assert_string_equal(sh->lines[2], "KEEPALIVE 1000");
	assert_string_equal(sh->lines[3], "KEEPALIVE");
	laser_close(l);
	stop_child(pid);
	close(m);
	close(keep);
	laser_cfg_free(cfg);
	for (int k = 0; k < 2; k++) {
		char text[256];
		snprintf(text, sizeof text, "device: /dev/null\nkeepalive_ms: %d\n", k ? 0 : 200);
		struct yc_doc *doc = NULL;
		assert_int_equal(yc_load_string("laser.yaml", text, strlen(text), &doc, &err), 0);
		struct laser_cfg *c = NULL;
		assert_int_equal(laser_cfg_parse(yc_root(doc), &c, &err), k ? 0 : -1);
		if (!k)
			assert_non_null(strstr(err.msg, "laser.yaml:2"));
		laser_cfg_free(c);
		yc_free(doc);
	}
}

static void test_config_errors(void **state)
{
	(void)state;
	static const char text[] = "baud: 9600\nspeed: 3\n";
	struct yc_doc *doc = NULL;
	struct laser_cfg *cfg = NULL;
	struct acq_err err = { 0 };
	assert_int_equal(yc_load_string("laser.yaml", text, strlen(text), &doc, &err), 0);
	assert_int_equal(laser_cfg_parse(yc_root(doc), &cfg, &err), -1);
	assert_non_null(strstr(err.msg, "laser.yaml:2"));
	assert_non_null(strstr(err.msg, "speed"));
	yc_free(doc);
	static const char text2[] = "baud: 9600\n";
	assert_int_equal(yc_load_string("laser.yaml", text2, strlen(text2), &doc, &err), 0);
	assert_int_equal(laser_cfg_parse(yc_root(doc), &cfg, &err), 0);
	struct laser *l = NULL;
	assert_int_equal(laser_open(cfg, &l, &err), -1);
	assert_int_equal(err.code, ACQ_E_CONFIG);
	assert_int_equal(laser_cfg_set_device(cfg, "/dev/nonexistent-laser", &err), 0);
	assert_int_equal(laser_open(cfg, &l, &err), -1);
	assert_non_null(strstr(err.msg, "/dev/nonexistent-laser"));
	laser_cfg_free(cfg);
	yc_free(doc); /* the configuration copies what it keeps */
	/* libserialport itself refuses a pseudo-terminal, with a clear error (hence the termios transport) */
	char path[128], text3[256];
	int keep, m = open_pty(path, sizeof path, &keep);
	snprintf(text3, sizeof text3, "device: %s\ntransport: serialport\ntimeout_ms: 50\n", path);
	assert_int_equal(yc_load_string("laser.yaml", text3, strlen(text3), &doc, &err), 0);
	assert_int_equal(laser_cfg_parse(yc_root(doc), &cfg, &err), 0);
	yc_free(doc);
	assert_int_equal(laser_open(cfg, &l, &err), -1);
	print_message("  -> %s\n", err.msg);
	assert_non_null(strstr(err.msg, path));
	laser_cfg_free(cfg);
	close(m);
	close(keep);
}

/* The example configurations' laser sections parse (config/bench-real.yaml, config/bench-sim.yaml). */
static void test_example_configs(void **state)
{
	(void)state;
	static const char *const files[] = { "config/bench-real.yaml", "config/bench-sim.yaml" };
	const char *src = getenv("ACQ_SRC") ? getenv("ACQ_SRC") : ".";
	for (int i = 0; i < 2; i++) {
		char path[4096];
		snprintf(path, sizeof path, "%s/%s", src, files[i]);
		struct yc_doc *doc = NULL;
		struct laser_cfg *cfg = NULL;
		struct acq_err err = { 0 };
		if (yc_load_file(path, &doc, &err) ||
		    laser_cfg_parse(yc_get(yc_get(yc_root(doc), "devices"), "laser"), &cfg, &err))
			fail_msg("%s", err.msg);
		laser_cfg_free(cfg);
		yc_free(doc);
	}
}

int main(void)
{
	sh = mmap(NULL, sizeof *sh, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
	if (sh == MAP_FAILED)
		return 1;
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_sim_identity_emission_power),
		cmocka_unit_test(test_sim_interlock_and_fault),
		cmocka_unit_test(test_sim_socket_link_and_keepalive),
		cmocka_unit_test(test_malformed_identity),
		cmocka_unit_test(test_malformed_status_switches_emission_off),
		cmocka_unit_test(test_stray_line_after_reply_dropped),
		cmocka_unit_test(test_hangup_error_order),
		cmocka_unit_test(test_dead_line_times_out),
		cmocka_unit_test(test_keepalive),
		cmocka_unit_test(test_config_errors),
		cmocka_unit_test(test_example_configs),
	};
	int rc = cmocka_run_group_tests(tests, NULL, NULL);
	munmap(sh, sizeof *sh);
	return rc;
}
