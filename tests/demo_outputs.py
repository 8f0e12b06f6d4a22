#!/usr/bin/python3
"""demo_outputs: the researcher-facing outputs of `make demo` from the sweep's reconstruction (issue 18): the
spectral RGL .bsdf and its RGB form (Mitsuba 3's RGB variants), the HDR preview (EXR + sRGB PNG + sidecar)
under the procedural sky, the slice plots with the measured samples, and the sweep as NeXus/HDF5 (acq-nexus).
Returns (label, path or reason) rows for the demo's summary."""
import os
import subprocess
import time


def make(build, out):
    """Write the outputs next to out/model.brdf; return [(label, path or '(not produced: why)')]."""
    B = os.path.join(build, "brdf-recon")
    m, s = os.path.join(out, "model.brdf"), os.path.join(out, "samples.csv")
    if not (os.path.exists(m) and os.access(B, os.X_OK)):
        return [("RGL .bsdf", "(not produced: no model)")]
    steps = (("RGL .bsdf", ["rgl", m, "-o", os.path.join(out, "model.bsdf"), "--threads", "2"], "model.bsdf"),
             ("RGL .bsdf, RGB", ["rgl", m, "-o", os.path.join(out, "model-rgb.bsdf"), "--threads", "2", "--rgb"],
              "model-rgb.bsdf"),
             ("HDR preview (EXR)", ["render", m, "-o", os.path.join(out, "preview-sky.png"), "--exr",
                                    os.path.join(out, "preview.exr"), "--threads", "2"], "preview.exr"),
             ("slice plot", ["slices", m, "-o", os.path.join(out, "slices.png"), "--samples", s, "--polar",
                             os.path.join(out, "slices-polar.png"), "--csv", os.path.join(out, "slices.csv")],
              "slices.png"))
    sweep = os.path.basename(os.path.normpath(out)).rsplit("-", 1)[-1]
    db = os.path.join(out, os.pardir, os.pardir, "acquisition.db")
    steps += (("NeXus/HDF5 sweep", [db, sweep, "-o", os.path.join(out, "sweep.nxs")], "sweep.nxs"),)
    rows = []
    for label, args, name in steps:
        if name == "sweep.nxs":
            B = os.path.join(build, "acq-nexus")
        t0 = time.time()
        p = subprocess.run([B, *args], capture_output=True, text=True)
        path = os.path.join(out, name)
        rows.append((label, path + " (%.1f s)" % (time.time() - t0) if p.returncode == 0 else
                     "(not produced: %s)" % p.stderr.strip().splitlines()[-1:]))
        if name == "preview.exr" and p.returncode == 0:
            rows.append(("sRGB preview + JSON", os.path.join(out, "preview-sky.png") + ", preview-sky.png.colour.json"))
        if name == "slices.png" and p.returncode == 0:
            rows.append(("polar slices", os.path.join(out, "slices-polar.png")))
    return rows
