#!/usr/bin/python3
"""bench_rgl: `brdf-recon rgl` at the paper's size: a model fitted to the 10x10x10 sampling with 651 wavelengths
(450-1100 nm, recon_synth.py's Lambertian + GGX truth, 2 % noise), written as a spectral RGL .bsdf at the default
tables (30 incidences, 32x32 warped grid, 128x128 NDF) and at 64x64, with 1 and 2 threads: wall and CPU time,
peak memory, file size; and the file's agreement with `brdf-recon eval` through the tests' reader (rglread.py)
at 10^4 random pairs (theta <= 80 deg, and the whole hemisphere): max and RMS relative error over all
wavelengths. Writes $ACQ_BENCH_OUT/bench_rgl.csv (metric,value)."""
import math
import os
import sys
import tempfile

import numpy as np

BUILD = os.environ.get("ACQ_BUILD", "build")
SRC = os.environ.get("ACQ_SRC", ".")
OUT = os.environ.get("ACQ_BENCH_OUT", os.path.join(BUILD, "bench"))
SEED = int(os.environ.get("ACQ_SEED", "1")) % (2**31)
B = os.path.join(BUILD, "brdf-recon")
sys.path.insert(0, os.path.join(SRC, "tests", "integration"))
import benchlib  # noqa: E402
import rglread  # noqa: E402
from recon_tools import model_eval, synth_model, vec  # noqa: E402


def timed(args):
    """(wall s, CPU s, peak RSS MiB) of a child."""
    w, c, rss, err = benchlib.run_child(args, "bench_rgl")
    print("   ", err.strip())
    return w, c, rss


def agreement(d, model, bsdf, tmax_deg, rng, n=10000):
    c = math.cos(math.radians(tmax_deg))
    ang = np.stack([np.arccos(rng.uniform(c, 1, n)), rng.uniform(0, 2 * math.pi, n),
                    np.arccos(rng.uniform(c, 1, n)), rng.uniform(0, 2 * math.pi, n)], 1)
    ev = model_eval(d, model, ang)[1]
    r = rglread.RGL(bsdf)
    f = r.eval(vec(ang[:, 0], ang[:, 1]), vec(ang[:, 2], ang[:, 3]))
    rel = np.abs(f - ev) / ev
    return rel.max(), math.sqrt(np.mean(rel ** 2)), np.median(rel)


def main():
    os.makedirs(OUT, exist_ok=True)
    d = tempfile.mkdtemp(prefix="bench_rgl_")
    print("bench_rgl: seed %d, data in %s" % (SEED, d))
    m, _ = synth_model(d, 651, SEED)
    res = {}
    rng = np.random.default_rng(SEED)
    for tag, extra in (("32", []), ("64", ["--resolution", "64"])):
        f = os.path.join(d, "m%s.bsdf" % tag)
        for th in (1, 2):
            w, c, rss = timed([B, "rgl", m, "-o", f, "--threads", str(th), *extra])
            res["rgl%s_%dt_wall_s" % (tag, th)] = w
            res["rgl%s_%dt_cpu_s" % (tag, th)] = c
            res["rgl%s_%dt_rss_mib" % (tag, th)] = rss
        res["rgl%s_bytes" % tag] = os.path.getsize(f)
        for dom in (80, 90):
            mx, rms, med = agreement(d, m, f, dom, rng)
            res["rgl%s_theta%d_max_rel" % (tag, dom)] = mx
            res["rgl%s_theta%d_rms_rel" % (tag, dom)] = rms
            res["rgl%s_theta%d_median_rel" % (tag, dom)] = med
    benchlib.write_results(OUT, "bench_rgl", res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
