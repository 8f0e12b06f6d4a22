/* Fuzz target: the simulated arm controller (sim/sim_arm.c) fed arbitrary bytes by a client, over Modbus TCP
 * (first input byte even) or RTU on a pseudo-terminal (odd). It must never crash, whatever the frames. */
#include <fcntl.h>
#include <poll.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include "config/yconf.h"
#include "sim/sim.h"
#include "sim/sim_arm.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static struct sim_world world;
static struct sim_service *tcp_svc, *rtu_svc;
static struct yc_doc *doc;
static int pty_master = -1;

static const char *maps_yaml =
	"    oriental_az:\n"
	"      write: block\n      block: {start: 0x58, count: 16}\n"
	"      fields:\n"
	"        op_data: {addr: 0x58, type: int32, value: 0}\n        op_type: {addr: 0x5A, type: int32, value: 1}\n"
	"        target: {addr: 0x5C, type: int32, scale: 100}\n        speed: {addr: 0x5E, type: int32, scale: 100}\n"
	"        accel: {addr: 0x60, type: int32, scale: 100}\n        decel: {addr: 0x62, type: int32, scale: 100}\n"
	"        current: {addr: 0x64, type: int32, value: 1000}\n        trigger: {addr: 0x66, type: int32, value: 1}\n"
	"        status: {addr: 0x7F}\n        alarm_code: {addr: 0x80, type: int32}\n"
	"        actual: {addr: 0xCC, type: int32, scale: 100}\n"
	"      status_bits: {homed: 4, ready: 5, alarm: 7, busy: 8, move: 13, in_position: 14}\n"
	"      commands:\n        home: {addr: 0x7D, value: 0x10, mode: level}\n"
	"        stop: {addr: 0x7D, value: 0x20, mode: level}\n        alarm_reset: {addr: 0x7D, value: 0x80, mode: level}\n"
	"        start: {addr: 10, fc: coil, mode: pulse}\n";

static void setup(void)
{
	signal(SIGPIPE, SIG_IGN);
	world.scale = 1000;
	bench_defaults(&world.geom);
	world.detector_theta_deg = 60;
	world.detector_phi_deg = 180;
	pty_master = posix_openpt(O_RDWR | O_NOCTTY);
	if (pty_master < 0 || grantpt(pty_master) || unlockpt(pty_master))
		abort();
	char text[4096];
	snprintf(text, sizeof text,
		 "maps:\n%s"
		 "laser: {link: {type: tcp, port: 0}, axes: {theta: {unit: 1, map: oriental_az}}}\n"
		 "det: {link: {type: rtu, device: %s}, axes: {theta: {unit: 1, map: oriental_az},"
		 " phi: {unit: 2, map: oriental_az}}}\n", maps_yaml, ptsname(pty_master));
	struct acq_err err = { 0 };
	if (yc_load_string("f.yaml", text, strlen(text), &doc, &err))
		abort();
	struct yc_node *r = yc_root(doc);
	tcp_svc = sim_arm_new(&world, SIM_ARM_LASER, yc_get(r, "laser"), yc_get(r, "maps"), NULL, &err);
	rtu_svc = sim_arm_new(&world, SIM_ARM_DETECTOR, yc_get(r, "det"), yc_get(r, "maps"), NULL, &err);
	if (!tcp_svc || !rtu_svc) {
		fprintf(stderr, "%s\n", err.msg);
		abort();
	}
}

static double now_b;

/* Turn the service's loop a few times (as acq-sim does), draining what the client side receives. */
static void spin(struct sim_service *svc, int client, int turns)
{
	for (int k = 0; k < turns; k++) {
		struct pollfd fds[32];
		int n = svc->pollfds(svc->self, fds, 32);
		if (poll(fds, (nfds_t)n, 0) > 0)
			svc->handle(svc->self, fds, n, now_b);
		now_b += 0.01;
		svc->tick(svc->self, now_b);
		uint8_t junk[512];
		while (recv(client, junk, sizeof junk, MSG_DONTWAIT) > 0 || read(client, junk, 0) > 0) {
		}
	}
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (!tcp_svc)
		setup();
	if (size < 1)
		return 0;
	if (data[0] % 2 == 0) {
		int c = socket(AF_INET, SOCK_STREAM, 0);
		struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)simarm_port(tcp_svc)),
					  .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
		if (c < 0 || connect(c, (struct sockaddr *)&sa, sizeof sa))
			abort();
		spin(tcp_svc, c, 2); /* accept */
		if (size > 1 && send(c, data + 1, size - 1, MSG_NOSIGNAL) < 0) {
		}
		shutdown(c, SHUT_WR);
		spin(tcp_svc, c, 4);
		close(c);
		spin(tcp_svc, c, 1);
	} else {
		/* zeros after the input complete any torn frame (it then fails its CRC), so no turn waits for the
		 * simulator's 50 ms inter-byte timeout */
		static const uint8_t pad[300];
		if ((size > 1 && write(pty_master, data + 1, size - 1) < 0) || write(pty_master, pad, sizeof pad) < 0) {
		}
		struct pollfd p = { .fd = pty_master, .events = POLLIN };
		for (int k = 0; k < 8; k++) {
			spin(rtu_svc, -1, 1);
			uint8_t junk[512];
			while (poll(&p, 1, 0) > 0 && read(pty_master, junk, sizeof junk) > 0) {
			}
		}
	}
	return 0;
}
