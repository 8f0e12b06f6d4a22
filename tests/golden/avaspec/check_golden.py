#!/usr/bin/python3
"""Checks the committed AvaSpec golden files against the protocol fact sheet (drivers/avaspec-usb.md), by a
second derivation that shares nothing with gen_golden.py (which wrote them) nor with the C driver (which must
send the same bytes under umockdev):

  - every host -> device frame is compared with bytes written out by hand below, field by field from the
    fact sheet (type, sequence, little-endian length, command, 0x00, big-endian payload);
  - every device -> host answer is decoded by the rules of the fact sheet: type 0x21, byte 5 = 0x00, length =
    payload + 2, a reply's command = request + 0x80, an error reply of length 3 with command 0x00, spectra
    0xB0 (uint32 time stamp + uint16 per pixel) / 0xB1 (+ uint16 averages + uint32 per pixel), the
    configuration record of 63484 bytes; IN reads of at most 16384 bytes on endpoint 0x86, OUT on 0x02;
  - the device description has vendor 0x1992, product 0x0667, interface 0 with bulk 0x02 OUT / 0x86 IN.

Usage: check_golden.py [DIR]   (default: this script's folder). Prints one line per file; exit 1 on the first
disagreement, naming the file, the line and the field."""
import os
import sys

NPIX = 2048           # the golden device's pixel count (gen_golden.py's header; asserted by test_avaspec_usb.c)


def h(s):
    return bytes.fromhex(s.replace(" ", ""))


# ---- host -> device, by hand from the fact sheet ------------------------------------------------------------
# header: 20 (host->device), seq, length LE (= payload + 2), command, 00
STOP = "20 {s} 02 00 0F 00"             # 0x0F stop measurement, no payload
IDENT = "20 {s} 02 00 13 00"            # 0x13 identity
GETCFG = "20 {s} 02 00 01 00"           # 0x01 get device configuration
START1 = "20 {s} 04 00 06 00 00 01"     # 0x06 start, int16 count = 1 (big-endian)
ACK = "20 {s} 02 00 C0 00"              # 0xC0 acknowledges a data message (type 0x20 as the host)
# 0x05 prepare, 41-byte measurement configuration, length 43 = 0x2B:
#   StartPixel 0000, StopPixel 07FF (2047), IntegrationTime float32 BE, IntegrationDelay 00000000, NrAverages
#   uint32 BE, dark Enable 00 Forget 00, SmoothPix 0000 SmoothModel 00, SaturationDetection, trigger 00 00 00,
#   StrobeControl 0000, LaserDelay 00000000, LaserWidth 00000000, LaserWaveLength 00000000, StoreToRam 0000
PREPARE = ("20 {s} 2B 00 05 00  0000 07FF {t} 00000000 {n}  00 00  0000 00  {sat}  00 00 00  0000 00000000 00000000"
           " 00000000 0000")
F10 = "41200000"    # 10.0 = 1.25 * 2^3: sign 0, exponent 127 + 3 = 0x82, fraction .25 -> 0x200000
F2_5 = "40200000"   # 2.5 = 1.25 * 2^1: exponent 0x80, fraction .25


def opening():
    return [STOP.format(s="00"), IDENT.format(s="01"), GETCFG.format(s="02")]


def prepared(t, n, sat):
    return opening() + [PREPARE.format(s="03", t=t, n=n, sat=sat)]


def started(t=F10, n="00000001", sat="01"):
    return prepared(t, n, sat) + [START1.format(s="04")]


OUT = {
    "cycle": started() + [ACK.format(s="05")],
    "averaged": started(F2_5, "00000004", "00") + [ACK.format(s="05")],
    "error_reply": prepared(F10, "00000001", "01"),
    "short_data": started(),
    "oversized_data": started(),
    "vanish": started(),
    "stale_reset": opening(),
}
# pixels in the spectra each case's device sends (short/oversized: one less/more, deliberately)
SPECTRUM_PIXELS = {"short_data": NPIX - 1, "oversized_data": NPIX + 1}


class Bad(Exception):
    pass


def urbs(path):
    """(depth, endpoint, status, buflen, data, line number) of every URB line of an .ioctl file."""
    with open(path) as f:
        lines = f.read().split("\n")
    if lines[0] != "@DEV /dev/bus/usb/001/002":
        raise Bad("%s:1: not an ioctl recording of /dev/bus/usb/001/002" % path)
    out = []
    for no, line in enumerate(lines[1:], 2):
        if not line:
            continue
        depth = len(line) - len(line.lstrip(" "))
        w = line.split()
        if w[0] != "USBDEVFS_REAPURBNDELAY" or w[2] != "3" or len(w) not in (9, 10):
            raise Bad("%s:%d: not a bulk URB line" % (path, no))
        data = bytes.fromhex(w[9]) if len(w) == 10 else b""
        if int(w[7]) != len(data):
            raise Bad("%s:%d: actual length %s but %d bytes" % (path, no, w[7], len(data)))
        out.append((depth, int(w[3]), int(w[4]), int(w[6]), data, no))
    return out


