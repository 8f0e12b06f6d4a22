#!/usr/bin/python3
"""Integration: `acqctl export N --format nexus` on the simulated bench (acq-sim + acquisitiond).
A small sweep runs to completion; then
- `acqctl export N --format nexus -o FILE` (the daemon writes the HDF5 file in a worker thread, passes its
  descriptor once complete; acqctl writes FILE as the caller) and the --json summary agree on the byte count,
  and the summary matches acqctl-replies.schema.json;
- the file read back with h5py (/usr/bin/python3) equals SQLite number by number (nexuscheck.py), and a
  copy with one calibrated value changed does not (the check can fail); h5dump reads it;
- `path=NAME` writes a new file in the daemon's export folder with the same content, refuses an existing
  name, and build/acq-nexus on the same database gives the same content too; so do two exports at once;
- refusals: an unknown format, --format on another command, no such sweep; a client that leaves before its
  file is ready costs nothing; no temporary file is left in the export folder, and one that an interrupted
  export left is removed."""
import json
import os
import re
import shutil
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import nexuscheck  # noqa: E402
import sweeplib as L  # noqa: E402

ACQCTL = os.path.join(L.BUILD, "acqctl")
NEXUS = os.path.join(L.BUILD, "acq-nexus")
PLAN = """name: it-nexus
incidence:
  theta_deg: [20]
observation:
  theta_deg: [30, 60]
  phi_deg: [0, 180]
integration: {mode: auto, target_peak: 0.8, estimate_ms: 20, max_ms: 2000}
averages: 2
blind_points: drop
"""


def ctl(b, *args, timeout=120):
    p = subprocess.run([ACQCTL, "-s", b.sock] + list(args), capture_output=True, text=True, timeout=timeout)
    L.say("$ acqctl %s -> %d %s" % (" ".join(args), p.returncode, p.stderr.strip()[:300]))
    return p


def validate(doc):
    """The --json summary against acqctl-replies.schema.json's export schema (python3-jsonschema: DEB_PKGS)."""
    import jsonschema
    sch = dict(json.load(open(os.path.join(L.SRC, "proto", "schema", "acqctl-replies.schema.json"))))
    sch["$ref"] = "#/$defs/export"
    jsonschema.validate(doc, sch)
    bad = dict(doc)
    del bad["points"]
    try:
        jsonschema.validate(bad, sch)
        raise AssertionError("a NeXus summary without points passes the schema")
    except jsonschema.ValidationError:
        pass


