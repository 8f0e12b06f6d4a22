#!/usr/bin/python3
"""Defect 9 of issue 15: a database that carries acquisitiond's application_id but user_version 0 (with tables,
or without) was not written by acquisitiond (which sets both in one transaction): the daemon refuses to start
on it, says why, and leaves the file byte for byte as it was (before the fix it was migrated in place)."""
import hashlib
import os
import sqlite3
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import acqtest as A  # noqa: E402

APP_ID = 0x42524446  # "BRDF", daemon/store.h


def digest(path):
    h = hashlib.sha256()
    for p in (path, path + "-wal", path + "-shm", path + "-journal"):
        if os.path.exists(p):
            h.update(p.encode() + open(p, "rb").read())
    return h.hexdigest()


def main():
    for tables in (True, False):
        d = A.Daemon()
        try:
            os.makedirs(d.state, exist_ok=True)
            db = os.path.join(d.state, "acquisition.db")
            c = sqlite3.connect(db)
            c.execute("PRAGMA application_id = %d" % APP_ID)
            if tables:
                c.execute("CREATE TABLE notes (id INTEGER PRIMARY KEY, text TEXT)")
                c.execute("INSERT INTO notes (text) VALUES ('someone else''s data')")
            else:
                c.execute("CREATE TABLE t (x)")  # a non-empty file; then dropped: no table left
                c.execute("DROP TABLE t")
            c.commit()
            c.close()
            before = digest(db)
            d.start(wait=False)
            try:
                rc = d.proc.wait(20)
            except Exception:
                d.stop()
                rc = 0  # still running after 20 s: it accepted the file
            log = d.logtext()
            print("our application_id, user_version 0, %s: exit %d: %s" % (
                "a foreign table" if tables else "no table", rc, log.strip().splitlines()[-1] if log.strip() else ""))
            A.check(rc != 0, "the daemon started on a foreign database")
            A.check("no schema version" in log, "the refusal does not say why: %s" % log[-500:])
            A.check(digest(db) == before, "the foreign database was modified")
        finally:
            d.cleanup()


A.run_main(main)
