#!/usr/bin/python3
"""No client can stall or starve the daemon (issue 15): real processes under several uids against one daemon.
- An unlisted user gets the daemon's refusal from acqctl (rc 1), never "Broken pipe" (rc 2), 21 times out of 21.
- Per-user limit: a 33rd connection of one uid is refused with "too many clients", and acqctl shows that
  refusal (rc 1), not "unsupported protocol version"; other users are not affected.
- Slots kept for controllers: with the observers' share of the table full, observers are refused, root
  (a controller) still gets `status`.
- A huge plan (10 x 1000 Fibonacci points; 31 s on the loop before) leaves `status` answering in < 0.5 s and
  is ended by the planner's bounds (daemon.plan_cpu_s, set to 1 s of CPU here; 30 s real; test_plan_limits.py).
- Clients pipelining requests without reading their replies: the daemon's RSS stays < 64 MB and a
  well-behaved client is answered in < 0.5 s.
- The TCP port is off by default; when configured it gives observers no configuration text."""
import json
import os
import pwd
import socket
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import acqtest as A  # noqa: E402

HELPER = r'''
import json, os, socket, sys, time
path, n = sys.argv[1], int(sys.argv[2])
socks = []
for i in range(n):
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.connect(path)
    socks.append(s)
time.sleep(0.5)
ok, refused = 0, []
for s in socks:
    s.setblocking(False)
    data = b""
    try:
        while True:
            d = s.recv(65536)
            if not d:
                break
            data += d
    except BlockingIOError:
        pass
    lines = [json.loads(l) for l in data.split(b"\n") if l.strip()]
    errs = [l for l in lines if l.get("ok") is False]
    if errs:
        refused.append(errs[0]["error"]["message"])
    elif lines:
        ok += 1
print(json.dumps({"ok": ok, "refused": refused}), flush=True)
sys.stdin.read()
'''


def as_user(name):
    pw = pwd.getpwnam(name)
    def drop():
        os.setgid(pw.pw_gid)
        os.setuid(pw.pw_uid)
    return drop


def hold(d, user, n):
    """A process of `user` holding n connections; returns (process, {"ok": k, "refused": [messages]})."""
    p = subprocess.Popen([sys.executable, "-c", HELPER, d.sock, str(n)], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True, preexec_fn=as_user(user))
    line = p.stdout.readline()
    A.check(line, "helper of %s died" % user)
    return p, json.loads(line)


