/* AvaSpec protocol (drivers/avaspec_proto.c) and the backend's session logic through the transport seam
 * (drivers/avaspec.h) with an in-memory device: the cases umockdev cannot replay ("no data yet", split
 * transfers, timeouts that scale with integration × averages, reset after an interrupted run). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "drivers/avaspec.h"
#include "drivers/avaspec_proto.h"
#include "drivers/spectro_backend.h"

#define NPIX 64

/* ---- pure protocol ----------------------------------------------------------------------------------- */

static void test_frame_roundtrip_and_rejects(void **state)
{
	(void)state;
	uint8_t buf[64];
	struct acq_err err = { 0 };
	const uint8_t pl[3] = { 1, 2, 3 };
	int n = avs_frame(buf, sizeof buf, AVS_TYPE_DEV, 7, 0x93, pl, 3, &err);
	assert_int_equal(n, 9);
	static const uint8_t want[9] = { 0x21, 7, 5, 0, 0x93, 0, 1, 2, 3 };
	assert_memory_equal(buf, want, 9);
	assert_int_equal(avs_frame_need(buf, 3), 0);
	assert_int_equal(avs_frame_need(buf, 4), 9);
	struct avs_msg m;
	assert_int_equal(avs_parse(buf, 9, &m, &err), 0);
	assert_int_equal(m.cmd, 0x93);
	assert_int_equal(m.plen, 3);
	assert_int_equal(avs_expect_reply(&m, 0x13, &err), 0);
	assert_int_equal(avs_expect_reply(&m, 0x01, &err), -1);
	assert_int_equal(err.code, ACQ_E_PROTO);
	assert_int_equal(avs_parse(buf, 8, &m, &err), -1); /* length field says 9 */
	assert_non_null(strstr(err.msg, "length field"));
	assert_int_equal(avs_parse(buf, 5, &m, &err), -1);
	buf[5] = 1;
	assert_int_equal(avs_parse(buf, 9, &m, &err), -1);
	buf[5] = 0;
	buf[0] = 0x42;
	assert_int_equal(avs_parse(buf, 9, &m, &err), -1);
	assert_non_null(strstr(err.msg, "type 0x42"));
	static const uint8_t tiny[6] = { 0x21, 0, 1, 0, 0, 0 }; /* length 1 < 2 */
	assert_int_equal(avs_parse(tiny, 5, &m, &err), -1);
	assert_int_equal(avs_frame(buf, 8, 0x20, 0, 1, pl, 3, &err), -1);
}

static void test_error_reasons_named(void **state)
{
	(void)state;
	static const char *const names[13] = {
		"unknown error", "invalid parameter", "invalid password", "invalid command", "invalid size",
		"measurement pending", "invalid pixel range", "invalid integration time", "not supported",
		"invalid combination", "no buffer", "no spectra", "invalid state",
	};
	for (int r = 0; r <= 13; r++) {
		uint8_t buf[16], pl = (uint8_t)(r == 13 ? 0x42 : r);
		struct acq_err err = { 0 };
		struct avs_msg m;
		int n = avs_frame(buf, sizeof buf, AVS_TYPE_DEV, 0, AVS_CMD_ERROR, &pl, 1, &err);
		assert_int_equal(n, 7);
		assert_int_equal(buf[2], 3); /* an error reply has length 3 */
		assert_int_equal(avs_parse(buf, (size_t)n, &m, &err), 0);
		assert_int_equal(avs_expect_reply(&m, AVS_CMD_PREPARE, &err), -1);
		assert_int_equal(err.code, ACQ_E_DEVICE);
		assert_int_equal(err.detail, pl + 1);
		assert_non_null(strstr(err.msg, r == 13 ? "undocumented reason" : names[r]));
	}
	/* an error reply of the wrong length is a protocol error, not a guess */
	uint8_t buf[16], pl[2] = { 1, 2 };
	struct avs_msg m;
	struct acq_err err = { 0 };
	avs_frame(buf, sizeof buf, AVS_TYPE_DEV, 0, AVS_CMD_ERROR, pl, 2, &err);
	assert_int_equal(avs_parse(buf, 8, &m, &err), 0);
	assert_int_equal(avs_expect_reply(&m, AVS_CMD_PREPARE, &err), -1);
	assert_int_equal(err.code, ACQ_E_PROTO);
}

