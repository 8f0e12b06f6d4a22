#!/usr/bin/python3
"""make bench: the planner's predicted sweep time against the simulated bench, and the live ETA's error.

For each case (plan, time scale), acq-sim + acquisitiond run the sweep the way an operator does (white reference,
pause, sample, resume) while `acqctl watch` (JSON lines) records every progress event. Reported:
- predicted: `acqctl plan --json` predicted_s (bench seconds; reference, darks and executor overheads included);
- measured: bench seconds from the sweep's start to its completion as the daemon recorded them (sweeps.started_at,
  finished_at: wall clock), the operator's pause (pause to resume events) taken out, times the time scale;
- the ETA's error at 25, 50 and 75 % of the points: (eta_s at that point) / (wall seconds actually left to the
  daemon's finished_at) - 1.
Cases: the small plan (config/plan-quick.yaml) with fixed integration at time scales 1 and 10, with auto
integration at time scale 1 (its estimate 20 ms), then again on the same bench (`-repeat`: an operator repeating
a sample; the plans name it, sample: green-paint, so the repeat is timed from the first sweep's exposures, the
exposure prior; the repeat starts once the first sweep's automatic reconstruction has ended, see wait_recon); the
paper's 10x10x10 (auto, estimate 50 ms) at the demo's time scale 35, and its repeat. BENCH_DURATION_QUICK=1: the
small fixed one only;
BENCH_DURATION_CASES=a,b: those cases (name@scale for one time scale; name a repeat with the case before it).
BENCH_DURATION_SAMPLE=MATERIAL: that simulator material is placed after the reference (default green-paint).
BENCH_DURATION_SURVEY=K: the auto plans measure K points per incidence first (plan key survey:; -1: 6 where the
prior lacks an incidence, so a first sweep's and not its repeat's; 0 or unset: none); the ETA right after the survey
is reported with the 25/50/75 % checkpoints.
BENCH_DURATION_LOG=debug: the daemon logs at that level (debug: a stall line per point: where the host's time went).
Also reported: the simulator's own lag (acq-sim ctl status lag_s: its 1 ms waits ending late, the host not keeping
the time scale) over the sweep and its share of the measured time; the host's time per point (host_per_point: real
seconds its exposures and planned move do not account for) against the model's; per ETA checkpoint the ETA's error
had the host's time per point of the rest been known (host_known): what is left is the model's, the difference the
host's. Also: the host's part of the prediction (host_s: point_overhead_s x time scale per
point, load-dependent),
the residual per point (real seconds beyond the model's bench part), the load average, the prediction's interval
where the exposures are unknown (acqctl plan's interval: a first sweep's, or incidences its prior has not measured)
and whether it covers the measured time, the ETA's interval at 25/50/75 % (eta_low_s, eta_high_s) against the time
left, the faults the sweep
recovered from (not in the model) and the exposure prior used. On a shared machine the
script runs as its own session with a raised share (prioritize(); root only), else every figure at a high time scale
measures the other sessions' load. BENCH_DURATION_TABLE=S instead: the README trade table's plans at time scale S (duration_table.csv; see table()); with BENCH_DURATION_REPEAT=1 each plan names its sample and runs twice on one bench, the second timed by the exposure prior. Writes duration.csv under
$ACQ_BENCH_OUT."""
import csv
import json
import math
import os
import re
import signal
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.join(os.environ.get("ACQ_SRC", "."), "tests", "integration"))
import sweeplib as L  # noqa: E402

OUT = os.environ.get("ACQ_BENCH_OUT") or os.path.join(L.BUILD, "bench")
CTL = os.path.join(L.BUILD, "acqctl")
QUICK = open(os.path.join(L.SRC, "config", "plan-quick.yaml")).read()
FIXED = QUICK.replace("mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000", "mode: fixed, ms: 20") \
             .replace("name: quick-2x2x4", "name: quick-fixed")
PAPER = open(os.path.join(L.SRC, "config", "plan-paper-10x10x10.yaml")).read()
# BENCH_DURATION_SURVEY=K: the auto plans say survey: K (0: none, the route alone; plan_survey_apply)
if os.environ.get("BENCH_DURATION_SURVEY"):
    _sv = "survey: %d\n" % int(os.environ["BENCH_DURATION_SURVEY"])
    QUICK, PAPER = QUICK + _sv, PAPER + _sv


def wait_recon(b, sid, timeout=900):
    """Wait until the automatic reconstruction of sweep sid has ended (or never started within 10 s); returns the
    wall seconds waited. A repeat starts after it: its CPU time is real seconds that the time scale does not
    shorten (at time scale 35, 25 s of fitting stand for 15 bench minutes, which a real bench's repeat would not
    overlap), and measured over the repeat's first half it is host time no model or ETA can foresee."""
    t0 = time.time()
    while time.time() - t0 < timeout:
        c = b.client()
        r = c.req("recon.status", sweep=sid)
        c.close()
        state = (r.get("run") or {}).get("state")
        if state not in (None, "running") or (state is None and time.time() - t0 > 10):
            break
        time.sleep(0.2)
    return time.time() - t0


