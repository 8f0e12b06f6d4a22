/* avaspec_proto: pure AvaSpec framing, parsing and corrections (no I/O); conventions in avaspec_proto.h. */
#include "drivers/avaspec_proto.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static uint16_t be16(const uint8_t *p)
{
	return (uint16_t)((p[0] << 8) | p[1]);
}

static uint32_t be32(const uint8_t *p)
{
	return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | p[3];
}

static uint64_t be64(const uint8_t *p)
{
	return ((uint64_t)be32(p) << 32) | be32(p + 4);
}

static float bef32(const uint8_t *p)
{
	uint32_t u = be32(p);
	float f;
	memcpy(&f, &u, sizeof f);
	return f;
}

static double bef64(const uint8_t *p)
{
	uint64_t u = be64(p);
	double d;
	memcpy(&d, &u, sizeof d);
	return d;
}

static void put16(uint8_t *p, uint16_t v)
{
	p[0] = (uint8_t)(v >> 8);
	p[1] = (uint8_t)v;
}

static void put32(uint8_t *p, uint32_t v)
{
	p[0] = (uint8_t)(v >> 24);
	p[1] = (uint8_t)(v >> 16);
	p[2] = (uint8_t)(v >> 8);
	p[3] = (uint8_t)v;
}

static void putf32(uint8_t *p, float f)
{
	uint32_t u;
	memcpy(&u, &f, sizeof u);
	put32(p, u);
}

const char *avs_reason_name(int reason)
{
	static const char *const names[AVS_R__COUNT] = {
		"unknown error", "invalid parameter", "invalid password", "invalid command", "invalid size",
		"measurement pending", "invalid pixel range", "invalid integration time", "not supported",
		"invalid combination", "no buffer", "no spectra", "invalid state",
	};
	if (reason >= 0 && reason < AVS_R__COUNT)
		return names[reason];
	return "undocumented reason";
}

int avs_frame(uint8_t *out, size_t cap, uint8_t type, uint8_t seq, uint8_t cmd, const uint8_t *payload,
	      size_t plen, struct acq_err *err)
{
	if (plen > 65533 || cap < AVS_HDR + plen)
		return acq_errf(err, ACQ_E_RANGE, "avaspec: frame of %zu payload bytes does not fit", plen);
	out[0] = type;
	out[1] = seq;
	out[2] = (uint8_t)((plen + 2) & 0xff);
	out[3] = (uint8_t)((plen + 2) >> 8);
	out[4] = cmd;
	out[5] = 0;
	if (plen)
		memcpy(out + AVS_HDR, payload, plen);
	return (int)(AVS_HDR + plen);
}

size_t avs_frame_need(const uint8_t *buf, size_t n)
{
	if (n < 4)
		return 0;
	return 4 + (size_t)(buf[2] | (buf[3] << 8));
}

int avs_parse(const uint8_t *buf, size_t n, struct avs_msg *msg, struct acq_err *err)
{
	if (n < AVS_HDR)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: frame of %zu bytes is shorter than its %d-byte header", n,
				AVS_HDR);
	size_t need = avs_frame_need(buf, n);
	if (need < AVS_HDR)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: length field %zu is below the minimum 2", need - 4);
	if (need != n)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: frame has %zu bytes but its length field says %zu", n,
				need);
	if (buf[0] != AVS_TYPE_DEV && buf[0] != AVS_TYPE_HOST)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: unknown frame type 0x%02x", buf[0]);
	if (buf[5] != 0)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: byte 5 is 0x%02x, expected 0x00", buf[5]);
	msg->type = buf[0];
	msg->seq = buf[1];
	msg->cmd = buf[4];
	msg->payload = buf + AVS_HDR;
	msg->plen = n - AVS_HDR;
	return 0;
}

int avs_expect_reply(const struct avs_msg *msg, uint8_t cmd, struct acq_err *err)
{
	if (msg->type != AVS_TYPE_DEV)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: reply to 0x%02x has type 0x%02x, expected 0x21", cmd,
				msg->type);
	if (msg->cmd == AVS_CMD_ERROR) {
		if (msg->plen != 1)
			return acq_errf(err, ACQ_E_PROTO, "avaspec: error reply to 0x%02x has %zu payload bytes, "
					"expected 1", cmd, msg->plen);
		int r = msg->payload[0];
		acq_errf(err, ACQ_E_DEVICE, "avaspec: device refused command 0x%02x: %s (reason %d)", cmd,
			 avs_reason_name(r), r);
		if (err)
			err->detail = r + 1;
		return -1;
	}
	if (msg->cmd != (uint8_t)(cmd + AVS_REPLY))
		return acq_errf(err, ACQ_E_PROTO, "avaspec: expected reply 0x%02x to command 0x%02x, got 0x%02x",
				(uint8_t)(cmd + AVS_REPLY), cmd, msg->cmd);
	return 0;
}

