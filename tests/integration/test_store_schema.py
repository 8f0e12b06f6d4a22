#!/usr/bin/python3
"""Integration: the database acquisitiond creates — read with the sqlite3 CLI and Python's sqlite3:
application_id, user_version, WAL, integrity, and exactly the schema documented in daemon/schema.sql; a
foreign SQLite file, a corrupt file and a newer-schema database are refused at start-up with a clear
message and left byte-identical."""
import hashlib
import os
import random
import shutil
import sqlite3
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from acqtest import DAEMON, SRC, Daemon, check  # noqa: E402


def schema_of(con):
    return sorted((t, n, " ".join(s.split())) for t, n, s in
                  con.execute("SELECT type, name, sql FROM sqlite_master WHERE sql IS NOT NULL"))


def digest(p):
    return hashlib.sha256(open(p, "rb").read()).hexdigest()


def refused(d, db, words):
    before = digest(db)
    p = subprocess.run([DAEMON, "-f", "-c", d.conf], capture_output=True, text=True, timeout=20)
    check(p.returncode == 1, "daemon must refuse %s (rc %d): %s" % (db, p.returncode, p.stderr))
    check(all(w in p.stderr for w in words), "message for %s: %s" % (db, p.stderr))
    check(digest(db) == before, "%s was modified" % db)
    check(not os.path.exists(db + "-wal") and not os.path.exists(db + "-shm"), "%s got a -wal/-shm file" % db)
    check(not os.path.exists(d.sock), "socket left behind")


def main():
    have_cli = shutil.which("sqlite3") is not None
    with Daemon() as d:
        d.start()
        c = d.client()
        check(c.req("version")["schema"] == 6, "schema version over the protocol")
        c.close()
        db = os.path.join(d.state, "acquisition.db")
        check(d.stop() == 0, "clean stop")
        if have_cli:
            out = subprocess.run(["sqlite3", db, "PRAGMA application_id; PRAGMA user_version; PRAGMA journal_mode; "
                                  "PRAGMA integrity_check;"], capture_output=True, text=True).stdout.split()
            check(out == [str(0x42524446), "6", "wal", "ok"], "sqlite3 CLI: %r" % out)
            tables = subprocess.run(["sqlite3", db, ".tables"], capture_output=True, text=True).stdout.split()
            for t in ("sweeps", "points", "spectra", "spectrometers", "devices", "calibrated", "recon_runs",
                      "recon_outputs", "events", "sweep_devices", "adaptive_batches", "adaptive_picks", "sweep_samples"):
                check(t in tables, "table %s missing (%r)" % (t, tables))
        else:
            check(False, "the sqlite3 CLI is absent (a make deps package): its checks cannot run")
        con = sqlite3.connect(db)
        check(con.execute("PRAGMA application_id").fetchone()[0] == 0x42524446, "application_id")
        check(con.execute("PRAGMA user_version").fetchone()[0] == 6, "user_version")
        ref = sqlite3.connect(":memory:")
        ref.executescript(open(os.path.join(SRC, "daemon", "schema.sql")).read())
        check(schema_of(con) == schema_of(ref), "database schema differs from daemon/schema.sql")
        check("plan_kind" in [r[1] for r in con.execute("PRAGMA table_info(sweeps)")], "sweeps.plan_kind (schema 6)")
        # The CHECK constraints hold: a spectrum whose blob does not match npix is rejected.
        try:
            con.execute("INSERT INTO spectra (kind, integration_ms, averages, npix, counts, taken_at) "
                        "VALUES ('sample', 1, 1, 4, x'00', 0)")
            check(False, "length check not enforced")
        except sqlite3.IntegrityError:
            pass
        con.close()
        # Restart on the same database: reopened, not recreated.
        con = sqlite3.connect(db)
        con.execute("INSERT INTO events (at, kind, message) VALUES (1, 'info', 'marker')")
        con.commit()
        con.close()
        d.start()
        d.stop()
        con = sqlite3.connect(db)
        check(con.execute("SELECT count(*) FROM events WHERE message = 'marker'").fetchone()[0] == 1, "kept")
        con.close()

        # Foreign, corrupt, newer: refused, untouched.
        os.remove(db)
        for f in os.listdir(d.state):
            if f.startswith("acquisition.db"):
                os.remove(os.path.join(d.state, f))
        con = sqlite3.connect(db)
        con.execute("CREATE TABLE photos (id INTEGER PRIMARY KEY, name TEXT)")
        con.execute("INSERT INTO photos (name) VALUES ('holiday')")
        con.commit()
        con.close()
        refused(d, db, [db, "not an acquisitiond database", "left as is"])
        rng = random.Random(int(os.environ.get("ACQ_SEED", "1")))
        with open(db, "wb") as f:
            f.write(b"SQLite format 3\x00" + bytes(rng.randrange(256) for _ in range(4000)))
        refused(d, db, [db, "refusing"])
        # A corrupt file whose header claims WAL mode (bytes 18, 19 = 2) and a valid page size.
        with open(db, "wb") as f:
            f.write(b"SQLite format 3\x00" + bytes([0x10, 0x00, 2, 2]) + bytes(rng.randrange(256) for _ in range(8188)))
        refused(d, db, [db, "refusing"])
        with open(db, "wb") as f:
            f.write(b"\x00garbage\xff" * 1000)
        refused(d, db, [db, "refusing"])
        os.remove(db)
        con = sqlite3.connect(db)
        con.execute("PRAGMA application_id = %d" % 0x42524446)
        con.execute("PRAGMA user_version = 99")
        con.execute("CREATE TABLE future (x)")
        con.commit()
        con.close()
        refused(d, db, [db, "schema version 99 is newer"])
        # --check-config does not touch the database at all
        p = subprocess.run([DAEMON, "--check-config", d.conf], capture_output=True, text=True)
        check(p.returncode == 0 and "ok" in p.stdout, "check-config %r" % p.stdout)
        print("ok: schema matches daemon/schema.sql; foreign, corrupt and newer databases refused untouched")


if __name__ == "__main__":
    main()
