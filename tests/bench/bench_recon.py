#!/usr/bin/python3
"""bench_recon: brdf-recon at the paper's size (10x10x10 = 1000 samples, 651 wavelengths 450-1100 nm) against
scipy.interpolate.RBFInterpolator on the same samples, measured in one run:
  - time and peak memory (ru_maxrss of each child) of `brdf-recon fit` and `brdf-recon merl`;
  - held-out accuracy (2000 random directions): log-RMSE of cosine-weighted values, relative RMSE, DHR error
    at 8/30/60 degrees against the ground truth (recon_synth.py: Lambertian + GGX lobe, 2 % noise);
  - the baseline: RBFInterpolator (default thin-plate spline + linear tail, and smoothing=1e-3) in the
    isotropic frame (phi_i rotated to 0, mirror folded, the two unit vectors as a point of R^5), fitted to
    the 651 channels (held-out accuracy) and, for its MERL-equivalent, to 3 channels (its map is linear, so
    spectra are reduced to RGB first) evaluated at the 1,096,216 existing MERL cells.
Fit time per simulator material (issue 13, item 6): `brdf-recon fit` CPU time on `acq-sim truth MATERIAL --grid
10x10x10` (1 % noise, 651 wavelengths) for every material acq-sim knows (ACQ_BENCH_MATERIALS), the worst one
reported (goal <= 3 s), and on the extremes (log-uniform random values over 12 decades at three seeds, a Ward lobe
of alpha 0.01 over a 1e-8 floor, normal incidence only; 1000 rows x 651: goal <= 10 s), the worst one reported.
Times are wall clock and CPU (the machine is shared: CPU time is the steadier figure); both tools run
single-threaded (OPENBLAS_NUM_THREADS=1 under make bench, brdf-recon merl --threads 1); brdf-recon merl is also
timed with --threads 2 (the table's θh rows on both cores: speedup_fit_plus_merl_2t is a wall-clock ratio).
Writes $ACQ_BENCH_OUT/bench_recon.csv (metric,value) and prints the ratios."""
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

import benchlib

BUILD = os.environ.get("ACQ_BUILD", "build")
SRC = os.environ.get("ACQ_SRC", ".")
OUT = os.environ.get("ACQ_BENCH_OUT", os.path.join(BUILD, "bench"))
SEED = int(os.environ.get("ACQ_SEED", "1")) % (2**31)
B = os.path.join(BUILD, "brdf-recon")


CPU = {}


def timed(args):
    """Run a child; return (wall seconds, peak RSS in MiB); its CPU time goes to CPU[args[1]]."""
    dt, CPU[args[1]], rss, err = benchlib.run_child(args, "bench")
    print("   ", err.strip().replace("\n", "\n    "))
    return dt, rss


def feat(a):
    ti, pi, to, po = a.T
    d = po - pi
    return np.stack([np.sin(ti), np.cos(ti), np.sin(to) * np.cos(d), np.abs(np.sin(to) * np.sin(d)), np.cos(to)], -1)


def merl_cells():
    i = (np.arange(90) + 0.5) / 90
    th = (i * i) * math.pi / 2
    td = (np.arange(90) + 0.5) * (math.pi / 2) / 90
    pd = (np.arange(180) + 0.5) * math.pi / 180
    TH, TD, PD = np.meshgrid(th, td, pd, indexing="ij")
    d = np.stack([np.sin(TD) * np.cos(PD), np.sin(TD) * np.sin(PD), np.cos(TD)], -1)
    c, s = np.cos(TH), np.sin(TH)
    wi = np.stack([c * d[..., 0] + s * d[..., 2], d[..., 1], -s * d[..., 0] + c * d[..., 2]], -1)
    h = np.stack([s, np.zeros_like(s), c], -1)
    wo = 2 * (wi * h).sum(-1, keepdims=True) * h - wi
    ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
    wi, wo = wi[ok], wo[ok]
    ti, to = np.arccos(np.clip(wi[:, 2], 0, 1)), np.arccos(np.clip(wo[:, 2], 0, 1))
    return np.stack([ti, np.arctan2(wi[:, 1], wi[:, 0]), to, np.arctan2(wo[:, 1], wo[:, 0])], -1)


