#!/usr/bin/python3
"""An adaptive sweep whose budget is bench seconds counts the seconds it MEASURED, not the planner's prediction:
an unreachable target, a budget of the seed's predicted time plus a few batches, and an operator pause of 1.5 s
wall (30 bench s) in the middle. Checks: it stops saying "budget spent: X of B bench seconds measured"; X equals
the measured time recomputed here from the stored points, batches and events (per done point: done_at minus the
latest of the previous point's done_at, its batch's decision time and the last start/resume event), × the time
scale; X leaves out the pause and the waits (X is at most the sweep's wall time since the sample swap minus the
pause, × scale, minus the recorded waits);
every chosen batch fitted the budget as measured when it was decided plus its predicted time; and the stop is not
premature (not even the cheapest of select's picks, as the stop reason states its time, would have fitted)."""
import json
import os
import re
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adaptlib as A  # noqa: E402
import sweeplib as L  # noqa: E402

PAUSE_WALL = 1.5


def measured_from_db(b, sid, before=None):
    """The measured bench seconds of the points with order_index < before (all when None)."""
    db = b.db()
    try:
        pts = db.execute("SELECT order_index, done_at FROM points WHERE sweep_id = ? AND state = 'done' AND "
                         "done_at IS NOT NULL ORDER BY order_index", (sid,)).fetchall()
        opens = dict(db.execute("SELECT first_order_index, decided_at FROM adaptive_batches WHERE sweep_id = ? AND "
                                "n_points > 0", (sid,)).fetchall())
        evs = [t for (t,) in db.execute("SELECT at FROM events WHERE sweep_id = ? AND kind IN ('start', 'resume') "
                                        "ORDER BY at", (sid,))]
    finally:
        db.close()
    total, prev = 0.0, None
    for oi, done in pts:
        if before is not None and oi >= before:
            break
        frm = [t for t in (prev, opens.get(oi), max([e for e in evs if e <= done], default=None)) if t is not None]
        if frm and done > max(frm):
            total += done - max(frm)
        prev = done
    return total * b.scale


