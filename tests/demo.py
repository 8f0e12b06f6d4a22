#!/usr/bin/python3
"""demo: the end-to-end run on the simulated bench (make demo, through tests/demo.sh): acq-sim and acquisitiond
with their state in build/demo/ (fresh each run), the paper's 10 x 10 x 10 plan on the simulated green paint
(white reference first, then the sample), progress from `acqctl watch`, the reconstruction on completion, and
where every output is. Everything started here is stopped here, also on Ctrl-C."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "integration"))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

SCALE = float(os.environ.get("DEMO_TIME_SCALE", "35"))
PLAN = os.path.join(L.SRC, "config", "plan-paper-10x10x10.yaml")
ACQCTL = os.path.join(L.BUILD, "acqctl")


def main():
    demo = os.path.join(L.BUILD, "demo")
    shutil.rmtree(demo, ignore_errors=True)
    os.makedirs(demo)
    if not os.path.exists(PLAN):
        print("make demo: %s is missing (the planner's example plans are not merged yet)" % PLAN, file=sys.stderr)
        return 1
    b = L.Bench(state_dir=demo, scale=SCALE, seed=int(os.environ.get("ACQ_SEED", "1")))
    watch = None
    t0 = time.time()
    try:
        print("demo: starting acq-sim (time scale %g) and acquisitiond in %s" % (SCALE, demo), flush=True)
        b.start_sim()
        b.start_daemon()
        with open(PLAN) as f:
            plan = f.read()
        sid = L.start_sweep(b, plan, "demo-paper-10x10x10")
        total = L.sweep_row(b, sid)["points_total"]
        print("demo: sweep %d started: %d points (the plan's visible ones), white reference first" % (sid, total),
              flush=True)
        watch = subprocess.Popen([ACQCTL, "-s", b.sock, "watch"], stdin=subprocess.DEVNULL)
        row = L.drive_to_end(b, sid, timeout=1800)
        if watch.poll() is None:
            watch.terminate()
            watch.wait(5)
        watch = None
        print("\ndemo: sweep %d %s in %.0f s" % (sid, row["state"], time.time() - t0), flush=True)
        if row["state"] != "completed":
            print("demo: the sweep did not complete; see %s" % b.daemon_log)
            return 1
        # the reconstruction chain runs in a child process of the daemon: wait for its last word
        verdict, deadline = None, time.time() + 900
        while time.time() < deadline and verdict is None:
            db = b.db()
            for (msg,) in db.execute("SELECT message FROM events WHERE sweep_id = ? AND device = 'recon' "
                                     "ORDER BY id", (sid,)):
                if msg.startswith("reconstruction ") or msg.startswith("no reconstruction") or \
                        "no reconstruction ran" in msg:
                    verdict = msg
            db.close()
            time.sleep(0.5)
        out = os.path.join(b.state, "recon", "sweep-%d" % sid)
        try:
            zs, nan = L.zscores(b, sid)
            import numpy as np
            z = np.array(zs)
            acc = "calibrated samples vs the simulator's ground truth: %d values, z mean %.3f, std %.3f, " \
                  "|z| < 3 for %.2f %%" % (len(z), z.mean(), z.std(), 100 * np.mean(np.abs(z) < 3))
        except (L.Skip, AssertionError) as e:
            acc = "ground-truth comparison unavailable: %s" % e
        print("\n==== demo results (all under %s) ====" % demo)
        print("database:            %s" % b.db_path())
        print("calibrated samples:  %s" % os.path.join(out, "samples.csv"))
        print("accuracy:            %s" % acc)
        print("reconstruction:      %s" % (verdict or "no word from the reconstruction within 15 min"))
        for label, name in (("model", "model.brdf"), ("MERL table", "merl.binary"), ("DHR table", "dhr.csv"),
                            ("DHR plot", "dhr.png"), ("preview image", "preview.png")):
            p = os.path.join(out, name)
            print("%-20s %s" % (label + ":", p if os.path.exists(p) else "(not produced: %s)" % p))
        import demo_outputs  # issue 18: RGL .bsdf, HDR preview, slice plots
        for label, p in demo_outputs.make(L.BUILD, out):
            print("%-20s %s" % (label + ":", p))
        print("logs:                %s, %s" % (b.daemon_log, b.sim_log))
        return 0
    except L.Skip as e:
        print("make demo: cannot run yet: %s" % e, file=sys.stderr)
        return 1
    except AssertionError as e:
        print("make demo: failed: %s" % e, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("\nmake demo: interrupted; stopping everything", file=sys.stderr)
        return 130
    except (OSError, EOFError) as e:
        # Ctrl-C reaches the daemon too (same process group): it may be gone before we see the interrupt
        print("\nmake demo: acquisitiond is gone (%s); stopping everything; logs: %s" % (e, b.daemon_log),
              file=sys.stderr)
        return 130 if b.daemon and b.daemon.poll() is not None else 1
    finally:
        if watch and watch.poll() is None:
            watch.terminate()
            watch.wait(5)
        b.stop()


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, lambda *a: (_ for _ in ()).throw(KeyboardInterrupt()))
    sys.exit(main())
