#!/usr/bin/python3
"""recon_synth: synthetic spectral ground truth (Lambertian + GGX lobe) and the paper's 10x10x10 sparse
sampling with noise, as CSV; held-out random directions; the true DHR. Shared by the recon tests and bench."""
import argparse
import math
import sys

import numpy as np


def wavelengths(n, lo=450.0, hi=1100.0):
    return np.linspace(lo, hi, n)


def truth(ti, pi_, to, po, wl, alpha=0.25):
    """f(wi, wo, lambda) in sr^-1, arrays of angles (radians) broadcast against wl (last axis)."""
    rho = 0.05 + 0.45 * np.exp(-((wl - 550.0) / 45.0) ** 2) + 0.25 / (1 + np.exp(-(wl - 800.0) / 30.0))
    ks = 0.6 + 0.2 * (wl - 450.0) / 650.0
    wi = np.stack([np.sin(ti) * np.cos(pi_), np.sin(ti) * np.sin(pi_), np.cos(ti)], -1)
    wo = np.stack([np.sin(to) * np.cos(po), np.sin(to) * np.sin(po), np.cos(to)], -1)
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    ch = np.clip(h[..., 2], 0, 1)
    a2 = alpha * alpha
    D = a2 / (math.pi * (ch * ch * (a2 - 1) + 1) ** 2)
    ci, co = np.maximum(np.cos(ti), 1e-4), np.maximum(np.cos(to), 1e-4)

    def g1(c):
        return 2 * c / (c + np.sqrt(a2 + (1 - a2) * c * c))
    G = g1(ci) * g1(co)
    spec = D * G / (4 * ci * co)
    return rho / math.pi * (1 - 0.5 * ks[None, :] * 0.1) + (ks * 0.12)[None, :] * spec[:, None]


def sparse_grid():
    tis = np.radians(np.linspace(0, 75, 10))
    tos = np.radians(np.linspace(5, 80, 10))
    pos = np.radians(np.arange(10) * 36.0)
    T = np.array([(a, 0.0, b, c) for a in tis for b in tos for c in pos])
    return T


def random_dirs(rng, n):
    ti = np.arccos(rng.uniform(0.05, 1, n))
    to = np.arccos(rng.uniform(0.05, 1, n))
    return np.stack([ti, rng.uniform(0, 2 * math.pi, n), to, rng.uniform(0, 2 * math.pi, n)], -1)


def dhr(theta_i, wl, nmu=96, nphi=192):
    x, w = np.polynomial.legendre.leggauss(nmu)
    mu = 0.5 * (x + 1)
    wmu = 0.5 * w
    ph = (np.arange(nphi) + 0.5) * 2 * math.pi / nphi
    M, P = np.meshgrid(mu, ph, indexing="ij")
    to = np.arccos(M.ravel())
    n = to.size
    f = truth(np.full(n, theta_i), np.zeros(n), to, P.ravel(), wl)
    wt = (wmu[:, None] * M * (2 * math.pi / nphi)).ravel()
    return (f * wt[:, None]).sum(0)


def write_csv(path, ang, vals, wl, sig=None):
    with open(path, "w") as fh:
        fh.write("# synthetic ground truth: Lambertian + GGX lobe (recon_synth.py)\n")
        cols = ["theta_i", "phi_i", "theta_o", "phi_o"] + ["%g" % w for w in wl]
        if sig is not None:
            cols += ["sigma_%g" % w for w in wl]
        fh.write(",".join(cols) + "\n")
        deg = np.degrees(ang)
        for k in range(len(ang)):
            row = ["%.6f" % v for v in deg[k]] + ["%.8g" % v for v in vals[k]]
            if sig is not None:
                row += ["%.4g" % v for v in sig[k]]
            fh.write(",".join(row) + "\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--nwl", type=int, default=8)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--noise", type=float, default=0.02, help="relative noise")
    ap.add_argument("--samples", required=True)
    ap.add_argument("--heldout")
    ap.add_argument("--nheld", type=int, default=500)
    ap.add_argument("--truth-held")
    ap.add_argument("--dhr")
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    wl = wavelengths(a.nwl)
    ang = sparse_grid()
    f = truth(ang[:, 0], ang[:, 1], ang[:, 2], ang[:, 3], wl)
    sig = a.noise * f + 1e-4
    meas = f + sig * rng.standard_normal(f.shape)
    write_csv(a.samples, ang, meas, wl, sig)
    if a.heldout:
        h = random_dirs(rng, a.nheld)
        write_csv(a.heldout, h, np.zeros((len(h), 0)), [])
        if a.truth_held:
            np.save(a.truth_held, truth(h[:, 0], h[:, 1], h[:, 2], h[:, 3], wl))
            np.save(a.truth_held + ".ang.npy", h)
    if a.dhr:
        with open(a.dhr, "w") as fh:
            fh.write("theta_i,wavelength_nm,dhr\n")
            for t in (8, 30, 60):
                d = dhr(math.radians(t), wl)
                for w, v in zip(wl, d):
                    fh.write("%g,%g,%.10g\n" % (t, w, v))


if __name__ == "__main__":
    sys.exit(main())
