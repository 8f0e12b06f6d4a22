#!/usr/bin/python3
"""Integration: acqctl as the operator uses it, on the simulated bench.
- every command's --json output validates against its schema in proto/schema/acqctl-replies.schema.json
  (and every refusal against the error schema), human output is produced for each;
- exit codes: 0 ok, 1 refused, 64 usage, 65 a plan that is not UTF-8 text (file:line:col), 66 unreadable input,
  69 no daemon; --help and --version never connect
  (checked with a socket path that would hang: a listener that never answers);
- home, stop (of a running move: the move's requester gets the refusal), laser off (the simulator's truth says
  emission off), spectrum ID (--json, --csv, -o);
- replies show the state after the command (sweep abort -> idle, move -> the new positions);
- `acqctl watch` (not a terminal) prints JSON lines and reconnects when the daemon restarts;
- `acq-sim ctl` drives the simulator (sample, fault, truth) with its exit codes; --version of the five programs."""
import json
import re
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import acqtest as A  # noqa: E402
import sweeplib as L  # noqa: E402

try:
    import jsonschema
except ImportError:  # Debian python3-jsonschema is for /usr/bin/python3 (make deps installs it)
    jsonschema = None

CTL = os.path.join(L.BUILD, "acqctl")
SCHEMA = json.load(open(os.path.join(L.SRC, "proto", "schema", "acqctl-replies.schema.json")))
PLAN = "name: t-acqctl\nincidence:\n  theta_deg: [20]\nobservation:\n  theta_deg: [40]\n" \
       "  phi_deg: [0, 180]\nintegration: {mode: fixed, ms: 5}\naverages: 1\nblind_points: drop\n"


def check(cond, what):
    if not cond:
        raise AssertionError(what)


def validate(doc, name):
    if jsonschema is None:
        raise L.Skip("python3-jsonschema missing (make deps installs it)")
    sch = dict(SCHEMA)
    sch["$ref"] = "#/$defs/" + name
    try:
        jsonschema.validate(doc, sch)
    except jsonschema.ValidationError as e:
        raise AssertionError("%s: %s does not match its schema: %s" % (name, json.dumps(doc)[:300], e.message))


class Ctl:
    def __init__(self, sock, env=None):
        self.sock, self.env = sock, env

    def run(self, *args, timeout=60):
        return subprocess.run([CTL, "-s", self.sock] + list(args), capture_output=True, text=True, timeout=timeout,
                              env=self.env)

    def json(self, name, *args, rc=0):
        """acqctl --json ARGS: exit status rc, one JSON document on stdout, valid against $defs[name]."""
        p = self.run("--json", *args)
        check(p.returncode == rc, "acqctl %s: exit %d, wanted %d: %s" % (" ".join(args), p.returncode, rc, p.stderr))
        lines = p.stdout.splitlines()
        check(len(lines) == 1, "acqctl --json %s: %d lines of output" % (" ".join(args), len(lines)))
        doc = json.loads(lines[0])
        validate(doc, name if rc == 0 else "error")
        return doc

    def human(self, *args, rc=0):
        p = self.run(*args)
        check(p.returncode == rc and (p.stdout if rc == 0 else p.stderr),
              "acqctl %s: exit %d (wanted %d), out %r err %r" % (" ".join(args), p.returncode, rc, p.stdout, p.stderr))
        return p.stdout if rc == 0 else p.stderr


def wait_for(cond, what, timeout=30):
    """Poll cond() until it is true (a deadline, not a fixed wait: the machine may be loaded)."""
    end = time.time() + timeout
    while not cond():
        check(time.time() < end, "%s: not within %d s" % (what, timeout))
        time.sleep(0.02)


class Lines:
    """A subprocess's stdout read line by line on a thread, so a test can wait for a line as it arrives."""

    def __init__(self, proc):
        self.lines, self.lock = [], threading.Lock()
        self.t = threading.Thread(target=self._read, args=(proc.stdout,), daemon=True)
        self.t.start()

    def _read(self, f):
        for line in f:
            with self.lock:
                self.lines.append(line)

    def events(self):
        with self.lock:
            return [json.loads(x)["event"] for x in self.lines]