def run():
    try:
        import h5py
    except ImportError:
        raise AssertionError("python3-h5py (in DEB_PKGS) is missing for /usr/bin/python3")
    # the bench's own sweep section without the reconstruction after completion: its events would change the
    # sweep between the exports that are compared
    text = open(os.path.join(L.SRC, "config", "bench-sim.yaml")).read()
    names = {m.group(1) for m in re.finditer(r"^([A-Za-z_][A-Za-z0-9_]*):", text, re.M)}
    sweep = L.strip_sections(text, names - {"sweep"})
    assert "auto_recon: true" in sweep, "config/bench-sim.yaml's sweep section has no auto_recon: true"
    with L.Bench(scale=100, sweep_yaml=sweep.replace("auto_recon: true", "auto_recon: false")) as b:
        b.start_sim()
        b.start_daemon()
        sid = L.start_sweep(b, PLAN, "it-nexus")
        row = L.drive_to_end(b, sid, timeout=120)
        assert row["state"] == "completed", "sweep ended %s" % row["state"]
        db = b.db_path()
        out = os.path.join(b.dir, "sweep.nxs")
        # what an interrupted export of an earlier run left (a hidden name no request can give): removed
        os.makedirs(os.path.join(b.state, "export"), exist_ok=True)
        stale = os.path.join(b.state, "export", ".nexus-3.nxs.tmp.12345")
        open(stale, "wb").write(b"\x89HDF partial")
        # streamed: acqctl writes the file as the caller
        p = ctl(b, "--json", "export", str(sid), "--format", "nexus", "-o", out)
        assert p.returncode == 0, "export --format nexus: %s" % p.stderr
        rep = json.loads(p.stdout)
        size = os.path.getsize(out)
        assert rep["ok"] and rep["format"] == "nexus" and rep["bytes"] == size and rep["output"] == out, rep
        assert not os.path.exists(stale), "a stale temporary file was left in the export folder"
        validate(rep)
        with open(out, "rb") as f:
            assert f.read(8) == b"\x89HDF\r\n\x1a\n", "not an HDF5 file"
        got = nexuscheck.check_roundtrip(out, db, sid)
        L.say("NeXus export of sweep %d: %d bytes; %s" % (sid, size, got))
        assert got["points"] == rep["points"] and got["calibrated"] == rep["calibrated"] > 0, (got, rep)
        assert got["spectra"]["sample"] >= got["calibrated"] and got["spectra"]["dark"] > 0
        assert got["spectra"]["reference"] > 0 and got["events"] > 0, got
        with h5py.File(out, "r") as f:
            P = f["entry/points"]
            done = np.array([nexuscheck.s(x) == "done" for x in P["state"][()]])
            assert done.any() and np.all(np.isfinite(P["measured_theta_o"][()][done])), "measured angles of done points"
        h = subprocess.run(["h5dump", "-H", out], capture_output=True, text=True)
        assert h.returncode == 0 and 'GROUP "entry"' in h.stdout, "h5dump: %s" % h.stderr[:300]
        p = ctl(b, "export", str(sid), "--format", "nexus", "-o", out)   # the human summary; -o truncates
        assert p.returncode == 0 and "NeXus" in p.stdout and "%d bytes" % size in p.stdout, p.stdout
        # the round trip can fail: one calibrated value changed
        bad = os.path.join(b.dir, "changed.nxs")
        shutil.copy(out, bad)
        with h5py.File(bad, "r+") as f:
            f["entry/data/brdf"][0, 5] = f["entry/data/brdf"][0, 5] * 1.001 + 1e-6
        try:
            nexuscheck.check_roundtrip(bad, db, sid)
            raise RuntimeError("a changed value passed the round trip")
        except AssertionError as e:
            L.say("changed file refused: %s" % e)
        # daemon-side file: a new name in the export folder, same content; never overwritten
        p = ctl(b, "--json", "export", str(sid), "--format", "nexus", "path=sweep-%d.nxs" % sid)
        assert p.returncode == 0, p.stderr
        rep2 = json.loads(p.stdout)
        assert rep2["path"] == os.path.join(b.state, "export", "sweep-%d.nxs" % sid), rep2
        validate(rep2)
        n = nexuscheck.same_content(out, rep2["path"])
        p = ctl(b, "export", str(sid), "--format", "nexus", "path=sweep-%d.nxs" % sid)
        assert p.returncode != 0 and "never overwrite" in p.stderr, p.stderr
        # acq-nexus beside it, on the same database (read-only while the daemon runs)
        alone = os.path.join(b.dir, "alone.nxs")
        q = subprocess.run([NEXUS, db, str(sid), "-o", alone], capture_output=True, text=True, timeout=60)
        assert q.returncode == 0, q.stderr
        nexuscheck.same_content(out, alone)
        L.say("path= file and acq-nexus: the same %d objects" % n)
        # two at once (the daemon runs two exports; the HDF5 writes take turns)
        pair = [os.path.join(b.dir, "p%d.nxs" % k) for k in (1, 2)]
        procs = [subprocess.Popen([ACQCTL, "-s", b.sock, "export", str(sid), "--format", "nexus", "-o", x],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for x in pair]
        for x, pr in zip(pair, procs):
            _, err = pr.communicate(timeout=120)
            assert pr.returncode == 0, "concurrent export: %s" % err
            nexuscheck.same_content(out, x)
        # --format csv is the CSV stream, as without --format
        csv = os.path.join(b.dir, "s.csv")
        p = ctl(b, "export", str(sid), "--format", "csv", "-o", csv)
        assert p.returncode == 0 and len(open(csv).read().splitlines()) == got["calibrated"] + 2, p.stderr
        # refusals
        p = ctl(b, "export", str(sid), "format=xml", "-o", os.path.join(b.dir, "x"))
        assert p.returncode == 1 and "expected csv or nexus" in p.stderr, p.stderr
        p = ctl(b, "status", "--format", "nexus")
        assert p.returncode == 64 and "option of export" in p.stderr, p.stderr
        missing = os.path.join(b.dir, "none.nxs")
        p = ctl(b, "export", "999", "--format", "nexus", "-o", missing)
        assert p.returncode == 1 and "999" in p.stderr, p.stderr
        # a client that leaves before its file is ready: the daemon carries on
        c = L.Client(b.sock)
        c.sock.sendall((json.dumps({"cmd": "export", "id": 7, "sweep": sid, "format": "nexus"}) + "\n").encode())
        c.close()
        time.sleep(1.0)
        p = ctl(b, "export", str(sid), "--format", "nexus", "-o", os.path.join(b.dir, "again.nxs"))
        assert p.returncode == 0, p.stderr
        left = [x for x in os.listdir(os.path.join(b.state, "export")) if x.startswith(".")]
        assert not left, "temporary files left in the export folder: %s" % left
        assert not os.path.exists(missing)


L.main(run)
