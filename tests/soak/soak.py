#!/usr/bin/python3
"""`make soak`: no client can stall acquisition (issue 15). A sweep runs on the simulated bench, first alone
(the baseline), then again and again while hostile and careless clients load the daemon for SOAK_SECONDS
(default 1200):
  flood       4 processes x 4 connections pipelining batches of valid and malformed requests, reading replies
  no-read     2 processes x 20 connections pipelining requests and never reading (reconnect when dropped)
  slots       2 users holding every connection their per-user limit allows (reconnect when closed)
  huge plans  2 connections asking for 10 x 1000 Fibonacci plans back to back (31 s on the loop before)
  half lines  10 connections sending half a request and nothing more (reconnect when closed)
  config      1 connection asking for the configuration text in a loop
and one well-behaved controller sends `status` every 50 ms. Load processes run as other users (observers).
After each sweep under load, a control sweep runs beside it with the load clients stopped (same plan, same seed,
same machine a minute later), so the machine's own stalls (7 engineers on 2 cores) are told from those the
clients cause.
Prints: the sweep's stall (largest gap between consecutive points under load; the largest excess of a point's
gap over the same point in the control sweep beside it, the goal's figure; and over the first, unloaded
baseline), the well-behaved client's reply latency p50/p99/max, the daemon's peak RSS, the server's refusal,
drop and timeout counters, the machine's load average beside every sweep, and where the daemon's threads lost
time (its log: laser requests and keep-alive gaps split into running, waiting for a CPU and waiting for the
laser; loop blocks with the loop's wait for a CPU). Goals: stall (excess over the control) <= 100 ms,
p99 < 50 ms, RSS < 64 MB; exit 1 when one is missed.
Priorities: the daemon at nice -5 (the unit's Nice=, applied to every thread: setpriority() on a pid changes
only its main thread), the simulator at -10 (it stands for hardware with its own processors), the load at
SOAK_LOAD_NICE (default 0).
SOAK_LOAD_SESSION=1 puts the load clients in a session of their own: Linux's autogroup then gives them one CPU
share, as a unit's cgroup and the users' are separate on a real machine (default 0: they share the daemon's).
SOAK_SIM_SESSION=1 does the same for acq-sim, which stands for controllers and a laser with processors of their
own (default 0: it shares the daemon's CPU group, and the daemon's work for the clients delays the "hardware").
Every point whose gap exceeds the same point's in the control sweep by more than 50 ms explains itself (a
"stall, sweep N point K" line): the daemon logs at debug level, per point, where the real time since the previous
commit went (daemon/executor_stall.c: what the executor waited for by phase — laser off, move, settle, dark,
exposure —, its own steps and database writes, WAL checkpoints (off the loop), the loop's callbacks (device
completions, the executor's, the rest: clients, plans), timers run late, the loop thread's wait for a CPU, and per
device port its requests' wait in the queue, run time with the thread's CPU wait and the part of clients' status
reads, and wait for the loop), and the
soak adds acq-sim's wait for a CPU over the same interval (its threads' schedstat, sampled); each line compares
them with the control's and names the cause by ordered rules (the daemon's own: its executor steps (a commit's database writes),
the loop busy with other callbacks, requests queued on a device thread, completions waiting for the loop; or the
host's: the loop, the device threads or acq-sim waiting for a CPU). The results block counts the causes.
Also printed: the scheduler's run and wait-for-a-CPU times of the simulator's and the daemon's threads during
the loaded and the control sweeps.
SOAK_OBSERVER_RATE sets daemon.observer_rate (requests per second per observer; 0: no limit, for comparison;
unset: the daemon's default).
The last block ("soak results") states each goal's figure, the goal and met/MISSED, with the source commit, the
knobs, the simulated laser's line and the machine's load: on a shared machine every figure includes the other
work, which the control sweeps show.
Environment: SOAK_SECONDS, SOAK_SCALE (bench time scale, default 10), SOAK_LOAD_NICE, SOAK_LOAD_SESSION,
SOAK_SIM_SESSION, SOAK_OBSERVER_RATE, ACQ_BUILD, ACQ_SRC, ACQ_SEED."""
import json
import multiprocessing as mp
import os
import pwd
import re
import socket
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "integration"))
import sweeplib as L  # noqa: E402

