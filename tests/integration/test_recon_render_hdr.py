#!/usr/bin/python3
"""Integration test of `brdf-recon render` as an HDR preview: the EXR is a valid OpenEXR (exrheader reads it:
float R, G, B, Rec. 709 chromaticities, a comment) whose linear pixels, through the tone stages the sidecar
states (Reinhard on luminance with the stated white, clip, sRGB curve), give the PNG's 8-bit pixels within one
code value; the PNG carries sRGB, gAMA and cHRM; the sidecar describes the image (colour space, tone counters,
EXR encoding, lighting and sampling) and the BRDF-to-RGB chain separately; the image does not depend on the
thread count; a user's lat-long EXR (here the first render's own EXR) lights the sphere; bad inputs are refused."""
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import zlib

import numpy as np

SEED = int(os.environ.get("ACQ_SEED", "1")) % (2**31)
sys.path.insert(0, os.path.join(os.environ.get("ACQ_SRC", "."), "tests", "integration"))
import exrread  # noqa: E402
from recon_tools import B, run, synth_model  # noqa: E402

print("ACQ_SEED=%d" % SEED)


def png_pixels_and_chunks(path):
    buf = open(path, "rb").read()
    assert buf[:8] == b"\x89PNG\r\n\x1a\n"
    pos, chunks, idat = 8, {}, b""
    while pos < len(buf):
        (n,) = struct.unpack(">I", buf[pos:pos + 4])
        t = buf[pos + 4:pos + 8].decode()
        d = buf[pos + 8:pos + 8 + n]
        chunks[t] = d
        if t == "IDAT":
            idat += d
        pos += 12 + n
    w, h, depth, ctype = struct.unpack(">IIBB", chunks["IHDR"][:10])
    assert depth == 8 and ctype == 2
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + 3 * w)
    img = np.zeros((h, 3 * w), np.int64)
    prev = np.zeros(3 * w, np.int64)
    for j in range(h):  # undo the PNG filters
        f, x = raw[j, 0], raw[j, 1:].astype(np.int64)
        cur = np.zeros(3 * w, np.int64)
        for i in range(3 * w):
            a = cur[i - 3] if i >= 3 else 0
            b = prev[i]
            c = prev[i - 3] if i >= 3 else 0
            if f == 0:
                pr = 0
            elif f == 1:
                pr = a
            elif f == 2:
                pr = b
            elif f == 3:
                pr = (a + b) // 2
            else:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pr = a if pa <= pb and pa <= pc else b if pb <= pc else c
            cur[i] = (x[i] + pr) % 256
        img[j] = cur
        prev = cur
    return img.reshape(h, w, 3), chunks


def srgb(v):
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(np.maximum(v, 0), 1 / 2.4) - 0.055)


