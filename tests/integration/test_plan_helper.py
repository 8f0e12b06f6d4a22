#!/usr/bin/python3
"""Plans are forked by the job helper, never by the daemon's loop (reliability: a `plan` request cost 5-21 ms of
the loop thread's CPU when the loop forked the whole daemon for it and parsed the plan itself).
1. While a huge `plan` is computed, its child (comm acq-job) is the helper's (comm acq-helper, the daemon's only
   child): the daemon forked nothing for the request. Before the change the child was the daemon's own.
2. The helper SIGKILLed mid-request: that `plan` gets a clear error at once (the planner's process was lost,
   retry), not the 10 s deadline; the next `plan` is answered by a new helper, which holds no descriptor or
   mapping of the database, no device, one thread: the daemon's program run again as the helper, not a fork of
   the daemon (that one kept the database's -shm mapping).
3. The same for `sweep.start`'s plan: the start fails with the message, the daemon is idle, not "planning".
4. A flood of `plan` requests (8 clients back to back for 4 s, one of them huge plans) leaves `status` answering in
   < 0.5 s (the bound test_client_limits uses); every flood reply is a plan, "unavailable" (2 at once at most)
   or the deadline, never an internal error."""
import json
import os
import signal
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

HUGE = ("name: huge\nincidence:\n  theta_deg: [0, 8, 16, 24, 32, 40, 48, 56, 64, 72]\n"
        "observation:\n  fibonacci: {count: 1000, max_theta_deg: 85}\nintegration: {mode: fixed, ms: 20}\n"
        "averages: 1\nblind_points: move\n")
SMALL = ("name: small\nincidence:\n  theta_deg: [20, 40]\nobservation:\n  theta_deg: [30, 50]\n"
         "  phi_deg: [0, 90]\nintegration: {mode: fixed, ms: 20}\naverages: 1\nblind_points: drop\n")


def comm(pid):
    try:
        with open("/proc/%d/comm" % pid) as f:
            return f.read().strip()
    except OSError:
        return None


def children(pid):
    try:
        with open("/proc/%d/task/%d/children" % (pid, pid)) as f:
            return [int(p) for p in f.read().split()]
    except OSError:
        return []


def helper(b, timeout=10):
    """The daemon's job helper: its only child named acq-helper."""
    t0 = time.time()
    while True:
        hs = [p for p in children(b.daemon.pid) if comm(p) == "acq-helper"]
        if len(hs) == 1:
            return hs[0]
        if time.time() - t0 > timeout:
            raise AssertionError("no single job helper among the daemon's children: %s" % [
                (p, comm(p)) for p in children(b.daemon.pid)])
        time.sleep(0.02)


def holdings(pid):
    """What process pid holds: its descriptors' targets, the files it maps, its threads, its command line."""
    fds = {}
    for fd in os.listdir("/proc/%d/fd" % pid):
        try:
            fds[int(fd)] = os.readlink("/proc/%d/fd/%s" % (pid, fd))
        except OSError:
            pass
    with open("/proc/%d/maps" % pid) as f:
        maps = set(line.split(None, 5)[5].strip() for line in f if len(line.split(None, 5)) == 6)
    with open("/proc/%d/status" % pid) as f:
        threads = int([line.split()[1] for line in f if line.startswith("Threads:")][0])
    with open("/proc/%d/cmdline" % pid, "rb") as f:
        cmd = f.read().split(b"\0")
    return fds, maps, threads, cmd


def check_clean(b, h):
    """The helper h holds neither the daemon's database (a descriptor or a mapping: SQLite maps the WAL's -shm
    file) nor a device (any socket but its own to the daemon, any /dev node but /dev/null), runs one thread and
    is the daemon's program run as the helper. The daemon itself holds the database: the check can see it."""
    db = b.db_path()
    dfds, dmaps, dthreads, _ = holdings(b.daemon.pid)
    if not any(t.startswith(db) for t in dfds.values()):
        raise AssertionError("the daemon holds no descriptor of %s: %s" % (db, dfds))
    fds, maps, threads, cmd = holdings(h)
    L.say("helper %d: descriptors %s, threads %d, command %s; %d mapped files; the daemon: %d threads, %d "
          "descriptors, maps the database: %s" % (h, fds, threads, cmd[:2], len(maps), dthreads, len(dfds),
                                                  any(m.startswith(db) for m in dmaps)))
    bad = [t for t in fds.values() if t.startswith(db) or (t.startswith("/dev/") and t != "/dev/null")]
    bad += [m for m in maps if m.startswith(db)]
    if bad:
        raise AssertionError("the helper %d holds the daemon's %s" % (h, bad))
    socks = [fd for fd, t in fds.items() if t.startswith("socket:")]
    if socks != [3]:
        raise AssertionError("the helper %d holds sockets %s (its own is 3): %s" % (h, socks, fds))
    if threads != 1 or cmd[:2] != [b"acq-helper", b"--job-helper"]:
        raise AssertionError("the helper %d: %d threads, command %s" % (h, threads, cmd))


