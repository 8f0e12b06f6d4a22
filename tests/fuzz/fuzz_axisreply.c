/* Fuzz target: the axis driver (drivers/axis_modbus.c over libmodbus) reading arbitrary controller replies.
 * The bytes are queued on the controller side of a loopback TCP connection before the driver asks, then that
 * side is shut down; the driver reads status, starts a move, steps it, resets an alarm. It must return errors,
 * never crash or hang. */
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "config/yconf.h"
#include "drivers/axis.h"
#include "drivers/axis_modbus.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int lfd = -1;
static struct yc_doc *doc;
static struct axis_cfg *cfg;

static void setup(void)
{
	signal(SIGPIPE, SIG_IGN);
	lfd = socket(AF_INET, SOCK_STREAM, 0);
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	socklen_t sl = sizeof sa;
	if (lfd < 0 || bind(lfd, (struct sockaddr *)&sa, sizeof sa) || listen(lfd, 4) ||
	    getsockname(lfd, (struct sockaddr *)&sa, &sl))
		abort();
	char text[2048];
	snprintf(text, sizeof text,
		 "maps:\n  az:\n    write: block\n    block: {start: 0x58, count: 16}\n    fields:\n"
		 "      op_type: {addr: 0x5A, type: int32, value: 1}\n      target: {addr: 0x5C, type: int32, scale: 100}\n"
		 "      speed: {addr: 0x5E, type: int32, scale: 100}\n      trigger: {addr: 0x66, type: int32, value: 1}\n"
		 "      status: {addr: 0x7F}\n      alarm_code: {addr: 0x80, type: int32}\n"
		 "      actual: {addr: 0xCC, type: float32, word_order: little}\n"
		 "    status_bits: {homed: 4, ready: 5, alarm: 7, busy: 8, in_position: 14}\n"
		 "    commands: {stop: {addr: 0x7D, value: 0x20, mode: level}, alarm_reset: {addr: 0x7D, value: 0x80}}\n"
		 "arm:\n  link: {type: tcp, port: %d, response_timeout_ms: 2, byte_timeout_ms: 1}\n"
		 "  axes: {theta: {unit: 1, map: az, retries: 1, poll_s: 0.01, timeout_margin_s: 0.05}}\n",
		 ntohs(sa.sin_port));
	struct acq_err err = { 0 };
	int n = 0;
	if (yc_load_string("f.yaml", text, strlen(text), &doc, &err) ||
	    axis_arm_parse(yc_get(yc_root(doc), "arm"), yc_get(yc_root(doc), "maps"), "laser_arm", &cfg, 1, &n, &err)) {
		fprintf(stderr, "%s\n", err.msg);
		abort();
	}
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (lfd < 0)
		setup();
	struct axis *ax = NULL;
	struct acq_err err = { 0 };
	if (axis_open(cfg, &ax, &err))
		return 0;
	int c = accept(lfd, NULL, NULL);
	if (c < 0)
		abort();
	if (size && send(c, data, size, MSG_NOSIGNAL) < 0) {
	}
	shutdown(c, SHUT_WR);
	struct axis_status st;
	struct axis_identity id;
	(void)axis_read_status(ax, &st, &err);
	if (axis_move_begin(ax, 12.5, 0, &err) == 0)
		for (double t = 0.01; t < 1 && axis_move_step(ax, t, &err) == AXIS_MOVE_RUNNING; t += 0.01) {
		}
	(void)axis_alarm_reset(ax, &err);
	(void)axis_identity(ax, &id, &err);
	(void)axis_stop(ax, &err);
	axis_close(ax);
	close(c);
	return 0;
}
