#!/usr/bin/python3
"""bench_time_to_accuracy: issue 17's study — bench time an adaptive sweep needs to reach a DHR error <= 0.5 % (at
8/30/60 deg) and a held-out log-RMSE <= the paper plan's, against the fixed grids and Fibonacci sets of the README's
trade study (bench_tradeoff.py's plans), on every simulator material, over ACQ_TTA_SEEDS noise seeds.

Bench time is the planner's (daemon/plan/plan_time.c) predicted bench seconds at time scale 1 (a real bench's pace),
never this machine's wall clock: a fixed plan is charged `acqctl plan --json` predicted_s; the adaptive plan is
charged what the daemon charges itself (daemon/sweep_adaptive.c: the seed's predicted_s plus each batch's). The loop
is OFFLINE: build/bench/bench_tta_plan (tests/bench/bench_tta_plan.c) runs the daemon's own planner code for the seed,
the candidates with their cost (plan_adaptive_candidates) and each batch (the budget cut, plan_make_points from the
arms, plan_time_apply); the samples at the planned points are the truth (`acq-sim truth --eval`) with the noise
model of `acq-sim truth --grid` (1 % + 1e-4 sr^-1, bench_tradeoff.noisy), fitted with `brdf-recon fit` (warm from
the second decision, `--warm` on the previous decision's model, as daemon/recon_select.c does), and `brdf-recon
select` chooses each batch. Overlap as the plan says (config/plan-adaptive.yaml: off; with it, batch k+2 chosen from
the model through batch k). The budget counts measured bench seconds (as the daemon's); the bench time of a state
adds the arms' waits for the decisions, as on the bench: the CPU seconds of the fit and select runs behind each
batch (single-threaded BLAS, this machine; with overlap only what exceeds the batch measured meanwhile).
The adaptive plan: config/plan-adaptive.yaml (seed 4 incidences x 16 Fibonacci + its specular plane, batch 16, its
candidates and integration; its lobe gate, candidates.lobe_above_deg, passed to select as the daemon does) with the
target ACQ_TTA_TARGET (default dhr:8,30,60:le=1e-09+lnf:bright:le=1e-09, session 17: the DHR's sigma at 8, 30, 60 deg
and the largest sigma of ln f together, never met, so it runs to its budget; lnf, lnf:rad or lnf:mix instead of
lnf:bright: the plan's lnf_sigma gets weight: projected (no key), rad or mix) and the
budget ACQ_TTA_BUDGET (1.5) x the paper plan's predicted time on the lobes (G2), ACQ_TTA_BUDGET_OTHER (1.0) x
on the others (G1, G3 need no more; their time to accuracy beyond it shows as '-').
Validation (ACQ_TTA_VALIDATE=1, default on): one adaptive sweep on the simulated bench (acq-sim + acquisitiond,
tests/integration/adaptlib.py; green paint, small budget) — its recorded decisions are replayed offline from the
daemon's own samples and candidates (same picks, planned points and predicted batch times), and its DHR error at
each decision is set beside the offline loop's at equal bench time.

Figures per (material, seed, plan): bench time, points, its motion seconds (plan.h motion_s, settle included), DHR error = the largest over 8/30/60 deg of the mean over
wavelengths of |DHR - truth| / truth (the trade table's measure, its worst incidence), also the largest absolute
|DHR - truth|, and the held-out log-RMSE (bench_tradeoff: 1000 directions, cosine-weighted). Time to accuracy: the
first bench time at which both criteria hold (a fixed family: its cheapest member that meets them).
Goals (issue 17), reported met / not met with the figures:
  G1 diffuse-like (white, narrow-lines, rough-backscatter, green-paint): adaptive reaches the target in <= 1/3 of
     the paper plan's time (every seed);
  G2 lobes the paper plan cannot resolve (sharp-lobe, clear-coat): adaptive DHR error <= 0.01 within 1.5 x the
     paper plan's time (every seed);
  G3 every material: at the paper plan's time, adaptive is never worse than the paper plan (DHR error and log-RMSE,
     mean over seeds).
Environment: ACQ_TTA_MATERIALS (all eight), ACQ_TTA_SEEDS (3), ACQ_TTA_SEED_LIST (instead: e.g. 2,3), ACQ_TTA_SIZES (5,6,8,10: grids N^3 and
Fibonacci N x N^2; the trade study's 12 and 15 take 35-68 min, beyond every budget here), ACQ_TTA_WL (450:1100:25), ACQ_TTA_BUDGET (1.5), ACQ_TTA_JOBS (2), ACQ_TTA_VALIDATE (1; ACQ_TTA_VALIDATE_ONLY=1: that sweep alone, beside ACQ_TTA_ROWS, an earlier CSV),
ACQ_TTA_VALIDATE_SCALE (20), ACQ_TTA_VALIDATE_BUDGET (700), ACQ_TTA_TARGET (above), ACQ_TTA_PLAN (the adaptive plan:
config/plan-adaptive.yaml; select gets its batch). Adaptive rows also carry darks_s (of measured_s, the darks) and
charged_s (what select's route model charged the measured picks: against measured_s minus the seed's, how far its
costs fall short of the planner's). Writes $ACQ_BENCH_OUT/time_to_accuracy.csv (every state), time_to_accuracy_summary.txt
and time_to_accuracy.png (error vs bench time, one line per plan kind, per material)."""
import concurrent.futures as cf
import json
import os
import re
import shutil
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_tradeoff as T  # noqa: E402  (plans, noise model, held-out set and metrics: one definition)

