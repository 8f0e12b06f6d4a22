#!/usr/bin/python3
"""Integration on the simulated bench: acq-sim serves the bench of config/bench-sim.yaml, acquisitiond
drives it through --sim PORTS.json (one config for both): every device connects, `devices` reports
identities and positions, manual moves reach their targets (a collision is refused when the planner is
there), a dark and a sample are stored (the sample with the laser on at the asked power, off afterwards),
SIGTERM leaves the laser off."""
import json
import os
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from acqtest import BUILD, SRC, Client, check  # noqa: E402


def main():
    sim_bin = os.path.join(BUILD, "acq-sim")
    tmp = tempfile.mkdtemp(prefix="acqsim.")
    ports = os.path.join(tmp, "ports.json")
    state = os.path.join(tmp, "state")
    conf = os.path.join(tmp, "bench.yaml")
    text = open(os.path.join(SRC, "config", "bench-sim.yaml")).read().replace("/tmp/acquisitiond-sim", state)
    with open(conf, "w") as f:
        f.write(text)
    # Bench time 10× faster than real time: the daemon's loop clock follows the ports file's time_scale.
    sim = subprocess.Popen([sim_bin, "-c", conf, "--ports-file", ports, "--control", os.path.join(tmp, "ctl.sock"),
                            "--time-scale", "10"],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    daemon = None
    try:
        deadline = time.time() + 8
        while time.time() < deadline and not os.path.exists(ports) and sim.poll() is None:
            time.sleep(0.05)
        if not os.path.exists(ports):
            sim.kill()
            err = sim.communicate()[1].strip().splitlines()
            print("FAIL: acq-sim did not serve the bench: %s" % (err[-1] if err else "no ports file in 8 s"))
            sys.exit(1)
        log = open(os.path.join(tmp, "daemon.log"), "w")
        daemon = subprocess.Popen([os.path.join(BUILD, "acquisitiond"), "-f", "-c", conf, "--sim", ports],
                                  stdout=log, stderr=subprocess.STDOUT)
        sock = os.path.join(state, "acquisitiond.sock")
        c = None
        while time.time() < deadline + 10 and c is None:
            try:
                c = Client(sock)
            except OSError:
                time.sleep(0.05)
        check(c is not None, "daemon did not start")
        r = None
        for _ in range(100):
            r = c.req("devices")
            if all(d["available"] for d in r["devices"]):
                break
            time.sleep(0.1)
        states = {d["name"]: (d["state"], d.get("note")) for d in r["devices"]}
        if not all(d["available"] for d in r["devices"]):
            print("FAIL: devices not all connected on the simulated bench: %r" % states)
            sys.exit(1)
        check(c.req("status")["devices"] == {"available": 5, "total": 5}, "5/5 available")
        t0 = time.time()
        moved = c.req("move", laser_theta=30.0, detector_theta=45.0, detector_phi=180.0, _id="m")
        move_s = time.time() - t0
        check(moved["ok"], "move: %r" % moved)
        # 30° of the laser arm at 10°/s is ≥ 3 bench seconds: well under 3 real seconds at 10×.
        check(move_s < 2.5, "move took %.2f s of real time at time scale 10" % move_s)
        check(abs(moved["laser.theta"] - 30) < 0.1 and abs(moved["detector.theta"] - 45) < 0.1, "reached %r" % moved)
        bad = c.req("move", laser_theta=45.0, detector_theta=45.0, detector_phi=0.0)  # the detector onto the laser arm
        check(bad["ok"] is False and bad["error"]["code"] == "range", "collision refused as range: %r" % bad)
        dark = c.req("dark", integration_ms=5.0)
        check(dark["ok"] and dark["kind"] == "dark" and dark["npix"] > 0, "dark %r" % dark)
        sample = c.req("measure", integration_ms=5.0, power_pct=60.0)
        check(sample["ok"] and sample["peak"] > dark["peak"] + 100, "sample above dark: %r vs %r" % (sample, dark))
        laser = [d for d in c.req("devices")["devices"] if d["name"] == "laser"][0]
        check(laser["status"]["emission"] is False, "laser off after the measurement: %r" % laser)
        c.close()

        # SIGKILL while spectra are being written: every spectrum whose reply arrived is in the database.
        k = Client(sock)
        ids = []
        t_end = time.time() + 1.0
        while time.time() < t_end:
            r = k.req("dark", integration_ms=2.0)
            check(r["ok"], "dark %r" % r)
            ids.append(r["spectrum_id"])
        k.send_raw(b'{"cmd":"dark","integration_ms":2}\n')  # in flight when the daemon dies
        daemon.send_signal(signal.SIGKILL)
        daemon.wait(10)
        k.close()
        con = sqlite3.connect(os.path.join(state, "acquisition.db"))
        check(con.execute("PRAGMA integrity_check").fetchone()[0] == "ok", "integrity after SIGKILL")
        have = {i for (i,) in con.execute("SELECT id FROM spectra")}
        missing = [i for i in ids if i not in have]
        check(not missing, "acknowledged spectra lost after SIGKILL: %r" % missing)
        con.close()
        killed_n = len(ids)
        daemon = subprocess.Popen([os.path.join(BUILD, "acquisitiond"), "-f", "-c", conf, "--sim", ports],
                                  stdout=log, stderr=subprocess.STDOUT)
        c = None
        t_end = time.time() + 10
        while time.time() < t_end and c is None:
            try:
                c = Client(sock)
            except OSError:
                time.sleep(0.05)
        check(c is not None and c.req("version")["ok"], "restart after SIGKILL (stale socket replaced)")
        c.close()
        daemon.send_signal(signal.SIGTERM)
        check(daemon.wait(15) == 0, "daemon exit")
        con = sqlite3.connect(os.path.join(state, "acquisition.db"))
        kinds = [k for (k,) in con.execute("SELECT kind FROM spectra ORDER BY id")]
        check(kinds[:2] == ["dark", "sample"] and len(kinds) >= 2 + killed_n, "stored spectra %r" % kinds[:4])
        check(con.execute("SELECT count(*) FROM spectrometers").fetchone()[0] == 1, "calibration recorded")
        check(con.execute("SELECT count(*) FROM devices").fetchone()[0] >= 3, "identities recorded")
        con.close()
        print("ok: simulated bench (time scale 10) driven through --sim: move %.2f s real, dark %.0f, sample %.0f "
              "counts; %d acknowledged spectra all kept across SIGKILL" % (move_s, dark["peak"], sample["peak"],
                                                                         killed_n))
    finally:
        for p in (daemon, sim):
            if p and p.poll() is None:
                p.kill()
                p.wait()
        subprocess.run(["rm", "-rf", tmp])


if __name__ == "__main__":
    main()
