/* store_nexus: read-only access to one sweep of the acquisitiond database for exports (NeXus/HDF5): the sweep
 * and its spectrometer, points, spectra by kind, calibrated samples, devices and events, streamed row by row
 * through callbacks. Same checks as the store (application_id, schema version); opens read-only. */
#ifndef DAEMON_STORE_NEXUS_H
#define DAEMON_STORE_NEXUS_H

#include <stdint.h>

#include "config/acq_err.h"

struct storenx;

struct storenx_sweep {
	int64_t id, points_total;
	char *name, *state, *plan_text, *config_snapshot, *software_version, *calibration_method; /* may be NULL */
	double created_at, started_at, finished_at; /* Unix s; NAN when not set */
	float *grid;                                /* wavelength grid of the calibrated samples (nm), or NULL */
	int ngrid;
	int has_spectrometer, npix;
	char *sp_model, *sp_serial, *sp_firmware, *sp_nonlinearity;
	double sp_coef[5];                          /* λ(p) = c0 + c1 p + ... + c4 p⁴ */
};

struct storenx_point {
	int64_t id;
	int order_index;
	double planned[4];  /* θi, φi, θo, φo, degrees */
	double actual[3];   /* laser_theta, detector_theta, detector_phi, degrees (NAN: not reached) */
	double measured[4]; /* θi, φi, θo, φo actually measured, sample frame, degrees (NAN: not done) */
	const char *state;
	double done_at;     /* NAN when not done */
};

struct storenx_spectrum {
	int64_t id, point_id;     /* point_id −1 when not tied to a point */
	const char *kind;
	double integration_ms, temperature_c, taken_at; /* temperature NAN when unknown */
	int averages, npix, saturated_count;
	const float *counts;      /* [npix] */
	const float *stddev;      /* [npix] or NULL */
};

struct storenx_calibrated {
	int64_t point_id;
	int n;
	const float *brdf, *sigma; /* [n] */
};

struct storenx_event {
	int64_t id;
	double at;
	const char *kind, *device, *message; /* device may be NULL */
};

struct storenx_device {
	const char *name, *vendor, *model, *serial, *firmware;
};

/* Open read-only; refuses a file that is not an acquisitiond database of schema version 1. 0, or -1. */
int storenx_open(const char *path, struct storenx **out, struct acq_err *err);
/* Close (NULL is fine). */
void storenx_close(struct storenx *h);
/* The sweep row and its spectrometer (free with storenx_sweep_free). ACQ_E_NOTFOUND if there is none. */
int storenx_sweep_get(struct storenx *h, int64_t id, struct storenx_sweep *s, struct acq_err *err);
/* Release the strings and grid of s. */
void storenx_sweep_free(struct storenx_sweep *s);
/* Rows of a sweep: what = "points", "calibrated", "events", "devices", or a spectrum kind ("sample", "dark",
 * "reference", "beam"); *n receives the count. 0, or -1 with err. */
int storenx_count(struct storenx *h, int64_t id, const char *what, int64_t *n, struct acq_err *err);
/* Stream the rows (the pointers are valid during the call only); fn returns 0 to go on, else stops the scan
 * and its value is returned. Points in execution order, spectra/events by id, calibrated by point order. */
int storenx_points(struct storenx *h, int64_t id, int (*fn)(void *, const struct storenx_point *), void *ctx,
		   struct acq_err *err);
int storenx_spectra(struct storenx *h, int64_t id, const char *kind, int (*fn)(void *, const struct storenx_spectrum *),
		    void *ctx, struct acq_err *err);
int storenx_calibrated(struct storenx *h, int64_t id, int (*fn)(void *, const struct storenx_calibrated *), void *ctx,
		       struct acq_err *err);
int storenx_events(struct storenx *h, int64_t id, int (*fn)(void *, const struct storenx_event *), void *ctx,
		   struct acq_err *err);
int storenx_devices(struct storenx *h, int64_t id, int (*fn)(void *, const struct storenx_device *), void *ctx,
		    struct acq_err *err);

#endif
