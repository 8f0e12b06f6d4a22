#!/usr/bin/python3
"""The systemd watchdog is fed only by a loop that makes progress (issue 15). The daemon runs with a fake
NOTIFY_SOCKET (a datagram socket of this test) and WATCHDOG_USEC=1 s, so it must send WATCHDOG=1 every 0.5 s.
Its log goes to a pipe of one page that this test stops reading: the loop's next log line blocks in write()
(as it would if journald stopped reading), while the daemon's other threads and the process go on. Checked:
1. READY=1, then WATCHDOG=1 about every 0.5 s while the loop runs;
2. while the loop is blocked (a well-behaved client's `status` gets no reply), not one WATCHDOG=1 for 3 s: a
   watchdog fed by a thread of its own, or by a timer outside the loop, would go on feeding it;
3. once the pipe is read again, the loop answers, WATCHDOG=1 comes back within a period, and the daemon logs
   the late feed with the measured block ("the loop was blocked for about X s", X >= 2.5 s)."""
import fcntl
import json
import os
import re
import socket
import struct
import subprocess
import sys
import termios
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

F_SETPIPE_SZ = getattr(fcntl, "F_SETPIPE_SZ", 1031)
FIONREAD = getattr(termios, "FIONREAD", 0x541B)
BLOCK_S = 3.0


def pipe_bytes(fd):
    return struct.unpack("i", fcntl.ioctl(fd, FIONREAD, b"\0\0\0\0"))[0]


def run():
    b = L.Bench(scale=20)
    notify_path = os.path.join(b.dir, "notify.sock")
    ns = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    ns.bind(notify_path)
    msgs = []  # (monotonic time, message)
    stop = threading.Event()

    def listen():
        ns.settimeout(0.1)
        while not stop.is_set():
            try:
                d = ns.recv(4096)
            except socket.timeout:
                continue
            except OSError:
                return
            msgs.append((time.monotonic(), d.decode(errors="replace")))
    threading.Thread(target=listen, daemon=True).start()

    rfd, wfd = os.pipe()
    fcntl.fcntl(wfd, F_SETPIPE_SZ, 4096)
    log = bytearray()
    draining = threading.Event()
    draining.set()

    def drain():
        while True:
            draining.wait()
            try:
                d = os.read(rfd, 65536)
            except OSError:
                return
            if not d:
                return
            log.extend(d)
    threading.Thread(target=drain, daemon=True).start()
    try:
        b.start_sim()
        env = dict(os.environ, NOTIFY_SOCKET=notify_path, WATCHDOG_USEC="1000000")
        env.pop("WATCHDOG_PID", None)
        b.daemon = subprocess.Popen([L.DAEMON, "-f", "-c", b.conf, "--sim", b.ports], stdout=wfd, stderr=wfd,
                                    env=env)
        os.close(wfd)
        t0 = time.monotonic()
        while not any("READY=1" in m for _, m in msgs):
            assert b.daemon.poll() is None, "acquisitiond exited %d:\n%s" % (b.daemon.returncode, log.decode())
            assert time.monotonic() - t0 < 30, "no READY=1 in 30 s:\n" + log.decode()
            time.sleep(0.05)
        b.wait_devices()
        time.sleep(2.0)
        now = time.monotonic()
        feeds = [t for t, m in msgs if "WATCHDOG=1" in m and t > now - 2.0]
        L.say("WATCHDOG=1 in the last 2 s of normal running: %d" % len(feeds))
        assert len(feeds) >= 2, "the watchdog is not fed every 0.5 s: %s" % msgs[-10:]

        # 2. block the loop on its own log output
        draining.clear()
        time.sleep(0.3)  # the drain thread is parked before the next read
        good = b.client(timeout=30)
        spam = b.client(timeout=30)
        blocked_at = None
        t1 = time.monotonic()
        while time.monotonic() - t1 < 30:
            # each laser.off is logged ("laser off requested by the operator"): the page fills in about 40
            for _ in range(20):
                spam.n += 1
                spam.sock.sendall((json.dumps({"cmd": "laser.off", "id": spam.n}) + "\n").encode())
            good.sock.settimeout(1.0)
            try:
                good.req("status")
                continue
            except socket.timeout:
                pass
            # blocked on the log, not merely slow on a loaded machine: nothing more reaches the pipe for 1 s
            # although more logged requests are sent, and the status stays unanswered
            n1 = pipe_bytes(rfd)
            for _ in range(5):
                spam.n += 1
                spam.sock.sendall((json.dumps({"cmd": "laser.off", "id": spam.n}) + "\n").encode())
            time.sleep(1.0)
            n2 = pipe_bytes(rfd)
            good.sock.settimeout(0.1)
            try:
                r = good.read()
            except socket.timeout:
                r = None
            good.sock.settimeout(30)
            if r is None and n1 == n2 and n1 > 0:
                blocked_at = time.monotonic()
                break
            while r is None or r.get("id") != good.n:  # slow, not blocked: its late reply, then again
                r = good.read()
        assert blocked_at is not None, "the loop never blocked on its log (a pipe of one page not read)"
        L.say("loop blocked on its log output after %.1f s of laser.off requests" % (blocked_at - t1))
        time.sleep(BLOCK_S)
        window = (blocked_at + 0.5, blocked_at + BLOCK_S)  # a feed already on its way may land just after
        during = [t - blocked_at for t, m in msgs if "WATCHDOG=1" in m and window[0] <= t <= window[1]]
        alive = b.daemon.poll() is None
        L.say("WATCHDOG=1 while the loop was blocked (%.1f-%.1f s after): %d; daemon process alive: %s" % (
            window[0] - blocked_at, window[1] - blocked_at, len(during), alive))
        assert alive, "the daemon died while its log was not read"
        assert not during, "WATCHDOG=1 sent by a loop that made no progress (at +%s s)" % during

        # 3. read the log again: the loop resumes and reports its late feed
        t_release = time.monotonic()
        draining.set()
        r = good.read()
        while r.get("id") != good.n:
            r = good.read()
        L.say("status answered %.2f s after the log was read again" % (time.monotonic() - t_release))
        time.sleep(2.5)
        after = [t for t, m in msgs if "WATCHDOG=1" in m and t > t_release]
        L.say("WATCHDOG=1 within 2.5 s of the release: %d" % len(after))
        assert after and after[0] - t_release < 2.0, "the watchdog was not fed again after the loop resumed"
        text = log.decode(errors="replace")
        m = re.findall(r"watchdog: the loop was blocked for about ([0-9.]+) s", text)
        L.say("late-feed log lines: %s" % m)
        assert m and max(float(x) for x in m) >= BLOCK_S - 0.5, (
            "no late-feed line with the measured block:\n" + text[-3000:])
        good.close()
        spam.close()
    except Exception:
        print(log.decode(errors="replace")[-3000:])
        raise
    finally:
        stop.set()
        draining.set()
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")
        ns.close()


L.main(run)
