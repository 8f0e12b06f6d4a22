/* avaspec: the "avaspec-usb" spectrometer backend: libusb-1.0 transport, device session (reset, identify,
 * configuration, prepare/start, data + acknowledgement, stop) and the spectro_backend table.
 *
 * Config (devices.spectrometer, backend: avaspec-usb):
 *   vendor_id: 0x1992            product_ids: [0x0667]       serial: "1234567"   (optional: match identity)
 *   endpoint_out: 0x02           endpoint_in: 0x86           interface: 0
 *   timeout_margin_ms: 2000      (added to the expected measurement time: (integration + readout) × averages)
 *   readout_ms: 10               reply_timeout_ms: 1000      poll_timeout_ms: 2 (one fetch() read)
 *   ack_type: 0x20               (type byte of the 0xC0 data acknowledgement; implementations disagree)
 *   dark_pixels: [2, 3, 4, 5]    (optically black pixels; empty = no dark-pixel correction)
 *   nonlinearity: true           (apply the device's nonlinearity polynomial when the device enables it)
 *   max_stale_messages: 64       (reset after an interrupted run: messages discarded before the stop reply)
 *   averaged_data: sum           (0xB1 pixel values are the sum of the scans | mean: already averaged)
 *
 * Session: open sends stop (0x0F) and discards stale data until the stop reply (0x8F), so a run left by a
 * killed process never leaks into ours; then identity (0x13) and device configuration (0x01). start() sends
 * prepare (0x05) and start (0x06, count 1) and waits for their replies; fetch() reads with a short timeout,
 * acknowledges a data message with 0xC0 and applies dark-pixel then nonlinearity correction. Any error or a
 * timeout during a run marks the session dirty: the next start() or stop() resets it first. */
#include "drivers/avaspec.h"

#include <libusb.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "drivers/avaspec_proto.h"
#include "drivers/spectro_backend.h"

#define AVS_MAX_PIDS 8
#define AVS_MAX_DARK 8

struct avs_config {
	int vendor_id;
	int product_ids[AVS_MAX_PIDS];
	int npids;
	char *serial;
	int ep_out, ep_in, iface;
	double timeout_margin_ms, readout_ms;
	int reply_timeout_ms, poll_timeout_ms;
	int ack_type;
	int dark_pixels[AVS_MAX_DARK];
	int ndark;
	bool nonlinearity;
	int max_stale;
	bool avg_is_sum;
};

enum avs_state { AVS_IDLE, AVS_RUNNING };

struct avs_dev {
	const struct avs_config *cfg;
	struct avs_transport t;
	uint8_t seq;
	struct avs_identity id;
	struct avs_devcfg dc;
	enum avs_state state;
	bool dirty;                 /* a run was interrupted: reset before the next one */
	struct spectro_meas meas;
	double deadline;
	size_t rxn;
	uint8_t rx[AVS_MAX_MSG + AVS_CHUNK];
	uint8_t tx[AVS_HDR + 64];
};

/* ---- configuration ------------------------------------------------------------------------------------ */

static void av_cfg_free(void *state)
{
	struct avs_config *c = state;
	if (!c)
		return;
	free(c->serial);
	free(c);
}

static int parse_int_list(struct yc_node *map, const char *key, int *out, int max, int *n, long long lo,
			  long long hi, struct acq_err *err)
{
	struct yc_node *seq = yc_get(map, key);
	if (!seq)
		return 0;
	if (yc_expect_seq(seq, key, err))
		return -1;
	if (seq->n > (size_t)max)
		return yc_errf(err, seq, "%s: at most %d entries", key, max);
	for (size_t i = 0; i < seq->n; i++) {
		long long v;
		if (yc_node_int(seq->items[i], key, lo, hi, &v, err))
			return -1;
		out[i] = (int)v;
	}
	*n = (int)seq->n;
	return 0;
}

