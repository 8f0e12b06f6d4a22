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
