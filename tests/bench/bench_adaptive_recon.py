#!/usr/bin/python3
"""bench_adaptive_recon: time to accuracy of adaptive selection (`brdf-recon select`) against fixed grids at equal
points (= equal bench time here: every candidate costs the same ACQ_ADAPT_POINT_S seconds, acq-sim's --point-time
default), on simulator materials, and the honesty of select's predictions.

Per material and seed: a seed plan (`acq-sim truth --grid 3x4x6`, 1 % noise, blind zones dropped) is fitted; then
batches of ACQ_ADAPT_BATCH picks (target dhr:8,30,60) from a candidate pool (theta_i 0..75, theta_o 5..80 step 5 deg,
delta phi 0..180 step 15 deg, pairs closer than 7.5 deg dropped as blind) are "measured" (`acq-sim truth --eval`
at the picks, 1 % noise, sigma columns as --grid writes them), appended and refitted warm (`fit --warm`), up to
ACQ_ADAPT_POINTS points. Against: the fixed grids 4x5x8 and 6x6x8 (`--grid`), and the paper's 10x10x10.
Figures per point count: the largest |DHR - truth| over wavelengths at 8/30/60 deg (the exact DHR from
`acq-sim truth --dhr`), and the RMS over wavelengths of the DHR's sigma at 8 deg.
Time to accuracy: the points adaptive needs to reach each grid's error.
Honesty of the prediction: after each batch, select's predicted sigma (predicted_per_after of its last pick)
against the sigma obtained after measuring and refitting (ratio obtained/predicted per incidence), and the
RMS over wavelengths of (DHR - truth) / predicted sigma ("z").
Warm against cold: at the last batch, the fit is also run cold: CPU seconds of both, and max |DHR_warm - DHR_cold|
in units of the cold sigma, and the sigma ratio range.
Environment: ACQ_ADAPT_MATERIALS (green-paint,white,metal,sharp-lobe,clear-coat), ACQ_ADAPT_SEEDS (3),
ACQ_ADAPT_POINTS (300), ACQ_ADAPT_BATCH (16), ACQ_ADAPT_WL (450:1100:25), ACQ_ADAPT_POINT_S (20).
Writes $ACQ_BENCH_OUT/bench_adaptive_recon.csv (material,seed,plan,points,metric,value)."""
import json
import os
import resource
import subprocess
import sys
import tempfile

import numpy as np

BUILD = os.environ.get("ACQ_BUILD", "build")
OUT = os.environ.get("ACQ_BENCH_OUT", os.path.join(BUILD, "bench"))
SIM = os.path.join(BUILD, "acq-sim")
B = os.path.join(BUILD, "brdf-recon")
MATS = os.environ.get("ACQ_ADAPT_MATERIALS", "green-paint,white,metal,sharp-lobe,clear-coat").split(",")
NSEEDS = int(os.environ.get("ACQ_ADAPT_SEEDS", "3"))
NPTS = int(os.environ.get("ACQ_ADAPT_POINTS", "300"))
BATCH = int(os.environ.get("ACQ_ADAPT_BATCH", "16"))
WL = os.environ.get("ACQ_ADAPT_WL", "450:1100:25")
POINT_S = float(os.environ.get("ACQ_ADAPT_POINT_S", "20"))
TH = (8.0, 30.0, 60.0)


def sh(args, cpu=None):
    """Run, fail loudly; with cpu (a list) append the child's CPU seconds."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(args, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit("FAIL: %s -> %d\n%s" % (" ".join(args), p.returncode, p.stderr[-2000:]))
    if cpu is not None:
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return p


def pool():
    rows = []
    for ti in range(0, 76, 5):
        for to in range(5, 81, 5):
            for p in range(0, 181, 15):
                a, b = np.radians([ti, to])
                wi = np.array([np.sin(a), 0, np.cos(a)])
                wo = np.array([np.sin(b) * np.cos(np.radians(p)), np.sin(b) * np.sin(np.radians(p)), np.cos(b)])
                if np.degrees(np.arccos(np.clip(wi @ wo, -1, 1))) < 7.5:
                    continue
                rows.append((ti, 0.0, float(to), float(p)))
    return rows


def read_samples(path):
    with open(path) as fh:
        lines = [ln for ln in fh if not ln.startswith("#")]
    return lines[0].strip(), [ln.strip() for ln in lines[1:] if ln.strip()]


def measure(d, mat, ang, seed, k):
    """Samples at the pairs ang (degrees) as acq-sim's --grid writes them: value x (1 + 0.01 N), sigma 0.01 value."""
    q, e = os.path.join(d, "q%d.csv" % k), os.path.join(d, "e%d.csv" % k)
    with open(q, "w") as fh:
        fh.write("theta_i,phi_i,theta_o,phi_o\n")
        for a in ang:
            fh.write("%g,%g,%g,%g\n" % tuple(a))
    sh([SIM, "truth", mat, "--eval", q, "-o", e, "--wavelengths", WL])
    v = np.atleast_2d(np.genfromtxt(e, delimiter=",", skip_header=1))
    rng = np.random.default_rng(seed * 1000 + k)
    f = v[:, 4:]
    noisy = f * (1 + 0.01 * rng.standard_normal(f.shape))
    sig = 0.01 * f
    return ["%s,%s,%s" % (",".join("%g" % x for x in v[i, :4]), ",".join("%.9g" % x for x in noisy[i]),
                          ",".join("%.3g" % x for x in sig[i])) for i in range(len(v))]