def run_case(name, plan_text, scale, bench=None, keep_open=False, after=None):
    """One sweep of plan_text on a new bench, or on bench (a repeat: its database holds the previous sweeps, so the
    sample's exposure prior applies; after = the previous sweep, whose reconstruction it waits for). With keep_open
    the bench is returned with the row, not cleaned up."""
    b = bench or L.Bench(scale=scale)
    try:
        recon_wait = 0.0
        if not bench and os.environ.get("BENCH_DURATION_LOG"):
            # the daemon's log level (debug: a stall line per point, where the host's time went; kept with
            # ACQ_BENCH_KEEP=1 in the bench's acquisitiond.log)
            L.compose_config(b.conf, b.state, b.sock, scale, log_level=os.environ["BENCH_DURATION_LOG"])
        if not bench and os.environ.get("BENCH_DURATION_DARK_EVERY"):
            # the dark schedule (sweep.dark_every: 0 at each incidence, -1 by age only) against the config's
            text = open(b.conf).read()
            text, n = re.subn(r"(?m)^(  dark_every:)\s*-?\d+", r"\g<1> " + os.environ["BENCH_DURATION_DARK_EVERY"], text)
            if n != 1:
                raise AssertionError("BENCH_DURATION_DARK_EVERY: no sweep.dark_every line in %s" % b.conf)
            open(b.conf, "w").write(text)
        if not bench:
            b.start_sim()
            b.start_daemon()
        elif after:
            recon_wait = wait_recon(b, after)
        planf = os.path.join(b.dir, "plan.yaml")
        open(planf, "w").write(plan_text)
        # with the steps (predicted_start_s per step, kept with ACQ_BENCH_KEEP=1) when the reply is small enough
        p = subprocess.run([CTL, "-s", b.sock, "--json", "plan", planf, "--points"], capture_output=True, text=True)
        if p.returncode == 0:
            with open(os.path.join(b.dir, "plan.json"), "w") as fh:
                fh.write(p.stdout)
            steps = json.loads(p.stdout)["plan"].get("steps") or []
            steps_host = None  # the daemon's own per-step prediction: its host_s below
        else:
            # the moves per step from a local dry run on the same bench configuration (the same planner and
            # order; only the exposure timing, which this does not use, may differ)
            loc = subprocess.run([CTL, "--json", "plan", planf, "--points", "--config", b.conf], capture_output=True,
                                 text=True)
            steps = json.loads(loc.stdout)["plan"].get("steps") or [] if loc.returncode == 0 else []
            steps_host = json.loads(loc.stdout)["plan"].get("host_s") if loc.returncode == 0 else None
            p = subprocess.run([CTL, "-s", b.sock, "--json", "plan", planf], capture_output=True, text=True, check=True)
        pj = json.loads(p.stdout)["plan"]
        pred, host = pj["predicted_s"], pj.get("host_s", 0.0)
        prior = pj.get("exposure_prior") or {}
        load0 = os.getloadavg()[0]
        events = []
        w = subprocess.Popen([CTL, "-s", b.sock, "watch"], stdout=subprocess.PIPE, text=True)

        def reader():
            for line in w.stdout:
                events.append((time.time(), json.loads(line)))
        th = threading.Thread(target=reader, daemon=True)
        th.start()
        lags, stop = [], threading.Event()

        def lag_sampler():
            # the simulator's own lag (ctl status lag_s: real seconds its 1 ms waits ended late), 5 times a second
            while not stop.is_set():
                try:
                    lags.append((time.time(), float(b.sim_status()["lag_s"])))
                except (OSError, KeyError, ValueError, AssertionError):
                    pass
                stop.wait(0.2)
        ls = threading.Thread(target=lag_sampler, daemon=True)
        ls.start()
        time.sleep(0.3)
        sid = L.start_sweep(b, plan_text, name)
        row = L.drive_to_end(b, sid, timeout=7200, sample=MATERIAL)
        time.sleep(0.3)
        stop.set()
        ls.join(10)
        w.terminate()
        w.wait(10)
        if row["state"] != "completed":
            raise AssertionError("%s: sweep %s" % (name, row["state"]))
        db = b.db()
        ev = {k: at for at, k in db.execute("SELECT at, kind FROM events WHERE sweep_id = ? AND kind IN "
                                            "('pause', 'resume')", (sid,))}
        # the integration time the bench chose per point (its first exposure), the darks and exposures taken
        first = sorted(r[0] for r in db.execute("SELECT min(integration_ms) FROM spectra WHERE sweep_id = ? AND "
                                                "kind = 'sample' GROUP BY point_id", (sid,)))
        darks, expos = db.execute("SELECT sum(kind = 'dark'), sum(kind = 'sample') FROM spectra WHERE sweep_id = ? "
                                  "AND point_id IS NOT NULL", (sid,)).fetchone()
        started, finished = db.execute("SELECT started_at, finished_at FROM sweeps WHERE id = ?", (sid,)).fetchone()
        host_pts = host_per_point(db, sid, steps, scale)
        # faults the sweep recovered from (the simulator answering late on a loaded machine): not in the model
        faults = db.execute("SELECT count(*) FROM events WHERE sweep_id = ? AND kind = 'fault'", (sid,)).fetchone()[0]
        paused = max(0.0, ev.get("resume", 0) - ev.get("pause", 0))
        # the daemon's own wall-clock record (not this script's polling, 0.1 s = 3.5 bench s at time scale 35)
        measured = (finished - started - paused) * scale
        meas_terms, shot_check = measured_terms(db, sid, scale, steps, b.conf, started, finished, ev,
                                                 auto=pj.get("integration_mode") != "fixed")
        redos = db.execute("SELECT count(*) FROM events WHERE sweep_id = ? AND kind = 'info' AND message LIKE "
                           "'%measuring the point again%'", (sid,)).fetchone()[0]
        db.close()
        # a first auto sweep is timed from the plan's estimate (acqctl plan's "estimate"): the same model's time
        # had the estimate been the sample's median integration time, the pre-start prediction moved by what a
        # local dry run on the same bench configuration gives for the two estimates (the estimate's part of the
        # error; the rest is the model's)
        es = pj.get("estimate") or {}
        at_median = None
        if es and first:
            m = re.search(r"estimate_ms:\s*([0-9.]+)", plan_text)
            if m:
                at_median = pred + local_predicted(b, plan_text.replace(m.group(0), "estimate_ms: %.6g" % (
                    first[len(first) // 2]))) - local_predicted(b, plan_text)
        prog = [(t, e) for t, e in events if e.get("event") == "sweep.progress" and e.get("sweep") == sid]
        total = row["points_total"]
        eta_err, eta_host, eta_parts, eta_iv = {}, {}, {}, {}
        # the per-step prediction the ETA used: the daemon's steps, or a local dry run's (no prior, time scale 1),
        # which times the exposures as the daemon did only without a prior
        split_ok = steps and (steps_host is None or not prior)
        per_pt = split_points(b.db(), sid, steps, pj, steps_host, scale, shot_price(b.conf),
                              pj.get("integration_mode") != "fixed") if split_ok else None
        for frac in (0.25, 0.5, 0.75):
            for t, e in prog:
                if e["done"] >= frac * total and e.get("eta_s") is not None:
                    left = finished - t
                    eta_err[frac] = e["eta_s"] / left - 1 if left > 0 else float("nan")
                    if left > 0 and e.get("eta_low_s") is not None and e.get("eta_high_s") is not None:
                        # the ETA's interval where the rest's exposures are unknown, as errors of its two ends
                        eta_iv[frac] = (e["eta_low_s"] / left - 1, e["eta_high_s"] / left - 1)
                    eta_host[frac] = host_known(host_pts, t, e["eta_s"], finished)
                    if per_pt and left > 0:
                        eta_parts[frac] = eta_split(per_pt, e["done"], total, left)
                    break
        # the ETA right after the survey (acqctl plan's survey: its points are measured first, then the sweep is
        # re-timed from their exposures): the first progress event at or past the survey's points
        n_survey = (pj.get("survey") or {}).get("points") or 0
        eta_sv = eta_sv_iv = eta_sv_host = None
        for t, e in prog if n_survey else []:
            if e["done"] >= n_survey and e.get("eta_s") is not None:
                left = finished - t
                if left > 0:
                    eta_sv = e["eta_s"] / left - 1
                    eta_sv_host = host_known(host_pts, t, e["eta_s"], finished)
                    if e.get("eta_low_s") is not None and e.get("eta_high_s") is not None:
                        eta_sv_iv = (e["eta_low_s"] / left - 1, e["eta_high_s"] / left - 1)
                break
        if eta_parts:
            print("%-17s ETA error split at 25/50/75 %%: %s" % (name, "; ".join(
                "%d %%: model %+.1f %%, host %+.1f %% (the rest's host %.1f ms/point, the recent past's %.1f)" % (
                    100 * f, 100 * m, 100 * hh, 1000 * hr, 1000 * hp) for f, (m, hh, hr, hp) in sorted(
                        eta_parts.items()))), flush=True)
        # real seconds per point beyond the model's bench part (predicted_s - host_s), per time scale: the host's
        # time per point when the bench part is right (fixed integration), compare the model's constant
        # host_s / points / scale; with auto integration it also holds the sample's error
        host_pp = (measured - (pred - host)) / total / scale
        # the simulator's lag while the sweep ran (from the operator's resume, or the start, to the completion)
        sim_lag = lag_between(lags, ev.get("resume", started), finished)
        if os.environ.get("ACQ_BENCH_KEEP") == "1":  # the raw series, for a look at where the time went
            with open(os.path.join(b.dir, "series-%d.json" % sid), "w") as fh:
                json.dump({"events": events, "sim_lag": lags, "host_per_point": host_pts}, fh)
        row = dict(case=name, sweep=sid, recon_wait_s=recon_wait, scale=scale, points=total, predicted_s=pred,
                   measured_s=measured,
                    error=pred / measured - 1, predicted_host_s=host, residual_per_point_s=host_pp,
                    load=(load0 + os.getloadavg()[0]) / 2, eta25=eta_err.get(0.25), eta50=eta_err.get(0.5),
                    eta75=eta_err.get(0.75), median_ms=first[len(first) // 2] if first else None,
                    darks=darks, exposures=expos, faults=faults, prior_sweep=prior.get("sweep"),
                    sim_lag_s=sim_lag, sim_lag_share=(sim_lag * scale / measured if sim_lag is not None else None),
                    host_per_point_s=(sum(h for _, h in host_pts) / len(host_pts) if host_pts else None),
                    eta25_host=eta_host.get(0.25), eta50_host=eta_host.get(0.5), eta75_host=eta_host.get(0.75),
                    redos=redos, estimate_ms=es.get("ms"), predicted_at_half_s=es.get("predicted_at_half_s"),
                    predicted_at_double_s=es.get("predicted_at_double_s"), predicted_at_median_s=at_median,
                    error_at_median=(at_median / measured - 1 if at_median else None),
                    prior_host_ms=(1000 * prior["host_per_point_s"] if "host_per_point_s" in prior else None),
                    survey_points=n_survey, survey_cost_s=(pj.get("survey") or {}).get("cost_s"), eta_survey=eta_sv,
                    eta_survey_host=eta_sv_host,
                    eta_survey_low=eta_sv_iv[0] if eta_sv_iv else None,
                    eta_survey_high=eta_sv_iv[1] if eta_sv_iv else None)
        # the prediction's interval (acqctl plan --json interval: where the exposures are unknown) and whether it
        # covers the measured time; the ETA's interval at 25/50/75 % as errors of its ends against the time left
        iv = pj.get("interval") or {}
        row.update(interval_basis=iv.get("basis"), interval_low_s=iv.get("low_s"), interval_high_s=iv.get("high_s"),
                   interval_covers=(iv["low_s"] <= measured <= iv["high_s"]) if iv else None)
        for frac in (0.25, 0.5, 0.75):
            lo_hi = eta_iv.get(frac)
            row["eta%d_low" % (100 * frac)] = lo_hi[0] if lo_hi else None
            row["eta%d_high" % (100 * frac)] = lo_hi[1] if lo_hi else None
        for k in TERMS:
            row["pred_" + k] = (pj.get("predicted_terms") or {}).get(k)
            row["meas_" + k] = meas_terms[k]
        if n_survey:
            print("%-17s survey: %d points (%s per incidence) first, cost %s bench s predicted; ETA error right after "
                  "it %s%s" % (name, n_survey, (pj.get("survey") or {}).get("per_incidence"),
                              "-" if row["survey_cost_s"] is None else "%.1f" % row["survey_cost_s"],
                              "-" if eta_sv is None else "%+.1f %%%s" % (100 * eta_sv, "" if eta_sv_host is None else
                                                                         " (had the host's time of the rest been "
                                                                         "known: %+.1f %%)" % (100 * eta_sv_host)),
                              "" if not eta_sv_iv else " (interval [%+.1f %%, %+.1f %%])" % (
                                  100 * eta_sv_iv[0], 100 * eta_sv_iv[1])), flush=True)
        print(terms_line(name, pj.get("predicted_terms") or {}, meas_terms, shot_check, total, scale)
              + "; %d saturation redos" % redos, flush=True)
        return (row, b) if keep_open else row
    except BaseException:
        keep_open = False
        raise
    finally:
        if not keep_open:
            keep = os.environ.get("ACQ_BENCH_KEEP") == "1"
            if keep:
                print("bench_duration: %s kept in %s" % (name, b.dir), flush=True)
            b.cleanup(keep=keep)


def local_predicted(b, text):
    """predicted_s of a local dry run (no daemon: no prior, the default host) of plan text on bench b's
    configuration."""
    f = os.path.join(b.dir, "estimate.yaml")
    open(f, "w").write(text)
    loc = subprocess.run([CTL, "--json", "plan", f, "--config", b.conf], capture_output=True, text=True, check=True)
    return json.loads(loc.stdout)["plan"]["predicted_s"]


# daemon/plan/plan.h PLAN_MOVE_POLLS: the axis polls a move costs beyond its trapezoid and settling (poll_s 0.05)
MOVE_POLLS = 0.1
TERMS = ("reference_s", "motion_s", "settle_s", "probes_s", "darks_s", "first_exposures_s", "hdr_s", "host_s")


def shot_price(conf):
    """The model's cost of one exposure beyond its integration (bench seconds): the read-out (bench.readout_s) and
    half a spectrometer poll (sweep.acquisition.poll_s / 2), read from the bench's configuration as the daemon does
    (plan_time.c shot; the defaults where the file does not say)."""
    text = open(conf).read()
    ro = re.search(r"^\s*readout_s:\s*([0-9.eE+-]+)", text, re.M)
    acq = text.split("acquisition:", 1)[1] if "acquisition:" in text else ""
    poll = re.search(r"^\s*poll_s:\s*([0-9.eE+-]+)", acq, re.M)
    return (float(ro.group(1)) if ro else 0.01) + (float(poll.group(1)) if poll else 0.01) / 2


def measured_terms(db, sid, scale, steps, conf, started, finished, ev, auto=True):
    """The measured sweep split into the model's terms (acqctl plan --json predicted_terms), bench seconds:
    - probes_s, darks_s, first_exposures_s, hdr_s: what the bench took, from the stored spectra (every dark and
      exposure with its time and averages; the probe, not stored, at the previous point's first time, as the executor
      takes it, the first point's at the reference's; none with fixed integration; a first exposure at the previous
      point's first time took one scan fewer than it stores, its probe being one of them: executor_acq.c,
      exp_probe_reusable, session 17), each priced as the model prices a shot (averages x time +
      read-out + round trip): the counts and times are measured, the price per shot is the model's (shot_check tests
      it against the wall clock);
    - motion_s, settle_s: the plan's moves between the points (steps' move_s; settle_s with PLAN_MOVE_POLLS polls per move
      as the model counts): the record has no time stamp between a move's end and the probe, so these are the plan's;
    - reference_s: from the start to the operator's pause, plus the first point's time after the resume less its
      exposures (the move from the reference pose; the first point's host time with it);
    - host_s: the rest, measured minus everything above: the host's time (calibration, storage, round trips, late
      wake-ups) plus anything the other terms miss (saturation redos, whose spectra are dropped; re-probes).
    Returns (terms, shot_check) with shot_check = (wall s, priced s, count) over the shots that follow another shot
    of the same point (their wall time is the interval between the two spectra's taken_at)."""
    price = shot_price(conf)
    pts = db.execute("SELECT id, order_index, done_at FROM points WHERE sweep_id = ? AND state = 'done' ORDER BY "
                     "order_index", (sid,)).fetchall()
    sp = {}
    for pid, kind, ms, n, at in db.execute("SELECT point_id, kind, integration_ms, averages, taken_at FROM spectra "
                                           "WHERE sweep_id = ? AND point_id IS NOT NULL ORDER BY id", (sid,)):
        sp.setdefault(pid, []).append((kind, ms, n, at))
    ref = db.execute("SELECT min(integration_ms) FROM spectra WHERE sweep_id = ? AND kind = 'reference'",
                     (sid,)).fetchone()[0]
    t = dict.fromkeys(TERMS, 0.0)
    wall = priced = 0.0
    nshot = 0
    prev_first = ref
    first_point_shots = 0.0
    for k, (pid, oi, done) in enumerate(pts):
        shots = sp.get(pid, [])
        samples = [ms for kind, ms, _, _ in shots if kind == "sample"]
        first = min(samples) if samples else None
        seen_first, last_at, own = False, None, 0.0
        for kind, ms, n, at in shots:
            c = n * ms / 1000.0 + price
            if kind == "dark":
                term = "darks_s"
            elif not seen_first and ms == first:
                term, seen_first = "first_exposures_s", True
                if auto and prev_first is not None and ms == prev_first:  # the probe pooled: one scan fewer
                    c = (n - 1) * ms / 1000.0 + price if n > 1 else 0.0
            else:
                term = "hdr_s"
            t[term] += c
            own += c
            if last_at is not None:
                wall += (at - last_at) * scale
                priced += c
                nshot += 1
            last_at = at
        if auto and prev_first is not None:  # fixed integration: no probe
            c = prev_first / 1000.0 + price
            t["probes_s"] += c
            own += c
        if k == 0:
            first_point_shots = own
        prev_first = first if first is not None else prev_first
    for i, st in enumerate(steps):
        if i == 0:
            continue  # the move from the reference pose: in reference_s, as the model has it
        mv, se = st.get("move_s", 0.0), st.get("settle_s", 0.0)
        t["motion_s"] += mv
        t["settle_s"] += se + (MOVE_POLLS * 0.05 if mv + se > 0 else 0.0)
    pause, resume = ev.get("pause"), ev.get("resume")
    if pts and pause and resume:
        t["reference_s"] = ((pause - started) + (pts[0][2] - resume)) * scale - first_point_shots
    elif pts:
        t["reference_s"] = (pts[0][2] - started) * scale - first_point_shots
    total = (finished - started - (resume - pause if pause and resume else 0)) * scale
    t["host_s"] = total - sum(v for k, v in t.items() if k != "host_s")
    return t, (wall, priced, nshot)


def terms_line(name, pred, meas, shots, points, scale):
    """Each term predicted against measured (bench seconds), and the shot price's check."""
    parts = []
    for k in TERMS:
        p, m = pred.get(k), meas.get(k)
        parts.append("%s %s/%.1f" % (k[:-2], "-" if p is None else "%.1f" % p, m))
    wall, priced, n = shots
    return ("%-17s terms, predicted/measured bench s: %s; host per point %.2f ms real predicted, %.2f measured; "
            "shot price check: %d shots after another of the same point took %.1f s by the wall clock, priced %.1f s" % (
                name, ", ".join(parts), 1000 * pred.get("host_s", 0) / points / scale,
                1000 * meas["host_s"] / points / scale, n, wall, priced))


def lag_at(lags, t):
    """The simulator's summed lag (real s) at wall time t, interpolated between the samples; None outside them."""
    for (t0, l0), (t1, l1) in zip(lags, lags[1:]):
        if t0 <= t <= t1:
            return l0 + (l1 - l0) * (t - t0) / (t1 - t0) if t1 > t0 else l1
    return None


def lag_between(lags, t0, t1):
    """Real seconds the simulator ran late between wall times t0 and t1 (None without samples there)."""
    a, b = lag_at(lags, t0), lag_at(lags, t1)
    return None if a is None or b is None else b - a


def host_per_point(db, sid, steps, scale):
    """Per point after the first (which carries the move from the reference): (done_at, host seconds) = the real
    seconds since the previous point's commit that neither its exposures (its spectra's integration_ms x averages,
    darks included) nor its planned move and settle (steps[i].move_s + settle_s) account for, at the time scale:
    the host's time (and what the model does not time, the same for every point: probes, round trips). Empty
    without the steps."""
    if not steps:
        return []
    pts = db.execute("SELECT p.order_index, p.done_at, coalesce(sum(s.integration_ms * s.averages), 0) / 1000.0 "
                     "FROM points p LEFT JOIN spectra s ON s.point_id = p.id WHERE p.sweep_id = ? AND p.state = 'done' "
                     "GROUP BY p.id ORDER BY p.done_at", (sid,)).fetchall()
    out = []
    for (_, t0, _), (i, t1, expo) in zip(pts, pts[1:]):
        if i < len(steps):
            move = steps[i].get("move_s", 0) + steps[i].get("settle_s", 0)
            out.append((t1, (t1 - t0) - (expo + move) / scale))
    return out


# daemon/eta.c's constants: the plan's weight in points, the recent average's memory (fraction of the sweep's points,
# bounds)
ETA_PLAN_WEIGHT, ETA_MEMORY = 5.0, (0.125, 10.0, 120.0)


def split_points(db, sid, steps, pj, steps_host, scale, price, auto):
    """Per point after the first, in order: (e_b, h, h_plan): real seconds the point's exposures took beyond what the
    ETA's plan gave them (the measured shots priced as measured_terms does, less the plan's step less its moves and
    host), the host's real seconds (the real interval less the measured exposures and the plan's moves at the time
    scale), and the plan's host per point (real s). None when the record does not allow it."""
    n = len(steps)
    host_pp = (steps_host if steps_host is not None else pj.get("host_s", 0.0)) / max(n, 1)  # bench s per step
    ts = 1.0 if steps_host is not None else scale  # the time scale the steps were predicted at
    pts = db.execute("SELECT id, order_index, done_at FROM points WHERE sweep_id = ? AND state = 'done' ORDER BY "
                     "order_index", (sid,)).fetchall()
    sp = {}
    for pid, kind, ms, k in db.execute("SELECT point_id, kind, integration_ms, averages FROM spectra WHERE sweep_id = ? "
                                       "AND point_id IS NOT NULL ORDER BY id", (sid,)):
        sp.setdefault(pid, []).append((kind, ms, k))
    prev = db.execute("SELECT min(integration_ms) FROM spectra WHERE sweep_id = ? AND kind = 'reference'",
                      (sid,)).fetchone()[0]
    db.close()
    if len(pts) != n:
        return None
    out = []
    for i, (pid, oi, done) in enumerate(pts):
        s = sp.get(pid, [])
        samples = [ms for kind, ms, _ in s if kind == "sample"]
        meas = sum(k * ms / 1000.0 + price for _, ms, k in s) + (prev / 1000.0 + price if auto and prev else 0.0)
        st = steps[oi]
        mv = st.get("move_s", 0.0) + st.get("settle_s", 0.0)
        mv += MOVE_POLLS * 0.05 if mv > 0 else 0.0
        nxt = steps[oi + 1]["predicted_start_s"] if oi + 1 < n else pj.get("predicted_s") if steps_host is None else None
        if nxt is None:  # the local run's total is not given here: the last point left out
            break
        plan_exp = nxt - st["predicted_start_s"] - mv - host_pp
        if i > 0:
            real = done - pts[i - 1][2]
            out.append(((meas - plan_exp) / scale, real - (meas + mv) / scale, host_pp / ts))
        prev = min(samples) if samples else prev
    return out


def eta_split(per_pt, done, total, left_real):
    """The ETA's error at `done` points (daemon/eta.c: the plan's rest plus, per point left, the recent excess per point
    weighted n/(n + 5), its host part the median of the host's time over the last m points) split into the model's part (the rest's exposures against the recent past's excess over the
    plan) and the host's (the rest's host time against the plan's host plus the recent past's excess): each as a
    fraction of the real time left. Returns (model, host, host per point of the rest, the recent past's)."""
    m = min(max(ETA_MEMORY[0] * total, ETA_MEMORY[1]), ETA_MEMORY[2])
    a = 1 - math.exp(-1 / m)
    past, rest = per_pt[:max(done - 1, 0)], per_pt[max(done - 1, 0):]
    left = total - done
    if not past or not rest:
        return (float("nan"),) * 4
    re = None
    for e_b, h, hp in past:
        re = e_b if re is None else re + a * (e_b - re)
    # the host's part as eta.c takes it since session 14: the median of its time per point over the last m points
    hs = sorted(x[1] for x in past[-int(round(m)):])
    med = hs[len(hs) // 2] if len(hs) % 2 else 0.5 * (hs[len(hs) // 2 - 1] + hs[len(hs) // 2])
    rh = med - past[-1][2]
    w = len(past) / (len(past) + ETA_PLAN_WEIGHT)
    model = left * w * re - sum(x[0] for x in rest)
    host = sum(x[2] for x in rest) + left * w * rh - sum(x[1] for x in rest)
    recent_host = past[-1][2] + rh
    return model / left_real, host / left_real, sum(x[1] for x in rest) / len(rest), recent_host


def host_known(host, t, eta_s, finished):
    """The ETA's error at wall time t had the host's time per point of the rest been known: the ETA carries the
    host's time per point measured so far into the points left; the points after t took (after - before) more
    each. What is left of the error is the model's (exposures, darks, moves the plan timed wrong). None without
    per-point host times."""
    before = [h for at, h in host if at <= t]
    after = [h for at, h in host if at > t]
    left = finished - t
    if not before or not after or left <= 0:
        return None
    shift = (sum(after) / len(after) - sum(before) / len(before)) * len(after)
    return (eta_s + shift) / left - 1


# the simulator material placed on the stage after the reference (BENCH_DURATION_SAMPLE; the demo's green paint)
MATERIAL = os.environ.get("BENCH_DURATION_SAMPLE") or "green-paint"


def SAMPLE(text):
    """The plan naming its sample (the simulator's material): a later sweep of it gets the exposure prior."""
    return text.rstrip("\n") + "\nsample: %s\n" % MATERIAL


def table(scale):
    """The README trade table's plans (bench_tradeoff.plan_yaml: grids N^3 and Fibonacci N x N^2, N = 5, 8, 10, 12, 15;
    auto integration, estimate 50 ms, 4 averages) measured on the simulated bench at one time scale, with the
    model's prediction at that time scale (the daemon's) and at time scale 1 (a real bench's pace, local dry run).
    Writes duration_table.csv."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import bench_tradeoff as T  # noqa: E402 (numpy; only this mode needs it)
    sizes = [int(x) for x in os.environ.get("BENCH_DURATION_SIZES", "5,8,10,12,15").split(",")]
    rows = []
    for n in sizes:
        for fib in (False, True):
            name = "%s-%d" % ("fib" if fib else "grid", n)
            text = T.plan_yaml(name, n, fib)
            planf = os.path.join(OUT, name + ".yaml")
            with open(planf, "w") as fh:
                fh.write(text)
            p = subprocess.run([CTL, "--json", "plan", planf, "--config", os.path.join(L.SRC, "config", "bench-sim.yaml")],
                               capture_output=True, text=True, check=True)
            pred1 = json.loads(p.stdout)["plan"]["predicted_s"]
            runs = []
            if os.environ.get("BENCH_DURATION_REPEAT") == "1":
                # the plan naming its sample, then again on the same bench: the repeat is timed by the exposure prior
                text = SAMPLE(text)
                r, b = run_case(name, text, scale, keep_open=True)
                runs = [r, run_case(name + "-repeat", text, scale, bench=b, after=r["sweep"])]
            else:
                runs = [run_case(name, text, scale)]
            for r in runs:
                r["predicted_scale1_s"] = pred1
                rows.append(r)
                table_line(r, scale, pred1)
            with open(os.path.join(OUT, "duration_table.csv"), "w", newline="") as fh:
                wr = csv.DictWriter(fh, fieldnames=list(rows[0].keys()))
                wr.writeheader()
                wr.writerows(rows)
    return 0


def table_line(r, scale, pred1):
    """One row of the table mode's report."""
    name = r["case"]
    print("%-8s %4d points  time scale %g: predicted %7.1f s (host %.1f s) measured %7.1f s (%+5.1f%%; residual "
          "per point %.4f s, load %.1f, %d faults)  predicted at time scale 1: %7.1f s (%.1f min)  ETA error 25/50/75 %%: "
          "%s" % (
              name, r["points"], scale, r["predicted_s"], r["predicted_host_s"], r["measured_s"],
              100 * r["error"], r["residual_per_point_s"], r["load"], r["faults"], pred1, pred1 / 60,
              " ".join("-" if r[k] is None else "%+.1f%%" % (100 * r[k]) for k in ("eta25", "eta50", "eta75")))
          + "  (had the host's time of the rest been known: %s; simulator lag %s; waited %.0f s for the previous "
             "reconstruction)" % (
              " ".join("-" if r[k] is None else "%+.1f%%" % (100 * r[k]) for k in ("eta25_host", "eta50_host",
                                                                                  "eta75_host")), lag_text(r),
              r["recon_wait_s"]),
          flush=True)


def lag_text(r):
    """The simulator's own lag over the sweep: real seconds its 1 ms waits ended late, and that in bench seconds as a
    share of the measured time. The host holding the bench's processes back, not all of it on the sweep's path (a
    late wake-up with nothing due costs nothing): an indicator of the host's part, not a decomposition."""
    if r["sim_lag_s"] is None:
        return "-"
    model = 1000 * r["predicted_host_s"] / r["points"] / r["scale"]
    rq = "" if r["host_per_point_s"] is None else ("; real time per point beyond its stored exposures and planned "
                                                   "move %.1f ms (host, probe, round trips; the model's host part "
                                                   "%.1f ms)" % (1000 * r["host_per_point_s"], model))
    return "%.2f real s (%.1f%% of the measured in bench s)%s" % (r["sim_lag_s"], 100 * r["sim_lag_share"], rq)


def prioritize():
    """Timing on a shared machine: the kernel shares the CPUs between sessions (sched_autogroup), so `nice` alone
    does not help against other sessions' builds. With permission (root), this process becomes its own session and
    raises that session's share (autogroup nice -10; the bench's processes use a few % of a CPU but must answer
    within ms). BENCH_DURATION_PRIORITY=0 leaves it as it is. Returns what was done, for the report."""
    if os.environ.get("BENCH_DURATION_PRIORITY", "1") == "0":
        return "not prioritized (BENCH_DURATION_PRIORITY=0)"
    try:
        if os.getsid(0) != os.getpid():
            os.setsid()
        with open("/proc/self/autogroup", "w") as fh:
            fh.write("-10")
        os.nice(-10)
        return "own session, autogroup nice -10, nice -10"
    except OSError as e:
        return "not prioritized (%s)" % e


class Report:
    """The report's lines, to stdout and to $ACQ_BENCH_OUT/duration.log. Run detached (setsid ... | tee, a pipe whose
    reader went away with the shell that started it), a print to stdout raised BrokenPipeError: the script ended with
    rc 1 after its first line and its traceback went down the same broken pipe (session 8). Now a stdout that fails
    is dropped and the run goes on to the log and duration.csv."""

    def __init__(self, path):
        self.log = open(path, "a")
        self.out = sys.stdout

    def write(self, text):
        self.log.write(text)
        self.log.flush()
        if self.out is not None:
            try:
                self.out.write(text)
                self.out.flush()
            except (BrokenPipeError, OSError):
                self.out = None
                try:  # stdout's descriptor to /dev/null: the interpreter's own flush at exit must not fail either
                    fd = os.open(os.devnull, os.O_WRONLY)
                    os.dup2(fd, 1)
                    os.close(fd)
                except OSError:
                    pass

    def flush(self):
        pass


def select_cases(cases, only):
    """The cases BENCH_DURATION_CASES names (name, or name@scale), each repeat with the case it repeats (a repeat runs
    on its first sweep's bench). A name that matches no case is an error naming the known ones (before: nothing ran,
    and the csv's rows[0] raised IndexError)."""
    want = [w.strip() for w in only.split(",") if w.strip()]
    names = ["%s@%g" % (c[0], c[2]) for c in cases]
    unknown = [w for w in want if not any(w == c[0] or w == n for c, n in zip(cases, names))]
    if unknown or not want:
        raise ValueError("BENCH_DURATION_CASES=%r: no case named %s (cases: %s)" % (
            only, ", ".join(unknown) if unknown else "(none given)", ", ".join(names)))
    keep = [c[0] in want or n in want for c, n in zip(cases, names)]
    for i in range(len(cases) - 1, 0, -1):
        if keep[i] and cases[i][1] is None:
            keep[i - 1] = True
    return [c for c, k in zip(cases, keep) if k]


def main():
    os.makedirs(OUT, exist_ok=True)
    sys.stdout = Report(os.path.join(OUT, "duration.log"))
    signal.signal(signal.SIGHUP, signal.SIG_IGN)  # detached: the starting shell's hang-up is not this run's end
    print("bench_duration: %s; load average %.1f" % (prioritize(), os.getloadavg()[0]), flush=True)
    if os.environ.get("BENCH_DURATION_TABLE"):
        return table(float(os.environ["BENCH_DURATION_TABLE"]))
    # (name, plan, time scale); None as the plan: the previous case's plan again on the same bench (an operator
    # repeating a sample: the plan names it, sample: green-paint, so the daemon times it from the previous sweep's
    # exposures, the exposure prior; the plan's estimate is left as it was)
    cases = [("quick-fixed", FIXED, 1.0)]
    if os.environ.get("BENCH_DURATION_QUICK") != "1":
        cases += [("quick-fixed", FIXED, 10.0), ("quick-auto", SAMPLE(QUICK), 1.0), ("quick-auto-repeat", None, 1.0),
                  ("paper-10x10x10", SAMPLE(PAPER), 35.0), ("paper-repeat", None, 35.0)]
    only = os.environ.get("BENCH_DURATION_CASES")
    if only:
        try:
            cases = select_cases(cases, only)
        except ValueError as e:
            print("bench_duration: %s" % e, file=sys.stderr)
            return 2
    rows = []
    prev = None
    for i, (name, text, scale) in enumerate(cases):
        repeat_next = i + 1 < len(cases) and cases[i + 1][1] is None
        bench = after = None
        if text is None:
            if not prev:
                continue
            text, bench = prev
            after = rows[-1]["sweep"]
        try:
            r = run_case(name, text, scale, bench=bench, keep_open=repeat_next, after=after)
        except L.Skip as e:
            print("bench_duration: skip: %s" % e)
            return 0
        if repeat_next:
            r, b = r
            prev = (text, b)
        rows.append(r)
        if r.get("estimate_ms"):
            print("%-17s timed from the plan's estimate %.3g ms (no exposure prior): %.1f s if the sample needed half, "
                  "%.1f s if twice; had the estimate been the sample's median (%.3g ms), %.1f s: error %+.1f %%"
                  % (name, r["estimate_ms"], r["predicted_at_half_s"], r["predicted_at_double_s"], r["median_ms"],
                     r["predicted_at_median_s"] or float("nan"), 100 * (r["error_at_median"] or float("nan"))),
                  flush=True)
        f = lambda x: "   -  " if x is None else "%+5.1f%%" % (100 * x)  # noqa: E731
        print("%-17s scale %4g  %4d points  predicted %7.1f s (host %.1f s)  measured %7.1f s  error %s  ETA error at "
              "25/50/75 %%: %s %s %s  (had the host's time of the rest been known: %s %s %s)  (median integration %s "
              "ms, %s "
              "darks, %s exposures; residual per point %.4f s; simulator lag %s; load %.1f; %d faults; exposure prior "
              "%s; waited %.0f s for the previous sweep's reconstruction)"
              % (name, scale, r["points"], r["predicted_s"], r["predicted_host_s"], r["measured_s"], f(r["error"]),
                 f(r["eta25"]), f(r["eta50"]), f(r["eta75"]), f(r["eta25_host"]), f(r["eta50_host"]),
                 f(r["eta75_host"]), "-" if r["median_ms"] is None else "%.3g" % r["median_ms"],
                 r["darks"], r["exposures"], r["residual_per_point_s"], lag_text(r), r["load"], r["faults"],
                 "sweep %s" % r["prior_sweep"] if r["prior_sweep"] else "none", r["recon_wait_s"]), flush=True)
        if r.get("interval_basis") or any(r.get("eta%d_low" % k) is not None for k in (25, 50, 75)):
            g = lambda x: "-" if x is None else "%+.1f%%" % (100 * x)  # noqa: E731
            print("%-17s interval (%s): %s to %s, measured %.1f s %s; ETA interval at 25/50/75 %%: %s (covers: %s)"
                  % (name, r.get("interval_basis") or "none", "-" if r.get("interval_low_s") is None else
                     "%.1f" % r["interval_low_s"], "-" if r.get("interval_high_s") is None else
                     "%.1f" % r["interval_high_s"], r["measured_s"],
                     "" if r.get("interval_covers") is None else "covered" if r["interval_covers"] else "NOT covered",
                     " ".join("[%s, %s]" % (g(r.get("eta%d_low" % k)), g(r.get("eta%d_high" % k)))
                              for k in (25, 50, 75)),
                     " ".join("-" if r.get("eta%d_low" % k) is None else
                              "yes" if r["eta%d_low" % k] <= 0 <= r["eta%d_high" % k] else "NO" for k in (25, 50, 75))),
                  flush=True)
    if not rows:
        print("bench_duration: no case ran")
        return 1
    with open(os.path.join(OUT, "duration.csv"), "w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=list(rows[0].keys()))
        wr.writeheader()
        wr.writerows(rows)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Exception:
        import traceback
        if isinstance(sys.stdout, Report):  # also into duration.log: stderr may be a pipe nobody reads any more
            sys.stdout.log.write(traceback.format_exc())
        raise