static int av_cfg_parse(struct yc_node *node, void **state, struct acq_err *err)
{
	*state = NULL;
	struct avs_config *c = calloc(1, sizeof *c);
	if (!c)
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	long long vid = 0x1992, ep_out = 0x02, ep_in = 0x86, iface = 0, reply = 1000, poll_ms = 2, ack = 0x20;
	long long stale = 64;
	double margin = 2000, readout = 10;
	bool nonlin = true;
	int avg_mode = 0;
	static const char *const avg_modes[] = { "sum", "mean", NULL };
	const char *serial = NULL;
	c->product_ids[0] = 0x0667;
	c->npids = 1;
	if (yc_int(node, "vendor_id", false, 0, 0xffff, &vid, err) ||
	    parse_int_list(node, "product_ids", c->product_ids, AVS_MAX_PIDS, &c->npids, 0, 0xffff, err) ||
	    yc_string(node, "serial", false, &serial, err) ||
	    yc_int(node, "endpoint_out", false, 0x01, 0x0f, &ep_out, err) ||
	    yc_int(node, "endpoint_in", false, 0x81, 0x8f, &ep_in, err) ||
	    yc_int(node, "interface", false, 0, 31, &iface, err) ||
	    yc_double(node, "timeout_margin_ms", false, 0, 3600e3, &margin, err) ||
	    yc_double(node, "readout_ms", false, 0, 10e3, &readout, err) ||
	    yc_int(node, "reply_timeout_ms", false, 1, 600000, &reply, err) ||
	    yc_int(node, "poll_timeout_ms", false, 1, 1000, &poll_ms, err) ||
	    yc_int(node, "ack_type", false, 0x20, 0x21, &ack, err) ||
	    parse_int_list(node, "dark_pixels", c->dark_pixels, AVS_MAX_DARK, &c->ndark, 0, SPECTRO_MAX_PIXELS - 1,
			   err) ||
	    yc_bool(node, "nonlinearity", false, &nonlin, err) ||
	    yc_int(node, "max_stale_messages", false, 0, 100000, &stale, err) ||
	    yc_enum(node, "averaged_data", false, avg_modes, &avg_mode, err))
		goto fail;
	if (c->npids == 0) {
		yc_errf(err, yc_get(node, "product_ids"), "product_ids: at least one product id");
		goto fail;
	}
	if (serial && !(c->serial = strdup(serial))) {
		acq_errf(err, ACQ_E_NOMEM, "out of memory");
		goto fail;
	}
	c->vendor_id = (int)vid;
	c->ep_out = (int)ep_out;
	c->ep_in = (int)ep_in;
	c->iface = (int)iface;
	c->timeout_margin_ms = margin;
	c->readout_ms = readout;
	c->reply_timeout_ms = (int)reply;
	c->poll_timeout_ms = (int)poll_ms;
	c->ack_type = (int)ack;
	c->nonlinearity = nonlin;
	c->max_stale = (int)stale;
	c->avg_is_sum = avg_mode == 0;
	*state = c;
	return 0;
fail:
	av_cfg_free(c);
	return -1;
}

/* ---- message exchange over the transport --------------------------------------------------------------- */

static int send_cmd(struct avs_dev *d, uint8_t type, uint8_t cmd, const uint8_t *payload, size_t plen,
		    struct acq_err *err)
{
	int n = avs_frame(d->tx, sizeof d->tx, type, d->seq++, cmd, payload, plen, err);
	if (n < 0)
		return -1;
	return d->t.write(d->t.ctx, d->tx, (size_t)n, d->cfg->reply_timeout_ms, err);
}

/* One complete frame: 1 (msg filled, valid until the next call), 0 (nothing within timeout_ms, a partial
 * frame is kept), -1. A transfer carrying more than its frame says is an error (the frame is dropped). */
static int recv_msg(struct avs_dev *d, int timeout_ms, struct avs_msg *msg, struct acq_err *err)
{
	for (;;) {
		size_t need = avs_frame_need(d->rx, d->rxn);
		if (need) {
			if (need < AVS_HDR) {
				d->rxn = 0;
				return acq_errf(err, ACQ_E_PROTO, "avaspec: length field %zu is below the minimum 2",
						need - 4);
			}
			if (d->rxn > need) {
				size_t got = d->rxn;
				d->rxn = 0;
				return acq_errf(err, ACQ_E_PROTO, "avaspec: oversized transfer: %zu bytes for a frame "
						"whose length field says %zu", got, need);
			}
			if (d->rxn == need) {
				d->rxn = 0;
				return avs_parse(d->rx, need, msg, err) ? -1 : 1;
			}
		}
		/* rx holds AVS_MAX_MSG + AVS_CHUNK bytes and rxn < need ≤ AVS_MAX_MSG here: a chunk always fits. */
		int n = d->t.read(d->t.ctx, d->rx + d->rxn, AVS_CHUNK, timeout_ms, err);
		if (n < 0) {
			d->rxn = 0;
			return -1;
		}
		if (n == 0)
			return 0;
		if ((size_t)n > AVS_CHUNK) {
			d->rxn = 0;
			return acq_errf(err, ACQ_E_IO, "avaspec: transport returned %d bytes for a %d-byte read", n,
					AVS_CHUNK);
		}
		d->rxn += (size_t)n;
	}
}

