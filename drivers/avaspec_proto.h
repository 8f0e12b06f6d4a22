/* avaspec_proto: pure AvaSpec (AS5216 family) framing, parsing and spectrum corrections; no I/O, no state.
 *
 * Framing (drivers/avaspec-usb.md): byte 0 type (0x20 host→device, 0x21 device→host), byte 1 sequence number,
 * bytes 2–3 length = payload + 2 (uint16 little-endian), byte 4 command, byte 5 0x00, payload from byte 6.
 * Multi-byte payload fields are big-endian. A reply carries cmd + 0x80; an error reply has length 3, cmd 0x00
 * and the reason in byte 6.
 *
 * Our conventions where the public sheet stops (a driver must fail, not guess, outside them):
 *  - identity reply 0x93: serial char[10], user-friendly name char[64], status uint8 (75 bytes, as the
 *    vendor's AvsIdentityType).
 *  - device configuration reply 0x81: exactly AVS_DEVCFG_LEN bytes; the offsets used are the AVS_CFG_OFF_*
 *    below (the packed DeviceConfigType layout of the vendor header, fields read big-endian as the sheet says
 *    for every payload field). Everything else in the record is ignored.
 *  - data 0xB0: uint32 time stamp (10 µs ticks), then npix × uint16 counts.
 *    data 0xB1: uint32 time stamp, optionally one uint16 averages field, then npix × uint32 = the SUM of the
 *    averaged scans by default, or their mean (config averaged_data: mean); told apart by length, anything
 *    else is an error.
 *  - the data acknowledgement 0xC0 is sent with the configured type byte (default 0x20) and no payload. */
#ifndef AVASPEC_PROTO_H
#define AVASPEC_PROTO_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "drivers/spectro.h"

#define AVS_TYPE_HOST 0x20
#define AVS_TYPE_DEV 0x21
#define AVS_HDR 6                 /* bytes before the payload */
#define AVS_MAX_MSG (4 + 65535)   /* largest frame the length field can describe */

enum avs_cmd {
	AVS_CMD_ERROR = 0x00,
	AVS_CMD_GET_CONFIG = 0x01,
	AVS_CMD_PREPARE = 0x05,
	AVS_CMD_START = 0x06,
	AVS_CMD_STOP = 0x0F,
	AVS_CMD_IDENTIFY = 0x13,
	AVS_CMD_DATA_SINGLE = 0xB0,
	AVS_CMD_DATA_AVG = 0xB1,
	AVS_CMD_ACK = 0xC0,
	AVS_REPLY = 0x80,             /* added to the request's command in its reply */
};

/* The 13 error reasons of an error reply (byte 6); also stored in acq_err.detail as reason + 1. */
enum avs_reason {
	AVS_R_UNKNOWN = 0, AVS_R_INVALID_PARAMETER, AVS_R_INVALID_PASSWORD, AVS_R_INVALID_COMMAND,
	AVS_R_INVALID_SIZE, AVS_R_MEASUREMENT_PENDING, AVS_R_INVALID_PIXEL_RANGE, AVS_R_INVALID_INTEGRATION_TIME,
	AVS_R_NOT_SUPPORTED, AVS_R_INVALID_COMBINATION, AVS_R_NO_BUFFER, AVS_R_NO_SPECTRA, AVS_R_INVALID_STATE,
	AVS_R__COUNT
};

#define AVS_IDENT_LEN 75
#define AVS_DEVCFG_LEN 63484
#define AVS_MEASCFG_LEN 41

/* Offsets in the device configuration record (our convention, see the file comment). */
#define AVS_CFG_OFF_LEN 0           /* uint16 record length */
#define AVS_CFG_OFF_VERSION 2       /* uint16 */
#define AVS_CFG_OFF_NAME 4          /* char[64] user-friendly id */
#define AVS_CFG_OFF_SENSOR 68       /* uint8 sensor type */
#define AVS_CFG_OFF_NPIX 69         /* uint16 number of pixels */
#define AVS_CFG_OFF_FIT 71          /* float32[5] wavelength polynomial */
#define AVS_CFG_OFF_NL_ENABLE 91    /* uint8 */
#define AVS_CFG_OFF_NL_COEF 92      /* float64[8] */
#define AVS_CFG_OFF_NL_LOW 156      /* float64 */
#define AVS_CFG_OFF_NL_HIGH 164     /* float64 */
#define AVS_CFG_OFF_DEFECTIVE 196   /* uint16[30] defective pixels (0xFFFF or 0 = none), read but unused */

