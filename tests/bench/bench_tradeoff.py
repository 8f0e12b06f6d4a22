#!/usr/bin/python3
"""bench_tradeoff: speed against accuracy of the whole chain, measured on the simulated bench.

Three studies, each a CSV table and a PNG plot under $ACQ_BENCH_OUT (default build/bench/), then a summary
(tradeoff_summary.txt, also copied to summary.txt) recommending a plan per time budget:

 1. Sampling density: plans from sparse to dense (grids N x N x N with the paper's ranges, N = 5, 8, 10,
    12, 15, and Fibonacci sets of equal counts: N incidences x N^2 near-uniform directions). Each plan file
    is written to the output folder and dry-run by `acqctl plan --json --points`: predicted sweep time on the
    simulated bench, and the positions actually measured (blind points dropped). The ground truth of
    `acq-sim truth MATERIAL --eval` at those positions gets the noise model of `acq-sim truth --grid`
    (value x (1 + REL N) + FLOOR N, sigma columns) with several seeds; `brdf-recon fit` (defaults: Wendland,
    log, shape and smoothing by leave-one-out) reconstructs it; accuracy is the held-out log-RMSE of
    cosine-weighted values at random directions (truth from `acq-sim truth --eval`) and the DHR error at
    8/30/60 degrees (truth from `acq-sim truth --dhr`). Materials: green paint, white, metal.
 2. Integration time and averages: the per-band SNR measured by build/bench/bench_snr (the simulator's
    counts model, sim/sim_physics.h) becomes a per-wavelength relative noise on the paper's plan; the DHR
    uncertainty (brdf-recon dhr Monte Carlo) and the DHR error follow, against the planned sweep time of
    the same plan with that fixed integration time and number of averages.
 3. Compute: kernels x transforms, and the spectral resolution kept (1 nm measured, binned to 2/5/10/20 nm
    bands by averaging), on the paper's plan: CPU time and peak RSS (/usr/bin/time) of `fit` and `merl` (MERL
    export timed for the log transform only: the transform does not change its cost), against the same
    accuracy measures.
Plans with N > 10 (800-3300 centres) are fitted with one noise seed (the spread over seeds is printed for
the others). Everything runs single-threaded (OPENBLAS_NUM_THREADS=1), two jobs at a time. ACQ_TRADEOFF_QUICK=1 runs
a reduced set (one seed, N up to 10) to test the script."""
import concurrent.futures as cf
import json
import math
import os
import re
import shutil
import subprocess
import sys
import threading
import time

import numpy as np

BUILD = os.path.abspath(os.environ.get("ACQ_BUILD", "build"))
SRC = os.path.abspath(os.environ.get("ACQ_SRC", "."))
OUT = os.path.abspath(os.environ.get("ACQ_BENCH_OUT", os.path.join(BUILD, "bench")))
SEED = int(os.environ.get("ACQ_SEED", "1")) % (2**31)
QUICK = os.environ.get("ACQ_TRADEOFF_QUICK") == "1"
FIXED_SHAPE = os.environ.get("ACQ_TRADEOFF_FIXED_SHAPE") == "1"
WORK = os.path.join(OUT, "tradeoff")
SIM, REC, CTL = (os.path.join(BUILD, p) for p in ("acq-sim", "brdf-recon", "acqctl"))
ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1", ACQ_SRC=SRC)

MATERIALS = ["green-paint", "white", "metal"]
SIZES = [5, 8, 10] if QUICK else [5, 8, 10, 12, 15]
WIDTHS = [1, 10] if QUICK else [1, 5, 10, 20]
NSEEDS = 1 if QUICK else 3
WL = "450:1100:10"        # 66 channels for studies 1 and 2
REL, FLOOR = 0.01, 1e-4   # noise model of acq-sim truth --grid (its default REL), floor in 1/sr
THETA_DHR = [8, 30, 60]
NHELD = 1000
BUDGETS_MIN = [30, 60, 180]
JOBS = 2


def log(*a):
    print(*a, flush=True)


TIME = "/usr/bin/time"


def run(args, out=None):
    """Run a child; returns (CPU seconds, peak RSS MiB, wall seconds); raises RuntimeError on failure. CPU and
    RSS come from /usr/bin/time (a child forked from this Python process would report Python's own peak RSS:
    Linux keeps the high-water mark across exec); without it, from wait4."""
    t0 = time.perf_counter()
    tf = None
    if os.access(TIME, os.X_OK):
        tf = "%s/.time.%d.%d" % (WORK, os.getpid(), threading.get_ident())
        args = [TIME, "-f", "%M %U %S", "-o", tf] + list(args)
    p = subprocess.Popen(args, stdout=open(out, "w") if out else subprocess.DEVNULL, stderr=subprocess.PIPE,
                         env=ENV)
    err = p.stderr.read().decode()
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    if status != 0:
        raise RuntimeError("%s failed: %s" % (" ".join(args), err.strip()))
    if tf:
        with open(tf) as f:
            rss, u, sy = f.read().split()[-3:]
        os.unlink(tf)
        return float(u) + float(sy), float(rss) / 1024.0, wall
    return ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0, wall


