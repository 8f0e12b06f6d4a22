/* laser_serial: the supercontinuum laser over a serial line (libserialport), ASCII line protocol below.
 *
 * Line protocol (ours; the simulator in sim/sim_laser.c speaks it, a real laser gets a small adapter or a
 * protocol of the same shape). ASCII, one command per line ending in "\n" (the laser accepts "\r\n"), one
 * reply line per command ending in "\n" ("\r" before it ignored), at most LASER_LINE_MAX bytes:
 *
 *   ID?             → ID <model> <serial> <firmware>          (three tokens without spaces)
 *   EMISSION ON     → OK | ERR <code> <text>                   (refused while interlock open or in fault)
 *   EMISSION OFF    → OK                                       (always accepted)
 *   EMISSION?       → EMISSION <0|1>                           (answered by the simulator; the driver uses STATUS?)
 *   POWER <pct>     → OK | ERR <code> <text>                   (pct in [0, 100], decimal)
 *   POWER?          → POWER <pct>                              e.g. "POWER 42.0"
 *   KEEPALIVE <ms>  → OK        arm the laser's watchdog: emission stops if no command arrives within ms
 *                               (0 disarms); every command, and "KEEPALIVE" alone, refreshes it
 *   KEEPALIVE       → OK
 *   STATUS?         → STATUS emission=<0|1> interlock=<0|1> fault=<code>
 *                     interlock=1 means closed (emission allowed); fault 0 = none
 *   any error       → ERR <code> <text>: 1 unknown command, 2 bad argument, 3 interlock open,
 *                     4 fault active, 5 line too long
 *
 * Every command waits at most timeout_ms for its complete reply line (calls block: laser_status() sends two
 * commands, so up to 2 × timeout_ms). Unread input is discarded before each command, so a late reply to a
 * timed-out command is not taken for the next one (unless it arrives after that command was sent: the
 * protocol has no sequence numbers). Anything else (another reply, a missing field, a number out of range, an
 * overlong line, a non-printable byte) is an ACQ_E_PROTO error quoting the line; "ERR n text" is
 * ACQ_E_DEVICE with detail = n.
 * Safety: open switches emission off; every failed call switches it off (best effort) before returning;
 * close switches it off. Open arms the laser's keep-alive (keepalive_ms, default 1000): a daemon that dies
 * or hangs stops refreshing it (laser_keepalive(), called by the daemon's laser thread every keepalive_ms / 4
 * while its loop beats) and emission stops by itself.
 *
 * Config (devices.laser):
 *   device: /dev/ttyUSB0   baud: 115200   data_bits: 8   parity: none|odd|even   stop_bits: 1|2
 *   flow_control: none|xonxoff|rtscts      timeout_ms: 500     max_power_pct: 100     keepalive_ms: 1000
 *   transport: auto|serialport|termios|socket   backend: serial (this file) | fake (drivers/laser_fake.c, tests)
 * With acq-sim, the device is the one written in its ports file ("laser": {"device": "unix:PATH"}, or
 * "/dev/pts/N" with sim.laser.link: pty): laser_cfg_set_device() puts it in.
 *
 * Transport: real serial ports go through libserialport. libserialport 0.1.1 refuses pseudo-terminals
 * (sp_get_port_by_name wants a /sys/class/tty entry, sp_open needs the TIOCMGET modem-line ioctl a pty does not
 * have; upstream treats PTYs as out of scope, sigrokproject/libserialport PR #4), so a device that resolves to
 * /dev/pts/N uses the same line protocol over plain termios + poll ("auto", the default). A device
 * "unix:PATH" is a serial line served on a Unix stream socket (a serial device server such as ser2net, or
 * acq-sim's laser): the same line protocol over the socket ("socket"; the line settings do not apply there).
 * "serialport", "termios" or "socket" force one. */
#include "config/acq_num.h"
#include "drivers/laser.h"
#include "drivers/laser_backend.h"

#include <errno.h>
#include <fcntl.h>
#include <libserialport.h>
#include <limits.h>
#include <math.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#define LASER_LINE_MAX 128

