#!/usr/bin/python3
"""The simulated laser (its line protocol, on its default link: a Unix socket) and the simulated spectrometer
share one world: counts follow EMISSION and POWER set over the laser's link, and an interlock opened on the control socket darkens the
spectrum and is reported by the laser. Arm services are left out (positions set with `pose`)."""
import os
import select
import socket
import struct
import time

from simlib import SEED, Ctl, SimTest

T = SimTest("acq-sim-laser.")
check, finish = T.check, T.finish


def ask(fd, cmd, timeout=3.0):
    os.write(fd, (cmd + "\n").encode())
    buf, end = b"", time.monotonic() + timeout
    while not buf.endswith(b"\n"):
        left = end - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            finish(1, f"FAIL: no reply to {cmd!r} (got {buf!r})")
        buf += os.read(fd, 256)
    return buf.decode().rstrip("\r\n")


def measure(s, it, avg):
    s.sendall(struct.pack("<IHHII", 0x4D495341, 1, 2, 7, 16) + struct.pack("<dII", it, avg, 0))
    magic, ver, typ, seq, ln = struct.unpack("<IHHII", T.recv(s, 16))
    p = T.recv(s, ln)
    check(typ == 0x82, "spectrum received")
    npix = struct.unpack_from("<I", p, 28)[0]
    counts = struct.unpack_from(f"<{npix}d", p, 48)
    return sum(counts[4:]) / (npix - 4)


cfg, spec, ctl_path = (T.path(n) for n in ("bench.yaml", "spec.sock", "ctl.sock"))
with open(cfg, "w") as f:
    f.write(f"devices:\n  spectrometer: {{backend: sim, socket: {spec}}}\n  laser: {{}}\nsim:\n  sample: white\n")
proc, pj = T.start(["-c", cfg, "--disable", "laser_arm,detector_arm", "--time-scale", "100", "--seed", SEED,
                    "--control", ctl_path], T.path("ports.json"))
check("laser" in pj and "device" in pj["laser"] and "spectrometer" in pj, f"ports file lists laser and spectrometer: {pj}")
check(pj["laser"]["device"].startswith("unix:"), "the laser's default link is a Unix socket: %s" % pj["laser"])
laser = socket.socket(socket.AF_UNIX)
laser.settimeout(10)
laser.connect(pj["laser"]["device"][5:])
fd = laser.fileno()
control = Ctl(ctl_path)


sp = socket.socket(socket.AF_UNIX)
sp.settimeout(10)
sp.connect(spec)
T.recv(sp, 16 + 36)  # HELLO
check(control("pose 20 40 150").startswith("ok"), "pose")
dark = measure(sp, 20, 4)
check(ask(fd, "POWER 50") == "OK" and ask(fd, "EMISSION ON") == "OK", "laser: POWER 50, EMISSION ON")
s50 = measure(sp, 20, 4) - dark
check(ask(fd, "POWER 25") == "OK", "laser: POWER 25")
s25 = measure(sp, 20, 4) - dark
print(f"signal above dark: 50 % {s50:.0f}, 25 % {s25:.0f} counts (ratio {s25 / s50:.3f})")
check(s50 > 2000 and abs(s25 / s50 - 0.5) < 0.02, "counts follow the laser's power")
check(control("fault laser-interlock on").startswith("ok"), "interlock opened on the control socket")
locked = measure(sp, 20, 4) - dark
status = ask(fd, "STATUS?")
check(abs(locked) < 3 and "interlock=0" in status and "emission=0" in status,
      f"interlock: no light ({locked:.1f}), laser reports it: {status}")
check(ask(fd, "EMISSION ON").startswith("ERR"), "emission refused while the interlock is open")
control("fault laser-interlock off")
check(ask(fd, "EMISSION ON") == "OK" and measure(sp, 20, 4) - dark > 0.9 * s25, "interlock closed: light again")
laser.close()
finish(0, "all passed")
