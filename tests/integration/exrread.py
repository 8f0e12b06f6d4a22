#!/usr/bin/python3
"""exrread: a small OpenEXR reader for the tests (scanline images, FLOAT/HALF channels, NO or ZIP/ZIPS
compression), written from the OpenEXR file layout so the tests can check pixel values without Python bindings."""
import struct
import zlib

import numpy as np


def _attrs(buf):
    if buf[:4] != b"\x76\x2f\x31\x01":
        raise ValueError("not an OpenEXR file")
    pos, attrs = 8, {}
    while buf[pos] != 0:
        e = buf.index(b"\0", pos)
        name = buf[pos:e].decode()
        e2 = buf.index(b"\0", e + 1)
        typ = buf[e + 1:e2].decode()
        (size,) = struct.unpack_from("<i", buf, e2 + 1)
        attrs[name] = (typ, buf[e2 + 5:e2 + 5 + size])
        pos = e2 + 5 + size
    return attrs, pos + 1


def read(path):
    """(channels dict name -> [H, W] float array, attributes dict name -> (type, raw bytes))."""
    with open(path, "rb") as fh:
        buf = fh.read()
    attrs, pos = _attrs(buf)
    comp = attrs["compression"][1][0]
    if comp not in (0, 2, 3):
        raise ValueError("compression %d not supported by this reader" % comp)
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"][1])
    W, H = x1 - x0 + 1, y1 - y0 + 1
    raw = attrs["channels"][1]
    chans, p = [], 0
    while raw[p] != 0:
        e = raw.index(b"\0", p)
        name = raw[p:e].decode()
        ptype, = struct.unpack_from("<i", raw, e + 1)
        chans.append((name, ptype))
        p = e + 17
    lines = {0: 1, 2: 1, 3: 16}[comp]
    nchunks = (H + lines - 1) // lines
    offs = struct.unpack_from("<%dQ" % nchunks, buf, pos)
    out = {n: np.zeros((H, W), np.float32) for n, _ in chans}
    for off in offs:
        y, size = struct.unpack_from("<ii", buf, off)
        data = buf[off + 8:off + 8 + size]
        nl = min(lines, y1 - y + 1)
        expect = sum(W * nl * (2 if t == 1 else 4) for _, t in chans)
        if comp != 0 and size < expect:
            t = np.frombuffer(zlib.decompress(data), np.uint8).astype(np.int64)
            t[1:] -= 128                                   # undo the predictor: u[i] = u[i-1] + t[i] - 128
            t = (np.cumsum(t) % 256).astype(np.uint8)
            half = (len(t) + 1) // 2
            d = np.empty(len(t), np.uint8)
            d[0::2] = t[:half]
            d[1::2] = t[half:]
            data = d.tobytes()
        q = 0
        for row in range(nl):
            for n, typ in chans:
                dt, sz = ("<f2", 2) if typ == 1 else ("<f4", 4) if typ == 2 else ("<u4", 4)
                out[n][y - y0 + row] = np.frombuffer(data, dt, W, q)
                q += W * sz
    return out, attrs