static void test_meascfg_pack_and_combinations(void **state)
{
	(void)state;
	struct avs_meascfg m = { .start_pixel = 0, .stop_pixel = 2047, .integration_ms = 10.0f, .averages = 3,
				 .saturation = 1, .laser_wavelength = 532.0f, .store_to_ram = 0 };
	uint8_t b[AVS_MEASCFG_LEN];
	avs_meascfg_pack(&m, b);
	static const uint8_t head[16] = { 0x00, 0x00, 0x07, 0xFF, 0x41, 0x20, 0x00, 0x00,
					  0, 0, 0, 0, 0, 0, 0, 3 };
	assert_memory_equal(b, head, 16);
	assert_int_equal(b[21], 1);                  /* saturation detection */
	static const uint8_t wl[4] = { 0x44, 0x05, 0x00, 0x00 }; /* 532.0f big-endian */
	assert_memory_equal(b + 35, wl, 4);
	struct acq_err err = { 0 };
	assert_int_equal(avs_meascfg_check(&m, &err), 0);
	m.saturation = 2;
	assert_int_equal(avs_meascfg_check(&m, &err), -1);
	assert_non_null(strstr(err.msg, "peak inversion"));
	m.saturation = 0;
	m.store_to_ram = 1;
	assert_int_equal(avs_meascfg_check(&m, &err), -1);
	m.store_to_ram = 0;
	m.integration_ms = 600000.0f;
	m.averages = 5001;
	assert_int_equal(avs_meascfg_check(&m, &err), -1);
	m.averages = 5000;
	assert_int_equal(avs_meascfg_check(&m, &err), 0);
	m.integration_ms = 0;
	assert_int_equal(avs_meascfg_check(&m, &err), -1);
}

static void test_nonlinearity_guards(void **state)
{
	(void)state;
	double c[4] = { 100, 2000, 30000, 70000 };
	const double zero[8] = { 0 };
	assert_false(avs_nonlin_correct(c, 4, zero, 1000, 60000));
	assert_true(c[1] == 2000);
	/* P(x) = 1 − x/30000 reaches 0 at 30000 and goes negative above: those pixels stay as measured */
	const double lin[8] = { 1.0, -1.0 / 30000 };
	assert_true(avs_nonlin_correct(c, 4, lin, 0, 0));
	for (int i = 0; i < 4; i++)
		assert_true(isfinite(c[i]));
	assert_true(fabs(c[1] - 2000 / (1 - 2000.0 / 30000)) < 1e-9);
	assert_true(c[2] == 30000 && c[3] == 70000);
	const double bad[8] = { 1.0, NAN };
	assert_false(avs_nonlin_correct(c, 4, bad, 0, 0));
	/* clamping to the limits */
	double d[2] = { 10, 1e6 };
	const double quad[8] = { 1.0, 1e-5 };
	assert_true(avs_nonlin_correct(d, 2, quad, 1000, 60000));
	assert_true(fabs(d[0] - 10 / 1.01) < 1e-12 && fabs(d[1] - 1e6 / 1.6) < 1e-6);
	double e[3] = { 5, 7, 9 };
	const int dark[3] = { 0, 1, 99 };
	double level;
	assert_true(avs_dark_correct(e, 3, dark, 3, &level));
	assert_true(level == 6 && e[2] == 3);
	const int none[1] = { -1 };
	assert_false(avs_dark_correct(e, 3, none, 1, &level));
}

/* ---- the session through an in-memory transport ------------------------------------------------------ */

enum { IN_DATA, IN_NOTHING, IN_ERROR };
struct chunk {
	int kind;
	size_t n;
	uint8_t *data;
};
struct fake {
	struct chunk in[64];
	int nin, pos;
	uint8_t out[64][128];
	size_t outn[64];
	int nout;
	int closed;
	int last_read_timeout;
};

static struct fake *fk;