/* Send cmd and wait for its reply (error replies become named ACQ_E_DEVICE errors). */
static int transact(struct avs_dev *d, uint8_t cmd, const uint8_t *payload, size_t plen, struct avs_msg *reply,
		    struct acq_err *err)
{
	if (send_cmd(d, AVS_TYPE_HOST, cmd, payload, plen, err))
		return -1;
	int rc = recv_msg(d, d->cfg->reply_timeout_ms, reply, err);
	if (rc < 0)
		return -1;
	if (rc == 0) {
		d->rxn = 0;
		return acq_errf(err, ACQ_E_TIMEOUT, "avaspec: no reply to command 0x%02x within %d ms", cmd,
				d->cfg->reply_timeout_ms);
	}
	return avs_expect_reply(reply, cmd, err);
}

static int expect_empty(const struct avs_msg *m, const char *what, struct acq_err *err)
{
	if (m->plen != 0)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: %s reply has %zu payload bytes, expected none", what,
				m->plen);
	return 0;
}

/* Stop and discard whatever a previous run left until the stop reply: the reset after an interrupted run. */
static int reset_run(struct avs_dev *d, struct acq_err *err)
{
	d->rxn = 0;
	/* The device answers once the exposure under way is read out: wait for one exposure more than a reply. */
	int wait_ms = d->cfg->reply_timeout_ms;
	if (d->state == AVS_RUNNING || d->dirty) {
		double extra = d->meas.integration_ms + d->cfg->readout_ms;
		wait_ms = extra + wait_ms > 3600e3 ? (int)3600e3 : wait_ms + (int)extra;
	}
	if (send_cmd(d, AVS_TYPE_HOST, AVS_CMD_STOP, NULL, 0, err))
		return -1;
	for (int stale = 0;; stale++) {
		struct avs_msg m;
		int rc = recv_msg(d, wait_ms, &m, err);
		if (rc < 0)
			return acq_err_prefix(err, "resetting: ");
		if (rc == 0)
			return acq_errf(err, ACQ_E_TIMEOUT, "avaspec: no reply to stop (0x0F) within %d ms", wait_ms);
		if (m.type == AVS_TYPE_DEV && (m.cmd == AVS_CMD_DATA_SINGLE || m.cmd == AVS_CMD_DATA_AVG)) {
			if (stale >= d->cfg->max_stale)
				return acq_errf(err, ACQ_E_DEVICE, "avaspec: device still sends data after %d stale "
						"messages following a stop", stale);
			continue;
		}
		if (avs_expect_reply(&m, AVS_CMD_STOP, err) || expect_empty(&m, "stop", err))
			return -1;
		d->state = AVS_IDLE;
		d->dirty = false;
		return 0;
	}
}

/* ---- backend -------------------------------------------------------------------------------------------- */

static void av_close(void *dev)
{
	struct avs_dev *d = dev;
	if (!d)
		return;
	if (d->state == AVS_RUNNING || d->dirty) {
		struct acq_err ignored;
		/* Best effort: leave the device idle for the next user. */
		if (send_cmd(d, AVS_TYPE_HOST, AVS_CMD_STOP, NULL, 0, &ignored) == 0) {
			struct avs_msg m;
			(void)recv_msg(d, d->cfg->reply_timeout_ms, &m, &ignored);
		}
	}
	d->t.close(d->t.ctx);
	free(d);
}

