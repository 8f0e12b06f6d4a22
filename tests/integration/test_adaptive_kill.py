#!/usr/bin/python3
"""Crash-resume of an adaptive sweep: acquisitiond is SIGKILLed at random moments (while measuring the seed or a
batch, while a batch is being chosen) and restarted each time (daemon.auto_resume). The sweep must go on from its
recorded decisions and end on its budget with nothing lost and nothing twice: every point recorded before a kill is
still there afterwards with the same row, angles and spectra; every planned point is measured exactly once; no
configuration is planned twice; the batches are contiguous and each batch's points are the ones its picks name.
The plan overlaps each decision with the measurement of the batch before it (overlap: true), so kills also land
while a decision is under way or chosen and not yet recorded. A restart that measured says so with a resume event
(a daemon killed during its own start-up, before it got to resume, owes none: asserting one resume per kill failed
under ASan at load 9, 5 resumes for 6 kills, session 18)."""
import os
import random
import signal
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import adaptlib as A  # noqa: E402
import sweeplib as L  # noqa: E402

BUDGET = 51   # the seed's 15 points + 9 batches of 4 (with 5 batches the sweep once completed before the sixth
              # kill under load: ACQ_SEED=3711987124, house's make check)
KILLS = 6


def snapshot(b, sid):
    """The points done so far: id -> (order_index, measured angles, sorted spectrum ids)."""
    db = b.db()
    try:
        pts = {r[0]: r[1:] for r in db.execute(
            "SELECT id, order_index, m_theta_i, m_phi_i, m_theta_o, m_phi_o FROM points WHERE sweep_id = ? AND "
            "state = 'done'", (sid,))}
        spec = {}
        for pid, sid_ in db.execute("SELECT point_id, id FROM spectra WHERE sweep_id = ? AND point_id IS NOT NULL",
                                    (sid,)):
            spec.setdefault(pid, []).append(sid_)
        planned = {r[0]: r[1:] for r in db.execute(
            "SELECT order_index, theta_i, phi_i, theta_o, phi_o FROM points WHERE sweep_id = ?", (sid,))}
        return {k: v + (tuple(sorted(spec.get(k, []))),) for k, v in pts.items()}, planned
    finally:
        db.close()


def resumes(b, sid):
    """The sweep's resume events so far."""
    db = b.db()
    try:
        return db.execute("SELECT count(*) FROM events WHERE sweep_id = ? AND kind = 'resume'", (sid,)).fetchone()[0]
    finally:
        db.close()


def run():
    rng = random.Random(L.SEED)
    b = A.bench()
    try:
        b.start_sim()
        b.start_daemon()
        sid = L.start_sweep(b, A.plan(budget="points: %d" % BUDGET, overlap=True), "it-adaptive-kill")
        kills, t0, seen = 0, time.time(), []
        before, planned_before = {}, {}
        dead = None  # (points done, resume events) left by the daemon killed last, read before its restart
        while kills < KILLS:
            deadline = time.time() + rng.uniform(0.2, 1.5)
            while time.time() < deadline:
                row = L.sweep_row(b, sid)
                if row["state"] in ("completed", "aborted", "failed"):
                    break
                L.swap_when_asked(b, row, "white")
                time.sleep(0.02)
            if L.sweep_row(b, sid)["state"] in ("completed", "aborted", "failed"):
                break
            before, planned_before = snapshot(b, sid)
            if dead is not None and len(before) > dead[0]:
                # the restarted daemon measured: it must have resumed the sweep, and said so (a daemon killed
                # before it got to resume -- a loaded machine's slow start -- measures nothing and owes no event)
                assert resumes(b, sid) > dead[1], "points measured after restart %d without a resume event" % kills
            b.kill_daemon(signal.SIGKILL)
            kills += 1
            after, planned_after = snapshot(b, sid)  # what the dead daemon left
            assert after == before or set(before) <= set(after), "points lost at the kill"
            seen.append((len(after), len(planned_after)))
            dead = (len(after), resumes(b, sid))
            b.start_daemon(wait_devices=False)
            now, planned_now = snapshot(b, sid)
            for pid, v in after.items():
                assert now.get(pid) == v, "point %d changed by the restart: %s -> %s" % (pid, v, now.get(pid))
            for oi, v in planned_after.items():
                assert planned_now.get(oi) == v, "planned point %d changed by the restart" % oi
        L.say("%d kills at (done, planned) points %s" % (kills, seen))
        row = L.drive_to_end(b, sid, timeout=240, sample="white")
        L.say("sweep %s after %.1f s" % (row["state"], time.time() - t0))
        assert row["state"] == "completed", "sweep ended %s" % row["state"]
        assert kills == KILLS, "the sweep completed after only %d kills: make it longer" % kills
        final, planned = snapshot(b, sid)
        for pid, v in before.items():
            assert final.get(pid) == v, "point %d recorded before the last kill changed: %s -> %s" % (pid, v, final.get(pid))
        n, _ = L.check_points(b, sid, max_exposures=1)
        rows, why = A.check_decisions(b, sid)
        A.no_repeats(b, sid)
        assert why.startswith("budget spent") and n == BUDGET, "stopped after %d points: %s" % (n, why)
        nres = resumes(b, sid)
        L.say("%d points, %d batches after %d kills (%d resume events): %s" % (n, len(rows) - 2, kills, nres, why))
        assert nres > dead[1], "the last restart finished the sweep without a resume event"
        # overlap: some batch was chosen while the one before it was being measured (the daemon logs each such start)
        ahead = b.daemon_text().count("overlapping the measurement of the batch before it")
        L.say("%d decisions started while a batch was being measured" % ahead)
        assert ahead >= 1, "overlap: true, but no decision started while a batch was measured"
    finally:
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")


if __name__ == "__main__":
    L.main(run)