struct laser_cfg {
	char *device;
	int baud, data_bits, parity, stop_bits, flow;
	int timeout_ms;
	int keepalive_ms;       /* 0: the laser's watchdog stays disarmed */
	double max_power_pct;
	int transport;          /* enum laser_transport */
	int backend;            /* 0 serial (this file), 1 fake (drivers/laser_fake.c) */
};

enum laser_transport { LASER_T_AUTO, LASER_T_SERIALPORT, LASER_T_TERMIOS, LASER_T_SOCKET };

struct laser_dev;

/* The byte link under the line protocol: libserialport or termios (see the file comment). */
struct laser_io {
	const char *name;
	int (*open)(struct laser_dev *l, struct acq_err *err);
	/* Write all n bytes within timeout_ms. 0 or -1. The read and write errors say what happened only: exchange()
	 * puts the laser and the command before it. */
	int (*write)(struct laser_dev *l, const char *buf, size_t n, int timeout_ms, struct acq_err *err);
	/* Read one byte: 1, 0 (nothing within timeout_ms), -1. */
	int (*read)(struct laser_dev *l, char *c, int timeout_ms, struct acq_err *err);
	/* Discard unread input. */
	void (*flush)(struct laser_dev *l);
	void (*close)(struct laser_dev *l);
};

struct laser_dev {
	const struct laser_cfg *cfg;
	const struct laser_io *io;
	struct sp_port *port;   /* serialport transport */
	int fd;                 /* termios transport */
	struct laser_identity id;
	char line[LASER_LINE_MAX + 1];
	/* termios and socket transports: what one read(2) brought beyond the bytes taken (a reply line is read in
	 * one or a few calls, not a poll and a read per byte); emptied with the unread input before each command */
	char rbuf[2 * LASER_LINE_MAX];
	size_t rpos, rlen;
};

/* ---- configuration ------------------------------------------------------------------------------------ */

int laser_cfg_parse(struct yc_node *node, struct laser_cfg **out, struct acq_err *err)
{
	*out = NULL;
	if (yc_expect_map(node, "laser", err))
		return -1;
	static const char *const parities[] = { "none", "odd", "even", NULL };
	static const char *const flows[] = { "none", "xonxoff", "rtscts", NULL };
	static const char *const transports[] = { "auto", "serialport", "termios", "socket", NULL };
	static const char *const backends[] = { "serial", "fake", NULL };
	int transport = 0, backend = 0;
	const char *device = NULL;
	long long baud = 115200, bits = 8, stop = 1, timeout = 500, keepalive = 1000;
	int parity = 0, flow = 0;
	double maxp = 100;
	if (yc_string(node, "device", false, &device, err) || yc_int(node, "baud", false, 50, 4000000, &baud, err) ||
	    yc_int(node, "data_bits", false, 5, 8, &bits, err) || yc_enum(node, "parity", false, parities, &parity, err) ||
	    yc_int(node, "stop_bits", false, 1, 2, &stop, err) ||
	    yc_enum(node, "flow_control", false, flows, &flow, err) ||
	    yc_int(node, "timeout_ms", false, 1, 60000, &timeout, err) ||
	    yc_int(node, "keepalive_ms", false, 0, 60000, &keepalive, err) ||
	    yc_double(node, "max_power_pct", false, 0, 100, &maxp, err) ||
	    yc_enum(node, "transport", false, transports, &transport, err) ||
	    yc_enum(node, "backend", false, backends, &backend, err) || yc_check_unknown(node, "laser", err))
		return -1;
	if (keepalive && keepalive < 500) /* the daemon refreshes it every keepalive_ms / 4: >= 125 ms apart */
		return yc_errf(err, yc_get(node, "keepalive_ms"), "laser.keepalive_ms: %lld: expected 0 (off) or 500 to "
			       "60000 ms", keepalive);
	struct laser_cfg *c = calloc(1, sizeof *c);
	if (!c || (device && !(c->device = strdup(device)))) {
		free(c);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	c->baud = (int)baud;
	c->data_bits = (int)bits;
	c->parity = parity;
	c->stop_bits = (int)stop;
	c->flow = flow;
	c->timeout_ms = (int)timeout;
	c->keepalive_ms = (int)keepalive;
	c->max_power_pct = maxp;
	c->transport = transport;
	c->backend = backend;
	*out = c;
	return 0;
}

int laser_cfg_set_device(struct laser_cfg *cfg, const char *device, struct acq_err *err)
{
	char *d = strdup(device);
	if (!d)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	free(cfg->device);
	cfg->device = d;
	return 0;
}

void laser_cfg_free(struct laser_cfg *cfg)
{
	if (!cfg)
		return;
	free(cfg->device);
	free(cfg);
}

/* ---- line exchange -------------------------------------------------------------------------------------- */

static double mono_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* libserialport's last error as "laser DEV: what: message"; dev NULL inside an exchange (which puts the laser and
 * the command first). */
