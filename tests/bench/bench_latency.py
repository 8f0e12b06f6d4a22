#!/usr/bin/python3
"""bench_latency: does device I/O block the daemon's loop? Socket round-trip of `status` requests while one
device times out (issue 14 item 1: p99 < 5 ms under `acqctl watch` + 5 clients polling status).

The simulated bench (acq-sim + acquisitiond --sim, tests/integration/sweeplib.py) runs three scenarios, each for
BENCH_LATENCY_S seconds (default 15):
  baseline      all devices answer; an operator panel polls `devices` every second (reads every axis and the
                laser); no sweep.
  timeout-idle  the detector arm's controller stops answering (acq-sim `fault modbus-timeout detector on`); the
                panel keeps polling `devices`; no sweep.
  timeout-sweep a sweep runs; after 2 s the detector arm stops answering (the executor faults, suspends and
                retries the device with backoff); the panel keeps polling.
Load in every scenario: `acqctl watch` (event stream) and 5 client processes each sending `status` in a loop
(10 ms apart), timing each round trip with time.perf_counter(). Printed per scenario: count, p50, p99 and max
of the status round trips (ms), the panel's `devices` round trips, and whether p99 < 5 ms. Results also go to
$ACQ_BENCH_OUT/latency.txt. Exit status 0 whatever the figures (a benchmark reports; it does not gate)."""
import multiprocessing as mp
import os
import socket
import json
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integration"))
import sweeplib as L  # noqa: E402

DURATION = float(os.environ.get("BENCH_LATENCY_S", "15"))
NCLIENTS = 5
BOUND_MS = 5.0
PLAN = """name: bench-latency
incidence: {theta_deg: [15, 45]}
observation: {theta_deg: [10, 30, 50, 70], phi_deg: [0, 90, 180, 270]}
integration: {mode: auto, target_peak: 0.7, estimate_ms: 20, max_ms: 1000}
averages: 2
blind_points: drop
"""


def rtt_loop(sock_path, cmd, period, stop_at, q):
    """A client process: `cmd` every `period` s until stop_at (time.time()); puts the round trips (s)."""
    c = L.Client(sock_path, 30)
    out = []
    try:
        while time.time() < stop_at:
            t0 = time.perf_counter()
            r = c.req(cmd)
            dt = time.perf_counter() - t0
            if not r.get("ok", True) and "error" in r:
                raise AssertionError("%s: %s" % (cmd, r))
            out.append(dt)
            time.sleep(period)
    finally:
        c.close()
    q.put((cmd, out))


def pct(v, p):
    if not v:
        return float("nan")
    v = sorted(v)
    k = min(len(v) - 1, max(0, int(round(p / 100.0 * (len(v) - 1)))))
    return v[k]


def scenario(name, setup):
    b = L.Bench(scale=40.0)
    try:
        b.start_sim()
        b.start_daemon()
        watch = subprocess.Popen([os.path.join(L.BUILD, "acqctl"), "-s", b.sock, "watch"], stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL)
        time.sleep(0.3)
        setup(b)
        stop_at = time.time() + DURATION
        q = mp.Queue()
        procs = [mp.Process(target=rtt_loop, args=(b.sock, "status", 0.01, stop_at, q)) for _ in range(NCLIENTS)]
        procs.append(mp.Process(target=rtt_loop, args=(b.sock, "devices", 1.0, stop_at, q)))
        for p in procs:
            p.start()
        got = [q.get(timeout=DURATION + 120) for _ in procs]
        for p in procs:
            p.join()
        watch.terminate()
        watch.wait(5)
        status = [x for cmd, v in got if cmd == "status" for x in v]
        devices = [x for cmd, v in got if cmd == "devices" for x in v]
        ms = lambda x: 1e3 * x
        line = ("%-14s status n=%-6d p50=%8.3f ms  p99=%9.3f ms  max=%9.3f ms  %s | devices n=%-3d p50=%8.1f ms "
                "max=%8.1f ms" % (name, len(status), ms(pct(status, 50)), ms(pct(status, 99)), ms(max(status or [0])),
                                  "p99<5ms" if ms(pct(status, 99)) < BOUND_MS else "p99>=5ms", len(devices),
                                  ms(pct(devices, 50)), ms(max(devices or [0]))))
        return line
    finally:
        b.cleanup()


def timeout_idle(b):
    b.ctl("fault modbus-timeout detector on")


def timeout_sweep(b):
    L.start_sweep(b, PLAN, "bench-latency", white_first=False)
    time.sleep(2)
    b.ctl("fault modbus-timeout detector on")


def main():
    lines = ["bench_latency: %d status clients (10 ms apart) + acqctl watch + devices panel (1 s), %g s per scenario, "
             "load average %s" % (NCLIENTS, DURATION, open("/proc/loadavg").read().split()[0])]
    print(lines[0], flush=True)
    for name, setup in (("baseline", lambda b: None), ("timeout-idle", timeout_idle), ("timeout-sweep", timeout_sweep)):
        try:
            line = scenario(name, setup)
        except (L.Skip, AssertionError) as e:
            line = "%-14s not measured: %s" % (name, e)
        print(line, flush=True)
        lines.append(line)
    # the machine's load decides how long a ready process waits for a core: say it with the figures
    lines.append("load average at the end %s" % open("/proc/loadavg").read().split()[0])
    print(lines[-1], flush=True)
    out = os.environ.get("ACQ_BENCH_OUT")
    if out:
        with open(os.path.join(out, "latency.txt"), "w") as f:
            f.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