int avs_open_transport(const void *state, const struct avs_transport *t, void **dev, struct spectro_info *info,
		       struct acq_err *err)
{
	const struct avs_config *cfg = state;
	*dev = NULL;
	struct avs_dev *d = calloc(1, sizeof *d);
	if (!d) {
		t->close(t->ctx);
		return acq_errf(err, ACQ_E_NOMEM, "out of memory");
	}
	d->cfg = cfg;
	d->t = *t;
	struct avs_msg m;
	if (reset_run(d, err))
		goto fail;
	if (transact(d, AVS_CMD_IDENTIFY, NULL, 0, &m, err) || avs_parse_identity(m.payload, m.plen, &d->id, err))
		goto fail;
	if (cfg->serial && strcmp(cfg->serial, d->id.serial) != 0) {
		acq_errf(err, ACQ_E_NOTFOUND, "avaspec: serial number is '%s', configured '%s'", d->id.serial,
			 cfg->serial);
		goto fail;
	}
	if (transact(d, AVS_CMD_GET_CONFIG, NULL, 0, &m, err) || avs_parse_devcfg(m.payload, m.plen, &d->dc, err))
		goto fail;
	memset(info, 0, sizeof *info);
	snprintf(info->model, sizeof info->model, "%s", d->id.name[0] ? d->id.name : "AvaSpec");
	snprintf(info->serial, sizeof info->serial, "%s", d->id.serial);
	snprintf(info->firmware, sizeof info->firmware, "unknown (status %u)", d->id.status);
	info->npix = d->dc.npix;
	memcpy(info->wl_coef, d->dc.wl_coef, sizeof info->wl_coef);
	info->nonlin_enabled = d->dc.nl_enabled && cfg->nonlinearity;
	memcpy(info->nonlin_coef, d->dc.nl_coef, sizeof info->nonlin_coef);
	info->nonlin_low = d->dc.nl_low;
	info->nonlin_high = d->dc.nl_high;
	for (int i = 0; i < cfg->ndark; i++)
		if (cfg->dark_pixels[i] < d->dc.npix)
			info->dark_pixels[info->ndark_pixels++] = cfg->dark_pixels[i];
	info->max_counts = 65535;
	*dev = d;
	return 0;
fail:
	d->dirty = false;
	d->state = AVS_IDLE;
	av_close(d);
	return -1;
}

static int av_start(void *dev, const struct spectro_meas *sm, double now, struct acq_err *err)
{
	struct avs_dev *d = dev;
	if (d->state == AVS_RUNNING)
		return acq_errf(err, ACQ_E_STATE, "avaspec: a measurement is already running");
	if (d->dirty && reset_run(d, err))
		return -1;
	struct avs_meascfg mc = {
		.start_pixel = 0,
		.stop_pixel = (uint16_t)(d->dc.npix - 1),
		.integration_ms = (float)sm->integration_ms,
		.averages = sm->averages,
		.saturation = sm->saturation_detection ? 1 : 0,
	};
	if (avs_meascfg_check(&mc, err))
		return -1;
	uint8_t pkt[AVS_MEASCFG_LEN];
	avs_meascfg_pack(&mc, pkt);
	struct avs_msg m;
	/* Until the start is acknowledged a failure leaves the device state unknown (dirty), except a plain
	 * refusal of the prepare: then nothing was started. */
	d->dirty = true;
	if (transact(d, AVS_CMD_PREPARE, pkt, sizeof pkt, &m, err) || expect_empty(&m, "prepare", err)) {
		if (err && err->code == ACQ_E_DEVICE)
			d->dirty = false;
		return -1;
	}
	const uint8_t count[2] = { 0x00, 0x01 }; /* int16 big-endian: one measurement */
	if (transact(d, AVS_CMD_START, count, sizeof count, &m, err) || expect_empty(&m, "start", err))
		return -1;
	d->meas = *sm;
	d->meas.integration_ms = (double)mc.integration_ms;
	d->state = AVS_RUNNING;
	d->dirty = false;
	d->deadline = now + ((sm->integration_ms + d->cfg->readout_ms) * sm->averages + d->cfg->timeout_margin_ms) /
				    1000.0;
	return 0;
}

static int run_failed(struct avs_dev *d)
{
	d->state = AVS_IDLE;
	d->dirty = true;
	return -1;
}