static void copy_text(char *dst, size_t cap, const uint8_t *src, size_t n)
{
	size_t k = 0;
	for (; k < n && k + 1 < cap && src[k]; k++)
		dst[k] = (src[k] >= 0x20 && src[k] < 0x7f) ? (char)src[k] : '?';
	dst[k] = '\0';
}

int avs_parse_identity(const uint8_t *p, size_t n, struct avs_identity *id, struct acq_err *err)
{
	if (n != AVS_IDENT_LEN)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: identity reply has %zu bytes, expected %d", n,
				AVS_IDENT_LEN);
	copy_text(id->serial, sizeof id->serial, p, 10);
	copy_text(id->name, sizeof id->name, p + 10, 64);
	id->status = p[74];
	return 0;
}

int avs_parse_devcfg(const uint8_t *p, size_t n, struct avs_devcfg *cfg, struct acq_err *err)
{
	if (n != AVS_DEVCFG_LEN)
		return acq_errf(err, ACQ_E_PROTO, "avaspec: device configuration has %zu bytes, expected %d", n,
				AVS_DEVCFG_LEN);
	memset(cfg, 0, sizeof *cfg);
	cfg->sensor_type = p[AVS_CFG_OFF_SENSOR];
	cfg->npix = be16(p + AVS_CFG_OFF_NPIX);
	if (cfg->npix < 1 || cfg->npix > SPECTRO_MAX_PIXELS)
		return acq_errf(err, ACQ_E_UNSUPPORTED, "avaspec: device reports %d pixels (supported: 1..%d)",
				cfg->npix, SPECTRO_MAX_PIXELS);
	for (int i = 0; i < 5; i++) {
		cfg->wl_coef[i] = bef32(p + AVS_CFG_OFF_FIT + 4 * i);
		if (!isfinite(cfg->wl_coef[i]))
			return acq_errf(err, ACQ_E_PROTO, "avaspec: wavelength coefficient %d is not finite", i);
	}
	cfg->nl_enabled = p[AVS_CFG_OFF_NL_ENABLE] != 0;
	for (int i = 0; i < 8; i++)
		cfg->nl_coef[i] = bef64(p + AVS_CFG_OFF_NL_COEF + 8 * i);
	cfg->nl_low = bef64(p + AVS_CFG_OFF_NL_LOW);
	cfg->nl_high = bef64(p + AVS_CFG_OFF_NL_HIGH);
	return 0;
}

void avs_meascfg_pack(const struct avs_meascfg *m, uint8_t out[AVS_MEASCFG_LEN])
{
	uint8_t *p = out;
	put16(p, m->start_pixel); p += 2;
	put16(p, m->stop_pixel); p += 2;
	putf32(p, m->integration_ms); p += 4;
	put32(p, m->integration_delay); p += 4;
	put32(p, m->averages); p += 4;
	*p++ = m->dark_enable;
	*p++ = m->dark_forget;
	put16(p, m->smooth_pix); p += 2;
	*p++ = m->smooth_model;
	*p++ = m->saturation;
	*p++ = m->trig_mode;
	*p++ = m->trig_source;
	*p++ = m->trig_source_type;
	put16(p, m->strobe); p += 2;
	put32(p, m->laser_delay); p += 4;
	put32(p, m->laser_width); p += 4;
	putf32(p, m->laser_wavelength); p += 4;
	put16(p, m->store_to_ram); p += 2;
}

int avs_meascfg_check(const struct avs_meascfg *m, struct acq_err *err)
{
	if (m->stop_pixel < m->start_pixel)
		return acq_errf(err, ACQ_E_INVAL, "avaspec: stop pixel %u before start pixel %u", m->stop_pixel,
				m->start_pixel);
	if (!(m->integration_ms > 0) || m->integration_ms > 600000.0f)
		return acq_errf(err, ACQ_E_INVAL, "avaspec: integration time %g ms outside (0, 600000]",
				(double)m->integration_ms);
	if (m->averages < 1)
		return acq_errf(err, ACQ_E_INVAL, "avaspec: averages must be ≥ 1");
	if (m->saturation > 2)
		return acq_errf(err, ACQ_E_INVAL, "avaspec: saturation detection %u (expected 0, 1 or 2)", m->saturation);
	if (m->saturation == 2 && m->averages > 1)
		return acq_errf(err, ACQ_E_INVAL, "avaspec: saturation detection with peak inversion cannot be "
				"combined with averaging");
	if (m->store_to_ram && (m->averages > 1 || m->trig_source == 1 || m->trig_source_type == 1))
		return acq_errf(err, ACQ_E_INVAL, "avaspec: store-to-RAM cannot be combined with averaging, sync "
				"or level trigger");
	if (m->integration_ms >= 600000.0f && m->averages > 5000)
		return acq_errf(err, ACQ_E_INVAL, "avaspec: 600000 ms integration allows at most 5000 averages");
	return 0;
}

