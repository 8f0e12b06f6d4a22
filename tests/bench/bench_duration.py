#!/usr/bin/python3
"""make bench: the planner's predicted sweep time against the simulated bench, and the live ETA's error.

For each case (plan, time scale), acq-sim + acquisitiond run the sweep the way an operator does (white reference,
pause, sample, resume) while `acqctl watch` (JSON lines) records every progress event. Reported:
- predicted: `acqctl plan --json` predicted_s (bench seconds; reference, darks and executor overheads included);
- measured: bench seconds from the sweep's start to its completion, the operator's pause taken out
  (wall seconds x time scale);
- the ETA's error at 25, 50 and 75 % of the points: (eta_s at that point) / (wall seconds actually left) - 1.
Cases: two small plans at time scale 1 (fixed and auto integration) and the paper's 10x10x10 at the demo's
time scale 35 (BENCH_DURATION_QUICK=1: the small fixed one only). Writes duration.csv under $ACQ_BENCH_OUT."""
import csv
import json
import os
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.join(os.environ.get("ACQ_SRC", "."), "tests", "integration"))
import sweeplib as L  # noqa: E402

OUT = os.environ.get("ACQ_BENCH_OUT") or os.path.join(L.BUILD, "bench")
CTL = os.path.join(L.BUILD, "acqctl")
QUICK = open(os.path.join(L.SRC, "config", "plan-quick.yaml")).read()
FIXED = QUICK.replace("mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000", "mode: fixed, ms: 20") \
             .replace("name: quick-2x2x4", "name: quick-fixed")
PAPER = open(os.path.join(L.SRC, "config", "plan-paper-10x10x10.yaml")).read()


def run_case(name, plan_text, scale):
    b = L.Bench(scale=scale)
    try:
        b.start_sim()
        b.start_daemon()
        planf = os.path.join(b.dir, "plan.yaml")
        open(planf, "w").write(plan_text)
        p = subprocess.run([CTL, "-s", b.sock, "--json", "plan", planf], capture_output=True, text=True, check=True)
        pred = json.loads(p.stdout)["plan"]["predicted_s"]
        events = []
        w = subprocess.Popen([CTL, "-s", b.sock, "watch"], stdout=subprocess.PIPE, text=True)

        def reader():
            for line in w.stdout:
                events.append((time.time(), json.loads(line)))
        th = threading.Thread(target=reader, daemon=True)
        th.start()
        time.sleep(0.3)
        t0 = time.time()
        sid = L.start_sweep(b, plan_text, name)
        row = L.drive_to_end(b, sid, timeout=7200)
        t1 = time.time()
        time.sleep(0.3)
        w.terminate()
        w.wait(10)
        if row["state"] != "completed":
            raise AssertionError("%s: sweep %s" % (name, row["state"]))
        db = b.db()
        ev = {k: at for at, k in db.execute("SELECT at, kind FROM events WHERE sweep_id = ? AND kind IN "
                                            "('pause', 'resume')", (sid,))}
        db.close()
        paused = max(0.0, ev.get("resume", 0) - ev.get("pause", 0))
        measured = (t1 - t0 - paused) * scale
        prog = [(t, e) for t, e in events if e.get("event") == "sweep.progress" and e.get("sweep") == sid]
        total = row["points_total"]
        eta_err = {}
        for frac in (0.25, 0.5, 0.75):
            for t, e in prog:
                if e["done"] >= frac * total and e.get("eta_s") is not None:
                    left = t1 - t
                    eta_err[frac] = e["eta_s"] / left - 1 if left > 0 else float("nan")
                    break
        return dict(case=name, scale=scale, points=total, predicted_s=pred, measured_s=measured,
                    error=pred / measured - 1, eta25=eta_err.get(0.25), eta50=eta_err.get(0.5),
                    eta75=eta_err.get(0.75))
    finally:
        b.cleanup()


def main():
    os.makedirs(OUT, exist_ok=True)
    cases = [("quick-fixed", FIXED, 1.0)]
    if os.environ.get("BENCH_DURATION_QUICK") != "1":
        cases += [("quick-auto", QUICK, 1.0), ("paper-10x10x10", PAPER, 35.0)]
    rows = []
    for name, text, scale in cases:
        try:
            r = run_case(name, text, scale)
        except L.Skip as e:
            print("bench_duration: skip: %s" % e)
            return 0
        rows.append(r)
        f = lambda x: "   -  " if x is None else "%+5.1f%%" % (100 * x)  # noqa: E731
        print("%-15s scale %4g  %4d points  predicted %7.1f s  measured %7.1f s  error %s  ETA error at 25/50/75 %%: "
              "%s %s %s" % (name, scale, r["points"], r["predicted_s"], r["measured_s"], f(r["error"]), f(r["eta25"]),
                            f(r["eta50"]), f(r["eta75"])), flush=True)
    with open(os.path.join(OUT, "duration.csv"), "w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=list(rows[0].keys()))
        wr.writeheader()
        wr.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