static int av_fetch(void *dev, struct spectro_frame *f, double now, struct acq_err *err)
{
	struct avs_dev *d = dev;
	if (d->state != AVS_RUNNING)
		return acq_errf(err, ACQ_E_STATE, "avaspec: fetch without a running measurement");
	struct avs_msg m;
	int rc = recv_msg(d, d->cfg->poll_timeout_ms, &m, err);
	if (rc < 0)
		return run_failed(d);
	if (rc == 0) {
		if (now <= d->deadline)
			return 0;
		acq_errf(err, ACQ_E_TIMEOUT, "avaspec: no spectrum %.3f s after the deadline (integration %g ms × "
			 "%u averages + %g ms margin)", now - d->deadline, d->meas.integration_ms, d->meas.averages,
			 d->cfg->timeout_margin_ms);
		return run_failed(d);
	}
	if (m.type != AVS_TYPE_DEV || (m.cmd != AVS_CMD_DATA_SINGLE && m.cmd != AVS_CMD_DATA_AVG)) {
		if (m.type == AVS_TYPE_DEV && m.cmd == AVS_CMD_ERROR && m.plen == 1) {
			acq_errf(err, ACQ_E_DEVICE, "avaspec: device error during the measurement: %s (reason %d)",
				 avs_reason_name(m.payload[0]), m.payload[0]);
			if (err)
				err->detail = m.payload[0] + 1;
		} else if (avs_expect_reply(&m, AVS_CMD_START, err) == 0)
			acq_errf(err, ACQ_E_PROTO, "avaspec: unexpected second start reply during a measurement");
		else if (m.cmd != AVS_CMD_ERROR)
			acq_errf(err, ACQ_E_PROTO, "avaspec: unexpected message type 0x%02x command 0x%02x during a "
				 "measurement", m.type, m.cmd);
		return run_failed(d);
	}
	int npix = d->dc.npix;
	f->npix = npix;
	if (avs_decode_data(&m, npix, d->meas.averages, d->cfg->avg_is_sum, f->counts, f->saturated, &f->nsaturated,
			    &f->device_time_s, err))
		return run_failed(d);
	if (send_cmd(d, (uint8_t)d->cfg->ack_type, AVS_CMD_ACK, NULL, 0, err))
		return run_failed(d);
	d->state = AVS_IDLE;
	memset(f->stddev, 0, sizeof f->stddev[0] * (size_t)npix);
	f->temperature_c = NAN;
	f->meas = d->meas;
	f->dark_pixel_level = 0;
	f->dark_pixel_corrected = false;
	if (d->cfg->ndark)
		f->dark_pixel_corrected = avs_dark_correct(f->counts, npix, d->cfg->dark_pixels, d->cfg->ndark,
							   &f->dark_pixel_level);
	f->nonlin_applied = false;
	if (d->cfg->nonlinearity && d->dc.nl_enabled)
		f->nonlin_applied = avs_nonlin_correct(f->counts, npix, d->dc.nl_coef, d->dc.nl_low, d->dc.nl_high);
	return 1;
}

static int av_stop(void *dev, struct acq_err *err)
{
	struct avs_dev *d = dev;
	if (d->state != AVS_RUNNING && !d->dirty)
		return 0;
	if (reset_run(d, err)) {
		d->state = AVS_IDLE;
		d->dirty = true;
		return -1;
	}
	return 0;
}

static int av_pollfd(const void *dev)
{
	(void)dev;
	return -1; /* libusb's fds would need its event loop: the daemon polls fetch() by timer */
}

/* ---- libusb transport -------------------------------------------------------------------------------- */

struct usb_link {
	libusb_context *ctx;
	libusb_device_handle *h;
	int ep_out, ep_in, iface;
};

static int usb_errf(struct acq_err *err, int rc, const char *what)
{
	int code = ACQ_E_IO;
	if (rc == LIBUSB_ERROR_NO_DEVICE)
		code = ACQ_E_DISCONNECTED;
	else if (rc == LIBUSB_ERROR_TIMEOUT)
		code = ACQ_E_TIMEOUT;
	return acq_errf(err, code, "avaspec: USB %s: %s%s", what, libusb_error_name(rc),
			rc == LIBUSB_ERROR_NO_DEVICE ? " (device disconnected)" : "");
}

static int usb_write(void *ctx, const uint8_t *buf, size_t n, int timeout_ms, struct acq_err *err)
{
	struct usb_link *u = ctx;
	int sent = 0;
	int rc = libusb_bulk_transfer(u->h, (unsigned char)u->ep_out, (unsigned char *)(uintptr_t)buf, (int)n, &sent,
				      (unsigned)timeout_ms);
	if (rc)
		return usb_errf(err, rc, "write");
	if ((size_t)sent != n)
		return acq_errf(err, ACQ_E_IO, "avaspec: USB write: %d of %zu bytes sent", sent, n);
	return 0;
}