BUILD, SRC, OUT = T.BUILD, T.SRC, T.OUT
WORK = os.path.join(OUT, "tta")
HELPER = os.path.join(BUILD, "bench", "bench_tta_plan")
CONF = os.path.join(SRC, "config", "bench-sim.yaml")
ALL = "green-paint,white,metal,clear-coat,rough-backscatter,cloth-sheen,sharp-lobe,narrow-lines"
MATS = os.environ.get("ACQ_TTA_MATERIALS", ALL).split(",")
NSEEDS = int(os.environ.get("ACQ_TTA_SEEDS", "3"))
# the seeds run: 1..ACQ_TTA_SEEDS, or ACQ_TTA_SEED_LIST (e.g. "2,3": a study split over runs whose CSVs are joined
# for ACQ_TTA_REPORT; each seed's figures do not depend on the others')
SEED_LIST = [int(x) for x in os.environ["ACQ_TTA_SEED_LIST"].split(",")] if os.environ.get("ACQ_TTA_SEED_LIST") \
    else list(range(1, NSEEDS + 1))
NSEEDS = max(SEED_LIST)
SIZES = [int(x) for x in os.environ.get("ACQ_TTA_SIZES", "5,6,8,10").split(",")]
WL = os.environ.get("ACQ_TTA_WL", "450:1100:25")
BUDGET_X = float(os.environ.get("ACQ_TTA_BUDGET", "1.5"))
BUDGET_OTHER = float(os.environ.get("ACQ_TTA_BUDGET_OTHER", "1.0"))
JOBS = int(os.environ.get("ACQ_TTA_JOBS", "2"))
VALIDATE = os.environ.get("ACQ_TTA_VALIDATE", "1") == "1"
# the adaptive plan's target as select takes it (never met: the run goes to its budget); the default is the study's
# own criterion, the DHR and ln f together (dhr alone: ACQ_TTA_TARGET=dhr:8,30,60:le=1e-09)
TARGET = os.environ.get("ACQ_TTA_TARGET", "dhr:8,30,60:le=1e-09+lnf:bright:le=1e-09")
DIFFUSE = ["white", "narrow-lines", "rough-backscatter", "green-paint"]
LOBES = ["sharp-lobe", "clear-coat"]
DHR_GOAL, LOBE_GOAL = 0.005, 0.01
# the adaptive plan the study runs (its target and budget replaced): config/plan-adaptive.yaml, or ACQ_TTA_PLAN (a
# variant of it, e.g. another batch size); select gets its batch, as the daemon passes the plan's
PLAN_SRC = os.environ.get("ACQ_TTA_PLAN", os.path.join(SRC, "config", "plan-adaptive.yaml"))
BATCH = [int(re.search(r"\nbatch: (\d+)", open(PLAN_SRC).read()).group(1))]
DAEMON_VALUE_CHANNELS = "64"  # daemon/recon_select.c RSEL_VALUE_CHANNELS: the replay runs select as the daemon does
TH = T.THETA_DHR
T.WL = WL
T.WORK = WORK


def log(*a):
    print(*a, flush=True)


def helper(*args, out=None):
    """bench_tta_plan with args; its stdout (JSON parsed unless out is 'text')."""
    p = subprocess.run([HELPER] + [str(a) for a in args], capture_output=True, text=True, env=T.ENV)
    if p.returncode != 0:
        raise RuntimeError("bench_tta_plan %s failed: %s" % (" ".join(map(str, args)), p.stderr.strip()))
    return p.stdout if out == "text" else json.loads(p.stdout)


def adaptive_plan(paper_s, path, overlap=None, budget_s=None, target=None):
    """config/plan-adaptive.yaml with the study's target and budget written to path."""
    text = open(PLAN_SRC).read()
    tg = target or ("{dhr_sigma: {incidence_deg: [8, 30, 60], le: 1e-9}%s}"
                    % ((", lnf_sigma: {le: 1e-9%s}" % next((", weight: " + w for w in ("rad", "mix", "bright")
                                                             if "+lnf:%s:" % w in TARGET), ""))
                       if "+lnf" in TARGET else ""))
    text = re.sub(r"\ntarget:\n  dhr_sigma: [^\n]*\n", "\ntarget: %s\n" % tg, text)
    text = re.sub(r"\nbudget:\n  seconds: [0-9.]+[^\n]*\n(\s*#[^\n]*\n)*", "\nbudget: {seconds: %.1f}\n"
                  % (budget_s or BUDGET_X * paper_s), text)
    if overlap is not None:
        text = re.sub(r"\noverlap: \w+", "\noverlap: %s" % ("true" if overlap else "false"), text)
    assert "le: 1e-9" in text or target, "plan-adaptive.yaml's layout changed: target not replaced"
    assert "budget: {seconds:" in text, "plan-adaptive.yaml's layout changed: budget not replaced"
    with open(path, "w") as fh:
        fh.write(text)
    return text


def lobe_gate(plan_path):
    """The plan's lobe gate as select's target suffix (':lobe_above=DEG', as the daemon's
    plan_adaptive_target_spec writes it), or ''."""
    g = re.search(r"\blobe_above_deg:\s*([0-9.]+)", open(plan_path).read())
    return ":lobe_above=%s" % g.group(1) if g else ""