def info(model):
    """key=value lines of brdf-recon info."""
    p = subprocess.run([REC, "info", model], capture_output=True, text=True, env=ENV, check=True)
    return dict(l.split("=", 1) for l in p.stdout.splitlines() if "=" in l)


def read_csv(path):
    """Header and float rows of a CSV with # comments."""
    with open(path) as f:
        lines = [l for l in f if not l.startswith("#") and l.strip()]
    head = lines[0].strip().split(",")
    return head, np.array([[float(x) for x in l.split(",")] for l in lines[1:]])


def write_queries(path, ang):
    with open(path, "w") as f:
        f.write("theta_i,phi_i,theta_o,phi_o\n")
        for a in ang:
            f.write("%.10g,%.10g,%.10g,%.10g\n" % tuple(a))


def truth_eval(mat, ang_path, out, wl=WL):
    run([SIM, "truth", mat, "--eval", ang_path, "-o", out, "--wavelengths", wl])
    h, d = read_csv(out)
    return np.array([float(x) for x in h[4:]]), d[:, :4], d[:, 4:]


def truth_dhr(mat, out, wl=WL):
    run([SIM, "truth", mat, "--dhr", out, "--theta-i", ",".join(map(str, THETA_DHR)), "--wavelengths", wl])
    _, d = read_csv(out)
    return {t: d[d[:, 0] == t][:, 2] for t in THETA_DHR}


def write_samples(path, wl, ang, val, sig):
    with open(path, "w") as f:
        f.write("theta_i,phi_i,theta_o,phi_o," + ",".join("%g" % w for w in wl) + "," +
                ",".join("sigma_%g" % w for w in wl) + "\n")
        for a, v, s in zip(ang, val, sig):
            f.write(",".join("%.10g" % x for x in a) + "," + ",".join("%.9g" % x for x in v) + "," +
                    ",".join("%.3g" % x for x in s) + "\n")


def noisy(f, rel, floor, seed):
    """The noise model of acq-sim truth --grid: value (1 + rel N) + floor N; rel may be per wavelength."""
    r = np.random.default_rng(seed)
    v = f * (1 + rel * r.standard_normal(f.shape)) + floor * r.standard_normal(f.shape)
    s = np.sqrt((rel * f) ** 2 + floor ** 2)
    return v, s


def log_rmse(pred, truth, ang):
    c = (np.cos(np.radians(ang[:, 0])) * np.cos(np.radians(ang[:, 2])))[:, None]
    return float(np.sqrt(np.mean((np.log1p(pred * c) - np.log1p(truth * c)) ** 2)))


def model_dhr(model, out, draws=16, seed=1):
    run([REC, "dhr", model, "--theta-i", ",".join(map(str, THETA_DHR)), "--draws", str(draws), "--seed", str(seed),
         "-o", out])
    _, d = read_csv(out)
    return {t: (d[d[:, 0] == t][:, 2], d[d[:, 0] == t][:, 3]) for t in THETA_DHR}


def laser_phi():
    try:
        with open(os.path.join(SRC, "config", "bench-sim.yaml")) as f:
            m = re.search(r"laser_phi_deg:\s*([-0-9.eE+]+)", f.read())
        return float(m.group(1)) if m else 0.0
    except OSError:
        return 0.0


def plan_yaml(name, n, fib, integ=None, averages=4):
    inc = "  theta_deg: {from: 0, to: 67.5, count: %d}\n" % n
    if fib:
        obs = "  fibonacci: {count: %d, max_theta_deg: 81}\n" % (n * n)
    else:
        obs = ("  theta_deg: {from: 0, to: 81, count: %d}\n  phi_deg: {from: 0, to: %.10g, count: %d}\n"
               % (n, 360.0 - 360.0 / n, n))
    integ_s = ("{mode: fixed, ms: %g}" % integ if integ else
               "{mode: auto, target_peak: 0.8, estimate_ms: 50, max_ms: 5000}")
    return ("# bench_tradeoff: %s\nname: %s\nincidence:\n%sobservation:\n%sintegration: %s\naverages: %d\n"
            "reciprocal_pairs: 0\nblind_points: drop\n" % (name, name, inc, obs, integ_s, averages))


