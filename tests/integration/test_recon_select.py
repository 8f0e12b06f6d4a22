#!/usr/bin/python3
"""Integration test of `brdf-recon select` against the select/adaptive contract (OWNERS.md,
/work/notes/select-contract.md): a seed sweep of the simulator's green paint (acq-sim truth --grid 3x4x5) fitted,
candidates on a grid with every pair also written swapped and rotated (reciprocal duplicates).
Checked: the JSON's fields and types; the picks are candidates of the file, at most --batch, never two copies of
one measurement, the cheaper copy's id; the predicted value never rises along the batch and starts below the
current value; the current value is the RMS over wavelengths of `brdf-recon dhr`'s sigma (same draws and seed,
to 1e-9 relative) per incidence, the largest of them; a threshold above the value is met with no pick; the ln f
target; --route's charges (base/open, and with band nodes the planner's exposure price: the picks' charges add up to
their formula; a dark due, more rungs, a wider band cost more); the lobe gate's fields (and, keeping none, the picks of the candidates at or below its bound); a header-only candidate file; bad input of every kind exits 2 with a message naming what (and the row),
never a crash. `fit --warm`: the previous trend kind kept, shape and smoothing searched, so the model (settings, DHR
and σ) equals a cold fit's when that keeps the trend kind; a white model's settings refused on a sharp lobe (full
search); a conflicting kernel exits 2, a missing model 1."""
import csv
import json
import math
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.join(os.environ.get("ACQ_SRC", "."), "tests", "integration"))
from recon_tools import BUILD, run  # noqa: E402

SEED = int(os.environ.get("ACQ_SEED", "1")) % (2**31)
SIM = os.path.join(BUILD, "acq-sim")
print("ACQ_SEED=%d" % SEED)


def check(cond, what):
    if not cond:
        sys.exit("FAIL: " + what)


def write_cands(path, rows):
    with open(path, "w") as fh:
        fh.write("id,theta_i,phi_i,theta_o,phi_o,cost_s\n")
        for r in rows:
            fh.write(",".join(str(x) for x in r) + "\n")