static int sp_errf(struct acq_err *err, const char *dev, const char *what)
{
	char *m = sp_last_error_message();
	if (dev)
		acq_errf(err, ACQ_E_IO, "laser %s: %s: %s", dev, what, m ? m : "error");
	else
		acq_errf(err, ACQ_E_IO, "%s: %s", what, m ? m : "error");
	sp_free_error_message(m);
	return -1;
}

/* A decimal integer in [0, max] at *p (digits only: no sign, space or base prefix), *p moved past it.
 * 0, or -1 (not a number, or out of range: *p is left where it was). */
static int dec_long(const char **p, long max, long *out)
{
	if (**p < '0' || **p > '9')
		return -1;
	char *end;
	errno = 0;
	long v = strtol(*p, &end, 10);
	if (errno || v > max)
		return -1;
	*p = end;
	*out = v;
	return 0;
}

/* Send cmd and read one reply line into l->line (without the newline). 0 or -1; every error reads
 * "laser DEV: 'CMD': what happened" (the transports' read/write errors say only what happened). */
static int exchange(struct laser_dev *l, const char *cmd, struct acq_err *err)
{
	const char *dev = l->cfg->device;
	char out[LASER_LINE_MAX + 2];
	int n = snprintf(out, sizeof out, "%s\n", cmd);
	if (n < 0 || (size_t)n >= sizeof out)
		return acq_errf(err, ACQ_E_INVAL, "laser %s: command too long", dev);
	/* Whatever arrived unasked (a late reply to a timed-out command) must not be taken for this reply. */
	l->io->flush(l);
	if (l->io->write(l, out, (size_t)n, l->cfg->timeout_ms, err))
		return acq_err_prefix(err, "laser %s: '%s': ", dev, cmd);
	double deadline = mono_ms() + l->cfg->timeout_ms;
	size_t len = 0;
	for (;;) {
		/* Past the deadline, what has arrived is still read (a thread descheduled on a loaded machine wakes
		 * after its deadline with the reply waiting): only nothing more to read ends the wait. */
		double left = deadline - mono_ms();
		char c;
		int r = l->io->read(l, &c, left < 1 ? 0 : (int)left, err);
		if (r < 0)
			return acq_err_prefix(err, "laser %s: '%s': ", dev, cmd);
		if (r == 0) {
			if (left >= 1)
				continue;
			l->line[len] = '\0';
			return acq_errf(err, ACQ_E_TIMEOUT, "laser %s: no reply to '%s' within %d ms%s%s%s", dev, cmd,
					l->cfg->timeout_ms, len ? " (partial: '" : "", len ? l->line : "", len ? "')" : "");
		}
		if (c == '\n')
			break;
		if (c == '\r')
			continue;
		if (len >= LASER_LINE_MAX)
			return acq_errf(err, ACQ_E_PROTO, "laser %s: reply to '%s' longer than %d bytes", dev, cmd,
					LASER_LINE_MAX);
		if ((unsigned char)c < 0x20 || (unsigned char)c > 0x7e)
			return acq_errf(err, ACQ_E_PROTO, "laser %s: reply to '%s' has a non-printable byte 0x%02x", dev,
					cmd, (unsigned char)c);
		l->line[len++] = c;
	}
	l->line[len] = '\0';
	if (!strncmp(l->line, "ERR", 3) && (l->line[3] == ' ' || !l->line[3])) {
		long code;
		acq_errf(err, ACQ_E_DEVICE, "laser %s: '%s' refused: %s", dev, cmd, l->line);
		const char *p = l->line + 3 + (l->line[3] == ' ');
		if (err && !dec_long(&p, INT_MAX, &code) && (*p == ' ' || !*p))
			err->detail = (int)code; /* "ERR n text": n when it is a number 0..INT_MAX, else 0 */
		return -1;
	}
	return 0;
}

