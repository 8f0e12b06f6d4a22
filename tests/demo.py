#!/usr/bin/python3
"""demo: the end-to-end run on the simulated bench (make demo, through tests/demo.sh): acq-sim and acquisitiond
with their state in build/demo/ (fresh each run), the paper's 10 x 10 x 10 plan on a simulated sample
(DEMO_SAMPLE, default green-paint; any `acq-sim truth --help` material) with the white reference first,
progress from `acqctl watch`, the reconstruction on completion, the paper's validation (its Fig. 4): the
reconstructed DHR at 8 deg against a simulated integrating-sphere spectrophotometer measurement of the same
sample (`acq-sim truth SAMPLE --spectrophotometer`, read by `brdf-recon dhr --reference`), and where every
output is. Everything started here is stopped here, also on Ctrl-C."""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "integration"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

SCALE = float(os.environ.get("DEMO_TIME_SCALE", "35"))
PLAN = os.environ.get("DEMO_PLAN") or os.path.join(L.SRC, "config", "plan-paper-10x10x10.yaml")  # e.g. plan-adaptive
ACQCTL = os.path.join(L.BUILD, "acqctl")
RECON = os.path.join(L.BUILD, "brdf-recon")
SAMPLE = os.environ.get("DEMO_SAMPLE", "green-paint")
# The simulator's calibration errors (sim/sim_refdrift.h), off unless asked for: DEMO_REFERENCE_U=0.002 puts a white
# standard off its certificate by that standard deviation on the stage, DEMO_DRIFT=0.005 lets the source drift.
REF_U = float(os.environ.get("DEMO_REFERENCE_U", "0"))
DRIFT = float(os.environ.get("DEMO_DRIFT", "0"))


def sim_section_value(text, section, key):
    """A number under `  section:` / `    key:` of the composed configuration's sim part (0 if absent)."""
    m = re.search(r"^  %s:\s*(?:#.*)?\n((?:    .*\n)+)" % re.escape(section), text, re.M)
    if not m:
        return 0.0
    k = re.search(r"^    %s:\s*([-0-9.eE+]+)" % re.escape(key), m.group(1), re.M)
    return float(k.group(1)) if k else 0.0


def set_systematics(conf):
    """Turn the simulator's reference-standard and drift errors on in the composed configuration (DEMO_REFERENCE_U,
    DEMO_DRIFT); the daemon's calibration is unchanged (it believes the certificate and a steady source)."""
    if REF_U <= 0 and DRIFT <= 0:
        return
    with open(conf) as f:
        text = f.read()
    if REF_U > 0:
        text = re.sub(r"(^  reference_standard:.*\n    u:\s*)[-0-9.eE+]+", lambda m: m.group(1) + repr(REF_U), text,
                      count=1, flags=re.M)
    if DRIFT > 0:
        text = re.sub(r"(^  source_drift:.*\n    amplitude:\s*)[-0-9.eE+]+", lambda m: m.group(1) + repr(DRIFT), text,
                      count=1, flags=re.M)
    with open(conf, "w") as f:
        f.write(text)


def budget_args(conf, out):
    """The `brdf-recon dhr` budget options that match the simulator's systematic errors where they are on
    (recon/reconstruction.md, sim/sim_refdrift.h): --cert with the certificate table of the daemon's calibration and
    the standard's stated u when the standard is off its certificate; --drift-rel amplitude * sqrt(2 (1 + tilt^2/3))
    (the drift's stated uncertainty) when the source drifts. Empty when both are off."""
    with open(conf) as f:
        text = f.read()
    args = []
    u = sim_section_value(text, "reference_standard", "u")
    if u > 0:
        m = re.search(r"^\s*table:\s*(\[\[.*\]\])\s*$", text, re.M)
        if m:
            cert = os.path.join(out, "certificate.csv")
            with open(cert, "w") as f:
                f.write("wavelength_nm,rho,u\n")
                for wl, rho, _ in json.loads(m.group(1)):
                    f.write("%g,%.6g,%.6g\n" % (wl, rho, u))
            args += ["--cert", cert]
        else:
            args += ["--cert-rel", "%.6g" % (u / 0.98)]
    a = sim_section_value(text, "source_drift", "amplitude")
    if a > 0:
        tilt = sim_section_value(text, "source_drift", "tilt")
        args += ["--drift-rel", "%.6g" % (a * (2 * (1 + tilt * tilt / 3)) ** 0.5)]
    return args


