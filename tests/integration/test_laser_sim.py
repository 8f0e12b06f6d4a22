#!/usr/bin/python3
"""acq-sim serves the laser on the link named in its ports file, by default a Unix socket ("unix:PATH"), with
sim.laser.link: pty a pty, and it speaks the line protocol of drivers/laser_serial.c on both: ID?, EMISSION
ON/OFF, POWER, POWER?, STATUS?, errors. An acq-sim that does not start is a failure."""
import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import termios
import time
import tty

build, src = os.environ["ACQ_BUILD"], os.environ["ACQ_SRC"]
# What is tested is the protocol, not how fast a process runs: on a saturated machine (make check beside other
# work) acq-sim's start and its replies can wait seconds for a CPU. The bounds only end a test that would hang:
# a reply that never comes, a ports file never written (the process alive: an exit fails at once).
REPLY_S = 20.0
START_S = 60.0


def ask(fd, cmd, timeout=REPLY_S):
    os.write(fd, (cmd + "\n").encode())
    buf = b""
    end = time.monotonic() + timeout
    while not buf.endswith(b"\n"):
        left = end - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            sys.exit("no reply to %r (got %r)" % (cmd, buf))
        buf += os.read(fd, 256)
    return buf.decode().rstrip("\r\n")


def expect(fd, cmd, want):
    got = ask(fd, cmd)
    if got != want:
        sys.exit("%r: expected %r, got %r" % (cmd, want, got))


def protocol(fd):
    idline = ask(fd, "ID?")
    if len(idline.split()) != 4 or not idline.startswith("ID "):
        sys.exit("bad identity %r" % idline)
    expect(fd, "STATUS?", "STATUS emission=0 interlock=1 fault=0")
    expect(fd, "POWER 12.5", "OK")
    expect(fd, "POWER?", "POWER 12.5")
    expect(fd, "EMISSION ON", "OK")
    expect(fd, "STATUS?", "STATUS emission=1 interlock=1 fault=0")
    expect(fd, "POWER 101", "ERR 2 power must be a number in [0, 100]")
    expect(fd, "FLY", "ERR 1 unknown command")
    expect(fd, "X" * 300, "ERR 5 line too long")
    expect(fd, "EMISSION OFF", "OK")
    expect(fd, "STATUS?", "STATUS emission=0 interlock=1 fault=0")


def serve(tmp, link):
    """acq-sim on config/bench-sim.yaml with sim.laser.link = link (None: the default); its laser device."""
    cfg = open(os.path.join(src, "config/bench-sim.yaml")).read()
    if link:
        assert "\nsim:\n" in cfg and "\n  laser:" not in cfg[cfg.index("\nsim:\n"):]
        cfg = cfg.replace("\nsim:\n", "\nsim:\n  laser: {link: %s}\n" % link, 1)
    path = os.path.join(tmp, "bench-%s.yaml" % (link or "default"))
    with open(path, "w") as f:
        f.write(cfg)
    ports = os.path.join(tmp, "ports-%s.json" % (link or "default"))
    sim = subprocess.Popen([os.path.join(build, "acq-sim"), "-c", path, "--ports-file", ports,
                            "--seed", os.environ.get("ACQ_SEED", "1")], stderr=subprocess.PIPE, text=True)
    end = time.monotonic() + START_S
    while not os.path.exists(ports):
        if sim.poll() is not None:
            sys.exit("acq-sim exited %d: %s" % (sim.returncode, sim.stderr.read()))
        if time.monotonic() > end:
            stop(sim)
            sys.exit("acq-sim wrote no ports file in %g s" % START_S)
        time.sleep(0.05)
    with open(ports) as f:
        return sim, json.load(f)["laser"]["device"]


def stop(sim):
    if sim.poll() is None:
        sim.send_signal(signal.SIGTERM)
        try:
            sim.wait(timeout=5)
        except subprocess.TimeoutExpired:
            sim.kill()
            sim.wait()


with tempfile.TemporaryDirectory() as tmp:
    # the default link: a Unix socket ("unix:PATH"), no tty in the way (sim/sim_laser.c)
    sim, dev = serve(tmp, None)
    try:
        if not dev.startswith("unix:"):
            sys.exit("the simulated laser's default link is %r, expected a Unix socket (unix:PATH)" % dev)
        s = socket.socket(socket.AF_UNIX)
        s.settimeout(REPLY_S)
        s.connect(dev[5:])
        protocol(s.fileno())
        s.close()
        print("laser on %s: protocol ok" % dev)
    finally:
        stop(sim)
    # sim.laser.link: pty, for terminal programs and the driver's termios transport
    sim, dev = serve(tmp, "pty")
    try:
        fd = os.open(dev, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        termios.tcflush(fd, termios.TCIFLUSH)
        protocol(fd)
        os.close(fd)
        print("laser on %s: protocol ok" % dev)
    finally:
        stop(sim)