def wait_job(h, timeout=10):
    """The helper's first child named acq-job (a plan being computed)."""
    t0 = time.time()
    while time.time() - t0 < timeout:
        kids = [p for p in children(h) if comm(p) == "acq-job"]
        if kids:
            return kids[0]
        time.sleep(0.01)
    raise AssertionError("the helper %d started no acq-job child in %g s" % (h, timeout))


def flood(b, stop, replies, text):
    c = b.client(timeout=60)
    while not stop.is_set():
        r = c.req("plan", plan=text)
        replies.append("plan" if r.get("ok") else r["error"]["code"] + ": " + r["error"]["message"])
    c.close()


def run():
    with L.Bench(scale=20, daemon_extra="  auto_resume: false\n") as b:
        b.start_sim()
        b.start_daemon()
        b.ctl("sample white")
        h1 = helper(b)
        L.say("daemon %d, job helper %d" % (b.daemon.pid, h1))

        # 1. the plan's child is the helper's; the daemon's only child is the helper
        c = b.client(timeout=60)
        c.sock.sendall((json.dumps({"cmd": "plan", "id": 1, "plan": HUGE}) + "\n").encode())
        kid = wait_job(h1)
        dk = [(p, comm(p)) for p in children(b.daemon.pid)]
        L.say("planning: child %d of the helper; the daemon's children %s" % (kid, dk))
        if dk != [(h1, "acq-helper")]:
            raise AssertionError("the daemon forked for the plan: its children %s" % dk)

        # 2. the helper killed mid-request: a clear error now, then a new helper answers
        t0 = time.monotonic()
        os.kill(h1, signal.SIGKILL)
        r = c.read()
        dt = time.monotonic() - t0
        L.say("helper killed: reply after %.2f s: %s" % (dt, r))
        if r.get("ok") or "lost" not in r["error"]["message"] or "retry" not in r["error"]["message"]:
            raise AssertionError("the plan of a killed helper: %s" % r)
        if dt > 5:
            raise AssertionError("the lost plan was answered after %.1f s (its deadline, not the helper's end)" % dt)
        r = c.req("plan", plan=SMALL)
        if not r.get("ok") or r["plan"]["requested"] != 8:
            raise AssertionError("the plan after the helper's restart: %s" % str(r)[:300])
        h2 = helper(b)
        if h2 == h1:
            raise AssertionError("the same helper after its SIGKILL")
        L.say("next plan answered by the new helper %d" % h2)
        check_clean(b, h2)

        # 3. sweep.start's plan: the helper killed while it plans
        c.sock.sendall((json.dumps({"cmd": "sweep.start", "id": 5, "plan": HUGE, "name": "huge"}) + "\n").encode())
        wait_job(h2)
        os.kill(h2, signal.SIGKILL)
        while True:
            r = c.read()
            if r.get("id") == 5:
                break
        L.say("sweep.start with its helper killed: %s" % r)
        if r.get("ok") or not r["error"]["message"].startswith("sweep.start: the planner's process was lost"):
            raise AssertionError("sweep.start of a killed helper: %s" % r)
        st = c.req("status")
        if st["sweep"]["state"] != "idle" or st["sweep"].get("planning"):
            raise AssertionError("not idle after the failed start: %s" % st["sweep"])

        # 4. a plan flood does not stall status
        stop = threading.Event()
        replies = []
        threads = [threading.Thread(target=flood, args=(b, stop, replies, HUGE if i == 0 else SMALL))
                   for i in range(8)]
        for t in threads:
            t.start()
        lat = []
        t_end = time.monotonic() + 4
        while time.monotonic() < t_end:
            t0 = time.monotonic()
            r = c.req("status")
            lat.append(time.monotonic() - t0)
            if not r.get("ok"):
                raise AssertionError("status refused during the flood: %s" % r)
            time.sleep(0.02)
        stop.set()
        for t in threads:
            t.join(60)
        kinds = {}
        for x in replies:
            k = "plan" if x == "plan" else x.split(":")[0] + (": deadline" if "within" in x else "")
            kinds[k] = kinds.get(k, 0) + 1
        lat.sort()
        L.say("flood of %d plan replies %s; status latency median %.4f s, max %.3f s (%d samples)" % (
            len(replies), kinds, lat[len(lat) // 2], lat[-1], len(lat)))
        bad = [x for x in replies if x != "plan" and not x.startswith("unavailable") and "within" not in x]
        if bad:
            raise AssertionError("flood replies other than plan/unavailable/deadline: %s" % bad[:5])
        if kinds.get("plan", 0) < 5:
            raise AssertionError("the flood got %d plans" % kinds.get("plan", 0))
        if lat[-1] >= 0.5:
            raise AssertionError("status took %.3f s during the plan flood" % lat[-1])
        c.close()
        log = b.daemon_text()
        if "job helper restarted" not in log:
            raise AssertionError("the daemon's log does not say the helper was restarted")


L.main(run)
