#!/usr/bin/python3
"""Crash-resume: acquisitiond is killed with SIGKILL at 20 random moments of a sweep on the simulated bench and
restarted each time (daemon.auto_resume); the sweep must end complete with zero lost or duplicated points, no
spectra left on unfinished points, and PRAGMA integrity_check ok. The start-up resume plans in a worker after the
daemon is ready: a restart runs until the sweep is loaded again before its random while, except every fifth,
killed at once (inside the start-up planning when it is still on its way); every restart that got its sweep
loaded must have recorded a resume."""
import os
import random
import signal
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

PLAN = L.PLAN_3X18

KILLS = 20


def run():
    rng = random.Random(L.SEED)
    with L.Bench(scale=20) as b:
        b.start_sim()
        b.start_daemon()
        sid = L.start_sweep(b, PLAN, "it-crash")
        total = L.sweep_row(b, sid)["points_total"]
        kills, early, t0 = 0, 0, time.time()
        done_at_kill = []
        while kills < KILLS:
            if kills % 5 == 4 and kills < KILLS - 1:  # at once: maybe while the start-up resume is planned
                b.kill_daemon(signal.SIGKILL)
                kills += 1
                early += 1
                done_at_kill.append(-1)
                b.start_daemon(wait_devices=False)
            if kills:  # until the start-up resume has loaded the sweep again
                c = b.client()
                t1 = time.time()
                while c.req("status")["sweep"]["id"] != sid and L.sweep_row(b, sid)["state"] not in (
                        "completed", "aborted", "failed"):
                    assert time.time() - t1 < 60, "sweep %d not resumed 60 s after a restart:\n%s" % (
                        sid, b.daemon_text()[-3000:])
                    time.sleep(0.02)
                c.close()
            # run for a random while (the operator's sample swap included), then SIGKILL
            deadline = time.time() + rng.uniform(0.05, 0.3)
            while time.time() < deadline:
                row = L.sweep_row(b, sid)
                if row["state"] in ("completed", "aborted", "failed"):
                    break
                if row["state"] == "paused":
                    ev = [e for e in row.get("events", []) if e.get("kind") in ("pause", "resume", "start", "stop")]
                    if ev and ev[0]["kind"] == "pause" and "place the sample" in (ev[0].get("message") or ""):
                        b.ctl("sample green-paint")
                        c = b.client()
                        c.req("sweep.resume")
                        c.close()
                time.sleep(0.02)
            if L.sweep_row(b, sid)["state"] in ("completed", "aborted", "failed"):
                break
            b.kill_daemon(signal.SIGKILL)
            kills += 1
            db = b.db()
            done_at_kill.append(db.execute("SELECT count(*) FROM points WHERE sweep_id = ? AND state = 'done'",
                                           (sid,)).fetchone()[0])
            db.close()
            b.start_daemon(wait_devices=False)
        L.say("%d kills at %s points done (of %d; -1: killed at once after the restart)" % (
            kills, done_at_kill, total))
        row = L.drive_to_end(b, sid, timeout=180)
        L.say("sweep %s after %.1f s" % (row["state"], time.time() - t0))
        assert row["state"] == "completed", "sweep ended %s" % row["state"]
        assert kills == KILLS, "the sweep completed after only %d kills: make it longer" % kills
        n, cal = L.check_points(b, sid)
        db = b.db()
        resumes = db.execute("SELECT count(*) FROM events WHERE sweep_id = ? AND kind = 'resume'", (sid,)).fetchone()[0]
        refs = db.execute("SELECT count(*) FROM events WHERE sweep_id = ? AND kind = 'reference'", (sid,)).fetchone()[0]
        db.close()
        L.say("points %d, calibrated %d, resume events %d, reference measurements %d" % (n, cal, resumes, refs))
        assert resumes >= kills - early, "fewer resumes (%d) than kills after a resume (%d)" % (resumes, kills - early)
        zs, nan = L.zscores(b, sid)
        import numpy as np
        z = np.array(zs)
        L.say("z-scores after the crashes: %d values, mean %.3f, std %.3f" % (len(z), z.mean(), z.std()))
        assert abs(z.mean()) < 0.3 and 0.6 < z.std() < 1.6, "calibration spoiled by the restarts"


L.main(run)
