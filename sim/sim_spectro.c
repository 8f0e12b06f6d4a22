/* sim_spectro: acq-sim's spectrometer service: a Unix socket speaking drivers/spectro_sim_proto.h, counts
 * from sim/sim_physics.c at the arms' actual positions when each exposure ends (bench time).
 *
 * Config: devices.spectrometer.socket (the path to listen on; default /tmp/acq-sim.<pid>.spectro.sock),
 * sim.sample (green-paint | white | metal | none, default white), sim.spectrometer (sim_physics.h keys).
 * Faults consumed: spectro_disconnect (close the client half way through the next exposure),
 * spectro_offline_until (refuse connections until then), saturation_burst (next N spectra x 1000 signal). */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "drivers/spectro_sim_proto.h"
#include "sim/sim.h"
#include "sim/sim_physics.h"

#define IN_MAX 256

struct spectro_svc {
	struct sim_service svc;  /* what the constructor returns; freed with the rest by svc_destroy */
	struct sim_world *w;
	struct phys *phys;
	struct sim_rng rng;
	char path[108];
	int lfd, cfd;
	unsigned char in[IN_MAX];
	size_t nin;
	unsigned char *out;
	size_t nout, capout;
	bool closing;            /* close once the output is flushed */
	/* the running exposure */
	bool pending;
	double start_at, done_at, integration_ms;
	unsigned averages;
	uint32_t seq;
	struct phys_frame frame;
	unsigned char *msg;      /* reply buffer */
};

static void drop_client(struct spectro_svc *s)
{
	if (s->cfd >= 0)
		close(s->cfd);
	s->cfd = -1;
	s->nin = s->nout = 0;
	s->pending = false;
	s->closing = false;
}

static int queue(struct spectro_svc *s, const unsigned char *p, size_t n)
{
	if (s->nout + n > s->capout) {
		size_t cap = s->capout ? s->capout : 4096;
		while (cap < s->nout + n)
			cap *= 2;
		unsigned char *b = realloc(s->out, cap);
		if (!b)
			return -1;
		s->out = b;
		s->capout = cap;
	}
	memcpy(s->out + s->nout, p, n);
	s->nout += n;
	return 0;
}

static void queue_error(struct spectro_svc *s, uint32_t code, unsigned reqtype, uint32_t seq, const char *msg)
{
	unsigned char b[SSP_HDR + 8 + 256];
	size_t ml = strlen(msg);
	if (ml > 256)
		ml = 256;
	ssp_header(b, SSP_ERROR, seq, (uint32_t)(8 + ml));
	ssp_put32(b + SSP_HDR, code);
	ssp_put32(b + SSP_HDR + 4, reqtype);
	memcpy(b + SSP_HDR + 8, msg, ml);
	if (queue(s, b, SSP_HDR + 8 + ml))
		drop_client(s);
}

static void flush(struct spectro_svc *s)
{
	while (s->cfd >= 0 && s->nout > 0) {
		ssize_t n = send(s->cfd, s->out, s->nout, MSG_NOSIGNAL | MSG_DONTWAIT);
		if (n < 0) {
			if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)
				return;
			drop_client(s);
			return;
		}
		memmove(s->out, s->out + n, s->nout - (size_t)n);
		s->nout -= (size_t)n;
	}
	if (s->cfd >= 0 && s->nout == 0 && s->closing)
		drop_client(s);
}

static void send_identity(struct spectro_svc *s, uint32_t seq)
{
	const struct phys_cfg *c = phys_config(s->phys);
	unsigned char b[SSP_HDR + SSP_IDENTITY_LEN] = { 0 }, *p = b + SSP_HDR;
	ssp_header(b, SSP_IDENTITY, seq, SSP_IDENTITY_LEN);
	memcpy(p, c->model, strnlen(c->model, 31));
	memcpy(p + 32, c->serial, strnlen(c->serial, 31));
	memcpy(p + 64, c->firmware, strnlen(c->firmware, 31));
	ssp_put32(p + 96, (uint32_t)c->npix);
	for (int i = 0; i < 5; i++)
		ssp_putd(p + 100 + 8 * i, c->wl_coef[i]);
	ssp_put32(p + 140, PHYS_NDARK);
	for (int i = 0; i < PHYS_NDARK; i++)
		ssp_put32(p + 144 + 4 * i, (uint32_t)i);
	ssp_putd(p + 176, PHYS_FULL_SCALE);
	ssp_put32(p + 184, 1);
	double nl[8];
	phys_nonlin_coef(c, nl);
	for (int i = 0; i < 8; i++)
		ssp_putd(p + 192 + 8 * i, nl[i]);
	ssp_putd(p + 256, 0.0);
	ssp_putd(p + 264, PHYS_FULL_SCALE);
	ssp_putd(p + 272, s->w->sensor_temp_c);
	if (queue(s, b, sizeof b))
		drop_client(s);
}

