#!/usr/bin/python3
"""Integration test of brdf-recon fit --db FILE --sweep ID: a database with the daemon's schema
(daemon/schema.sql) holding calibrated samples (float32 blobs) of a synthetic ground truth; the fit from the
database must equal the fit from the same samples as CSV, and bad databases must give clear errors."""
import os
import sqlite3
import struct
import subprocess
import sys
import tempfile
import shutil

import numpy as np

BUILD = os.environ.get("ACQ_BUILD", "build")
SRC = os.environ.get("ACQ_SRC", ".")
SEED = int(os.environ.get("ACQ_SEED", "1")) % (2**31)
B = os.path.join(BUILD, "brdf-recon")


def blob(v):
    return struct.pack("<%df" % len(v), *v)


def main():
    print("ACQ_SEED=%d" % SEED)
    schema = os.path.join(SRC, "daemon", "schema.sql")
    if not os.path.exists(schema):
        print("daemon/schema.sql not in this tree")
        return 77
    d = tempfile.mkdtemp(prefix="recon_db_")
    sys.path.insert(0, os.path.join(SRC, "tests", "integration"))
    import recon_synth as rs
    rng = np.random.default_rng(SEED)
    wl = np.float32(rs.wavelengths(6)).astype(np.float64)  # exactly representable in float32
    ang = rs.sparse_grid()
    f = rs.truth(ang[:, 0], ang[:, 1], ang[:, 2], ang[:, 3], wl)
    sig = 0.02 * f + 1e-4
    meas = (f + sig * rng.standard_normal(f.shape)).astype(np.float32)
    sig = sig.astype(np.float32)
    dbp = os.path.join(d, "acq.db")
    db = sqlite3.connect(dbp)
    db.executescript(open(schema).read())
    db.execute("PRAGMA application_id = %d" % 0x42524446)
    db.execute("PRAGMA user_version = 3")
    db.execute("INSERT INTO sweeps (id, name, plan_text, config_snapshot, state, created_at, software_version, "
               "points_total, wavelength_grid) VALUES (7, 't', '', '', 'completed', 0, 'x', ?, ?)",
               (len(ang), blob(wl)))
    db.execute("INSERT INTO sweeps (id, name, plan_text, config_snapshot, state, created_at, software_version) "
               "VALUES (8, 'u', '', '', 'running', 0, 'x')")
    deg = np.degrees(ang)
    for k in range(len(ang)):
        # planned angles off by a degree: the measured ones (m_*, what the readers use) are the samples' own
        db.execute("INSERT INTO points (id, sweep_id, order_index, theta_i, phi_i, theta_o, phi_o, state, m_theta_i, "
                   "m_phi_i, m_theta_o, m_phi_o) VALUES (?, 7, ?, ?, ?, ?, ?, 'done', ?, ?, ?, ?)",
                   (k + 1, k, *[min(90.0, float(v) + 1) for v in deg[k]], *map(float, deg[k])))
        db.execute("INSERT INTO calibrated (point_id, sweep_id, brdf, sigma) VALUES (?, 7, ?, ?)",
                   (k + 1, blob(meas[k]), blob(sig[k])))
    db.commit()
    db.close()
    # the same samples as CSV (float32 values printed exactly)
    csv = os.path.join(d, "s.csv")
    with open(csv, "w") as fh:  # 9 significant digits: float32 values round-trip exactly
        fh.write(",".join(["theta_i", "phi_i", "theta_o", "phi_o"] + ["%.9g" % w for w in wl] +
                          ["sigma_%.9g" % w for w in wl]) + "\n")
        for k in range(len(ang)):
            fh.write(",".join(["%.17g" % v for v in deg[k]] + ["%.9g" % v for v in meas[k]] +
                              ["%.9g" % v for v in sig[k]]) + "\n")
    m1, m2 = os.path.join(d, "db.model"), os.path.join(d, "csv.model")
    p = subprocess.run([B, "fit", "--db", dbp, "--sweep", "7", "-o", m1], capture_output=True, text=True)
    print(p.stderr)
    assert p.returncode == 0
    subprocess.run([B, "fit", csv, "-o", m2], check=True, capture_output=True)
    q = os.path.join(d, "q.csv")
    h = rs.random_dirs(rng, 50)
    rs.write_csv(q, h, np.zeros((50, 0)), [])
    e1 = subprocess.run([B, "eval", m1, q], check=True, capture_output=True, text=True).stdout
    e2 = subprocess.run([B, "eval", m2, q], check=True, capture_output=True, text=True).stdout
    a = np.genfromtxt(e1.splitlines(), delimiter=",", skip_header=1)
    b = np.genfromtxt(e2.splitlines(), delimiter=",", skip_header=1)
    print("max relative difference db vs csv: %.3g" % np.max(np.abs(a[:, 4:] - b[:, 4:]) / b[:, 4:]))
    assert np.allclose(a[:, 4:], b[:, 4:], rtol=1e-7)  # decimal → double of a float32 differs by < 1e-9
    for args, words in ((["--sweep", "99"], "no sweep 99"), (["--sweep", "8"], "no calibrated wavelength grid")):
        p = subprocess.run([B, "fit", "--db", dbp, *args, "-o", os.path.join(d, "x")], capture_output=True, text=True)
        print(p.stderr.strip())
        assert p.returncode == 1 and words in p.stderr
    open(os.path.join(d, "junk.db"), "w").write("not a database")
    p = subprocess.run([B, "fit", "--db", os.path.join(d, "junk.db"), "--sweep", "1", "-o", os.path.join(d, "x")],
                       capture_output=True, text=True)
    print(p.stderr.strip())
    assert p.returncode == 1
    shutil.rmtree(d, ignore_errors=True)
    print("all ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