static int expect_ok(struct laser_dev *l, const char *cmd, struct acq_err *err)
{
	if (exchange(l, cmd, err))
		return -1;
	if (strcmp(l->line, "OK"))
		return acq_errf(err, ACQ_E_PROTO, "laser %s: '%s': expected 'OK', got '%s'", l->cfg->device, cmd, l->line);
	return 0;
}

/* A reply that is not what cmd expects: "laser DEV: 'CMD': what (reply 'LINE'; expected 'FORM')". -1. */
static int reply_errf(struct laser_dev *l, struct acq_err *err, const char *cmd, const char *form, const char *fmt, ...)
	__attribute__((format(printf, 5, 6)));
static int reply_errf(struct laser_dev *l, struct acq_err *err, const char *cmd, const char *form, const char *fmt, ...)
{
	char what[256];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(what, sizeof what, fmt, ap);
	va_end(ap);
	return acq_errf(err, ACQ_E_PROTO, "laser %s: '%s': %s (reply '%s'; expected '%s')", l->cfg->device, cmd, what,
			l->line, form);
}

/* Best-effort emission off after an error; err keeps the first error. */
static int fail_safe(struct laser_dev *l)
{
	struct acq_err ignored;
	(void)expect_ok(l, "EMISSION OFF", &ignored);
	return -1;
}

/* ---- transports --------------------------------------------------------------------------------------- */

static int sp_open_port(struct laser_dev *l, struct acq_err *err)
{
	const struct laser_cfg *cfg = l->cfg;
	static const enum sp_parity par[] = { SP_PARITY_NONE, SP_PARITY_ODD, SP_PARITY_EVEN };
	static const enum sp_flowcontrol flow[] = { SP_FLOWCONTROL_NONE, SP_FLOWCONTROL_XONXOFF, SP_FLOWCONTROL_RTSCTS };
	if (sp_get_port_by_name(cfg->device, &l->port) != SP_OK) {
		l->port = NULL;
		return acq_errf(err, ACQ_E_NOTFOUND, "laser %s: not a serial port libserialport knows", cfg->device);
	}
	if (sp_open(l->port, SP_MODE_READ_WRITE) != SP_OK) {
		sp_errf(err, cfg->device, "open");
		sp_free_port(l->port);
		l->port = NULL;
		return -1;
	}
	if (sp_set_baudrate(l->port, cfg->baud) != SP_OK || sp_set_bits(l->port, cfg->data_bits) != SP_OK ||
	    sp_set_parity(l->port, par[cfg->parity]) != SP_OK || sp_set_stopbits(l->port, cfg->stop_bits) != SP_OK ||
	    sp_set_flowcontrol(l->port, flow[cfg->flow]) != SP_OK)
		return sp_errf(err, cfg->device, "configuring the line");
	return 0;
}

static int sp_write_all(struct laser_dev *l, const char *buf, size_t n, int timeout_ms, struct acq_err *err)
{
	int w = sp_blocking_write(l->port, buf, n, (unsigned)timeout_ms);
	if (w < 0)
		return sp_errf(err, NULL, "write");
	if ((size_t)w != n)
		return acq_errf(err, ACQ_E_TIMEOUT, "not sent within %d ms", timeout_ms);
	return 0;
}

