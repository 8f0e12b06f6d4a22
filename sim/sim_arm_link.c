/* sim_arm_link: the Modbus links of a simulated arm controller (sim_arm.c answers the requests): TCP on 127.0.0.1
 * with several clients at once, or RTU on a tty framed here (several units share the bus); opened, polled, read
 * and closed on acq-sim's loop. */
#include <errno.h>
#include <modbus.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include "sim/sim_arm_int.h"

/* ---- RTU: libmodbus's server filters frames by its one slave id, but a bus carries several units; so the
 * simulator frames requests itself (length from the function code, CRC) and answers with modbus_reply(). */
static uint16_t crc16(const uint8_t *p, int n)
{
	uint16_t crc = 0xFFFF;
	for (int i = 0; i < n; i++) {
		crc ^= p[i];
		for (int b = 0; b < 8; b++)
			crc = crc & 1 ? (uint16_t)((crc >> 1) ^ 0xA001) : (uint16_t)(crc >> 1);
	}
	return crc;
}

/* Length of the RTU request frame starting at req (function codes 1–6, 15, 16), -1 if unknown. */
static int simarm_rtu_frame_len(const uint8_t *req, int avail)
{
	if (avail < 2)
		return -1;
	switch (req[1]) {
	case 1: case 2: case 3: case 4: case 5: case 6:
		return 8;
	case 15: case 16:
		return avail >= 7 ? 9 + req[6] : -1;
	default:
		return -1;
	}
}

/* Read one frame; the first byte is there (poll said so), the others must follow within 50 ms each. */
static int rtu_read_frame(int fd, uint8_t *buf, int cap)
{
	int n = 0, need = 2;
	while (n < need) {
		if (n > 0) {
			struct pollfd pfd = { .fd = fd, .events = POLLIN };
			if (poll(&pfd, 1, 50) <= 0)
				return -1; /* a torn frame: the bus drops it */
		}
		ssize_t r = read(fd, buf + n, (size_t)(need - n));
		if (r <= 0)
			return r == 0 || errno != EINTR ? -1 : (int)0;
		n += (int)r;
		if (n >= 2) {
			int l = simarm_rtu_frame_len(buf, n);
			if (l < 0 && (n >= 7 || (buf[1] != 15 && buf[1] != 16)))
				return -1;
			need = l < 0 ? 7 : l;
			if (need > cap)
				return -1;
		}
	}
	return n;
}

static void handle_rtu(struct sim_arm *s, double now)
{
	uint8_t req[MODBUS_RTU_MAX_ADU_LENGTH] = { 0 };
	int fd = modbus_get_socket(s->ctx);
	int len = rtu_read_frame(fd, req, (int)sizeof req);
	if (len < 4) {
		tcflush(fd, TCIFLUSH);
		return;
	}
	uint16_t crc = crc16(req, len - 2);
	if (req[len - 2] != (crc & 0xFF) || req[len - 1] != (crc >> 8))
		return;
	s->serve(s, req, len, now);
}

/* ---- TCP ---------------------------------------------------------------------------------------------- */

static void close_client(struct sim_arm *s, int i)
{
	close(s->clients[i]);
	s->clients[i] = s->clients[--s->nclients];
}

static void handle_tcp_client(struct sim_arm *s, int i, double now)
{
	uint8_t req[MODBUS_TCP_MAX_ADU_LENGTH] = { 0 };
	modbus_set_socket(s->ctx, s->clients[i]);
	int rc = modbus_receive(s->ctx, req);
	if (rc > 0)
		s->serve(s, req, rc, now);
	else if (rc < 0 && errno != EMBBADDATA && errno != EMBMDATA)
		close_client(s, i);
}

/* ---- the service's descriptors ------------------------------------------------------------------------- */

int simarm_pollfds(void *self, struct pollfd *fds, int max)
{
	struct sim_arm *s = self;
	int n = 0;
	if (max < 1)
		return 0;
	if (s->link_type == AXIS_LINK_RTU) {
		/* a hung-up tty (the pty pair's other end gone) is polled again only after a bench second */
		if (s->now >= s->rtu_quiet_until)
			fds[n++] = (struct pollfd){ .fd = modbus_get_socket(s->ctx), .events = POLLIN };
		return n;
	}
	fds[n++] = (struct pollfd){ .fd = s->listen_fd, .events = POLLIN };
	for (int i = 0; i < s->nclients && n < max; i++)
		fds[n++] = (struct pollfd){ .fd = s->clients[i], .events = POLLIN };
	return n;
}