def reference_check(out, seed, conf=None):
    """The paper's Fig. 4: the reconstructed DHR at 8 deg vs a simulated spectrophotometer (d/8 sphere) measurement
    of the sample, z = (model - reference) / sqrt(sigma_model^2 + sigma_ref^2) per wavelength. Returns a summary
    line (or why there is none); writes spectrophotometer.csv, dhr-reference-z.csv and dhr-reference.png in out."""
    import numpy as np
    model = os.path.join(out, "model.brdf")
    if not os.path.exists(model):
        return "no model to compare"
    ref = os.path.join(out, "spectrophotometer.csv")
    r = subprocess.run([L.SIM, "truth", SAMPLE, "--spectrophotometer", "--seed", str(seed), "--wavelengths",
                        "450:1100:1", "-o", ref], capture_output=True, text=True)
    if r.returncode != 0:
        return "acq-sim truth --spectrophotometer failed: %s" % r.stderr.strip()
    zpath = os.path.join(out, "dhr-reference-z.csv")
    helptext = subprocess.run([RECON, "dhr", "--help"], capture_output=True, text=True)
    if "--reference" in helptext.stdout + helptext.stderr:
        # the instrument's stated calibration part, correlated over 150 nm (sim/sim_sphere.h), and the budget
        # options matching the simulator's systematic errors where they are on
        extra = ["--reference-corr", "0.003,150"] if "--reference-corr" in helptext.stdout else []
        extra += budget_args(conf, out) if conf else []
        rn = os.path.join(out, "reference-noise.csv")  # the daemon's: its white reference's own noise
        extra += ["--ref-noise", rn] if os.path.exists(rn) and "--ref-noise" in helptext.stdout else []
        r = subprocess.run([RECON, "dhr", model, "--theta-i", "8", "--reference", ref, "--z-out", zpath, "-o",
                            os.path.join(out, "dhr8.csv"), "--plot", os.path.join(out, "dhr-reference.png"), *extra],
                           capture_output=True, text=True)
        if r.returncode != 0:
            return "brdf-recon dhr --reference failed: %s" % r.stderr.strip()[-500:]
        z = np.genfromtxt(zpath, delimiter=",", names=True)["z"]
        how = "brdf-recon dhr --reference %s" % " ".join(extra)
        chi = re.search(r"chi2 ([0-9.eE+-]+) for (\d+) wavelengths, P\(chi2 >= that \| agreement\) = ([0-9.eE+-]+): "
                        r"(NOT consistent|consistent)", r.stderr)
        if chi:
            how += "; chi2 %s for %s wavelengths, P(chi2) %s: %s at the 1 %% level" % chi.groups()
    else:
        # a build without --reference: the same comparison here, from `brdf-recon dhr` at 8 deg
        d8 = os.path.join(out, "dhr8.csv")
        r = subprocess.run([RECON, "dhr", model, "--theta-i", "8", "-o", d8], capture_output=True, text=True)
        if r.returncode != 0:
            return "brdf-recon dhr failed: %s" % r.stderr.strip()[-500:]
        a = np.genfromtxt(d8, delimiter=",", names=True)
        b = np.genfromtxt(ref, delimiter=",", names=True)
        k = (b["wavelength_nm"] >= a["wavelength_nm"].min()) & (b["wavelength_nm"] <= a["wavelength_nm"].max())
        md = np.interp(b["wavelength_nm"][k], a["wavelength_nm"], a["dhr"])
        ms = np.interp(b["wavelength_nm"][k], a["wavelength_nm"], a["sigma"])
        z = (md - b["dhr"][k]) / np.sqrt(ms ** 2 + b["sigma"][k] ** 2)
        with open(zpath, "w") as f:
            f.write("wavelength_nm,z\n")
            for w, v in zip(b["wavelength_nm"][k], z):
                f.write("%g,%.6g\n" % (w, v))
        how = "brdf-recon dhr (the build has no --reference)"
    if len(z) == 0:
        return "no wavelength in common with the model"
    return ("%.1f %% of %d wavelengths within |z| < 2 (RMS z %.2f, max |z| %.2f; z with both uncertainties; %s)"
            % (100 * np.mean(np.abs(z) < 2), len(z), float(np.sqrt(np.mean(z ** 2))), float(np.abs(z).max()), how))


