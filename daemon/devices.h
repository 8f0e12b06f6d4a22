/* devices: the daemon's device instances (three arm axes, spectrometer, laser), each behind its own I/O
 * thread (daemon/port.h) so that no device call ever blocks the loop — opened at start without requiring any
 * to be present, reconnected on a timer while absent, reported by state from a cache; manual move/measure for
 * the `move`, `measure`, `dark`, `reference` commands; and the sweep executor's device operations
 * (devices_ex_ops), whose faults come back through devices_lost(). */
#ifndef DEVICES_H
#define DEVICES_H

#include <jansson.h>
#include <stdbool.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "daemon/conf.h"

struct loop;
struct store;
struct devices;

/* Called on the loop when a device becomes available (up) or unavailable, with a reason. */
typedef void (*devices_notify_fn)(void *ctx, enum conf_dev dev, bool up, const char *why);

/* Open every configured device (the driver backend its configuration names) on its own port thread; failures
 * leave it unavailable, tried again every daemon.device_retry_s. The configuration must outlive the devices.
 * 0 or -1 (only out of memory). */
int devices_init(struct loop *lp, struct store *st, const struct conf *c, devices_notify_fn notify, void *ctx,
		 double (*wallclock)(void), struct devices **out, struct acq_err *err);
/* After a reload: safe stop, close every device, reopen from c (which must outlive the devices). The object
 * (and the pointer the executor holds) stays. 0, or -1 with ACQ_E_STATE while a manual operation runs. */
int devices_reconfigure(struct devices *dv, const struct conf *c, struct acq_err *err);
/* Safe stop (laser off, arms stopped), close every device, end the threads (after what is queued), free.
 * NULL is fine. */
void devices_finish(struct devices *dv);

/* True when device d is open and answering (as far as the last operation knows). */
bool devices_up(const struct devices *dv, enum conf_dev d);
/* Who to kick when a completion the executor waits for has come in (the sweep's step). */
void devices_set_kick(struct devices *dv, void (*kick)(void *ctx), void *ctx);
/* Database id (devices table) of the open device d's identity, 0 if unknown (the spectrometer: see below). */
int64_t devices_device_id(const struct devices *dv, enum conf_dev d);
/* Database id of the open spectrometer's identity/calibration, 0 if unknown. */
long long devices_spectrometer_id(const struct devices *dv);
/* A user of a handle saw it fail: close it, mark it unavailable with why, and retry on the timer. */
void devices_lost(struct devices *dv, enum conf_dev d, const char *why);
/* Last known axis positions (degrees) into pos[3] (laser θ, detector θ, detector φ); NaN where unknown. */
void devices_positions(struct devices *dv, double pos[3]);
/* Number of devices available now. */
int devices_available(const struct devices *dv);
/* JSON array from what is known now (no device I/O): {name, configured, available, state, note, identity{...},
 * limits_deg, status{...}}. */
json_t *devices_json(struct devices *dv);
/* True while a manual move or measurement runs. */
bool devices_busy(const struct devices *dv);

/* The sweep executor's device operations over these handles (ctx: the struct devices): the drivers of the
 * open devices, ACQ_E_DISCONNECTED for an absent one, link failures handed to devices_lost(). */
struct ex_ops;
const struct ex_ops *devices_ex_ops(void);

/* `devices`: read the status of every available axis and the laser (on their threads), then call
 * done(ctx, 0, NULL, {devices: devices_json}) from the loop. 0 or -1 (out of memory). */
typedef void (*devices_done_fn)(void *ctx, int rc, const struct acq_err *err, json_t *result);
int devices_query(struct devices *dv, devices_done_fn done, void *ctx, struct acq_err *err);
/* The axes' positions read afresh on their threads (after what is queued there, e.g. a stop): done(ctx, 0,
 * NULL, {"laser.theta": deg|null, ...}). 0 or -1 (out of memory). */
int devices_read_positions(struct devices *dv, devices_done_fn done, void *ctx, struct acq_err *err);

/* Manual move to absolute angles (NaN: leave that axis). Soft limits are checked first (ACQ_E_RANGE);
 * a missing axis gives ACQ_E_UNSUPPORTED. done(ctx, ok, err, result) is called once from the loop. */
int devices_move(struct devices *dv, const double target[3], devices_done_fn done, void *ctx, struct acq_err *err);
/* One spectrum of kind "sample", "dark" (laser off first) or "reference" (laser on for the measurement
 * only, at power_pct unless NaN), stored in the database; result {spectrum_id, kind, npix, peak, saturated,
 * integration_ms, averages}. 0 (started) or -1. */
/* Home the axes whose mask bit (1 << axis) is set (their alarms reset first), together; done(ctx, rc, err, positions) at the end, like
 * devices_move(). -1 with err if an operation runs or an axis is unavailable. */
int devices_home(struct devices *dv, unsigned mask, devices_done_fn done, void *ctx, struct acq_err *err);
/* Stop every available axis (deceleration, queued first on its thread, a running move interrupted) and the
 * running manual operation (laser off, acquisition stopped); its done() gets an ACQ_E_STATE "stopped by the
 * operator" error. *stopped: whether one was running. 0 (a stop the device refuses is logged when it comes back). */
int devices_stop(struct devices *dv, bool *stopped, struct acq_err *err);
/* Switch the laser emission off on its thread and read it back; done(ctx, 0, NULL, {emission: false}) or the
 * error. -1 at once when the laser is unavailable. */
int devices_laser_off(struct devices *dv, devices_done_fn done, void *ctx, struct acq_err *err);
/* The loop is alive: call from a loop timer every 250 ms of real time. The laser's keep-alive is refreshed on
 * the laser's own thread every keepalive_ms / 4, ahead of any queued laser request (no client query can delay
 * it), but only while this was called within the last 3 × keepalive_ms: a loop that hangs leaves the laser to
 * switch itself off. Keep-alive failures and pauses since the last call are logged here. */
void devices_heartbeat(struct devices *dv);
/* Keep-alive counters of the laser's thread: refreshes sent, failures, periods skipped (loop silent). */
void devices_keepalive_counts(struct devices *dv, unsigned long *refreshes, unsigned long *failures,
			      unsigned long *skipped);
int devices_measure(struct devices *dv, const char *kind, double integration_ms, int averages, double power_pct,
		    devices_done_fn done, void *ctx, struct acq_err *err);

#endif
