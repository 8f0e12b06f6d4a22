"""Shared by the adaptive-sweep tests (test_adaptive*.py): a small adaptive plan, the sweep run on the simulated bench
(sweeplib), and the checks every adaptive sweep must pass in the database: decisions stored batch after batch,
every point of a batch measured once, picks that are visible, the stop and its reason."""
import math
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

# A small seed (2 incidences x 8 directions, the blind ones dropped) and few candidates keep a sweep to seconds at
# time scale 20; fixed 5 ms integration, one average.
PLAN = """name: it-adaptive
kind: adaptive
seed:
  incidence: {theta_deg: [8, 40]}
  observation: {fibonacci: {count: 8, max_theta_deg: 75}}
target: {%(target)s}
budget: {%(budget)s}
batch: %(batch)d
overlap: %(overlap)s
candidates: {%(cands)s}
integration: {mode: fixed, ms: 5}
averages: 1
"""


def plan(target="dhr_sigma: {incidence_deg: [8], le: 1.0e-9}", budget="points: 24", batch=4,
         cands="incidence_deg: [8, 25, 40, 55], per_incidence: 30", overlap=False):
    return PLAN % {"target": target, "budget": budget, "batch": batch, "cands": cands,
                   "overlap": "true" if overlap else "false"}


def bench(scale=20):
    b = L.Bench(scale=scale)
    recon = os.environ.get("ACQ_ADAPTIVE_RECON")  # another brdf-recon build to run against (default: build/'s)
    if recon:
        with open(b.conf, "a") as f:
            f.write("recon:\n  program: %s\n" % recon)
    return b


def batches(b, sid):
    db = b.db()
    try:
        cols = ("batch", "first_order_index", "n_points", "target_spec", "target_value", "target_met", "model",
                "criterion", "warm", "candidates", "predicted_s", "waited_s", "stop_reason")
        rows = [dict(zip(cols, r)) for r in db.execute(
            "SELECT %s FROM adaptive_batches WHERE sweep_id = ? ORDER BY batch" % ", ".join(cols), (sid,))]
        for r in rows:
            r["picks"] = [dict(zip(("rank", "candidate_id", "order_index", "laser_theta", "detector_theta",
                                    "detector_phi", "gain", "cost_s"), p)) for p in db.execute(
                "SELECT rank, candidate_id, order_index, laser_theta, detector_theta, detector_phi, gain, cost_s "
                "FROM adaptive_picks WHERE sweep_id = ? AND batch = ? ORDER BY rank", (sid, r["batch"]))]
        return rows
    finally:
        db.close()


def psi_deg(lt, dt, dp, laser_phi=0.0):
    """Great-circle angle between the incident and observed directions of an arm configuration."""
    def v(t, p):
        t, p = math.radians(t), math.radians(p)
        return (math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))
    a, c = v(lt, laser_phi), v(dt, dp)
    return math.degrees(math.acos(max(-1.0, min(1.0, sum(x * y for x, y in zip(a, c))))))


def blind_limit(b):
    """The largest blind-zone half-angle of the bench (the planner's (a), (b), (c) with the margin), from the
    dry run of a probe plan: the smallest ψ the planner keeps must be above it; read from bench-sim.yaml."""
    import re
    text = open(os.path.join(L.SRC, "config", "bench-sim.yaml")).read()
    num = lambda k: float(re.search(r"\b%s:\s*([0-9.eE+-]+)" % k, text).group(1))
    m = num("safety_margin_deg")
    lim = num("laser_body_halfwidth_deg") + num("detector_body_halfwidth_deg") + m
    if num("detector_radius_mm") < num("laser_radius_mm"):
        lim = max(lim, num("detector_body_halfwidth_deg") + num("beam_halfwidth_deg") + m)
    if num("laser_radius_mm") < num("detector_radius_mm"):
        lim = max(lim, num("laser_body_halfwidth_deg") + num("fov_halfwidth_deg") + m)
    return lim


def check_decisions(b, sid):
    """The decisions as stored: batch 0 the seed, then contiguous batches whose points are the sweep's next
    order indices, each measured by exactly one pick, picks visible, one final row with the stop reason.
    Returns (rows, stop_reason)."""
    rows = batches(b, sid)
    assert rows and rows[0]["batch"] == 0 and rows[0]["first_order_index"] == 0, "no seed decision: %s" % rows[:1]
    assert [r["batch"] for r in rows] == list(range(len(rows))), "batches not contiguous: %s" % [r["batch"] for r in rows]
    nxt = rows[0]["n_points"]
    lim = blind_limit(b)
    for r in rows[1:]:
        assert r["first_order_index"] == nxt, "batch %d starts at %d, expected %d" % (r["batch"], r["first_order_index"], nxt)
        if r["stop_reason"] is None:
            assert r["model"] and r["target_value"] is not None and r["candidates"] > 0, r
            measured = sorted(p["order_index"] for p in r["picks"] if p["order_index"] is not None)
            assert measured == list(range(nxt, nxt + r["n_points"])), \
                "batch %d: picks measured at %s, points %d..%d" % (r["batch"], measured, nxt, nxt + r["n_points"] - 1)
            for p in r["picks"]:
                psi = psi_deg(p["laser_theta"], p["detector_theta"], p["detector_phi"])
                assert psi > lim, "batch %d pick %d in a blind zone: psi %.2f <= %.2f" % (r["batch"], p["rank"], psi, lim)
        nxt += r["n_points"]
    finals = [r for r in rows if r["stop_reason"] is not None]
    assert len(finals) == 1 and finals[0] is rows[-1] and rows[-1]["n_points"] == 0, \
        "not exactly one final row with the stop reason: %s" % [(r["batch"], r["stop_reason"]) for r in rows]
    db = b.db()
    total = db.execute("SELECT points_total FROM sweeps WHERE id = ?", (sid,)).fetchone()[0]
    db.close()
    assert total == nxt, "points_total %d, batches %d" % (total, nxt)
    return rows, rows[-1]["stop_reason"]