def budget_and_truth(out):
    """Issue 13 item 1 in the summary: the DHR's uncertainty budget at 8 deg (`brdf-recon info`, median and largest
    per component) and the DHR at 8 deg (dhr8.csv, written by reference_check) against the simulator's exact DHR
    (`acq-sim truth SAMPLE --dhr`): the share of wavelengths with |z| < 2 and z RMS, z = (DHR - truth) / sigma.
    Returns the lines to print."""
    import numpy as np
    lines = []
    model, d8 = os.path.join(out, "model.brdf"), os.path.join(out, "dhr8.csv")
    r = subprocess.run([RECON, "info", model], capture_output=True, text=True)
    if r.returncode == 0:
        txt = r.stdout.splitlines()
        k = [i for i, x in enumerate(txt) if x.startswith("budget at theta_i=8")]
        if k:
            lines.append("budget:              %s" % txt[k[0]].strip())
            lines += ["                     %s" % x.strip() for x in txt[k[0] + 1:] if x.startswith("  ")]
    tr = os.path.join(out, "truth-dhr8.csv")
    if os.path.exists(d8) and subprocess.run([L.SIM, "truth", SAMPLE, "--dhr", tr, "--theta-i", "8", "--wavelengths",
                                              "450:1100:1"], capture_output=True).returncode == 0:
        a = np.genfromtxt(d8, delimiter=",", names=True)
        with open(tr) as f:  # '#' lines, then theta_i,wavelength_nm,dhr,sigma
            t = np.array([ln.split(",") for ln in f if ln[:1].isdigit()], dtype=float)
        truth = np.interp(a["wavelength_nm"], t[:, 1], t[:, 2])
        z = (a["dhr"] - truth) / a["sigma"]
        lines.append("DHR vs exact truth:  DHR at 8 deg vs `acq-sim truth %s --dhr`: %.1f %% of %d wavelengths within "
                     "|z| < 2, RMS z %.2f (z = (DHR - truth) / sigma, the model's sigma alone)"
                     % (SAMPLE, 100 * np.mean(np.abs(z) < 2), len(z), float(np.sqrt(np.mean(z ** 2)))))
    return lines


