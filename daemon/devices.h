/* devices: the daemon's device instances (three arm axes, spectrometer, laser) — opened at start without
 * requiring any to be present, reconnected on a timer while absent, reported by state; plus manual
 * move/measure used by the `move`, `measure`, `dark`, `reference` commands. The sweep executor takes the
 * handles from here and reports faults with devices_lost(). */
#ifndef DEVICES_H
#define DEVICES_H

#include <jansson.h>
#include <stdbool.h>

#include "config/acq_err.h"
#include "daemon/conf.h"

struct loop;
struct store;
struct devices;
struct axis;
struct spectro;
struct laser;

struct axis_cfg;
struct spectro_cfg;
struct laser_cfg;
struct axis_status;
struct axis_identity;
struct spectro_info;
struct spectro_meas;
struct spectro_frame;
struct laser_status;
struct laser_identity;

/* The driver entry points devices.c calls: the real drivers (devices_real_drv) unless a test substitutes
 * fakes. The sweep executor calls the drivers directly on the handles it gets from devices_axis() etc. */
struct devices_drv {
	int (*axis_open)(const struct axis_cfg *cfg, struct axis **out, struct acq_err *err);
	void (*axis_close)(struct axis *ax);
	void (*axis_cfg_limits)(const struct axis_cfg *cfg, double *min_deg, double *max_deg);
	int (*axis_read_status)(struct axis *ax, struct axis_status *st, struct acq_err *err);
	int (*axis_move_begin)(struct axis *ax, double target_deg, double now, struct acq_err *err);
	int (*axis_move_step)(struct axis *ax, double now, struct acq_err *err);
	int (*axis_stop)(struct axis *ax, struct acq_err *err);
	int (*axis_identity)(struct axis *ax, struct axis_identity *id, struct acq_err *err);
	int (*spectro_open)(const struct spectro_cfg *cfg, struct spectro **out, struct acq_err *err);
	void (*spectro_close)(struct spectro *s);
	const struct spectro_info *(*spectro_info)(const struct spectro *s);
	int (*spectro_start)(struct spectro *s, const struct spectro_meas *m, double now, struct acq_err *err);
	int (*spectro_fetch)(struct spectro *s, struct spectro_frame *frame, double now, struct acq_err *err);
	int (*spectro_stop)(struct spectro *s, struct acq_err *err);
	int (*laser_open)(const struct laser_cfg *cfg, struct laser **out, struct acq_err *err);
	void (*laser_close)(struct laser *l);
	int (*laser_set_emission)(struct laser *l, bool on, struct acq_err *err);
	int (*laser_set_power)(struct laser *l, double pct, struct acq_err *err);
	int (*laser_status)(struct laser *l, struct laser_status *st, struct acq_err *err);
	const struct laser_identity *(*laser_identity)(const struct laser *l);
	int (*axis_home_begin)(struct axis *ax, double now, struct acq_err *err);
	int (*axis_alarm_reset)(struct axis *ax, struct acq_err *err);
};
extern const struct devices_drv devices_real_drv;

/* Called on the loop when a device becomes available (up) or unavailable, with a reason. */
typedef void (*devices_notify_fn)(void *ctx, enum conf_dev dev, bool up, const char *why);

/* Open every configured device with drv (NULL: the real drivers); failures leave it unavailable and retried
 * (one absent device per daemon.device_retry_s, in turn). The configuration must outlive the devices. 0 or -1 (only out of memory). */
int devices_init(struct loop *lp, struct store *st, const struct conf *c, const struct devices_drv *drv,
		 devices_notify_fn notify, void *ctx, double (*wallclock)(void), struct devices **out,
		 struct acq_err *err);
/* After a reload: safe stop, close every device, reopen from c (which must outlive the devices). The object
 * (and the pointer the executor holds) stays. 0, or -1 with ACQ_E_STATE while a manual operation runs. */
int devices_reconfigure(struct devices *dv, const struct conf *c, struct acq_err *err);
/* Safe stop (laser off, arms stopped), close every device, free. NULL is fine. */
void devices_finish(struct devices *dv);
/* Laser emission off and every arm stopped, best effort; returns the number of failures. */
int devices_safe_stop(struct devices *dv);

/* The open axis of slot d (CONF_DEV_LASER_THETA..DETECTOR_PHI), or NULL when unavailable. */
struct axis *devices_axis(struct devices *dv, enum conf_dev d);
/* The open spectrometer, or NULL. */
struct spectro *devices_spectro(struct devices *dv);
/* The open laser, or NULL. */
struct laser *devices_laser(struct devices *dv);
/* Database id of the open spectrometer's identity/calibration, 0 if unknown. */
long long devices_spectrometer_id(const struct devices *dv);
/* A user of a handle saw it fail: close it, mark it unavailable with why, and retry on the timer. */
void devices_lost(struct devices *dv, enum conf_dev d, const char *why);
/* Current axis positions (degrees) into pos[3] (laser θ, detector θ, detector φ); NaN where unknown. */
void devices_positions(struct devices *dv, double pos[3]);
/* Number of devices available now. */
int devices_available(const struct devices *dv);
/* JSON array: {name, configured, available, state, note, identity{...}, position_deg, limits_deg}. */
json_t *devices_json(struct devices *dv);
/* True while a manual move or measurement runs. */
bool devices_busy(const struct devices *dv);

/* The sweep executor's device operations over these handles (ctx: the struct devices): the drivers of the
 * open devices, ACQ_E_DISCONNECTED for an absent one, link failures handed to devices_lost(). */
struct ex_ops;
const struct ex_ops *devices_ex_ops(void);

/* Manual move to absolute angles (NaN: leave that axis). Soft limits are checked first (ACQ_E_RANGE);
 * a missing axis gives ACQ_E_UNSUPPORTED. done(ctx, ok, err, result) is called once from the loop. */
typedef void (*devices_done_fn)(void *ctx, int rc, const struct acq_err *err, json_t *result);
int devices_move(struct devices *dv, const double target[3], devices_done_fn done, void *ctx, struct acq_err *err);
/* One spectrum of kind "sample", "dark" (laser off first) or "reference" (laser on for the measurement
 * only, at power_pct unless NaN), stored in the database; result {spectrum_id, kind, npix, peak, saturated,
 * integration_ms, averages}. 0 (started) or -1. */
/* Home the axes whose mask bit (1 << axis) is set (their alarms reset first), together; done(ctx, rc, err, positions) at the end, like
 * devices_move(). -1 with err if an operation runs or an axis is unavailable. */
int devices_home(struct devices *dv, unsigned mask, devices_done_fn done, void *ctx, struct acq_err *err);
/* Stop every available axis (deceleration) and the running manual operation (laser off, acquisition stopped);
 * its done() gets an ACQ_E_STATE "stopped by the operator" error. *stopped: whether one was running. 0 or -1. */
int devices_stop(struct devices *dv, bool *stopped, struct acq_err *err);
/* Switch the laser emission off (and check it reads back off). 0 or -1 (unavailable, device error). */
int devices_laser_off(struct devices *dv, struct acq_err *err);
int devices_measure(struct devices *dv, const char *kind, double integration_ms, int averages, double power_pct,
		    devices_done_fn done, void *ctx, struct acq_err *err);

#endif
