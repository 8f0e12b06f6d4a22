/* spectro_sim: the "sim" spectrometer backend: talks to acq-sim's spectrometer over a Unix socket
 * (protocol in drivers/spectro_sim_proto.h), without blocking the caller's loop once open.
 *
 * Config (`devices.spectrometer`):
 *   backend: sim
 *   socket: PATH                 the acq-sim spectrometer socket, or
 *   ports_file: PATH             acq-sim's --ports-file (JSON); the socket is read from "spectrometer.socket"
 *                                at open time. At most one of socket / ports_file; with neither, the ports
 *                                file named by the environment variable ACQ_SIM_PORTS is used at open time
 *                                (so `acquisitiond --sim PORTS.json` can point every sim backend at one run)
 *   timeout_margin_ms: 2000      added to integration x averages (+ read-out) for the fetch deadline
 *   open_timeout_ms: 2000        how long open waits for the banner and the identity
 *   nonlinearity_correction: true  linearise counts with the device's coefficients (frame.nonlin_applied)
 * Counts are linearised per pixel as x = raw / P(raw) (P the device's 8 coefficients); the standard deviation
 * follows through the derivative. Dark pixels are reported (dark_pixel_level) but not subtracted. */
#include <errno.h>
#include <math.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include <jansson.h>

#include "drivers/spectro_backend.h"
#include "drivers/spectro_sim_proto.h"

#define BUF_MAX (SSP_HDR + SSP_SPECTRUM_LEN(SPECTRO_MAX_PIXELS))

struct sim_cfg {
	char socket[108];
	char ports_file[4096];
	double margin_ms, open_ms;
	bool linearise;
};

struct sim_dev {
	const struct sim_cfg *cfg;
	int fd;
	uint32_t seq, pending_seq;
	bool pending, gone;
	double deadline, started;
	double started_real;     /* mono(): the margin also runs in real time (see ss_fetch) */
	struct spectro_meas meas;
	struct spectro_info info;
	double temperature;
	unsigned char *buf;
	size_t nbuf;
};

static int ss_cfg_parse(struct yc_node *node, void **state, struct acq_err *err)
{
	*state = NULL;
	struct sim_cfg *c = calloc(1, sizeof *c);
	if (!c)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	c->margin_ms = 2000;
	c->open_ms = 2000;
	c->linearise = true;
	const char *sock = NULL, *ports = NULL;
	if (yc_string(node, "socket", false, &sock, err) || yc_string(node, "ports_file", false, &ports, err) ||
	    yc_double(node, "timeout_margin_ms", false, 0, 3.6e6, &c->margin_ms, err) ||
	    yc_double(node, "open_timeout_ms", false, 1, 3.6e6, &c->open_ms, err) ||
	    yc_bool(node, "nonlinearity_correction", false, &c->linearise, err))
		goto fail;
	if (sock && ports) {
		yc_errf(err, node, "spectrometer backend 'sim': give one of `socket: PATH` or `ports_file: PATH`, not both");
		goto fail;
	}
	if (sock && strlen(sock) >= sizeof c->socket) {
		yc_errf(err, yc_get(node, "socket"), "socket path longer than %zu bytes", sizeof c->socket - 1);
		goto fail;
	}
	if (ports && strlen(ports) >= sizeof c->ports_file) {
		yc_errf(err, yc_get(node, "ports_file"), "ports file path too long");
		goto fail;
	}
	snprintf(c->socket, sizeof c->socket, "%s", sock ? sock : "");
	snprintf(c->ports_file, sizeof c->ports_file, "%s", ports ? ports : "");
	*state = c;
	return 0;
fail:
	free(c);
	return -1;
}

static void ss_cfg_free(void *state)
{
	free(state);
}

static double mono(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static int socket_from_ports(const char *file, char *out, size_t len, struct acq_err *err)
{
	json_error_t je;
	json_t *root = json_load_file(file, 0, &je);
	if (!root)
		return acq_errf(err, ACQ_E_CONFIG, "spectrometer 'sim': ports file %s:%d: %s", file, je.line, je.text);
	json_t *sock = json_object_get(json_object_get(root, "spectrometer"), "socket");
	int rc = 0;
	if (!json_is_string(sock))
		rc = acq_errf(err, ACQ_E_CONFIG, "spectrometer 'sim': ports file %s has no \"spectrometer\": {\"socket\": PATH} "
			      "(is the simulated spectrometer enabled?)", file);
	else if (strlen(json_string_value(sock)) >= len)
		rc = acq_errf(err, ACQ_E_CONFIG, "spectrometer 'sim': socket path in %s too long", file);
	else
		snprintf(out, len, "%s", json_string_value(sock));
	json_decref(root);
	return rc;
}

/* Read from the socket into the buffer without blocking; on end of file or error mark the device gone (what
 * was received before is still parsed by the caller). */
static void pump(struct sim_dev *d)
{
	while (!d->gone && d->nbuf < BUF_MAX) {
		ssize_t n = recv(d->fd, d->buf + d->nbuf, BUF_MAX - d->nbuf, MSG_DONTWAIT);
		if (n > 0) {
			d->nbuf += (size_t)n;
			continue;
		}
		if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR))
			return;
		d->gone = true;
	}
}

