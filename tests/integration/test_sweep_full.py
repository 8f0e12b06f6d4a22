#!/usr/bin/python3
"""A full sweep on the simulated bench (acq-sim + acquisitiond): white reference, sample swap, every visible
planned point measured once, calibrated values against the simulator's ground truth (acq-sim truth --eval at
the measured angles) in z-scores over every sample and wavelength, CSV export and the recorded events."""
import json
import os
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

PLAN = """name: it-full
incidence:
  theta_deg: [10, 40]
observation:
  theta_deg: [20, 50, 70]
  phi_deg: [0, 90, 180, 270]
integration: {mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000}
averages: 4
blind_points: drop
survey: 1
"""


def wait_recon(b, sid, nruns, timeout=240):
    """Wait until the sweep has nruns finished reconstruction runs; (state, seconds, output kinds) of the last."""
    t0 = time.time()
    while time.time() - t0 < timeout:
        db = b.db()
        runs = db.execute("SELECT id, state, finished_at - started_at FROM recon_runs WHERE sweep_id = ? ORDER BY id",
                          (sid,)).fetchall()
        kinds = [k for (k,) in db.execute("SELECT kind FROM recon_outputs WHERE run_id = ?", (runs[-1][0],))] \
            if runs else []
        db.close()
        if len(runs) >= nruns and runs[nruns - 1][1] != "running":
            return runs[nruns - 1][1], runs[nruns - 1][2], kinds
        time.sleep(0.5)
    raise AssertionError("reconstruction run %d not finished in %d s" % (nruns, timeout))


def run():
    import numpy as np
    with L.Bench(scale=100) as b:  # higher scales leave the drivers a few real ms for bench-time timeouts
        b.start_sim()
        b.start_daemon()
        sid = L.start_sweep(b, PLAN, "it-full")
        row = L.drive_to_end(b, sid, timeout=120)
        assert row["state"] == "completed", "sweep ended %s: %s" % (row["state"], row.get("events", [])[:3])
        n, cal = L.check_points(b, sid)
        L.say("points: %d planned, %d done with a calibrated sample" % (n, cal))
        # the survey (plan key survey: 1, plan_survey_apply) is measured first: the plan's survey steps (acqctl plan,
        # the same bench) are the sweep's first points, every incidence among them, and each direction is stored once
        f = os.path.join(b.dir, "it-full.yaml")
        open(f, "w").write(PLAN)
        pj = json.loads(subprocess.run([os.path.join(L.BUILD, "acqctl"), "--json", "plan", f, "--config", b.conf,
                                        "--points"], capture_output=True, text=True, check=True).stdout)["plan"]
        ns = (pj.get("survey") or {}).get("points", 0)
        want = [(round(abs(x["laser.theta"]), 2), round(abs(x["detector.theta"]), 2)) for x in pj["steps"][:ns]]
        assert ns == 2 and all(x.get("survey") for x in pj["steps"][:ns]), "survey %s" % pj.get("survey")
        db = b.db()
        got = db.execute("SELECT round(theta_i, 2), round(theta_o, 2) FROM points WHERE sweep_id = ? AND "
                         "order_index < ? ORDER BY order_index", (sid, ns)).fetchall()
        dirs = db.execute("SELECT count(DISTINCT printf('%.2f %.2f %.2f', theta_i, theta_o, phi_o)) FROM points "
                          "WHERE sweep_id = ? AND state = 'done'", (sid,)).fetchone()[0]
        db.close()
        assert [tuple(g) for g in got] == want and len({g[0] for g in got}) == 2, \
            "survey points %s, the plan's %s" % (got, want)
        assert dirs == n, "%d distinct directions stored for %d points" % (dirs, n)
        zs, nan = L.zscores(b, sid)
        z = np.array(zs)
        frac3 = float(np.mean(np.abs(z) < 3))
        L.say("z-scores over %d values (%d NaN): mean %.3f, std %.3f, |z|<3: %.4f, |z|<2: %.4f" % (
            len(z), nan, z.mean(), z.std(), frac3, float(np.mean(np.abs(z) < 2))))
        assert len(z) > 0.95 * n * 651, "too few finite calibrated values: %d" % len(z)
        assert abs(z.mean()) < 0.3, "calibrated values biased against the truth: mean z %.3f" % z.mean()
        assert 0.6 < z.std() < 1.6, "stated uncertainties do not match the errors: std z %.3f" % z.std()
        assert frac3 > 0.98, "only %.4f of |z| < 3" % frac3
        # the CSV interchange export with sigma columns, and the recorded events
        csv = os.path.join(b.state, "recon", "sweep-%d" % sid, "samples.csv")
        assert os.path.exists(csv), "no CSV export at %s" % csv
        with open(csv) as f:
            lines = [l for l in f if not l.startswith("#")]
        header = lines[0].strip().split(",")
        assert header[:4] == ["theta_i", "phi_i", "theta_o", "phi_o"] and "sigma_450" in header, header[:6]
        assert len(lines) - 1 == n, "CSV rows %d, points %d" % (len(lines) - 1, n)
        db = b.db()
        kinds = [k for (k,) in db.execute("SELECT kind FROM events WHERE sweep_id = ?", (sid,))]
        db.close()
        for k in ("start", "reference", "pause", "resume", "complete"):
            assert k in kinds, "no '%s' event in %s" % (k, sorted(set(kinds)))
        st = b.sim_status()
        assert st.get("emission") in ("0", "off", "false"), "laser left on after completion: %s" % st
        # the reconstruction chain on completion, then recon.start runs it again
        if os.access(os.path.join(L.BUILD, "brdf-recon"), os.X_OK):
            first = wait_recon(b, sid, 1)
            assert first[0] == "succeeded", "reconstruction run: %s" % (first,)
            c = b.client()
            r = c.req("recon.start", sweep=sid)
            c.close()
            assert r.get("ok"), "recon.start: %s" % r
            second = wait_recon(b, sid, 2)
            L.say("reconstruction: first run %s (%.1f s), recon.start run %s; outputs %s" % (
                first[0], first[1], second[0], sorted(second[2])))
            assert second[0] == "succeeded" and {"model", "merl", "dhr", "preview"} <= set(second[2])
        else:
            db = b.db()
            msgs = [m for (m,) in db.execute("SELECT message FROM events WHERE sweep_id = ? AND device = 'recon'",
                                             (sid,))]
            db.close()
            assert any("no reconstruction ran" in m for m in msgs), "no plain word about the missing brdf-recon"


L.main(run)
