"""sweeplib: the simulated bench (acq-sim) plus acquisitiond for the sweep integration tests and the demo:
configuration from config/bench-sim.yaml with the sweep's sections, processes started and always stopped,
the control socket, a protocol client, the reference/sample swap, database checks and the ground truth."""
import json
import math
import os
import random
import re
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time

import acqtest

BUILD = os.environ.get("ACQ_BUILD") or os.path.abspath("build")
SRC = os.environ.get("ACQ_SRC") or os.path.abspath(".")
SEED = int(os.environ.get("ACQ_SEED", "1"))
SIM = os.path.join(BUILD, "acq-sim")
DAEMON = os.path.join(BUILD, "acquisitiond")
SKIP = 77


# A 52-point plan of 3 incidences x 18 directions (auto exposure): the crash, disk-full and soak runs.
PLAN_3X18 = """name: it-3x18
incidence:
  theta_deg: [15, 40, 60]
observation:
  theta_deg: [25, 55, 75]
  phi_deg: [0, 60, 120, 180, 240, 300]
integration: {mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000}
averages: 4
blind_points: drop
"""


class Skip(Exception):
    """A tool the test needs is genuinely absent from the machine: exit 77 with the reason (a missing or
    failing piece of this tree is a failure, never a skip)."""


def say(*a):
    print(*a, flush=True)


def strip_sections(text, names):
    """Remove the top-level YAML blocks `names` (a block runs to the next top-level key)."""
    out, skipping = [], False
    for line in text.splitlines(keepends=True):
        m = re.match(r"^([A-Za-z_][A-Za-z0-9_]*):", line)
        if m:
            skipping = m.group(1) in names
        if not skipping:
            out.append(line)
    return "".join(out)


def scale_device_timing(text, scale):
    """In the devices section, the drivers' settling waits and polling periods run on the daemon's (real)
    clock while the simulator settles in bench time: divide settle_s by the time scale and poll faster."""
    out, in_devices = [], False
    for line in text.splitlines(keepends=True):
        m = re.match(r"^([A-Za-z_][A-Za-z0-9_]*):", line)
        if m:
            in_devices = m.group(1) == "devices"
        if in_devices and re.search(r"\bsettle_s:\s*[0-9.eE+-]+", line):
            line = re.sub(r"\bsettle_s:\s*([0-9.eE+-]+)",
                          lambda mm: "settle_s: %.6g, poll_s: 0.004" % (float(mm.group(1)) / scale), line)
        out.append(line)
    return "".join(out)


def compose_config(path, state, sock, scale, sweep_yaml=None, daemon_extra="", log_level="info"):
    """config/bench-sim.yaml (devices timed for the scale) + a test daemon section; its own sweep section
    unless sweep_yaml replaces it."""
    with open(os.path.join(SRC, "config", "bench-sim.yaml")) as f:
        base = f.read()
    base = strip_sections(base, {"daemon", "recon"} | ({"sweep"} if sweep_yaml is not None else set()))
    if os.environ.get("ACQ_SCALE_DEVICE_TIMING") == "1":  # a daemon whose loop runs on real time
        base = scale_device_timing(base, scale)
    with open(path, "w") as f:
        f.write(base)
        f.write("\ndaemon:\n  state_dir: %s\n  socket: {path: %s, mode: \"0600\"}\n  log_level: %s\n"
                "  device_retry_s: 0.2\n%s" % (state, sock, log_level, daemon_extra))
        if sweep_yaml is not None:
            f.write(sweep_yaml)


