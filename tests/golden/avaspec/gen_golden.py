#!/usr/bin/python3
"""Writes the umockdev golden files of the AvaSpec driver tests, deterministically, from the protocol as
drivers/avaspec-usb.md describes it (written independently of the C framing code, so a framing bug in the
driver shows up as an OUT mismatch under umockdev).

Usage: tests/golden/avaspec/gen_golden.py [OUTDIR]      (default: this script's folder)
Files: avaspec.umockdev (the device: bus 001 device 002, 1992:0667, interface 0, bulk 0x02 OUT / 0x86 IN,
512-byte packets) and one <case>.ioctl per test case of tests/unit/test_avaspec_usb.c.

The device's contents (fixed here and asserted by the C test):
  identity: serial "BRDF0001", name "AvaSpec-ULS2048CL-EVO", status 1
  configuration: 2048 pixels, λ = 450 + 0.32 p − 1e-6 p², nonlinearity enabled with P(c) = 1 + 1e-6 c,
                 limits [1000, 60000]
  spectrum: raw(p) = 1000 + (37 p) mod 20000, except raw(100) = 0xFFFF (saturated), raw(2..5) = 1000 + p
"""
import os
import struct
import sys

NPIX = 2048
CHUNK = 16384          # bytes the driver asks per IN read (AVS_CHUNK)
EP_OUT, EP_IN = 0x02, 0x86
DEVCFG_LEN = 63484


def frame(typ, seq, cmd, payload=b""):
    return bytes([typ, seq & 0xFF]) + struct.pack("<H", len(payload) + 2) + bytes([cmd, 0]) + payload


def raw_spectrum():
    r = [1000 + (37 * p) % 20000 for p in range(NPIX)]
    for p in range(2, 6):
        r[p] = 1000 + p
    r[100] = 0xFFFF
    return r


def identity():
    return b"BRDF0001".ljust(10, b"\0") + b"AvaSpec-ULS2048CL-EVO".ljust(64, b"\0") + bytes([1])


def devcfg():
    rec = bytearray(DEVCFG_LEN)
    struct.pack_into(">H", rec, 0, DEVCFG_LEN & 0xFFFF)
    struct.pack_into(">H", rec, 2, 1)
    rec[4:4 + 64] = b"AvaSpec-ULS2048CL-EVO".ljust(64, b"\0")
    rec[68] = 14
    struct.pack_into(">H", rec, 69, NPIX)
    struct.pack_into(">5f", rec, 71, 450.0, 0.32, -1e-6, 0.0, 0.0)
    rec[91] = 1
    struct.pack_into(">8d", rec, 92, 1.0, 1e-6, 0, 0, 0, 0, 0, 0)
    struct.pack_into(">d", rec, 156, 1000.0)
    struct.pack_into(">d", rec, 164, 60000.0)
    return bytes(rec)


def meascfg(integration_ms, averages, saturation):
    # StartPixel, StopPixel, IntegrationTime, IntegrationDelay, NrAverages, dark Enable, Forget,
    # SmoothPix, SmoothModel, SaturationDetection, trigger Mode, Source, SourceType,
    # StrobeControl, LaserDelay, LaserWidth, LaserWaveLength, StoreToRam
    b = struct.pack(">HHfII BB HB B BBB HIIfH".replace(" ", ""), 0, NPIX - 1, integration_ms, 0, averages,
                    0, 0, 0, 0, saturation, 0, 0, 0, 0, 0, 0, 0.0, 0)
    assert len(b) == 41
    return b


class Script:
    """Builds an .ioctl file: OUT URBs at depth 0, the device's answers as a chain of deeper lines."""

    def __init__(self):
        self.lines = ["@DEV /dev/bus/usb/001/002"]
        self.seq = 0
        self.depth = 0

    def out(self, cmd, payload=b"", typ=0x20, status=0):
        data = frame(typ, self.seq, cmd, payload)
        self.seq += 1
        self.lines.append("USBDEVFS_REAPURBNDELAY 0 3 %d %d 0 %d %d 0 %s"
                          % (EP_OUT, status, len(data), len(data), data.hex().upper()))
        self.depth = 0

    def inp(self, data, status=0):
        for off in range(0, max(len(data), 1), CHUNK):
            part = data[off:off + CHUNK]
            self.depth += 1
            self.lines.append(" " * self.depth + "USBDEVFS_REAPURBNDELAY 0 3 %d %d 0 %d %d 0 %s"
                              % (EP_IN, status, CHUNK, len(part), part.hex().upper()))

    def reply(self, cmd, payload=b""):
        self.inp(frame(0x21, 0, cmd + 0x80, payload))

    def text(self):
        return "\n".join(self.lines) + "\n"