SECONDS = float(os.environ.get("SOAK_SECONDS", "1200"))
SCALE = float(os.environ.get("SOAK_SCALE", "10"))
LOAD_NICE = int(os.environ.get("SOAK_LOAD_NICE", "0"))
LOAD_SESSION = os.environ.get("SOAK_LOAD_SESSION", "0") == "1"
SIM_SESSION = os.environ.get("SOAK_SIM_SESSION", "0") == "1"
OBSERVER_RATE = os.environ.get("SOAK_OBSERVER_RATE")  # daemon.observer_rate (unset: the daemon's default)
OBSERVERS = ["daemon", "bin", "sys", "sync", "games", "man"]

PLAN = L.PLAN_3X18
HUGE = ("name: huge\nincidence:\n  theta_deg: [0, 8, 16, 24, 32, 40, 48, 56, 64, 72]\nobservation:\n"
        "  fibonacci: {count: 1000, max_theta_deg: 85}\nintegration: {mode: fixed, ms: 20}\naverages: 1\n"
        "blind_points: move\n")


def become(user):
    if LOAD_NICE:
        os.setpriority(os.PRIO_PROCESS, 0, LOAD_NICE)
    pw = pwd.getpwnam(user)
    os.setgid(pw.pw_gid)
    os.setuid(pw.pw_uid)


def connect(path):
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(5)
    s.connect(path)
    return s


def w_flood(path, user, stop):
    become(user)
    reqs = [b'{"cmd":"status","id":1}\n', b'{"cmd":"devices","id":2}\n', b'{"cmd":"sweep.list","id":3}\n',
            b'{"cmd":"version","id":4}\n', b'{"cmd":"nope","id":5}\n', b'not json at all\n', b'{"cmd":1}\n',
            b'{"cmd":"sweep.show","sweep":"x"}\n']
    conns = []
    while not stop.is_set():
        try:
            while len(conns) < 4:
                conns.append(connect(path))
            for s in list(conns):
                batch = b"".join(reqs[i % len(reqs)] for i in range(50))
                s.sendall(batch)
                got = 0
                while got < 51 and not stop.is_set():  # 50 replies (+ the banner the first time)
                    d = s.recv(1 << 16)
                    if not d:
                        raise OSError("closed")
                    got += d.count(b"\n")
                    if got >= 50:
                        break
        except OSError:
            for s in conns:
                s.close()
            conns = []
            time.sleep(0.05)


def w_noread(path, user, stop):
    become(user)
    conns = []
    batch = b'{"cmd":"status","id":1}\n' * 200
    while not stop.is_set():
        while len(conns) < 20:
            try:
                s = connect(path)
                s.setblocking(False)
                conns.append(s)
            except OSError:
                time.sleep(0.2)
                break
        for s in list(conns):
            try:
                s.send(batch)
            except BlockingIOError:
                pass
            except OSError:
                conns.remove(s)
                s.close()
        time.sleep(0.01)


def reap_closed(conns):
    """Drop the connections the daemon closed (refused, timed out); keep reading nothing else."""
    for s in list(conns):
        s.setblocking(False)
        try:
            while True:
                d = s.recv(1 << 16)
                if not d:
                    raise OSError("closed")
        except BlockingIOError:
            pass
        except OSError:
            conns.remove(s)
            s.close()


def w_slots(path, user, stop):
    become(user)
    conns = []
    while not stop.is_set():
        while len(conns) < 40:  # more than the per-user limit: the extra ones are refused
            try:
                conns.append(connect(path))
            except OSError:
                break
        time.sleep(0.5)
        reap_closed(conns)


def w_huge(path, user, stop):
    become(user)
    line = (json.dumps({"cmd": "plan", "id": 1, "plan": HUGE}) + "\n").encode()
    while not stop.is_set():
        try:
            s = connect(path)
            s.settimeout(60)
            f = s.makefile("rb")
            f.readline()
            while not stop.is_set():
                s.sendall(line)
                if not f.readline():
                    break
        except OSError:
            time.sleep(0.1)


def w_half(path, user, stop):
    become(user)
    conns = []
    while not stop.is_set():
        while len(conns) < 10:
            try:
                s = connect(path)
                s.sendall(b'{"cmd":"sta')
                conns.append(s)
            except OSError:
                break
        time.sleep(0.5)
        reap_closed(conns)


def w_config(path, user, stop):
    become(user)
    while not stop.is_set():
        try:
            s = connect(path)
            f = s.makefile("rb")
            f.readline()
            while not stop.is_set():
                s.sendall(b'{"cmd":"config","id":1,"text":true}\n')
                if not f.readline():
                    break
        except OSError:
            time.sleep(0.1)


def renice_all(pid, nice):
    """Every thread of pid at nice (Linux: a thread's nice is its own; setpriority(pid) sets the main one's)."""
    for tid in os.listdir("/proc/%d/task" % pid):
        try:
            os.setpriority(os.PRIO_PROCESS, int(tid), nice)
        except OSError:
            pass


