/* spectro_sim_proto: the wire protocol between acq-sim's spectrometer (sim/sim_spectro.c) and the "sim"
 * spectrometer backend (drivers/spectro_sim.c), over a Unix stream socket. Header-only.
 *
 * Every message, both ways, is a 16-byte header then a payload; all fields little-endian:
 *   u32 magic 0x4D495341 (bytes "ASIM") | u16 version (1) | u16 type | u32 seq | u32 payload length (<= 1 MiB)
 * A reply carries its request's seq. Requests (client → server) and replies:
 *   server on connect   0x80 HELLO     u32 protocol version, char[32] server name (seq 0)
 *   0x01 IDENTIFY (empty)  → 0x81 IDENTITY  (SSP_IDENTITY_LEN bytes)
 *        char model[32], serial[32], firmware[32]; u32 npix; f64 wl_coef[5]; u32 ndark; u32 dark[8];
 *        f64 max_counts; u32 nonlin_enabled; u32 reserved; f64 nonlin_coef[8]; f64 nonlin_low, nonlin_high;
 *        f64 temperature_c
 *   0x02 MEASURE  f64 integration_ms; u32 averages; u32 flags (bit 0: saturation detection)
 *                      → 0x82 SPECTRUM, sent when the exposure is over: (integration x averages + read-out)
 *                        bench seconds later, i.e. divided by the time scale in real time
 *        f64 device_time_s (bench); f64 temperature_c; f64 integration_ms; u32 averages; u32 npix;
 *        u32 nsaturated; u32 occlusion (bits: 1 detector in beam, 2 laser arm hides view);
 *        then f64 counts[npix] (raw ADC counts averaged, not linearised), f32 std[npix] (over the scans),
 *        u8 saturated[npix] (1 if any scan reached >= 0xFFFC)           (48 + 13 npix bytes)
 *   0x03 STOP (empty)     → 0x83 STOPPED (empty); a running measurement is dropped (no SPECTRUM)
 *   any                   → 0xFF ERROR  u32 code (SSP_E_*), u32 request type, then a message (<= 256 bytes,
 *                                         not NUL-terminated)
 * One client at a time holds the device; a second one gets ERROR SSP_E_BUSY and is closed. A MEASURE while
 * one runs gets SSP_E_PENDING. The server closes the connection when the device "disappears" (fault). */
#ifndef SPECTRO_SIM_PROTO_H
#define SPECTRO_SIM_PROTO_H

#include <stdbool.h>
#include <stdint.h>
#include <string.h>

#include "drivers/spectro.h"

#define SSP_MAGIC 0x4D495341u
#define SSP_VERSION 1
#define SSP_HDR 16
#define SSP_MAX_PAYLOAD (1u << 20)

enum ssp_type {
	SSP_IDENTIFY = 0x01, SSP_MEASURE = 0x02, SSP_STOP = 0x03,
	SSP_HELLO = 0x80, SSP_IDENTITY = 0x81, SSP_SPECTRUM = 0x82, SSP_STOPPED = 0x83, SSP_ERROR = 0xFF,
};

enum ssp_errcode { SSP_E_UNKNOWN = 1, SSP_E_BADREQ = 2, SSP_E_PENDING = 3, SSP_E_BUSY = 4, SSP_E_VERSION = 5 };

#define SSP_HELLO_LEN 36
#define SSP_IDENTITY_LEN 288
#define SSP_MEASURE_LEN 16
#define SSP_SPECTRUM_FIXED 48
#define SSP_SPECTRUM_LEN(npix) (SSP_SPECTRUM_FIXED + 13u * (uint32_t)(npix))

static inline void ssp_put32(unsigned char *p, uint32_t v)
{
	for (int i = 0; i < 4; i++)
		p[i] = (unsigned char)(v >> (8 * i));
}

static inline void ssp_put16(unsigned char *p, uint16_t v)
{
	p[0] = (unsigned char)v;
	p[1] = (unsigned char)(v >> 8);
}

static inline uint32_t ssp_get32(const unsigned char *p)
{
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static inline uint16_t ssp_get16(const unsigned char *p)
{
	return (uint16_t)(p[0] | p[1] << 8);
}

static inline void ssp_putd(unsigned char *p, double d)
{
	uint64_t u;
	memcpy(&u, &d, 8);
	ssp_put32(p, (uint32_t)u);
	ssp_put32(p + 4, (uint32_t)(u >> 32));
}

static inline double ssp_getd(const unsigned char *p)
{
	uint64_t u = (uint64_t)ssp_get32(p) | (uint64_t)ssp_get32(p + 4) << 32;
	double d;
	memcpy(&d, &u, 8);
	return d;
}

static inline void ssp_putf(unsigned char *p, float f)
{
	uint32_t u;
	memcpy(&u, &f, 4);
	ssp_put32(p, u);
}

static inline float ssp_getf(const unsigned char *p)
{
	uint32_t u = ssp_get32(p);
	float f;
	memcpy(&f, &u, 4);
	return f;
}

/* Write a header at p. */
static inline void ssp_header(unsigned char *p, unsigned type, uint32_t seq, uint32_t len)
{
	ssp_put32(p, SSP_MAGIC);
	ssp_put16(p + 4, SSP_VERSION);
	ssp_put16(p + 6, (uint16_t)type);
	ssp_put32(p + 8, seq);
	ssp_put32(p + 12, len);
}

/* Decode an IDENTITY payload into info and the sensor temperature; validates every field. 0 or -1 with err
 * (drivers/spectro_sim.c). */
int ssp_parse_identity(const unsigned char *p, uint32_t len, struct spectro_info *info, double *temperature,
		       struct acq_err *err);
/* Decode a SPECTRUM payload for the device described by info into f (linearised when linearise and the
 * device has nonlinearity coefficients); f->meas is left to the caller. 0 or -1 with err. */
int ssp_parse_spectrum(const unsigned char *p, uint32_t len, const struct spectro_info *info, bool linearise,
		       struct spectro_frame *f, struct acq_err *err);

#endif
