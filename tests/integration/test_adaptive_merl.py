#!/usr/bin/python3
"""An adaptive sweep rehearsed on a measured material: a MERL table written from one of the simulator's own truths
(`acq-sim truth green-paint --merl`) is the simulated bench's sample (`sim.merl_file`, sample `merl`: RGB upsampled
to spectra by sim/material.h's energy-preserving basis), and an adaptive sweep (a target on the σ of the MERL
table's RGB, unreachable, so the budget of points stops it; auto exposure, 4 averages) measures it through the
daemon, as an operator would rehearse one (README "Adaptive sweeps"). Checks: the sweep completes on its budget
with its decisions stored (adaptlib.check_decisions), every point measured once, no configuration twice; what the
bench measured is the MERL material: the calibrated samples against `acq-sim truth merl:FILE` at the measured
angles give z of mean ≈ 0 and spread ≈ 1 (measured: mean −0.013…0.032, std 0.76–0.79 at seeds 1–4; with
green-paint itself on the stage instead, mean 208, std 152); and against the green paint the table was written from
they do not (the upsampled spectrum keeps the table's RGB, not the paint's spectrum: z RMS ~4500), so the check
tells the two apart."""
import os
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adaptlib as A  # noqa: E402
import sweeplib as L  # noqa: E402

BUDGET = 23  # the seed's 15 points + 2 batches of 4


def run():
    b = A.bench(scale=40)  # auto exposures: a faster clock keeps the wall time near the other adaptive tests
    try:
        table = os.path.join(b.dir, "green-paint.binary")
        p = subprocess.run([L.SIM, "truth", "green-paint", "--merl", table, "--wavelengths", "450:1100:5"],
                           capture_output=True, text=True, timeout=120)
        assert p.returncode == 0 and os.path.getsize(table) == 34992012, "acq-sim truth --merl: %s" % p.stderr[-2000:]
        with open(b.conf) as f:
            conf = f.read()
        assert "\nsim:\n" in conf, "no sim section in the bench's configuration"
        with open(b.conf, "w") as f:
            f.write(conf.replace("\nsim:\n", "\nsim:\n  merl_file: %s\n" % table, 1))
        b.start_sim()
        b.start_daemon()
        plan = A.plan(target="rgb_sigma: {le: 1.0e-9}", budget="points: %d" % BUDGET)
        fixed = "integration: {mode: fixed, ms: 5}\naverages: 1\n"
        assert fixed in plan, plan
        # auto exposure and 4 averages, as the example plan: with adaptlib's 5 ms and one average the white
        # reference's own noise (one spectrum shared by every sample, not in a sample's σ: reference-noise.csv)
        # is several σ at every wavelength, and z would not measure the material
        plan = plan.replace(fixed, "integration: {mode: auto, target_peak: 0.8, estimate_ms: 50, max_ms: 5000}\n"
                                   "averages: 4\n")
        sid = L.start_sweep(b, plan, "it-adaptive-merl")
        row = L.drive_to_end(b, sid, timeout=240, sample="merl")
        assert row["state"] == "completed", row["state"]
        rows, why = A.check_decisions(b, sid)
        n, _ = L.check_points(b, sid)  # auto exposure: HDR may add exposures
        A.no_repeats(b, sid)
        assert why.startswith("budget spent") and n == BUDGET and len(rows) >= 4, \
            "%d points, %d batches: %s" % (n, len(rows) - 2, why)
        z, nan = L.zscores(b, sid, material="merl:" + table)
        mean, sd = statistics.fmean(z), statistics.pstdev(z)
        zg, _ = L.zscores(b, sid, material="green-paint")
        rms_g = statistics.fmean(x * x for x in zg) ** 0.5
        L.say("MERL sample: %d points, %d batches (%s); z vs merl:FILE: %d values, mean %.3f, std %.3f, %d NaN; "
              "z RMS vs green-paint itself %.1f" % (n, len(rows) - 2, why, len(z), mean, sd, nan, rms_g))
        # the demo's calibrated samples vs their truth: z mean 0.02, std 0.74 (make demo); the bound leaves room
        # for the table's cells (piecewise constant) being looked up at slightly different angles than measured
        assert len(z) > 1000 and nan == 0, "%d z values, %d NaN" % (len(z), nan)
        assert abs(mean) < 0.3 and 0.4 < sd < 1.6, "the bench did not measure the MERL material: z mean %.3f, " \
            "std %.3f" % (mean, sd)
        assert rms_g > 3, "the samples agree with green-paint's own spectra too (z RMS %.2f): the check cannot tell " \
            "the MERL material from the paint" % rms_g
    finally:
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


if __name__ == "__main__":
    L.main(run)
