#!/usr/bin/python3
"""The laser is off whenever nothing controls it: acquisitiond is SIGKILLed while the laser emits (a long
manual `measure` on the simulated bench) and the time until the simulated laser stops emitting is measured.
1. Keep-alive alone: the driver armed the laser's keep-alive (devices.laser.keepalive_ms, 1000 ms) and the
   daemon's laser thread refreshed it every 250 ms; nobody refreshes it after the kill, so emission must stop within
   1 s (asserted < 1.2 s: 0.2 s for scheduling the simulator's loop on a loaded 2-core machine). Before the
   kill, emission must have lasted well past one keep-alive period (the refresh works); if it stopped, the
   daemon must have logged a late refresh (its laser thread or loop held off the CPU for more than the period:
   the laser then rightly switches off), and the measurement is tried again (3 attempts). A stop later than
   1.2 s counts only if acq-sim (which stands for the laser's own controller, timing on its own processor)
   waited for a CPU during it by at least the excess (its schedstat); then the kill is repeated (3 kills), else
   the test fails (seen: 1.232 s beside `stress-ng --cpu 4` at load 23).
2. The unit's ExecStopPost= helper, `acquisitiond --laser-off`, run right after the kill: emission off when it
   returns, exit 0 (confirmed by the laser's status).
Without the keep-alive the emission stays on after a SIGKILL until a new daemon opens the laser."""
import json
import os
import re
import signal
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402


def emission(b):
    return L.Bench.sim_status(b).get("emission") == "1"


def start_long_measure(b):
    """A manual measurement whose exposure lasts far longer than the test (bench time 600 s)."""
    c = b.client()
    c.n += 1
    c.sock.sendall(('{"cmd":"measure","id":%d,"integration_ms":600000,"averages":1,"power_pct":10}\n' % c.n).encode())
    t0 = time.time()
    while not emission(b):
        if time.time() - t0 > 10:
            raise AssertionError("the laser never emitted; daemon log:\n" + b.daemon_text()[-3000:])
        time.sleep(0.01)
    return c


def emitting(b):
    """A long measurement with the laser emitting, checked to stay on for two keep-alive periods (the daemon's
    refresh works); its client connection."""
    for attempt in range(1, 4):
        mark = len(b.daemon_text())
        c = start_long_measure(b)
        time.sleep(2.0)  # two keep-alive periods: the daemon's refresh keeps it on
        if emission(b):
            return c
        # Emission stopped while the daemon lived. Right only if the daemon's refreshes came late (its laser
        # thread held off the CPU, or its loop silent): the daemon logs every such gap (> 2 refresh
        # periods), skip and failure within a heartbeat (0.25 s). Without one, the refresh does not work.
        time.sleep(0.5)
        late = re.findall(r"laser keep-alive: ([0-9.]+ s between two refreshes[^\n]*|not refreshed[^\n]*|"
                          r"\d+ failure[^\n]*)", b.daemon_text()[mark:])
        assert late, "emission stopped while the daemon was alive and its keep-alive refreshes were on time"
        L.say("attempt %d: the keep-alive expired after a late refresh the daemon logged (%s); again" % (
            attempt, late[0]))
        s = b.client()
        r = s.req("stop")  # the measurement ends (its reply on c), the daemon is free for the next one
        s.close()
        assert r.get("ok"), "stop: %s" % r
        c.read()
        c.close()
    raise AssertionError("three attempts, each with a late keep-alive refresh: the machine starves the laser's "
                         "thread for more than a keep-alive period")


def sim_cpu_wait(pid):
    """Seconds acq-sim's threads have waited for a CPU so far (/proc/PID/task/*/schedstat)."""
    total = 0
    for tid in os.listdir("/proc/%d/task" % pid):
        try:
            with open("/proc/%d/task/%s/schedstat" % (pid, tid)) as f:
                total += int(f.read().split()[1])
        except (OSError, IndexError, ValueError):
            pass
    return total * 1e-9


def time_to_off(b, limit):
    t0 = time.monotonic()
    while emission(b):
        if time.monotonic() - t0 > limit:
            return None
        time.sleep(0.005)
    return time.monotonic() - t0


def ttys(pid):
    """The terminals (pty master or slave) among pid's own open files (not 0-2: inherited from whoever ran us)."""
    out = []
    for fd in os.listdir("/proc/%d/fd" % pid):
        if int(fd) < 3:
            continue
        try:
            t = os.readlink("/proc/%d/fd/%s" % (pid, fd))
        except OSError:
            continue
        if t == "/dev/ptmx" or t.startswith("/dev/pts/"):
            out.append(t)
    return out


def run():
    b = L.Bench(scale=20)
    try:
        b.start_sim()
        b.start_daemon()
        # The laser's line is a Unix socket, not a pty: a pty's bytes wait for a kernel worker thread that a
        # loaded machine kept off the CPU for up to 0.8 s, longer than the keep-alive's margin (sim/sim_laser.c).
        with open(b.ports) as f:
            dev = json.load(f)["laser"]["device"]
        assert dev.startswith("unix:"), "the simulated laser's link is %r, not a Unix socket" % dev
        assert not ttys(b.sim.pid) and not ttys(b.daemon.pid), "a tty on the laser's link: acq-sim %s, daemon %s" % (
            ttys(b.sim.pid), ttys(b.daemon.pid))
        b.ctl("sample white")
        for kill in range(1, 4):
            c = emitting(b)
            w0 = sim_cpu_wait(b.sim.pid)
            b.kill_daemon(signal.SIGKILL)
            c.close()
            dt = time_to_off(b, 5.0)
            waited = sim_cpu_wait(b.sim.pid) - w0
            L.say("keep-alive: emission stopped %s after SIGKILL (acq-sim waited %.3f s for a CPU meanwhile)" % (
                "%.3f s" % dt if dt is not None else "NOT within 5 s", waited))
            assert dt is not None, "emission still on 5 s after the daemon was killed"
            if dt < 1.2:
                break
            # Late. acq-sim stands for the laser's own controller, which keeps its time on its own processor: the
            # expiry may come late only when the simulator itself was kept off the CPU, by at least the excess;
            # then it is measured again (the bound stays).
            assert dt - waited < 1.2, "emission stopped %.3f s after the kill (keep-alive 1 s); acq-sim waited only " \
                "%.3f s for a CPU" % (dt, waited)
            L.say("kill %d: late by the simulator's own wait for a CPU; again" % kill)
            b.start_daemon()
        else:
            raise AssertionError("three kills, each with acq-sim kept off the CPU past the bound: the machine starves "
                                 "the simulated laser")
        assert "keep-alive expired" in open(b.sim_log, errors="replace").read(), "the simulator did not log the expiry"

        b.start_daemon()
        c = start_long_measure(b)
        b.kill_daemon(signal.SIGKILL)
        t0 = time.monotonic()
        r = subprocess.run([L.DAEMON, "--laser-off", "-c", b.conf, "--sim", b.ports], capture_output=True,
                           text=True, timeout=30)
        dt = time.monotonic() - t0
        on = emission(b)
        c.close()
        L.say("ExecStopPost helper: rc %d in %.3f s, emission %s afterwards: %s" % (
            r.returncode, dt, "ON" if on else "off", (r.stdout + r.stderr).strip()))
        assert r.returncode == 0, "acquisitiond --laser-off failed: " + r.stdout + r.stderr
        assert not on, "emission still on after acquisitiond --laser-off"
    finally:
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


L.main(run)