def logrmse(f, t, ang):
    c = (np.cos(ang[:, 0]) * np.cos(ang[:, 2]))[:, None]
    return float(np.sqrt(np.mean((np.log1p(np.maximum(f, 0) * c) - np.log1p(t * c)) ** 2)))


def relrmse(f, t):
    return float(np.sqrt(np.mean(((f - t) / t) ** 2)))


MATERIALS = os.environ.get("ACQ_BENCH_MATERIALS", "green-paint,white,metal,clear-coat,rough-backscatter,cloth-sheen,"
                           "sharp-lobe,narrow-lines").split(",")


def fit_times(d, res):
    """Fit CPU time at the paper size on every simulator material and on log-uniform random values."""
    sim = os.path.join(BUILD, "acq-sim")
    worst, worst_mat = 0.0, "-"
    for mat in MATERIALS:
        s = os.path.join(d, "mat_%s.csv" % mat)
        r = subprocess.run([sim, "truth", mat, "--grid", "10x10x10", "--noise", "0.01", "--seed", str(SEED), "-o", s],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if r.returncode:
            print("    fit time: %s not measured (acq-sim: %s)" % (mat, r.stderr.strip().splitlines()[-1:]))
            continue
        timed([B, "fit", s, "-o", os.path.join(d, "mat_%s.model" % mat)])
        res["fit_cpu_s_" + mat] = CPU["fit"]
        if CPU["fit"] > worst:
            worst, worst_mat = CPU["fit"], mat
    print("    fit time: worst material %s, %.2f s CPU (goal <= 3 s)" % (worst_mat, worst))
    res["fit_cpu_s_worst_material"] = worst
    # the extremes at the paper size (test_recon_honest_extremes' kinds, 651 wavelengths): the worst one reported
    import recon_synth as rs
    wl = np.arange(450, 1101, 1.0)
    worst_x, worst_xname = 0.0, "-"
    for name, (ang, f, sg) in extremes(wl):
        s = os.path.join(d, "x_%s.csv" % name)
        rs.write_csv(s, ang, f, wl, sg)
        timed([B, "fit", s, "-o", os.path.join(d, "x_%s.model" % name)])
        res["fit_cpu_s_" + name] = CPU["fit"]
        print("    fit time: extreme %s, %.2f s CPU (goal <= 10 s)" % (name, CPU["fit"]))
        if CPU["fit"] > worst_x:
            worst_x, worst_xname = CPU["fit"], name
    res["fit_cpu_s_worst_extreme"] = worst_x
    print("    fit time: worst extreme %s, %.2f s CPU (goal <= 10 s)" % (worst_xname, worst_x))


def extremes(wl):
    """The extreme inputs at the paper size (session 15's generator, /work/notes/s15/fittest-mkext.py): log-uniform
    random values over 12 decades (1000 rows; three seeds: its fit time varies by ~15 % with the data), a Ward lobe
    of alpha 0.01 over a 1e-8 floor (10 x 10 x 10, theta_i and theta_o 5-80 deg, 1 % noise), normal incidence only
    (theta_i = 0, 10 theta_o x 100 phi_o: a rough diffuse with an opposition peak). Yields (name, (ang, f, sigma))."""
    n = 1000
    for k in range(3):
        rng = np.random.default_rng(SEED + k)
        ang = np.stack([np.arccos(rng.uniform(0, 1, n)), rng.uniform(0, 2 * math.pi, n),
                        np.arccos(rng.uniform(0, 1, n)), rng.uniform(0, 2 * math.pi, n)], -1)
        yield ("log_uniform_random" if k == 0 else "log_uniform_random_%d" % (k + 1),
               (ang, 10 ** rng.uniform(-8, 4, (n, len(wl))), None))
    rng = np.random.default_rng(SEED)
    g = np.radians(5 + 75.0 * np.arange(10) / 9)
    A = np.array([[ti, 0, to, math.radians(36.0 * p)] for ti in g for to in g for p in range(10)])
    wi, wo = unit(A[:, 0], A[:, 1]), unit(A[:, 2], A[:, 3])
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    ch = np.maximum(h[:, 2], 1e-9)
    t2, al = (1 - ch * ch) / (ch * ch), 0.01
    f = 1e-8 + 0.25 * np.exp(-t2 / al ** 2) / (4 * math.pi * al * al * np.sqrt(np.maximum(wi[:, 2], 1e-4) *
                                                                              np.maximum(wo[:, 2], 1e-4)))
    f = f[:, None] * np.ones(len(wl))
    sg = 0.01 * f + 1e-12
    yield "ward_alpha_0.01", (A, f + sg * rng.standard_normal(f.shape), sg)
    A = np.array([[0, 0, math.radians(5 + 75.0 * o / 9), math.radians(3.6 * p)] for o in range(10) for p in range(100)])
    rho = 0.3 + 0.2 * (wl - 450) / 650
    s2 = 0.25
    on = 1 - 0.5 * s2 / (s2 + 0.33)  # Oren-Nayar's A term; its B term vanishes at theta_i = 0 (tan(min) = 0)
    c = np.clip((unit(A[:, 0], A[:, 1]) * unit(A[:, 2], A[:, 3])).sum(-1), -1, 1)
    gg = np.arccos(c) / math.radians(8)
    f = (rho[None, :] / math.pi) * (on * (1 + np.exp(-gg * gg)))[:, None]
    sg = 0.01 * f + 1e-5
    yield "normal_incidence_only", (A, f + sg * rng.standard_normal(f.shape), sg)


def unit(t, p):
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)


