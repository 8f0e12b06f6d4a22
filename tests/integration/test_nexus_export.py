#!/usr/bin/python3
"""Round trip of the NeXus/HDF5 export (build/acq-nexus): a database made from daemon/schema.sql with a sweep of
known rows (random float32 counts and sigmas, NULL actual angles, a spectrum without stddev, a manual spectrum
of another sweep, UTF-8 events) is exported, then read back with h5py (Debian's, /usr/bin/python3) and every
number compared with what SQLite holds (nexuscheck.py): raw counts, darks, reference, calibrated f and sigma, planned and actual
angles, wavelengths, integration times, timestamps, the configuration and plan snapshots, events; NeXus classes
and units attributes are checked; h5dump reads the file; bad input is refused and leaves no file."""
import os
import sqlite3
import subprocess
import sys
import tempfile

import numpy as np

BUILD = os.environ.get("ACQ_BUILD", "build")
SRC = os.environ.get("ACQ_SRC", ".")
SEED = int(os.environ.get("ACQ_SEED", "1")) % (2**31)
X = os.path.join(BUILD, "acq-nexus")
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import nexuscheck  # noqa: E402

print("ACQ_SEED=%d" % SEED)


def make_db(path, rng):
    db = sqlite3.connect(path)
    db.executescript(open(os.path.join(SRC, "daemon", "schema.sql")).read())
    db.execute("PRAGMA application_id = %d" % 0x42524446)
    db.execute("PRAGMA user_version = 3")
    npix, nwl = 64, 23
    db.execute("INSERT INTO spectrometers VALUES (1, 'AvaSpec-ULS2048', '1234567U1', '2.1', ?, 450.0, 0.32, "
               "-1.1e-5, 2e-9, 0, NULL, 1700000000.0)", (npix,))
    db.execute("INSERT INTO devices VALUES (1, 'laser', 'NKT', 'SuperK', 'L1', '1.0', 1.7e9, 1.7e9)")
    db.execute("INSERT INTO devices VALUES (2, 'detector.theta', 'Oriental', 'AZD', 'A2', '3.1', 1.7e9, 1.7e9)")
    grid = np.linspace(450, 1100, nwl).astype("<f4")
    db.execute("INSERT INTO sweeps (id, name, plan_text, config_snapshot, state, created_at, started_at, finished_at,"
               " software_version, calibration_method, spectrometer_id, points_total, wavelength_grid) VALUES "
               "(1, 'green paint – test', 'grid: {n: 2}\n', 'daemon:\n  socket: x\n', 'completed', 1.7e9, "
               "1.7e9 + 5, 1.7e9 + 500, 'acquisitiond test', 'reference-white-v1', 1, 3, ?)", (grid.tobytes(),))
    db.execute("INSERT INTO sweeps (id, name, plan_text, config_snapshot, state, created_at, software_version, "
               "points_total) VALUES (2, 'other', '', '', 'planned', 1.7e9, 'x', 0)")
    db.execute("INSERT INTO sweep_devices VALUES (1, 1), (1, 2)")
    pts = [(10, 1, 0, 30.0, 0.0, 45.0, 180.0, 30.01, 44.98, 179.9, "done", 1.7e9 + 100),
           (11, 1, 1, 30.0, 0.0, 60.0, 90.0, None, None, None, "skipped", None),
           (12, 1, 2, 0.0, 0.0, 10.0, 0.0, 0.0, 10.02, 0.01, "done", 1.7e9 + 200)]
    db.executemany("INSERT INTO points (id, sweep_id, order_index, theta_i, phi_i, theta_o, phi_o, laser_theta, "
                   "detector_theta, detector_phi, state, done_at) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)", pts)
    db.execute("UPDATE points SET m_theta_i = 30.004, m_phi_i = 0.01, m_theta_o = 44.98, m_phi_o = 179.9 WHERE id = 10")
    spectra = []
    sid = 100
    for kind, point, sd in (("reference", None, True), ("dark", None, True), ("sample", 10, True), ("dark", 10, False),
                            ("sample", 12, True), ("sample", 12, False)):
        c = rng.uniform(0, 60000, npix).astype("<f4")
        s = rng.uniform(0, 50, npix).astype("<f4") if sd else None
        spectra.append((sid, 1, point, kind, 1, float(rng.uniform(1, 100)), int(rng.integers(1, 16)), npix, c.tobytes(),
                        s.tobytes() if sd else None, int(rng.integers(0, 3)), None, 21.5 if sd else None,
                        1.7e9 + sid))
        sid += 1
    spectra.append((sid, None, None, "sample", 1, 5.0, 1, npix, np.zeros(npix, "<f4").tobytes(), None, 0, None,
                    None, 1.7e9))
    db.executemany("INSERT INTO spectra VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)", spectra)
    for p in (10, 12):
        db.execute("INSERT INTO calibrated VALUES (?, 1, ?, ?)", (p, rng.uniform(0, 1, nwl).astype("<f4").tobytes(),
                                                                 rng.uniform(0, .01, nwl).astype("<f4").tobytes()))
    db.executemany("INSERT INTO events (at, sweep_id, kind, device, message) VALUES (?,?,?,?,?)",
                   [(1.7e9 + 5, 1, "start", None, "sweep started"),
                    (1.7e9 + 50, 1, "fault", "detector.theta", "move did not complete (at 62.99°)"),
                    (1.7e9 + 51, 1, "recovered", "detector.theta", "answers again"),
                    (1.7e9 + 60, 2, "info", None, "not this sweep")])
    db.commit()
    db.close()


