#!/usr/bin/python3
"""Crash windows of the sweep state machine: acquisitiond is SIGKILLed right after each named durable step
(ACQ_CRASH_AT=STEP:N: start, reference, the pause for the sample swap, the operator's resume, a committed point,
a device fault, complete, a reconstruction stage started) and restarted (daemon.auto_resume) each time; the sweep must end complete with every point once,
integrity ok, and a restart after the reference must ask for the sample swap again before measuring any point
(before the fix it resumed "after point 0 (reference reloaded)" and measured the white standard as the sample); killed
between the reference's spectra and their marker (reference_stored, inside the executor's commit), the sweep is
already paused in the database.
A daemon killed while `brdf-recon fit` runs leaves no child behind (PR_SET_PDEATHSIG), the run is marked
interrupted at the next start (not left `running`), and `recon start` is accepted again once, refused while
that one runs. The random-time kills are tests/integration/test_sweep_crash.py."""
import os
import signal
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

PLAN = """name: it-step-kill
incidence:
  theta_deg: [20, 50]
observation:
  theta_deg: [30, 60]
  phi_deg: [0, 90, 180]
integration: {mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000}
averages: 2
blind_points: drop
"""


def start_with(b, step):
    env = dict(os.environ)
    env.pop("ACQ_CRASH_AT", None)
    if step:
        env["ACQ_CRASH_AT"] = step
    log = open(b.daemon_log, "ab")
    import subprocess
    b.daemon = subprocess.Popen([L.DAEMON, "-f", "-c", b.conf, "--sim", b.ports], stdout=log,
                                stderr=subprocess.STDOUT, env=env)
    t0 = time.time()
    while True:
        if b.daemon.poll() is not None:
            return  # may die at once (a step reached during start-up)
        try:
            L.Client(b.sock, 2).close()
            return
        except (OSError, EOFError):  # EOF: killed between accepting this connection and its banner
            if time.time() - t0 > 15:
                raise AssertionError("acquisitiond did not listen in 15 s")
            time.sleep(0.02)


def wait_killed(b, step, timeout=60):
    try:
        rc = b.daemon.wait(timeout)
    except Exception:
        raise AssertionError("the daemon was not killed at %s within %d s; log tail:\n%s" % (
            step, timeout, b.daemon_text()[-3000:]))
    assert rc == -signal.SIGKILL, "daemon exited %s, not SIGKILLed at %s" % (rc, step)
    b.daemon = None
    L.say("killed at %s" % step)


def last_pause(row):
    ev = [e for e in row.get("events", []) if e.get("kind") in ("pause", "resume", "start", "stop")]
    return ev[0] if ev and ev[0]["kind"] == "pause" else None


def wait_state(b, sid, states, timeout=60):
    t0 = time.time()
    while time.time() - t0 < timeout:
        row = L.sweep_row(b, sid)
        if row["state"] in states:
            return row
        time.sleep(0.05)
    raise AssertionError("sweep %d not %s after %d s: %s" % (sid, states, timeout, row["state"]))


def resume(b):
    c = b.client()
    r = c.req("sweep.resume")
    c.close()
    assert r.get("ok"), "sweep.resume: %s" % r


def done_points(b, sid):
    db = b.db()
    n = db.execute("SELECT count(*) FROM points WHERE sweep_id = ? AND state = 'done'", (sid,)).fetchone()[0]
    db.close()
    return n