static int gone_error(struct acq_err *err)
{
	return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer 'sim': connection closed by acq-sim (device gone)");
}

/* A complete message at the head of the buffer? 1 (type, seq, payload, len set), 0 not yet, -1 malformed. */
static int next_msg(struct sim_dev *d, unsigned *type, uint32_t *seq, const unsigned char **payload, uint32_t *len,
		    struct acq_err *err)
{
	if (d->nbuf < SSP_HDR)
		return 0;
	if (ssp_get32(d->buf) != SSP_MAGIC)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': bad magic 0x%08x (not the acq-sim protocol)",
				ssp_get32(d->buf));
	if (ssp_get16(d->buf + 4) != SSP_VERSION)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': protocol version %u, expected %d", ssp_get16(d->buf + 4),
				SSP_VERSION);
	*len = ssp_get32(d->buf + 12);
	if (*len > BUF_MAX - SSP_HDR)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': message of %u bytes exceeds the %u-byte limit", *len,
				(unsigned)(BUF_MAX - SSP_HDR));
	if (d->nbuf < SSP_HDR + *len)
		return 0;
	*type = ssp_get16(d->buf + 6);
	*seq = ssp_get32(d->buf + 8);
	*payload = d->buf + SSP_HDR;
	return 1;
}

static void consume(struct sim_dev *d, uint32_t len)
{
	size_t n = SSP_HDR + len;
	memmove(d->buf, d->buf + n, d->nbuf - n);
	d->nbuf -= n;
}

static int error_reply(const unsigned char *p, uint32_t len, struct acq_err *err)
{
	if (len < 8)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': error reply of %u bytes (< 8)", len);
	char msg[257];
	uint32_t ml = len - 8 > 256 ? 256 : len - 8;
	memcpy(msg, p + 8, ml);
	msg[ml] = 0;
	for (uint32_t i = 0; i < ml; i++)
		if ((unsigned char)msg[i] < 32)
			msg[i] = '?';
	acq_errf(err, ACQ_E_DEVICE, "spectrometer 'sim': device error %u: %s", ssp_get32(p), msg);
	err->detail = (int)ssp_get32(p);
	return -1;
}

static int send_msg(struct sim_dev *d, unsigned type, const unsigned char *payload, uint32_t len, struct acq_err *err)
{
	unsigned char b[SSP_HDR + 64];
	if (len > 64)
		return acq_errf(err, ACQ_E_INVAL, "spectrometer 'sim': request too long");
	ssp_header(b, type, ++d->seq, len);
	if (len)
		memcpy(b + SSP_HDR, payload, len);
	ssize_t n = send(d->fd, b, SSP_HDR + len, MSG_NOSIGNAL | MSG_DONTWAIT);
	if (n != (ssize_t)(SSP_HDR + len)) {
		d->gone = n < 0 && errno != EAGAIN && errno != EWOULDBLOCK;
		return acq_errf(err, d->gone ? ACQ_E_DISCONNECTED : ACQ_E_IO, "spectrometer 'sim': cannot send request: %s",
				n < 0 ? strerror(errno) : "short write");
	}
	return 0;
}

/* Block (open only) until a message of type want arrives; skips nothing else. */
static int wait_msg(struct sim_dev *d, unsigned want, double deadline, const unsigned char **p, uint32_t *len,
		    struct acq_err *err)
{
	for (;;) {
		unsigned type;
		uint32_t seq;
		int r = next_msg(d, &type, &seq, p, len, err);
		if (r < 0)
			return -1;
		if (r > 0) {
			if (type == SSP_ERROR)
				return error_reply(*p, *len, err);
			if (type != want)
				return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': expected message 0x%02x, got 0x%02x", want, type);
			return 0;
		}
		if (d->gone)
			return gone_error(err);
		double left = deadline - mono();
		if (left <= 0)
			return acq_errf(err, ACQ_E_TIMEOUT, "spectrometer 'sim': no answer within %.0f ms", d->cfg->open_ms);
		struct pollfd pfd = { .fd = d->fd, .events = POLLIN };
		int pr = poll(&pfd, 1, (int)ceil(left * 1000));
		if (pr < 0 && errno != EINTR)
			return acq_errf(err, ACQ_E_IO, "spectrometer 'sim': poll: %s", strerror(errno));
		if (pr > 0)
			pump(d);
	}
}