def plan(name, text):
    """Write the plan file, dry-run it; returns (json summary, measured angles (deg) n x 4)."""
    path = os.path.join(WORK, name + ".yaml")
    with open(path, "w") as f:
        f.write(text)
    js = os.path.join(WORK, name + ".plan.json")
    run([CTL, "plan", path, "--json", "--points"], out=js)
    with open(js) as f:
        d = json.load(f)["plan"]  # acqctl's --json reply: {"ok", "plan": {...}, "source"}
    lp = laser_phi()
    ang = []
    for s in d["steps"]:
        ti, to, po = s["laser.theta"], s["detector.theta"], s["detector.phi"]  # the arms' pose
        pi = lp + (180.0 if ti < 0 else 0.0)
        if to < 0:
            to, po = -to, po + 180.0
        ang.append([abs(ti), pi % 360.0, to, po % 360.0])
    return d, np.array(ang)


def heldout(seed):
    """NHELD random direction pairs, cos(theta) uniform on [cos 81 deg, 1] (the planned range), phi_i = 0."""
    r = np.random.default_rng(seed)
    c0 = math.cos(math.radians(81))
    ti = np.degrees(np.arccos(c0 + (1 - c0) * r.random(NHELD)))
    to = np.degrees(np.arccos(c0 + (1 - c0) * r.random(NHELD)))
    return np.stack([ti, np.zeros(NHELD), to, 360 * r.random(NHELD)], -1)


class Truth:
    """Held-out truth and DHR truth per material (computed once)."""

    def __init__(self, wl=WL, tag="10nm"):
        self.q = heldout(SEED + 7)
        self.qpath = os.path.join(WORK, "heldout.csv")
        write_queries(self.qpath, self.q)
        self.f, self.dhr = {}, {}
        for m in MATERIALS:
            _, _, self.f[m] = truth_eval(m, self.qpath, os.path.join(WORK, "heldout_%s_%s.csv" % (m, tag)), wl)
            self.dhr[m] = truth_dhr(m, os.path.join(WORK, "dhr_%s_%s.csv" % (m, tag)), wl)


def reconstruct(tag, wl, ang, f, mat, truth, seed, rel=REL, fit_args=(), merl=False, draws=16, bin_to=None,
                truth_f=None, truth_dhr_=None):
    """Noisy samples → fit → held-out eval and DHR. Returns a dict of measured figures."""
    v, s = noisy(f, rel, FLOOR, seed)
    w = wl
    if bin_to:
        v, s, w = binned(v, s, wl, bin_to)
    sp = os.path.join(WORK, tag + ".samples.csv")
    write_samples(sp, w, ang, v, s)
    mp = os.path.join(WORK, tag + ".model")
    fcpu, frss, fwall = run([REC, "fit", sp, "-o", mp] + list(fit_args))
    pp = os.path.join(WORK, tag + ".pred.csv")
    run([REC, "eval", mp, truth.qpath, "-o", pp])
    _, pred = read_csv(pp)
    tf = truth_f if truth_f is not None else truth.f[mat]
    td = truth_dhr_ if truth_dhr_ is not None else truth.dhr[mat]
    inf = info(mp)
    res = {"fit_cpu_s": fcpu, "fit_rss_mib": frss, "fit_wall_s": fwall, "centres": int(inf.get("directions", 0)),
           "shape": float(inf.get("shape", "nan")), "eta": float(inf.get("smoothing", "nan")),
           "logrmse": log_rmse(pred[:, 4:], tf, truth.q)}
    d = model_dhr(mp, os.path.join(WORK, tag + ".dhr.csv"), draws=draws, seed=seed)
    for t in THETA_DHR:
        got, sig = d[t]
        res["dhr_err_%d" % t] = float(np.mean(np.abs(got - td[t]) / td[t]))
        res["dhr_sig_%d" % t] = float(np.median(sig / np.maximum(got, 1e-300)))
    res["dhr_err"] = float(np.mean([res["dhr_err_%d" % t] for t in THETA_DHR]))
    if merl:
        bp = os.path.join(WORK, tag + ".binary")
        mcpu, mrss, mwall = run([REC, "merl", mp, "-o", bp, "--threads", "1"])
        res.update(merl_cpu_s=mcpu, merl_rss_mib=mrss, merl_wall_s=mwall)
        for p in (bp, bp + ".colour.json"):
            if os.path.exists(p):
                os.unlink(p)
    for p in (sp, pp):
        os.unlink(p)
    return res


def binned(v, s, wl, width):
    """Average 1 nm channels over bands of width nm (centred); sigma of the mean of independent channels."""
    edges = np.arange(wl[0], wl[-1] + 1e-9, width)
    cols, sig, centres = [], [], []
    for e in edges:
        k = (wl >= e - width / 2 + 1e-9) & (wl < e + width / 2 + 1e-9) if width > 1 else (wl == e)
        if not k.any():
            continue
        cols.append(v[:, k].mean(1))
        sig.append(np.sqrt((s[:, k] ** 2).sum(1)) / k.sum())
        centres.append(wl[k].mean())
    return np.stack(cols, 1), np.stack(sig, 1), np.array(centres)