def main():
    d = tempfile.mkdtemp(prefix="test_select.")
    seed, model = os.path.join(d, "seed.csv"), os.path.join(d, "seed.model")
    subprocess.run([SIM, "truth", "green-paint", "--grid", "3x4x5", "-o", seed, "--noise", "0.01", "--seed",
                    str(SEED % 100000 + 1), "--wavelengths", "450:1100:25"], check=True, capture_output=True)
    run("fit", seed, "-o", model)
    rows, i, twin, distinct = [], 0, {}, 0
    for ti in range(0, 76, 15):
        for to in range(5, 81, 15):
            for p in range(0, 181, 30):
                i += 1
                cost = 5 + (i * 7919 % 100) / 10.0
                rows.append((i, ti, 0, to, p, cost))
                distinct += ti > 0 or p == 0  # at normal incidence the azimuth is no direction
                if ti != to:  # the reciprocal pair rotated by 33 deg, dearer or cheaper
                    rows.append((100000 + i, to, 33, ti, p + 33, cost + (1 if i % 2 else -1)))
                    twin[i], twin[100000 + i] = 100000 + i, i
    cands = os.path.join(d, "cand.csv")
    write_cands(cands, rows)
    byid = {r[0]: r for r in rows}
    out = os.path.join(d, "out.json")
    run("select", model, "--candidates", cands, "--target", "dhr:8,30,60", "--batch", "8", "-o", out)
    with open(out) as fh:
        j = json.load(fh)
    print(json.dumps(j)[:600])
    t = j["target"]
    check(t["spec"] == "dhr:8,30,60" and t["threshold"] is None and t["met"] is False, "target fields")
    check(len(t["per"]) == 3 and abs(t["value"] - max(t["per"])) <= 1e-12 * t["value"], "value = largest per")
    check(j["model"] == model and isinstance(j["criterion"], str) and j["criterion"], "model, criterion")
    check(j["candidates"]["read"] == len(rows) and j["candidates"]["distinct"] == distinct, "reciprocal duplicates "
          "merged (%d read, %d distinct, expected %d)" % (j["candidates"]["read"], j["candidates"]["distinct"], distinct))
    picks = j["picks"]
    check(1 <= len(picks) <= 8, "picks within the batch")
    seen, prev = set(), t["value"]
    for p in picks:
        check(set(p) >= {"id", "gain", "cost_s", "predicted_value_after"}, "pick fields")
        check(p["id"] in byid and abs(p["cost_s"] - byid[p["id"]][5]) < 1e-9, "pick is a candidate with its cost")
        check(p["id"] not in seen and twin.get(p["id"]) not in seen, "one measurement picked twice")
        if p["id"] in twin:
            check(byid[p["id"]][5] <= byid[twin[p["id"]]][5], "the cheaper copy of a measurement is reported")
        seen.add(p["id"])
        check(p["gain"] > 0 and p["predicted_value_after"] <= prev * (1 + 1e-12), "gain > 0, prediction falls")
        prev = p["predicted_value_after"]
    check(picks[0]["predicted_value_after"] < t["value"], "the first pick lowers the prediction")
    # the value is `dhr`'s sigma, RMS over wavelengths per incidence
    dcsv = os.path.join(d, "dhr.csv")
    run("dhr", model, "--draws", "16", "--seed", "1", "-o", dcsv)
    acc = {}
    with open(dcsv) as fh:
        hdr = fh.readline().strip().split(",")
        for line in fh:
            v = dict(zip(hdr, map(float, line.split(","))))
            acc.setdefault(v["theta_i"], []).append(v["sigma"] ** 2)
    for k, th in enumerate((8.0, 30.0, 60.0)):
        rms = math.sqrt(sum(acc[th]) / len(acc[th]))
        print("theta_i %g: select %.10g, dhr RMS sigma %.10g" % (th, t["per"][k], rms))
        check(abs(rms - t["per"][k]) <= 1e-9 * rms, "value equals dhr's sigma RMS")
    # a threshold already met: no pick
    p = run("select", model, "--candidates", cands, "--target", "dhr:8,30,60:le=%.9g" % (2 * t["value"]))
    jm = json.loads(p.stdout)
    check(jm["target"]["met"] is True and jm["picks"] == [] and jm["target"]["threshold"] > 0, "threshold met")
    # ln f
    p = run("select", model, "--candidates", cands, "--target", "lnf", "--batch", "3")
    jl = json.loads(p.stdout)
    check(len(jl["target"]["per"]) == 1 and jl["target"]["value"] > 0 and len(jl["picks"]) == 3, "lnf target")
    check(set(jl["target"]["where"]) == {"theta_i", "phi_i", "theta_o", "phi_o"}, "lnf where")
    # the lobe gate (:lobe_above=50): the candidates above 50 deg counted, kept only on the model's lobe; with none kept
    # the picks are those of the file without them (ids, gains); lnf:bright reports its bright cells
    p = run("select", model, "--candidates", cands, "--target", "lnf:bright:lobe_above=50", "--batch", "3")
    jg = json.loads(p.stdout)
    above = sum(1 for r in rows if r[1] > 50)
    print("lobe gate:", json.dumps(jg["candidates"]), "bright_cells", jg.get("bright_cells"))
    check(jg["candidates"]["beyond"] == above and 0 <= jg["candidates"]["admitted"] <= above and
          isinstance(jg.get("bright_cells"), int) and "beyond" not in jl["candidates"], "lobe gate fields")
    if jg["candidates"]["admitted"] == 0:
        below = os.path.join(d, "below.csv")
        write_cands(below, [r for r in rows if r[1] <= 50])
        jb = json.loads(run("select", model, "--candidates", below, "--target", "lnf:bright", "--batch", "3").stdout)
        check([(q["id"], q["gain"]) for q in jg["picks"]] == [(q["id"], q["gain"]) for q in jb["picks"]],
              "lobe gate keeping none: the picks of the candidates at or below the bound")
    # dhr + lnf, both must be met: the parts are the single targets' values, the value their larger ratio
    spec = "dhr:8,30,60:le=%.9g+lnf:le=%.9g" % (2 * t["value"], 0.5 * jl["target"]["value"])
    p = run("select", model, "--candidates", cands, "--target", spec, "--batch", "3")
    jc = json.loads(p.stdout)["target"]
    print("combined:", json.dumps(jc))
    check(abs(jc["parts"]["dhr"]["value"] - t["value"]) <= 1e-12 * t["value"] and
          abs(jc["parts"]["lnf"]["value"] - jl["target"]["value"]) <= 1e-12 * jl["target"]["value"], "combined parts")
    check(abs(jc["value"] - 2.0) < 1e-6 and jc["threshold"] == 1 and jc["met"] is False and len(jc["per"]) == 4,
          "combined value: the larger part/threshold ratio, unmet while the ln f part is")
    check(len(json.loads(p.stdout)["picks"]) == 3, "combined: picks while one part is unmet")
    # zero candidates
    empty = os.path.join(d, "empty.csv")
    write_cands(empty, [])
    p = run("select", model, "--candidates", empty, "--target", "dhr:8")
    je = json.loads(p.stdout)
    check(je["picks"] == [] and je["target"]["value"] > 0 and je["candidates"]["distinct"] == 0, "no candidates")
    # bad input: exit 2, a message saying what and where
    bad = [
        ([(1, 95, 0, 10, 0, 5)], "theta_i", "row 1"),
        ([(1, 10, 0, 10, 0, 5), (2, 10, 0, 20, 0, 0)], "cost_s", "row 2"),
        ([(1, 10, 0, 10, 0, 5), (1, 10, 0, 20, 0, 5)], "id 1", "more than once"),
        ([(1.5, 10, 0, 10, 0, 5)], "id", "row 1"),
        ([(1, 10, 0, "nan", 0, 5)], "bad4.csv:2", "column 4"),
        ([(1, 10, 0, 10, 0, "x")], "bad5.csv:2", "column 6"),
    ]
    for k, (rs, w1, w2) in enumerate(bad):
        f = os.path.join(d, "bad%d.csv" % k)
        write_cands(f, rs)
        p = run("select", model, "--candidates", f, "--target", "dhr:8", ok=False)
        check(p.returncode == 2 and w1 in p.stderr and w2 in p.stderr, "bad candidates %d: exit 2 naming %s %s"
              % (k, w1, w2))
    big = os.path.join(d, "big.csv")
    write_cands(big, [(k, 10, 0, 20, k % 180, 5) for k in range(50001)])
    p = run("select", model, "--candidates", big, "--target", "dhr:8", ok=False)
    check(p.returncode == 2 and "50001 candidates, at most 50000" in p.stderr, "too many candidates: exit 2")
    with open(os.path.join(d, "nohdr.csv"), "w") as fh:
        fh.write("id,theta_i,phi_i,theta_o,cost_s\n1,10,0,10,5\n")
    junk = os.path.join(d, "junk.model")
    with open(junk, "wb") as fh:
        fh.write(b"BRDFRBF\n" + os.urandom(200))
    cases = [
        (["select", model, "--candidates", os.path.join(d, "nohdr.csv"), "--target", "dhr:8"], "phi_o"),
        (["select", model, "--candidates", os.path.join(d, "missing.csv"), "--target", "dhr:8"], "missing.csv"),
        (["select", model, "--candidates", cands, "--target", "dhr:8,100"], "100"),
        (["select", model, "--candidates", cands, "--target", "mse"], "mse"),
        (["select", model, "--candidates", cands, "--target", "lnf:le=-2"], "le="),
        (["select", junk, "--candidates", cands, "--target", "dhr:8"], "junk.model"),
        (["select", model, "--candidates", cands], "--target"),
        (["select", model, "--target", "dhr:8"], "--candidates"),
        (["select", model, "--candidates", cands, "--target", "dhr:8", "--batch", "-1"], "--batch"),
    ]
    # --route: each pick charged its increment to the batch's route (the candidates' bench positions, base and open
    # costs as columns); the charged cost_s adds up to at most base + open + the moves, and bad input says what
    rcands = os.path.join(d, "route.csv")
    with open(rcands, "w") as fh:
        fh.write("id,theta_i,phi_i,theta_o,phi_o,cost_s,base_s,open_s,laser_deg,det_theta_deg,det_phi_deg\n")
        for r in rows:
            fh.write("%d,%.9g,%.9g,%.9g,%.9g,%.9g,2,3,%.9g,%.9g,%.9g\n" % (tuple(r) + (r[1], r[3], r[4])))
    route = "0,0,0,10,20,0.3,20,60,0.2,30,90,0.2,0.075"
    p = run("select", model, "--candidates", rcands, "--route", route, "--target", "lnf", "--batch", "4")
    jr = json.loads(p.stdout)
    check(len(jr["picks"]) == 4 and all(2 <= x["cost_s"] <= 2 + 3 + 20 for x in jr["picks"]) and
          jr["picks"][0]["cost_s"] >= 5, "route: picks charged base (+ open when new) + their move")
    # --route with band nodes (the planner's price of the exposures, plan_time.c): every candidate at the arms' bench
    # position (no motion) and incidence, so the picks' charges add up to their exposure seconds: point_s each, a dark
    # of dark_s with probability q^(since + k) for the k-th, q = 1 - 1/rungs, the band of the picks' band_cos
    # (largest / smallest) moving point by the nodes' difference, dark and rungs by their ratio
    nodes = [(1, 2.0, 1.0, 4.0), (10, 3.0, 2.0, 8.0)]
    broute = "40,30,0,10,20,0.3,20,60,0.2,30,90,0.2,0.075," + ",".join("%g,%g,%g,%g" % x for x in nodes)
    bcands = os.path.join(d, "band.csv")

    def banded(since, coses, rungs=4.0, n=None):
        some = [r for r in rows if r[0] < 100000 and r[1] == 30 and r[3] in (35, 65)][:n] if n else rows
        with open(bcands, "w") as fh:
            fh.write("id,theta_i,phi_i,theta_o,phi_o,cost_s,base_s,open_s,laser_deg,det_theta_deg,det_phi_deg,"
                     "point_s,dark_s,rungs,since,band_cos\n")
            for k, r in enumerate(some):
                fh.write("%d,%.9g,%.9g,%.9g,%.9g,%.9g,2,3,40,30,0,2,1,%g,%g,%g\n"
                         % (tuple(r) + (rungs, since, coses[k % len(coses)])))
        picks = json.loads(run("select", model, "--candidates", bcands, "--route", broute, "--target", "lnf",
                               "--batch", str(n or 4)).stdout)["picks"]
        cs = [coses[[r[0] for r in some].index(x["id"]) % len(coses)] for x in picks]
        rho = max(cs) / min(cs)
        f = math.log(rho) / math.log(nodes[1][0])  # the nodes' band, linear in ln rho
        node = [a + f * (b - a) for a, b in zip(nodes[0], nodes[1])]
        q = 1 - 1 / (rungs * node[3] / nodes[0][3])
        k = len(picks)
        want = k * node[1] + node[2] / nodes[0][2] * q ** since * (1 - q ** k) / (1 - q)
        got = sum(x["cost_s"] for x in picks)
        print("band price: since %g, band_cos %s, rungs %g: %d picks charged %.6f s, expected %.6f s (rho %g)"
              % (since, coses, rungs, k, got, want, rho))
        check(k == (n or 4) and abs(got - want) < 1e-6, "band price: the picks' charges are their exposure seconds")
        return got

    fresh, cached, more = banded(0, [1.0]), banded(2, [1.0]), banded(2, [1.0], rungs=8.0)
    banded(0, [1.0, 0.5, 0.25, 0.1])  # whichever band the picks span
    two, wide = banded(0, [1.0, 1.0], n=2), banded(0, [1.0, 0.1], n=2)  # two picks: the second widens the band
    check(fresh > cached and more > cached and wide > two + 1.9, "band price: a dark due, more rungs, a wider band "
          "(its point 1 s dearer for both picks) cost more")
    cases += [
        (["select", model, "--candidates", rcands, "--target", "lnf", "--route", broute], "point_s"),
        (["select", model, "--candidates", bcands, "--target", "lnf", "--route", broute.replace(",1,2,1,4,", ",2,2,1,4,")],
         "band node 1"),
        (["select", model, "--candidates", bcands, "--target", "lnf", "--route", broute + ",20,1"], "band nodes of 4"),
    ]
    with open(os.path.join(d, "noroute.csv"), "w") as fh:
        fh.write("id,theta_i,phi_i,theta_o,phi_o,cost_s\n1,10,0,10,0,5\n")
    with open(os.path.join(d, "badbase.csv"), "w") as fh:
        fh.write("id,theta_i,phi_i,theta_o,phi_o,cost_s,base_s,open_s,laser_deg,det_theta_deg,det_phi_deg\n"
                 "1,10,0,10,0,5,0,3,10,10,0\n")
    cases += [
        (["select", model, "--candidates", rcands, "--target", "lnf", "--route", "1,2,3"], "13 comma-separated"),
        (["select", model, "--candidates", rcands, "--target", "lnf", "--route", route.replace("10,20", "0,20", 1)],
         "axis 1 needs speed > 0"),
        (["select", model, "--candidates", os.path.join(d, "noroute.csv"), "--target", "lnf", "--route", route],
         "base_s"),
        (["select", model, "--candidates", os.path.join(d, "badbase.csv"), "--target", "lnf", "--route", route],
         "base_s = 0 must be > 0"),
    ]
    for args, what in cases:
        p = run(*args, ok=False)
        check(p.returncode == 2 and what in p.stderr, "%s: exit 2 naming %s" % (" ".join(args[2:]), what))
    # fit --warm: the previous settings kept when still leave-one-out competitive, else the full search
    more, wm = os.path.join(d, "more.csv"), os.path.join(d, "warm.model")
    subprocess.run([SIM, "truth", "green-paint", "--grid", "4x5x6", "-o", more, "--noise", "0.01", "--seed",
                    str(SEED % 100000 + 2), "--wavelengths", "450:1100:25"], check=True, capture_output=True)
    p = run("fit", more, "--warm", model, "-o", wm)
    info = {k: v for k, v in (ln.split("=", 1) for ln in run("info", wm, "--no-budget").stdout.splitlines()
                              if "=" in ln)}
    prev = {k: v for k, v in (ln.split("=", 1) for ln in run("info", model, "--no-budget").stdout.splitlines()
                              if "=" in ln)}
    check("warm start from" in p.stderr and ("kept" in p.stderr or "full search" in p.stderr), "warm start said")
    # the warm model is the cold one when the trend kind is kept (shape and smoothing searched as in a cold fit):
    # the same settings, and the same DHR and σ (the value and the σ select stops on) to 1e-9
    cm = os.path.join(d, "cold.model")
    run("fit", more, "-o", cm)
    cold = {k: v for k, v in (ln.split("=", 1) for ln in run("info", cm, "--no-budget").stdout.splitlines()
                              if "=" in ln)}
    if "kept" in p.stderr and cold["trend"] == prev["trend"]:
        for k in ("shape", "smoothing", "trend", "trend_alpha", "loo_rms_transformed"):
            check(info[k] == cold[k], "warm %s %s, cold %s" % (k, info[k], cold[k]))
        out = []
        for mod in (wm, cm):
            o = os.path.join(d, os.path.basename(mod) + ".dhr.csv")
            run("dhr", mod, "--theta-i", "8,30,60", "--draws", "16", "--seed", "1", "-o", o)
            out.append([(float(r["dhr"]), float(r["sigma"])) for r in csv.DictReader(open(o))])
        worst = max(max(abs(a[0] - b[0]), abs(a[1] - b[1])) / b[1] for a, b in zip(*out))
        check(len(out[0]) == len(out[1]) and worst <= 1e-9, "warm and cold DHR/σ differ by %.3g σ" % worst)
        print("fit --warm: the same model as a cold fit (trend %s, shape %s, smoothing %s; DHR and σ within %.2g σ)"
              % (cold["trend"], cold["shape"], cold["smoothing"], worst))
    white, wmod, lobe = os.path.join(d, "white.csv"), os.path.join(d, "white.model"), os.path.join(d, "lobe.csv")
    subprocess.run([SIM, "truth", "white", "--grid", "3x4x5", "-o", white, "--noise", "0.01", "--seed", "1",
                    "--wavelengths", "450:1100:25"], check=True, capture_output=True)
    subprocess.run([SIM, "truth", "sharp-lobe", "--grid", "5x5x8", "-o", lobe, "--noise", "0.01", "--seed", "1",
                    "--wavelengths", "450:1100:25"], check=True, capture_output=True)
    run("fit", white, "-o", wmod)
    p = run("fit", lobe, "--warm", wmod, "-o", os.path.join(d, "lobe.model"))
    check("not leave-one-out competitive" in p.stderr and "full search" in p.stderr, "warm start refused on a lobe")
    p = run("fit", lobe, "--warm", wmod, "--kernel", "exp", "-o", os.path.join(d, "x.model"), ok=False)
    check(p.returncode == 2 and "--warm" in p.stderr, "warm with another kernel: exit 2")
    p = run("fit", lobe, "--warm", os.path.join(d, "none.model"), "-o", os.path.join(d, "x.model"), ok=False)
    check(p.returncode == 1 and "none.model" in p.stderr, "missing warm model named")
    print("ok")


if __name__ == "__main__":
    main()