static void push_bytes(const uint8_t *b, size_t n)
{
	struct chunk *c = &fk->in[fk->nin++];
	c->kind = IN_DATA;
	c->n = n;
	c->data = malloc(n ? n : 1);
	memcpy(c->data, b, n);
}

static void push_frame(uint8_t cmd, const uint8_t *payload, size_t plen)
{
	static uint8_t buf[AVS_MAX_MSG];
	int n = avs_frame(buf, sizeof buf, AVS_TYPE_DEV, 0, cmd, payload, plen, NULL);
	assert_true(n > 0);
	/* one USB transfer delivers at most AVS_CHUNK bytes */
	for (int off = 0; off < n; off += AVS_CHUNK)
		push_bytes(buf + off, (size_t)(n - off < AVS_CHUNK ? n - off : AVS_CHUNK));
}

static void push_kind(int kind)
{
	fk->in[fk->nin++].kind = kind;
}

static int f_write(void *ctx, const uint8_t *buf, size_t n, int timeout_ms, struct acq_err *err)
{
	(void)ctx; (void)timeout_ms; (void)err;
	assert_true(fk->nout < 64 && n <= 128);
	memcpy(fk->out[fk->nout], buf, n);
	fk->outn[fk->nout++] = n;
	return 0;
}

static int f_read(void *ctx, uint8_t *buf, size_t cap, int timeout_ms, struct acq_err *err)
{
	(void)ctx;
	fk->last_read_timeout = timeout_ms;
	if (fk->pos >= fk->nin)
		return 0; /* nothing yet */
	struct chunk *c = &fk->in[fk->pos++];
	if (c->kind == IN_NOTHING)
		return 0;
	if (c->kind == IN_ERROR)
		return acq_errf(err, ACQ_E_DISCONNECTED, "fake: device gone");
	assert_true(c->n <= cap);
	memcpy(buf, c->data, c->n);
	return (int)c->n;
}

static void f_close(void *ctx)
{
	(void)ctx;
	fk->closed++;
}

static const struct avs_transport fake_transport = { .ctx = NULL, .write = f_write, .read = f_read, .close = f_close };

static void put_be16(uint8_t *p, unsigned v) { p[0] = (uint8_t)(v >> 8); p[1] = (uint8_t)v; }

static void push_open_replies(const char *serial)
{
	push_frame(AVS_CMD_STOP + AVS_REPLY, NULL, 0);
	uint8_t id[AVS_IDENT_LEN] = { 0 };
	memcpy(id, serial, strlen(serial));
	memcpy(id + 10, "FakeSpec", 8);
	id[74] = 1;
	push_frame(AVS_CMD_IDENTIFY + AVS_REPLY, id, sizeof id);
	static uint8_t rec[AVS_DEVCFG_LEN];
	memset(rec, 0, sizeof rec);
	put_be16(rec + AVS_CFG_OFF_NPIX, NPIX);
	rec[AVS_CFG_OFF_FIT] = 0x43;   /* 128.0f... as c0: 0x43000000 */
	push_frame(AVS_CMD_GET_CONFIG + AVS_REPLY, rec, sizeof rec);
}

static void push_data(unsigned base)
{
	uint8_t pl[4 + 2 * NPIX];
	memset(pl, 0, 4);
	pl[3] = 100;
	for (int i = 0; i < NPIX; i++)
		put_be16(pl + 4 + 2 * i, base + (unsigned)i);
	push_frame(AVS_CMD_DATA_SINGLE, pl, sizeof pl);
}

struct session {
	struct yc_doc *doc;
	void *cfg;
	void *dev;
	struct spectro_info info;
	struct acq_err err;
};

static int session_open(struct session *s, const char *yaml)
{
	memset(s, 0, sizeof *s);
	assert_int_equal(yc_load_string("t.yaml", yaml, strlen(yaml), &s->doc, &s->err), 0);
	assert_int_equal(spectro_avaspec_backend.cfg_parse(yc_root(s->doc), &s->cfg, &s->err), 0);
	return avs_open_transport(s->cfg, &fake_transport, &s->dev, &s->info, &s->err);
}