class Bench:
    """acq-sim + acquisitiond in a state directory; stop() ends both, whatever happened."""

    def __init__(self, state_dir=None, scale=200.0, seed=SEED, sweep_yaml=None, daemon_extra="", sim_session=False):
        for prog in (SIM, DAEMON):
            if not os.access(prog, os.X_OK):
                raise AssertionError("%s not built (make all)" % prog)
        self.dir = state_dir or tempfile.mkdtemp(prefix="acq-sweep.")
        os.makedirs(self.dir, exist_ok=True)
        os.chmod(self.dir, 0o755)
        self.state = os.path.join(self.dir, "state")
        self.sock = os.path.join(self.dir, "acq.sock")
        self.ctl_path = os.path.join(self.dir, "sim.ctl")
        self.ports = os.path.join(self.dir, "sim-ports.json")
        self.conf = os.path.join(self.dir, "acquisitiond.yaml")
        self.scale, self.seed = scale, seed
        self.sim_session = sim_session  # acq-sim in a session (Linux autogroup: CPU share) of its own (the soak)
        compose_config(self.conf, self.state, self.sock, scale, sweep_yaml, daemon_extra)
        self.sim = self.daemon = None
        self.sim_log = os.path.join(self.dir, "acq-sim.log")
        self.daemon_log = os.path.join(self.dir, "acquisitiond.log")

    # ---- processes ----
    def start_sim(self):
        log = open(self.sim_log, "ab")
        self.sim = subprocess.Popen([SIM, "-c", self.conf, "--time-scale", str(self.scale), "--seed", str(self.seed),
                                     "--ports-file", self.ports, "--control", self.ctl_path],
                                    stdout=log, stderr=subprocess.STDOUT, start_new_session=self.sim_session)
        t0 = time.time()
        while not os.path.exists(self.ports):
            if self.sim.poll() is not None:
                text = open(self.sim_log, errors="replace").read()
                if "not implemented" in text:
                    raise AssertionError("acq-sim: " + text.strip().splitlines()[-1])
                raise AssertionError("acq-sim exited %d:\n%s" % (self.sim.returncode, text))
            if time.time() - t0 > 15:
                raise AssertionError("acq-sim wrote no ports file in 15 s")
            time.sleep(0.02)

    def start_daemon(self, wait_devices=True):
        log = open(self.daemon_log, "ab")
        self.daemon = subprocess.Popen([DAEMON, "-f", "-c", self.conf, "--sim", self.ports], stdout=log,
                                       stderr=subprocess.STDOUT)
        t0 = time.time()
        while True:
            if self.daemon.poll() is not None:
                raise AssertionError("acquisitiond exited %d:\n%s" % (self.daemon.returncode, self.daemon_text()[-3000:]))
            try:
                Client(self.sock, 2).close()
                break
            except OSError:
                if time.time() - t0 > 15:
                    raise AssertionError("acquisitiond did not listen in 15 s:\n" + self.daemon_text()[-3000:])
                time.sleep(0.02)
        if wait_devices:
            self.wait_devices()

    def wait_devices(self, timeout=15):
        c = self.client()
        t0 = time.time()
        try:
            while True:
                r = c.req("devices")
                devs = r.get("devices") or []
                missing = [d for d in devs if not d.get("available")]
                if devs and not missing:
                    return
                if time.time() - t0 > timeout:
                    notes = "; ".join("%s: %s" % (d.get("name"), d.get("note") or d.get("state")) for d in missing)
                    if "not implemented" in notes:
                        raise AssertionError("devices unavailable: " + notes)
                    raise AssertionError("devices unavailable after %g s: %s" % (timeout, notes))
                time.sleep(0.1)
        finally:
            c.close()

    def kill_daemon(self, sig=signal.SIGKILL):
        if self.daemon and self.daemon.poll() is None:
            self.daemon.send_signal(sig)
            try:
                self.daemon.wait(15)
            except subprocess.TimeoutExpired:
                self.daemon.kill()
                self.daemon.wait()
        self.daemon = None

    def stop(self):
        for p in (self.daemon, self.sim):
            if p and p.poll() is None:
                p.terminate()
                try:
                    p.wait(10)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
        self.daemon = self.sim = None

    def cleanup(self, keep=False):
        self.stop()
        if not keep:
            shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        """`with Bench(...) as b:` a failure prints the daemon's last log lines; the bench is cleaned up either
        way (its folder kept with ACQ_KEEP=1)."""
        if kind is not None:
            print(self.daemon_text()[-3000:])
        self.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")
        return False

    def daemon_text(self):
        try:
            return open(self.daemon_log, errors="replace").read()
        except OSError:
            return ""

    # ---- talking ----
    def ctl(self, line):
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.settimeout(10)
        s.connect(self.ctl_path)
        s.sendall((line + "\n").encode())
        buf = acqtest.recv_line(s)
        s.close()
        reply = buf.decode(errors="replace").strip()
        if not reply.startswith("ok"):
            raise AssertionError("acq-sim control '%s': %s" % (line, reply))
        return reply

    def sim_status(self):
        r = self.ctl("status")
        return dict(kv.split("=", 1) for kv in r.split()[1:] if "=" in kv)

    def client(self, timeout=20):
        return Client(self.sock, timeout)

    def db(self):
        return sqlite3.connect("file:%s?mode=ro" % os.path.join(self.state, "acquisition.db"), uri=True, timeout=10)

    def db_path(self):
        return os.path.join(self.state, "acquisition.db")