static void getstr(char *dst, size_t len, const unsigned char *src)
{
	size_t n = strnlen((const char *)src, 32);
	if (n >= len)
		n = len - 1;
	memcpy(dst, src, n);
	dst[n] = 0;
	for (size_t i = 0; i < n; i++)
		if ((unsigned char)dst[i] < 32 || (unsigned char)dst[i] > 126)
			dst[i] = '?';
}

int ssp_parse_identity(const unsigned char *p, uint32_t len, struct spectro_info *in, double *temperature,
		       struct acq_err *err)
{
	if (len != SSP_IDENTITY_LEN)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': identity of %u bytes, expected %d", len, SSP_IDENTITY_LEN);
	memset(in, 0, sizeof *in);
	getstr(in->model, sizeof in->model, p);
	getstr(in->serial, sizeof in->serial, p + 32);
	getstr(in->firmware, sizeof in->firmware, p + 64);
	uint32_t npix = ssp_get32(p + 96), ndark = ssp_get32(p + 140);
	if (npix < 1 || npix > SPECTRO_MAX_PIXELS)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': %u pixels (supported: 1..%d)", npix, SPECTRO_MAX_PIXELS);
	if (ndark > 8)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': %u dark pixels (max 8)", ndark);
	in->npix = (int)npix;
	for (int i = 0; i < 5; i++)
		in->wl_coef[i] = ssp_getd(p + 100 + 8 * i);
	in->ndark_pixels = (int)ndark;
	for (uint32_t i = 0; i < ndark; i++) {
		uint32_t px = ssp_get32(p + 144 + 4 * i);
		if (px >= npix)
			return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': dark pixel %u outside 0..%u", px, npix - 1);
		in->dark_pixels[i] = (int)px;
	}
	in->max_counts = ssp_getd(p + 176);
	in->nonlin_enabled = ssp_get32(p + 184) != 0;
	for (int i = 0; i < 8; i++)
		in->nonlin_coef[i] = ssp_getd(p + 192 + 8 * i);
	in->nonlin_low = ssp_getd(p + 256);
	in->nonlin_high = ssp_getd(p + 264);
	*temperature = ssp_getd(p + 272);
	for (int i = 0; i < 5; i++)
		if (!isfinite(in->wl_coef[i]))
			return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': wavelength coefficient %d not finite", i);
	if (!(in->max_counts > 0 && in->max_counts < 1e9))
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': full scale %g out of range", in->max_counts);
	bool any = false;
	for (int i = 0; i < 8; i++) {
		if (!isfinite(in->nonlin_coef[i]))
			return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': nonlinearity coefficient %d not finite", i);
		any |= in->nonlin_coef[i] != 0;
	}
	if (in->nonlin_enabled && !any)
		in->nonlin_enabled = false; /* all-zero coefficients would divide by zero: treat as disabled */
	return 0;
}

static void ss_close(void *dev)
{
	struct sim_dev *d = dev;
	if (!d)
		return;
	if (d->fd >= 0)
		close(d->fd);
	free(d->buf);
	free(d);
}