def bin_truth(f, wl, width):
    b, _, c = binned(f, f, wl, width)
    return b, c


def write_table(name, rows):
    path = os.path.join(OUT, name)
    keys = list(rows[0].keys())
    with open(path, "w") as f:
        f.write(",".join(keys) + "\n")
        for r in rows:
            f.write(",".join(("%.6g" % r[k]) if isinstance(r[k], float) else str(r[k]) for k in keys) + "\n")
    log("   wrote", path)
    return path


def plt_mod():
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        return plt
    except ImportError:
        log("   matplotlib missing (Debian: python3-matplotlib): no plots")
        return None


# ---- study 1: density --------------------------------------------------------------------------------
def study_density(truth, pool):
    plans = []
    for n in SIZES:
        for fib in (False, True):
            name = "%s-%d" % ("fib" if fib else "grid", n)
            d, ang = plan(name, plan_yaml(name, n, fib))
            plans.append((name, n, fib, d, ang))
            log("   plan %-8s requested %5d measured %5d  sweep %7.0f s (predicted)" % (name, d["requested"],
                                                                                    d["measured"], d["predicted_s"]))
    # phase A: N <= 10, NSEEDS seeds; phase B: N > 10 (800-3300 centres), one seed (fits take 10-80 s CPU).
    # Shape and smoothing by leave-one-out (the defaults) everywhere; ACQ_TRADEOFF_FIXED_SHAPE=1 fixes the
    # shape of phase B to the one chosen for grid-10 (same material, seed 0), 4x cheaper.
    rows = []
    shape10 = {}
    for phase in ("A", "B"):
        jobs = {}
        for name, n, fib, d, ang in plans:
            if (phase == "A") != (n <= 10):
                continue
            qp = os.path.join(WORK, name + ".points.csv")
            write_queries(qp, ang)
            for m in MATERIALS:
                wl, _, f = truth_eval(m, qp, os.path.join(WORK, "%s_%s.truth.csv" % (name, m)))
                fa = ("--shape", "%g" % shape10[m]) if phase == "B" and m in shape10 and FIXED_SHAPE else ()
                for k in range(NSEEDS if phase == "A" else 1):
                    tag = "%s_%s_s%d" % (name, m, k)
                    jobs[pool.submit(reconstruct, tag, wl, ang, f, m, truth, SEED + 101 * k, REL, fa)] = (
                        name, n, fib, d, m, k, "fixed(grid-10)" if fa else "loo")
        for fu in cf.as_completed(jobs):
            name, n, fib, d, m, k, mode = jobs[fu]
            r = fu.result()
            if name == "grid-10" and k == 0:
                shape10[m] = r["shape"]
            rows.append(dict(plan=name, kind="fibonacci" if fib else "grid", n=n, requested=d["requested"],
                             measured=d["measured"], sweep_s=float(d["predicted_s"]), raster_s=float(d["raster_s"]),
                             material=m, seed=k, shape_mode=mode, **r))
            log("   %-8s %-11s seed %d: %4d centres, log-RMSE %.4f  DHR err %.3f %%  fit %.1f s CPU %.0f MiB" %
                (name, m, k, r["centres"], r["logrmse"], 100 * r["dhr_err"], r["fit_cpu_s"], r["fit_rss_mib"]))
    rows.sort(key=lambda r: (r["kind"], r["n"], r["material"], r["seed"]))
    write_table("tradeoff_density.csv", rows)
    return rows


def aggregate(rows):
    """Per plan: mean over seeds and materials (and per material) of the accuracy measures."""
    out = {}
    for r in rows:
        a = out.setdefault(r["plan"], dict(plan=r["plan"], kind=r["kind"], n=r["n"], measured=r["measured"],
                                           sweep_s=r["sweep_s"], per={}, fit=[]))
        a["per"].setdefault(r["material"], []).append((r["logrmse"], r["dhr_err"], r["dhr_err_8"]))
        a["fit"].append(r["fit_cpu_s"])
    for a in out.values():
        a["logrmse"] = float(np.mean([np.mean([x[0] for x in v]) for v in a["per"].values()]))
        a["dhr_err"] = float(np.mean([np.mean([x[1] for x in v]) for v in a["per"].values()]))
        for m, v in a["per"].items():
            a["logrmse_" + m] = float(np.mean([x[0] for x in v]))
            a["logrmse_sd_" + m] = float(np.std([x[0] for x in v]))
            a["dhr_err_" + m] = float(np.mean([x[1] for x in v]))
            a["dhr8_err_" + m] = float(np.mean([x[2] for x in v]))
        a["fit_cpu_s"] = float(np.mean(a["fit"]))
    return sorted(out.values(), key=lambda a: a["sweep_s"])