def pressure():
    try:
        with open("/proc/pressure/cpu") as f:
            return f.readline().split()[1]  # some avg10=...
    except (OSError, IndexError):
        return "avg10=?"


def load_str():
    return "load %.1f %.1f %.1f, cpu pressure %s" % (os.getloadavg() + (pressure(),))


def thread_report(text):
    """Where the daemon's threads lost time, from its log (daemon/cputime.h diagnostics)."""
    out = []
    req = [tuple(map(float, m)) for m in re.findall(
        r"laser: request \d+ took ([0-9.]+) s on its thread \(([0-9.]+) s running, ([0-9.]+) s waiting for a CPU, "
        r"(-?[0-9.]+) s waiting for the laser\)", text)]
    if req:
        out.append("laser requests holding the laser's thread > 2 keep-alive periods: %d, %.1f s in all (max %.2f s):"
                   " %.1f s running, %.1f s waiting for a CPU, %.1f s waiting for the laser" % (
                       len(req), sum(r[0] for r in req), max(r[0] for r in req), sum(r[1] for r in req),
                       sum(r[2] for r in req), sum(r[3] for r in req)))
    ka = [tuple(map(float, m)) for m in re.findall(
        r"laser keep-alive: ([0-9.]+) s between two refreshes \(period [0-9.]+ s; the laser's thread waited "
        r"(-?[0-9.]+) s of it for a CPU\)", text)]
    if ka:
        out.append("laser keep-alive gaps > 2 periods: %d (max %.2f s); of their %.1f s the laser's thread waited "
                   "%.1f s for a CPU" % (len(ka), max(k[0] for k in ka), sum(k[0] for k in ka), sum(k[1] for k in ka)))
    wd = [tuple(map(float, m)) for m in re.findall(
        r"watchdog: the loop was blocked for about ([0-9.]+) s \(fed [0-9.]+ s after the last time, period [0-9.]+ s; "
        r"the loop's thread waited (-?[0-9.]+) s of it for a CPU\)", text)]
    if wd:
        out.append("loop blocks > 1 s (late watchdog feeds): %d (max %.1f s); the loop waited %.1f s of them for a "
                   "CPU" % (len(wd), max(w[0] for w in wd), sum(w[1] for w in wd)))
    faults = len(re.findall(r"stopped emitting", text))
    out.append("laser faults (stopped emitting during an exposure): %d; keep-alive failures: %d" % (
        faults, len(re.findall(r"laser keep-alive: \d+ failure", text))))
    return out


def describe_src():
    """The source tree's commit (and whether it has local changes) at the start, for the record (the binaries are
    ACQ_BUILD's: built from it by make soak)."""
    try:
        rev = subprocess.run(["git", "-C", L.SRC, "describe", "--always", "--dirty"], capture_output=True, text=True,
                             timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        rev = ""
    return "source %s" % (rev or "(not a git tree)")


def laser_link(b):
    """The simulated laser's line as the daemon opened it (acq-sim's ports file)."""
    try:
        with open(b.ports) as f:
            dev = json.load(f).get("laser", {}).get("device", "?")
    except (OSError, ValueError):
        return "?"
    return "%s (%s)" % (dev, "Unix socket" if dev.startswith("unix:") else "pty")


def rss_mb(pid):
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def gaps(b, sid):
    db = b.db()
    rows = db.execute("SELECT order_index, done_at FROM points WHERE sweep_id = ? AND state = 'done' "
                      "ORDER BY order_index", (sid,)).fetchall()
    db.close()
    return {rows[i][0]: rows[i][1] - rows[i - 1][1] for i in range(1, len(rows))
            if rows[i][0] == rows[i - 1][0] + 1}


def run_sweep(b, name, on_tick=None):
    c = b.client()
    r = c.req("sweep.start", plan=PLAN, name=name)
    c.close()
    if not r.get("ok"):
        raise AssertionError("sweep.start: %s" % r)
    sid = int(r["sweep"])
    row = L.drive_to_end(b, sid, timeout=3600, swap=False, on_tick=on_tick, poll=0.05)
    if row["state"] != "completed":
        raise AssertionError("sweep %d ended %s" % (sid, row["state"]))
    return sid


def pct(xs, p):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p / 100.0 * len(xs)))] if xs else float("nan")


STALL_RE = re.compile(r"stall: sweep (\d+) point (\d+): ([0-9.]+) ms since the last commit \(monotonic ([0-9.]+)-"
                      r"([0-9.]+)\); waited, ms: (.*?); executor (.*?); loop (.*?); ports: (.*)$", re.M)
