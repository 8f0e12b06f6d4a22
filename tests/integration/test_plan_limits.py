#!/usr/bin/python3
"""The `plan` command's bounds (daemon/commands_plan.c): its child's work is bounded in CPU time (PLAN_CPU_S, 10 s;
test_client_limits.py's huge plan is stopped by it), its wait only by a generous real-time bound (PLAN_DEADLINE_S,
30 s). A child that gets no CPU for a while is not killed early: at load 13 a nice +10 plan of 0.1 s of CPU
waited more than the 10 real seconds that were its only bound until session 14 (test_acqctl.py failed). Here the
job helper that forks the plan's child is stopped (SIGSTOP) for 12 s, as a loaded machine would starve it, then
let go: the plan must be answered, planned. With the 10 s real-time bound it failed: "plan: not planned within
10 s, the daemon's bound"."""
import json
import os
import signal
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import acqtest as A  # noqa: E402

PLAN = ("name: small\nincidence:\n  theta_deg: [20, 45]\nobservation:\n  theta_deg: [30, 60]\n"
        "  phi_deg: [0, 90, 180, 270]\nintegration: {mode: fixed, ms: 20}\naverages: 1\nblind_points: drop\n")


def helper_pid(daemon_pid):
    """The job helper: the daemon's child whose command line says --job-helper (None when not running)."""
    for p in os.listdir("/proc"):
        if not p.isdigit():
            continue
        try:
            stat = open("/proc/%s/stat" % p).read()
            cmd = open("/proc/%s/cmdline" % p, "rb").read().split(b"\0")
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        if ppid == daemon_pid and b"--job-helper" in cmd:
            return int(p)
    return None


def main():
    with A.Daemon() as d:
        d.start()
        c = d.client()
        r = c.req("plan", plan=PLAN)  # starts the helper
        A.check("plan" in r.get("result", r), "the plan was not planned: %s" % r)
        hp = helper_pid(d.proc.pid)
        A.check(hp is not None, "no job helper under the daemon (pid %d)" % d.proc.pid)
        os.kill(hp, signal.SIGSTOP)
        try:
            t0 = time.monotonic()
            c.send_raw((json.dumps({"cmd": "plan", "id": 2, "plan": PLAN}) + "\n").encode())
            time.sleep(12)
        finally:
            os.kill(hp, signal.SIGCONT)
        c.sock.settimeout(60)
        r = c.read()
        dt = time.monotonic() - t0
        print("a plan whose helper was stopped for 12 s: answered after %.1f s: %s" % (
            dt, r.get("error", {}).get("message", "planned")))
        A.check("error" not in r, "the starved plan was killed: %s" % r.get("error"))
        A.check("plan" in r.get("result", r), "no plan in the reply: %s" % r)
        c.close()
    print("ok: a starved plan is answered")


if __name__ == "__main__":
    A.run_main(main)