def run():
    b = A.bench()
    try:
        with open(b.conf) as f:
            conf = f.read()
        assert "auto_recon: true" in conf
        with open(b.conf, "w") as f:  # no reconstruction after the first sweep, beside the second
            f.write(conf.replace("auto_recon: true", "auto_recon: false"))
        b.start_sim()
        b.start_daemon()
        path = os.path.join(b.dir, "probe.yaml")
        with open(path, "w") as f:
            f.write(A.plan(budget="points: 1000"))

        def dry_run():
            dry = subprocess.run([os.path.join(L.BUILD, "acqctl"), "-s", b.sock, "plan", path, "--json"],
                                 capture_output=True, text=True, timeout=60)
            assert dry.returncode == 0, "acqctl plan: %s" % (dry.stderr or dry.stdout)
            return json.loads(dry.stdout)["plan"]
        seed_n = dry_run()["measured"]
        # The budget counts the bench seconds a point MEASURED, the host's part included, and the sweep's clock is
        # bench time (x the time scale): on a loaded machine the host's part of a point is several times what the
        # prediction assumes (the default host figure: this state has no completed sweep of 50 points), and a
        # budget of 1.6 x the predicted seed was spent by the seed alone (74.6 of 73 bench s at load 20+), leaving
        # no batch to check. So the seed is measured first, by a sweep of the same plan that stops after it (its
        # measured seconds recomputed from the store as below), and the budget is 1.6 x the larger of the two.
        psid = L.start_sweep(b, A.plan(budget="points: %d" % seed_n), "it-adaptive-seconds-seed")
        prow = L.drive_to_end(b, psid, timeout=300, sample="white")
        assert prow["state"] == "completed", prow["state"]
        seed_meas = measured_from_db(b, psid)
        seed_s = dry_run()["predicted_s"]
        L.say("seed: %d points, %.1f bench s predicted, %.1f bench s measured by sweep %d" % (
            seed_n, seed_s, seed_meas, psid))
        seed_s = max(seed_s, seed_meas)
        budget = round(seed_s * 1.6)
        sid = L.start_sweep(b, A.plan(budget="seconds: %d" % budget), "it-adaptive-seconds")
        state = {"paused": False}

        def tick(row):
            # the pause inside the seed's measurement (never inside a wait for a decision)
            done = row.get("points_done") or 0
            if not state["paused"] and row.get("state") == "running" and 5 <= done <= seed_n - 3:
                c = b.client()
                r = c.req("sweep.pause")
                assert r.get("ok"), "sweep.pause: %s" % r
                t0 = time.time()
                while L.sweep_row(b, sid)["state"] != "paused":
                    assert time.time() - t0 < 60, "the sweep did not pause"
                    time.sleep(0.05)
                time.sleep(PAUSE_WALL)
                r = c.req("sweep.resume")
                c.close()
                assert r.get("ok"), "sweep.resume: %s" % r
                state["paused"] = True

        row = L.drive_to_end(b, sid, timeout=300, sample="white", on_tick=tick)
        t_end = time.time()
        assert row["state"] == "completed", row["state"]
        if not state["paused"]:  # the polling missed the seed's window (extreme load): the bound without the pause
            L.say("the test's pause missed the seed's measurement: checked without it")
        rows, why = A.check_decisions(b, sid)
        L.check_points(b, sid, max_exposures=1)
        m = re.match(r"budget spent: ([0-9.]+) of ([0-9]+) bench seconds measured", why)
        assert m, "stopped: %s" % why
        x, bud = float(m.group(1)), float(m.group(2))
        assert bud == budget, why
        mine = measured_from_db(b, sid)
        predicted = sum(r["predicted_s"] for r in rows if r["predicted_s"])
        L.say("budget %d s: stopped at %.1f bench s measured (recomputed %.2f), %.1f s predicted, %d batches: %s" % (
            budget, x, mine, predicted, len(rows) - 2, why))
        assert abs(x - mine) <= 0.06 + 1e-6 * mine, "the daemon measured %.1f s, the stored points say %.3f s" % (
            x, mine)
        # an independent bound: the wall time from the swap's resume to the end, minus the arms' recorded waits for
        # decisions and the test's own pause (during the seed, never inside a wait), x scale; counting the pause
        # would exceed it by ~30 bench s
        db = b.db()
        first_resume = db.execute("SELECT min(at) FROM events WHERE sweep_id = ? AND kind = 'resume'",
                                  (sid,)).fetchone()[0]
        db.close()
        waits = sum(r["waited_s"] or 0 for r in rows)
        upper = (t_end - first_resume - (PAUSE_WALL if state["paused"] else 0)) * b.scale - waits
        assert mine <= upper + 2.0, "measured %.1f bench s > %.1f s of wall time since the swap without the waits " \
            "(%.1f s) and the pause (the pause was counted)" % (mine, upper, waits)
        chosen = rows[1:-1]
        assert chosen, "no batch chosen within a budget of %d s (seed predicted %.0f s)" % (budget, seed_s)
        for r in chosen:
            before = measured_from_db(b, sid, r["first_order_index"])
            assert before + r["predicted_s"] <= budget + 0.01, \
                "batch %d: %.1f s measured before it + %.1f s predicted > budget %d" % (
                    r["batch"], before, r["predicted_s"], budget)
        # the stop is not premature: the budget is gone, or not even the cheapest of select's picks (a dearer pick is
        # skipped for a cheaper later one) would have fitted what was left. The reason prints both figures to 0.1 s
        # (each within 0.05 of the daemon's value): a sum within 0.1 below the budget is the rounding (seen under
        # the sanitizers at ACQ_SEED 4256352481: 72.0 + 2.0 of 74, the stored points say 71.99)
        need = re.search(r"the cheapest of select's [0-9]+ picks needs ([0-9.]+) s", why)
        assert x >= budget - 0.05 or (need and x + float(need.group(1)) > budget - 0.1), \
            "stopped at %.1f of %d s: %s" % (x, budget, why)
    finally:
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


if __name__ == "__main__":
    L.main(run)
