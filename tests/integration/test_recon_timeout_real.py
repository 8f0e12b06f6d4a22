#!/usr/bin/env python3
"""The reconstruction's timeout (recon.timeout_s) is in real seconds at any simulated time scale: brdf-recon is a
computation on the host, not bench time. At time scale 100 a stand-in reconstruction taking 1 s per stage must
complete under timeout_s 20 (the daemon's loop clock runs 100 x real time: a timeout read on it would kill each stage
after 0.2 s), and the run's record says succeeded."""
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import sweeplib as L  # noqa: E402

PLAN = """name: it-recon-timeout
incidence:
  theta_deg: [30]
observation:
  theta_deg: [40]
  phi_deg: [0, 180]
integration: {mode: fixed, ms: 20}
averages: 1
blind_points: drop
"""


def run():
    cfg = open(os.path.join(L.SRC, "config", "bench-sim.yaml")).read()
    sweep = cfg[cfg.index("\nsweep:") + 1:]
    sweep = L.strip_sections(sweep, {"recon", "daemon"})
    assert "auto_recon: true" in sweep, "config/bench-sim.yaml's sweep section has no auto_recon: true"
    fake = tempfile.NamedTemporaryFile("w", suffix=".sh", delete=False, dir="/tmp")
    # writes the -o file of each stage, like brdf-recon, after 1 s of "work"
    fake.write("#!/bin/sh\nwhile [ $# -gt 0 ]; do [ \"$1\" = -o ] && o=\"$2\"; shift; done\n"
               "sleep 1\n[ -n \"$o\" ] && echo x > \"$o\"\nexit 0\n")
    fake.close()
    os.chmod(fake.name, 0o755)
    sweep += "recon:\n  program: %s\n  timeout_s: 20\n" % fake.name
    try:
        with L.Bench(scale=100, sweep_yaml=sweep) as b:
            b.start_sim()
            b.start_daemon()
            sid = L.start_sweep(b, PLAN, "it-recon-timeout")
            row = L.drive_to_end(b, sid, timeout=120)
            assert row["state"] == "completed", "sweep ended %s" % row["state"]
            t0 = time.time()
            st = None
            while time.time() - t0 < 120:
                c = b.client()
                st = c.req("recon.status", sweep=sid)
                c.close()
                if st.get("ok") and st["run"]["state"] not in ("running", "queued", "pending"):
                    break
                time.sleep(0.2)
            assert st and st.get("ok"), "recon.status: %r" % st
            run_ = st["run"]
            assert run_["state"] == "succeeded", "the reconstruction of 1 s stages under timeout_s 20 at time " \
                "scale 100 ended %r; daemon log tail:\n%s" % (run_, b.daemon_text()[-3000:])
            took = time.time() - t0
            L.say("reconstruction succeeded, %.1f s real after the sweep (1 s stages, timeout_s 20, scale 100)" % took)
    finally:
        os.unlink(fake.name)


if __name__ == "__main__":
    L.main(run)
