#!/usr/bin/python3
"""Integration test of brdf-recon against the simulator's ground truths (acq-sim truth: green paint, white
reference, metal): noisy 10x10x10 samples -> fit -> check (three properties) -> DHR against the truth's DHR.
A failing `acq-sim truth` is a failure.

Tolerances (relative DHR error), measured with acq-sim's truths at 1 % noise on this 25 nm grid (seeds 1-4,
the errors are systematic, not noise). With the GGX trend (session 3, 6 more seeds): white <= 0.18 % at every
incidence, green paint <= 0.24 / 0.19 / 0.29 % at 8 / 30 / 60 deg, metal <= 0.31 / 0.33 / 0.37 %. Without it (the plain
interpolant, before session 3): paint 1.5 / 4 / 10 %, metal 6.6 / 8.2 / 10 %: a 36 deg azimuth step is wider
than a specular lobe, and only the trend gives the lobe its out-of-plane shape. The thresholds (1 / 1 / 1.5 %
paint, 1 / 1.5 / 2 % metal) leave a margin of ~3x for other seeds and fail if the trend is lost (or the
model loses the lobe or the colour). The 8 deg figure is the paper's comparison (spectrophotometer
geometry)."""
import os
import subprocess
import sys
import tempfile
import shutil

import numpy as np

BUILD = os.environ.get("ACQ_BUILD", "build")
SEED = int(os.environ.get("ACQ_SEED", "1")) % 100000
SIM = os.environ.get("ACQ_SIM_BIN", os.path.join(BUILD, "acq-sim"))
B = os.path.join(BUILD, "brdf-recon")
TOL = {"white": (0.01, 0.01, 0.01), "green-paint": (0.01, 0.01, 0.015), "metal": (0.01, 0.015, 0.02)}


def run(args):
    p = subprocess.run(args, capture_output=True, text=True)
    if p.returncode != 0:
        print(p.stdout, p.stderr)
        sys.exit("FAIL: %s" % " ".join(args))
    return p


def main():
    print("ACQ_SEED=%d" % SEED)
    p = subprocess.run([SIM, "truth", "white", "--dhr", os.devnull, "--wavelengths", "450:1100:50"],
                       capture_output=True, text=True)
    if p.returncode != 0:
        print("FAIL: acq-sim truth: %s" % (p.stderr.strip() or p.stdout.strip()))
        return 1
    d = tempfile.mkdtemp(prefix="recon_simtruth_")
    for mat, tol in TOL.items():
        s, t, m, o = (os.path.join(d, "%s.%s" % (mat, x)) for x in ("csv", "dhr.csv", "model", "out.csv"))
        run([SIM, "truth", mat, "--grid", "10x10x10", "-o", s, "--wavelengths", "450:1100:25", "--seed", str(SEED)])
        run([SIM, "truth", mat, "--dhr", t, "--theta-i", "8,30,60", "--wavelengths", "450:1100:25"])
        fit = run([B, "fit", s, "-o", m]).stderr.strip()
        print(fit)
        if mat != "white":  # microfacet lobes: the leave-one-out choice keeps the trend
            assert "trend ggx" in fit, mat
        c = subprocess.run([B, "check", m, "--pairs", "5000", "--thetas", "4"], capture_output=True, text=True)
        print(c.stdout.strip())
        assert c.returncode == 0 and c.stdout.count("ok  ") == 3, mat
        run([B, "dhr", m, "--draws", "8", "--seed", str(SEED), "-o", o])
        a = np.genfromtxt(o, delimiter=",", skip_header=1)
        b = np.array([[float(x) for x in line.split(",")] for line in open(t)
                      if line[:1].isdigit()])
        assert a.shape[0] == b.shape[0] and a.shape[1] == 14 and np.allclose(a[:, :2], b[:, :2]), mat  # the budget
        rel = np.abs(a[:, 2] - b[:, 2]) / b[:, 2]
        worst = [float(rel[a[:, 0] == th].max()) for th in (8, 30, 60)]
        print("%s: worst relative DHR error at 8/30/60 deg: %s (tolerances %s)" %
              (mat, ["%.4f" % w for w in worst], tol))
        assert all(w < tl for w, tl in zip(worst, tol)), mat
    shutil.rmtree(d, ignore_errors=True)
    print("all ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