def data_single(raw, ts=123456):
    return frame(0x21, 0, 0xB0, struct.pack(">I", ts) + b"".join(struct.pack(">H", v) for v in raw))


def opened(stale=0):
    s = Script()
    s.out(0x0F)
    for _ in range(stale):
        s.inp(data_single(raw_spectrum(), ts=1))
    s.reply(0x0F)
    s.out(0x13)
    s.reply(0x13, identity())
    s.out(0x01)
    s.reply(0x01, devcfg())
    return s


def started(integration_ms=10.0, averages=1, saturation=1):
    s = opened()
    s.out(0x05, meascfg(integration_ms, averages, saturation))
    s.reply(0x05)
    s.out(0x06, struct.pack(">h", 1))
    s.reply(0x06)
    return s


def case_cycle():
    s = started()
    s.inp(data_single(raw_spectrum()))
    s.out(0xC0)
    return s


def case_averaged():
    s = started(integration_ms=2.5, averages=4, saturation=0)
    raw = raw_spectrum()
    # sums of 4 scans; the averages field (uint16) follows the time stamp
    payload = struct.pack(">IH", 777, 4) + b"".join(struct.pack(">I", 4 * v + (p % 4)) for p, v in enumerate(raw))
    s.inp(frame(0x21, 0, 0xB1, payload))
    s.out(0xC0)
    return s


def case_error_reply():
    s = opened()
    s.out(0x05, meascfg(10.0, 1, 1))
    s.inp(frame(0x21, 0, 0x00, bytes([0x07])))   # invalid integration time
    return s


def case_short_data():
    s = started()
    s.inp(data_single(raw_spectrum()[:-1]))
    return s


def case_oversized_data():
    s = started()
    s.inp(data_single(raw_spectrum() + [5]))
    return s


def case_vanish():
    s = started()
    s.inp(b"", status=-19)       # -ENODEV: the device went away during the exposure
    return s


def case_stale_reset():
    s = opened(stale=2)
    return s


CASES = {
    "cycle": case_cycle, "averaged": case_averaged, "error_reply": case_error_reply,
    "short_data": case_short_data, "oversized_data": case_oversized_data, "vanish": case_vanish,
    "stale_reset": case_stale_reset,
}


def umockdev_text():
    dev = bytes.fromhex("12010002000000409219670601000102030109022000010100" "80FA"
                        "0904000002FF000000" "0705020200020007058602000200")
    h = dev.hex().upper()
    return ("P: /devices/pci0000:00/0000:00:14.0/usb1/1-1\n"
            "N: bus/usb/001/002=%s\n"
            "E: BUSNUM=001\nE: DEVNAME=/dev/bus/usb/001/002\nE: DEVNUM=002\nE: DEVTYPE=usb_device\n"
            "E: DRIVER=usb\nE: ID_BUS=usb\nE: ID_MODEL_ID=0667\nE: ID_VENDOR_ID=1992\nE: ID_SERIAL_SHORT=BRDF0001\n"
            "E: MAJOR=189\nE: MINOR=1\nE: PRODUCT=1992/667/100\nE: SUBSYSTEM=usb\nE: TYPE=0/0/0\n"
            "A: bConfigurationValue=1\nA: bDeviceClass=00\nA: bNumConfigurations=1\nA: bNumInterfaces= 1\n"
            "A: busnum=1\\n\nA: devnum=2\\n\nA: dev=189:1\nA: idProduct=0667\nA: idVendor=1992\n"
            "A: manufacturer=Avantes\nA: product=AvaSpec\nA: serial=BRDF0001\nA: speed=480\n"
            "H: descriptors=%s\n" % (h, h))


def main():
    outdir = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
    os.makedirs(outdir, exist_ok=True)
    with open(os.path.join(outdir, "avaspec.umockdev"), "w") as f:
        f.write(umockdev_text())
    for name, fn in sorted(CASES.items()):
        with open(os.path.join(outdir, name + ".ioctl"), "w") as f:
            f.write(fn().text())


if __name__ == "__main__":
    main()