def pareto(aggs, key):
    front, best = [], math.inf
    for a in sorted(aggs, key=lambda a: (a["sweep_s"], a[key])):
        if a[key] < best:
            front.append(a)
            best = a[key]
    return front


def plot_density(aggs, plt):
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.8))
    for ax, key, lab in ((axs[0], "logrmse", "held-out log-RMSE (cos-weighted)"),
                         (axs[1], "dhr_err", "DHR relative error (8/30/60°)")):
        for m, mk in zip(MATERIALS, "osD"):
            for kind, col in (("grid", "C0"), ("fibonacci", "C1")):
                pts = [a for a in aggs if a["kind"] == kind]
                ax.plot([a["sweep_s"] / 60 for a in pts], [a[key.replace("dhr_err", "dhr_err") + "_" + m] for a in pts],
                        mk + "-", color=col, alpha=0.55, ms=5, label="%s, %s" % (kind, m))
        fr = pareto(aggs, key)
        ax.plot([a["sweep_s"] / 60 for a in fr], [a[key] for a in fr], "k--", lw=2, label="Pareto (mean of materials)")
        for a in aggs:
            ax.annotate(a["plan"], (a["sweep_s"] / 60, a[key]), fontsize=7, alpha=0.8)
        ax.plot([a["sweep_s"] / 60 for a in aggs], [a[key] for a in aggs], "k.", ms=6)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("planned sweep time on the simulated bench (min)")
        ax.set_ylabel(lab)
        ax.grid(True, which="both", alpha=0.3)
        for b in BUDGETS_MIN:
            ax.axvline(b, color="grey", lw=0.8, ls=":")
    axs[0].legend(fontsize=6, ncol=2)
    fig.suptitle("Sampling density: sweep time vs reconstruction error (%d seed%s, noise %g %% + %g sr⁻¹)" %
                 (NSEEDS, "s" if NSEEDS > 1 else "", 100 * REL, FLOOR))
    fig.tight_layout()
    p = os.path.join(OUT, "tradeoff_pareto.png")
    fig.savefig(p, dpi=110)
    log("   wrote", p)


# ---- study 2: integration time and averages ----------------------------------------------------------
def study_snr(truth, pool):
    snr_csv = os.path.join(OUT, "bench_snr.csv")
    if not os.path.exists(snr_csv):
        run([os.path.join(BUILD, "bench", "bench_snr")])
    rows_snr = []
    with open(snr_csv) as f:
        for l in f:
            if l.startswith("#") or l.startswith("case"):
                continue
            c, t, a, w, s, snr, sat = l.strip().split(",")
            rows_snr.append((c, float(t), int(a), float(w), float(s), float(snr), int(sat)))
    case = "paint-diffuse"
    settings = [(t, a) for a in (1, 4, 16) for t in (2, 10, 50)]
    name = "paper-10"
    _, ang = plan(name, plan_yaml(name, 10, False))
    qp = os.path.join(WORK, name + ".snrpoints.csv")
    write_queries(qp, ang)
    wl, _, f = truth_eval("green-paint", qp, os.path.join(WORK, "snr_truth.csv"))
    jobs = {}
    meta = {}
    for t, a in settings:
        band = {r[3]: r for r in rows_snr if r[0] == case and r[1] == t and r[2] == a}
        if not band:
            continue
        centres = np.array(sorted(band))
        sat = any(band[c][6] for c in centres)
        snr = np.array([band[c][5] for c in centres])
        idx = np.clip(np.searchsorted(centres, wl) - 1, 0, len(centres) - 1)
        idx = np.where((idx + 1 < len(centres)) & (np.abs(centres[np.minimum(idx + 1, len(centres) - 1)] - wl) <
                                                   np.abs(centres[idx] - wl)), idx + 1, idx)
        rel = 1.0 / np.maximum(snr[idx], 1e-9)
        pn = "snr-%gms-%davg" % (t, a)
        d, _ = plan(pn, plan_yaml(pn, 10, False, integ=t, averages=a))
        meta[(t, a)] = (d, sat, float(np.median(snr)), float(np.median(rel)))
        if sat:
            continue
        jobs[pool.submit(reconstruct, pn, wl, ang, f, "green-paint", truth, SEED + 5, rel, (), False, 64)] = (t, a)
    rows = []
    for (t, a), (d, sat, msnr, mrel) in sorted(meta.items()):
        rows.append(dict(integration_ms=t, averages=a, point_dwell_s=float(d["point_dwell_s"]),
                         sweep_s=float(d["predicted_s"]), median_snr=msnr, median_rel_noise=mrel, saturated=int(sat),
                         dhr_sig_8=math.nan, dhr_err_8=math.nan, logrmse=math.nan))
    for fu in cf.as_completed(jobs):
        t, a = jobs[fu]
        r = fu.result()
        for row in rows:
            if row["integration_ms"] == t and row["averages"] == a:
                row.update(dhr_sig_8=r["dhr_sig_8"], dhr_err_8=r["dhr_err_8"], logrmse=r["logrmse"])
        log("   %4g ms x %2d: DHR(8°) sigma %.3f %%, error %.3f %%" % (t, a, 100 * r["dhr_sig_8"], 100 * r["dhr_err_8"]))
    rows.sort(key=lambda r: (r["averages"], r["integration_ms"]))
    write_table("tradeoff_snr.csv", rows)
    return rows_snr, rows