def main():
    if not os.access(B, os.X_OK):
        print("brdf-recon not built")
        return 77
    if not shutil.which("exrheader"):
        sys.exit("FAIL: exrheader (Debian package openexr, in DEB_PKGS) is missing")
    d = tempfile.mkdtemp(prefix="recon_hdr_")
    m, _ = synth_model(d, 8, SEED)
    png, exr = os.path.join(d, "p.png"), os.path.join(d, "p.exr")
    run("render", m, "-o", png, "--exr", exr, "--size", "64", "--threads", "1", "--seed", str(SEED))
    hdr = subprocess.run(["exrheader", exr], capture_output=True, text=True, check=True).stdout
    print(hdr)
    for k in ("R, 32-bit floating-point", "G, 32-bit floating-point", "B, 32-bit floating-point",
              "red   (0.64 0.33)", "white (0.3127 0.329)", "comments", "zip"):
        assert k in hdr, k
    ch, attrs = exrread.read(exr)
    lin = np.stack([ch["R"], ch["G"], ch["B"]], -1).astype(float)
    assert lin.shape == (64, 64, 3) and np.all(np.isfinite(lin)) and lin.max() > 0
    img, chunks = png_pixels_and_chunks(png)
    assert chunks["sRGB"] == b"\x00" and struct.unpack(">I", chunks["gAMA"])[0] == 45455
    assert struct.unpack(">8I", chunks["cHRM"])[:2] == (31270, 32900)
    side = json.load(open(png + ".colour.json"))
    im = side["image"]
    assert "sRGB" in im["png"]["colour_space"] and im["exr"]["path"] == exr and "linear" in im["exr"]["encoding"]
    assert im["lighting"]["spp"] == 64 and "sun" in im["lighting"]["kind"] and im["lighting"]["sun"] is not None
    assert side["brdf_to_rgb"]["illuminant"] == "D65" and "stats" not in im["png"]["tone"]
    tone = im["png"]["tone"]
    assert tone["pixels"] == 64 * 64
    # the PNG is the EXR through the stated tone stages: Reinhard on luminance, clip, sRGB curve, 8 bits
    lw = tone["reinhard_white"]
    L = (0.2126 * lin[..., 0] + 0.7152 * lin[..., 1] + 0.0722 * lin[..., 2])[..., None]
    toned = np.clip(np.where(L > 0, lin * (1 + L / lw ** 2) / (1 + L), lin), 0, 1)
    expect = np.round(srgb(toned) * 255)
    diff = np.abs(expect - img)
    print("PNG vs tone-mapped EXR: max difference %d code values" % diff.max())
    assert diff.max() <= 1
    # thread count does not change the image
    exr2 = os.path.join(d, "p2.exr")
    run("render", m, "-o", os.path.join(d, "p2.png"), "--exr", exr2, "--size", "64", "--threads", "2",
        "--seed", str(SEED))
    c2, _ = exrread.read(exr2)
    assert all(np.array_equal(ch[k], c2[k]) for k in "RGB")
    # a user environment map (the first render's EXR as a lat-long map) is used as it is: no procedural sun unless
    # --sun (since session 18: a captured HDR map holds its own sun; before, the sun was added unless --no-sun)
    pe, ee = os.path.join(d, "e.png"), os.path.join(d, "e.exr")
    run("render", m, "-o", pe, "--exr", ee, "--size", "32", "--env", exr, "--env-scale", "4")
    se = json.load(open(pe + ".colour.json"))["image"]["lighting"]
    assert se["sun"] is None and "environment map" in se["kind"] and "sun" not in se["kind"], se
    ce, _ = exrread.read(ee)
    assert np.all(np.isfinite(ce["G"])) and ce["G"].max() > 0
    ps, es = os.path.join(d, "s.png"), os.path.join(d, "s.exr")
    run("render", m, "-o", ps, "--exr", es, "--size", "32", "--env", exr, "--env-scale", "4", "--sun", "--direct",
        "--spp", "8")
    ss = json.load(open(ps + ".colour.json"))["image"]["lighting"]
    assert ss["sun"] is not None and "sun" in ss["kind"], ss
    cs, _ = exrread.read(es)
    assert np.all(np.isfinite(cs["G"])) and cs["G"].max() > ce["G"].max()  # the sun's highlight on top of the map
    print("--env: no sun by default; --sun adds it (brightest pixel %.3g -> %.3g)" % (ce["G"].max(), cs["G"].max()))
    # the old fixed lights remain available
    run("render", m, "-o", os.path.join(d, "l.png"), "--size", "32", "--lights")
    # refusals
    p = run("render", m, "-o", pe, "--env", os.path.join(d, "missing.exr"), ok=False)
    assert p.returncode != 0 and "missing.exr" in p.stderr
    p = run("render", m, "-o", pe, "--spp", "2", ok=False)
    assert p.returncode == 2 and "--spp" in p.stderr
    p = run("merl", m, "-o", os.path.join(d, "x.binary"), "--exr", ee, ok=False)
    assert p.returncode == 2
    p = run("render", m, "-o", pe, "--env", exr, "--sun", "--no-sun", ok=False)
    assert p.returncode == 2 and "--no-sun" in p.stderr
    p = run("render", m, "-o", pe, "--sun", ok=False)
    assert p.returncode == 2 and "--env" in p.stderr
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