def run():
    cfg = open(os.path.join(L.SRC, "config", "bench-sim.yaml")).read()
    sweep = cfg[cfg.index("\nsweep:") + 1:]
    sweep = L.strip_sections(sweep.replace("auto_recon: true", "auto_recon: false"), {"recon", "daemon"})
    # The reconstruction program: a stand-in that runs long enough to be killed with the daemon (the real
    # brdf-recon fit of 10 points may end before the kill lands).
    import tempfile
    slow = tempfile.NamedTemporaryFile("w", suffix=".sh", delete=False, dir="/tmp")
    slow.write("#!/bin/sh\nexec sleep 60\n")
    slow.close()
    os.chmod(slow.name, 0o755)
    sweep += "recon:\n  program: %s\n  timeout_s: 120\n" % slow.name
    b = L.Bench(scale=20, sweep_yaml=sweep)
    try:
        b.start_sim()
        b.ctl("sample white")
        # 1. right after the start event
        start_with(b, "start:1")
        b.wait_devices()
        c = b.client()
        try:
            c.req("sweep.start", plan=PLAN, name="it-step-kill")
        except (EOFError, OSError):
            pass  # killed before its reply
        c.close()
        wait_killed(b, "start")
        db = b.db()
        sid = db.execute("SELECT max(id) FROM sweeps").fetchone()[0]
        db.close()
        assert sid, "no sweep stored before the kill at start"
        # 2a. between the reference's spectra and its marker (the "reference" event that lists them): the sweep is
        # already paused in the database, so the swap step is durable from the spectra on
        start_with(b, "reference_stored:1")
        wait_killed(b, "reference_stored")
        db = b.db()
        state = db.execute("SELECT state FROM sweeps WHERE id = ?", (sid,)).fetchone()[0]
        nref = db.execute("SELECT count(*) FROM spectra WHERE sweep_id = ? AND point_id IS NULL AND kind = "
                          "'reference'", (sid,)).fetchone()[0]
        marks = db.execute("SELECT count(*) FROM events WHERE sweep_id = ? AND kind = 'reference'",
                           (sid,)).fetchone()[0]
        db.close()
        L.say("killed between the reference's spectra and its marker: sweep %s, %d reference spectra, %d markers" % (
            state, nref, marks))
        assert nref >= 1 and marks == 0, "not the window: %d reference spectra, %d markers" % (nref, marks)
        assert state == "paused", "the sweep is %s in the database with its reference stored: the sample swap " \
            "is not a durable state from the reference's spectra on" % state
        # 2b. right after the reference is committed (before its pause: the window of the defect); the reference
        # is measured again (its first spectra have no marker)
        start_with(b, "reference:1")
        wait_killed(b, "reference")
        # 3. restarted: it must ask for the swap again, with no point measured
        start_with(b, "pause:1")
        wait_killed(b, "the swap prompt (pause)")
        start_with(b, None)
        row = wait_state(b, sid, ("paused",))
        p = last_pause(row)
        L.say("after the kills at reference and pause: %s, %d points done, last pause: %s" % (
            row["state"], done_points(b, sid), p and p.get("message")))
        assert done_points(b, sid) == 0, "points measured before the sample swap"
        assert p and "place the sample" in p.get("message", ""), "no swap prompt after the restart: %s" % p
        b.kill_daemon(signal.SIGTERM)
        # 4. the operator swaps and resumes; killed right after that resume (before any point)
        b.ctl("sample green-paint")
        start_with(b, "resume:2")  # resume 1 is the restart's own
        wait_state(b, sid, ("paused",))
        try:
            resume(b)
        except (EOFError, OSError):
            pass  # killed before its reply
        wait_killed(b, "the operator's resume")
        # 5. asked again (no point committed yet); then killed after the second committed point
        start_with(b, "point:2")
        row = wait_state(b, sid, ("paused",))
        assert "place the sample" in (last_pause(row) or {}).get("message", ""), "no swap prompt after kill 4"
        resume(b)
        wait_killed(b, "point 2")
        n2 = done_points(b, sid)
        assert n2 >= 1, "no point committed before the kill at point 2"
        # 5b. killed right after a device fault is recorded (the "fault" step: the connection to the detector's
        # controller dropped mid-sweep, its event committed, the recovery not yet done)
        start_with(b, "fault:1")
        b.ctl("fault drop-connection detector")
        wait_killed(b, "a device fault", timeout=120)
        db = b.db()
        nf = db.execute("SELECT count(*) FROM events WHERE sweep_id = ? AND kind = 'fault'", (sid,)).fetchone()[0]
        db.close()
        L.say("killed after a device fault: %d fault event(s), %d points done" % (nf, done_points(b, sid)))
        assert nf >= 1, "no fault event stored before the kill at fault"
        assert done_points(b, sid) >= n2, "points lost across the kill at the fault"
        # 6. killed right after completion
        start_with(b, "complete:1")
        wait_killed(b, "complete", timeout=120)
        start_with(b, None)
        row = L.drive_to_end(b, sid, timeout=60, swap=False)
        assert row["state"] == "completed", "sweep ended %s" % row["state"]
        n, cal = L.check_points(b, sid)
        db = b.db()
        refs = db.execute("SELECT count(*) FROM events WHERE sweep_id = ? AND kind = 'reference'", (sid,)).fetchone()[0]
        db.close()
        L.say("completed: %d points, %d calibrated, %d reference measurement(s)" % (n, cal, refs))
        assert refs == 1, "the reference was measured %d times (it was committed before the kills)" % refs

        # 7. killed while the reconstruction's first stage runs
        b.kill_daemon(signal.SIGTERM)
        start_with(b, "recon:2")  # recon 1: samples exported; recon 2: brdf-recon fit started (pid N)
        c = b.client()
        try:
            c.req("recon.start", sweep=sid)
        except (EOFError, OSError):
            pass
        c.close()
        wait_killed(b, "brdf-recon fit started")
        db = b.db()
        msg = db.execute("SELECT message FROM events WHERE sweep_id = ? AND message LIKE 'brdf-recon fit started%' "
                         "ORDER BY id DESC LIMIT 1", (sid,)).fetchone()
        db.close()
        assert msg, "no 'brdf-recon fit started' event"
        pid = int(msg[0].split("pid ")[1].rstrip(")"))

        def alive(p):
            try:
                with open("/proc/%d/status" % p) as f:
                    return "\tZ" not in [l for l in f if l.startswith("State:")][0]
            except OSError:
                return False
        t0 = time.time()
        while alive(pid) and time.time() - t0 < 5:
            time.sleep(0.01)
        L.say("brdf-recon fit (pid %d) %s %.3f s after the daemon's SIGKILL" % (
            pid, "still ALIVE" if alive(pid) else "gone", time.time() - t0))
        assert not alive(pid), "the reconstruction child outlived the daemon"
        assert time.time() - t0 < 2, "the child was still there after the kill"
        start_with(b, None)
        db = b.db()
        rows = db.execute("SELECT id, state, output FROM recon_runs WHERE sweep_id = ?", (sid,)).fetchall()
        db.close()
        L.say("after the restart: runs %s" % [(r[0], r[1], (r[2] or "")[:40]) for r in rows])
        assert rows and all(r[1] != "running" for r in rows), "a run left running: %s" % rows
        assert rows[-1][1] == "interrupted" and rows[-1][2].startswith("interrupted"), \
            "the run is not marked interrupted: %s" % (rows[-1],)
        c = b.client()
        r1 = c.req("recon.start", sweep=sid)
        r2 = c.req("recon.start", sweep=sid)
        c.close()
        L.say("recon start again: %s; while it runs: %s" % (r1.get("ok"), r2.get("error", {}).get("message")))
        assert r1.get("ok"), "recon start refused after the restart: %s" % r1
        assert not r2.get("ok") and "already running" in r2["error"]["message"], "second recon start: %s" % r2
    finally:
        b.cleanup(keep=os.environ.get("ACQ_KEEP") == "1")
        os.unlink(slow.name)


L.main(run)