void simarm_handle(void *self, const struct pollfd *fds, int n, double now)
{
	struct sim_arm *s = self;
	if (n < 1)
		return;
	if (s->link_type == AXIS_LINK_RTU) {
		if (fds[0].revents & (POLLHUP | POLLERR | POLLNVAL))
			s->rtu_quiet_until = now + 1.0;
		else if (fds[0].revents & POLLIN)
			handle_rtu(s, now);
		return;
	}
	/* clients first (indices stay valid while we walk backwards and close) */
	for (int k = n - 1; k >= 1; k--) {
		if (!(fds[k].revents & (POLLIN | POLLHUP | POLLERR)))
			continue;
		for (int i = 0; i < s->nclients; i++)
			if (s->clients[i] == fds[k].fd) {
				handle_tcp_client(s, i, now);
				break;
			}
	}
	if (fds[0].revents & POLLIN) {
		int c = accept4(s->listen_fd, NULL, NULL, SOCK_CLOEXEC);
		if (c >= 0) {
			if (s->nclients < MAX_CLIENTS)
				s->clients[s->nclients++] = c;
			else
				close(c);
		}
	}
}

/* ---- opening and closing --------------------------------------------------------------------------------- */

int simarm_link_open(struct sim_arm *s, const struct axis_link_cfg *l, struct acq_err *err)
{
	s->link_type = l->type;
	if (l->type == AXIS_LINK_TCP) {
		s->ctx = modbus_new_tcp("127.0.0.1", l->port);
		if (!s->ctx) {
			acq_errf(err, ACQ_E_IO, "simulated %s: modbus_new_tcp: %s", s->key, modbus_strerror(errno));
			return -1;
		}
		s->listen_fd = modbus_tcp_listen(s->ctx, 8);
		if (s->listen_fd < 0) {
			acq_errf(err, ACQ_E_IO, "simulated %s: cannot listen on 127.0.0.1:%d: %s", s->key, l->port,
				 modbus_strerror(errno));
			return -1;
		}
		struct sockaddr_in sa;
		socklen_t slen = sizeof sa;
		if (getsockname(s->listen_fd, (struct sockaddr *)&sa, &slen) != 0) {
			acq_errf(err, ACQ_E_IO, "simulated %s: getsockname: %s", s->key, strerror(errno));
			return -1;
		}
		s->port = ntohs(sa.sin_port);
	} else {
		snprintf(s->device, sizeof s->device, "%s", l->device);
		s->ctx = modbus_new_rtu(l->device, l->baud, l->parity, l->data_bits, l->stop_bits);
		if (!s->ctx) {
			acq_errf(err, ACQ_E_IO, "simulated %s: modbus_new_rtu(%s): %s", s->key, l->device,
				 modbus_strerror(errno));
			return -1;
		}
		if (modbus_connect(s->ctx) != 0) {
			acq_errf(err, ACQ_E_IO, "simulated %s: cannot open %s: %s", s->key, l->device, modbus_strerror(errno));
			modbus_free(s->ctx);
			s->ctx = NULL;
			return -1;
		}
		modbus_set_byte_timeout(s->ctx, 0, 100000);
	}
	if (s->ctx)
		modbus_set_byte_timeout(s->ctx, 0, 100000);
	/* On a server's context libmodbus uses the response timeout only for the pause before it flushes the input
	 * after a request it rejects itself in modbus_reply (a quantity out of range, say): with its default 0.5 s,
	 * one such frame froze every simulated device of acq-sim (one loop) for half a real second. */
	if (s->ctx)
		modbus_set_response_timeout(s->ctx, 0, 1000);
	return 0;
}

void simarm_link_drop(struct sim_arm *s)
{
	while (s->nclients > 0)
		close_client(s, s->nclients - 1);
}

void simarm_link_close(struct sim_arm *s)
{
	simarm_link_drop(s);
	if (s->listen_fd >= 0)
		close(s->listen_fd);
	if (s->ctx) {
		if (s->link_type == AXIS_LINK_RTU)
			modbus_close(s->ctx);
		modbus_free(s->ctx);
	}
}
