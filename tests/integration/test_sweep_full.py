#!/usr/bin/python3
"""A full sweep on the simulated bench (acq-sim + acquisitiond): white reference, sample swap, every visible
planned point measured once, calibrated values against the simulator's ground truth (acq-sim truth --eval at
the measured angles) in z-scores over every sample and wavelength, CSV export and the recorded events."""
import os
import sys

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
"""


def run():
    import numpy as np
    b = L.Bench(scale=100)  # higher scales leave the drivers a few real ms for bench-time timeouts
    try:
        b.start_sim()
        b.start_daemon()
        sid = L.start_sweep(b, PLAN, "it-full")
        row = L.drive_to_end(b, sid, timeout=120)
        assert row["state"] == "completed", "sweep ended %s: %s" % (row["state"], row.get("events", [])[:3])
        n, cal = L.check_points(b, sid)
        L.say("points: %d planned, %d done with a calibrated sample" % (n, cal))
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
    finally:
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


L.main(run)