def plot_snr(rows_snr, rows, plt):
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.6))
    ax = axs[0]
    for a, ls in zip((1, 4, 16), ("-", "--", ":")):
        for t, col in zip((2, 10, 50, 200), ("C0", "C1", "C2", "C3")):
            pts = [r for r in rows_snr if r[0] == "paint-diffuse" and r[1] == t and r[2] == a]
            if pts:
                ax.plot([r[3] for r in pts], [r[5] if not r[6] else np.nan for r in pts], ls, color=col,
                        label="%g ms × %d" % (t, a))
    ax.set_yscale("log")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("SNR of S − D (green paint, diffuse geometry)")
    ax.legend(fontsize=6, ncol=3)
    ax.grid(True, which="both", alpha=0.3)
    ax = axs[1]
    ok = [r for r in rows if not r["saturated"] and not math.isnan(r["dhr_sig_8"])]
    ax.plot([r["sweep_s"] / 60 for r in ok], [100 * r["dhr_sig_8"] for r in ok], "o", label="DHR(8°) σ (Monte Carlo)")
    ax.plot([r["sweep_s"] / 60 for r in ok], [100 * r["dhr_err_8"] for r in ok], "x", label="DHR(8°) error vs truth")
    for r in ok:
        ax.annotate("%g ms×%d" % (r["integration_ms"], r["averages"]), (r["sweep_s"] / 60, 100 * r["dhr_sig_8"]),
                    fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("planned sweep time, paper plan 10×10×10 (min)")
    ax.set_ylabel("relative DHR σ / error at 8° (%)")
    ax.legend(fontsize=7)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    p = os.path.join(OUT, "tradeoff_snr.png")
    fig.savefig(p, dpi=110)
    log("   wrote", p)


# ---- study 3: compute --------------------------------------------------------------------------------
def study_compute(pool):
    name = "paper-10"
    _, ang = plan(name, plan_yaml(name, 10, False))
    qp = os.path.join(WORK, name + ".points.csv")
    write_queries(qp, ang)
    mats = ["green-paint", "metal"]
    t1 = Truth("450:1100:1", "1nm")
    jobs = {}
    f1 = {}
    for m in mats:
        wl1, _, f1[m] = truth_eval(m, qp, os.path.join(WORK, "compute_%s_1nm.csv" % m), "450:1100:1")
    for m in mats:
        for width in WIDTHS:
            tf, _ = bin_truth(t1.f[m], wl1, width)
            td = {t: bin_truth(t1.dhr[m][t][None, :], wl1, width)[0][0] for t in THETA_DHR}
            tag = "res%dnm_%s" % (width, m)
            jobs[pool.submit(reconstruct, tag, wl1, ang, f1[m], m, t1, SEED + 3, REL, (), True, 16,
                             width if width > 1 else None, tf, td)] = dict(study="spectral", material=m,
                                                                          kernel="wendland", transform="log",
                                                                          bin_nm=width)
        tf, _ = bin_truth(t1.f[m], wl1, 10)
        td = {t: bin_truth(t1.dhr[m][t][None, :], wl1, 10)[0][0] for t in THETA_DHR}
        for k in ("wendland", "exp", "gauss", "paper"):
            for tr in ("log", "sqrt"):
                if k == "wendland" and tr == "log":
                    continue  # the 10 nm row of the spectral study
                tag = "k_%s_%s_%s" % (k, tr, m)
                jobs[pool.submit(reconstruct_safe, tag, wl1, ang, f1[m], m, t1, SEED + 3, REL,
                                 ("--kernel", k, "--transform", tr), tr == "log", 16, 10, tf, td)] = dict(
                    study="kernel", material=m, kernel=k, transform=tr, bin_nm=10)
    rows = []
    for fu in cf.as_completed(jobs):
        meta = jobs[fu]
        r = fu.result()
        row = dict(meta)
        for key in ("fit_cpu_s", "fit_rss_mib", "merl_cpu_s", "merl_rss_mib", "logrmse", "dhr_err", "dhr_err_8"):
            row[key] = r.get(key, math.nan)
        row["error"] = r.get("error", "")
        rows.append(row)
        log("   %-8s %-8s %-4s %2d nm %-11s fit %6.2f s %6.0f MiB  merl %6.2f s  log-RMSE %.4f  DHR err %.2f %% %s" %
            (row["study"], row["kernel"], row["transform"], row["bin_nm"], row["material"], row["fit_cpu_s"],
             row["fit_rss_mib"], row["merl_cpu_s"], row["logrmse"], 100 * row["dhr_err"], row["error"]))
    rows.sort(key=lambda r: (r["study"], r["material"], r["kernel"], r["transform"], r["bin_nm"]))
    write_table("tradeoff_compute.csv", rows)
    return rows


def reconstruct_safe(*a, **k):
    try:
        return reconstruct(*a, **k)
    except RuntimeError as e:
        msg = str(e).split("failed:")[-1].strip().replace(",", ";")[:160]
        return {"error": msg}


def plot_compute(rows, plt):
    fig, axs = plt.subplots(1, 2, figsize=(12, 4.6))
    ax = axs[0]
    for m, mk in zip(("green-paint", "metal"), "oD"):
        pts = sorted([r for r in rows if r["study"] == "spectral" and r["material"] == m], key=lambda r: r["bin_nm"])
        ax.plot([r["fit_cpu_s"] + r["merl_cpu_s"] for r in pts], [r["logrmse"] for r in pts], mk + "-", label=m)
        for r in pts:
            ax.annotate("%d nm (%.0f MiB)" % (r["bin_nm"], max(r["fit_rss_mib"], r["merl_rss_mib"])),
                        (r["fit_cpu_s"] + r["merl_cpu_s"], r["logrmse"]), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("CPU time, fit + MERL export (s)")
    ax.set_ylabel("held-out log-RMSE (binned truth)")
    ax.set_title("spectral resolution kept", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax = axs[1]
    for m, mk in zip(("green-paint", "metal"), "oD"):
        pts = [r for r in rows if r["bin_nm"] == 10 and r["material"] == m and not r["error"]]
        ax.plot([r["fit_cpu_s"] for r in pts], [r["logrmse"] for r in pts], mk, label=m)
        for r in pts:
            ax.annotate("%s/%s" % (r["kernel"], r["transform"]), (r["fit_cpu_s"], r["logrmse"]), fontsize=7)
    ax.set_xlabel("fit CPU time (s), 10 nm channels")
    ax.set_ylabel("held-out log-RMSE")
    ax.set_yscale("log")
    ax.set_title("kernel / transform (paper plan 10×10×10)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    p = os.path.join(OUT, "tradeoff_compute.png")
    fig.savefig(p, dpi=110)
    log("   wrote", p)


# ---- summary -----------------------------------------------------------------------------------------
def summary(aggs, snr_rows, comp_rows, wall):
    L = []
    L.append("bench_tradeoff summary (measured by tests/bench/bench_tradeoff.py; ACQ_SEED=%d; %d noise seed%s;"
             " noise %g %% + %g sr^-1;" % (SEED, NSEEDS, "s" if NSEEDS > 1 else "", 100 * REL, FLOOR))
    L.append("  %d held-out directions, theta <= 81 deg; DHR error = mean over wavelengths of |rel. error| at 8/30/60 deg)" % NHELD)
    L.append("")
    L.append("Sampling density (means over materials; per material: green-paint / white / metal log-RMSE):")
    L.append("  %-8s %6s %9s %10s %9s   %-26s %s" % ("plan", "points", "sweep", "log-RMSE", "DHR err", "per material",
                                                     "seed sd (largest)"))
    for a in aggs:
        L.append("  %-8s %6d %7.1f m %10.4f %8.2f%%   %-26s %.1e" % (a["plan"], a["measured"], a["sweep_s"] / 60,
                 a["logrmse"], 100 * a["dhr_err"], " / ".join("%.4f" % a["logrmse_" + m] for m in MATERIALS),
                 max(a["logrmse_sd_" + m] for m in MATERIALS)) if min(len(v) for v in a["per"].values()) > 1 else
                 "  %-8s %6d %7.1f m %10.4f %8.2f%%   %-26s (1 seed)" % (a["plan"], a["measured"], a["sweep_s"] / 60,
                 a["logrmse"], 100 * a["dhr_err"], " / ".join("%.4f" % a["logrmse_" + m] for m in MATERIALS)))
    L.append("")
    L.append("Recommended plan per time budget (lowest mean held-out log-RMSE among the plans that fit; ties"
             " within 5 % go to the shorter sweep):")
    for b in BUDGETS_MIN:
        ok = [a for a in aggs if a["sweep_s"] <= 60 * b]
        if not ok:
            L.append("  %4d min: no measured plan fits" % b)
            continue
        for key, what in (("logrmse", "by log-RMSE"), ("dhr_err", "by DHR error")):
            best = min(ok, key=lambda a: a[key])
            pick = min([a for a in ok if a[key] <= 1.05 * best[key]], key=lambda a: a["sweep_s"])
            L.append("  %4d min, %-12s: %-8s (%d points, %.1f min): log-RMSE %.4f, DHR error %.2f %%" %
                     (b, what, pick["plan"], pick["measured"], pick["sweep_s"] / 60, pick["logrmse"],
                      100 * pick["dhr_err"]))
        spare = 60 * b - max(a["sweep_s"] for a in ok)
        if spare > 0.25 * 60 * b:
            L.append("            no measured plan uses the last %.0f min: spend them on averages (below) or a"
                     " second sweep" % (spare / 60))
    fr = pareto(aggs, "logrmse")
    L.append("  Pareto front (sweep time vs log-RMSE): " + ", ".join("%s (%.0f min)" % (a["plan"], a["sweep_s"] / 60)
                                                               for a in fr))
    L.append("")
    if snr_rows:
        L.append("Integration time x averages (paper plan, green paint, SNR of the diffuse geometry from bench_snr):")
        for r in snr_rows:
            L.append("  %5g ms x %2d: sweep %6.1f min, median SNR %7.1f, DHR(8) sigma %s, error %s%s" %
                     (r["integration_ms"], r["averages"], r["sweep_s"] / 60, r["median_snr"],
                      "%.3f %%" % (100 * r["dhr_sig_8"]) if not math.isnan(r["dhr_sig_8"]) else "-",
                      "%.3f %%" % (100 * r["dhr_err_8"]) if not math.isnan(r["dhr_err_8"]) else "-",
                      "  (saturates)" if r["saturated"] else ""))
        L.append("")
    if comp_rows:
        L.append("Compute (paper plan; CPU s and peak RSS MiB of brdf-recon fit and merl, single thread):")
        for r in comp_rows:
            merl = ("merl %6.2f s %5.0f MiB" % (r["merl_cpu_s"], r["merl_rss_mib"]) if not math.isnan(r["merl_cpu_s"])
                    else "merl (not run)      ")
            L.append("  %-8s %-8s %-4s %2d nm %-11s fit %6.2f s %5.0f MiB  %s  log-RMSE %s  DHR err %s %s" %
                     (r["study"], r["kernel"], r["transform"], r["bin_nm"], r["material"], r["fit_cpu_s"],
                      r["fit_rss_mib"], merl,
                      "%.4f" % r["logrmse"] if not math.isnan(r["logrmse"]) else "-",
                      "%.2f %%" % (100 * r["dhr_err"]) if not math.isnan(r["dhr_err"]) else "-", r["error"]))
    L.append("")
    L.append("bench wall time %.0f s" % wall)
    txt = "\n".join(L) + "\n"
    for n in ("tradeoff_summary.txt", "summary.txt"):
        with open(os.path.join(OUT, n), "w") as f:
            f.write(txt)
    print(txt)


def main():
    t0 = time.time()
    for p in (SIM, REC, CTL):
        if not os.access(p, os.X_OK):
            sys.exit("bench_tradeoff: %s missing (make all)" % p)
    os.makedirs(WORK, exist_ok=True)
    plt = plt_mod()
    with cf.ThreadPoolExecutor(JOBS) as pool:
        log(" study 1: sampling density vs accuracy vs sweep time")
        truth = Truth()
        rows = study_density(truth, pool)
        aggs = aggregate(rows)
        if plt:
            plot_density(aggs, plt)
        log("   (%.0f s)" % (time.time() - t0))
        log(" study 2: integration time and averages vs SNR and DHR uncertainty")
        rows_snr, snr_rows = study_snr(truth, pool)
        if plt:
            plot_snr(rows_snr, snr_rows, plt)
        log("   (%.0f s)" % (time.time() - t0))
        log(" study 3: compute (kernels, spectral resolution) vs accuracy")
        comp = study_compute(pool)
        if plt:
            plot_compute(comp, plt)
    summary(aggs, snr_rows, comp, time.time() - t0)
    if os.environ.get("ACQ_TRADEOFF_KEEP") != "1":
        shutil.rmtree(WORK, ignore_errors=True)


if __name__ == "__main__":
    main()