KV_RE = re.compile(r"([a-z_]+)=(-?[0-9.]+)")
EXPLAIN_MS = 50.0  # a point whose gap exceeds the control's by more than this explains itself


def stall_points(text, sid):
    """The daemon's per-point stall lines (executor_stall.c, log_level debug) of sweep sid: {point: record}."""
    out = {}
    for m in STALL_RE.finditer(text):
        if int(m.group(1)) != sid:
            continue
        rec = {"total": float(m.group(3)), "t0": float(m.group(4)), "t1": float(m.group(5)), "ports": {}}
        for part in (m.group(6), m.group(7), m.group(8)):
            rec.update({k: float(v) for k, v in KV_RE.findall(part)})
        for key in ("callback_max_at", "callback_cpu_max_at"):  # (KV_RE read their "0x" as 0)
            at = re.search(r"\b%s=(0x[0-9a-f]+)" % key, m.group(8))
            rec[key] = at.group(1) if at else None
        for port in m.group(9).split("; "):
            name, _, rest = port.partition(": ")
            if rest:
                rec["ports"][name] = {k: float(v) for k, v in KV_RE.findall(rest)}
        out[int(m.group(2))] = rec
    return out


def sched_between(samples, t0, t1, idx):
    """Growth of column idx of the scheduler samples (monotonic time first) between t0 and t1, interpolated."""
    def at(t):
        prev = None
        for s in samples:
            if s[0] >= t:
                if prev is None:
                    return s[idx]
                f = (t - prev[0]) / (s[0] - prev[0]) if s[0] > prev[0] else 1.0
                return prev[idx] + f * (s[idx] - prev[idx])
            prev = s
        return prev[idx] if prev else 0.0
    return max(0.0, at(t1) - at(t0)) * 1e3 if samples else float("nan")


PHASES = ("laser_off", "verify", "homing", "move", "settle", "dark", "exposure", "acq", "retry", "durable", "other")
CAUSES = (("daemon: the executor's own steps on the loop (the previous point's commit: database writes)", "executor"),
          ("daemon: loop busy with other callbacks (clients, plans)", "loop_other"),
          ("daemon: device threads busy with clients' status reads", "client_reads"),
          ("daemon: device requests queued on their thread (behind others, or the thread not scheduled)", "queued"),
          ("daemon: device completions waiting for the loop", "completion_wait"),
          ("host: the daemon's loop waited for a CPU", "loop_cpu_wait"),
          ("host: the daemon's device threads waited for a CPU", "port_cpu_wait"),
          ("host: acq-sim waited for a CPU", "sim_cpu_wait"))


def pick_cause(d, excess_ms):
    """The cause named for a stalled point, from the growths d over the control (ms). Ordered rules, as the
    figures overlap: a loop that waited for a CPU also runs its timers and completions late, so the loop's own
    lateness counts as the daemon's only when the loop was on a CPU; the first rule whose figure reaches its
    share of the excess wins, else the largest growth."""
    label = dict((key, text) for text, key in CAUSES)
    for key, share in (("executor", 0.5), ("client_reads", 0.25), ("loop_cpu_wait", 0.5), ("loop_other", 0.5),
                       ("completion_wait", 0.5), ("sim_cpu_wait", 0.5), ("port_cpu_wait", 0.5), ("queued", 0.5)):
        if d[key] == d[key] and d[key] >= share * excess_ms:
            return label[key]
    best = max(((d[key], text) for text, key in CAUSES if d[key] == d[key]), default=(0, ""))
    if best[0] > 0.25 * excess_ms:
        return best[1]
    return ("not in the daemon's figures (device time: the simulator)" if d["device_run"] > 0.5 * excess_ms
            else "unexplained")


def figures(rec, samples):
    ports = rec["ports"].values()
    return {"executor": rec.get("steps", 0), "loop_other": rec.get("loop_other", 0),
            "queued": sum(p.get("queued", 0) for p in ports),
            "client_reads": sum(p.get("clients", 0) for p in ports),
            "completion_wait": sum(p.get("loop", 0) for p in ports),
            "loop_cpu_wait": rec.get("loop_cpu_wait", 0), "port_cpu_wait": sum(p.get("cpu_wait", 0) for p in ports),
            "sim_cpu_wait": sched_between(samples, rec["t0"], rec["t1"], 1),
            "device_run": sum(p.get("run", 0) for p in ports)}


