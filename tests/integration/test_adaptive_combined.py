#!/usr/bin/python3
"""An adaptive sweep with a combined target (plan `target: {dhr_sigma: ..., lnf_sigma: ...}`: both must be met) on
the simulated bench, white reference: the DHR part's threshold is met by the seed already (σ ~0.009 ≤ 1), the ln f
part's never (≤ 1e-9). Checks: the daemon does not stop on the met DHR part (a DHR-only reading would stop at the seed)
but measures batches until its budget of points (given with a far budget of seconds: both keys in one sweep, the
first spent stops it); every decision stores the combined spec and a value that is the
larger of each part's value over its threshold (select's JSON of the batch: target.parts), > 1 while unmet. The ln f
part weighs its picks by the study's error (`lnf_sigma: {…, weight: rad}`, select's lnf:rad): the daemon passes the
key through to every decision's spec and select's answer."""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adaptlib as A  # noqa: E402
import sweeplib as L  # noqa: E402

BUDGET = 23  # the seed's points + 2 batches of 4


def run():
    b = A.bench()
    try:
        b.start_sim()
        b.start_daemon()
        sid = L.start_sweep(b, A.plan(target="dhr_sigma: {incidence_deg: [8], le: 1}, lnf_sigma: {le: 1.0e-9, weight: rad}",
                                      budget="seconds: 100000, points: %d" % BUDGET), "it-adaptive-combined")
        rows, why, n = A.completes(b, sid)
        chosen = rows[1:-1]
        L.say("combined target: %d points, %d batches: %s; values %s" % (
            n, len(chosen), why, ["%.4g" % r["target_value"] for r in rows[1:]]))
        # both budget keys given (the seconds far away): the points' one stops it
        assert why == "budget spent: %d of %d points measured" % (BUDGET, BUDGET), "stopped: %s" % why
        assert n == BUDGET and len(chosen) >= 2, "%d points in %d batches" % (n, len(chosen))
        for r in chosen:
            assert r["target_spec"] == "dhr:8:le=1+lnf:rad:le=1e-09", r["target_spec"]
            t = json.load(open(os.path.join(os.path.dirname(os.path.join(b.state, r["model"])), "select.json")))
            t = t["target"]
            assert t["spec"] == r["target_spec"], t["spec"]
            parts = t["parts"]
            assert parts["dhr"]["value"] <= 1 < parts["lnf"]["value"] / 1e-9, parts
            ratio = max(parts["dhr"]["value"] / parts["dhr"]["threshold"], parts["lnf"]["value"] / 1e-9)
            assert abs(r["target_value"] - ratio) <= 1e-9 * ratio and t["met"] is False, (r["target_value"], t)
    finally:
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


if __name__ == "__main__":
    L.main(run)