static void session_close(struct session *s)
{
	if (s->dev)
		spectro_avaspec_backend.close(s->dev);
	spectro_avaspec_backend.cfg_free(s->cfg);
	yc_free(s->doc);
	for (int i = 0; i < fk->nin; i++)
		free(fk->in[i].data);
	memset(fk, 0, sizeof *fk);
}

static int setup(void **state)
{
	(void)state;
	fk = calloc(1, sizeof *fk);
	return fk ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	free(fk);
	return 0;
}

static const char base_yaml[] = "backend: avaspec-usb\ntimeout_margin_ms: 500\nreadout_ms: 10\n";

static void test_seam_not_yet_then_split_frame(void **state)
{
	(void)state;
	struct session s;
	push_open_replies("S1");
	assert_int_equal(session_open(&s, base_yaml), 0);
	assert_int_equal(s.info.npix, NPIX);
	assert_true(s.info.wl_coef[0] == 128.0);
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	struct spectro_meas m = { .integration_ms = 100, .averages = 1 };
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 10.0, &s.err), 0);
	static struct spectro_frame f;
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 10.01, &s.err), 0); /* no data yet */
	/* a data frame split over three transfers with "nothing" in between */
	uint8_t pl[4 + 2 * NPIX] = { 0 };
	for (int i = 0; i < NPIX; i++)
		put_be16(pl + 4 + 2 * i, 500u + (unsigned)i);
	static uint8_t fr[AVS_HDR + sizeof pl];
	int n = avs_frame(fr, sizeof fr, AVS_TYPE_DEV, 0, AVS_CMD_DATA_SINGLE, pl, sizeof pl, NULL);
	push_bytes(fr, 3);
	push_kind(IN_NOTHING);
	push_bytes(fr + 3, 50);
	push_kind(IN_NOTHING);
	push_bytes(fr + 53, (size_t)n - 53);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 10.02, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 10.03, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 10.04, &s.err), 1);
	assert_int_equal(f.npix, NPIX);
	assert_true(f.counts[10] == 510 && !f.nonlin_applied && !f.dark_pixel_corrected);
	/* the acknowledgement went out */
	assert_int_equal(fk->out[fk->nout - 1][4], AVS_CMD_ACK);
	assert_int_equal(fk->out[fk->nout - 1][0], 0x20);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 10.05, &s.err), -1);
	assert_int_equal(s.err.code, ACQ_E_STATE);
	session_close(&s);
}

static void test_seam_timeout_scales_and_reset_follows(void **state)
{
	(void)state;
	struct session s;
	push_open_replies("S1");
	assert_int_equal(session_open(&s, base_yaml), 0);
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	struct spectro_meas m = { .integration_ms = 1000, .averages = 5 };
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 0.0, &s.err), 0);
	static struct spectro_frame f;
	/* deadline = (1000 + 10) ms × 5 + 500 ms = 5.55 s */
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 5.0, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 5.54, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 5.54, &s.err), -1);
	assert_int_equal(s.err.code, ACQ_E_STATE);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 5.56, &s.err), -1);
	assert_int_equal(s.err.code, ACQ_E_TIMEOUT);
	assert_non_null(strstr(s.err.msg, "1000 ms × 5 averages"));
	/* the next start resets the interrupted run: stop (discarding the late spectrum) before prepare */
	int before = fk->nout;
	push_data(0);
	push_frame(AVS_CMD_STOP + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	push_data(1000);
	m.averages = 1;
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 6.0, &s.err), 0);
	assert_int_equal(fk->out[before][4], AVS_CMD_STOP);
	assert_int_equal(fk->out[before + 1][4], AVS_CMD_PREPARE);
	assert_int_equal(fk->out[before + 2][4], AVS_CMD_START);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 6.1, &s.err), 1);
	assert_true(f.counts[0] == 1000); /* the fresh spectrum, not the stale one */
	session_close(&s);
}