static int ss_open(const void *state, void **dev, struct spectro_info *info, struct acq_err *err)
{
	const struct sim_cfg *c = state;
	*dev = NULL;
	char path[108];
	const char *env = getenv("ACQ_SIM_PORTS");
	if (c->socket[0]) {
		snprintf(path, sizeof path, "%s", c->socket);
	} else if (c->ports_file[0] || (env && env[0])) {
		if (socket_from_ports(c->ports_file[0] ? c->ports_file : env, path, sizeof path, err))
			return -1;
	} else {
		return acq_errf(err, ACQ_E_CONFIG, "spectrometer backend 'sim': no socket: set devices.spectrometer.socket "
				"or .ports_file, or the environment variable ACQ_SIM_PORTS (acq-sim's --ports-file)");
	}
	struct sim_dev *d = calloc(1, sizeof *d);
	if (!d || !(d->buf = malloc(BUF_MAX))) {
		free(d);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	d->cfg = c;
	d->temperature = NAN;
	d->fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	snprintf(a.sun_path, sizeof a.sun_path, "%s", path);
	const unsigned char *p;
	uint32_t len;
	double deadline = mono() + c->open_ms * 1e-3;
	if (d->fd < 0 || connect(d->fd, (struct sockaddr *)&a, sizeof a)) {
		acq_errf(err, ACQ_E_NOTFOUND, "spectrometer 'sim': cannot connect to %s: %s", path, strerror(errno));
		goto fail;
	}
	if (wait_msg(d, SSP_HELLO, deadline, &p, &len, err))
		goto fail;
	if (len < 4 || ssp_get32(p) != SSP_VERSION) {
		acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': server speaks protocol %u, expected %d", len >= 4 ? ssp_get32(p) : 0,
			 SSP_VERSION);
		goto fail;
	}
	consume(d, len);
	if (send_msg(d, SSP_IDENTIFY, NULL, 0, err) || wait_msg(d, SSP_IDENTITY, deadline, &p, &len, err) ||
	    ssp_parse_identity(p, len, &d->info, &d->temperature, err))
		goto fail;
	consume(d, len);
	*info = d->info;
	*dev = d;
	return 0;
fail:
	acq_err_prefix(err, "%s: ", path);
	ss_close(d);
	return -1;
}

static int ss_start(void *dev, const struct spectro_meas *m, double now, struct acq_err *err)
{
	struct sim_dev *d = dev;
	if (d->gone)
		return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer 'sim': device gone (close and open it again)");
	if (d->pending)
		return acq_errf(err, ACQ_E_STATE, "spectrometer 'sim': a measurement is already running");
	if (!(m->integration_ms > 0 && m->integration_ms <= 600000) || m->averages < 1 || m->averages > 100000)
		return acq_errf(err, ACQ_E_RANGE, "spectrometer 'sim': integration %g ms must be in (0, 600000], averages %u in "
				"[1, 100000]", m->integration_ms, m->averages);
	unsigned char pl[SSP_MEASURE_LEN];
	ssp_putd(pl, m->integration_ms);
	ssp_put32(pl + 8, m->averages);
	ssp_put32(pl + 12, m->saturation_detection ? 1 : 0);
	if (send_msg(d, SSP_MEASURE, pl, sizeof pl, err))
		return -1;
	d->pending = true;
	d->pending_seq = d->seq;
	d->meas = *m;
	d->started = now;
	d->started_real = mono();
	d->deadline = now + m->integration_ms * 1e-3 * m->averages + 0.01 * m->averages + d->cfg->margin_ms * 1e-3;
	return 0;
}

static double poly(const double *c, int n, double x)
{
	double v = 0;
	for (int i = n - 1; i >= 0; i--)
		v = v * x + c[i];
	return v;
}

int ssp_parse_spectrum(const unsigned char *p, uint32_t len, const struct spectro_info *in, bool linearise,
		       struct spectro_frame *f, struct acq_err *err)
{
	if (len < SSP_SPECTRUM_FIXED)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': spectrum of %u bytes (< %d)", len, SSP_SPECTRUM_FIXED);
	uint32_t npix = ssp_get32(p + 28), nsat = ssp_get32(p + 32);
	if ((int)npix != in->npix || npix > SPECTRO_MAX_PIXELS)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': spectrum of %u pixels, the device has %d", npix, in->npix);
	if (len != SSP_SPECTRUM_LEN(npix))
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': spectrum of %u bytes, expected %u for %u pixels", len,
				SSP_SPECTRUM_LEN(npix), npix);
	const unsigned char *pc = p + SSP_SPECTRUM_FIXED, *ps = pc + 8 * npix, *pf = ps + 4 * npix;
	int count = 0;
	bool lin = linearise && in->nonlin_enabled;
	for (uint32_t i = 0; i < npix; i++) {
		double x = ssp_getd(pc + 8 * i);
		double s = ssp_getf(ps + 4 * i);
		if (!isfinite(x) || x < 0 || x > in->max_counts || !isfinite(s) || s < 0)
			return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': pixel %u: counts %g / std %g out of range", i, x, s);
		if (pf[i] > 1)
			return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': pixel %u: saturation flag %u", i, pf[i]);
		if (lin) {
			double pv = poly(in->nonlin_coef, 8, x);
			double dp = 0;
			for (int k = 7; k >= 1; k--)
				dp = dp * x + k * in->nonlin_coef[k];
			if (pv > 1e-3 && isfinite(pv)) {
				double slope = (pv - x * dp) / (pv * pv);
				x /= pv;
				s *= fabs(slope);
			}
		}
		f->counts[i] = x;
		f->stddev[i] = (float)s;
		f->saturated[i] = pf[i];
		count += pf[i];
	}
	if ((uint32_t)count != nsat)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': %u saturated pixels announced, %d flagged", nsat, count);
	f->npix = (int)npix;
	f->nsaturated = count;
	f->device_time_s = ssp_getd(p);
	f->temperature_c = ssp_getd(p + 8);
	f->nonlin_applied = lin;
	f->dark_pixel_corrected = false;
	double dl = 0;
	for (int i = 0; i < in->ndark_pixels; i++)
		dl += f->counts[in->dark_pixels[i]];
	f->dark_pixel_level = in->ndark_pixels ? dl / in->ndark_pixels : NAN;
	if (!isfinite(f->device_time_s) || !isfinite(f->temperature_c) || f->temperature_c < -100 || f->temperature_c > 200)
		return acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': device time %g s / temperature %g C out of range",
				f->device_time_s, f->temperature_c);
	return 0;
}

