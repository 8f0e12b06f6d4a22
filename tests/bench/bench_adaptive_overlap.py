#!/usr/bin/python3
"""bench_adaptive_overlap: does choosing the next batch while the arms measure the current one (`overlap: true`)
pay on the example adaptive sweep (config/plan-adaptive.yaml)? Runs the example on the simulated bench with
overlap on and off, per seed, and prints per run: the stop reason, points, batches, the arms' total wait for
decisions (bench seconds), the measured bench time (the stored points' done_at span per batch x the time scale) and
the whole sweep's bench time from start to stop (wall x scale), so both costs of each choice show: waiting arms
(off) against batches chosen from one batch less (on).

  ACQ_BUILD=$PWD/build ACQ_SRC=$PWD /usr/bin/python3 tests/bench/bench_adaptive_overlap.py
Environment: ACQ_OVERLAP_SEEDS (default 1,2), ACQ_OVERLAP_SCALE (simulated bench time scale, default 35),
ACQ_OVERLAP_SAMPLE (default green-paint), ACQ_OVERLAP_PLAN (default the example), ACQ_OVERLAP_MODES (default
"false,true": the overlap settings to run), ACQ_ADAPTIVE_RECON (another brdf-recon for the daemon, as adaptlib).
Not part of make check."""
import os
import re
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integration"))
import adaptlib as A  # noqa: E402
import sweeplib as L  # noqa: E402

SEEDS = [int(s) for s in os.environ.get("ACQ_OVERLAP_SEEDS", "1,2").split(",")]
SCALE = float(os.environ.get("ACQ_OVERLAP_SCALE", "35"))
SAMPLE = os.environ.get("ACQ_OVERLAP_SAMPLE", "green-paint")
PLAN = os.environ.get("ACQ_OVERLAP_PLAN") or os.path.join(L.SRC, "config", "plan-adaptive.yaml")


def one(text, overlap, seed):
    b = L.Bench(scale=SCALE, seed=seed)
    recon = os.environ.get("ACQ_ADAPTIVE_RECON")
    if recon:
        with open(b.conf, "a") as f:
            f.write("recon:\n  program: %s\n" % recon)
    try:
        b.start_sim()
        b.start_daemon()
        plan = re.sub(r"(?m)^overlap:.*$", "overlap: %s" % ("true" if overlap else "false"), text)
        if "overlap:" not in plan:
            plan += "\noverlap: %s\n" % ("true" if overlap else "false")
        t0 = time.time()
        sid = L.start_sweep(b, plan, "overlap-%s-%d" % (overlap, seed))
        row = L.drive_to_end(b, sid, timeout=3600, sample=SAMPLE)
        wall = time.time() - t0
        rows = A.batches(b, sid)
        db = b.db()
        started = db.execute("SELECT min(taken_at) FROM spectra WHERE sweep_id = ? AND kind = 'sample'",
                             (sid,)).fetchone()[0]
        last = db.execute("SELECT max(done_at) FROM points WHERE sweep_id = ?", (sid,)).fetchone()[0]
        db.close()
        waited = sum(r["waited_s"] or 0 for r in rows)
        values = ["%.3g" % r["target_value"] for r in rows[1:] if r["target_value"] is not None]
        return {"overlap": overlap, "seed": seed, "state": row["state"], "points": row["points_total"],
                "batches": len(rows) - 2, "waited_s": waited, "why": rows[-1]["stop_reason"] if rows else None,
                "sample_span_s": (last - started) * SCALE if started and last else None,
                "predicted_s": sum(r["predicted_s"] or 0 for r in rows), "wall_s": wall, "values": values}
    finally:
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


def main():
    text = open(PLAN).read()
    res = []
    for seed in SEEDS:
        for overlap in [m == "true" for m in os.environ.get("ACQ_OVERLAP_MODES", "false,true").split(",")]:
            r = one(text, overlap, seed)
            res.append(r)
            print("seed %d overlap %-5s: %s, %d points, %d batches, arms waited %.0f s, first sample to last point "
                  "%.0f bench s, predicted %.0f s, wall %.0f s; values %s; %s" % (
                      seed, overlap, r["state"], r["points"], r["batches"], r["waited_s"], r["sample_span_s"] or -1,
                      r["predicted_s"], r["wall_s"], " ".join(r["values"]), r["why"]), flush=True)
    for overlap in (False, True):
        rs = [r for r in res if r["overlap"] == overlap]
        if not rs:
            continue
        print("overlap %-5s: mean points %.1f, mean wait %.0f bench s, mean span %.0f bench s" % (
            overlap, sum(r["points"] for r in rs) / len(rs), sum(r["waited_s"] for r in rs) / len(rs),
            sum(r["sample_span_s"] or 0 for r in rs) / len(rs)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
