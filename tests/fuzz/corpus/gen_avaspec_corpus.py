#!/usr/bin/python3
"""Writes the seed corpus of tests/fuzz/fuzz_avaspec_frame.c (deterministic). Usage: gen_avaspec_corpus.py"""
import os
import struct

NPIX = 64
out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "fuzz_avaspec_frame")


def frame(cmd, payload=b"", typ=0x21):
    return bytes([typ, 0]) + struct.pack("<H", len(payload) + 2) + bytes([cmd, 0]) + payload


def single(n=NPIX):
    return frame(0xB0, struct.pack(">I", 5) + b"".join(struct.pack(">H", 100 + 7 * i) for i in range(n)))


def averaged(n=NPIX, field=True):
    head = struct.pack(">IH", 5, 1) if field else struct.pack(">I", 5)
    return frame(0xB1, head + b"".join(struct.pack(">I", 100 + i) for i in range(n)))


def transfers(*chunks):
    return b"\x01" + b"".join(struct.pack(">H", len(c)) + c for c in chunks)


seeds = {
    "frame_single": b"\x00" + single(),
    "frame_averaged": b"\x00" + averaged(),
    "frame_averaged_nofield": b"\x00" + averaged(field=False),
    "frame_error": b"\x00" + frame(0x00, b"\x07"),
    "frame_identity": b"\x00" + frame(0x93, b"SER".ljust(10, b"\0") + b"Name".ljust(64, b"\0") + b"\x01"),
    "session_single": transfers(single()),
    "session_split": transfers(single()[:3], b"", single()[3:40], single()[40:]),
    "session_averaged": transfers(b"", averaged()),
    "session_error": transfers(frame(0x00, b"\x0b")),
    "session_short": transfers(single(NPIX - 1)),
    "session_oversized": transfers(single() + b"\x00\x00"),
    "session_saturated": transfers(frame(0xB0, struct.pack(">I", 5) + b"\xff\xff" * NPIX)),
}
os.makedirs(out, exist_ok=True)
for name, data in sorted(seeds.items()):
    with open(os.path.join(out, name), "wb") as f:
        f.write(data)
