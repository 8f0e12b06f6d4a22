#!/usr/bin/python3
"""bench_dhr_honesty: is the DHR uncertainty of `brdf-recon dhr` honest?
For acq-sim's truths (green paint, white, metal) on the paper's 10 x 10 x 10 plan with 1 % noise, over 20
noise seeds: fit, dhr (Monte Carlo sigma), compare with the exact DHR (acq-sim truth --dhr). Per material and
incidence (8, 30, 60 degrees) it reports
  - frac_z_lt2: fraction of (wavelength, seed) with |error/sigma| < 2 (issue goal: >= 0.95 at 8 deg);
  - max_abs_err: largest |DHR - truth| (issue goal: < 0.01 at 8 deg);
  - z_rms: RMS of error/sigma over seeds and wavelengths, the spread about 0 (honest: near 1; it includes the
    deterministic interpolation bias); z_std: std over seeds (the random part only), averaged over wavelengths;
  - the same with sigma_noise alone (the Monte-Carlo part), to show what the interpolation-error term adds;
  - bias: mean error over seeds and wavelengths (deterministic part), and bias/sigma;
  - sigma_mean: mean reported sigma.
Writes $ACQ_BENCH_OUT/bench_dhr_honesty.csv (material,theta_i,metric,value)."""
import os
import subprocess
import sys
import tempfile

import numpy as np

BUILD = os.environ.get("ACQ_BUILD", "build")
OUT = os.environ.get("ACQ_BENCH_OUT", os.path.join(BUILD, "bench"))
SIM = os.path.join(BUILD, "acq-sim")
B = os.path.join(BUILD, "brdf-recon")
NSEEDS = int(os.environ.get("ACQ_HONESTY_SEEDS", "20"))
NOISE = os.environ.get("ACQ_HONESTY_NOISE", "0.01")
WLS = os.environ.get("ACQ_HONESTY_WL", "450:1100:10")
MATS = os.environ.get("ACQ_HONESTY_MATERIALS", "green-paint,white,metal").split(",")
THETAS = (8, 30, 60)
EXTRA = os.environ.get("ACQ_HONESTY_DHR_ARGS", "").split()


def run(args):
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def main():
    os.makedirs(OUT, exist_ok=True)
    d = tempfile.mkdtemp(prefix="bench_honesty_")
    rows = []
    for mat in MATS:
        tr = os.path.join(d, "truth_%s.csv" % mat)
        run([SIM, "truth", mat, "--dhr", tr, "--theta-i", ",".join(map(str, THETAS)), "--wavelengths", WLS])
        T = np.genfromtxt(tr, delimiter=",", skip_header=2, names=True)
        err, sig, sn = [], [], []
        for seed in range(1, NSEEDS + 1):
            s, m, o = (os.path.join(d, "%s_%d.%s" % (mat, seed, x)) for x in ("csv", "model", "dhr.csv"))
            run([SIM, "truth", mat, "--grid", "10x10x10", "--noise", NOISE, "--seed", str(seed), "--wavelengths",
                 WLS, "-o", s])
            run([B, "fit", s, "-o", m])
            run([B, "dhr", m, "--theta-i", ",".join(map(str, THETAS)), "--seed", str(seed), "-o", o, *EXTRA])
            A = np.genfromtxt(o, delimiter=",", names=True)
            err.append(A["dhr"] - T["dhr"])
            sig.append(A["sigma"])
            sn.append(A["sigma_noise"])
        err, sig, sn = np.array(err), np.array(sig), np.array(sn)
        z = err / sig
        for t in THETAS:
            k = T["theta_i"] == t
            e, s_, zz = err[:, k], sig[:, k], z[:, k]
            res = {
                "frac_z_lt2": float(np.mean(np.abs(zz) < 2)),
                "max_abs_err": float(np.abs(e).max()),
                "z_std": float(np.mean(np.std(zz, axis=0, ddof=1))),
                "z_rms": float(np.sqrt(np.mean(zz ** 2))),
                "frac_z_lt2_noise_only": float(np.mean(np.abs(e / sn[:, k]) < 2)),
                "z_rms_noise_only": float(np.sqrt(np.mean((e / sn[:, k]) ** 2))),
                "err_std_over_sigma": float(np.mean(np.std(e, axis=0, ddof=1) / s_.mean(axis=0))),
                "bias": float(np.mean(e)),
                "bias_over_sigma_max": float(np.max(np.abs(e.mean(axis=0)) / s_.mean(axis=0))),
                "sigma_mean": float(s_.mean()),
                "rel_err_max": float(np.max(np.abs(e) / T["dhr"][k])),
            }
            for kk, v in res.items():
                rows.append((mat, t, kk, v))
                print("  %-12s %2d° %-22s %.4g" % (mat, t, kk, v))
    path = os.path.join(OUT, "bench_dhr_honesty.csv")
    with open(path, "w") as fh:
        fh.write("material,theta_i,metric,value\n")
        for r in rows:
            fh.write("%s,%d,%s,%.6g\n" % r)
    print("bench_dhr_honesty: %s (%d seeds, noise %s, wavelengths %s)" % (path, NSEEDS, NOISE, WLS))
    return 0


if __name__ == "__main__":
    sys.exit(main())