class Client(acqtest.Client):
    """acqtest's protocol client with numbered requests: req() returns the reply that carries its own id (events
    and replies to earlier requests in between are passed over)."""

    def __init__(self, path, timeout=20):
        self.n = 0
        super().__init__(path, timeout)

    def req(self, cmd, **args):
        self.n += 1
        msg = {"cmd": cmd, "id": self.n}
        msg.update(args)
        self.sock.sendall((json.dumps(msg) + "\n").encode())
        while True:
            r = self.read()
            if r.get("id") == self.n:
                return r


def sweep_row(bench, sid):
    c = bench.client()
    try:
        r = c.req("sweep.show", sweep=sid)
    finally:
        c.close()
    if not r.get("ok"):
        raise AssertionError("sweep.show %d: %s" % (sid, r))
    return r.get("sweep", r)


def start_sweep(bench, plan_text, name="test", white_first=True):
    """Start a sweep; with white_first the white standard is put on the stage first (the executor measures
    the reference, then pauses for the sample: drive_to_end swaps it)."""
    if white_first:
        bench.ctl("sample white")
    c = bench.client()
    try:
        r = c.req("sweep.start", plan=plan_text, name=name)
    finally:
        c.close()
    if not r.get("ok"):
        raise AssertionError("sweep.start refused: %s" % r)
    return int(r.get("sweep") or r.get("id"))


def progress(bench):
    c = bench.client()
    try:
        r = c.req("status")
    finally:
        c.close()
    return r


def swap_when_asked(bench, row, sample):
    """When the sweep (its sweep.show row) is paused for the sample swap after the white reference, put the sample
    (a simulator material) on the stage and resume, as an operator would. True when it did."""
    if row.get("state") != "paused":
        return False
    ev = [e for e in row.get("events", []) if e.get("kind") in ("pause", "resume", "start", "stop")]
    if not (ev and ev[0]["kind"] == "pause" and "place the sample" in (ev[0].get("message") or "")):
        return False
    bench.ctl("sample %s" % sample)
    c = bench.client()
    r = c.req("sweep.resume")
    c.close()
    if not r.get("ok"):
        raise AssertionError("sweep.resume: %s" % r)
    return True


def drive_to_end(bench, sid, timeout, swap=True, on_tick=None, poll=0.1, sample="green-paint"):
    """Poll the sweep until it is completed/aborted/failed; at the pause after the white reference put the
    sample (a simulator material) on the stage and resume (as an operator would). Returns the final sweep row."""
    t0 = time.time()
    swapped = False
    while True:
        row = sweep_row(bench, sid)
        st = row.get("state")
        if st in ("completed", "aborted", "failed"):
            return row
        if swap and swap_when_asked(bench, row, sample):
            swapped = True
        if on_tick:
            on_tick(row)
        if time.time() - t0 > timeout:
            raise AssertionError("sweep %d still %s after %g s (%s/%s points); daemon log tail:\n%s" % (
                sid, st, timeout, row.get("points_done"), row.get("points_total"), bench.daemon_text()[-4000:]))
        time.sleep(poll)


def check_points(bench, sid, max_exposures=3):
    """Every planned point done exactly once with one calibrated sample, nothing pending, samples of one
    acquisition per point, integrity ok. Returns (n_points, n_calibrated)."""
    db = bench.db()
    try:
        q = lambda sql, *a: db.execute(sql, a).fetchone()[0]
        total = q("SELECT points_total FROM sweeps WHERE id = ?", sid)
        done = q("SELECT count(*) FROM points WHERE sweep_id = ? AND state = 'done'", sid)
        npts = q("SELECT count(*) FROM points WHERE sweep_id = ?", sid)
        cal = q("SELECT count(*) FROM calibrated c JOIN points p ON p.id = c.point_id WHERE c.sweep_id = ? "
                "AND p.state = 'done'", sid)
        bad = q("SELECT count(*) FROM points p WHERE sweep_id = ? AND ((SELECT count(*) FROM spectra s WHERE "
                "s.point_id = p.id AND s.kind = 'sample') NOT BETWEEN 1 AND ?)", sid, max_exposures)
        orphans = q("SELECT count(*) FROM spectra s JOIN points p ON p.id = s.point_id WHERE s.sweep_id = ? "
                    "AND p.state <> 'done'", sid)
        integ = db.execute("PRAGMA integrity_check").fetchone()[0]
    finally:
        db.close()
    assert integ == "ok", "integrity_check: %s" % integ
    assert npts == total, "points table %d rows, plan %d" % (npts, total)
    assert done == total, "lost points: %d of %d done" % (done, total)
    assert cal == total, "calibrated samples %d of %d" % (cal, total)
    assert bad == 0, "%d points with a duplicated or missing acquisition" % bad
    assert orphans == 0, "%d spectra on points not done" % orphans
    return total, cal