static int sp_read_byte(struct laser_dev *l, char *c, int timeout_ms, struct acq_err *err)
{
	int r = sp_blocking_read(l->port, c, 1, (unsigned)(timeout_ms > 0 ? timeout_ms : 1));
	if (r < 0)
		return sp_errf(err, NULL, "read");
	return r;
}

static void sp_flush_in(struct laser_dev *l)
{
	sp_flush(l->port, SP_BUF_INPUT);
}

static void sp_close_port(struct laser_dev *l)
{
	if (l->port) {
		sp_close(l->port);
		sp_free_port(l->port);
		l->port = NULL;
	}
}

static const struct laser_io io_serialport = {
	"libserialport", sp_open_port, sp_write_all, sp_read_byte, sp_flush_in, sp_close_port,
};

static int tio_open(struct laser_dev *l, struct acq_err *err)
{
	const struct laser_cfg *cfg = l->cfg;
	static const struct { int baud; speed_t sp; } speeds[] = {
		{ 1200, B1200 }, { 2400, B2400 }, { 4800, B4800 }, { 9600, B9600 }, { 19200, B19200 },
		{ 38400, B38400 }, { 57600, B57600 }, { 115200, B115200 }, { 230400, B230400 },
		{ 460800, B460800 }, { 921600, B921600 },
	};
	speed_t sp = 0;
	for (size_t i = 0; i < sizeof speeds / sizeof speeds[0]; i++)
		if (speeds[i].baud == cfg->baud)
			sp = speeds[i].sp;
	if (!sp)
		return acq_errf(err, ACQ_E_CONFIG, "laser %s: baud %d is not a standard termios rate", cfg->device,
				cfg->baud);
	l->fd = open(cfg->device, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
	if (l->fd < 0)
		return acq_errf(err, errno == ENOENT ? ACQ_E_NOTFOUND : ACQ_E_IO, "laser %s: open: %s", cfg->device,
				strerror(errno));
	struct termios t;
	if (tcgetattr(l->fd, &t))
		return acq_errf(err, ACQ_E_IO, "laser %s: not a terminal: %s", cfg->device, strerror(errno));
	cfmakeraw(&t);
	t.c_cflag &= ~(tcflag_t)(CSIZE | PARENB | PARODD | CSTOPB | CRTSCTS);
	static const tcflag_t bits[] = { CS5, CS6, CS7, CS8 };
	t.c_cflag |= bits[cfg->data_bits - 5] | CLOCAL | CREAD;
	if (cfg->parity)
		t.c_cflag |= PARENB | (cfg->parity == 1 ? PARODD : 0);
	if (cfg->stop_bits == 2)
		t.c_cflag |= CSTOPB;
	if (cfg->flow == 2)
		t.c_cflag |= CRTSCTS;
	if (cfg->flow == 1)
		t.c_iflag |= IXON | IXOFF;
	cfsetispeed(&t, sp);
	cfsetospeed(&t, sp);
	if (tcsetattr(l->fd, TCSANOW, &t))
		return acq_errf(err, ACQ_E_IO, "laser %s: configuring the line: %s", cfg->device, strerror(errno));
	return 0;
}

/* Write all n bytes to l->fd within timeout_ms: write(2) on a terminal, send(2) on a socket (a closed peer then
 * gives EPIPE, not SIGPIPE). 0 or -1. */
static int fd_write_all(struct laser_dev *l, const char *buf, size_t n, int timeout_ms, bool sock, struct acq_err *err)
{
	double deadline = mono_ms() + timeout_ms;
	while (n) {
		ssize_t w = sock ? send(l->fd, buf, n, MSG_NOSIGNAL) : write(l->fd, buf, n);
		if (w > 0) {
			buf += w;
			n -= (size_t)w;
			continue;
		}
		if (w < 0 && errno != EAGAIN && errno != EINTR)
			return acq_errf(err, errno == EIO || errno == EPIPE || errno == ECONNRESET ? ACQ_E_DISCONNECTED : ACQ_E_IO,
					"write: %s", strerror(errno));
		double left = deadline - mono_ms();
		if (left < 1)
			return acq_errf(err, ACQ_E_TIMEOUT, "not sent within %d ms", timeout_ms);
		struct pollfd p = { .fd = l->fd, .events = POLLOUT };
		poll(&p, 1, (int)left);
	}
	return 0;
}

static int tio_write(struct laser_dev *l, const char *buf, size_t n, int timeout_ms, struct acq_err *err)
{
	return fd_write_all(l, buf, n, timeout_ms, false, err);
}

/* Fill l->rbuf with what is waiting (waiting up to timeout_ms for the first byte): 1, 0 (nothing), -1. */
static int tio_fill(struct laser_dev *l, int timeout_ms, struct acq_err *err)
{
	for (int polled = 0;; polled = 1) {
		ssize_t n = read(l->fd, l->rbuf, sizeof l->rbuf);
		if (n > 0) {
			l->rpos = 0;
			l->rlen = (size_t)n;
			return 1;
		}
		if (n == 0 || errno == EIO)
			return acq_errf(err, ACQ_E_DISCONNECTED, "the line was hung up");
		if (errno != EAGAIN && errno != EINTR)
			return acq_errf(err, ACQ_E_IO, "read: %s", strerror(errno));
		if (polled)
			return 0;
		struct pollfd p = { .fd = l->fd, .events = POLLIN };
		int r = poll(&p, 1, timeout_ms > 0 ? timeout_ms : 1);
		if (r < 0)
			return errno == EINTR ? 0 : acq_errf(err, ACQ_E_IO, "poll: %s", strerror(errno));
		if (r == 0)
			return 0;
	}
}

static int tio_read(struct laser_dev *l, char *c, int timeout_ms, struct acq_err *err)
{
	if (l->rpos == l->rlen) {
		int r = tio_fill(l, timeout_ms, err);
		if (r <= 0)
			return r;
	}
	*c = l->rbuf[l->rpos++];
	return 1;
}

static void tio_flush(struct laser_dev *l)
{
	l->rpos = l->rlen = 0;
	tcflush(l->fd, TCIFLUSH);
}

static void tio_close(struct laser_dev *l)
{
	if (l->fd >= 0)
		close(l->fd);
	l->fd = -1;
}

static const struct laser_io io_termios = { "termios", tio_open, tio_write, tio_read, tio_flush, tio_close };

/* The socket transport: "unix:PATH" (or a bare path with transport: socket). */
static const char *sock_path(const char *device)
{
	return strncmp(device, "unix:", 5) ? device : device + 5;
}

static int sock_open(struct laser_dev *l, struct acq_err *err)
{
	const char *dev = l->cfg->device, *path = sock_path(dev);
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	if (strlen(path) >= sizeof sa.sun_path)
		return acq_errf(err, ACQ_E_CONFIG, "laser %s: socket path longer than %zu bytes", dev, sizeof sa.sun_path - 1);
	strcpy(sa.sun_path, path);
	l->fd = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
	if (l->fd < 0)
		return acq_errf(err, ACQ_E_IO, "laser %s: socket: %s", dev, strerror(errno));
	if (connect(l->fd, (struct sockaddr *)&sa, sizeof sa) < 0)
		return acq_errf(err, errno == ENOENT || errno == ECONNREFUSED ? ACQ_E_NOTFOUND : ACQ_E_IO,
				"laser %s: connect: %s", dev, strerror(errno));
	return 0;
}

static int sock_write(struct laser_dev *l, const char *buf, size_t n, int timeout_ms, struct acq_err *err)
{
	return fd_write_all(l, buf, n, timeout_ms, true, err);
}

static void sock_flush(struct laser_dev *l)
{
	l->rpos = l->rlen = 0;
	char buf[256];
	while (recv(l->fd, buf, sizeof buf, MSG_DONTWAIT) > 0)
		;
}

static const struct laser_io io_socket = { "socket", sock_open, sock_write, tio_read, sock_flush, tio_close };

static const struct laser_io *pick_io(const struct laser_cfg *cfg)
{
	if (cfg->transport == LASER_T_SERIALPORT)
		return &io_serialport;
	if (cfg->transport == LASER_T_TERMIOS)
		return &io_termios;
	if (cfg->transport == LASER_T_SOCKET || !strncmp(cfg->device, "unix:", 5))
		return &io_socket;
	char real[PATH_MAX];
	if (realpath(cfg->device, real) && !strncmp(real, "/dev/pts/", 9))
		return &io_termios;
	return &io_serialport;
}

/* ---- API ------------------------------------------------------------------------------------------------- */

/* "ID <model> <serial> <firmware>" in l->line into l->id: three words (no spaces, the reply is printable), each
 * at most 63 characters. 0 or -1. */
static int parse_id(struct laser_dev *l, struct acq_err *err)
{
	static const char form[] = "ID <model> <serial> <firmware>";
	static const char *const names[] = { "model", "serial", "firmware" };
	char *const dst[] = { l->id.model, l->id.serial, l->id.firmware };
	if (strncmp(l->line, "ID ", 3))
		return reply_errf(l, err, "ID?", form, "not an identity");
	const char *p = l->line + 3;
	for (int k = 0; k < 3; k++) {
		while (*p == ' ')
			p++;
		size_t n = strcspn(p, " ");
		if (!n)
			return reply_errf(l, err, "ID?", form, "no %s", names[k]);
		if (n >= sizeof l->id.model)
			return reply_errf(l, err, "ID?", form, "the %s is %zu characters, more than %zu", names[k], n,
					  sizeof l->id.model - 1);
		memcpy(dst[k], p, n);
		dst[k][n] = '\0';
		p += n;
	}
	while (*p == ' ')
		p++;
	if (*p)
		return reply_errf(l, err, "ID?", form, "more than three words");
	return 0;
}

static int ls_open(const struct laser_cfg *cfg, struct laser_dev **out, struct acq_err *err)
{
	*out = NULL;
	if (!cfg->device)
		return acq_errf(err, ACQ_E_CONFIG, "laser: no serial device configured (devices.laser.device)");
	struct laser_dev *l = calloc(1, sizeof *l);
	if (!l)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	l->cfg = cfg;
	l->fd = -1;
	l->io = pick_io(cfg);
	bool opened = false;
	if (l->io->open(l, err))
		goto fail;
	opened = true;
	if (exchange(l, "ID?", err))
		goto fail;
	if (parse_id(l, err))
		goto fail;
	if (expect_ok(l, "EMISSION OFF", err))
		goto fail;
	if (cfg->keepalive_ms) {
		char cmd[32];
		snprintf(cmd, sizeof cmd, "KEEPALIVE %d", cfg->keepalive_ms);
		if (expect_ok(l, cmd, err)) {
			if (err) /* the laser and the command first, as every error of this driver */
				snprintf(err->msg + strlen(err->msg), sizeof err->msg - strlen(err->msg),
					 " (arming the keep-alive; devices.laser.keepalive_ms: 0 runs without it)");
			goto fail;
		}
	}
	*out = l;
	return 0;
fail:
	if (opened)
		fail_safe(l);
	l->io->close(l);
	free(l);
	return -1;
}

static void ls_close(struct laser_dev *l)
{
	if (!l)
		return;
	fail_safe(l);
	l->io->close(l);
	free(l);
}

static int ls_set_emission(struct laser_dev *l, bool on, struct acq_err *err)
{
	if (expect_ok(l, on ? "EMISSION ON" : "EMISSION OFF", err))
		return fail_safe(l);
	return 0;
}

static int ls_set_power(struct laser_dev *l, double pct, struct acq_err *err)
{
	if (!isfinite(pct) || pct < 0 || pct > l->cfg->max_power_pct) {
		acq_errf(err, ACQ_E_RANGE, "laser %s: power %g%% outside [0, %g]", l->cfg->device, pct,
			 l->cfg->max_power_pct);
		return fail_safe(l);
	}
	char cmd[64];
	snprintf(cmd, sizeof cmd, "POWER %.2f", pct);
	if (expect_ok(l, cmd, err))
		return fail_safe(l);
	return 0;
}

/* "STATUS emission=<0|1> interlock=<0|1> fault=<N>" in l->line into st (each number decimal, in range: a
 * number past int's range is refused, not wrapped). 0 or -1. */
static int parse_status(struct laser_dev *l, struct laser_status *st, struct acq_err *err)
{
	static const char form[] = "STATUS emission=0|1 interlock=0|1 fault=N";
	static const struct { const char *key; long max; } f[] = { { "emission", 1 }, { "interlock", 1 },
								      { "fault", INT_MAX } };
	long v[3];
	if (strncmp(l->line, "STATUS ", 7))
		return reply_errf(l, err, "STATUS?", form, "not a status");
	const char *p = l->line + 7;
	for (int k = 0; k < 3; k++) {
		size_t kl = strlen(f[k].key);
		if (strncmp(p, f[k].key, kl) || p[kl] != '=')
			return reply_errf(l, err, "STATUS?", form, "'%s=' expected at column %d", f[k].key,
					  (int)(p - l->line) + 1);
		p += kl + 1;
		const char *num = p;
		if (dec_long(&p, f[k].max, &v[k]))
			return reply_errf(l, err, "STATUS?", form, "%s='%.*s' is not %s", f[k].key,
					  (int)strcspn(num, " "), num, f[k].max == 1 ? "0 or 1" : "a number 0..2147483647");
		if (k < 2 && !*p)
			return reply_errf(l, err, "STATUS?", form, "no '%s=' after %s=%ld", f[k + 1].key, f[k].key, v[k]);
		if (*p != (k < 2 ? ' ' : '\0'))
			return reply_errf(l, err, "STATUS?", form, "unexpected '%s' after %s=%ld", p, f[k].key, v[k]);
		if (k < 2)
			p++;
	}
	st->emission = v[0];
	st->interlock_ok = v[1];
	st->fault = v[2] != 0;
	st->fault_code = (int)v[2];
	return 0;
}

/* "POWER <pct>" in l->line: a decimal number (digits first: no sign, space, hex, inf or nan) in [0, 100]. 0 or -1. */
static int parse_power(struct laser_dev *l, double *pct, struct acq_err *err)
{
	static const char form[] = "POWER <0..100>";
	if (strncmp(l->line, "POWER ", 6))
		return reply_errf(l, err, "POWER?", form, "not a power");
	const char *num = l->line + 6;
	if (*num < '0' || *num > '9' || strpbrk(num, "xX") || acq_num_parse(num, 0, 100, pct))
		return reply_errf(l, err, "POWER?", form, "power '%s' is not a number in [0, 100]", num);
	return 0;
}

static int ls_status(struct laser_dev *l, struct laser_status *st, struct acq_err *err)
{
	memset(st, 0, sizeof *st);
	if (exchange(l, "STATUS?", err))
		return fail_safe(l);
	if (parse_status(l, st, err))
		return fail_safe(l);
	if (exchange(l, "POWER?", err) || parse_power(l, &st->power_pct, err))
		return fail_safe(l);
	return 0;
}

static int ls_keepalive(struct laser_dev *l, struct acq_err *err)
{
	if (!l->cfg->keepalive_ms)
		return 0;
	if (expect_ok(l, "KEEPALIVE", err))
		return fail_safe(l);
	return 0;
}

static const struct laser_identity *ls_identity(const struct laser_dev *l)
{
	return &l->id;
}

const struct laser_backend laser_serial_backend = {
	.name = "serial", .open = ls_open, .close = ls_close, .set_emission = ls_set_emission,
	.set_power = ls_set_power, .status = ls_status, .identity = ls_identity, .keepalive = ls_keepalive,
};

const struct laser_backend *laser_cfg_backend(const struct laser_cfg *cfg)
{
	return cfg->backend == 1 ? &laser_fake_backend : &laser_serial_backend;
}

int laser_cfg_keepalive_ms(const struct laser_cfg *cfg)
{
	return cfg->keepalive_ms;
}

double laser_cfg_max_power(const struct laser_cfg *cfg)
{
	return cfg->max_power_pct;
}