def main():
    demo = os.path.join(L.BUILD, "demo")
    shutil.rmtree(demo, ignore_errors=True)
    os.makedirs(demo)
    if not os.path.exists(PLAN):
        print("make demo: %s is missing (the planner's example plans are not merged yet)" % PLAN, file=sys.stderr)
        return 1
    b = L.Bench(state_dir=demo, scale=SCALE, seed=int(os.environ.get("ACQ_SEED", "1")))
    set_systematics(b.conf)
    watch = None
    t0 = time.time()
    try:
        print("demo: starting acq-sim (time scale %g) and acquisitiond in %s" % (SCALE, demo), flush=True)
        b.start_sim()
        b.start_daemon()
        with open(PLAN) as f:
            plan = f.read()
        sid = L.start_sweep(b, plan, "demo-%s-%s" % (os.path.basename(PLAN).rsplit(".", 1)[0].replace("plan-", ""),
                                                      SAMPLE))
        total = L.sweep_row(b, sid)["points_total"]
        print("demo: sweep %d started: %d points (the plan's visible ones), white reference first" % (sid, total),
              flush=True)
        watch = subprocess.Popen([ACQCTL, "-s", b.sock, "watch"], stdin=subprocess.DEVNULL)
        row = L.drive_to_end(b, sid, timeout=1800, sample=SAMPLE)
        if watch.poll() is None:
            watch.terminate()
            watch.wait(5)
        watch = None
        print("\ndemo: sweep %d %s in %.0f s" % (sid, row["state"], time.time() - t0), flush=True)
        if row["state"] != "completed":
            print("demo: the sweep did not complete; see %s" % b.daemon_log)
            return 1
        # the reconstruction chain runs in a child process of the daemon: wait for its last word
        verdict, deadline = None, time.time() + 900
        while time.time() < deadline and verdict is None:
            db = b.db()
            for (msg,) in db.execute("SELECT message FROM events WHERE sweep_id = ? AND device = 'recon' "
                                     "ORDER BY id", (sid,)):
                if msg.startswith("reconstruction ") or msg.startswith("no reconstruction") or \
                        "no reconstruction ran" in msg:
                    verdict = msg
            db.close()
            time.sleep(0.5)
        out = os.path.join(b.state, "recon", "sweep-%d" % sid)
        try:
            zs, nan = L.zscores(b, sid, material=SAMPLE)
            import numpy as np
            z = np.array(zs)
            acc = "calibrated samples vs the simulator's ground truth: %d values, z mean %.3f, std %.3f, " \
                  "|z| < 3 for %.2f %%" % (len(z), z.mean(), z.std(), 100 * np.mean(np.abs(z) < 3))
        except (L.Skip, AssertionError) as e:
            acc = "ground-truth comparison unavailable: %s" % e
        print("\n==== demo results (all under %s) ====" % demo)
        print("database:            %s" % b.db_path())
        print("calibrated samples:  %s" % os.path.join(out, "samples.csv"))
        print("accuracy:            %s" % acc)
        print("reconstruction:      %s" % (verdict or "no word from the reconstruction within 15 min"))
        try:
            agree = reference_check(out, int(os.environ.get("ACQ_SEED", "1")), b.conf)
        except (OSError, ValueError) as e:
            agree = "comparison failed: %s" % e
        print("spectrophotometer:   DHR at 8 deg vs the simulated d/8 sphere measurement of %s: %s" % (SAMPLE, agree))
        try:
            for line in budget_and_truth(out):
                print(line)
        except (OSError, ValueError) as e:
            print("budget:              not shown: %s" % e)
        for label, name in (("model", "model.brdf"), ("MERL table", "merl.binary"), ("DHR table", "dhr.csv"),
                            ("DHR plot", "dhr.png"), ("preview image", "preview.png"),
                            ("spectrophotometer", "spectrophotometer.csv"), ("DHR vs reference", "dhr-reference.png"),
                            ("z per wavelength", "dhr-reference-z.csv")):
            p = os.path.join(out, name)
            print("%-20s %s" % (label + ":", p if os.path.exists(p) else "(not produced: %s)" % p))
        import demo_outputs  # issue 18: RGL .bsdf, HDR preview, slice plots
        for label, p in demo_outputs.make(L.BUILD, out):
            print("%-20s %s" % (label + ":", p))
        print("logs:                %s, %s" % (b.daemon_log, b.sim_log))
        return 0
    except L.Skip as e:
        print("make demo: cannot run yet: %s" % e, file=sys.stderr)
        return 1
    except AssertionError as e:
        print("make demo: failed: %s" % e, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("\nmake demo: interrupted; stopping everything", file=sys.stderr)
        return 130
    except (OSError, EOFError) as e:
        # Ctrl-C reaches the daemon too (same process group): it may be gone before we see the interrupt
        print("\nmake demo: acquisitiond is gone (%s); stopping everything; logs: %s" % (e, b.daemon_log),
              file=sys.stderr)
        return 130 if b.daemon and b.daemon.poll() is not None else 1
    finally:
        if watch and watch.poll() is None:
            watch.terminate()
            watch.wait(5)
        b.stop()


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
    sys.exit(main())