def rss_mb(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return -1


def latency(d):
    c = d.client()
    t0 = time.monotonic()
    r = c.req("status")
    dt = time.monotonic() - t0
    c.close()
    A.check(r.get("ok"), "status refused: %s" % r)
    return dt


def main():
    if os.geteuid() != 0:
        print("needs root to act as several users")
        sys.exit(77)
    # ASan keeps freed memory in quarantine (256 MB by default): the RSS bound would count every allocation
    # ever made instead of the live ones; a small quarantine keeps it meaningful under the sanitizer.
    env = dict(os.environ, ASAN_OPTIONS=os.environ.get("ASAN_OPTIONS", "") +
               ":quarantine_size_mb=1:thread_local_quarantine_size_kb=64")
    # plan_cpu_s 1: the huge plan below is ended by its CPU bound (its RLIMIT_CPU) rather than by waiting out the
    # default 10 s of CPU, which at nice +10 beside two busy processes takes the 30 s deadline instead
    d = A.Daemon(extra_daemon="  observers: [daemon, bin, sys, sync]\n  plan_cpu_s: 1\n").start(env=env)
    helpers = []
    try:
        # 1. an unlisted user: the refusal, not a broken pipe
        bad = 0
        for i in range(21):
            r = subprocess.run([A.ACQCTL, "-s", d.sock, "status"], capture_output=True, text=True, timeout=20,
                               preexec_fn=as_user("nobody"))
            if r.returncode != 1 or "neither a controller nor an observer" not in r.stderr:
                bad += 1
                print("unlisted user: rc %d: %s" % (r.returncode, r.stderr.strip()))
        A.check(bad == 0, "%d of 21 unlisted-user runs did not show the refusal" % bad)
        print("unlisted user: refusal shown 21/21 (rc 1)")

        # 2. per-user limit, and acqctl shows "too many clients"
        p, res = hold(d, "daemon", 40)
        helpers.append(p)
        print("uid daemon, 40 connections: %d served, %d refused (%s)" % (
            res["ok"], len(res["refused"]), res["refused"][:1]))
        A.check(res["ok"] == 32 and len(res["refused"]) == 8, "per-user limit not 32: %s" % res)
        A.check(all("too many clients" in m for m in res["refused"]), "refusals: %s" % res["refused"])
        r = subprocess.run([A.ACQCTL, "-s", d.sock, "status"], capture_output=True, text=True, timeout=20,
                           preexec_fn=as_user("daemon"))
        print("acqctl as uid daemon at its limit: rc %d: %s" % (r.returncode, r.stderr.strip()))
        A.check(r.returncode == 1 and "too many clients" in r.stderr and "protocol version" not in r.stderr,
                "acqctl at the limit: rc %d %r" % (r.returncode, r.stderr))
        r = subprocess.run([A.ACQCTL, "-s", d.sock, "status"], capture_output=True, text=True, timeout=20,
                           preexec_fn=as_user("bin"))
        A.check(r.returncode == 0, "another observer refused: %s" % r.stderr)

        # 3. slots kept for controllers: observers fill 112 of 128
        for user in ("bin", "sys"):
            p, res = hold(d, user, 32)
            helpers.append(p)
            A.check(res["ok"] == 32, "%s: %s" % (user, res))
        p, res = hold(d, "sync", 32)
        helpers.append(p)
        print("uid sync after 96 observer connections: %d served, %d refused (%s)" % (
            res["ok"], len(res["refused"]), res["refused"][:1]))
        A.check(res["ok"] == 16 and all("kept for controllers" in m for m in res["refused"]), "reserve: %s" % res)
        r = A.acqctl(d.sock, "status")
        A.check(r.returncode == 0, "root refused with the observers' slots full: %s" % r.stderr)
        print("root (controller) with the observers' share full: status rc 0")
        for p in helpers:
            p.stdin.close()
            p.wait(10)
        helpers = []

        # 4. a huge plan does not stall the loop; 5. non-reading pipelining clients stay bounded
        plan = ("name: huge\nincidence:\n  theta_deg: [0, 8, 16, 24, 32, 40, 48, 56, 64, 72]\n"
                "observation:\n  fibonacci: {count: 1000, max_theta_deg: 85}\nintegration: {mode: fixed, ms: 20}\n"
                "averages: 1\nblind_points: move\n")
        pc = d.client()
        t_plan = time.monotonic()
        pc.send_raw((json.dumps({"cmd": "plan", "id": 9, "plan": plan}) + "\n").encode())
        floods = []
        req = b'{"cmd":"status","id":1}\n' * 4096
        for i in range(20):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.connect(d.sock)
            s.setblocking(False)
            floods.append(s)
        t_end = time.monotonic() + 4
        sent = 0
        lat = []
        while time.monotonic() < t_end:
            for s in floods:
                try:
                    sent += s.send(req)
                except (BlockingIOError, BrokenPipeError, ConnectionResetError):
                    pass
            lat.append(latency(d))
        rss = rss_mb(d.proc.pid)
        print("20 non-reading clients sent %.1f MB of requests; daemon RSS %.1f MB; status latency max %.3f s "
              "(%d samples) while a huge plan is computed" % (sent / 1e6, rss, max(lat), len(lat)))
        A.check(rss < 64, "daemon RSS %.1f MB with non-reading clients" % rss)
        A.check(max(lat) < 0.5, "status took %.3f s during the flood and the plan" % max(lat))
        pc.sock.settimeout(60)
        r = pc.read()
        dt = time.monotonic() - t_plan
        print("huge plan answered after %.1f s: %s" % (dt, r.get("error", {}).get("message", "planned")))
        # bounded by its 1 s of CPU (daemon.plan_cpu_s above; at nice +10 on a loaded machine that is more real
        # seconds), at worst by the 30 s real-time bound (daemon.plan_deadline_s; a 120 s bound outlived this
        # read's 60 s at CI's load, session 14). The CPU bound is what ends it on a machine that is not starved.
        msg = r.get("error", {}).get("message", "")
        A.check(dt < 40, "the plan was not bounded: %.1f s" % dt)
        A.check("not planned within" in msg, "the huge plan was not stopped by a bound: %s" % (msg or "planned"))
        for s in floods:
            s.close()
        pc.close()
    finally:
        for p in helpers:
            p.kill()
        d.cleanup()

    # 6. TCP: off by default; when on, observers without configuration text
    d = A.Daemon().start()
    try:
        c = d.client()
        r = c.req("config")
        A.check(r["config"]["daemon"]["tcp_port"] == 0, "tcp_port not off by default: %s" % r["config"]["daemon"])
        c.close()
    finally:
        d.cleanup()
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    d = A.Daemon(extra_daemon="  tcp_port: %d\n" % port).start()
    try:
        t = socket.create_connection(("127.0.0.1", port), timeout=10)
        f = t.makefile("rb")
        json.loads(f.readline())
        t.sendall(b'{"cmd":"version","id":1}\n')
        r = json.loads(f.readline())
        A.check(r.get("role") == "observer", "TCP role: %s" % r)
        t.sendall(b'{"cmd":"config","id":2,"text":true}\n')
        r = json.loads(f.readline())
        A.check(r.get("ok") is False and r["error"]["code"] == "forbidden", "config text over TCP: %s" % str(r)[:200])
        t.sendall(b'{"cmd":"config","id":3}\n')
        r = json.loads(f.readline())
        A.check(r.get("ok") and "text" not in r["config"], "config over TCP: %s" % str(r)[:200])
        print("TCP: observer, configuration text refused")
        t.close()
    finally:
        d.cleanup()


A.run_main(main)