/* A parsed frame header; payload points into the caller's buffer. */
struct avs_msg {
	uint8_t type, seq, cmd;
	const uint8_t *payload;
	size_t plen;
};

struct avs_identity {
	char serial[11];
	char name[65];
	uint8_t status;
};

struct avs_devcfg {
	int sensor_type;
	int npix;
	double wl_coef[5];
	bool nl_enabled;
	double nl_coef[8];
	double nl_low, nl_high;
};

/* The measurement configuration (the 41-byte packed record). */
struct avs_meascfg {
	uint16_t start_pixel, stop_pixel;
	float integration_ms;
	uint32_t integration_delay, averages;
	uint8_t dark_enable, dark_forget;
	uint16_t smooth_pix;
	uint8_t smooth_model, saturation, trig_mode, trig_source, trig_source_type;
	uint16_t strobe;
	uint32_t laser_delay, laser_width;
	float laser_wavelength;
	uint16_t store_to_ram;
};

/* Stable name of an error reason ("invalid integration time"); "reason N" text for unknown values. */
const char *avs_reason_name(int reason);

/* Write a host frame (type, seq, cmd, payload) into out (cap bytes). Returns its length, or -1 with err. */
int avs_frame(uint8_t *out, size_t cap, uint8_t type, uint8_t seq, uint8_t cmd, const uint8_t *payload,
	      size_t plen, struct acq_err *err);
/* Bytes a frame needs in total once its first 4 bytes are known (4 + length field), or 0 if n < 4. */
size_t avs_frame_need(const uint8_t *buf, size_t n);
/* Parse exactly one complete frame of n bytes. 0, or -1 with a protocol error naming what is wrong. */
int avs_parse(const uint8_t *buf, size_t n, struct avs_msg *msg, struct acq_err *err);
/* Check msg is the reply to cmd: an error reply becomes ACQ_E_DEVICE with the named reason (detail =
 * reason + 1); anything else that is not type 0x21/cmd+0x80 becomes ACQ_E_PROTO. 0 or -1. */
int avs_expect_reply(const struct avs_msg *msg, uint8_t cmd, struct acq_err *err);

/* Parse the identity payload. 0 or -1. */
int avs_parse_identity(const uint8_t *p, size_t n, struct avs_identity *id, struct acq_err *err);
/* Parse the device configuration payload (must be exactly AVS_DEVCFG_LEN bytes; npix in 1..max). 0 or -1. */
int avs_parse_devcfg(const uint8_t *p, size_t n, struct avs_devcfg *cfg, struct acq_err *err);
/* Serialise a measurement configuration into 41 bytes (big-endian fields). */
void avs_meascfg_pack(const struct avs_meascfg *m, uint8_t out[AVS_MEASCFG_LEN]);
/* Check the documented invalid combinations before sending. 0 or -1 (ACQ_E_INVAL). */
int avs_meascfg_check(const struct avs_meascfg *m, struct acq_err *err);

/* Decode a data message (0xB0 or 0xB1) for npix pixels into raw per-scan mean counts (double[npix]),
 * the per-pixel saturation flags (a scan mean ≥ SPECTRO_SATURATED) and the time stamp in seconds.
 * averages is what was asked for; avg_is_sum says whether 0xB1 values are sums (else means).
 * Exact lengths only; a mean above 16-bit full scale is an error. 0 or -1 (ACQ_E_PROTO). */
int avs_decode_data(const struct avs_msg *msg, int npix, unsigned averages, bool avg_is_sum, double *counts,
		    unsigned char *saturated, int *nsaturated, double *time_s, struct acq_err *err);

/* Dark-pixel correction: mean of the listed pixels subtracted from every pixel; returns the level via *level.
 * Indices outside [0, npix) are skipped; false when no usable pixel. */
bool avs_dark_correct(double *counts, int npix, const int *dark, int ndark, double *level);
/* Nonlinearity correction (Avantes style): c ← c / P(c), P the 8-coefficient polynomial evaluated at c
 * clamped to [low, high]. Returns false (counts untouched) when every coefficient is zero or P is not
 * finite and positive over the range used: a zero or broken calibration never makes infinities. */
bool avs_nonlin_correct(double *counts, int npix, const double coef[8], double low, double high);

#endif