static void test_seam_errors_during_run(void **state)
{
	(void)state;
	static struct spectro_frame f;
	struct spectro_meas m = { .integration_ms = 5, .averages = 1 };
	struct session s;
	/* error reply instead of data */
	push_open_replies("S1");
	assert_int_equal(session_open(&s, base_yaml), 0);
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	uint8_t reason = AVS_R_NO_SPECTRA;
	push_frame(AVS_CMD_ERROR, &reason, 1);
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 0, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 0, &s.err), -1);
	assert_int_equal(s.err.code, ACQ_E_DEVICE);
	assert_int_equal(s.err.detail, AVS_R_NO_SPECTRA + 1);
	assert_non_null(strstr(s.err.msg, "no spectra"));
	/* a transfer longer than its frame */
	push_frame(AVS_CMD_STOP + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	uint8_t junk[12] = { 0x21, 0, 2, 0, 0xB0, 0, 9, 9, 9, 9, 9, 9 };
	push_bytes(junk, sizeof junk);
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 0, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 0, &s.err), -1);
	assert_int_equal(s.err.code, ACQ_E_PROTO);
	assert_non_null(strstr(s.err.msg, "oversized transfer"));
	/* the device vanishes */
	push_frame(AVS_CMD_STOP + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	push_kind(IN_ERROR);
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 0, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 0, &s.err), -1);
	assert_int_equal(s.err.code, ACQ_E_DISCONNECTED);
	/* stop() on the interrupted run resets it */
	push_frame(AVS_CMD_STOP + AVS_REPLY, NULL, 0);
	assert_int_equal(spectro_avaspec_backend.stop(s.dev, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.stop(s.dev, &s.err), 0); /* idle: nothing sent */
	int nout = fk->nout;
	spectro_avaspec_backend.close(s.dev);
	s.dev = NULL;
	assert_int_equal(nout, fk->nout); /* closing an idle session sends nothing */
	assert_int_equal(fk->closed, 1);
	session_close(&s);
}

static void test_seam_open_failures(void **state)
{
	(void)state;
	struct session s;
	/* configured serial differs */
	push_open_replies("OTHER");
	assert_int_equal(session_open(&s, "backend: avaspec-usb\nserial: WANTED\n"), -1);
	assert_int_equal(s.err.code, ACQ_E_NOTFOUND);
	assert_non_null(strstr(s.err.msg, "OTHER"));
	assert_int_equal(fk->closed, 1);
	session_close(&s);
	/* a device that keeps streaming stale data after stop */
	for (int i = 0; i < 6; i++)
		push_data(0);
	assert_int_equal(session_open(&s, "backend: avaspec-usb\nmax_stale_messages: 4\n"), -1);
	assert_int_equal(s.err.code, ACQ_E_DEVICE);
	session_close(&s);
	/* silence */
	assert_int_equal(session_open(&s, base_yaml), -1);
	assert_int_equal(s.err.code, ACQ_E_TIMEOUT);
	assert_non_null(strstr(s.err.msg, "stop"));
	session_close(&s);
	/* a short configuration record */
	push_frame(AVS_CMD_STOP + AVS_REPLY, NULL, 0);
	uint8_t id[AVS_IDENT_LEN] = { 0 };
	push_frame(AVS_CMD_IDENTIFY + AVS_REPLY, id, sizeof id);
	uint8_t rec[100] = { 0 };
	push_frame(AVS_CMD_GET_CONFIG + AVS_REPLY, rec, sizeof rec);
	assert_int_equal(session_open(&s, base_yaml), -1);
	assert_int_equal(s.err.code, ACQ_E_PROTO);
	assert_non_null(strstr(s.err.msg, "63484"));
	session_close(&s);
}

