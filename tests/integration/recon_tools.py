#!/usr/bin/python3
"""recon_tools: what the output tests of brdf-recon share (rgl, render HDR, slices, bench_rgl): run a command
and print it, a synthetic model (recon_synth.py samples + fit), the model at given directions through `eval`,
unit vectors from angles."""
import os
import subprocess
import sys

import numpy as np

BUILD = os.environ.get("ACQ_BUILD", "build")
SRC = os.environ.get("ACQ_SRC", ".")
B = os.path.join(BUILD, "brdf-recon")
SIM = os.environ.get("ACQ_SIM_BIN", os.path.join(BUILD, "acq-sim"))
SEED = int(os.environ.get("ACQ_SEED", "1")) % 100000


def run(*args, ok=True, prog=B):
    """Run prog (brdf-recon) with args, print the command, its status and stderr; exit on failure if ok."""
    p = subprocess.run([prog, *args], capture_output=True, text=True)
    print("$", os.path.basename(prog), " ".join(args), "->", p.returncode)
    if p.stderr:
        print(p.stderr.strip()[:2000])
    if ok and p.returncode != 0:
        sys.exit("FAIL: command failed")
    return p


def read_csv(path):
    """A CSV with optional # comment lines: ({column name: index}, float array of the rows)."""
    with open(path) as f:
        lines = [ln for ln in f if not ln.startswith("#") and ln.strip()]
    head = lines[0].strip().split(",")
    return {h: i for i, h in enumerate(head)}, np.array([ln.split(",") for ln in lines[1:]], dtype=float)


def synth_model(d, nwl, seed):
    """recon_synth.py samples (Lambertian + GGX truth, paper sampling, 2 % noise) fitted: (model, samples.csv)."""
    s, m = os.path.join(d, "s.csv"), os.path.join(d, "m.model")
    subprocess.run([sys.executable, os.path.join(SRC, "tests/integration/recon_synth.py"), "--samples", s,
                    "--nwl", str(nwl), "--seed", str(seed)], check=True)
    run("fit", s, "-o", m)
    return m, s


def model_eval(d, model, ang):
    """`brdf-recon eval` at ang [n, 4] (radians): (wavelengths, values [n, nwl])."""
    q, e = os.path.join(d, "q.csv"), os.path.join(d, "e.csv")
    with open(q, "w") as fh:
        fh.write("theta_i,phi_i,theta_o,phi_o\n")
        for a in np.degrees(ang):
            fh.write("%.17g,%.17g,%.17g,%.17g\n" % tuple(a))
    run("eval", model, q, "-o", e)
    with open(e) as fh:
        wl = np.array([float(x) for x in fh.readline().strip().split(",")[4:]])
    return wl, np.atleast_2d(np.genfromtxt(e, delimiter=",", skip_header=1))[:, 4:]


def vec(t, p):
    """Unit vectors [n, 3] from zenith t and azimuth p (radians)."""
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], 1)


def sim_truth_dhr(d, material, wl, thetas):
    """acq-sim's exact DHR of material at the incidences thetas (degrees) and wavelengths wl, written in folder d:
    the rows (theta_i, wavelength, dhr)."""
    tr = os.path.join(d, "truth.csv")
    run("truth", material, "--dhr", tr, "--theta-i", ",".join(map(str, thetas)), "--wavelengths", wl, prog=SIM)
    return read_csv(tr)[1]


def sim_fit_dhr(d, material, seed, wl, thetas):
    """acq-sim's material on the paper's 10 x 10 x 10 plan with 1 % noise (noise seed seed, wavelengths wl) in folder
    d, `brdf-recon fit`, then `dhr` at thetas with the same seed: (model path, the DHR CSV's columns, its rows)."""
    smp, m, o = (os.path.join(d, x) for x in ("s.csv", "m.model", "d.csv"))
    run("truth", material, "--grid", "10x10x10", "--noise", "0.01", "--seed", str(seed), "--wavelengths", wl,
        "-o", smp, prog=SIM)
    run("fit", smp, "-o", m)
    run("dhr", m, "--theta-i", ",".join(map(str, thetas)), "--seed", str(seed), "-o", o)
    c, A = read_csv(o)
    return m, c, A