def check_in(path, case, req, data, no):
    """Decode the device's answer (all IN URBs after one OUT, joined) to request command req."""
    pos = 0
    while pos < len(data):
        f = data[pos:]
        if len(f) < 6:
            raise Bad("%s:%d: %d stray bytes" % (path, no, len(f)))
        length = f[2] | f[3] << 8
        if f[0] != 0x21 or f[5] != 0 or len(f) < 4 + length:
            raise Bad("%s:%d: device frame header %s (type 0x21, byte 5 0x00, length %d)" % (path, no, f[:6].hex(),
                                                                                          length))
        cmd, pl = f[4], f[6:4 + length]
        if cmd == 0x00:
            if length != 3 or not 0 <= pl[0] <= 0x0C:
                raise Bad("%s:%d: error reply of length %d, reason %s" % (path, no, length, pl[:1].hex()))
        elif cmd == 0xB0:
            n = SPECTRUM_PIXELS.get(case, NPIX)
            if len(pl) != 4 + 2 * n:
                raise Bad("%s:%d: 0xB0 of %d bytes, want 4 + 2 x %d" % (path, no, len(pl), n))
        elif cmd == 0xB1:
            if len(pl) not in (4 + 4 * NPIX, 6 + 4 * NPIX):
                raise Bad("%s:%d: 0xB1 of %d bytes" % (path, no, len(pl)))
        elif cmd != (req + 0x80) & 0xFF:
            raise Bad("%s:%d: reply command 0x%02X to request 0x%02X" % (path, no, cmd, req))
        elif req == 0x01 and len(pl) != 63484:
            raise Bad("%s:%d: configuration record of %d bytes, not 63484" % (path, no, len(pl)))
        pos += 4 + length


def check_ioctl(path, case):
    want = [h(x) for x in OUT[case]]
    got_out, answers = [], []
    for depth, ep, status, buflen, data, no in urbs(path):
        if depth == 0:
            if ep != 0x02 or status != 0:
                raise Bad("%s:%d: OUT on endpoint %d status %d" % (path, no, ep, status))
            got_out.append((data, no))
            answers.append([b"", no])
            continue
        if ep != 0x86 or buflen != 16384 or len(data) > buflen:
            raise Bad("%s:%d: IN on endpoint %d, read of %d" % (path, no, ep, buflen))
        if status not in (0, -19) or (status == -19 and case != "vanish"):
            raise Bad("%s:%d: IN status %d" % (path, no, status))
        if not answers:
            raise Bad("%s:%d: an answer before any request" % (path, no))
        answers[-1][0] += data
    if len(got_out) != len(want):
        raise Bad("%s: %d host frames, the fact sheet's sequence has %d" % (path, len(got_out), len(want)))
    for i, ((data, no), w) in enumerate(zip(got_out, want)):
        if data != w:
            raise Bad("%s:%d: host frame %d is %s, by the fact sheet %s" % (path, no, i, data.hex(), w.hex()))
    for (data, no), (ans, _) in zip(got_out, answers):
        check_in(path, case, data[4], ans, no)
    return len(got_out)


def check_umockdev(path):
    with open(path) as f:
        text = f.read()
    for need in ("E: ID_VENDOR_ID=1992", "E: ID_MODEL_ID=0667", "A: idVendor=1992", "A: idProduct=0667"):
        if need not in text:
            raise Bad("%s: no line %r" % (path, need))
    desc = bytes.fromhex(text.split("N: bus/usb/001/002=")[1].split()[0])
    if desc[8:12] != h("9219 6706"):   # idVendor, idProduct, little-endian in the device descriptor
        raise Bad("%s: device descriptor ids %s" % (path, desc[8:12].hex()))
    eps = set()
    i = desc[0]
    while i + 1 < len(desc):
        if desc[i + 1] == 5:              # endpoint descriptor: address, attributes (2 = bulk)
            if desc[i + 3] != 2:
                raise Bad("%s: endpoint 0x%02X is not bulk" % (path, desc[i + 2]))
            eps.add(desc[i + 2])
        i += desc[i]
    if eps != {0x02, 0x86}:
        raise Bad("%s: endpoints %s, want 0x02 OUT and 0x86 IN" % (path, sorted(eps)))


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
    try:
        check_umockdev(os.path.join(d, "avaspec.umockdev"))
        print("avaspec.umockdev: ids and endpoints as the fact sheet says")
        for case in sorted(OUT):
            n = check_ioctl(os.path.join(d, case + ".ioctl"), case)
            print("%s.ioctl: %d host frames equal the hand-derived bytes; every answer decodes" % (case, n))
        extra = sorted(f for f in os.listdir(d) if f.endswith(".ioctl") and f[:-6] not in OUT)
        if extra:
            raise Bad("%s: no hand-derived traffic for %s" % (d, ", ".join(extra)))
    except Bad as e:
        print("golden check failed: %s" % e)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
