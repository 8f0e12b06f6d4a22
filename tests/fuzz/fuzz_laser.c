/* Fuzz target: the laser driver (drivers/laser_serial.c, socket transport) reading arbitrary replies. The input's
 * lines (split at '\n', at most FUZZ_LASER_MAX_LINES) are the laser's replies, one to each command the driver
 * sends, from a responder thread on a Unix socket; after the last the responder hangs up. The driver opens
 * (ID?, EMISSION OFF, KEEPALIVE), sets the power, switches emission on, reads the status, refreshes the
 * keep-alive, switches emission off and closes: it must return errors that name the laser, never crash or hang
 * (each reply is sent as soon as its command has arrived; the driver's timeout is 50 ms), and a status it accepts
 * must be what the replies said (printed back, the STATUS? reply is the same text: no number wrapped). */
#include <pthread.h>
#include <signal.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "config/yconf.h"
#include "drivers/laser.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define FUZZ_LASER_MAX_LINES 16

static int lfd = -1;
static struct yc_doc *doc;
static struct laser_cfg *cfg;

struct responder {
	const uint8_t *data;
	size_t size;
	char status[160], power[160]; /* the replies sent to STATUS? and POWER? (without the line end) */
};

static char path[108];

static void remove_socket(void)
{
	unlink(path);
}

static void setup(void)
{
	signal(SIGPIPE, SIG_IGN);
	snprintf(path, sizeof path, "/tmp/fuzz-laser-%ld.sock", (long)getpid());
	unlink(path);
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	snprintf(sa.sun_path, sizeof sa.sun_path, "%s", path);
	lfd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (lfd < 0 || bind(lfd, (struct sockaddr *)&sa, sizeof sa) || listen(lfd, 4))
		abort();
	char text[256];
	snprintf(text, sizeof text, "device: unix:%s\ntimeout_ms: 50\nkeepalive_ms: 500\n", path);
	struct acq_err err = { 0 };
	if (yc_load_string("f.yaml", text, strlen(text), &doc, &err) || laser_cfg_parse(yc_root(doc), &cfg, &err)) {
		fprintf(stderr, "%s\n", err.msg);
		abort();
	}
	atexit(remove_socket);
}

/* Accepts one connection, then answers each command line with the input's next line; hangs up after the last
 * (or when the driver does). */
static void *respond(void *arg)
{
	struct responder *r = arg;
	int c = accept(lfd, NULL, NULL);
	if (c < 0)
		return NULL;
	size_t pos = 0;
	int lines = 0;
	char cmd[256];
	size_t clen = 0;
	while (pos < r->size && lines < FUZZ_LASER_MAX_LINES) {
		char ch;
		ssize_t n = recv(c, &ch, 1, 0);
		if (n <= 0)
			break;
		if (ch != '\n') {
			if (clen < sizeof cmd)
				cmd[clen++] = ch;
			continue;
		}
		const uint8_t *nl = memchr(r->data + pos, '\n', r->size - pos);
		size_t len = nl ? (size_t)(nl - (r->data + pos)) + 1 : r->size - pos;
		char *keep = clen == 7 && !memcmp(cmd, "STATUS?", 7) ? r->status
			     : clen == 6 && !memcmp(cmd, "POWER?", 6) ? r->power : NULL;
		if (keep) { /* as the driver reads it: up to the newline, every CR dropped */
			size_t k = 0;
			for (size_t i = 0; i < len && r->data[pos + i] != '\n' && k < sizeof r->status - 1; i++)
				if (r->data[pos + i] != '\r')
					keep[k++] = (char)r->data[pos + i];
			keep[k] = '\0';
		}
		clen = 0;
		if (send(c, r->data + pos, len, MSG_NOSIGNAL) < 0)
			break;
		pos += len;
		lines++;
	}
	close(c);
	return NULL;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (lfd < 0)
		setup();
	struct responder r = { data, size, "", "" };
	pthread_t th;
	if (pthread_create(&th, NULL, respond, &r))
		abort();
	struct laser *l = NULL;
	struct acq_err err = { 0 };
	struct laser_status st;
	bool accepted = false;
	if (laser_open(cfg, &l, &err) == 0) {
		if (laser_set_power(l, 50, &err) == 0 && laser_set_emission(l, true, &err) == 0 &&
		    laser_status(l, &st, &err) == 0) {
			if (!(st.power_pct >= 0 && st.power_pct <= 100) || st.fault_code < 0)
				abort(); /* a status the driver accepted must be in range */
			accepted = true;
			(void)laser_keepalive(l, &err);
		}
		struct acq_err off = { 0 }; /* err keeps the session's first error */
		(void)laser_set_emission(l, false, err.msg[0] ? &off : &err);
		laser_close(l);
	} else if (!err.msg[0] || !strstr(err.msg, "laser")) {
		abort(); /* an error names the laser */
	}
	pthread_join(th, NULL);
	if (accepted) {
		/* the reply's numbers without leading zeros ("fault=007" is fault 7) */
		char *w = r.status;
		for (const char *q = r.status; *q; q++)
			if (!(*q == '0' && w > r.status && w[-1] == '=' && q[1] >= '0' && q[1] <= '9'))
				*w++ = *q;
		*w = '\0'; /* what the driver accepted is what the laser said (sscanf's %d wrapped 4294967297 to 1) */
		char back[160];
		snprintf(back, sizeof back, "STATUS emission=%d interlock=%d fault=%d", st.emission, st.interlock_ok,
			 st.fault_code);
		if (strcmp(back, r.status) || strncmp(r.power, "POWER ", 6) || strtod(r.power + 6, NULL) != st.power_pct)
			abort();
	}
	if (getenv("FUZZ_LASER_DEBUG")) /* what the driver made of the input */
		fprintf(stderr, "fuzz_laser: %s\n", err.msg[0] ? err.msg : "the whole session passed");
	return 0;
}