static void handle_request(struct spectro_svc *s, unsigned type, uint32_t seq, const unsigned char *p, uint32_t len,
			   double now)
{
	switch (type) {
	case SSP_IDENTIFY:
		send_identity(s, seq);
		return;
	case SSP_MEASURE: {
		if (len != SSP_MEASURE_LEN) {
			queue_error(s, SSP_E_BADREQ, type, seq, "MEASURE: payload must be 16 bytes");
			return;
		}
		double it = ssp_getd(p);
		uint32_t av = ssp_get32(p + 8);
		if (!(it > 0 && it <= 600000.0) || av < 1 || av > 100000) {
			char m[160];
			snprintf(m, sizeof m, "MEASURE: integration %g ms must be in (0, 600000] and averages %u in [1, 100000]",
				 it, av);
			queue_error(s, SSP_E_BADREQ, type, seq, m);
			return;
		}
		if (s->pending) {
			queue_error(s, SSP_E_PENDING, type, seq, "MEASURE: a measurement is pending");
			return;
		}
		s->pending = true;
		s->start_at = now;
		s->integration_ms = it;
		s->averages = av;
		s->seq = seq;
		s->done_at = now + it * 1e-3 * av + s->w->geom.readout_s;
		return;
	}
	case SSP_STOP: {
		s->pending = false;
		unsigned char b[SSP_HDR];
		ssp_header(b, SSP_STOPPED, seq, 0);
		if (queue(s, b, sizeof b))
			drop_client(s);
		return;
	}
	default: {
		char m[64];
		snprintf(m, sizeof m, "unknown request type 0x%02x", type);
		queue_error(s, SSP_E_UNKNOWN, type, seq, m);
	}
	}
}

static void read_client(struct spectro_svc *s, double now)
{
	for (;;) {
		ssize_t n = recv(s->cfd, s->in + s->nin, IN_MAX - s->nin, MSG_DONTWAIT);
		if (n == 0) {
			drop_client(s);
			return;
		}
		if (n < 0) {
			if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)
				drop_client(s);
			return;
		}
		s->nin += (size_t)n;
		while (s->cfd >= 0 && !s->closing && s->nin >= SSP_HDR) {
			uint32_t magic = ssp_get32(s->in), len = ssp_get32(s->in + 12), seq = ssp_get32(s->in + 8);
			unsigned ver = ssp_get16(s->in + 4), type = ssp_get16(s->in + 6);
			if (magic != SSP_MAGIC || ver != SSP_VERSION || len > IN_MAX - SSP_HDR) {
				queue_error(s, magic != SSP_MAGIC ? SSP_E_BADREQ : ver != SSP_VERSION ? SSP_E_VERSION : SSP_E_BADREQ,
					    type, seq,
					    magic != SSP_MAGIC ? "bad magic: not the acq-sim spectrometer protocol" :
					    ver != SSP_VERSION ? "unsupported protocol version (server speaks 1)" :
								 "request too long");
				s->closing = true;
				return;
			}
			if (s->nin < SSP_HDR + len)
				break;
			handle_request(s, type, seq, s->in + SSP_HDR, len, now);
			if (s->cfd < 0)
				return;
			memmove(s->in, s->in + SSP_HDR + len, s->nin - SSP_HDR - len);
			s->nin -= SSP_HDR + len;
		}
	}
}