int avs_decode_data(const struct avs_msg *msg, int npix, unsigned averages, bool avg_is_sum, double *counts,
		    unsigned char *saturated, int *nsaturated, double *time_s, struct acq_err *err)
{
	const uint8_t *p = msg->payload;
	size_t n = msg->plen, np = (size_t)npix;
	if (npix < 1 || npix > SPECTRO_MAX_PIXELS || averages < 1)
		return acq_errf(err, ACQ_E_INVAL, "avaspec: decoding for %d pixels and %u averages", npix, averages);
	*nsaturated = 0;
	if (msg->cmd == AVS_CMD_DATA_SINGLE) {
		if (n != 4 + 2 * np)
			return acq_errf(err, ACQ_E_PROTO, "avaspec: single-scan data has %zu bytes (%s), expected %zu "
					"for %d pixels", n, n < 4 + 2 * np ? "short" : "oversized", 4 + 2 * np, npix);
		if (averages != 1)
			return acq_errf(err, ACQ_E_PROTO, "avaspec: single-scan data (0xB0) for a measurement of %u "
					"averages", averages);
		*time_s = be32(p) * 1e-5;
		for (size_t i = 0; i < np; i++) {
			uint16_t v = be16(p + 4 + 2 * i);
			counts[i] = v;
			saturated[i] = v >= SPECTRO_SATURATED;
			*nsaturated += saturated[i];
		}
		return 0;
	}
	if (msg->cmd == AVS_CMD_DATA_AVG) {
		size_t off;
		if (n == 4 + 4 * np) {
			off = 4;
		} else if (n == 6 + 4 * np) {
			off = 6;
			unsigned dev_avg = be16(p + 4);
			if (dev_avg != averages)
				return acq_errf(err, ACQ_E_PROTO, "avaspec: averaged data says %u averages, %u were asked",
						dev_avg, averages);
		} else {
			return acq_errf(err, ACQ_E_PROTO, "avaspec: averaged data has %zu bytes (%s), expected %zu or "
					"%zu for %d pixels", n, n < 4 + 4 * np ? "short" : "oversized", 4 + 4 * np,
					6 + 4 * np, npix);
		}
		*time_s = be32(p) * 1e-5;
		for (size_t i = 0; i < np; i++) {
			double v = (double)be32(p + off + 4 * i) / (avg_is_sum ? averages : 1);
			if (v > 65535.0)
				return acq_errf(err, ACQ_E_PROTO, "avaspec: averaged pixel %zu is %g counts, above the "
						"16-bit full scale (%s of %u scans expected)", i, v,
						avg_is_sum ? "sum" : "mean", averages);
			counts[i] = v;
			saturated[i] = v >= SPECTRO_SATURATED;
			*nsaturated += saturated[i];
		}
		return 0;
	}
	return acq_errf(err, ACQ_E_PROTO, "avaspec: expected a data message (0xB0/0xB1), got command 0x%02x",
			msg->cmd);
}

bool avs_dark_correct(double *counts, int npix, const int *dark, int ndark, double *level)
{
	double sum = 0;
	int k = 0;
	for (int i = 0; i < ndark; i++) {
		if (dark[i] < 0 || dark[i] >= npix)
			continue;
		sum += counts[dark[i]];
		k++;
	}
	if (!k)
		return false;
	*level = sum / k;
	for (int i = 0; i < npix; i++)
		counts[i] -= *level;
	return true;
}

bool avs_nonlin_correct(double *counts, int npix, const double coef[8], double low, double high)
{
	bool any = false;
	for (int i = 0; i < 8; i++) {
		if (!isfinite(coef[i]))
			return false;
		any |= coef[i] != 0;
	}
	if (!any)
		return false;
	bool clamp = isfinite(low) && isfinite(high) && low < high;
	for (int i = 0; i < npix; i++) {
		double c = counts[i], x = c;
		if (clamp)
			x = x < low ? low : x > high ? high : x;
		double poly = 0;
		for (int k = 7; k >= 0; k--)
			poly = poly * x + coef[k];
		/* A factor that is not finite or not clearly positive would make the value meaningless or
		 * infinite: leave the pixel as measured. */
		if (isfinite(poly) && poly > 1e-6)
			counts[i] = c / poly;
	}
	return true;
}
