/* spectro: the spectrometer interface, a const table of functions behind an opaque handle.
 * Backends: "avaspec-usb" (libusb-1.0, drivers/avaspec*.c), "sim" (talks to acq-sim, drivers/spectro_sim.c) and
 * "fake" (no device, for unit tests: drivers/spectro_fake.c).
 *
 * A measurement never blocks the caller's loop: spectro_start() sends the request, then spectro_fetch() is
 * called (from a timer) until it returns 1 (frame ready), 0 (not yet), or -1 (error). Timeouts scale with
 * integration time × averages. Libraries do not log: every failure fills struct acq_err. */
#ifndef SPECTRO_H
#define SPECTRO_H

#include <stdbool.h>
#include <stddef.h>

#include "config/acq_err.h"
#include "config/yconf.h"

#define SPECTRO_MAX_PIXELS 4096
#define SPECTRO_SATURATED 0xFFFC  /* raw counts at or above this are saturated */

struct spectro;
struct spectro_cfg;

struct spectro_info {
	char model[64], serial[64], firmware[64];
	int npix;
	double wl_coef[5];         /* λ(p) = c0 + c1 p + ... + c4 p⁴, nm */
	bool nonlin_enabled;
	double nonlin_coef[8];
	double nonlin_low, nonlin_high;
	int ndark_pixels;
	int dark_pixels[8];        /* optically black pixels (dark-level estimate) */
	double max_counts;         /* full scale, e.g. 65535 */
};

struct spectro_meas {
	double integration_ms;
	unsigned averages;         /* ≥ 1 */
	bool saturation_detection;
};

struct spectro_frame {
	int npix;
	double counts[SPECTRO_MAX_PIXELS];  /* corrected counts (averaged), per pixel */
	float stddev[SPECTRO_MAX_PIXELS];   /* per-pixel standard deviation over the averages (0 if unknown) */
	unsigned char saturated[SPECTRO_MAX_PIXELS];
	int nsaturated;
	double device_time_s;      /* device time stamp */
	double temperature_c;      /* sensor temperature (NaN if unknown) */
	bool nonlin_applied, dark_pixel_corrected;
	double dark_pixel_level;   /* mean of the optically black pixels (counts), subtracted if corrected */
	struct spectro_meas meas;  /* what was measured */
};

/* Parse the `spectrometer` section. Allocates *out. 0 or -1 with file:line:col. */
int spectro_cfg_parse(struct yc_node *node, struct spectro_cfg **out, struct acq_err *err);
/* Free a parsed configuration. */
void spectro_cfg_free(struct spectro_cfg *cfg);

/* Open the backend named in cfg (which must outlive the handle), identify the device and read its
 * configuration. 0 or -1. */
int spectro_open(const struct spectro_cfg *cfg, struct spectro **out, struct acq_err *err);
/* Stop any measurement, release the device, free. NULL is fine. */
void spectro_close(struct spectro *s);
/* Device identity and calibration read at open. */
const struct spectro_info *spectro_info(const struct spectro *s);
/* Wavelength of pixel p in nm from the calibration polynomial. */
double spectro_wavelength(const struct spectro_info *info, int pixel);
/* Start one measurement (prepare + start). 0 or -1. */
int spectro_start(struct spectro *s, const struct spectro_meas *m, double now, struct acq_err *err);
/* Poll for the result: 1 frame filled, 0 not ready (call again), -1 error (timeout, device error, gone). */
int spectro_fetch(struct spectro *s, struct spectro_frame *frame, double now, struct acq_err *err);
/* Abort a running measurement. 0 or -1. */
int spectro_stop(struct spectro *s, struct acq_err *err);
/* A file descriptor that becomes readable when spectro_fetch() may progress, or -1 (then poll by timer). */
int spectro_pollfd(const struct spectro *s);

#endif