class Truth:
    """Per material: held-out truth (bench_tradeoff's set) and the DHR truth."""

    def __init__(self, mat, q, qpath):
        self.mat, self.q, self.qpath = mat, q, qpath
        _, _, self.f = T.truth_eval(mat, qpath, os.path.join(WORK, "heldout_%s.csv" % mat), WL)
        self.dhr = T.truth_dhr(mat, os.path.join(WORK, "dhr_%s.csv" % mat), WL)

    def figures(self, model, tag):
        """(DHR error: max over incidences of the mean relative error, max absolute error, log-RMSE, sigma(8) rms)."""
        pp = os.path.join(WORK, tag + ".pred.csv")
        T.run([T.REC, "eval", model, self.qpath, "-o", pp])
        _, pred = T.read_csv(pp)
        lr = T.log_rmse(pred[:, 4:], self.f, self.q)
        d = T.model_dhr(model, os.path.join(WORK, tag + ".dhr.csv"), draws=4, seed=1)
        rel = max(float(np.mean(np.abs(d[t][0] - self.dhr[t]) / self.dhr[t])) for t in TH)
        ab = max(float(np.max(np.abs(d[t][0] - self.dhr[t]))) for t in TH)
        s8 = float(np.sqrt(np.mean(d[8][1] ** 2)))
        os.unlink(pp)
        return rel, ab, lr, s8


def samples(mat, ang, seed, tag):
    """Noisy samples at the angles (degrees, n x 4) of material mat: truth x (1 + 0.01 N) + 1e-4 N."""
    qp = os.path.join(WORK, tag + ".q.csv")
    T.write_queries(qp, ang)
    wl, _, f = T.truth_eval(mat, qp, os.path.join(WORK, tag + ".truth.csv"), WL)
    v, s = T.noisy(f, T.REL, T.FLOOR, seed)
    return wl, v, s


def fixed_run(mat, truth, seed, plans):
    rows = []
    for name, kind, n, d, ang in plans:
        tag = "%s_%s_s%d" % (name, mat, seed)
        wl, v, s = samples(mat, ang, 1000 * seed + 17 * n + (kind == "fibonacci"), tag)
        sp, mp = os.path.join(WORK, tag + ".csv"), os.path.join(WORK, tag + ".model")
        T.write_samples(sp, wl, ang, v, s)
        T.run([T.REC, "fit", sp, "-o", mp])
        rel, ab, lr, s8 = truth.figures(mp, tag)
        rows.append(dict(material=mat, seed=seed, kind=kind, plan=name, batch=-1, points=len(ang),
                         bench_s=float(d["predicted_s"]), dhr_err=rel, dhr_abs=ab, logrmse=lr, sigma8=s8,
                         motion_s=float(d["motion_s"])))
        for x in (sp, mp):
            os.unlink(x)
    return rows


def adaptive_run(mat, truth, seed, plan_path, overlap, seed_plan, budget):
    """The daemon's loop, offline. Returns one row per decision (the state the decision saw) plus the final one.
    The budget counts measured (predicted) bench seconds, as the daemon's; a row's bench time adds the arms' waits
    for the decisions: the CPU seconds of the fit and select runs behind each batch (this machine's, single-threaded
    BLAS; wall time here depends on the other users' load), minus, with overlap, the batch measured meanwhile."""
    tag = "adaptive_%s_s%d" % (mat, seed)
    steps = seed_plan["steps"]
    spent = seed_plan["predicted_s"]  # measured bench seconds (the budget's)
    motion = seed_plan["split"]["motion_s"]  # of spent: the arms' motion with settle (plan.h motion_s)
    darks = seed_plan["split"]["darks_s"]  # of spent: the darks (plan.h darks_s)
    charged = 0.0  # of the batches' spent: what select charged their picks (its route model's cost_s)
    waited = 0.0  # the arms' waits for decisions
    done = [s[:3] for s in steps]
    ang = np.array([s[3:7] for s in steps])
    wl, v, s = samples(mat, ang, 1000 * seed + 1, tag + "_b0")
    V, S, A = [v], [s], [ang]
    sp = os.path.join(WORK, tag + ".csv")
    models = []  # model after batch k (index k)
    pending = sel_pending = None  # overlap: the batch decided ahead (and its selection), not measured yet
    rows, k, fits, stop = [], 0, [], None
    target = TARGET + lobe_gate(plan_path)
    admits = []  # per decision, with a lobe gate: the candidates above its bound kept
    brights = []  # per decision, under lnf:bright: the grid cells that took lnf:rad's weight (none: lnf's picks)

    def fit(warm):
        mp = os.path.join(WORK, "%s.m%d.model" % (tag, len(models)))
        T.write_samples(sp, wl, np.vstack(A), np.vstack(V), np.vstack(S))
        args = [T.REC, "fit", sp, "-o", mp] + (["--warm", warm] if warm else [])
        fits.append(T.run(args)[0])
        models.append(mp)
        return mp

    def decide(model, done_, frm, spent_, batch):
        """One decision: candidates from frm, select on model, the batch planned; (select json, batch json, stop
        reason, select's CPU seconds)."""
        st = os.path.join(WORK, tag + ".state.json")
        with open(st, "w") as fh:
            json.dump({"done": done_, "from": frm, "spent_s": spent_}, fh)
        cc, sj = os.path.join(WORK, tag + ".cand.csv"), os.path.join(WORK, tag + ".select.json")
        nc, route = helper("cand", CONF, plan_path, st, cc, out="text").split()
        if int(nc) == 0:
            return None, None, "nothing reachable left (no candidate)", 0.0
        cpu = T.run([T.REC, "select", model, "--candidates", cc, "--route", route, "--target", target, "--batch", str(BATCH[0]),
                     "-o", sj])[0]
        sel = json.load(open(sj))
        if "admitted" in sel["candidates"]:  # the lobe gate: candidates above its bound it kept
            admits.append(sel["candidates"]["admitted"])
        if "bright_cells" in sel:  # lnf:bright: the ln f grid's cells that took lnf:rad's weight
            brights.append(sel["bright_cells"])
        if not sel["picks"]:
            return sel, None, "nothing reachable left worth measuring", cpu
        b = helper("batch", CONF, plan_path, st, sj)
        if b["k"] == 0 or not b["steps"]:
            return sel, None, "budget spent", cpu
        return sel, b, None, cpu

    def row(m_, batch):
        rel, ab, lr, s8 = truth.figures(m_, tag)
        return dict(material=mat, seed=seed, kind="adaptive", plan="adaptive", batch=batch, points=len(done),
                    bench_s=spent + waited, dhr_err=rel, dhr_abs=ab, logrmse=lr, sigma8=s8, measured_s=spent,
                    waited_s=waited, motion_s=motion, darks_s=darks, charged_s=charged,
                    admitted=sum(admits) if admits else "", bright_cells=sum(brights) if brights else "")

    m = fit(None)
    ahead_cpu = 0.0
    while True:
        rows.append(row(m, k))
        if spent >= budget - 1e-9:
            stop = "budget spent: %.0f of %.0f s" % (spent, budget)
            break
        if pending is None:  # decide from the model of everything measured (the arms wait: fit + select)
            sel, b, stop, cpu = decide(m, done, done[-1], spent, k + 1)
            sel_b = sel
            waited += fits[-1] + cpu
            if stop:
                break
        else:
            b, sel_b = pending, sel_pending
            waited += max(0.0, ahead_cpu - b_prev_s)  # decided while the previous batch was measured
        # measure batch b
        bang = np.array([s_[3:7] for s_ in b["steps"]])
        _, v, s = samples(mat, bang, 1000 * seed + 1 + len(models), tag + "_b%d" % (k + 1))
        done += [s_[:3] for s_ in b["steps"]]
        spent += b["predicted_s"]
        motion += b["split"]["motion_s"]
        darks += b["split"]["darks_s"]
        charged += sum(sel_b["picks"][int(s_[7])]["cost_s"] for s_ in b["steps"])
        b_prev_s = b["predicted_s"]
        k += 1
        pending = None
        if overlap and spent < budget:
            # batch k+1 chosen while batch k is measured: from the model before batch k, costs from its last point
            sel2, b2, why, cpu2 = decide(m, done, done[-1], spent, k + 1)
            ahead_cpu = fits[-1] + cpu2
            pending, sel_pending = b2, sel2
            if why:
                stop = why
        A.append(bang)
        V.append(v)
        S.append(s)
        m = fit(m)
        if stop and pending is None:
            rows.append(row(m, k))
            break
    for r in rows:
        r["stop"] = stop
    # the accounting (a check of this loop): a state's bench time is measured + waited, the waits never negative,
    # and every decision made cost the arms a wait (without overlap)
    assert all(abs(r["bench_s"] - r["measured_s"] - r["waited_s"]) < 1e-9 for r in rows)
    assert all(b["waited_s"] >= a["waited_s"] for a, b in zip(rows, rows[1:]))
    assert overlap or all(b["waited_s"] > a["waited_s"] for a, b in zip(rows, rows[1:]) if b["points"] > a["points"])
    log("   %-17s seed %d adaptive: %d batches, %d points, %.0f s measured + %.0f s waited (%s); DHR err %.4f, "
        "log-RMSE %.5f; fits %.2f s CPU mean%s" % (mat, seed, k, len(done), spent, waited, stop, rows[-1]["dhr_err"],
                                                   rows[-1]["logrmse"], np.mean(fits),
                                                   ("; lobe gate admitted %s" % admits if admits else "") +
                                                   ("; lnf:bright cells %s" % brights if brights else "")))
    for mp in models:
        if os.path.exists(mp):
            os.unlink(mp)
    return rows


