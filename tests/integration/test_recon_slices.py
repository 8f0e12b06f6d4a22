#!/usr/bin/python3
"""Integration test of `brdf-recon slices`: in-plane slices at every measured incidence of the sample file, with
--csv giving the plotted numbers: the model curve equals `brdf-recon eval` at the same directions (one
wavelength: linear between channels; a band: the trapezoid-weighted channel mean), the uncertainty band
contains the curve and is not empty, the in-plane samples are the file's (count and values), and the
measured samples agree with the model within their error bars combined with the band (coverage printed and
held >= 90 %); the PNGs are sRGB-tagged; bad input is refused with a message."""
import os
import sys
import tempfile

import numpy as np

SEED = int(os.environ.get("ACQ_SEED", "1")) % (2**31)
sys.path.insert(0, os.path.join(os.environ.get("ACQ_SRC", "."), "tests", "integration"))
from recon_tools import B, model_eval, run, synth_model  # noqa: E402

print("ACQ_SEED=%d" % SEED)


def read_csv(path):
    rows = [l.strip().split(",") for l in open(path)][1:]
    kind = np.array([r[0] for r in rows])
    num = np.array([[float(x) for x in r[1:]] for r in rows])
    return kind, num


def eval_model(d, m, ti, tos):
    """The model in the plane: signed theta_o (deg), + forward (phi_o - phi_i = 180)."""
    tos = np.asarray(tos)
    ang = np.radians(np.stack([ti, np.zeros(len(tos)), np.abs(tos), np.where(tos >= 0, 180.0, 0.0)], 1))
    return model_eval(d, m, ang)


def main():
    if not os.access(B, os.X_OK):
        print("brdf-recon not built")
        return 77
    d = tempfile.mkdtemp(prefix="recon_slices_")
    m, s = synth_model(d, 8, SEED)
    out, pol, csv = (os.path.join(d, x) for x in ("sl.png", "slp.png", "sl.csv"))
    run("slices", m, "-o", out, "--samples", s, "--polar", pol, "--csv", csv, "--wavelength", "600")
    for p in (out, pol):
        b = open(p, "rb").read()
        assert b[:8] == b"\x89PNG\r\n\x1a\n" and b"sRGB" in b[:200], p
    kind, num = read_csv(csv)
    mod, smp = num[kind == "model"], num[kind == "sample"]
    # incidences: the distinct theta_i of the in-plane samples (recon_synth: 10 from 0 to 75 deg)
    th = np.unique(np.round(mod[:, 0], 6))
    assert len(th) == 10 and abs(th[0]) < 1e-9 and abs(th[-1] - 75) < 1e-6, th
    # the curve is the model at the same directions
    wl, ev = eval_model(d, m, mod[:, 0], mod[:, 1])
    ref = np.array([np.interp(600, wl, row) for row in ev])
    rel = np.abs(mod[:, 2] - ref) / ref
    print("curve vs eval: max relative difference %.3g" % rel.max())
    assert rel.max() < 1e-8
    assert np.all(mod[:, 3] <= mod[:, 2] * (1 + 1e-12)) and np.all(mod[:, 4] >= mod[:, 2] * (1 - 1e-12))
    width = (mod[:, 4] - mod[:, 3]) / mod[:, 2]
    print("band half-width / f: median %.3g, max %.3g" % (np.median(width) / 2, width.max() / 2))
    assert width.max() > 0
    # the in-plane samples of the file
    lines = [l.strip().split(",") for l in open(s) if not l.startswith("#")]
    hdr, body = lines[0], np.array([[float(x) for x in r] for r in lines[1:]])
    vcols = [i for i, c in enumerate(hdr) if i >= 4 and not c.startswith("sigma")]
    swl = np.array([float(hdr[i]) for i in vcols])
    dphi = np.radians(body[:, 3] - body[:, 1])
    inplane = np.abs(np.sin(dphi)) <= np.sin(np.radians(2))
    assert len(smp) == inplane.sum() and len(smp) > 0
    sv = np.array([np.interp(600, swl, body[i, vcols]) for i in np.nonzero(inplane)[0]])
    assert np.allclose(np.sort(smp[:, 2]), np.sort(sv), rtol=1e-6)
    # honesty: measured samples vs the curve, within the bars and the band combined
    wl2, ev2 = eval_model(d, m, smp[:, 0], smp[:, 1])
    fs = np.array([np.interp(600, wl2, row) for row in ev2])
    half_bar = (smp[:, 4] - smp[:, 3]) / 2
    band = np.zeros(len(smp))
    for i, r in enumerate(smp):  # the band's half-width at the sample's own direction (same incidence)
        c = mod[np.abs(mod[:, 0] - r[0]) < 1e-6]
        band[i] = 0.5 * (np.interp(r[1], c[:, 1], c[:, 4]) - np.interp(r[1], c[:, 1], c[:, 3]))
    cover = np.abs(smp[:, 2] - fs) <= np.sqrt(half_bar ** 2 + band ** 2) + 1e-12
    print("in-plane samples within +-2 sigma (bars with the band): %.1f %%" % (100 * cover.mean()))
    assert cover.mean() >= 0.9
    # a band: the trapezoid-weighted mean of the channels inside it
    csv2 = os.path.join(d, "b.csv")
    run("slices", m, "-o", os.path.join(d, "b.png"), "--samples", s, "--csv", csv2, "--band", "500:800",
        "--theta-i", "30")
    k2, n2 = read_csv(csv2)
    mb = n2[k2 == "model"]
    assert np.all(np.abs(mb[:, 0] - 30) < 1e-9)
    wl3, ev3 = eval_model(d, m, mb[:, 0], mb[:, 1])
    inside = (wl3 >= 500) & (wl3 <= 800)
    edges = np.concatenate([[500], 0.5 * (wl3[1:] + wl3[:-1]), [800]])
    lo_e = np.maximum(500, np.concatenate([[500], 0.5 * (wl3[1:] + wl3[:-1])]))
    hi_e = np.minimum(800, np.concatenate([0.5 * (wl3[1:] + wl3[:-1]), [800]]))
    w = np.where(inside, np.maximum(hi_e - lo_e, 0), 0)
    w /= w.sum()
    assert np.allclose(mb[:, 2], ev3 @ w, rtol=1e-8), (mb[:3, 2], (ev3 @ w)[:3])
    del edges
    # refusals
    p = run("slices", m, "-o", out, ok=False)
    assert p.returncode == 1 and "no incidences" in p.stderr
    p = run("slices", m, "-o", out, "--samples", s, "--wavelength", "300", ok=False)
    assert p.returncode == 1 and "outside" in p.stderr
    p = run("slices", m, "-o", out, "--db", os.path.join(d, "x.db"), ok=False)
    assert p.returncode == 2
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