def main():
    try:
        from scipy.interpolate import RBFInterpolator
    except ImportError:
        print("bench_recon: scipy missing for /usr/bin/python3")
        return 1
    os.makedirs(OUT, exist_ok=True)
    d = tempfile.mkdtemp(prefix="bench_recon_")
    sys.path.insert(0, os.path.join(SRC, "tests", "integration"))
    import recon_synth as rs
    s, h, th, dh = (os.path.join(d, x) for x in ("s.csv", "h.csv", "th.npy", "dhr.csv"))
    print("bench_recon: seed %d, data in %s" % (SEED, d))
    subprocess.run([sys.executable, os.path.join(SRC, "tests/integration/recon_synth.py"), "--samples", s,
                    "--heldout", h, "--truth-held", th, "--nheld", "2000", "--nwl", "651", "--seed", str(SEED),
                    "--dhr", dh], check=True)
    res = {}
    m = os.path.join(d, "m.model")
    res["recon_fit_s"], res["recon_fit_rss_mib"] = timed([B, "fit", s, "-o", m])
    res["recon_fit_cpu_s"] = CPU["fit"]
    res["recon_merl_s"], res["recon_merl_rss_mib"] = timed([B, "merl", m, "-o", os.path.join(d, "m.binary"),
                                                            "--threads", "1"])
    res["recon_merl_cpu_s"] = CPU["merl"]
    res["recon_merl_2t_s"], _ = timed([B, "merl", m, "-o", os.path.join(d, "m2t.binary"), "--threads", "2"])
    res["recon_merl_2t_cpu_s"] = CPU["merl"]
    res["recon_merl10nm_s"], _ = timed([B, "merl", m, "-o", os.path.join(d, "m10.binary"), "--threads", "1",
                                        "--bin-nm", "10"])
    res["recon_merl10nm_cpu_s"] = CPU["merl"]
    e = os.path.join(d, "e.csv")
    res["recon_eval2000_s"], _ = timed([B, "eval", m, h, "-o", e])
    ev = np.genfromtxt(e, delimiter=",", skip_header=1)[:, 4:]
    t = np.load(th)
    ang = np.load(th + ".ang.npy")
    res["recon_logrmse"] = logrmse(ev, t, ang)
    res["recon_relrmse"] = relrmse(ev, t)
    dd = os.path.join(d, "d.csv")
    res["recon_dhr_s"], _ = timed([B, "dhr", m, "--draws", "32", "-o", dd])
    a = np.genfromtxt(dd, delimiter=",", skip_header=1)
    b = np.genfromtxt(dh, delimiter=",", skip_header=1)
    rel = np.abs(a[:, 2] - b[:, 2]) / b[:, 2]
    for tdeg in (8, 30, 60):
        res["recon_dhr_maxrel_%d" % tdeg] = float(rel[a[:, 0] == tdeg].max())

    # the other kernels and the sqrt transform on the same data (accuracy, or the fit's error)
    for name, extra in (("exp", ["--kernel", "exp"]), ("gauss", ["--kernel", "gauss"]),
                        ("paper", ["--kernel", "paper"]), ("sqrt", ["--transform", "sqrt"]),
                        ("notrend", ["--trend", "none"])):
        mk = os.path.join(d, "m_%s.model" % name)
        p = subprocess.run([B, "fit", s, "-o", mk, *extra], capture_output=True, text=True)
        if p.returncode != 0:
            print("    %s: fit failed: %s" % (name, p.stderr.strip()))
            res["variant_%s_failed" % name] = 1
            continue
        ek = os.path.join(d, "e_%s.csv" % name)
        subprocess.run([B, "eval", mk, h, "-o", ek], check=True, capture_output=True)
        res["variant_%s_logrmse" % name] = logrmse(np.genfromtxt(ek, delimiter=",", skip_header=1)[:, 4:], t, ang)

    # the baseline, single-threaded BLAS as for brdf-recon (OPENBLAS_NUM_THREADS=1 under make bench)
    S = np.genfromtxt(s, delimiter=",", skip_header=2)
    X = feat(np.radians(S[:, :4]))
    F = S[:, 4:4 + 651]
    Xh = feat(ang)
    r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    for name, kw in (("scipy", {}), ("scipy_s1e-3", {"smoothing": 1e-3})):
        t0, c0 = time.perf_counter(), time.process_time()
        rbf = RBFInterpolator(X, F, **kw)
        res[name + "_fit_s"] = time.perf_counter() - t0
        res[name + "_fit_cpu_s"] = time.process_time() - c0
        fh = rbf(Xh)
        res[name + "_logrmse"] = logrmse(fh, t, ang)
        res[name + "_relrmse"] = relrmse(np.maximum(fh, 0), t)
    # MERL-equivalent: fit to 3 channels (a fixed 3 x 651 reduction: the cost does not depend on the weights)
    wl = rs.wavelengths(651)
    W3 = np.stack([np.exp(-((wl - c) / 40.0) ** 2) for c in (600, 550, 450)])
    cells = merl_cells()
    t0, c0 = time.perf_counter(), time.process_time()
    rbf = RBFInterpolator(X, F @ W3.T)
    Xc = feat(cells)
    part = Xc[: len(Xc) // 8]  # evaluated on 1/8 of the cells, scaled: the cost is linear in the cells
    t1, c1 = time.perf_counter(), time.process_time()
    rbf(part)
    t2, c2 = time.perf_counter(), time.process_time()
    res["scipy_merl_cells"] = len(Xc)
    res["scipy_fit3_merl_s"] = (t1 - t0) + (t2 - t1) * len(Xc) / len(part)
    res["scipy_fit3_merl_cpu_s"] = (c1 - c0) + (c2 - c1) * len(Xc) / len(part)
    res["scipy_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    res["scipy_rss_before_mib"] = r0 / 1024.0

    fit_times(d, res)
    res["speedup_fit_plus_merl"] = res["scipy_fit3_merl_s"] / (res["recon_fit_s"] + res["recon_merl_s"])
    res["speedup_fit_plus_merl_cpu"] = res["scipy_fit3_merl_cpu_s"] / (res["recon_fit_cpu_s"] + res["recon_merl_cpu_s"])
    res["speedup_fit_plus_merl10nm_cpu"] = res["scipy_fit3_merl_cpu_s"] / (res["recon_fit_cpu_s"] +
                                                                          res["recon_merl10nm_cpu_s"])
    res["speedup_fit_plus_merl_2t"] = res["scipy_fit3_merl_s"] / (res["recon_fit_s"] + res["recon_merl_2t_s"])
    res["speedup_fit_651"] = res["scipy_fit_s"] / res["recon_fit_s"]
    res["accuracy_ratio_logrmse_vs_scipy_default"] = res["scipy_logrmse"] / res["recon_logrmse"]
    res["accuracy_ratio_logrmse_vs_scipy_best"] = min(res["scipy_logrmse"], res["scipy_s1e-3_logrmse"]) / res["recon_logrmse"]
    benchlib.write_results(OUT, "bench_recon", res, 42)
    return 0


if __name__ == "__main__":
    sys.exit(main())