def main():
    if not os.access(X, os.X_OK):
        print("acq-nexus not built")
        return 77
    try:
        import h5py
    except ImportError:
        sys.exit("FAIL: python3-h5py (in DEB_PKGS) is missing for /usr/bin/python3")
    rng = np.random.default_rng(SEED)
    d = tempfile.mkdtemp(prefix="nexus_")
    dbp, out = os.path.join(d, "a.db"), os.path.join(d, "s.nxs")
    make_db(dbp, rng)
    p = subprocess.run([X, dbp, "1", "-o", out], capture_output=True, text=True)
    print(p.stderr.strip())
    assert p.returncode == 0
    h = subprocess.run(["h5dump", "-H", out], capture_output=True, text=True)
    assert h.returncode == 0 and 'GROUP "entry"' in h.stdout
    got = nexuscheck.check_roundtrip(out, dbp, 1)
    assert got["spectra"] == {"sample": 3, "dark": 2, "reference": 1, "beam": 0} and got["calibrated"] == 2, got
    assert got["events"] == 3 and got["devices"] == 2, got
    f = h5py.File(out, "r")
    e = f["entry"]
    s = nexuscheck.s
    assert s(e["title"][()]) == "green paint – test" and nexuscheck.nx_class(e["raw_dark"]) == "NXdata"
    assert s(e["start_time"][()]).startswith("2023-11-14T22:13:25")
    assert e["raw_sample"]["counts"].shape == (3, 64)
    f.close()
    print("round trip: points, 4 kinds of spectra, calibrated f/sigma, grid, calibration, devices, events identical")
    # refusals: no such sweep, not our database; nothing left behind
    bad = os.path.join(d, "bad.nxs")
    p = subprocess.run([X, dbp, "9", "-o", bad], capture_output=True, text=True)
    assert p.returncode == 1 and "no sweep 9" in p.stderr and not os.path.exists(bad), p.stderr
    other = os.path.join(d, "other.db")
    sqlite3.connect(other).execute("CREATE TABLE t (x)").connection.commit()
    p = subprocess.run([X, other, "1", "-o", bad], capture_output=True, text=True)
    assert p.returncode == 1 and "not an acquisitiond database" in p.stderr and not os.path.exists(bad)
    p = subprocess.run([X, dbp, "-o", bad], capture_output=True, text=True)
    assert p.returncode == 2
    assert not [x for x in os.listdir(d) if ".tmp." in x]
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
