#!/usr/bin/python3
"""An observer cannot keep the devices' lines busy (issue 15, "no client can stall acquisition"): its `devices`
requests read the hardware at most once a second and get the cached view otherwise. Before, each `devices` that
found no query running started a fresh status read of every device, so a client asking back to back kept the
laser's serial line busy with STATUS? exchanges queued ahead of the sweep's laser commands (the soak's flood).
Checked with the simulator's count of STATUS? commands the laser answered:
1. idle for 3 s: the count the daemon's own polling gives;
2. an observer (another uid listed in daemon.observers) asking `devices` back to back for 3 s (hundreds of
   replies): at most 3 / 1 s + 2 more reads than idle;
3. a controller's (root's) `devices` still reads live: the count grows right after an observer's read."""
import json
import os
import pwd
import socket
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

SECONDS = 3.0
OBSERVER = "daemon"


def observer_flood(sock_path, seconds, wfd):
    """In a child as the observer: `devices` back to back; writes the number of replies to wfd."""
    pw = pwd.getpwnam(OBSERVER)
    os.setgid(pw.pw_gid)
    os.setuid(pw.pw_uid)
    c = L.Client(sock_path, timeout=20)
    n, ok = 0, 0
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        r = c.req("devices")
        n += 1
        ok += bool(r.get("ok") and r.get("devices"))
    c.close()
    os.write(wfd, json.dumps({"n": n, "ok": ok}).encode())


def reads(b):
    return int(b.sim_status()["laser_status_reads"])


def run():
    with L.Bench(scale=20, daemon_extra="  observers: [%s]\n" % OBSERVER) as b:
        b.start_sim()
        b.start_daemon()
        os.chmod(b.sock, 0o666)
        time.sleep(1.0)
        r0 = reads(b)
        time.sleep(SECONDS)
        idle = reads(b) - r0
        L.say("laser STATUS? reads in %.0f s idle: %d" % (SECONDS, idle))

        rfd, wfd = os.pipe()
        pid = os.fork()
        if pid == 0:
            try:
                os.close(rfd)
                observer_flood(b.sock, SECONDS, wfd)
                os._exit(0)
            except BaseException as e:  # noqa: B036 (the child must never return into the test)
                os.write(wfd, json.dumps({"error": str(e)}).encode())
                os._exit(1)
        os.close(wfd)
        r1 = reads(b)
        out = b""
        while True:
            d = os.read(rfd, 4096)
            if not d:
                break
            out += d
        os.close(rfd)
        _, status = os.waitpid(pid, 0)
        flood = reads(b) - r1
        res = json.loads(out.decode() or "{}")
        L.say("observer: %s; laser STATUS? reads meanwhile: %d (idle: %d)" % (res, flood, idle))
        assert status == 0 and "n" in res, "observer child failed: %s" % res
        assert res["n"] >= 50 and res["ok"] == res["n"], "the observer's flood did not run: %s" % res
        bound = idle + int(SECONDS / 1.0) + 2
        assert flood <= bound, "an observer's `devices` caused %d laser status reads in %.0f s (bound %d)" % (
            flood, SECONDS, bound)

        # 3. a controller reads live, even right after an observer's read
        c = b.client()
        r2 = reads(b)
        r = c.req("devices")
        got = reads(b) - r2
        L.say("controller's devices: ok %s, laser STATUS? reads %d" % (r.get("ok"), got))
        assert r.get("ok") and got >= 1, "a controller's `devices` did not read the laser: %s" % r
        c.close()


L.main(run)
