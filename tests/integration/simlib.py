"""simlib: helpers for the tests that run acq-sim as a process: the prologue (the seed printed, acq-sim built or
the test fails), a scratch folder, acq-sim started with a ports file, checks that on failure stop every acq-sim
started and remove the folder, and the control and spectrometer sockets' plain framing."""
import json
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time

BUILD = os.environ.get("ACQ_BUILD", "build")
SRC = os.environ.get("ACQ_SRC", ".")
SEED = os.environ.get("ACQ_SEED", "1")
SIM = os.path.join(BUILD, "acq-sim")


class SimTest:
    """One test's state: prints ACQ_SEED, fails (exit 1) when acq-sim is not built, makes the scratch folder."""

    def __init__(self, prefix):
        print(f"ACQ_SEED={SEED}")
        if not os.access(SIM, os.X_OK):
            sys.exit(f"FAIL: {SIM} not built")
        self.tmp = tempfile.mkdtemp(prefix=prefix)
        self.procs = []

    def path(self, name):
        return os.path.join(self.tmp, name)

    def cleanup(self):
        """Stop every acq-sim started (SIGTERM, SIGKILL after 5 s) and remove the scratch folder."""
        for p in self.procs:
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(5)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
        shutil.rmtree(self.tmp, ignore_errors=True)

    def finish(self, code, msg):
        print(msg)
        self.cleanup()
        sys.exit(code)

    def check(self, cond, what):
        if not cond:
            self.finish(1, "FAIL: " + what)
        print("ok:", what)

    def start(self, args, ports, timeout=10):
        """acq-sim with args and --ports-file ports; waits for the ports file: (process, its JSON). A process that
        exits first, or no file within timeout seconds, fails the test with acq-sim's stderr."""
        p = subprocess.Popen([SIM, *args, "--ports-file", ports], stderr=subprocess.PIPE, text=True)
        self.procs.append(p)
        end = time.monotonic() + timeout
        while not os.path.exists(ports):
            if p.poll() is not None:
                self.finish(1, "FAIL: acq-sim exited: " + p.stderr.read().strip())
            if time.monotonic() > end:
                self.finish(1, f"FAIL: no ports file in {timeout} s")
            time.sleep(0.02)
        with open(ports) as f:
            return p, json.load(f)

    def recv(self, s, n):
        """Exactly n bytes from socket s; the peer closing first fails the test."""
        b = recv_exact(s, n)
        if b is None:
            self.finish(1, "FAIL: spectrometer closed the connection")
        return b


def recv_exact(s, n):
    """Exactly n bytes from socket s, or None when the peer closes first."""
    b = b""
    while len(b) < n:
        c = s.recv(n - len(b))
        if not c:
            return None
        b += c
    return b


class Ctl:
    """acq-sim's control socket: a call sends one command line and returns the reply line."""

    def __init__(self, path):
        self.s = socket.socket(socket.AF_UNIX)
        self.s.connect(path)
        self.f = self.s.makefile("rw")

    def __call__(self, line):
        self.f.write(line + "\n")
        self.f.flush()
        return self.f.readline().strip()