def fn_name(addr):
    """The daemon's function at addr (its offset in the binary, stall.c's callback_max_at), by addr2line."""
    if not addr or addr == "0x0":
        return "?"
    try:
        out = subprocess.run(["addr2line", "-f", "-e", L.DAEMON, addr], capture_output=True, text=True, timeout=10)
        return out.stdout.split("\n")[0] or "?"
    except (OSError, subprocess.SubprocessError):
        return addr


def explain(k, excess_ms, lrecs, crecs, lsamp, csamp):
    """One stalled point: its phases and causes under load against the same point in the control sweep; the
    cause is the largest growth among the daemon's and the host's figures (they can overlap: all are shown).
    The gap (done_at: the point's last spectrum) spans the end of the previous point's commit, so the executor's
    steps of this record (which include that commit) and the previous point's database writes are shown."""
    lrec, crec = lrecs.get(k), crecs.get(k)
    lprev, cprev = lrecs.get(k - 1, {}), crecs.get(k - 1, {})
    if not lrec or not crec:
        return "point %d: +%.0f ms over the control; no stall record (log_level debug?)" % (k, excess_ms), "unknown"
    grew = sorted(((lrec.get(p, 0) - crec.get(p, 0), p) for p in PHASES), reverse=True)
    lf, cf = figures(lrec, lsamp), figures(crec, csamp)
    d = {key: lf[key] - cf[key] for key in lf}
    cause = pick_cause(d, excess_ms)
    ports = "; ".join("%s queued %+.0f run %+.0f (cpu wait %+.0f; clients' reads %+.0f) loop %+.0f" % (
        n, p.get("queued", 0) - crec["ports"].get(n, {}).get("queued", 0),
        p.get("run", 0) - crec["ports"].get(n, {}).get("run", 0),
        p.get("cpu_wait", 0) - crec["ports"].get(n, {}).get("cpu_wait", 0),
        p.get("clients", 0) - crec["ports"].get(n, {}).get("clients", 0),
        p.get("loop", 0) - crec["ports"].get(n, {}).get("loop", 0)) for n, p in lrec["ports"].items() if p.get("n"))
    text = ("point %d: +%.0f ms over the control between the points' last spectra (commit to commit %.0f vs %.0f "
            "ms); phases grew %s; executor steps %+.0f ms (the previous commit's database writes %.0f vs %.0f ms; WAL "
            "checkpoints off the loop %d: %.0f ms), loop callbacks %+.0f (max %.0f ms in %s, %.0f ms of it on the CPU; most CPU %.0f ms in %s; others' %+.0f), timers "
            "late %+.0f (max %.0f ms), loop waited for a CPU %+.0f, acq-sim waited for a CPU %+.0f ms; ports (ms "
            "vs control): %s; cause: %s" % (
                k, excess_ms, lrec["total"], crec["total"],
                ", ".join("%s %+.0f" % (p, v) for v, p in grew[:3] if abs(v) >= 1) or "none",
                d["executor"], lprev.get("store", float("nan")), cprev.get("store", float("nan")),
                lrec.get("checkpoints", 0), lrec.get("checkpoint", 0),
                lrec.get("callbacks", 0) - crec.get("callbacks", 0), lrec.get("callback_max", 0),
                fn_name(lrec.get("callback_max_at")), lrec.get("callback_max_on_cpu", 0),
                lrec.get("callback_cpu_max", 0), fn_name(lrec.get("callback_cpu_max_at")), d["loop_other"],
                lrec.get("timers_late", 0) - crec.get("timers_late", 0), lrec.get("timer_late_max", 0),
                d["loop_cpu_wait"], d["sim_cpu_wait"], ports, cause))
    return text, cause


WORKERS = [(w_flood, OBSERVERS[0]), (w_flood, OBSERVERS[0]), (w_flood, OBSERVERS[1]), (w_flood, OBSERVERS[1]),
           (w_noread, OBSERVERS[2]), (w_noread, OBSERVERS[2]), (w_slots, OBSERVERS[3]), (w_slots, OBSERVERS[4]),
           (w_huge, OBSERVERS[5]), (w_huge, OBSERVERS[5]), (w_half, OBSERVERS[1]), (w_config, OBSERVERS[0])]


def load_group(sock, stop):
    """The load clients' parent: in a session of its own when SOAK_LOAD_SESSION=1, so that Linux's autogroup
    gives the clients one CPU share of their own, as users' processes (user.slice) and the unit (system.slice)
    have on a real machine; otherwise they share the soak's group with the daemon and the simulator."""
    if LOAD_SESSION:
        os.setsid()
    procs = []
    for fn, user in WORKERS:
        p = mp.Process(target=fn, args=(sock, user, stop), daemon=True)
        p.start()
        procs.append(p)
    stop.wait()
    for p in procs:
        p.join(3)
        if p.is_alive():
            p.kill()
            p.join(3)


