#!/usr/bin/python3
"""bench_few_directions: is the DHR's sigma honest when the samples are very few (issue 13 item 3)?

Three samples, or one direction repeated 2000 times, leave most of the hemisphere unseen: sigma must then come from
the prior on the unseen part (recon/reconstruction.md, "Honest sigma where the data are thin"), and must cover the
truth even when the few samples miss a specular lobe. Per acq-sim material and case, over noise seeds: samples
are acq-sim's truth (`acq-sim truth MAT --eval`) at the case's directions times (1 + NOISE N), sigma = NOISE x truth;
`brdf-recon fit`, `brdf-recon dhr` at 8/30/60 deg against `acq-sim truth MAT --dhr`; z = (DHR - truth)/sigma.
Cases (theta_i, phi_i, theta_o, phi_o in degrees):
  three      (10, 0, 30, 180), (40, 0, 50, 0), (60, 0, 20, 90)
  mirror     (30, 0, 30, 180) x 2000
  offmirror  (40, 0, 45, 120) x 2000
Printed per material x case x theta_i: max |z|, share |z| < 2, median sigma/|error|, max |error|, median sigma;
written to $ACQ_BENCH_OUT/bench_few_directions.csv (material,case,theta_i,metric,value).
Environment: ACQ_FEW_SEEDS (3), ACQ_FEW_NOISE (0.01), ACQ_FEW_WL (450:1100:50, 14 wavelengths),
ACQ_FEW_MATERIALS (all acq-sim materials), ACQ_FEW_CASES (three,mirror,offmirror).
Exit status 1 when some cell has max |z| >= ACQ_FEW_ZMAX (default: none, report only)."""
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_dhr_honesty import ALL, B, OUT, SIM, read_csv, run  # noqa: E402  (one definition of each)

NSEEDS = int(os.environ.get("ACQ_FEW_SEEDS", "3"))
NOISE = float(os.environ.get("ACQ_FEW_NOISE", "0.01"))
WLS = os.environ.get("ACQ_FEW_WL", "450:1100:50")
MATS = os.environ.get("ACQ_FEW_MATERIALS", ALL).split(",")
CASES = {
    "three": [(10, 0, 30, 180), (40, 0, 50, 0), (60, 0, 20, 90)],
    "mirror": [(30, 0, 30, 180)] * 2000,
    "offmirror": [(40, 0, 45, 120)] * 2000,
}
CASE_LIST = os.environ.get("ACQ_FEW_CASES", ",".join(CASES)).split(",")
THETAS = (8, 30, 60)
ZMAX = float(os.environ.get("ACQ_FEW_ZMAX", "inf"))


def samples(mat, case, seed, d):
    """The truth at dirs with relative noise NOISE (seeded), as a brdf-recon sample CSV; returns its path."""
    dirs = CASES[case]
    uniq = sorted(set(dirs))
    q = os.path.join(d, "q_%s.csv" % mat)
    with open(q, "w") as f:
        f.write("theta_i,phi_i,theta_o,phi_o\n")
        for r in uniq:
            f.write("%g,%g,%g,%g\n" % r)
    te = os.path.join(d, "te_%s.csv" % mat)
    run([SIM, "truth", mat, "--eval", q, "-o", te, "--wavelengths", WLS])
    head, T = read_csv(te)
    wl = head[4:]
    truth = {tuple(r[:4]): r[4:] for r in T}
    rng = np.random.default_rng(1000 * seed + 7)
    s = os.path.join(d, "s_%s_%s_%d.csv" % (mat, case, seed))
    with open(s, "w") as f:
        f.write(",".join(["theta_i", "phi_i", "theta_o", "phi_o"] + wl + ["sigma_" + w for w in wl]) + "\n")
        for r in dirs:
            t = truth[tuple(float(x) for x in r)]
            v = t * (1 + NOISE * rng.standard_normal(len(t)))
            f.write(",".join(["%g" % x for x in r] + ["%.9g" % x for x in v] + ["%.6g" % x for x in NOISE * t]) + "\n")
    return s


def main():
    os.makedirs(OUT, exist_ok=True)
    d = tempfile.mkdtemp(prefix="bench_few_")
    print("bench_few_directions: %d seeds, noise %g, wavelengths %s, data in %s" % (NSEEDS, NOISE, WLS, d))
    print("%-18s %-9s %4s %8s %7s %9s %9s %9s" % ("material", "case", "th_i", "max|z|", "|z|<2", "sig/|err|",
                                                   "max|err|", "med sig"))
    rows, worst = [], 0.0
    for mat in MATS:
        tr = os.path.join(d, "truth_%s.csv" % mat)
        run([SIM, "truth", mat, "--dhr", tr, "--theta-i", ",".join(map(str, THETAS)), "--wavelengths", WLS])
        _, T = read_csv(tr)
        th_t, dhr_t = T[:, 0], T[:, 2]
        for case in CASE_LIST:
            err, sig = [], []
            for seed in range(1, NSEEDS + 1):
                s = samples(mat, case, seed, d)
                m, o = s + ".model", s + ".dhr.csv"
                run([B, "fit", s, "-o", m])
                run([B, "dhr", m, "--theta-i", ",".join(map(str, THETAS)), "--seed", str(seed), "-o", o])
                head, A = read_csv(o)
                c = {h: i for i, h in enumerate(head)}
                err.append(A[:, c["dhr"]] - dhr_t)
                sig.append(A[:, c["sigma"]])
            err, sig = np.array(err), np.array(sig)
            for t in THETAS:
                k = th_t == t
                e, s_ = err[:, k], sig[:, k]
                z = e / s_
                res = {"max_abs_z": np.max(np.abs(z)), "share_z_lt_2": np.mean(np.abs(z) < 2),
                       "median_sigma_over_err": np.median(s_ / np.maximum(np.abs(e), 1e-12)),
                       "max_abs_err": np.max(np.abs(e)), "median_sigma": np.median(s_),
                       "median_truth": np.median(dhr_t[k])}
                worst = max(worst, res["max_abs_z"])
                print("%-18s %-9s %4d %8.2f %7.2f %9.3g %9.4f %9.4f" % (
                    mat, case, t, res["max_abs_z"], res["share_z_lt_2"], res["median_sigma_over_err"],
                    res["max_abs_err"], res["median_sigma"]), flush=True)
                rows += ["%s,%s,%d,%s,%.6g" % (mat, case, t, kk, v) for kk, v in res.items()]
    with open(os.path.join(OUT, "bench_few_directions.csv"), "w") as f:
        f.write("material,case,theta_i,metric,value\n" + "\n".join(rows) + "\n")
    print("worst max |z| %.2f" % worst)
    return 1 if worst >= ZMAX else 0


if __name__ == "__main__":
    sys.exit(main())