static int usb_read(void *ctx, uint8_t *buf, size_t cap, int timeout_ms, struct acq_err *err)
{
	struct usb_link *u = ctx;
	int got = 0;
	int rc = libusb_bulk_transfer(u->h, (unsigned char)u->ep_in, buf, (int)cap, &got, (unsigned)timeout_ms);
	if (rc == LIBUSB_ERROR_TIMEOUT)
		return got; /* possibly a partial frame; the caller keeps it */
	if (rc == LIBUSB_ERROR_OVERFLOW)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: USB read: device sent more than %zu bytes in one transfer",
				cap);
	if (rc)
		return usb_errf(err, rc, "read");
	return got;
}

static void usb_close(void *ctx)
{
	struct usb_link *u = ctx;
	if (!u)
		return;
	if (u->h) {
		libusb_release_interface(u->h, u->iface);
		libusb_close(u->h);
	}
	if (u->ctx)
		libusb_exit(u->ctx);
	free(u);
}

static bool pid_wanted(const struct avs_config *c, int pid)
{
	for (int i = 0; i < c->npids; i++)
		if (c->product_ids[i] == pid)
			return true;
	return false;
}

static int av_open(const void *state, void **dev, struct spectro_info *info, struct acq_err *err)
{
	const struct avs_config *c = state;
	*dev = NULL;
	libusb_context *ctx = NULL;
	int rc = libusb_init(&ctx);
	if (rc)
		return acq_errf(err, ACQ_E_IO, "avaspec: libusb_init: %s", libusb_error_name(rc));
	libusb_device **list = NULL;
	ssize_t n = libusb_get_device_list(ctx, &list);
	if (n < 0) {
		libusb_exit(ctx);
		return acq_errf(err, ACQ_E_IO, "avaspec: listing USB devices: %s", libusb_error_name((int)n));
	}
	/* Try each matching device: the first that opens, claims and (if configured) has the serial wins.
	 * The last failure is reported when none does. */
	struct acq_err last = { 0 };
	int candidates = 0, ok = -1;
	for (ssize_t i = 0; i < n && ok != 0; i++) {
		struct libusb_device_descriptor dd;
		if (libusb_get_device_descriptor(list[i], &dd) || dd.idVendor != c->vendor_id ||
		    !pid_wanted(c, dd.idProduct))
			continue;
		candidates++;
		libusb_device_handle *h = NULL;
		if ((rc = libusb_open(list[i], &h))) {
			usb_errf(&last, rc, "open");
			continue;
		}
		if ((rc = libusb_claim_interface(h, c->iface))) {
			if (rc == LIBUSB_ERROR_BUSY)
				acq_errf(&last, ACQ_E_STATE, "avaspec: interface %d of %04x:%04x is claimed by another "
					 "process", c->iface, dd.idVendor, dd.idProduct);
			else
				usb_errf(&last, rc, "claim interface");
			libusb_close(h);
			continue;
		}
		struct usb_link *u = calloc(1, sizeof *u);
		if (!u) {
			libusb_release_interface(h, c->iface);
			libusb_close(h);
			acq_errf(&last, ACQ_E_NOMEM, "out of memory");
			break;
		}
		u->h = h;
		u->ep_out = c->ep_out;
		u->ep_in = c->ep_in;
		u->iface = c->iface;
		/* The last transport to be tried owns the context; earlier ones share it and must not exit it. */
		struct avs_transport t = { .ctx = u, .write = usb_write, .read = usb_read, .close = usb_close };
		ok = avs_open_transport(c, &t, dev, info, &last);
		if (ok == 0) {
			u->ctx = ctx;
			ctx = NULL;
		}
	}
	libusb_free_device_list(list, 1);
	if (ctx)
		libusb_exit(ctx);
	if (ok == 0)
		return 0;
	if (!candidates) {
		char ids[64] = "";
		size_t len = 0;
		for (int i = 0; i < c->npids && len < sizeof ids; i++)
			len += (size_t)snprintf(ids + len, sizeof ids - len, "%s0x%04x", i ? ", " : "", c->product_ids[i]);
		return acq_errf(err, ACQ_E_NOTFOUND, "avaspec: no USB device with vendor id 0x%04x and product id "
				"in [%s]", c->vendor_id, ids);
	}
	if (err)
		*err = last;
	return -1;
}

const struct spectro_backend spectro_avaspec_backend = {
	.name = "avaspec-usb",
	.cfg_parse = av_cfg_parse,
	.cfg_free = av_cfg_free,
	.open = av_open,
	.close = av_close,
	.start = av_start,
	.fetch = av_fetch,
	.stop = av_stop,
	.pollfd = av_pollfd,
};