static int ss_fetch(void *dev, struct spectro_frame *frame, double now, struct acq_err *err)
{
	struct sim_dev *d = dev;
	if (!d->pending)
		return acq_errf(err, ACQ_E_STATE, "spectrometer 'sim': no measurement running");
	pump(d);
	for (;;) {
		unsigned type;
		uint32_t seq, len;
		const unsigned char *p;
		int r = next_msg(d, &type, &seq, &p, &len, err);
		if (r < 0) {
			d->pending = false;
			d->gone = true; /* framing lost: the connection cannot be trusted any more */
			return -1;
		}
		if (r == 0)
			break;
		if (seq != d->pending_seq) { /* a late answer to a stopped request: stale, drop it */
			consume(d, len);
			continue;
		}
		int rc;
		if (type == SSP_SPECTRUM) {
			rc = ssp_parse_spectrum(p, len, &d->info, d->cfg->linearise, frame, err) ? -1 : 1;
			if (rc == 1) {
				frame->meas = d->meas;
				d->temperature = frame->temperature_c;
			}
		}
		else if (type == SSP_ERROR)
			rc = error_reply(p, len, err);
		else
			rc = acq_errf(err, ACQ_E_PROTO, "spectrometer 'sim': unexpected message 0x%02x to a measurement", type);
		consume(d, len);
		d->pending = false;
		return rc;
	}
	if (d->gone) {
		d->pending = false;
		return acq_errf(err, ACQ_E_DISCONNECTED, "spectrometer 'sim': connection closed by acq-sim during the "
				"measurement (device gone; close and open it again)");
	}
	/* The exposure runs on the caller's clock (the simulated bench's, faster than real time when scaled), but the
	 * margin stands for transport and the simulator's computing, which take real time: at time scale 10 a
	 * 2000 ms margin was 0.2 s real, and a loaded machine then timed out spectra on their way (soak). */
	if (now > d->deadline && mono() - d->started_real > d->cfg->margin_ms * 1e-3) {
		d->pending = false;
		struct acq_err ignored = { 0 };
		if (send_msg(d, SSP_STOP, NULL, 0, &ignored)) {
			/* best effort: the device may be stuck; the late answer is dropped by its sequence number */
		}
		return acq_errf(err, ACQ_E_TIMEOUT, "spectrometer 'sim': no spectrum within %.3f s (integration %g ms x %u)",
				d->deadline - d->started, d->meas.integration_ms, d->meas.averages);
	}
	return 0;
}

static int ss_stop(void *dev, struct acq_err *err)
{
	struct sim_dev *d = dev;
	if (!d->pending)
		return 0;
	d->pending = false;
	if (d->gone)
		return 0;
	return send_msg(d, SSP_STOP, NULL, 0, err);
}

static int ss_pollfd(const void *dev)
{
	const struct sim_dev *d = dev;
	return d->fd;
}

const struct spectro_backend spectro_sim_backend = {
	.name = "sim",
	.cfg_parse = ss_cfg_parse,
	.cfg_free = ss_cfg_free,
	.open = ss_open,
	.close = ss_close,
	.start = ss_start,
	.fetch = ss_fetch,
	.stop = ss_stop,
	.pollfd = ss_pollfd,
};