def start_load(sock):
    stop = mp.Event()
    p = mp.Process(target=load_group, args=(sock, stop))
    p.start()
    return stop, [p]


def sched_times(pid, main_only=False):
    """(seconds on a CPU, seconds waiting for one) summed over pid's threads (/proc/PID/task/*/schedstat), or of
    its main thread only (the daemon's loop)."""
    run = wait = 0
    try:
        for tid in (["%d" % pid] if main_only else os.listdir("/proc/%d/task" % pid)):
            try:
                with open("/proc/%d/task/%s/schedstat" % (pid, tid)) as f:
                    a = f.read().split()
                run += int(a[0])
                wait += int(a[1])
            except (OSError, IndexError, ValueError):
                pass
    except OSError:
        pass
    return run * 1e-9, wait * 1e-9


def stop_load(stop, procs):
    stop.set()
    for p in procs:
        p.join(10)
        if p.is_alive():
            p.kill()
            p.join(3)


def main():
    if os.geteuid() != 0:
        print("soak: needs root (load clients run as other users)")
        return 2
    cfg = open(os.path.join(L.SRC, "config", "bench-sim.yaml")).read()
    sweep = cfg[cfg.index("\nsweep:") + 1:]
    sweep = L.strip_sections(sweep, {"recon", "daemon"}).replace("auto_recon: true", "auto_recon: false")
    sweep = sweep.replace("pause_after_reference: true", "pause_after_reference: false")
    b = L.Bench(scale=SCALE, sweep_yaml=sweep,
                daemon_extra="  observers: [%s]\n%s" % (", ".join(OBSERVERS), "  observer_rate: %s\n" % OBSERVER_RATE
                                                      if OBSERVER_RATE is not None else ""),
                sim_session=SIM_SESSION)
    with open(b.conf) as f:  # the per-point stall lines (executor_stall.c) are logged at debug level
        conf = f.read()
    with open(b.conf, "w") as f:
        f.write(conf.replace("log_level: info", "log_level: debug"))
    os.chmod(b.dir, 0o755)
    load = None
    try:
        b.start_sim()
        b.start_daemon()
        os.chmod(b.sock, 0o666)
        # Priorities as on a real bench: the unit runs the daemon at Nice=-5; the simulator stands for
        # controllers and a laser that have their own processors (-10 here, so the load does not starve it).
        # Every thread: the daemon's device threads exist already, and a thread's nice is its own.
        renice_all(b.sim.pid, -10)
        renice_all(b.daemon.pid, -5)
        t_start = time.time()
        src_rev = describe_src()  # now: the tree may change while the soak runs
        print("soak: %g s, bench time scale %g, plan of %s points, seed %d, load clients at nice %d, %s; %s" % (
            SECONDS, SCALE, "52", L.SEED, LOAD_NICE, "in a session (CPU group) of their own" if LOAD_SESSION else
            "in the daemon's session (CPU group)", load_str()), flush=True)
        print("soak: acq-sim %s; %s; laser line %s" % ("in a session (CPU group) of its own" if SIM_SESSION else
                                                     "in the daemon's session (CPU group)", src_rev, laser_link(b)),
              flush=True)
        good = L.Client(b.sock, timeout=10)  # connected before the load, like an operator's watch
        lat, ctl_lat, errors, rss = [], [], 0, []
        last = [0.0]

        def probe(into):
            nonlocal errors
            now = time.monotonic()
            if now - last[0] < 0.05:
                return
            last[0] = now
            t0 = time.monotonic()
            try:
                r = good.req("status")
                into.append(time.monotonic() - t0)
                if not r.get("ok"):
                    errors += 1
            except Exception:
                errors += 1
            rss.append(rss_mb(b.daemon.pid))

        paused = []
        samples = {}

        sched = {"load": [0.0] * 6, "control": [0.0] * 6}

        def drive(name, into, deadline, kind=None):
            """One sweep of the plan, probing status meanwhile; its gaps by point. kind: where to add the sweep's
            scheduler times of the simulator's and the daemon's threads."""
            s0, d0, m0 = sched_times(b.sim.pid), sched_times(b.daemon.pid), sched_times(b.daemon.pid, True)
            try:
                return drive1(name, into, deadline)
            finally:
                if kind:
                    s1, d1, m1 = sched_times(b.sim.pid), sched_times(b.daemon.pid), sched_times(b.daemon.pid, True)
                    acc = sched[kind]
                    for i, v in enumerate((s1[0] - s0[0], s1[1] - s0[1], d1[0] - d0[0], d1[1] - d0[1],
                                           m1[0] - m0[0], m1[1] - m0[1])):
                        acc[i] += v

        def drive1(name, into, deadline):
            r = good.req("sweep.start", plan=PLAN, name=name)
            if not r.get("ok"):
                raise AssertionError("sweep.start %s: %s" % (name, r))
            sid = int(r["sweep"])
            samp = samples[sid] = []  # acq-sim's scheduler times along the sweep, for its stalled points
            while True:
                run_s, wait_s = sched_times(b.sim.pid)
                samp.append((time.monotonic(), wait_s, run_s))
                probe(into)
                st = good.req("sweep.show", sweep=sid)
                state = st["sweep"]["state"] if st.get("ok") else "?"
                if state in ("completed", "aborted", "failed"):
                    break
                if state == "paused":
                    # A device fault the sweep could not ride out (the simulator starved of CPU): counted,
                    # resumed as an operator would.
                    ev = [e for e in st["sweep"].get("events", []) if e.get("kind") == "pause"]
                    paused.append(ev[0].get("message", "") if ev else "?")
                    print("  sweep %d paused: %s; resuming" % (sid, paused[-1]), flush=True)
                    good.req("sweep.resume")
                if time.time() > deadline:
                    raise AssertionError("sweep %d (%s) not finished in time" % (sid, name))
                time.sleep(0.05)
            if st["sweep"]["state"] != "completed":
                raise AssertionError("sweep %d (%s) ended %s" % (sid, name, st["sweep"]["state"]))
            return sid, gaps(b, sid)

        base_lat = []
        base_sid, base = drive("baseline", base_lat, time.time() + 3600)
        print("baseline sweep %d (no load): %d points, gap between points median %.0f ms, max %.0f ms; status "
              "latency p50 %.1f ms, p99 %.1f ms; %s" % (
                  base_sid, len(base) + 1, 1e3 * pct(list(base.values()), 50), 1e3 * max(base.values()),
                  1e3 * pct(base_lat, 50), 1e3 * pct(base_lat, 99), load_str()), flush=True)

        load_end = t_start + SECONDS
        excess, excess_ctl, load_gaps, ctl_gaps, sweeps, points = [], [], [], [], 0, 0
        per_sweep, loads, explained = [], [], []
        while time.time() < load_end or sweeps == 0:
            load = start_load(b.sock)
            sid, g = drive("soak-%d" % sweeps, lat, load_end + max(600, SECONDS), "load")
            lstr = load_str()
            loads.append(os.getloadavg()[0])
            stop_load(*load)
            load = None
            # the control beside it: the same plan on the same machine now, without the load clients
            csid, cg = drive("control-%d" % sweeps, ctl_lat, time.time() + 3600, "control")
            sweeps += 1
            points += len(g) + 1
            load_gaps += list(g.values())
            ctl_gaps += list(cg.values())
            ex_b = [g[k] - base[k] for k in g if k in base]
            ex_c = [g[k] - cg[k] for k in g if k in cg]
            excess += ex_b
            excess_ctl += ex_c
            per_sweep.append(max(ex_c))
            text = b.daemon_text()
            lrecs, crecs = stall_points(text, sid), stall_points(text, csid)
            for k in sorted(g):
                if k in cg and 1e3 * (g[k] - cg[k]) > EXPLAIN_MS:
                    line, cause = explain(k, 1e3 * (g[k] - cg[k]), lrecs, crecs, samples.get(sid), samples.get(csid))
                    explained.append((1e3 * (g[k] - cg[k]), cause))
                    print("    stall, sweep %d %s" % (sid, line), flush=True)
            samples.pop(sid, None)
            samples.pop(csid, None)
            print("  sweep %d under load: max gap %.0f ms (%s); control sweep %d beside it: max gap %.0f ms (%s); "
                  "largest excess of a point's gap over the same point in the control %.0f ms, over the baseline "
                  "%.0f ms; status p99 so far %.1f ms; RSS %.1f MB" % (
                      sid, 1e3 * max(g.values()), lstr, csid, 1e3 * max(cg.values()), load_str(), 1e3 * max(ex_c),
                      1e3 * max(ex_b), 1e3 * pct(lat, 99), max(rss) if rss else 0), flush=True)
        st = good.req("status")
        srv = st.get("server", {})
        good.close()
        elapsed = time.time() - t_start
        print()
        print("soak: %.0f s; %d sweeps (%d points) under load, each followed by a control sweep without it" % (
            elapsed, sweeps, points))
        print("sweep stall: max gap between points under load %.0f ms, in the control sweeps %.0f ms, in the "
              "baseline %.0f ms" % (1e3 * max(load_gaps), 1e3 * max(ctl_gaps), 1e3 * max(base.values())))
        print("sweep stall from the load clients: largest excess of a point's gap over the same point in the control "
              "sweep beside it %.0f ms (goal <= 100 ms); over the first baseline %.0f ms" % (
                  1e3 * max(excess_ctl), 1e3 * max(excess)))
        print("well-behaved client: %d status requests under load, latency p50 %.1f ms, p99 %.1f ms, max %.1f ms, "
              "%d errors (goal p99 < 50 ms); in the control sweeps p50 %.1f ms, p99 %.1f ms" % (
                  len(lat), 1e3 * pct(lat, 50), 1e3 * pct(lat, 99), 1e3 * max(lat), errors, 1e3 * pct(ctl_lat, 50),
                  1e3 * pct(ctl_lat, 99)))
        print("daemon RSS: peak %.1f MB (goal < 64 MB)" % max(rss))
        print("sweeps paused by device faults: %d%s" % (len(paused), (" (%s)" % paused[0]) if paused else ""))
        for kind in ("load", "control"):
            a = sched[kind]
            print("scheduler, the %s sweeps: acq-sim's threads ran %.1f s and waited %.1f s for a CPU; the daemon's "
                  "ran %.1f s and waited %.1f s, of which its loop (main thread) ran %.1f s and waited %.1f s" % (
                      (kind if kind == "control" else "loaded",) + tuple(a)))
        for line in thread_report(b.daemon_text()):
            print("daemon threads: " + line)
        print("machine at the end: %s on %d CPUs" % (load_str(), os.cpu_count()))
        print("server: %s" % json.dumps(srv))
        ok = max(excess_ctl) <= 0.100 and pct(lat, 99) < 0.050 and max(rss) < 64 and errors == 0 and not paused
        text = b.daemon_text()
        print()
        print("soak results (the issue's goals), measured on %d CPUs with the machine's 1-min load average %.1f-%.1f at "
              "the end of the loaded sweeps (other work on the machine counts in every figure: compare with the "
              "control sweeps):" % (os.cpu_count(), min(loads), max(loads)))
        print("  setup: %s; %s; laser line %s; daemon.observer_rate %s" % (
            src_rev, "SOAK_SECONDS=%g SOAK_SCALE=%g ACQ_SEED=%d SOAK_LOAD_NICE=%d SOAK_LOAD_SESSION=%d "
            "SOAK_SIM_SESSION=%d" % (SECONDS, SCALE, L.SEED, LOAD_NICE, LOAD_SESSION, SIM_SESSION),
            laser_link(b), OBSERVER_RATE if OBSERVER_RATE is not None else "the daemon's default"))
        verdict = lambda good: "met" if good else "MISSED"  # noqa: E731
        print("  stall (largest excess of a point's gap over the same point in the control sweep): %.0f ms, goal <= "
              "100 ms: %s; per loaded sweep: %s ms" % (1e3 * max(excess_ctl), verdict(max(excess_ctl) <= 0.100),
                                                     ", ".join("%.0f" % (1e3 * x) for x in per_sweep)))
        print("  well-behaved controller's status latency under load: p50 %.1f ms, p99 %.1f ms (%d requests, %d errors),"
              " goal p99 < 50 ms: %s" % (1e3 * pct(lat, 50), 1e3 * pct(lat, 99), len(lat), errors,
                                        verdict(pct(lat, 99) < 0.050 and errors == 0)))
        print("  daemon RSS peak: %.1f MB, goal < 64 MB: %s" % (max(rss), verdict(max(rss) < 64)))
        print("  sweeps paused by device faults: %d; laser requests > 2 keep-alive periods: %d; laser faults: %d" % (
            len(paused), len(re.findall(r"laser: request \d+ took", text)), len(re.findall(r"stopped emitting", text))))
        causes = {}
        for ms, cause in explained:
            causes.setdefault(cause, []).append(ms)
        print("  stall attribution: %d points over %.0f ms beyond the control%s" % (
            len(explained), EXPLAIN_MS, "".join("; %s: %d (max +%.0f ms)" % (c, len(v), max(v))
                                                for c, v in sorted(causes.items(), key=lambda kv: -max(kv[1])))))
        print("soak: %s" % ("all goals met" if ok else "GOALS MISSED"))
        return 0 if ok else 1
    finally:
        if load:
            stop_load(*load)
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


if __name__ == "__main__":
    sys.exit(main())
