/* avaspec: the transport seam of the "avaspec-usb" backend (internal to drivers/ and its tests).
 * The protocol logic talks to a transport (write / read with timeout); the real one is libusb-1.0 bulk
 * transfers, tests may plug an in-memory one to reach cases umockdev cannot replay ("no data yet"). */
#ifndef AVASPEC_H
#define AVASPEC_H

#include <stddef.h>
#include <stdint.h>

#include "drivers/spectro.h"

/* Bytes asked of the device per IN read: a multiple of the 512-byte packet size, one usbfs URB. */
#define AVS_CHUNK 16384

struct avs_transport {
	void *ctx;
	/* Send n bytes as one transfer. 0 or -1 (ACQ_E_DISCONNECTED when the device is gone). */
	int (*write)(void *ctx, const uint8_t *buf, size_t n, int timeout_ms, struct acq_err *err);
	/* Receive one transfer of at most cap bytes: bytes received (0 = nothing within timeout_ms) or -1. */
	int (*read)(void *ctx, uint8_t *buf, size_t cap, int timeout_ms, struct acq_err *err);
	/* Release the link. */
	void (*close)(void *ctx);
};

/* Open the backend over an existing transport (ownership passes, closed on failure too): reset any
 * interrupted run, identify, read the device configuration. cfg is the backend state from cfg_parse.
 * 0 or -1. */
int avs_open_transport(const void *cfg, const struct avs_transport *t, void **dev, struct spectro_info *info,
		       struct acq_err *err);

#endif
