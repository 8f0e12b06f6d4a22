#!/usr/bin/python3
"""acq-sim serves the laser on a pty named in its ports file, and it speaks the line protocol of
drivers/laser_serial.c there: ID?, EMISSION ON/OFF, POWER, POWER?, STATUS?, errors. An acq-sim that does not
start is a failure."""
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import termios
import time
import tty

build, src = os.environ["ACQ_BUILD"], os.environ["ACQ_SRC"]


def ask(fd, cmd, timeout=2.0):
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


with tempfile.TemporaryDirectory() as tmp:
    ports = os.path.join(tmp, "ports.json")
    sim = subprocess.Popen([os.path.join(build, "acq-sim"), "-c", os.path.join(src, "config/bench-sim.yaml"),
                            "--ports-file", ports, "--seed", os.environ.get("ACQ_SEED", "1")],
                           stderr=subprocess.PIPE, text=True)
    try:
        end = time.monotonic() + 10
        while not os.path.exists(ports):
            if sim.poll() is not None:
                err = sim.stderr.read()
                sys.exit("acq-sim exited %d: %s" % (sim.returncode, err))
            if time.monotonic() > end:
                sys.exit("acq-sim wrote no ports file in 10 s")
            time.sleep(0.05)
        with open(ports) as f:
            dev = json.load(f)["laser"]["device"]
        fd = os.open(dev, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(fd)
        termios.tcflush(fd, termios.TCIFLUSH)
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
        os.close(fd)
        print("laser on %s: protocol ok" % dev)
    finally:
        if sim.poll() is None:
            sim.send_signal(signal.SIGTERM)
            try:
                sim.wait(timeout=5)
            except subprocess.TimeoutExpired:
                sim.kill()
                sim.wait()
