#!/usr/bin/python3
"""acq-sim leaves no socket files in /tmp: its default sockets (/tmp/acq-sim.<pid>.<service>.sock) are removed
when it stops on SIGTERM or SIGINT, and at start it removes those of simulators that are gone (SIGKILLed: no such
process and nobody listening), keeping those of a running process and files that are not sockets."""
import os
import signal
import socket
import subprocess

import simlib
from simlib import SimTest

T = SimTest("acq-sim-sockets.")
check = T.check
CFG = os.path.join(simlib.SRC, "config", "bench-sim.yaml")


def dead_pid():
    """A pid with no process now (a child that has exited and been reaped)."""
    p = subprocess.Popen(["true"])
    p.wait()
    return p.pid


def stale_socket(path):
    """A socket file nobody listens on, as a SIGKILLed simulator leaves it."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(path)
    s.close()


def sock_paths(pid):
    return sorted("/tmp/" + n for n in os.listdir("/tmp") if n.startswith("acq-sim.%d." % pid) and n.endswith(".sock"))


def run_and_stop(sig, tag):
    p, ports = T.start(["-c", CFG, "--time-scale", "10", "--seed", simlib.SEED], T.path(tag + ".ports.json"))
    mine = sock_paths(p.pid)
    check(len(mine) == 3, "acq-sim %d serves on its three default sockets: %s" % (p.pid, mine))
    check(ports["control"]["socket"] in mine and ports["spectrometer"]["socket"] in mine and
          "unix:" + [m for m in mine if m.endswith(".laser.sock")][0] == ports["laser"]["device"],
          "the ports file names them")
    p.send_signal(sig)
    rc = p.wait(10)
    check(rc == 0, "acq-sim exits 0 on %s (%s)" % (signal.Signals(sig).name, rc))
    left = [m for m in mine if os.path.exists(m)]
    check(not left, "no socket file left after %s: %s" % (signal.Signals(sig).name, left))
    return p


try:
    gone = dead_pid()
    stale = ["/tmp/acq-sim.%d.%s.sock" % (gone, s) for s in ("spectro", "laser", "control")]
    for path in stale:
        if os.path.exists(path):
            os.unlink(path)
        stale_socket(path)
    # A socket of a running process (this test) and a regular file of a dead pid: not the simulator's to remove.
    alive = "/tmp/acq-sim.%d.spectro.sock" % os.getpid()
    stale_socket(alive)
    notsock = "/tmp/acq-sim.%d.spectro.sock" % dead_pid()
    with open(notsock, "w") as f:
        f.write("not a socket\n")
    p = run_and_stop(signal.SIGTERM, "term")
    left = [s for s in stale if os.path.exists(s)]
    check(not left, "the stale sockets of dead pid %d were removed at start: %s" % (gone, left))
    check(os.path.exists(alive), "the socket file of a running process (pid %d) is kept" % os.getpid())
    check(os.path.exists(notsock), "a regular file with a socket's name is kept")
    run_and_stop(signal.SIGINT, "int")
    # SIGKILL leaves them (nothing runs), and the next start removes them.
    k, _ = T.start(["-c", CFG, "--time-scale", "10", "--seed", simlib.SEED], T.path("kill.ports.json"))
    killed = sock_paths(k.pid)
    k.kill()
    k.wait()
    check(len(killed) == 3 and all(os.path.exists(m) for m in killed), "SIGKILL leaves its 3 socket files")
    run_and_stop(signal.SIGTERM, "after-kill")
    left = [m for m in killed if os.path.exists(m)]
    check(not left, "the next start removed the SIGKILLed simulator's sockets: %s" % left)
    for path in (alive, notsock):
        if os.path.exists(path):
            os.unlink(path)
    T.finish(0, "PASS")
finally:
    T.cleanup()
