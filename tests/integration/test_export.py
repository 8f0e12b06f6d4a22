#!/usr/bin/python3
"""Integration: exports at any size and where they may land.
- `acqctl export N > file` and `-o FILE` for a sweep the size of the paper's plan (866 points x 651 wavelengths,
  about 11 MB of CSV): the stream passed over the socket arrives whole (every row, same bytes as a file export),
  and memory stays bounded on both sides (daemon's VmHWM growth and acqctl's max RSS well below the CSV size);
- a client that stops reading loses its stream after the daemon's stall timeout, without stalling the daemon;
- daemon-side files (path=NAME) are only NEW files in <state_dir>/export: every name of the state directory,
  the SQLite side files and escapes are tried; the database and every other file are left untouched and the
  database still passes integrity_check."""
import hashlib
import json
import os
import sqlite3
import struct
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from acqtest import ACQCTL, Daemon, check  # noqa: E402

NPTS, NWL = 866, 651


def seed_big(db, npts=NPTS):
    con = sqlite3.connect(db, timeout=10)
    cur = con.cursor()
    cur.execute("INSERT INTO sweeps (name, plan_text, config_snapshot, state, created_at, software_version, "
                "points_total) VALUES ('paper-size', 'plan: x', 'bench: {}', 'completed', 1.0, 'test', ?)", (npts,))
    sid = cur.lastrowid
    grid = [450.0 + i for i in range(NWL)]
    cur.execute("UPDATE sweeps SET wavelength_grid = ? WHERE id = ?", (struct.pack("<%df" % NWL, *grid), sid))
    for k in range(npts):
        ang = ((k % 10) * 8.0, 0.0, (k % 7) * 9.0, float((k * 36) % 360))  # measured = planned here
        cur.execute("INSERT INTO points (sweep_id, order_index, theta_i, phi_i, theta_o, phi_o, state, m_theta_i, "
                    "m_phi_i, m_theta_o, m_phi_o) VALUES (?, ?, ?, ?, ?, ?, 'done', ?, ?, ?, ?)", (sid, k, *ang, *ang))
        pid = cur.lastrowid
        vals = struct.pack("<%df" % NWL, *[0.1 + 1e-4 * ((k * 7 + i) % 1000) for i in range(NWL)])
        sig = struct.pack("<%df" % NWL, *[1e-3 + 1e-7 * i for i in range(NWL)])
        cur.execute("INSERT INTO calibrated (point_id, sweep_id, brdf, sigma) VALUES (?, ?, ?, ?)", (pid, sid, vals, sig))
    con.commit()
    con.close()
    return sid


def run_rss(argv, stdout):
    """Run argv; (exit status, its own max RSS in kB)."""
    p = subprocess.Popen(argv, stdout=stdout)
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    return p.returncode, ru.ru_maxrss


def vm(pid, key):
    for line in open("/proc/%d/status" % pid):
        if line.startswith(key + ":"):
            return int(line.split()[1])  # kB
    return 0


def snapshot(state):
    """Every entry of the state directory outside export/: name -> (inode, size, mtime, sha256 of regular files)."""
    out = {}
    for name in os.listdir(state):
        if name == "export":
            continue
        p = os.path.join(state, name)
        st = os.lstat(p)
        h = hashlib.sha256(open(p, "rb").read()).hexdigest() if os.path.isfile(p) and not os.path.islink(p) else ""
        out[name] = (st.st_ino, st.st_size, st.st_mtime_ns, h)
    return out


