#!/usr/bin/python3
"""Golden test of acqctl's human output: a stand-in daemon answers with the recorded replies of
tests/golden/acqctl/replies.json, acqctl renders them (TZ=Europe/Paris, C.UTF-8), and the output must equal
tests/golden/acqctl/<command>.txt byte for byte (stable formatting: local ISO 8601 times with offset, h:mm:ss,
angles rounded with their unit, aligned tables). ACQ_GOLDEN_UPDATE=1 rewrites the .txt files (review the diff)."""
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import acqtest as A  # noqa: E402

BUILD = os.environ.get("ACQ_BUILD") or os.path.abspath("build")
SRC = os.environ.get("ACQ_SRC") or os.path.abspath(".")
GOLD = os.path.join(SRC, "tests", "golden", "acqctl")
CASES = [("version", ["version"]), ("status", ["status"]), ("devices", ["devices"]), ("sweep.list", ["sweep", "list"]),
         ("sweep.show", ["sweep", "show", "2"]), ("plan", ["plan", "PLANFILE"]),
         ("move", ["move", "laser.theta=20", "detector.theta=40", "detector.phi=90"]), ("home", ["home"]),
         ("sweep.abort", ["sweep", "abort"]), ("spectrum", ["spectrum", "7"]), ("spectrum", ["spectrum", "7", "--csv"]),
         ("recon.status", ["recon", "status", "2"]), ("measure", ["measure"]), ("laser.off", ["laser", "off"]),
         ("reload", ["reload"])]


def reply_from(replies, seen):
    """The golden reply to one request line (its id copied), the request kept in seen."""
    def reply(line):
        req = json.loads(line)
        seen.append(req)
        return (json.dumps(dict(replies[req["cmd"]], id=req["id"])) + "\n").encode()
    return reply


def main():
    replies = json.load(open(os.path.join(GOLD, "replies.json")))
    tmp = tempfile.mkdtemp(prefix="acqgold.")
    path = os.path.join(tmp, "d.sock")
    seen = []
    lsock = A.fake_daemon(path, reply_from(replies, seen), version="1.2.3")
    plan = os.path.join(tmp, "plan.yaml")
    open(plan, "w").write("name: quick\n")
    env = dict(os.environ, TZ="Europe/Paris", LC_ALL="C.UTF-8")
    update = os.environ.get("ACQ_GOLDEN_UPDATE") == "1"
    bad = []
    for name, args in CASES:
        args = [plan if a == "PLANFILE" else a for a in args]
        p = subprocess.run([os.path.join(BUILD, "acqctl"), "-s", path] + args, capture_output=True, text=True,
                           env=env, timeout=20)
        if p.returncode != 0:
            bad.append("%s: exit %d: %s" % (" ".join(args), p.returncode, p.stderr))
            continue
        gold = os.path.join(GOLD, "_".join(a for a in args if a != plan).replace("=", "-") + ".txt")
        if update:
            open(gold, "w").write(p.stdout)
            continue
        want = open(gold).read() if os.path.exists(gold) else None
        if p.stdout != want:
            bad.append("%s differs from %s:\n--- got\n%s--- want\n%s" % (" ".join(args), gold, p.stdout, want))
    lsock.close()
    if bad:
        print("FAIL:\n" + "\n".join(bad))
        sys.exit(1)
    print("ok: %d golden outputs%s" % (len(CASES), " rewritten" if update else ""))


if __name__ == "__main__":
    main()