def zscores(bench, sid, material="green-paint", grid_step=None):
    """z = (f_measured − f_true)/sigma for every finite calibrated value, the truth from `acq-sim truth --eval`
    at the measured sweep angles. Returns the list of z and the number of NaN values."""
    db = bench.db()
    rows = db.execute("SELECT p.laser_theta, p.detector_theta, p.detector_phi, c.brdf, c.sigma FROM calibrated c "
                      "JOIN points p ON p.id = c.point_id WHERE c.sweep_id = ? ORDER BY p.order_index",
                      (sid,)).fetchall()
    grid = db.execute("SELECT wavelength_grid FROM sweeps WHERE id = ?", (sid,)).fetchone()[0]
    db.close()
    import numpy as np
    wl = np.frombuffer(grid, dtype="<f4").astype(float)
    qpath = os.path.join(bench.dir, "truth-queries.csv")
    opath = os.path.join(bench.dir, "truth.csv")
    laser_phi = 0.0
    with open(qpath, "w") as f:
        f.write("theta_i,phi_i,theta_o,phi_o\n")
        for lt, dt, dp, _, _ in rows:
            ti, pi = abs(lt), (laser_phi + (180 if lt < 0 else 0)) % 360
            to, po = abs(dt), (dp + (180 if dt < 0 else 0)) % 360
            f.write("%.9f,%.9f,%.9f,%.9f\n" % (ti, pi, to, po))
    step = wl[1] - wl[0] if len(wl) > 1 else 1
    r = subprocess.run([SIM, "truth", material, "--eval", qpath, "-o", opath, "--wavelengths",
                        "%g:%g:%g" % (wl[0], wl[-1], step)], capture_output=True, text=True)
    if r.returncode != 0:
        if "not implemented" in r.stderr + r.stdout:
            raise AssertionError("acq-sim truth --eval: " + (r.stderr or r.stdout))
        raise AssertionError("acq-sim truth --eval failed: %s" % (r.stderr or r.stdout))
    truth = []
    with open(opath) as f:
        header = None
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            cells = line.strip().split(",")
            if header is None:
                header = cells
                continue
            truth.append([float(x) if x not in ("", "nan") else math.nan for x in cells])
    header_wl = [float(h) for h in header[4:] if not h.startswith("sigma")]
    assert len(truth) == len(rows), "truth rows %d, samples %d" % (len(truth), len(rows))
    idx = [header_wl.index(min(header_wl, key=lambda h: abs(h - w))) for w in wl]
    zs, nan = [], 0
    for (lt, dt, dp, b, s), t in zip(rows, truth):
        fb = np.frombuffer(b, dtype="<f4").astype(float)
        fs = np.frombuffer(s, dtype="<f4").astype(float)
        ft = np.array([t[4 + i] for i in idx])
        ok = np.isfinite(fb) & np.isfinite(fs) & (fs > 0)
        nan += int((~ok).sum())
        zs.extend(((fb[ok] - ft[ok]) / fs[ok]).tolist())
    return zs, nan


def main(fn):
    """Run fn(); exit 0, 77 (skip, with the reason) or 1 (failure, with the message)."""
    say("ACQ_SEED=%d" % SEED)
    try:
        fn()
    except Skip as e:
        say("skip: %s" % e)
        sys.exit(SKIP)
    except AssertionError as e:
        say("FAIL: %s" % e)
        sys.exit(1)
    say("ok")
    sys.exit(0)


if __name__ == "__main__":
    # python3 sweeplib.py compose OUT.yaml STATE_DIR SOCKET SCALE  (used by tests/demo.sh)
    if len(sys.argv) == 6 and sys.argv[1] == "compose":
        compose_config(sys.argv[2], sys.argv[3], sys.argv[4], float(sys.argv[5]))
        sys.exit(0)
    sys.stderr.write("usage: sweeplib.py compose OUT.yaml STATE_DIR SOCKET SCALE\n")
    sys.exit(2)