def main():
    d = Daemon()
    env = None
    if "sanitize=address" in open(os.path.join(os.environ.get("ACQ_BUILD", "build"), ".cflags")).read():
        # ASan keeps freed memory in quarantine (256 MB by default): peak RSS would count every allocation
        # ever made instead of the live ones; a small quarantine keeps the bound meaningful.
        env = dict(os.environ, ASAN_OPTIONS=os.environ.get("ASAN_OPTIONS", "") +
                   ":quarantine_size_mb=1:thread_local_quarantine_size_kb=64")
    try:
        d.start(env=env)
        c = d.client()
        db = os.path.join(d.state, "acquisition.db")
        small = seed_big(db, 3)
        sid = seed_big(db)
        pid = d.proc.pid
        # the baseline: one small export already ran (the thread, its database connection, the stream)
        r, fd = c.req_fd("export", sweep=small)
        with os.fdopen(fd, "rb") as sf:
            check(len(sf.read().splitlines()) == 3 + 2, "small export")
        time.sleep(0.2)
        hwm0 = vm(pid, "VmHWM")

        # --- streamed to stdout, and to -o FILE (written by acqctl)
        out1 = os.path.join(d.tmp, "stdout.csv")
        before = run_rss([ACQCTL, "-s", d.sock, "version"], subprocess.DEVNULL)[1]
        t0 = time.time()
        with open(out1, "wb") as f:
            rc, ctl_rss = run_rss([ACQCTL, "-s", d.sock, "export", str(sid)], f)
        t_stream = time.time() - t0
        check(rc == 0, "export > file: rc %d" % rc)
        size = os.path.getsize(out1)
        lines = open(out1).read().splitlines()
        check(len(lines) == NPTS + 2 and lines[1].startswith("theta_i,phi_i,theta_o,phi_o,450,451"), "rows %d" % len(lines))
        check(all(len(x.split(",")) == 4 + 2 * NWL for x in lines[1:]), "every row has every column")
        check(size > 5_000_000, "a paper-size export is several MB (%d)" % size)
        out2 = os.path.join(d.tmp, "o.csv")
        p = subprocess.run([ACQCTL, "-s", d.sock, "--json", "-o", out2, "export", str(sid)], capture_output=True,
                           text=True, timeout=120)
        check(p.returncode == 0, "export -o: %s" % p.stderr)
        rep = json.loads(p.stdout)
        check(rep["ok"] and rep["rows"] == NPTS and rep["bytes"] == size and rep["output"] == out2, "summary %r" % rep)
        check(open(out2, "rb").read() == open(out1, "rb").read(), "-o and stdout give the same bytes")
        # the daemon-side file export gives the same bytes too
        r = c.req("export", sweep=sid, path="paper.csv")
        check(r["ok"] and r["rows"] == NPTS and r["bytes"] == size, "file export %r" % r)
        check(open(r["path"], "rb").read() == open(out1, "rb").read(), "file export bytes")
        hwm1 = vm(pid, "VmHWM")
        grow = hwm1 - hwm0
        print("export of %d rows (%d bytes): streamed in %.2f s; daemon VmHWM +%d kB; acqctl max RSS %d kB (before %d)"
              % (NPTS, size, t_stream, grow, ctl_rss, before))
        # Bounded: the whole CSV held in memory would add its size (11 MB) to one side or the other.
        check(grow < size / 1024 / 2, "daemon peak memory grew by %d kB for a %d kB CSV" % (grow, size // 1024))
        check(ctl_rss - before < size / 1024 / 2, "acqctl max RSS %d kB (version: %d kB) for a %d kB CSV"
              % (ctl_rss, before, size // 1024))
        check(subprocess.run([ACQCTL, "-s", d.sock, "--json", "export", str(sid)], capture_output=True).returncode == 64,
              "export --json without -o is a usage error")

        # --- a client that never reads its stream: the daemon keeps answering others
        r, fd = c.req_fd("export", sweep=sid)
        check(r["ok"] and fd is not None, "stream %r" % r)
        t0 = time.time()
        for _ in range(20):
            check(d.client().req("version")["ok"], "daemon answers while a stream is not read")
        check(time.time() - t0 < 5, "replies while a stream is stalled took %.1f s" % (time.time() - t0))
        os.close(fd)

        # --- daemon-side names: every name of the state directory, SQLite side files, escapes
        c.req("sweep.list")  # make sure -wal/-shm exist
        names = sorted(set(os.listdir(d.state)) | {"acquisition.db-wal", "acquisition.db-shm",
                                                   "acquisition.db-journal", "x.db-journal", "acquisition.db",
                                                   ".", "..", "../acq.yaml", "/etc/passwd", "export/../acquisition.db",
                                                   "export", ".hidden", "-rf", "a/b", "paper.csv", ""})
        before = snapshot(d.state)
        accepted = []
        for name in names:
            r = c.req("export", sweep=sid, path=name)
            if r["ok"]:
                check(r["path"] == os.path.join(d.state, "export", name), "landed outside the export folder: %r" % r)
                accepted.append(name)
            else:
                check(r["error"]["code"] in ("invalid", "state"), "%r: %r" % (name, r))
        check(snapshot(d.state) == before, "a file of the state directory changed")
        for name in ("acquisition.db", "acquisition.db-wal", "acquisition.db-shm", "acquisition.db-journal",
                     "x.db-journal", "paper.csv", "..", "/etc/passwd", "a/b", ""):
            check(name not in accepted, "%r was accepted" % name)
        print("state directory names tried: %d, accepted as new export files: %s" % (len(names), accepted))
        con = sqlite3.connect("file:%s?mode=ro" % db, uri=True)
        check(con.execute("PRAGMA integrity_check").fetchone()[0] == "ok", "database integrity")
        con.close()
        # a symlink planted in the export folder is never followed (O_EXCL|O_NOFOLLOW)
        os.symlink(db, os.path.join(d.state, "export", "planted.csv"))
        r = c.req("export", sweep=sid, path="planted.csv")
        check(not r["ok"] and r["error"]["code"] == "state", "planted link %r" % r)
        check(snapshot(d.state) == before, "a planted link led to the database")
        check(d.stop() == 0, "clean stop")
        d.start(env=env)
        check(d.client().req("sweep.show", sweep=sid)["ok"], "database opens after the exports")
        print("ok: streamed export of %d bytes, confinement of %d names" % (size, len(names)))
    finally:
        d.cleanup()


if __name__ == "__main__":
    main()