def no_repeats(b, sid):
    """No configuration planned twice (a batch never repeats a measured point)."""
    db = b.db()
    rows = db.execute("SELECT round(theta_i, 6), round(phi_i, 6), round(theta_o, 6), round(phi_o, 6) FROM points "
                      "WHERE sweep_id = ?", (sid,)).fetchall()
    db.close()
    assert len(rows) == len(set(rows)), "%d points, %d distinct configurations" % (len(rows), len(set(rows)))


def completes(b, sid, timeout=240):
    """Drive sweep sid to its end (white on the stage when asked); it must complete, its decisions check
    (check_decisions), its points carry one exposure each and no configuration repeats: (rows, stop reason, points)."""
    row = L.drive_to_end(b, sid, timeout=timeout, sample="white")
    assert row["state"] == "completed", row["state"]
    rows, why = check_decisions(b, sid)
    n, _ = L.check_points(b, sid, max_exposures=1)
    no_repeats(b, sid)
    return rows, why, n


def reconstructs(b, sid):
    """The finished sweep reconstructs like any other: the daemon's chain succeeded, and brdf-recon fits it from
    the database and from its CSV export (one row per done point) to the same model."""
    import time
    t0 = time.time()
    while True:
        c = b.client()
        r = c.req("recon.status", sweep=sid)
        c.close()
        run = r.get("run") or {}
        if run.get("state") not in (None, "running") or time.time() - t0 > 90:
            break
        time.sleep(0.2)
    assert run.get("state") == "succeeded", "the completion chain: %s" % r
    out = os.path.join(b.dir, "db.model")
    p = subprocess.run([os.path.join(L.BUILD, "brdf-recon"), "fit", "--db", b.db_path(), "--sweep", str(sid), "-o", out],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, "brdf-recon fit --db: %s" % p.stderr[-2000:]
    csv = os.path.join(b.dir, "export.csv")
    p = subprocess.run([os.path.join(L.BUILD, "acqctl"), "-s", b.sock, "export", str(sid), "-o", csv],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, "acqctl export: %s" % (p.stderr or p.stdout)
    rows = sum(1 for line in open(csv) if line[:1].isdigit())
    db = b.db()
    done = db.execute("SELECT count(*) FROM points WHERE sweep_id = ? AND state = 'done'", (sid,)).fetchone()[0]
    db.close()
    assert rows == done, "CSV export %d rows, %d points done" % (rows, done)
    p = subprocess.run([os.path.join(L.BUILD, "brdf-recon"), "fit", csv, "-o", out + "2"], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0, "brdf-recon fit CSV: %s" % p.stderr[-2000:]
    # the same model both ways: evaluated at 60 fixed direction pairs (incidences 0-70°, observations 0-80°, every
    # azimuth), the two agree to 1e-6 relative (the export prints the database's float32 values with 9 significant
    # digits, which read back exactly; test_recon_db's bound is 1e-7 on synthetic data)
    q = os.path.join(b.dir, "query.csv")
    with open(q, "w") as f:
        f.write("theta_i,phi_i,theta_o,phi_o\n")
        for k in range(60):
            f.write("%.6f,%.6f,%.6f,%.6f\n" % (70.0 * (k % 7) / 6, 0.0, 80.0 * ((k * 5) % 11) / 10, (k * 137.5) % 360))
    vals = []
    for m in (out, out + "2"):
        p = subprocess.run([os.path.join(L.BUILD, "brdf-recon"), "eval", m, q], capture_output=True, text=True,
                           timeout=120)
        assert p.returncode == 0, "brdf-recon eval %s: %s" % (m, p.stderr[-2000:])
        vals.append([[float(x) for x in ln.split(",")[4:]] for ln in p.stdout.splitlines()[1:] if ln.strip()])
    worst = max(abs(x - y) / max(abs(y), 1e-30) for ra, rb in zip(*vals) for x, y in zip(ra, rb))
    assert len(vals[0]) == len(vals[1]) == 60 and len(vals[0][0]) == len(vals[1][0]) > 0 and worst <= 1e-6, \
        "the fit from the database and from the CSV export differ: %d x %d vs %d x %d values, worst %.3g relative" % (
            len(vals[0]), len(vals[0][0]) if vals[0] else 0, len(vals[1]), len(vals[1][0]) if vals[1] else 0, worst)
    L.say("reconstructs: brdf-recon fit from the database and from the CSV export (%d rows) agree to %.2g "
          "relative at 60 pairs x %d wavelengths" % (rows, worst, len(vals[0][0])))
