#!/usr/bin/python3
"""An adaptive sweep on the simulated bench that stops on its budget: a seed plan, then batches chosen by
`brdf-recon select` (an unreachable target on the σ of the MERL table's RGB values, rgb_sigma, so only the budget of
points can stop it). Checks: it stops saying
"budget spent" with exactly the budgeted points; every decision is stored (batch, picks in choice order with their
points, target value, model, candidates, predicted time, the arms' wait, the refit warm-started after batch 1);
no blind-zone direction and no configuration twice; `acqctl watch` streams the target's value and its trend per
batch; the finished sweep reconstructs from the database and from its CSV export like any other (the same model)."""
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adaptlib as A  # noqa: E402
import sweeplib as L  # noqa: E402

BUDGET = 27  # the seed's 15 points + 3 batches of 4 (the last one cut to 0 by the budget is not planned)
TARGET = "rgb_sigma: {le: 1.0e-9}"


def check_show_human(b, sid, rows, why):
    """`acqctl sweep show` (human) lists every decision: batch, points, the target's value, select's prediction, the
    measured picks' summed gain, the model; then the stop reason."""
    p = subprocess.run([os.path.join(L.BUILD, "acqctl"), "-s", b.sock, "sweep", "show", str(sid)],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, "acqctl sweep show: %s" % (p.stderr or p.stdout)
    lines = p.stdout.splitlines()
    assert any(ln.strip().startswith("decisions (adaptive, target %s)" % rows[0]["target_spec"]) for ln in lines), \
        p.stdout[-3000:]
    db = b.db()
    pred = dict(db.execute("SELECT batch, predicted_value FROM adaptive_batches WHERE sweep_id = ?", (sid,)).fetchall())
    db.close()
    for r in rows[1:-1]:
        gain = sum(x["gain"] for x in r["picks"] if x["order_index"] is not None)
        want = [str(r["batch"]), str(r["n_points"]), "%.6g" % r["target_value"], "%.6g" % pred[r["batch"]],
                "%.3g" % gain]
        got = [ln.split() for ln in lines if ln.split()[:2] == want[:2]]
        assert got and got[0][:5] == want and r["model"] in got[0], "batch %d: shown %s, want %s and %s" % (
            r["batch"], got, want, r["model"])
    assert "  stop after batch %d: %s" % (rows[-1]["batch"] - 1, why) in lines, p.stdout[-3000:]
    L.say("acqctl sweep show lists the %d decisions and the stop" % (len(rows) - 2))


def run():
    b = A.bench()
    watch = None
    try:
        b.start_sim()
        b.start_daemon()
        wlog = open(os.path.join(b.dir, "watch.jsonl"), "w")
        watch = subprocess.Popen([os.path.join(L.BUILD, "acqctl"), "-s", b.sock, "watch"], stdout=wlog,
                                 stderr=subprocess.STDOUT)
        path = os.path.join(b.dir, "plan.yaml")
        with open(path, "w") as f:
            f.write(A.plan(target=TARGET, budget="points: %d" % BUDGET))
        dry = subprocess.run([os.path.join(L.BUILD, "acqctl"), "-s", b.sock, "plan", path, "--json"],
                             capture_output=True, text=True, timeout=60)
        assert dry.returncode == 0, "acqctl plan: %s" % (dry.stderr or dry.stdout)
        d = json.loads(dry.stdout)["plan"]
        assert d["kind"] == "adaptive" and d["adaptive"]["worst_case_points"] == BUDGET, d.get("adaptive")
        seed_points = d["measured"]
        # the same dry run without the daemon, and the example plan of the README
        for pth in (path, os.path.join(L.SRC, "config", "plan-adaptive.yaml")):
            loc = subprocess.run([os.path.join(L.BUILD, "acqctl"), "plan", pth, "--config",
                                  os.path.join(L.SRC, "config", "bench-sim.yaml"), "--json"],
                                 capture_output=True, text=True, timeout=60, env=dict(os.environ, ACQ_SOCKET="/nonexistent"))
            assert loc.returncode == 0, "local acqctl plan %s: %s" % (pth, loc.stderr or loc.stdout)
            ld = json.loads(loc.stdout)["plan"]
            assert ld["kind"] == "adaptive" and ld["adaptive"]["worst_case_s"] >= ld["predicted_s"] > 0, ld["adaptive"]
            if pth == path:
                assert ld["measured"] == seed_points and ld["adaptive"]["worst_case_points"] == BUDGET, ld["adaptive"]
        L.say("dry run: seed %d points, predicted %.1f s; worst case %d points, %.1f s" % (
            seed_points, d["predicted_s"], d["adaptive"]["worst_case_points"], d["adaptive"]["worst_case_s"]))

        sid = L.start_sweep(b, A.plan(target=TARGET, budget="points: %d" % BUDGET), "it-adaptive-budget")
        t0 = time.time()
        row = L.drive_to_end(b, sid, timeout=240, sample="white")
        L.say("sweep %s: %s/%s points in %.1f s" % (row["state"], row.get("points_done"), row.get("points_total"),
                                                   time.time() - t0))
        assert row["state"] == "completed", row["state"]
        rows, why = A.check_decisions(b, sid)
        assert all(r["target_spec"] == "rgb:le=1e-09" for r in rows), [r["target_spec"] for r in rows]
        assert rows[0]["n_points"] == seed_points, "seed %d points, dry run %d" % (rows[0]["n_points"], seed_points)
        assert why.startswith("budget spent"), "stopped: %s" % why
        n, cal = L.check_points(b, sid, max_exposures=1)
        assert n == BUDGET, "%d points measured, budget %d" % (n, BUDGET)
        A.no_repeats(b, sid)
        chosen = rows[1:-1]
        assert len(chosen) >= 2, "only %d batches chosen" % len(chosen)
        for r in chosen:
            assert r["criterion"] and r["predicted_s"] > 0 and r["waited_s"] is not None and r["waited_s"] >= 0, r
            assert [p["rank"] for p in r["picks"]] == list(range(len(r["picks"]))), r["picks"]
        # refits between batches are warm-started from the batch before's model (brdf-recon fit --warm PREV; batch 1
        # has none): the daemon records which (a brdf-recon whose fit --help has no --warm gives 0 everywhere)
        assert [r["warm"] for r in chosen] == [0] + [1] * (len(chosen) - 1), \
            "warm starts per batch %s" % [r["warm"] for r in chosen]
        waited = sum(r["waited_s"] for r in rows if r["waited_s"] is not None)
        L.say("stopped: %s; %d batches; values %s; arms waited %.1f bench s (%.2f s wall) for %d decisions" % (
            why, len(chosen), ["%.4g" % r["target_value"] for r in chosen], waited, waited / b.scale, len(chosen) + 1))
        show = L.sweep_row(b, sid)
        assert any(why in (e.get("message") or "") for e in show.get("events", [])), "the stop reason is not an event"
        shown = show.get("adaptive") or []
        assert [r["batch"] for r in shown] == [r["batch"] for r in rows] and shown[-1]["stop_reason"] == why, \
            "sweep.show's decisions: %s" % [(r.get("batch"), r.get("stop_reason")) for r in shown]
        check_show_human(b, sid, rows, why)
        A.reconstructs(b, sid)
        # watch: one sweep.adaptive event per decision, the last one with the stop, the trend growing by one per batch
        watch.terminate()
        watch.wait(10)
        watch = None
        wlog.close()
        evs = []
        for line in open(os.path.join(b.dir, "watch.jsonl")):
            try:
                e = json.loads(line)
            except ValueError:
                continue
            if e.get("event") == "sweep.adaptive":
                evs.append(e)
        assert len(evs) == len(chosen) + 1, "%d sweep.adaptive events for %d decisions" % (len(evs), len(chosen) + 1)
        for i, e in enumerate(evs[:-1]):
            assert len(e["trend"]) == i + 1 and e["value"] == e["trend"][-1] and e["stop"] is None, e
            assert abs(e["value"] - chosen[i]["target_value"]) <= 1e-9 * abs(e["value"]), (e, chosen[i])
        assert evs[-1]["stop"] == why and evs[-1]["points"] == BUDGET, evs[-1]
    finally:
        if watch:
            watch.kill()
            watch.wait()
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


if __name__ == "__main__":
    L.main(run)
