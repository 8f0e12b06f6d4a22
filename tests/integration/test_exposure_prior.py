#!/usr/bin/python3
"""The exposure prior (issue 16): a completed auto sweep whose plan names its sample (sample: green-paint) times the
next plan of that sample. After the first sweep, `acqctl plan` of the same plan says which prior was used (the
sweep, its points and incidences, the median integration time, spread and HDR fraction, all as the database holds
them), predicts another duration than without it, and the local dry run (no database) says it has none; another
sample and a fixed plan get none. After a second sweep of the sample, the newest completed sweep is the prior."""
import json
import os
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

CTL = os.path.join(L.BUILD, "acqctl")
PLAN = ("name: prior\nincidence:\n  theta_deg: [10, 40]\nobservation:\n  theta_deg: [30, 60]\n  phi_deg: [0, 120, 240]\n"
        "integration: {mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000}\naverages: 1\nblind_points: drop\n"
        "sample: green-paint\n")


def check(cond, what):
    if not cond:
        raise AssertionError(what)


def plan(b, path, *extra):
    p = subprocess.run([CTL, "-s", b.sock, "--json", "plan", path] + list(extra), capture_output=True, text=True,
                       timeout=60)
    check(p.returncode == 0, "plan %s: %d %s" % (path, p.returncode, p.stderr))
    return json.loads(p.stdout)


def human(b, path):
    p = subprocess.run([CTL, "-s", b.sock, "plan", path], capture_output=True, text=True, timeout=60)
    check(p.returncode == 0, "plan %s: %d %s" % (path, p.returncode, p.stderr))
    return p.stdout


def main():
    with L.Bench(scale=20) as b:
        b.start_sim()
        b.start_daemon()
        pf = os.path.join(b.dir, "prior.yaml")
        open(pf, "w").write(PLAN)
        other = os.path.join(b.dir, "other.yaml")
        open(other, "w").write(PLAN.replace("sample: green-paint", "sample: white tile"))
        fixed = os.path.join(b.dir, "fixed.yaml")
        open(fixed, "w").write(PLAN.replace("mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000",
                                            "mode: fixed, ms: 20"))
        before = plan(b, pf)["plan"]
        check(before["exposure_prior"] is None and before["sample"] == "green-paint", "no prior yet: %r" %
              {k: before.get(k) for k in ("exposure_prior", "sample")})
        check("no completed auto sweep of sample green-paint" in human(b, pf), "human: no prior")
        # without a prior the reply says the estimate it timed the exposures with, and the same model's time for
        # a sample needing half and twice it (daemon/plan/plan_json.c)
        es = before.get("estimate") or {}
        check(es.get("ms") == 20 and es["predicted_at_half_s"] < before["predicted_s"] < es["predicted_at_double_s"],
              "estimate %r, predicted %r" % (es, before["predicted_s"]))
        check("as the estimate 20 ms says" in human(b, pf), "human: the estimate")
        # nothing of the sample known: the duration's interval from the policy's reach (plan_time_interval)
        iv = before.get("interval") or {}
        check(iv.get("basis") == "policy" and iv["low_s"] <= before["predicted_s"] < iv["high_s"] and
              iv.get("max_ms") == 2000, "interval before the first sweep %r" % iv)
        check("no exposure of the sample known yet" in human(b, pf), "human: the policy's interval")
        sid = L.start_sweep(b, PLAN, "first")
        row = L.drive_to_end(b, sid, timeout=600)
        check(row["state"] == "completed", "first sweep %s" % row["state"])
        db = b.db()
        firsts = [r[0] for r in db.execute("SELECT min(integration_ms) FROM spectra WHERE sweep_id = ? AND kind = "
                                           "'sample' GROUP BY point_id", (sid,))]
        hdr = db.execute("SELECT count(*) FROM (SELECT point_id FROM spectra WHERE sweep_id = ? AND kind = 'sample' "
                         "GROUP BY point_id HAVING count(*) > 1)", (sid,)).fetchone()[0]
        incs = db.execute("SELECT count(DISTINCT theta_i) FROM points WHERE sweep_id = ? AND state = 'done'",
                          (sid,)).fetchone()[0]
        db.close()
        after = plan(b, pf)["plan"]
        pr = after["exposure_prior"]
        check(isinstance(pr, dict) and pr["sweep"] == sid and pr["sample"] == "green-paint", "prior %r" % pr)
        check(pr["points"] == len(firsts) and pr["incidences"] == incs, "prior counts %r (%d points, %d incidences)" % (
            pr, len(firsts), incs))
        # the reply prints reals to 10 significant digits: compared within 1e-9 relative
        check(abs(pr["median_ms"] - statistics.median(firsts)) < 1e-9 * max(firsts), "median %r vs %r" % (
            pr["median_ms"], statistics.median(firsts)))
        check(abs(pr["spread"] - max(firsts) / min(firsts)) < 1e-9 * pr["spread"], "spread %r" % pr["spread"])
        check(abs(pr["hdr_fraction"] - hdr / len(firsts)) < 1e-9, "HDR fraction %r vs %d/%d" % (pr["hdr_fraction"],
                                                                                                 hdr, len(firsts)))
        check(after["predicted_s"] != before["predicted_s"], "the prior changes the prediction (%r)" % after["predicted_s"])
        check("estimate" not in after, "timed by the prior: no estimate's range (%r)" % after.get("estimate"))
        check("interval" not in after, "every incidence measured: no interval (%r)" % after.get("interval"))
        # a plan with an incidence the prior has not measured (70°): that one extrapolated, the interval around it
        wider = os.path.join(b.dir, "wider.yaml")
        open(wider, "w").write(PLAN.replace("theta_deg: [10, 40]", "theta_deg: [10, 40, 70]"))
        w = plan(b, wider)["plan"]
        iv = w.get("interval") or {}
        check(iv.get("basis") == "extrapolated" and iv["low_s"] < w["predicted_s"] < iv["high_s"] and
              iv.get("slope_per_deg", 0) >= 0.01, "interval with 70° unmeasured %r (predicted %r)" % (
                  iv, w["predicted_s"]))
        check("incidences the exposure prior has not measured" in human(b, wider), "human: the extrapolated interval")
        check("estimate" not in plan(b, fixed)["plan"], "a fixed plan has no estimate's range")
        out = human(b, pf)
        check("auto exposure timed from sweep %d of sample green-paint" % sid in out, "human output: %r" % out)
        check(plan(b, other)["plan"]["exposure_prior"] is None, "another sample has no prior")
        check("exposure_prior" not in plan(b, fixed)["plan"], "a fixed plan has no exposure prior")
        loc = subprocess.run([CTL, "--json", "plan", pf, "--config", os.path.join(b.dir, "acquisitiond.yaml")],
                             capture_output=True, text=True, timeout=60)
        check(loc.returncode == 0 and json.loads(loc.stdout)["plan"]["exposure_prior"] is None,
              "the local dry run has no database: %d %s" % (loc.returncode, loc.stderr))
        # the second sweep of the sample is started with the prior's prediction: its stored plan figure
        c = b.client()
        b.ctl("sample white")
        r = c.req("sweep.start", plan=PLAN, name="second")
        c.close()
        check(r.get("ok"), "second start %r" % r)
        sid2 = int(r.get("sweep") or r.get("id"))
        row = L.drive_to_end(b, sid2, timeout=600)
        check(row["state"] == "completed", "second sweep %s" % row["state"])
        check(plan(b, pf)["plan"]["exposure_prior"]["sweep"] == sid2, "the newest completed sweep is the prior")
    print("test_exposure_prior: ok")


if __name__ == "__main__":
    main()