static void test_seam_close_running_mean_data_long_stop(void **state)
{
	(void)state;
	static struct spectro_frame f;
	struct session s;
	push_open_replies("S1");
	assert_int_equal(session_open(&s, "backend: avaspec-usb\naveraged_data: mean\nreply_timeout_ms: 700\n"), 0);
	/* averaged data already divided by the device */
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	uint8_t pl[4 + 4 * NPIX] = { 0 };
	for (int i = 0; i < NPIX; i++)
		pl[4 + 4 * i + 3] = (uint8_t)(i + 1);
	push_frame(AVS_CMD_DATA_AVG, pl, sizeof pl);
	struct spectro_meas m = { .integration_ms = 5000, .averages = 3 };
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 0, &s.err), 0);
	assert_int_equal(spectro_avaspec_backend.fetch(s.dev, &f, 0, &s.err), 1);
	assert_true(f.counts[9] == 10);
	/* stop during a 5 s exposure waits for the exposure to end plus the reply time */
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 1, &s.err), 0);
	push_frame(AVS_CMD_STOP + AVS_REPLY, NULL, 0);
	assert_int_equal(spectro_avaspec_backend.stop(s.dev, &s.err), 0);
	assert_int_equal(fk->last_read_timeout, 5000 + 10 + 700);
	/* close during a run sends stop */
	push_frame(AVS_CMD_PREPARE + AVS_REPLY, NULL, 0);
	push_frame(AVS_CMD_START + AVS_REPLY, NULL, 0);
	assert_int_equal(spectro_avaspec_backend.start(s.dev, &m, 2, &s.err), 0);
	int nout = fk->nout;
	spectro_avaspec_backend.close(s.dev);
	s.dev = NULL;
	assert_int_equal(fk->nout, nout + 1);
	assert_int_equal(fk->out[nout][4], AVS_CMD_STOP);
	session_close(&s);
}

static void test_config_keys(void **state)
{
	(void)state;
	struct yc_doc *doc = NULL;
	struct spectro_cfg *cfg = NULL;
	struct acq_err err = { 0 };
	static const char ok[] = "backend: avaspec-usb\nvendor_id: 0x1992\nproduct_ids: [0x0667, 0x0669]\n"
				 "serial: '1234567'\ntimeout_margin_ms: 1500\ndark_pixels: [2, 3, 4, 5]\n"
				 "ack_type: 0x21\nnonlinearity: false\n";
	assert_int_equal(yc_load_string("s.yaml", ok, strlen(ok), &doc, &err), 0);
	if (spectro_cfg_parse(yc_root(doc), &cfg, &err))
		fail_msg("%s", err.msg);
	spectro_cfg_free(cfg);
	yc_free(doc);
	static const char bad[] = "backend: avaspec-usb\nproduct_ids: [0x0667]\ntimeout_margn_ms: 3\n";
	assert_int_equal(yc_load_string("s.yaml", bad, strlen(bad), &doc, &err), 0);
	assert_int_equal(spectro_cfg_parse(yc_root(doc), &cfg, &err), -1);
	assert_non_null(strstr(err.msg, "s.yaml:3"));
	yc_free(doc);
	/* the example configuration's section */
	char path[4096];
	snprintf(path, sizeof path, "%s/config/bench-real.yaml", getenv("ACQ_SRC") ? getenv("ACQ_SRC") : ".");
	if (yc_load_file(path, &doc, &err) ||
	    spectro_cfg_parse(yc_get(yc_get(yc_root(doc), "devices"), "spectrometer"), &cfg, &err))
		fail_msg("%s", err.msg);
	spectro_cfg_free(cfg);
	yc_free(doc);
	static const char bad2[] = "backend: avaspec-usb\nack_type: 0x30\n";
	assert_int_equal(yc_load_string("s.yaml", bad2, strlen(bad2), &doc, &err), 0);
	assert_int_equal(spectro_cfg_parse(yc_root(doc), &cfg, &err), -1);
	assert_non_null(strstr(err.msg, "s.yaml:2"));
	yc_free(doc);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_frame_roundtrip_and_rejects),
		cmocka_unit_test(test_error_reasons_named),
		cmocka_unit_test(test_meascfg_pack_and_combinations),
		cmocka_unit_test(test_nonlinearity_guards),
		cmocka_unit_test_setup_teardown(test_seam_not_yet_then_split_frame, setup, teardown),
		cmocka_unit_test_setup_teardown(test_seam_timeout_scales_and_reset_follows, setup, teardown),
		cmocka_unit_test_setup_teardown(test_seam_errors_during_run, setup, teardown),
		cmocka_unit_test_setup_teardown(test_seam_open_failures, setup, teardown),
		cmocka_unit_test_setup_teardown(test_seam_close_running_mean_data_long_stop, setup, teardown),
		cmocka_unit_test(test_config_keys),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