def dhr_figures(d, model, truth):
    out = os.path.join(d, "dhr.csv")
    sh([B, "dhr", model, "--draws", "16", "--seed", "1", "-o", out])
    m = np.genfromtxt(out, delimiter=",", names=True)
    err, s8, sig = {}, None, {}
    for th in TH:
        k = m["theta_i"] == th
        e = np.abs(m["dhr"][k] - truth[th])
        err[th] = float(e.max())
        sig[th] = m["sigma"][k]
        if th == 8.0:
            s8 = float(np.sqrt(np.mean(m["sigma"][k] ** 2)))
    return err, s8, m, sig


def main():
    os.makedirs(OUT, exist_ok=True)
    cand = pool()
    rec = []
    zs, ratios, warm_cpu, cold_cpu, warm_last, wc_dev, wc_sig = [], [], [], [], [], [], []
    for mat in MATS:
        for seed in range(1, NSEEDS + 1):
            d = tempfile.mkdtemp(prefix="bench_adapt.")
            tcsv = os.path.join(d, "truth.csv")
            sh([SIM, "truth", mat, "--dhr", tcsv, "--theta-i", "8,30,60", "--wavelengths", WL])
            t = np.genfromtxt(tcsv, delimiter=",", names=True, skip_header=2)
            truth = {th: t["dhr"][t["theta_i"] == th] for th in TH}
            # fixed grids
            for grid in ("4x5x8", "6x6x8", "10x10x10"):
                s, mdl = os.path.join(d, "g%s.csv" % grid), os.path.join(d, "g%s.model" % grid)
                sh([SIM, "truth", mat, "--grid", grid, "-o", s, "--noise", "0.01", "--seed", str(seed),
                    "--wavelengths", WL])
                npts = len(read_samples(s)[1])
                sh([B, "fit", s, "-o", mdl])
                err, s8, _, _ = dhr_figures(d, mdl, truth)
                rec.append((mat, seed, "grid " + grid, npts, err, s8))
                print("%-12s seed %d grid %-9s %4d points: max |DHR err| 8/30/60 %.4f %.4f %.4f, sigma(8) %.4f"
                      % (mat, seed, grid, npts, err[8.0], err[30.0], err[60.0], s8), flush=True)
            # adaptive
            s, mdl = os.path.join(d, "a.csv"), os.path.join(d, "a.model")
            sh([SIM, "truth", mat, "--grid", "3x4x6", "-o", s, "--noise", "0.01", "--seed", str(seed),
                "--wavelengths", WL])
            hdr, rows = read_samples(s)
            sh([B, "fit", s, "-o", mdl])
            cc = os.path.join(d, "cand.csv")
            with open(cc, "w") as fh:
                fh.write("id,theta_i,phi_i,theta_o,phi_o,cost_s\n")
                for i, a in enumerate(cand):
                    fh.write("%d,%g,%g,%g,%g,%g\n" % ((i,) + a + (POINT_S,)))
            k, pred = 0, None
            while True:
                err, s8, m, sig = dhr_figures(d, mdl, truth)
                if pred is not None:  # honesty of the last batch's prediction
                    hon = []
                    for i, th in enumerate(TH):
                        obt = float(np.sqrt(np.mean(sig[th] ** 2)))
                        ratios.append(obt / pred[i])
                        e = m["dhr"][m["theta_i"] == th] - truth[th]
                        zs.append(float(np.sqrt(np.mean(e ** 2))) / pred[i])
                        hon.append("%g: %.3g/%.3g" % (th, obt, pred[i]))
                    print("    sigma obtained/predicted after the batch: " + ", ".join(hon))
                npts = len(rows)
                rec.append((mat, seed, "adaptive", npts, err, s8))
                print("%-12s seed %d adaptive  %4d points: max |DHR err| 8/30/60 %.4f %.4f %.4f, sigma(8) %.4f"
                      % (mat, seed, npts, err[8.0], err[30.0], err[60.0], s8), flush=True)
                if npts >= NPTS:
                    break
                p = sh([B, "select", mdl, "--candidates", cc, "--target", "dhr:8,30,60", "--batch",
                        str(min(BATCH, NPTS - npts))])
                j = json.loads(p.stdout)
                if not j["picks"]:
                    break
                byid = {i: a for i, a in enumerate(cand)}
                picks = [byid[q["id"]] for q in j["picks"]]
                pred = j["picks"][-1]["predicted_per_after"]
                k += 1
                rows += measure(d, mat, picks, seed, k)
                with open(s, "w") as fh:
                    fh.write(hdr + "\n" + "\n".join(rows) + "\n")
                prev = os.path.join(d, "prev.model")
                os.replace(mdl, prev)
                cpu = []
                sh([B, "fit", s, "--warm", prev, "-o", mdl], cpu)
                warm_cpu.append(cpu[-1])
                if len(rows) >= NPTS:  # the last batch: the cold fit too
                    cm = os.path.join(d, "cold.model")
                    sh([B, "fit", s, "-o", cm], cpu)
                    warm_last.append(cpu[0])
                    cold_cpu.append(cpu[1])
                    _, _, mw, _ = dhr_figures(d, mdl, truth)
                    _, _, mc, _ = dhr_figures(d, cm, truth)
                    wc_dev.append(float(np.max(np.abs(mw["dhr"] - mc["dhr"]) / mc["sigma"])))
                    r = mw["sigma"] / mc["sigma"]
                    wc_sig += [float(r.min()), float(r.max())]
    with open(os.path.join(OUT, "bench_adaptive_recon.csv"), "w") as fh:
        fh.write("material,seed,plan,points,metric,value\n")
        for mat, seed, plan, n, err, s8 in rec:
            for th in TH:
                fh.write("%s,%d,%s,%d,dhr_err_%g,%.6g\n" % (mat, seed, plan, n, th, err[th]))
            fh.write("%s,%d,%s,%d,sigma_8,%.6g\n" % (mat, seed, plan, n, s8))
    print("\nAt equal points (every point %.0f s of bench time), mean over %d seeds of the largest |DHR error| over "
          "8/30/60 deg and sigma(8):" % (POINT_S, NSEEDS))
    for mat in MATS:
        for grid in ("4x5x8", "6x6x8", "10x10x10"):
            g = [r for r in rec if r[0] == mat and r[2] == "grid " + grid]
            n = int(np.mean([r[3] for r in g]))
            ge = np.mean([max(r[4].values()) for r in g])
            gs = np.mean([r[5] for r in g])
            a = []
            for seed in range(1, NSEEDS + 1):  # the adaptive state at the first count >= the grid's own
                c = [r for r in rec if r[0] == mat and r[1] == seed and r[2] == "adaptive" and r[3] >= n]
                if c:
                    a.append(c[0])
            if a:
                print("  %-12s %4d points: grid %-9s err %.4f sigma8 %.4f | adaptive (%d points) err %.4f sigma8 %.4f"
                      % (mat, n, grid, ge, gs, int(np.mean([r[3] for r in a])), np.mean([max(r[4].values()) for r in a]),
                         np.mean([r[5] for r in a])))
            else:
                print("  %-12s %4d points: grid %-9s err %.4f sigma8 %.4f | adaptive: not run that far"
                      % (mat, n, grid, ge, gs))
    print("\nTime to accuracy: points (x %.0f s) adaptive needs to reach each grid's largest DHR error, per seed:"
          % POINT_S)
    for mat in MATS:
        for grid in ("4x5x8", "6x6x8", "10x10x10"):
            out = []
            for seed in range(1, NSEEDS + 1):
                g = [r for r in rec if r[0] == mat and r[1] == seed and r[2] == "grid " + grid]
                ad = [r[3] for r in rec if r[0] == mat and r[1] == seed and r[2] == "adaptive"
                      and max(r[4].values()) <= max(g[0][4].values())] if g else []
                out.append("%d" % ad[0] if ad else ">%d" % NPTS)
            n = [r[3] for r in rec if r[0] == mat and r[2] == "grid " + grid]
            print("  %-12s grid %-9s (%d points): adaptive %s" % (mat, grid, n[0] if n else 0, " / ".join(out)))
    if ratios:
        r, z = np.array(ratios), np.array(zs)
        print("\nprediction honesty over %d (batch, incidence): sigma obtained / predicted median %.3g, 10-90 %% "
              "%.3g-%.3g; RMS error / predicted sigma: median %.3g, 90 %% %.3g, share <= 2: %.0f %%"
              % (len(r), np.median(r), np.percentile(r, 10), np.percentile(r, 90), np.median(z),
                 np.percentile(z, 90), 100 * np.mean(z <= 2)))
    if cold_cpu:
        print("warm fits: mean CPU %.3f s over %d; at the last batch warm %.3f s vs cold %.3f s (mean of %d); "
              "max |DHR warm - cold| / sigma_cold %.3g (median %.3g); sigma warm/cold %.3g-%.3g"
              % (np.mean(warm_cpu), len(warm_cpu), np.mean(warm_last), np.mean(cold_cpu),
                 len(cold_cpu), max(wc_dev), np.median(wc_dev), min(wc_sig), max(wc_sig)))


if __name__ == "__main__":
    main()
