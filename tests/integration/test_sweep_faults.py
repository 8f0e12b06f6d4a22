#!/usr/bin/python3
"""Faults during a sweep on the simulated bench: each fault type of acq-sim's control socket is injected while
the sweep runs (arm Modbus timeouts and dropped connections, alarms and stalls mid-move, the spectrometer
vanishing mid-exposure, a saturation burst, the laser interlock and a laser fault). The sweep must complete,
every fault must be in the event log with its recovery, no committed point lost or duplicated, and the laser
never emitting while the sweep is not acquiring (sampled from the simulator while the daemon reports the
sweep faulted, paused or idle)."""
import os
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

PLAN = """name: it-faults
incidence:
  theta_deg: [10, 35, 60]
observation:
  theta_deg: [20, 45, 70]
  phi_deg: [0, 72, 144, 216, 288]
integration: {mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000}
averages: 4
blind_points: drop
"""

SCALE = 40.0
# The faults that stay on until ended stay on at least their bench seconds AND until the daemon has recorded a
# fault of their device (the events' device column: NAME, or NAME.axis with a trailing dot here), at most
# HOLD_MAX_S real seconds: a real-time window of 4 bench seconds (0.1 s) can pass on a loaded machine without one
# read of the device, which tested the machine's load, not the daemon.
HOLD_MAX_S = 30.0
# (control command, command that ends it or None, bench seconds it stays on at least, its device)
FAULTS = [
    ("fault modbus-timeout laser on", "fault modbus-timeout laser off", 4, "laser."),
    ("fault modbus-timeout detector on", "fault modbus-timeout detector off", 4, "detector."),
    ("fault drop-connection laser", None, 0, None),
    ("fault drop-connection detector", None, 0, None),
    ("fault alarm-mid-move laser", None, 0, None),
    ("fault alarm-mid-move detector", None, 0, None),
    ("fault stall detector", None, 0, None),
    ("fault stall laser", None, 0, None),
    ("fault spectro-disconnect 20", None, 0, None),
    ("fault saturation-burst 3", None, 0, None),
    ("fault laser-interlock on", "fault laser-interlock off", 4, "laser"),
    ("fault laser-fault on", "fault laser-fault off", 4, "laser"),
]


def fault_events(b, sid, device, after_id):
    """The fault events of device (NAME, or a prefix NAME. for its axes) with an id above after_id."""
    db = b.db()
    try:
        rows = db.execute("SELECT id, device FROM events WHERE sweep_id = ? AND kind = 'fault' AND id > ?",
                          (sid, after_id)).fetchall()
    finally:
        db.close()
    return [r for r in rows if ((r[1] or "").startswith(device) if device.endswith(".") else r[1] == device)]


def last_event_id(b):
    db = b.db()
    try:
        return db.execute("SELECT COALESCE(MAX(id), 0) FROM events").fetchone()[0]
    finally:
        db.close()


class LaserWatch(threading.Thread):
    """Samples (daemon state, emission, daemon state): emission on between two 'not running' readings is a
    laser left on while the sweep is not acquiring."""

    def __init__(self, bench):
        super().__init__(daemon=True)
        self.b, self.stop, self.violations, self.samples = bench, False, [], 0

    def state(self):
        c = self.b.client(5)
        try:
            return c.req("status").get("sweep", {}).get("state")
        finally:
            c.close()

    def run(self):
        while not self.stop:
            try:
                s1 = self.state()
                em = self.b.sim_status().get("emission")
                s2 = self.state()
            except Exception:
                time.sleep(0.05)
                continue
            self.samples += 1
            if s1 == s2 and s1 in ("paused", "faulted", "idle") and em not in ("0", None):
                self.violations.append((s1, em))
            time.sleep(0.03)


def run():
    b = L.Bench(scale=SCALE)
    watch = None
    try:
        b.start_sim()
        b.start_daemon()
        sid = L.start_sweep(b, PLAN, "it-faults")
        total = L.sweep_row(b, sid)["points_total"]
        watch = LaserWatch(b)
        watch.start()
        injected, t0 = [], time.time()
        pending = list(FAULTS)
        last_done = -1
        clear_at, clear_cmd, clear_dev, clear_after, clear_by = None, None, None, 0, None

        def tick(row):
            nonlocal last_done, clear_at, clear_cmd, clear_dev, clear_after, clear_by
            now = time.time()
            if clear_cmd and now >= clear_at and (now >= clear_by or fault_events(b, sid, clear_dev, clear_after)):
                b.ctl(clear_cmd)
                clear_cmd = None
            done = row.get("points_done") or 0
            # one fault per newly committed point, once the sample is on the stage
            if pending and not clear_cmd and row["state"] == "running" and done > last_done and done >= 1:
                cmd, off, dur, dev = pending.pop(0)
                after = last_event_id(b)
                b.ctl(cmd)
                injected.append((cmd, done))
                last_done = done
                if off:
                    clear_cmd, clear_at, clear_by = off, time.time() + dur / SCALE, time.time() + HOLD_MAX_S
                    clear_dev, clear_after = dev, after

        row = L.drive_to_end(b, sid, timeout=150, on_tick=tick, poll=0.03)
        watch.stop = True
        watch.join(5)
        L.say("injected %d faults at points %s; sweep %s after %.1f s" % (
            len(injected), [d for _, d in injected], row["state"], time.time() - t0))
        assert row["state"] == "completed", "sweep ended %s" % row["state"]
        assert not pending, "the sweep finished before every fault was injected: %s left" % [p[0] for p in pending]
        n, cal = L.check_points(b, sid)
        db = b.db()
        ev = db.execute("SELECT kind, device, message FROM events WHERE sweep_id = ? ORDER BY id", (sid,)).fetchall()
        db.close()
        faults = [e for e in ev if e[0] == "fault"]
        recovered = [e for e in ev if e[0] == "recovered"]
        redo = [e for e in ev if e[0] == "info" and ("measuring the point again" in e[2] or "taken again" in e[2]
                                                     or "stay unmeasured" in e[2])]
        L.say("events: %d faults, %d recoveries, %d re-measured points; laser samples %d, violations %d" % (
            len(faults), len(recovered), len(redo), watch.samples, len(watch.violations)))
        for dev in ("laser.theta", "detector.theta", "spectrometer", "laser"):
            assert any(f[1] == dev for f in faults), "no fault recorded for %s" % dev
        # the device is the event's device column (and the log line's prefix): its message does not name it again
        named = [f for f in faults if f[2].startswith(f[1] + ":") or f[2].startswith(f[1] + " (")]
        assert not named, "fault messages repeat their device: %s" % named[:3]
        assert len(recovered) >= len(faults) - 1, "faults without recovery: %d faults, %d recoveries" % (
            len(faults), len(recovered))
        assert redo, "the saturation burst left no trace (no point measured again)"
        assert not watch.violations, "laser on while the sweep was not acquiring: %s" % watch.violations[:5]
        assert watch.samples > 20, "too few laser samples (%d)" % watch.samples
        zs, nan = L.zscores(b, sid)
        import numpy as np
        z = np.array(zs)
        L.say("z-scores after the faults: %d values, mean %.3f, std %.3f" % (len(z), z.mean(), z.std()))
        assert abs(z.mean()) < 0.3 and 0.6 < z.std() < 1.6, "faults spoiled the calibrated values"
    finally:
        if watch:
            watch.stop = True
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


L.main(run)