PAPER_S = [0.0]
SEEDS = {}  # material -> the seeds analysed (analyse)


def first_met(states, ok):
    """Bench time of the first state (sorted by time) meeting ok, or None."""
    for r in sorted(states, key=lambda r: r["bench_s"]):
        if ok(r):
            return r["bench_s"]
    return None


def at_time(states, t):
    """The last state at or before bench time t (None if none)."""
    c = [r for r in states if r["bench_s"] <= t + 1e-6]
    return max(c, key=lambda r: r["bench_s"]) if c else None


def analyse(rows):
    L = []
    paper = {(r["material"], r["seed"]): r for r in rows if r["plan"] == "grid-10"}
    for mat in MATS:  # the seeds with the paper plan, both fixed families and the adaptive run
        SEEDS[mat] = [s for s in range(1, NSEEDS + 1) if (mat, s) in paper and
                      any(r["material"] == mat and r["seed"] == s and r["kind"] == "adaptive" for r in rows)]
    P = PAPER_S[0]
    L.append("Time to accuracy (bench time predicted by the planner at time scale 1, minutes; target: DHR error <= "
             "%.1f %% at 8/30/60 deg AND held-out log-RMSE <= the paper plan's, same seed; '-' not reached within "
             "the plans run; adaptive: within its budget, %.1fx the paper time on %s, %.1fx elsewhere). Paper plan (trade "
             "study grid 10^3): %.1f min." % (100 * DHR_GOAL, BUDGET_X, ",".join(LOBES), BUDGET_OTHER, P / 60))
    L.append("  %-17s %-10s %-22s %-22s %-22s" % ("material", "kind", "target (both)", "DHR <= 0.5 %",
                                                 "log-RMSE <= paper"))
    tta = {}
    for mat in [m for m in MATS if SEEDS[m]]:
        for kind in ("grid", "fibonacci", "adaptive"):
            per = {"both": [], "dhr": [], "lr": []}
            for seed in SEEDS[mat]:
                st = [r for r in rows if r["material"] == mat and r["seed"] == seed and r["kind"] == kind]
                lr0 = paper[(mat, seed)]["logrmse"]
                per["both"].append(first_met(st, lambda r: r["dhr_err"] <= DHR_GOAL and r["logrmse"] <= lr0 + 1e-12))
                per["dhr"].append(first_met(st, lambda r: r["dhr_err"] <= DHR_GOAL))
                per["lr"].append(first_met(st, lambda r: r["logrmse"] <= lr0 + 1e-12))
            tta[(mat, kind)] = per
            f = lambda v: " / ".join("-" if x is None else "%.1f" % (x / 60) for x in v)  # noqa: E731
            L.append("  %-17s %-10s %-22s %-22s %-22s" % (mat, kind, f(per["both"]), f(per["dhr"]), f(per["lr"])))
    L.append("")
    L.append("At the paper plan's time (%.1f min; adaptive: its last state within it; mean of the seeds run):" % (P / 60))
    L.append("  %-17s %26s %26s %26s" % ("material", "paper: DHR err / log-RMSE", "adaptive: DHR / log-RMSE",
                                         "adaptive at its budget: DHR"))
    g3 = {}
    for mat in [m for m in MATS if SEEDS[m]]:
        pe = [paper[(mat, s)] for s in SEEDS[mat]]
        ad = [at_time([r for r in rows if r["material"] == mat and r["seed"] == s and r["kind"] == "adaptive"], P)
              for s in SEEDS[mat]]
        ad15 = [max([r for r in rows if r["material"] == mat and r["seed"] == s and r["kind"] == "adaptive"],
                    key=lambda r: r["bench_s"]) for s in SEEDS[mat]]
        pd, pl = np.mean([r["dhr_err"] for r in pe]), np.mean([r["logrmse"] for r in pe])
        adv, al = np.mean([r["dhr_err"] for r in ad]), np.mean([r["logrmse"] for r in ad])
        g3[mat] = (pd, pl, adv, al)
        L.append("  %-17s %12.4f / %-11.5f %12.4f / %-11.5f %12.4f (abs %.4f)" % (
            mat, pd, pl, adv, al, np.mean([r["dhr_err"] for r in ad15]), np.mean([r["dhr_abs"] for r in ad15])))
    L.append("")
    L.append("Goals (issue 17):")
    for mat in [m for m in DIFFUSE if m in MATS and SEEDS[m]]:
        v = tta[(mat, "adaptive")]["both"]
        ok = all(x is not None and x <= P / 3 + 1e-6 for x in v)
        L.append("  G1 %-17s target within 1/3 of the paper time (%.1f min): %s (adaptive %s min; DHR alone %s)" % (
            mat, P / 180, "MET" if ok else "NOT MET", " / ".join("-" if x is None else "%.1f" % (x / 60) for x in v),
            " / ".join("-" if x is None else "%.1f" % (x / 60) for x in tta[(mat, "adaptive")]["dhr"])))
    for mat in [m for m in LOBES if m in MATS and SEEDS[m]]:
        v = []
        for s in SEEDS[mat]:
            st = [r for r in rows if r["material"] == mat and r["seed"] == s and r["kind"] == "adaptive"]
            v.append(first_met(st, lambda r: r["dhr_err"] <= LOBE_GOAL and r["bench_s"] <= BUDGET_X * P + 1e-6))
        best = [min(r["dhr_err"] for r in rows if r["material"] == mat and r["seed"] == s and r["kind"] == "adaptive"
                    and r["bench_s"] <= BUDGET_X * P + 1e-6) for s in SEEDS[mat]]
        ok = all(x is not None for x in v)
        L.append("  G2 %-17s DHR error <= %.2f within %.1fx the paper time (%.1f min): %s (reached at %s min; "
                 "best DHR error per seed %s; paper plan %s)" % (
                     mat, LOBE_GOAL, BUDGET_X, BUDGET_X * P / 60, "MET" if ok else "NOT MET",
                     " / ".join("-" if x is None else "%.1f" % (x / 60) for x in v),
                     " / ".join("%.4f" % b for b in best),
                     " / ".join("%.4f" % paper[(mat, s)]["dhr_err"] for s in SEEDS[mat])))
    for mat in g3:
        pd, pl, adv, al = g3[mat]
        L.append("  G3 %-17s never worse than the paper plan at its time: %s (DHR %.4f vs %.4f: %s; log-RMSE %.5f vs "
                 "%.5f: %s)" % (mat, "MET" if adv <= pd and al <= pl else "NOT MET", adv, pd,
                                "not worse" if adv <= pd else "worse", al, pl, "not worse" if al <= pl else "worse"))
    return "\n".join(L)


