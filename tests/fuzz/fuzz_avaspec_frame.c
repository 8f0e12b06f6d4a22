/* Fuzz target for the AvaSpec protocol: arbitrary device bytes through the frame parser and decoders, and as
 * a stream of USB transfers into a running session (open with a valid 64-pixel device, start, fetch).
 * Input: byte 0 selects the mode (even: one frame; odd: session). Session input after byte 0 is a list of
 * transfers, each a 2-byte big-endian length then that many bytes (length 0: "nothing yet").
 * Corpus: tests/fuzz/corpus/fuzz_avaspec_frame/ (written by tests/fuzz/corpus/gen_avaspec_corpus.py). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "drivers/avaspec.h"
#include "drivers/avaspec_proto.h"
#include "drivers/spectro_backend.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define FZ_NPIX 64

struct fz {
	const uint8_t *p;
	size_t n;
	int phase;        /* 0: canned open replies, 1: fuzz stream */
	int canned;
	uint8_t *cfgrec;
};

static int fz_write(void *ctx, const uint8_t *buf, size_t n, int timeout_ms, struct acq_err *err)
{
	(void)ctx; (void)buf; (void)n; (void)timeout_ms; (void)err;
	return 0;
}

static int fz_read(void *ctx, uint8_t *buf, size_t cap, int timeout_ms, struct acq_err *err)
{
	(void)timeout_ms; (void)err;
	struct fz *f = ctx;
	if (f->phase == 0) {
		/* stop reply, identity, configuration (in AVS_CHUNK transfers), prepare, start */
		static const uint8_t stop[] = { 0x21, 0, 2, 0, 0x8F, 0 };
		static uint8_t id[AVS_HDR + AVS_IDENT_LEN];
		static uint8_t cfg[AVS_HDR + AVS_DEVCFG_LEN];
		avs_frame(id, sizeof id, 0x21, 0, 0x93, (const uint8_t[AVS_IDENT_LEN]){ 'F' }, AVS_IDENT_LEN, NULL);
		avs_frame(cfg, sizeof cfg, 0x21, 0, 0x81, f->cfgrec, AVS_DEVCFG_LEN, NULL);
		static const uint8_t prep[] = { 0x21, 0, 2, 0, 0x85, 0 }, start[] = { 0x21, 0, 2, 0, 0x86, 0 };
		int k = f->canned++;
		const uint8_t *src;
		size_t len;
		if (k == 0) { src = stop; len = sizeof stop; }
		else if (k == 1) { src = id; len = sizeof id; }
		else if (k >= 2 && k <= 5) {
			size_t off = (size_t)(k - 2) * AVS_CHUNK;
			src = cfg + off;
			len = sizeof cfg - off < AVS_CHUNK ? sizeof cfg - off : AVS_CHUNK;
			if (k == 5)
				f->canned = 100;
		} else if (k == 100) { src = prep; len = sizeof prep; }
		else { src = start; len = sizeof start; f->phase = 1; }
		if (len > cap)
			len = cap;
		memcpy(buf, src, len);
		return (int)len;
	}
	if (f->n < 2)
		return acq_errf(err, ACQ_E_DISCONNECTED, "end of input");
	size_t len = ((size_t)f->p[0] << 8) | f->p[1];
	f->p += 2;
	f->n -= 2;
	if (len > f->n)
		len = f->n;
	if (len > cap)
		len = cap;
	memcpy(buf, f->p, len);
	f->p += len;
	f->n -= len;
	return (int)len;
}

static void fz_close(void *ctx)
{
	(void)ctx;
}

static void one_frame(const uint8_t *p, size_t n)
{
	struct avs_msg m;
	struct acq_err err;
	if (avs_frame_need(p, n) != n || avs_parse(p, n, &m, &err))
		return;
	(void)avs_expect_reply(&m, AVS_CMD_PREPARE, &err);
	struct avs_identity id;
	(void)avs_parse_identity(m.payload, m.plen, &id, &err);
	struct avs_devcfg dc;
	(void)avs_parse_devcfg(m.payload, m.plen, &dc, &err);
	static double counts[SPECTRO_MAX_PIXELS];
	static unsigned char sat[SPECTRO_MAX_PIXELS];
	int nsat;
	double t;
	int guesses[4] = { (int)(m.plen / 2) - 2, (int)(m.plen / 4) - 1, FZ_NPIX, 1 };
	for (int i = 0; i < 4; i++)
		for (unsigned avg = 1; avg <= 4; avg *= 4)
			if (guesses[i] >= 1 && guesses[i] <= SPECTRO_MAX_PIXELS &&
			    avs_decode_data(&m, guesses[i], avg, avg == 1, counts, sat, &nsat, &t, &err) == 0)
				for (int k = 0; k < guesses[i]; k++)
					if (!isfinite(counts[k]))
						abort();
}

static void session(const uint8_t *p, size_t n)
{
	static uint8_t rec[AVS_DEVCFG_LEN];
	rec[AVS_CFG_OFF_NPIX] = 0;
	rec[AVS_CFG_OFF_NPIX + 1] = FZ_NPIX;
	rec[AVS_CFG_OFF_NL_ENABLE] = 1;
	struct fz f = { .p = p, .n = n, .cfgrec = rec };
	struct avs_transport t = { .ctx = &f, .write = fz_write, .read = fz_read, .close = fz_close };
	static const char yaml[] = "backend: avaspec-usb\ndark_pixels: [1, 2]\nmax_stale_messages: 2\n";
	struct yc_doc *doc = NULL;
	struct acq_err err;
	void *cfg = NULL, *dev = NULL;
	struct spectro_info info;
	if (yc_load_string("f.yaml", yaml, sizeof yaml - 1, &doc, &err) ||
	    spectro_avaspec_backend.cfg_parse(yc_root(doc), &cfg, &err))
		abort();
	if (avs_open_transport(cfg, &t, &dev, &info, &err) == 0) {
		struct spectro_meas m = { .integration_ms = 1, .averages = 1 };
		static struct spectro_frame fr;
		if (spectro_avaspec_backend.start(dev, &m, 0, &err) == 0) {
			for (int i = 0; i < 64; i++) {
				int rc = spectro_avaspec_backend.fetch(dev, &fr, 0, &err);
				if (rc == 1)
					for (int k = 0; k < fr.npix; k++)
						if (!isfinite(fr.counts[k]))
							abort();
				if (rc != 0)
					break;
			}
		}
		spectro_avaspec_backend.close(dev);
	}
	spectro_avaspec_backend.cfg_free(cfg);
	yc_free(doc);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (size < 1)
		return 0;
	if (data[0] & 1)
		session(data + 1, size - 1);
	else
		one_frame(data + 1, size - 1);
	return 0;
}