def hanging_socket(path):
    """A listener that accepts and never says anything: a client that connects waits forever."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(path)
    s.listen(8)
    return s


def garbling_socket(path):
    """A listener that greets as acquisitiond does, then answers every request with a line that is not JSON."""
    return A.fake_daemon(path, lambda line: b"this is not json\n")


def offline_checks(tmp):
    hang = os.path.join(tmp, "hang.sock")
    hs = hanging_socket(hang)
    try:
        for args in (["--help"], ["sweep", "start", "--help"], ["help", "export"], ["--version"], ["export", "-h"],
                     ["wait", "--help"]):
            t0 = time.time()
            p = subprocess.run([CTL, "-s", hang] + args, capture_output=True, text=True, timeout=10)
            check(p.returncode == 0 and p.stdout and time.time() - t0 < 5, "acqctl %s connected or failed: %d %r"
                  % (" ".join(args), p.returncode, p.stderr))
        check(subprocess.run([CTL, "--version"], capture_output=True, text=True).stdout.startswith("acqctl "),
              "acqctl --version")
        for prog in ("acquisitiond", "acq-sim", "brdf-recon", "acq-nexus"):
            p = subprocess.run([os.path.join(L.BUILD, prog), "--version"], capture_output=True, text=True, timeout=10)
            check(p.returncode == 0 and p.stdout.startswith(prog + " "), "%s --version: %d %r" % (prog, p.returncode,
                                                                                              p.stdout + p.stderr))
        # usage errors: 64, before anything is sent (the hanging socket would time the call out)
        # (and arguments that used to pass: an id beyond 2^63 sent as 2^63 - 1, -t wrapping around an int, an empty
        # -o or -s named as ": No such file" after the request)
        for args in (["bogus"], ["move", "laser_theta=abc"], ["move", "nope=1"], ["sweep", "show"], ["--frob"],
                     ["export", "1", "2"], ["wait", "sideways"], [], ["sweep", "show", "99999999999999999999"],
                     ["-t", "99999999999", "status"], ["export", "1", "-o", ""], ["-s", "", "status"]):
            try:
                p = subprocess.run([CTL, "-s", hang] + args, capture_output=True, text=True, timeout=10)
            except subprocess.TimeoutExpired:
                raise AssertionError("acqctl %r: sent to the daemon, wanted exit 64" % args)
            check(p.returncode == 64, "acqctl %s: exit %d, wanted 64 (%r)" % (" ".join(args), p.returncode, p.stderr))
        # a group's word alone names its sub-commands
        p = subprocess.run([CTL, "-s", hang, "sweep"], capture_output=True, text=True, timeout=10)
        check(p.returncode == 64 and "sweep: expected one of start, pause, resume, abort, list, show" in p.stderr,
              "acqctl sweep: %d %r" % (p.returncode, p.stderr))
        p = subprocess.run([CTL, "-s", hang, "--json", "bogus"], capture_output=True, text=True, timeout=10)
        validate(json.loads(p.stdout), "error")
        p = subprocess.run([CTL, "-s", hang, "sweep", "start", os.path.join(tmp, "none.yaml")], capture_output=True,
                           text=True, timeout=10)
        check(p.returncode == 66 and "none.yaml" in p.stderr, "unreadable plan: %d %r" % (p.returncode, p.stderr))
        # a plan that is not UTF-8 text: 65 before anything is sent, where the byte is (a NUL cut the text short
        # and sent the rest; a Latin-1 byte said "missing plan", 64)
        for name, data, where in (("nul.yaml", PLAN.encode()[:60] + b"\0\0garbage: [", "nul.yaml:5:4: a NUL byte"),
                                  ("latin1.yaml", b"# \xe9chantillon\n" + PLAN.encode(), "latin1.yaml:1:3: byte 0xe9")):
            open(os.path.join(tmp, name), "wb").write(data)
            try:
                p = subprocess.run([CTL, "-s", hang, "sweep", "start", os.path.join(tmp, name)], capture_output=True,
                                   text=True, timeout=10)
            except subprocess.TimeoutExpired:
                raise AssertionError("acqctl sweep start %s: sent to the daemon" % name)
            check(p.returncode == 65 and where in p.stderr, "plan %s: exit %d, wanted 65 naming %r (%r)" % (
                name, p.returncode, where, p.stderr))
        # export -o FILE that cannot be created: 73 before anything is sent (the daemon streams nothing for it)
        t0 = time.time()
        p = subprocess.run([CTL, "-s", hang, "export", "1", "-o", os.path.join(tmp, "nodir", "x.csv")],
                           capture_output=True, text=True, timeout=10)
        check(p.returncode == 73 and "nodir" in p.stderr and time.time() - t0 < 5,
              "export -o into no folder: exit %d, wanted 73 at once (%r)" % (p.returncode, p.stderr))
    finally:
        hs.close()
    # a reply that is not the protocol's: 76 (EX_PROTOCOL), with the error document under --json
    bad = os.path.join(tmp, "bad.sock")
    bs = garbling_socket(bad)
    try:
        p = subprocess.run([CTL, "-s", bad, "--json", "status"], capture_output=True, text=True, timeout=10)
        check(p.returncode == 76, "a reply that is not JSON: exit %d, wanted 76 (%r)" % (p.returncode, p.stderr))
        validate(json.loads(p.stdout), "error")
        check(json.loads(p.stdout)["error"]["code"] == "protocol", "protocol error %r" % p.stdout)
    finally:
        bs.close()
    nosock = os.path.join(tmp, "nosuch.sock")
    # the output cannot be written (a full disk: /dev/full): 73 (EX_CANTCREAT), human and --json alike
    plan_q = os.path.join(L.SRC, "config", "plan-quick.yaml")
    for js in ([], ["--json"]):
        with open("/dev/full", "w") as full:
            p = subprocess.run([CTL, "-s", nosock] + js + ["plan", plan_q], stdout=full, stderr=subprocess.PIPE,
                               text=True, timeout=30)
        check(p.returncode == 73 and "cannot write" in p.stderr, "plan %s to a full disk: exit %d, wanted 73 (%r)" % (
            " ".join(js), p.returncode, p.stderr))
    c = Ctl(nosock)
    d = c.json("error", "status", rc=69)
    check(d["error"]["code"] == "unavailable", "no daemon: %r" % d)
    check("cannot connect" in c.human("status", rc=69), "no daemon, human")
    # a plan's name with a control character (a terminal escape or a newline, into `sweep list`, the log) is
    # refused where it is, as sample: is
    escf = os.path.join(tmp, "esc.yaml")
    open(escf, "w").write(PLAN.replace("name: t-acqctl", 'name: "evil\\e[2J\\nline2"'))
    p = c.run("plan", escf, "--config", os.path.join(L.SRC, "config", "bench-sim.yaml"))
    check(p.returncode == 1 and "esc.yaml:1:7: name: a control character at position 5" in p.stderr,
          "a plan name with an escape: %d %r" % (p.returncode, p.stderr))
    # plan: one output whether or not a daemon answers (local dry run)
    plan = os.path.join(tmp, "p.yaml")
    open(plan, "w").write(PLAN)
    d = c.json("plan", "plan", plan, "--config", os.path.join(L.SRC, "config", "bench-sim.yaml"))
    check(d["source"] == "local", "local plan %r" % d)
    # the prediction term by term: the terms sum to it (JSON floats of 6 decimals); fixed integration: no probe
    t, pred = d["plan"]["predicted_terms"], d["plan"]["predicted_s"]
    check(abs(sum(t.values()) - pred) < 1e-4 and t["motion_s"] > 0 and t["first_exposures_s"] > 0 and
          t["probes_s"] == 0 and t["hdr_s"] == 0,
          "terms %r sum to %r, predicted %r" % (t, sum(t.values()), pred))
    return plan, d


PARK = {"laser.theta": 30.0, "detector.theta": 30.0, "detector.phi": 180.0}  # config/bench-sim.yaml home.park
COLLISION_DEG = 6 + 5 + 1  # bench-sim.yaml: laser body + detector body half-widths + safety margin


def separation_deg(lt, dt, dp):
    """Angle between the laser's direction (zenith lt, azimuth 0) and the detector's (dt, dp), degrees."""
    r = math.radians
    c = math.cos(r(lt)) * math.cos(r(dt)) + math.sin(r(lt)) * math.sin(r(dt)) * math.cos(r(dp))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def home_all(b, c, start=(10, 40, 90)):
    """acqctl home (all axes) from start: rc 0, every axis homed (the controllers say so), the reply's and the
    simulator's positions are the parks, no contact and no pose closer than the collision limit seen. Returns the
    reply."""
    c.json("move", "move", "detector.theta=%g" % start[1], "detector.phi=%g" % start[2])
    c.json("move", "move", "laser.theta=%g" % start[0])
    coll0 = int(b.sim_status()["collisions"])
    seen, stop = [], threading.Event()

    def sample():
        while not stop.is_set():
            st = b.sim_status()
            seen.append(separation_deg(float(st["laser.theta"]), float(st["detector.theta"]),
                                       float(st["detector.phi"])))
            time.sleep(0.01)
    t = threading.Thread(target=sample)
    t.start()
    try:
        d = c.json("home", "home")
    finally:
        stop.set()
        t.join(10)
    check(sorted(d["homed"]) == sorted(PARK) and d["parked"] is True, "home of all axes from %r: %r" % (start, d))
    for k, v in PARK.items():
        check(abs(d[k] - v) < 0.05, "home of all axes: %s at %r, its park %r" % (k, d[k], v))
    sim = b.sim_status()
    for k, v in PARK.items():
        check(abs(float(sim[k]) - v) < 0.05, "the simulator's %s at %s, its park %r" % (k, sim[k], v))
    check(int(sim["collisions"]) == coll0, "home of all axes: the simulator counted a contact %r" % sim)
    check(len(seen) > 20 and min(seen) >= COLLISION_DEG - 0.05,
          "home of all axes: %d samples, the arms %.2f° apart at the closest (limit %d)"
          % (len(seen), min(seen or [0]), COLLISION_DEG))
    print("# home of all axes: %d samples of the simulator, the arms %.2f° apart at the closest (limit %d)"
          % (len(seen), min(seen), COLLISION_DEG))
    devs = c.json("devices", "devices")
    axes = [x for x in devs["devices"] if x["name"] in PARK]
    check(len(axes) == 3 and all(x["status"]["homed"] for x in axes), "every axis referenced %r" % axes)
    return d


def main():
    with L.Bench(scale=5.0) as b:  # slow enough for a move to be stopped midway
        tmp = b.dir
        plan, local = offline_checks(tmp)
        b.start_sim()
        b.start_daemon()
        c = Ctl(b.sock)
        # --- information commands: schema and human output
        for name, args in (("version", ["version"]), ("status", ["status"]), ("devices", ["devices"]),
                           ("config", ["config"]), ("sweep.list", ["sweep", "list"])):
            c.json(name, *args)
            c.human(*args)
        out = c.human("status")
        check(out.startswith("daemon     running") and "(simulated bench)" in out, "status human %r" % out)
        out = c.human("devices")
        check("°" in out and "Oriental Motor" in out and "Avantes" in out, "devices human %r" % out)
        serials = re.findall(r"^(?:laser|detector)\.\w+ .*serial (\d+)", out, re.M)  # one per controller unit
        check(len(serials) == 3 and len(set(serials)) == 3, "the axes' serials %r (both arms said 1001)" % serials)
        # plan: the daemon's answer has the local one's shape and figures
        d = c.json("plan", "plan", plan)
        check(d["source"] == "daemon", "daemon plan %r" % d["source"])
        for k in ("requested", "kept", "dropped", "measured", "duration_s"):
            check(d["plan"][k] == local["plan"][k], "plan %s: daemon %r, local %r" % (k, d["plan"][k], local["plan"][k]))
        d = c.json("plan", "plan", plan, "--points")
        check(len(d["plan"]["steps"]) == d["plan"]["measured"], "--points reaches the daemon")
        # a plan whose steps take more than a request line (64 KiB; 287 points: 84 KB) comes whole from the daemon
        # (the paper's 866 points were refused: "the reply is longer than 65536 bytes")
        bigf = os.path.join(b.dir, "big.yaml")
        with open(bigf, "w") as fh:
            fh.write(PLAN.replace("theta_deg: [20]", "theta_deg: [10, 30, 50, 65]")
                     .replace("theta_deg: [40]", "theta_deg: [10, 25, 40, 55, 70]")
                     .replace("phi_deg: [0, 180]", "phi_deg: [%s]" % ", ".join(str(24 * k) for k in range(15))))
        p = c.run("--json", "plan", bigf, "--points")
        check(p.returncode == 0 and len(p.stdout) > 65536, "a large --points plan from the daemon: rc %d, %d bytes, %s"
              % (p.returncode, len(p.stdout), p.stderr.strip()))
        d = json.loads(p.stdout)
        check(d["source"] == "daemon" and len(d["plan"]["steps"]) == d["plan"]["measured"] > 250,
              "large --points: %s, %d steps of %d" % (d["source"], len(d["plan"]["steps"]), d["plan"]["measured"]))
        validate(d, "plan")
        # --- manual commands on the simulated bench
        d = c.json("home", "home", "detector.phi")
        check(d["homed"] == ["detector.phi"] and abs(d["detector.phi"]) < 0.05, "home %r" % d)
        # one axis whose way home is not free is refused and nothing moves: detector.theta's home (0°) is the
        # laser's place while the laser is at 0°
        c.json("move", "move", "laser.theta=0", "detector.theta=40", "detector.phi=90")
        p = c.run("home", "detector.theta")
        check(p.returncode == 1 and "home detector.theta" in p.stderr and "collision" in p.stderr,
              "home detector.theta with the laser at 0: rc %d %r" % (p.returncode, p.stderr))
        check(abs(float(b.sim_status()["detector.theta"]) - 40) < 0.05, "refused home left detector.theta at 40")
        # home of every axis from (10, 40, 90): each referenced, then at its park (home.park of bench-sim.yaml),
        # one axis at a time in a collision-free order; the simulator, sampled all along, never sees the arms
        # closer than the daemon's collision limit and counts no contact
        d = home_all(b, c)
        check("apart" not in d, "no apart move from (10, 40, 90) %r" % d)
        out = c.human("home")
        line = [x for x in out.splitlines() if x.startswith("parked at ")]
        shown = dict((k, float(v)) for k, v in re.findall(r"(\S+) (-?[0-9.]+)°", line[0])) if line else {}
        check("homed laser.theta, detector.theta, detector.phi" in out and sorted(shown) == sorted(PARK) and
              all(abs(shown[k] - v) < 0.05 for k, v in PARK.items()) and "apart" not in out,
              "home human (parked, and where) %r" % out)
        # from (10, 10, 90) every home closes the arms in (each axis's home is within 12° of the other arm): the
        # laser is moved apart first (one single-axis move the manual-move rule allows), then the order runs as above
        d = home_all(b, c, start=(10, 10, 90))
        check([m["axis"] for m in d.get("apart", [])] == ["laser.theta"] and d["apart"][0]["to"] > 10,
              "home from (10, 10, 90) moves the laser apart first %r" % d)
        # one name per axis (laser.theta=); the old spelling (laser_theta=) still moves the same axis
        d = c.json("move", "move", "laser.theta=20", "detector.theta=40", "detector_phi=90")
        check(abs(d["laser.theta"] - 20) < 0.05 and abs(d["detector.theta"] - 40) < 0.05 and
              abs(d["detector.phi"] - 90) < 0.05, "move shows the after %r" % d)
        p = c.run("move", "laser.theta=20", "laser_theta=21")
        check(p.returncode == 64 and "given twice (as laser_theta too)" in p.stderr, "one axis under both names: rc %d %r" % (p.returncode,
                                                                                                     p.stderr))
        p = c.run("home", "bogus")
        check(p.returncode == 1 and "laser.theta, detector.theta, detector.phi" in p.stderr,
              "home's error names the axes by their one name: %r" % p.stderr)
        d = c.json("stop", "stop")
        check(d["stopped"] is False, "stop with nothing running %r" % d)
        # stop a long move: its requester gets "stopped by the operator", the arm stops short of the target
        res = {}
        t = threading.Thread(target=lambda: res.update(p=c.run("--json", "move", "detector_phi=350")))
        t.start()
        wait_for(lambda: float(b.sim_status()["detector.phi"]) > 91, "the arm moving towards 350")  # under way, far from 350
        d = c.json("stop", "stop")
        t.join(30)
        check(d["stopped"] is True and 90 < d["detector.phi"] < 349, "stop mid-move %r" % d)
        mv = json.loads(res["p"].stdout)
        check(res["p"].returncode == 1 and "stopped by the operator" in mv["error"]["message"], "stopped move %r" % mv)
        validate(mv, "error")
        # laser off: the simulator's truth agrees
        b.ctl("laser on 50")
        d = c.json("laser.off", "laser", "off")
        check(b.sim_status()["emission"] == "0", "laser off: the simulator still emits")
        # a measurement, then its spectrum
        m = c.json("measure", "measure", "integration_ms=20", "averages=1")
        sid = m["spectrum_id"]
        check(b.sim_status()["emission"] == "0", "the laser is off after a measurement")
        d = c.json("spectrum", "spectrum", str(sid))
        s = d["spectrum"]
        check(s["id"] == sid and s["npix"] == len(s["counts"]) == len(s["wavelength_nm"]) and s["kind"] == "sample",
              "spectrum %r" % {k: s[k] for k in ("id", "npix", "kind")})
        check(abs(max(x for x in s["counts"] if x is not None) - m["peak"]) < 1e-3 * m["peak"], "the same spectrum")
        out = c.human("spectrum", str(sid), "--csv")
        rows = out.splitlines()
        check(rows[1].startswith("wavelength_nm,counts") and len(rows) == 2 + s["npix"], "spectrum CSV %r" % rows[:2])
        wl0 = float(rows[2].split(",")[0])
        check(400 < wl0 < 1200, "wavelength column in nm: %r" % rows[2])
        csvf = os.path.join(tmp, "spec.csv")
        check("rows written to" in c.human("spectrum", str(sid), "--csv", "-o", csvf), "spectrum -o summary")
        check(open(csvf).read() == out, "spectrum -o FILE")
        d = c.json("error", "spectrum", "999999", rc=1)
        check(d["error"]["code"] == "not_found", "missing spectrum %r" % d)
        # a dark (laser off) and a reference (the white standard is on the stage), each a stored spectrum
        d = c.json("dark", "dark", "integration_ms=20", "averages=1")
        check(d["spectrum_id"] > sid and b.sim_status()["emission"] == "0", "dark %r" % d)
        d = c.json("reference", "reference", "integration_ms=20", "averages=1")
        check(d["spectrum_id"] > sid and c.json("spectrum", "spectrum", str(d["spectrum_id"]))["spectrum"]["kind"] ==
              "reference", "reference %r" % d)
        err = c.human("move", "detector_theta=500", rc=1)  # refused by the daemon: 1, said once with its command
        check(err.startswith("acqctl: move: \"detector.theta\": expected a number in [") and "move: move" not in err,
              "refused move: %r" % err)
        # a move beyond the bench's range names the axis and the range; one into the other arm says so
        err = c.human("move", "detector.phi=400", rc=1)
        check("detector.phi: 400° is outside the bench's range [-179°, 359°]" in err, "move beyond the bench: %r" % err)
        err = c.human("move", "laser.theta=60", "detector.theta=60", "detector.phi=0", rc=1)
        check("collision: the arms would meet at laser.theta 60°, detector.theta 60°, detector.phi 0°" in err,
              "move into a collision: %r" % err)
        # the daemon's refusal of a plan names the file and its line (it reads the text as "plan")
        badf = os.path.join(tmp, "bad-avg.yaml")
        open(badf, "w").write(PLAN.replace("averages: 1", "averages: -2"))
        err = c.human("plan", badf, rc=1)
        check(err.startswith("acqctl: plan: %s:8:11: averages: -2" % badf), "plan refused: %r" % err)
        d = c.json("error", "sweep", "start", badf, rc=1)
        check(d["error"]["message"].startswith(badf + ":8:11: "), "sweep start refused, --json: %r" % d)
        # a plan longer than a request line (64 KiB) is refused by acqctl, naming the file (65; the daemon's own
        # refusal said "plan: line longer than 65536 bytes: ignored up to its newline", 1)
        longf = os.path.join(tmp, "long.yaml")
        open(longf, "w").write(PLAN.replace("phi_deg: [0, 180]", "phi_deg: [%s]" % ", ".join(
            "%.3f" % (k * 0.01) for k in range(12000))))
        p = c.run("sweep", "start", longf)
        check(p.returncode == 65 and p.stderr.startswith("acqctl: sweep start %s: the request is " % longf) and
              "more than the daemon reads in one line (65536 bytes)" in p.stderr, "a long plan: rc %d %r" % (
                  p.returncode, p.stderr))
        err = c.human("spectrum", "0", rc=1)  # an id's range is not 2^53
        check("expected an integer >= 1" in err and "spectrum: spectrum" not in err, "spectrum 0: %r" % err)
        # --- a sweep: replies show the state after the command
        b.ctl("sample white")
        d = c.json("sweep.start", "sweep", "start", plan)
        check(d["progress"]["state"] == "running" and d["progress"]["id"] == d["sweep"], "start %r" % d)
        p = c.run("wait", "paused", "--timeout-s", "60")  # the reference is measured, then it pauses
        check(p.returncode == 0 and "paused" in p.stdout, "wait paused: %d %r" % (p.returncode, p.stderr))
        d = c.json("sweep.resume", "sweep", "resume")
        check(d["progress"]["state"] == "running" and "paused" not in d["progress"]["message"], "resume %r" % d)
        d = c.json("sweep.pause", "sweep", "pause")
        # the reply comes once paused, or after 10 s with the pause still pending behind a slow point (a loaded
        # machine): then it must say so, and the sweep must pause after that point
        pr = d["progress"]
        check(pr["state"] == "paused" and not pr["pause_pending"]
              or pr["state"] == "running" and pr["pause_pending"], "pause shows after %r" % d)
        if pr["state"] != "paused":
            p = c.run("wait", "paused", "--timeout-s", "60")
            check(p.returncode == 0, "pending pause took effect: %d %r" % (p.returncode, p.stderr))
        # paused: no ETA (it does not count while paused), in the reply and in the human status
        d = c.json("status", "status")
        check(d["sweep"]["state"] == "paused" and d["sweep"]["eta_s"] is None, "paused status shows an ETA %r" %
              d["sweep"])
        check("ETA" not in d["summary"], "paused status' summary (systemctl status) shows an ETA %r" % d["summary"])
        out = c.human("status")
        check("paused" in out and "ETA" not in out, "paused human status shows an ETA %r" % out)
        # wait --json prints the status reply it waited for (the status schema)
        d = c.json("status", "wait", "paused", "--timeout-s", "10")
        check(d["sweep"]["state"] == "paused", "wait --json %r" % d["sweep"])
        p = c.run("wait", "running", "--timeout-s", "1")
        check(p.returncode == 75, "wait times out with 75: %d" % p.returncode)
        d = c.json("sweep.abort", "sweep", "abort")
        check(d["progress"]["state"] == "idle" and "aborted" in d["progress"]["message"], "abort shows after %r" % d)
        d = c.json("error", "sweep", "abort", rc=1)
        check(d["error"]["code"] == "state", "second abort %r" % d)
        d = c.json("sweep.list", "sweep", "list")
        check(d["sweeps"][0]["state"] == "aborted", "aborted in the list %r" % d["sweeps"][0])
        out = c.human("sweep", "list")
        check("aborted" in out and "T" in out.splitlines()[1], "sweep list with dates %r" % out)
        swid = d["sweeps"][0]["id"]
        d = c.json("sweep.show", "sweep", "show", str(swid), "--points")
        pts = d["sweep"]["points"]
        check(pts and all("laser.theta" in p and "laser_theta" not in p for p in pts) and
              all(isinstance(p["detector.phi"], (int, float)) for p in pts if p["state"] == "done"),
              "sweep show --points names the axes as everywhere %r" % pts[:2])
        d = c.json("error", "recon", "status", "1", rc=1)  # positional form, no run for this sweep
        check(d["error"]["code"] == "not_found", "recon status 1 %r" % d)
        d = c.json("error", "recon", "start", "999999", rc=1)
        check(d["error"]["code"] == "not_found", "recon start of no sweep %r" % d)
        # export --json -o: the CSV in the file (written by acqctl), the summary on stdout
        xf = os.path.join(tmp, "aborted.csv")
        open(xf, "w").write("x" * 4000000)  # an older, longer file: replaced, not written over in place
        d = c.json("export", "-o", xf, "export", str(swid))
        check(d["output"] == xf and os.path.getsize(xf) == d["bytes"], "export -o %r" % d)
        # a refused export leaves -o as it was: an existing file untouched, none created
        keep, gone = os.path.join(tmp, "keep.csv"), os.path.join(tmp, "gone.csv")
        open(keep, "w").write("keep\n")
        for f in (keep, gone):
            c.json("error", "-o", f, "export", "999999", rc=1)
        check(open(keep).read() == "keep\n" and not os.path.exists(gone), "-o after a refused export")
        # the next sweep starts without the previous one's ETA (none before its first point)
        d = c.json("sweep.start", "sweep", "start", plan)
        check(d["progress"]["state"] == "running" and d["progress"]["eta_s"] is None and
              "eta_low_s" not in d["progress"], "a second sweep starts with an ETA %r" % d["progress"])
        # a loaded sweep keeps its devices: reload is refused until it ends
        e = c.json("error", "reload", rc=1)
        check(e["error"]["code"] == "state" and "sweep is loaded" in e["error"]["message"], "reload in a sweep %r" % e)
        c.json("sweep.abort", "sweep", "abort")
        # --- reload says what the new file changed: a file without its devices section closes every device
        # (before: "configuration reloaded from PATH" and nothing else, the devices "not configured")
        good = open(b.conf).read()
        open(b.conf, "w").write(L.strip_sections(good, {"devices"}))
        out = c.human("reload")
        print("# acqctl reload of the file without devices:\n#   " + out.rstrip().replace("\n", "\n#   "))
        names = ("laser.theta", "detector.theta", "detector.phi", "spectrometer", "laser")
        check(all(("warning: %s: no longer configured" % n) in out for n in names) and
              "  devices: removed (was " in out, "reload without devices: %r" % out)
        changed = good.replace("response_timeout_ms: 500", "response_timeout_ms: 400", 1)
        check(changed != good, "bench-sim.yaml has no response_timeout_ms: 500")
        open(b.conf, "w").write(changed)
        d = c.json("reload", "reload")
        # (available, or unavailable with why when an open timed out on a loaded machine: the retry brings it)
        check(d["warnings"] == [] and all(any(x.startswith("%s: now configured, " % n) for x in d["changes"])
                                          for n in names) and
              any(x.startswith("devices: added (") for x in d["changes"]), "devices back %r" % d)
        open(b.conf, "w").write(good)
        d = c.json("reload", "reload")
        check(d["warnings"] == [] and d["changes"] == ["devices.laser_arm.response_timeout_ms: 400 → 500"],
              "one setting changed %r" % d)
        # --- watch: JSON lines, reconnects across a daemon restart
        watchers = lambda: c.json("status", "status").get("watchers", 0)
        before = watchers()
        w = subprocess.Popen([CTL, "-s", b.sock, "watch"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        seen = Lines(w)
        wait_for(lambda: watchers() > before, "acqctl watch subscribed")
        c.json("reload", "reload")
        wait_for(lambda: seen.events().count("config") == 1, "the first config event")
        b.kill_daemon(signal.SIGTERM)
        wait_for(lambda: "acqctl.disconnected" in seen.events(), "watch sees the daemon go")
        b.start_daemon()
        wait_for(lambda: "acqctl.reconnected" in seen.events(), "watch reconnects")
        wait_for(lambda: watchers() > 0, "acqctl watch subscribed again")
        c.json("reload", "reload")
        wait_for(lambda: seen.events().count("config") == 2, "the second config event")
        w.terminate()
        w.wait(10)
        seen.t.join(10)
        evs = [json.loads(x) for x in seen.lines]
        for e in evs:
            validate(e, "watch")
        names = [e["event"] for e in evs]
        check(names.count("config") == 2 and "acqctl.disconnected" in names and "acqctl.reconnected" in names,
              "watch across a restart: %r" % names)
        last_config = len(names) - 1 - names[::-1].index("config")
        check(names.index("acqctl.disconnected") < names.index("acqctl.reconnected") < last_config, "order %r" % names)
        check(w.returncode == 0, "watch ends with 0 on SIGTERM (%r)" % w.returncode)
        # --- watch on a terminal: the live view (redrawn in place), not JSON
        import pty
        mfd, sfd = pty.openpty()
        tw = subprocess.Popen([CTL, "-s", b.sock, "watch"], stdout=sfd, stderr=sfd, stdin=subprocess.DEVNULL)
        os.close(sfd)
        buf = b""
        deadline = time.time() + 10
        while time.time() < deadline and b"last events" not in buf:
            try:
                buf += os.read(mfd, 65536)
            except OSError:
                break
        c.json("reload", "reload")
        t_end = time.time() + 30
        while time.time() < t_end and b"configuration reloaded" not in buf:
            try:
                buf += os.read(mfd, 65536)
            except OSError:
                break
        tw.terminate()
        tw.wait(10)
        os.close(mfd)
        text = buf.decode(errors="replace")
        check("\033[H\033[2J" in text and "acqctl watch" in text and "devices" in text and "spectrometer" in text
              and "configuration reloaded" in text and not text.lstrip().startswith("{"), "TTY view %r" % text[-600:])
        # --- acq-sim ctl
        sim = os.path.join(L.BUILD, "acq-sim")
        env = dict(os.environ, ACQ_SIM_PORTS=b.ports)
        p = subprocess.run([sim, "ctl", "reference"], capture_output=True, text=True, env=env)
        check(p.returncode == 0 and b.sim_status()["sample"] == "white", "acq-sim ctl reference %r" % p.stderr)
        p = subprocess.run([sim, "ctl", "--json", "sample", "metal"], capture_output=True, text=True, env=env)
        check(p.returncode == 0 and json.loads(p.stdout) == {"ok": True, "sample": "metal"}, "ctl sample %r" % p.stdout)
        p = subprocess.run([sim, "ctl", "--control", b.ctl_path, "--json", "truth"], capture_output=True, text=True)
        t = json.loads(p.stdout)
        check(p.returncode == 0 and t["sample"] == "metal" and "laser.theta" in t and "laser_theta" not in t, "ctl truth %r" % t)
        p = subprocess.run([sim, "ctl", "fault", "bogus"], capture_output=True, text=True, env=env)
        check(p.returncode == 1 and "unknown fault" in p.stderr, "ctl refused %r" % p.stderr)
        p = subprocess.run([sim, "ctl", "fault", "saturation-burst", "2"], capture_output=True, text=True, env=env)
        check(p.returncode == 0, "ctl fault %r" % p.stderr)
        check("saturation-burst" in b.sim_status()["faults"], "fault active %r" % b.sim_status())
        p = subprocess.run([sim, "ctl", "--control", os.path.join(tmp, "none.sock"), "status"], capture_output=True,
                           text=True)
        check(p.returncode == 69, "ctl without a simulator: %d" % p.returncode)
        p = subprocess.run([sim, "ctl"], capture_output=True, text=True)
        check(p.returncode == 64, "ctl usage: %d" % p.returncode)
        # usage errors are 64 like acqctl's (were 1, "refused"): a missing argument (said before asking), an
        # unknown command (the simulator's "unknown command")
        for args, words in ((["sample"], "sample needs NAME"), (["pose", "1", "2"], "pose needs"),
                            (["frob"], "unknown command 'frob'")):
            p = subprocess.run([sim, "ctl"] + args, capture_output=True, text=True, env=env)
            check(p.returncode == 64 and words in p.stderr, "ctl %s: %d %r" % (" ".join(args), p.returncode, p.stderr))
        # --json: integers as integers, no float noise (74.325900000000004), time's value kept (was {"ok": true})
        p = subprocess.run([sim, "ctl", "--json", "truth"], capture_output=True, text=True, env=env)
        t = json.loads(p.stdout)
        check(type(t["emission"]) is int and type(t["collisions"]) is int and
              not re.search(r"\.\d*0000000\d", p.stdout), "ctl --json truth's numbers %r" % p.stdout)
        p = subprocess.run([sim, "ctl", "--json", "time"], capture_output=True, text=True, env=env)
        check(p.returncode == 0 and json.loads(p.stdout)["t"] > 0, "ctl --json time %r" % p.stdout)
        print("ok: acqctl commands, schemas, exit codes, watch reconnection, acq-sim ctl")


if __name__ == "__main__":
    L.main(main)