static void accept_client(struct spectro_svc *s, double now)
{
	int fd = accept4(s->lfd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
	if (fd < 0)
		return;
	unsigned char b[SSP_HDR + 8 + 64];
	if (now < s->w->spectro_offline_until) {
		close(fd); /* the device is gone: the connection is refused */
		return;
	}
	if (s->cfd >= 0) {
		const char *m = "busy: another client holds the spectrometer";
		size_t ml = strlen(m);
		ssp_header(b, SSP_ERROR, 0, (uint32_t)(8 + ml));
		ssp_put32(b + SSP_HDR, SSP_E_BUSY);
		ssp_put32(b + SSP_HDR + 4, 0);
		memcpy(b + SSP_HDR + 8, m, ml);
		if (send(fd, b, SSP_HDR + 8 + ml, MSG_NOSIGNAL | MSG_DONTWAIT) < 0) {
			/* nothing to do: the client is closed either way */
		}
		close(fd);
		return;
	}
	s->cfd = fd;
	s->nin = s->nout = 0;
	s->closing = false;
	s->pending = false;
	memset(b, 0, sizeof b);
	ssp_header(b, SSP_HELLO, 0, SSP_HELLO_LEN);
	ssp_put32(b + SSP_HDR, SSP_VERSION);
	memcpy(b + SSP_HDR + 4, "acq-sim spectrometer", 20);
	if (queue(s, b, SSP_HDR + SSP_HELLO_LEN))
		drop_client(s);
}

static int svc_pollfds(void *self, struct pollfd *fds, int max)
{
	struct spectro_svc *s = self;
	int n = 0;
	if (max < 2)
		return 0;
	fds[n++] = (struct pollfd){ .fd = s->lfd, .events = POLLIN };
	fds[n++] = (struct pollfd){ .fd = s->cfd, .events = (short)(POLLIN | (s->nout ? POLLOUT : 0)) };
	return n;
}

static void svc_handle(void *self, const struct pollfd *fds, int n, double now)
{
	struct spectro_svc *s = self;
	if (n < 2)
		return;
	if (fds[1].fd >= 0 && fds[1].fd == s->cfd && (fds[1].revents & (POLLIN | POLLHUP | POLLERR)))
		read_client(s, now);
	if (s->cfd >= 0 && fds[1].fd == s->cfd && (fds[1].revents & POLLOUT))
		flush(s);
	if (fds[0].revents & POLLIN)
		accept_client(s, now);
}

static void finish_exposure(struct spectro_svc *s, double now)
{
	struct sim_world *w = s->w;
	struct acq_err err = { 0 };
	double boost = 1.0;
	if (w->faults.saturation_burst > 0) {
		w->faults.saturation_burst--;
		boost = 1000.0;
	}
	s->pending = false;
	phys_set_time(s->phys, now);
	if (phys_measure(s->phys, w, s->integration_ms, s->averages, boost, &s->rng, &s->frame, &err)) {
		queue_error(s, SSP_E_BADREQ, SSP_MEASURE, s->seq, err.msg);
		return;
	}
	const struct phys_frame *f = &s->frame;
	uint32_t len = SSP_SPECTRUM_LEN(f->npix);
	unsigned char *b = s->msg, *p = b + SSP_HDR;
	ssp_header(b, SSP_SPECTRUM, s->seq, len);
	ssp_putd(p, now);
	ssp_putd(p + 8, w->sensor_temp_c + 0.02 * sim_rng_gauss(&s->rng));
	ssp_putd(p + 16, s->integration_ms);
	ssp_put32(p + 24, s->averages);
	ssp_put32(p + 28, (uint32_t)f->npix);
	ssp_put32(p + 32, (uint32_t)f->nsat);
	ssp_put32(p + 36, f->occlusion);
	ssp_put32(p + 40, 0);
	ssp_put32(p + 44, 0);
	unsigned char *q = p + SSP_SPECTRUM_FIXED;
	for (int i = 0; i < f->npix; i++)
		ssp_putd(q + 8 * i, f->counts[i]);
	q += 8 * f->npix;
	for (int i = 0; i < f->npix; i++)
		ssp_putf(q + 4 * i, f->std[i]);
	q += 4 * f->npix;
	memcpy(q, f->sat, (size_t)f->npix);
	if (queue(s, b, SSP_HDR + len))
		drop_client(s);
	else
		flush(s);
}

static void svc_tick(void *self, double now)
{
	struct spectro_svc *s = self;
	if (s->cfd >= 0 && s->pending) {
		if (s->w->faults.spectro_disconnect && now >= 0.5 * (s->start_at + s->done_at)) {
			s->w->faults.spectro_disconnect = false; /* consumed: the device vanished mid-read */
			drop_client(s);
			return;
		}
		if (now >= s->done_at)
			finish_exposure(s, now);
	}
	/* offline: no client is held, except one whose mid-read disconnect is still to come (it goes then) */
	if (s->cfd >= 0 && now < s->w->spectro_offline_until && !s->w->faults.spectro_disconnect)
		drop_client(s);
	if (s->cfd >= 0 && s->nout)
		flush(s);
}

static void svc_describe(void *self, char *buf, size_t len)
{
	struct spectro_svc *s = self;
	char esc[256];
	size_t j = 0;
	for (size_t i = 0; s->path[i] && j + 3 < sizeof esc; i++) {
		if (s->path[i] == '"' || s->path[i] == '\\')
			esc[j++] = '\\';
		esc[j++] = s->path[i];
	}
	esc[j] = 0;
	snprintf(buf, len, "\"spectrometer\": {\"socket\": \"%s\", \"pixels\": %d}", esc, phys_config(s->phys)->npix);
}

static void svc_destroy(void *self)
{
	struct spectro_svc *s = self;
	if (!s)
		return;
	drop_client(s);
	if (s->lfd >= 0) {
		close(s->lfd);
		unlink(s->path);
	}
	phys_free(s->phys);
	free(s->out);
	free(s->msg);
	free(s);
}

int sim_listen_unix(const char *path, struct acq_err *err)
{
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	if (strlen(path) >= sizeof a.sun_path)
		return acq_errf(err, ACQ_E_CONFIG, "socket path too long (max %zu bytes): %s", sizeof a.sun_path - 1, path);
	strcpy(a.sun_path, path);
	struct stat st;
	if (lstat(path, &st) == 0) {
		if (!S_ISSOCK(st.st_mode))
			return acq_errf(err, ACQ_E_IO, "%s: exists and is not a socket", path);
		unlink(path);
	}
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
	if (fd < 0)
		return acq_errf(err, ACQ_E_IO, "socket: %s", strerror(errno));
	if (bind(fd, (struct sockaddr *)&a, sizeof a) || listen(fd, 8)) {
		acq_errf(err, ACQ_E_IO, "%s: cannot listen: %s", path, strerror(errno));
		close(fd);
		return -1;
	}
	return fd;
}

struct sim_service *sim_spectro_new(struct sim_world *w, struct yc_node *node, struct yc_node *simcfg,
				    struct acq_err *err)
{
	struct phys_cfg pc;
	phys_defaults(&pc);
	const char *path = NULL;
	int sample = SIM_SAMPLE_WHITE;
	if (node && yc_expect_map(node, "devices.spectrometer", err))
		return NULL;
	if (node && yc_string(node, "socket", false, &path, err))
		return NULL;
	if (simcfg) {
		const char *samples[SIM_SAMPLE__COUNT + 1];
		for (int i = 0; i < SIM_SAMPLE__COUNT; i++)
			samples[i] = phys_sample_name(i);
		samples[SIM_SAMPLE__COUNT] = NULL;
		struct yc_node *sp = yc_get(simcfg, "spectrometer");
		const char *merl = NULL;
		if (yc_enum(simcfg, "sample", false, samples, &sample, err) || (sp && phys_parse(sp, &pc, err)) ||
		    refdrift_parse(simcfg, &pc.cal, err) || yc_string(simcfg, "merl_file", false, &merl, err))
			return NULL;
		if (merl && snprintf(pc.merl_file, sizeof pc.merl_file, "%s", merl) >= (int)sizeof pc.merl_file) {
			acq_errf(err, ACQ_E_CONFIG, "sim.merl_file: path longer than %zu bytes", sizeof pc.merl_file - 1);
			return NULL;
		}
		if (sample == SIM_SAMPLE_MERL && !merl) {
			acq_errf(err, ACQ_E_CONFIG, "sim.sample: merl needs sim.merl_file (a MERL binary table)");
			return NULL;
		}
	}
	struct spectro_svc *s = calloc(1, sizeof *s);
	if (s)
		s->lfd = s->cfd = -1;
	if (!s || !(s->msg = malloc(SSP_HDR + SSP_SPECTRUM_LEN(PHYS_MAX_PIXELS)))) {
		acq_errf(err, ACQ_E_NOMEM, "simulated spectrometer: out of memory");
		goto fail;
	}
	s->w = w;
	if (path)
		snprintf(s->path, sizeof s->path, "%s", path);
	else
		snprintf(s->path, sizeof s->path, "/tmp/acq-sim.%ld.spectro.sock", (long)getpid());
	if (!(s->phys = phys_new(&pc, err)))
		goto fail;
	if ((s->lfd = sim_listen_unix(s->path, err)) < 0) {
		acq_err_prefix(err, "simulated spectrometer: ");
		goto fail;
	}
	sim_rng_seed(&s->rng, w->seed ^ 0x5bec7c0ull);
	w->sample = sample;
	w->sensor_temp_c = pc.temperature_c;
	s->svc = (struct sim_service){ .name = "spectrometer", .self = s, .pollfds = svc_pollfds, .handle = svc_handle,
				     .tick = svc_tick, .describe = svc_describe, .destroy = svc_destroy };
	return &s->svc;
fail:
	if (s)
		svc_destroy(s);
	return NULL;
}
