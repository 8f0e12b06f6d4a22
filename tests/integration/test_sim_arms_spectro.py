#!/usr/bin/python3
"""The spectrometer sees the arms' ACTUAL positions: the detector arm is moved over real Modbus (Debian's
mbpoll, the register map of config/bench-sim.yaml: one FC16 block at 0x58 per move, actual position at 0xCC,
int32 big-endian words, 100 counts per degree). A move requested into the blind zone next to the laser arm
stops where the arm bodies touch (collision alarm): the spectrum is that of the actual position (lit, no
occlusion), not of the requested one (dark). After an alarm reset and a move to 40 deg, the white reference's
counts scale with cos(theta_o) between the two actual positions. Skips (77) only when mbpoll is not installed;
an acq-sim that does not start is a failure."""
import math
import os
import re
import shutil
import socket
import struct
import subprocess
import time

from simlib import SEED, SRC, Ctl, SimTest

T = SimTest("acq-sim-arms.")
check, finish = T.check, T.finish
if not shutil.which("mbpoll"):
    T.finish(77, "skip: mbpoll not installed (make deps installs it)")
ctl_path = T.path("ctl.sock")
proc, pj = T.start(["-c", os.path.join(SRC, "config/bench-sim.yaml"), "--time-scale", "50", "--seed", SEED,
                    "--control", ctl_path], T.path("ports.json"))
port = pj["detector_arm"]["port"]
control = Ctl(ctl_path)


def mb(*args, values=()):
    r = subprocess.run(["mbpoll", "-m", "tcp", "-p", str(port), "-a", "1", "-0", "-B", *args, "127.0.0.1", *values],
                       capture_output=True, text=True, timeout=10)
    return r.stdout


def actual_counts():
    m = re.search(r"^\[204\]:\s*(-?\d+)", mb("-r", "204", "-t", "4:int", "-c", "1", "-1"), re.M)
    return int(m.group(1)) if m else None


def move_detector_theta(deg):
    """Request a move; return the actual position (degrees) once the arm has stopped."""
    target = int(round(deg * 100))
    out = mb("-r", "88", "-t", "4:int", values=("0", "1", str(target), "2000", "6000", "6000", "1000", "1"))
    check("Written 8 references" in out, f"move block written (theta {deg} deg)")
    last, still = None, 0
    for _ in range(500):
        time.sleep(0.02)
        a = actual_counts()
        still = still + 1 if a is not None and a == last else 0
        last = a
        if still >= 10:
            return a / 100.0
    finish(1, f"FAIL: detector arm still moving after 10 s (at {last})")


sp = socket.socket(socket.AF_UNIX)
sp.settimeout(10)
sp.connect(pj["spectrometer"]["socket"])
T.recv(sp, 16 + 36)


def measure():
    sp.sendall(struct.pack("<IHHII", 0x4D495341, 1, 2, 9, 16) + struct.pack("<dII", 20.0, 4, 0))
    typ = struct.unpack("<IHHII", T.recv(sp, 16))
    p = T.recv(sp, typ[4])
    npix, occ = struct.unpack_from("<II", p, 28)[0], struct.unpack_from("<I", p, 36)[0]
    return sum(struct.unpack_from(f"<{npix}d", p, 48)[4:]) / (npix - 4), occ


control("sample white")
control("laser on 100")
status = control("status")
lt = float(re.search(r"laser\.theta=(-?[\d.]+)", status).group(1))
check(abs(lt) < 0.5, f"laser arm parked near the zenith ({lt})")
at = move_detector_theta(3.0)  # 3 deg from the laser arm: requested inside the blind zone
print(f"requested 3 deg, stopped at {at} deg")
check(at > 7.5, "the arm stopped before the blind zone (the bodies touch first)")
c_near, occ = measure()
st = control("status")
check(abs(float(re.search(r"detector\.theta=(-?[\d.]+)", st).group(1)) - at) < 0.05, f"world has the actual position: {st}")
check(occ == 0 and c_near > 3000, f"spectrum of the actual position: no occlusion, light ({c_near:.0f} counts)")
mb("-r", "125", "-t", "4", values=("128",))  # ALM-RST
at2 = move_detector_theta(40.0)
check(abs(at2 - 40) < 0.1, f"after the alarm reset the arm moves (at {at2} deg)")
c_far, occ = measure()
ratio, want = (c_far - 1500) / (c_near - 1500), math.cos(math.radians(at2)) / math.cos(math.radians(at))
print(f"white reference above bias: {c_near - 1500:.0f} at {at} deg, {c_far - 1500:.0f} at {at2} deg: ratio {ratio:.3f}, "
      f"cos ratio {want:.3f}")
check(abs(ratio / want - 1) < 0.03, "counts follow cos(theta_o) of the actual positions (Lambertian reference)")
finish(0, "all passed")
