#!/usr/bin/python3
"""The permissions model of the documented install, for both groups: the socket mode of config/bench-real.yaml
(every local user may connect), controllers and observers given as @groups, decided from peer credentials.
Three users that exist on every Debian system stand in (as root; skipped otherwise): "daemon" (group daemon) is
the controllers' group member, "nobody" (group nogroup) the observers', "bin" (group bin) a stranger.
- the controller commands (version role, sweep.abort reaches the executor: "state");
- the observer reads (status, sweep list, export stream) and is refused commands (forbidden, acqctl exit 1);
- the stranger is refused with a message naming its uid (acqctl exit 1 and the refusal, not "cannot connect");
- a member of the observers' group by a supplementary membership only (as `usermod -aG acquisition-view bob` makes
  one; the user database's, not the connecting process's groups) is an observer: a system user listed in another
  user's group in /etc/group stands in (Debian: postgres in ssl-cert), the check said absent when none is."""
import json
import os
import re
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from acqtest import ACQCTL, Daemon, check  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def as_user(uid, gid, code):
    script = ("import os,sys,json;sys.path.insert(0,%r)\nos.setgroups([]);os.setgid(%d);os.setuid(%d)\n" % (HERE, gid, uid)
              + code)
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=30)
    check(p.returncode == 0, "uid %d: %s" % (uid, p.stderr))
    return json.loads(p.stdout.splitlines()[-1])


def supplementary_member():
    """A user (not root, daemon, bin, nobody) listed as a supplementary member of a group that is not its primary
    group and none of the test's: (passwd entry, group entry), or (None, None)."""
    import grp
    import pwd
    mine = {"daemon", "nogroup", "bin", "root"}
    for g in grp.getgrall():
        for m in g.gr_mem:
            try:
                pw = pwd.getpwnam(m)
            except KeyError:
                continue
            others = {x.gr_name for x in grp.getgrall() if m in x.gr_mem} | {grp.getgrgid(pw.pw_gid).gr_name}
            if pw.pw_uid not in (0, 1, 2, 65534) and pw.pw_gid != g.gr_gid and g.gr_name not in mine and \
                    not (others & mine):
                return pw, g
    return None, None


def main():
    if os.geteuid() != 0:
        print("not root: the access model needs other uids")
        sys.exit(77)
    real = open(os.path.join(os.environ.get("ACQ_SRC", "."), "config", "bench-real.yaml")).read()
    mode = re.search(r'^\s+mode:\s*"(0[0-7]+)"', real, re.M).group(1)
    supp, sgrp = supplementary_member()
    observers = '"@nogroup"' + (', "@%s"' % sgrp.gr_name if supp else "")
    d = Daemon(extra_daemon="  controllers: [\"@daemon\"]\n  observers: [%s]\n" % observers)
    text = open(d.conf).read().replace('mode: "0666"', 'mode: "%s"' % mode)
    open(d.conf, "w").write(text)
    try:
        d.start()
        check(oct(os.stat(d.sock).st_mode & 0o777) == oct(int(mode, 8)), "socket mode %o" % os.stat(d.sock).st_mode)
        probe = ("from acqtest import Client\nout=[]\n"
                 "try:\n c=Client(%r)\n out.append(c.banner.get('protocol'))\n"
                 " for cmd in ('version','sweep.abort','sweep.list'):\n  r=c.req(cmd)\n"
                 "  out.append(r.get('role') if r['ok'] and cmd=='version' else r['ok'] if r['ok'] else r['error']['code'])\n"
                 "except Exception as e:\n out.append(type(e).__name__)\nprint(json.dumps(out))\n" % d.sock)
        ctl = ("import subprocess\nout=[]\nfor a in (['status'],['sweep','abort']):\n"
               " p=subprocess.run([%r,'-s',%r]+a,capture_output=True,text=True)\n out.append([p.returncode,p.stderr])\n"
               "print(json.dumps(out))\n" % (ACQCTL, d.sock))
        got = as_user(1, 1, probe)
        check(got == [1, "controller", "state", True], "controller (@daemon): %r" % got)
        got = as_user(65534, 65534, probe)
        check(got == [1, "observer", "forbidden", True], "observer (@nogroup): %r" % got)
        got = as_user(65534, 65534, ctl)
        check(got[0][0] == 0 and got[1][0] == 1 and "sweep abort needs a controller" in got[1][1],
              "observer with acqctl (commands named as typed): %r" % got)
        got = as_user(2, 2, "from acqtest import Client\nc=Client(%r)\nprint(json.dumps(c.read()))\n" % d.sock)
        check(got.get("ok") is False and got["error"]["code"] == "forbidden" and "uid 2" in got["error"]["message"],
              "stranger: %r" % got)
        got = as_user(2, 2, ctl)
        for rc, err in got:
            check(rc == 1 and "uid 2" in err, "stranger with acqctl: exit %d %r (wanted the refusal, exit 1)" % (rc, err))
        said = "not checked: no supplementary group membership on this system"
        if supp:
            got = as_user(supp.pw_uid, supp.pw_gid, probe)
            check(got == [1, "observer", "forbidden", True], "observer by a supplementary group (%s in @%s): %r"
                  % (supp.pw_name, sgrp.gr_name, got))
            said = "%s, in @%s by a supplementary membership, is an observer" % (supp.pw_name, sgrp.gr_name)
        print("ok: socket mode %s; controller, observer and stranger as documented; %s" % (mode, said))
    finally:
        d.cleanup()


if __name__ == "__main__":
    main()