def plot(rows, plt):
    n = len(MATS)
    nc = min(n, 4)
    npair = (n + nc - 1) // nc
    fig, axs = plt.subplots(2 * npair, nc, figsize=(3.6 * nc, 5.6 * npair), squeeze=False)
    P = PAPER_S[0] / 60
    for j, mat in enumerate(MATS):
        for i, (key, lab) in enumerate((("dhr_err", "DHR error (worst of 8/30/60°)"), ("logrmse", "held-out log-RMSE"))):
            ax = axs[2 * (j // nc) + i][j % nc]
            for kind, col in (("grid", "C0"), ("fibonacci", "C1"), ("adaptive", "C3")):
                st = [r for r in rows if r["material"] == mat and r["kind"] == kind]
                if kind == "adaptive":
                    for s in SEEDS[mat]:
                        x = sorted((r["bench_s"] / 60, r[key]) for r in st if r["seed"] == s)
                        ax.plot([a for a, _ in x], [b for _, b in x], "-", color=col, lw=1,
                                label="adaptive (per seed)" if s == 1 else None)
                else:
                    names = sorted({r["plan"] for r in st}, key=lambda p: min(r["bench_s"] for r in st if r["plan"] == p))
                    x = [np.mean([r["bench_s"] for r in st if r["plan"] == p]) / 60 for p in names]
                    y = [np.mean([r[key] for r in st if r["plan"] == p]) for p in names]
                    ax.plot(x, y, "o-", color=col, ms=3, label="%s (mean of seeds)" % kind)
            ax.axvline(P, color="k", lw=0.8, ls="--")
            ax.axvline(P / 3, color="grey", lw=0.8, ls=":")
            if key == "dhr_err":
                ax.axhline(DHR_GOAL, color="g", lw=0.8, ls=":")
                if mat in LOBES:
                    ax.axhline(LOBE_GOAL, color="m", lw=0.8, ls=":")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(True, which="both", alpha=0.3)
            if i == 0:
                ax.set_title(mat, fontsize=9)
            if i == 1:
                ax.set_xlabel("bench time (min, planner)", fontsize=8)
            if j % nc == 0:
                ax.set_ylabel(lab, fontsize=8)
            ax.tick_params(labelsize=7)
    axs[0][0].legend(fontsize=6)
    fig.suptitle("Time to accuracy (offline loop, bench time predicted at time scale 1; seeds %s)\n"
                 "dashed: the paper plan's time, dotted: 1/3 of it; green: DHR 0.5 %%, magenta: 0.01"
                 % ",".join(str(x) for x in sorted({r["seed"] for r in rows})), fontsize=9)
    fig.tight_layout()
    p = os.path.join(OUT, "time_to_accuracy.png")
    fig.savefig(p, dpi=100)
    log("   wrote", p)


def dhr_error_1nm(model, truth1):
    """The DHR error (as Truth.figures) of a model whose wavelengths are any within 450..1100 nm, against the truth
    at 1 nm (truth1: incidence -> 651 values), interpolated linearly to the model's wavelengths."""
    out = os.path.join(WORK, "validate.dhr.csv")
    T.run([T.REC, "dhr", model, "--theta-i", ",".join(map(str, TH)), "--draws", "4", "--seed", "1", "-o", out])
    _, d = T.read_csv(out)
    err = []
    for t in TH:
        k = d[:, 0] == t
        tr = np.interp(d[k, 1], np.arange(450.0, 1101.0), truth1[t])
        err.append(float(np.mean(np.abs(d[k, 2] - tr) / tr)))
    return max(err)


def validate(rows, paper_s):
    """One adaptive sweep of the study's plan on the simulated bench (green paint, budget ACQ_TTA_VALIDATE_BUDGET
    bench seconds, time scale ACQ_TTA_VALIDATE_SCALE), then each recorded decision replayed by the offline loop's
    parts from the daemon's own files: select on its model and candidates (same picks), the candidates from the
    planned points before it (same ids, costs), the batch planned from select's answer (same points, same predicted
    time, the helper at the daemon's time scale); and the daemon's DHR error per decision beside the offline
    loop's at the same batch. Returns text lines."""
    sys.path.insert(0, os.path.join(SRC, "tests", "integration"))
    import adaptlib as A  # noqa: E402
    L = A.L
    scale = float(os.environ.get("ACQ_TTA_VALIDATE_SCALE", "20"))
    budget = float(os.environ.get("ACQ_TTA_VALIDATE_BUDGET", "700"))
    mat = "green-paint"
    out = ["Validation of the offline loop against the daemon (acq-sim + acquisitiond, time scale %g, %s, the "
           "study's plan with a budget of %.0f s):" % (scale, mat, budget)]
    b = A.bench(scale=scale)
    try:
        b.start_sim()
        b.start_daemon()
        text = adaptive_plan(paper_s, os.path.join(WORK, "validate.yaml"), budget_s=budget)
        sid = L.start_sweep(b, text, "tta-validate")
        t0 = time.time()
        row = L.drive_to_end(b, sid, timeout=900, sample=mat)
        if row["state"] != "completed":
            return out + ["  the sweep ended %s: NOT VALIDATED" % row["state"]]
        dec, why = A.check_decisions(b, sid)
        out.append("  the sweep: %d points, %d batches, %.0f s wall; stop: %s" % (
            row.get("points_total", 0), len(dec) - 2, time.time() - t0, why))
        db = b.db()
        pts = db.execute("SELECT order_index, theta_i, phi_i, theta_o, phi_o FROM points WHERE sweep_id = ? ORDER BY "
                         "order_index", (sid,)).fetchall()
        db.close()
        conf = b.conf
        plan_path = os.path.join(WORK, "validate.yaml")
        seed = helper("seed", conf, plan_path, "--time-scale", scale)
        pos = [s[:3] for s in seed["steps"]]
        ok_seed = len(pos) == dec[0]["n_points"] and all(
            max(abs(a - b_) for a, b_ in zip(s[3:7], p[1:5])) < 1e-6 for s, p in zip(seed["steps"], pts))
        out.append("  seed: %d points, predicted %.2f s; helper %d points, %.2f s, angles %s" % (
            dec[0]["n_points"], dec[0]["predicted_s"], len(pos), seed["predicted_s"], "equal" if ok_seed else "DIFFER"))
        truth1 = T.truth_dhr(mat, os.path.join(WORK, "validate_dhr.csv"), "450:1100:1")
        spent = dec[0]["predicted_s"]
        worst = {"cost": 0.0, "time": 0.0, "angle": 0.0}
        same = True
        for r in dec[1:-1]:
            K, first = r["batch"], r["first_order_index"]
            bdir = os.path.join(b.state, os.path.dirname(r["model"]))
            for p in sorted(r["picks"], key=lambda p: p["order_index"] if p["order_index"] is not None else 1e9):
                if p["order_index"] is not None:
                    while len(pos) <= p["order_index"]:
                        pos.append(None)
                    pos[p["order_index"]] = [p["laser_theta"], p["detector_theta"], p["detector_phi"]]
            st = os.path.join(WORK, "validate.state.json")
            with open(st, "w") as fh:
                json.dump({"done": pos[:first], "from": pos[first - 1], "spent_s": spent}, fh)
            cc, sj = os.path.join(WORK, "validate.cand.csv"), os.path.join(WORK, "validate.select.json")
            route = helper("cand", conf, plan_path, st, cc, "--time-scale", scale, out="text").split()[1]
            _, mine = T.read_csv(cc)
            _, theirs = T.read_csv(os.path.join(bdir, "candidates.csv"))
            ids_same = mine.shape == theirs.shape and np.array_equal(mine[:, 0], theirs[:, 0])
            if ids_same:
                worst["cost"] = max(worst["cost"], float(np.max(np.abs(mine[:, 5] - theirs[:, 5]) / theirs[:, 5])))
            T.run([T.REC, "select", os.path.join(bdir, "model.brdf"), "--candidates", os.path.join(bdir, "candidates.csv"),
                   "--route", route, "--target", r["target_spec"], "--batch", str(BATCH[0]), "--value-channels", DAEMON_VALUE_CHANNELS, "-o", sj])
            sel = json.load(open(sj))
            picks_same = [x["id"] for x in sel["picks"]] == [p["candidate_id"] for p in r["picks"]]
            bb = helper("batch", conf, plan_path, st, sj, "--time-scale", scale)
            got = [s[3:7] for s in bb["steps"]]
            want = [p[1:5] for p in pts[first:first + r["n_points"]]]
            pts_same = len(got) == len(want)
            if pts_same:
                d = max(max(abs(a - c) % 360 if abs(a - c) % 360 < 180 else 360 - abs(a - c) % 360
                            for a, c in zip(g, w)) for g, w in zip(got, want))
                worst["angle"] = max(worst["angle"], d)
                pts_same = d < 1e-3
            worst["time"] = max(worst["time"], abs(bb["predicted_s"] - r["predicted_s"]) / r["predicted_s"])
            same = same and ids_same and picks_same and pts_same
            rel = dhr_error_1nm(os.path.join(b.state, r["model"]), truth1)
            nm = sum(1 for line in open(os.path.join(bdir, "samples.csv")) if line[:1].isdigit() or line[:1] == "-")
            off = [x for x in rows if x["material"] == mat and x["kind"] == "adaptive" and x["points"] == nm]
            out.append("  batch %2d: %2d points, daemon predicted %6.1f s, replay %6.1f s; candidates %s, picks %s, "
                       "points %s; DHR error of the model it used (%d samples) %.4f (offline loop at %d points, seeds: %s)" % (
                           K, r["n_points"], r["predicted_s"], bb["predicted_s"], "same" if ids_same else "DIFFER",
                           "same" if picks_same else "DIFFER", "same" if pts_same else "DIFFER", nm, rel, nm,
                           " / ".join("%.4f" % x["dhr_err"] for x in sorted(off, key=lambda x: x["seed"]))))
            spent += r["predicted_s"]
        out.append("  replay %s: largest relative cost difference %.2g, predicted batch time %.2g, planned angle "
                   "%.2g deg" % ("AGREES" if same and worst["time"] < 0.01 else "DISAGREES", worst["cost"],
                                 worst["time"], worst["angle"]))
        return out
    except (AssertionError, RuntimeError, OSError) as e:
        return out + ["  NOT VALIDATED: %s" % e]
    finally:
        b.cleanup(keep=os.environ.get("ACQ_TTA_KEEP") == "1")


def load_rows(path):
    """The rows of a time_to_accuracy.csv written before (ACQ_TTA_REPORT: the table and plot again, nothing run)."""
    with open(path) as fh:
        keys = fh.readline().strip().split(",")
        rows = []
        for line in fh:
            r = dict(zip(keys, line.rstrip("\n").split(",")))
            for k in ("seed", "batch", "points"):
                r[k] = int(r[k])
            for k in ("bench_s", "dhr_err", "dhr_abs", "logrmse", "sigma8", "measured_s", "waited_s", "motion_s",
                      "darks_s", "charged_s"):
                if r.get(k):
                    r[k] = float(r[k])
            rows.append(r)
    return rows


def main():
    t0 = time.time()
    if os.environ.get("ACQ_TTA_REPORT"):
        rows = load_rows(os.environ["ACQ_TTA_REPORT"])
        MATS[:] = [m for m in MATS if any(r["material"] == m for r in rows)]
        global NSEEDS
        NSEEDS = max(r["seed"] for r in rows)
        PAPER_S[0] = [r["bench_s"] for r in rows if r["plan"] == "grid-10"][0]
        txt = analyse(rows)
        vp = os.path.join(os.path.dirname(os.path.abspath(os.environ["ACQ_TTA_REPORT"])), "time_to_accuracy_validation.txt")
        if os.path.exists(vp):
            txt += "\n\n" + open(vp).read()
        print(txt)
        plt = T.plt_mod()
        if plt:
            plot(rows, plt)
        return 0
    for p in (T.SIM, T.REC, T.CTL, HELPER):
        if not os.access(p, os.X_OK):
            sys.exit("bench_time_to_accuracy: %s missing (make all build/bench/bench_tta_plan)" % p)
    os.makedirs(WORK, exist_ok=True)
    os.makedirs(T.WORK, exist_ok=True)
    if os.environ.get("ACQ_TTA_VALIDATE_ONLY") == "1":  # the daemon validation alone (offline rows: ACQ_TTA_ROWS CSV)
        d, _ = T.plan("grid-10", T.plan_yaml("grid-10", 10, False))
        rows = load_rows(os.environ["ACQ_TTA_ROWS"]) if os.environ.get("ACQ_TTA_ROWS") else []
        val = "\n".join(validate(rows, float(d["predicted_s"])))
        with open(os.path.join(OUT, "time_to_accuracy_validation.txt"), "w") as fh:
            fh.write(val + "\n")
        print(val + "\nwall time %.0f s" % (time.time() - t0))
        return 0
    plans = []
    for n in SIZES:
        for fib in (False, True):
            name = "%s-%d" % ("fib" if fib else "grid", n)
            d, ang = T.plan(name, T.plan_yaml(name, n, fib))
            plans.append((name, "fibonacci" if fib else "grid", n, d, ang))
    if not any(p[0] == "grid-10" for p in plans):
        name = "grid-10"
        d, ang = T.plan(name, T.plan_yaml(name, 10, False))
        plans.append((name, "grid", 10, d, ang))
    PAPER_S[0] = [float(p[3]["predicted_s"]) for p in plans if p[0] == "grid-10"][0]
    plan_path = os.path.join(WORK, "plan-adaptive-study.yaml")
    text = adaptive_plan(PAPER_S[0], plan_path)
    plan_other = os.path.join(WORK, "plan-adaptive-study-other.yaml")
    adaptive_plan(PAPER_S[0], plan_other, budget_s=BUDGET_OTHER * PAPER_S[0])
    overlap = re.search(r"\noverlap: true", text) is not None
    seed_plan = helper("seed", CONF, plan_path)
    dry = json.loads(subprocess.run([T.CTL, "--json", "plan", plan_path, "--config", CONF], capture_output=True,
                                    text=True, check=True).stdout)["plan"]
    log("bench_time_to_accuracy: materials %s, seeds %s, wavelengths %s, plans %s; paper plan (grid-10) %.0f s "
        "predicted; adaptive: seed %d points %.1f s (acqctl plan: %.1f s), budget %.0f s (%s; else %.0f s), overlap %s; "
        "offline loop "
        "(bench time = the planner's prediction at time scale 1); work in %s" % (
            ",".join(MATS), ",".join(map(str, SEED_LIST)), WL, ",".join(p[0] for p in plans), PAPER_S[0], len(seed_plan["steps"]),
            seed_plan["predicted_s"], dry["predicted_s"], BUDGET_X * PAPER_S[0], ",".join(LOBES), BUDGET_OTHER * PAPER_S[0],
            overlap, WORK))
    if abs(seed_plan["predicted_s"] - dry["predicted_s"]) > 1e-6 * dry["predicted_s"]:
        sys.exit("bench_time_to_accuracy: the helper's seed time %.3f s differs from acqctl plan's %.3f s"
                 % (seed_plan["predicted_s"], dry["predicted_s"]))
    q = T.heldout(T.SEED + 7)
    qpath = os.path.join(WORK, "heldout.csv")
    T.write_queries(qpath, q)
    rows = []
    with cf.ThreadPoolExecutor(JOBS) as pool:
        truths = {m: pool.submit(Truth, m, q, qpath) for m in MATS}
        truths = {m: f.result() for m, f in truths.items()}
        jobs = {}
        # seed after seed (a run cut short still has whole seeds: ACQ_TTA_REPORT on its CSV), the longest first
        for seed in SEED_LIST:
            for mat in sorted(MATS, key=lambda m: m not in LOBES):
                lobe = mat in LOBES
                jobs[pool.submit(adaptive_run, mat, truths[mat], seed, plan_path if lobe else plan_other, overlap,
                                 seed_plan, (BUDGET_X if lobe else BUDGET_OTHER) * PAPER_S[0])] = mat
                jobs[pool.submit(fixed_run, mat, truths[mat], seed, plans)] = mat
        keys = ["material", "seed", "kind", "plan", "batch", "points", "bench_s", "dhr_err", "dhr_abs", "logrmse",
                "sigma8", "measured_s", "waited_s", "motion_s", "darks_s", "charged_s", "admitted", "bright_cells", "stop"]
        with open(os.path.join(OUT, "time_to_accuracy.csv"), "w") as fh:
            fh.write(",".join(keys) + "\n")
            for fu in cf.as_completed(jobs):
                got = fu.result()
                rows += got
                for r in sorted(got, key=lambda r: (r["kind"], r["bench_s"])):
                    fh.write(",".join(("%.6g" % r[k]) if isinstance(r.get(k), float) else str(r.get(k, ""))
                                      for k in keys) + "\n")
                fh.flush()
    txt = analyse(rows)
    if VALIDATE:
        val = "\n".join(validate(rows, PAPER_S[0]))
        with open(os.path.join(OUT, "time_to_accuracy_validation.txt"), "w") as fh:
            fh.write(val + "\n")
        txt += "\n\n" + val
    txt = ("bench_time_to_accuracy (offline loop: bench time = planner-predicted, time scale 1; %d seeds; wavelengths "
           "%s; command: make bench, or ACQ_BUILD=build ACQ_SRC=. OPENBLAS_NUM_THREADS=1 "
           "tests/bench/bench_time_to_accuracy.py)\n" % (NSEEDS, WL)) + txt + \
        "\n\nwall time %.0f s (%d jobs)\n" % (time.time() - t0, JOBS)
    with open(os.path.join(OUT, "time_to_accuracy_summary.txt"), "w") as fh:
        fh.write(txt)
    print(txt)
    plt = T.plt_mod()
    if plt:
        plot(rows, plt)
    if os.environ.get("ACQ_TTA_KEEP") != "1":
        shutil.rmtree(WORK, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
