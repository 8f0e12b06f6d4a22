"""acqtest: helpers for the daemon's integration tests — temporary state, a daemon process, raw clients."""
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time

BUILD = os.environ.get("ACQ_BUILD") or os.path.abspath("build")
SRC = os.environ.get("ACQ_SRC") or os.path.abspath(".")
DAEMON = os.path.join(BUILD, "acquisitiond")
ACQCTL = os.path.join(BUILD, "acqctl")


def check(cond, what):
    if not cond:
        raise AssertionError(what)


def run_main(main):
    """Run a test's main(): "FAIL: <what>" and exit status 1 when a check fails, else "ok"."""
    try:
        main()
    except AssertionError as e:
        print("FAIL: %s" % e)
        sys.exit(1)
    print("ok")


class Client:
    """A raw protocol client: reads the banner, sends lines, reads JSON lines."""

    def __init__(self, path, timeout=10):
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.settimeout(timeout)
        self.sock.connect(path)
        self.buf = b""
        self.banner = self.read()

    def read(self):
        while b"\n" not in self.buf:
            chunk = self.sock.recv(1 << 16)
            if not chunk:
                raise EOFError("connection closed")
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return json.loads(line)

    def req_fd(self, cmd, **args):
        """A request whose reply may carry a file descriptor (export): (reply, fd or None)."""
        msg = {"cmd": cmd, "id": args.pop("_id", 1)}
        msg.update(args)
        self.sock.sendall((json.dumps(msg) + "\n").encode())
        fd = None
        while b"\n" not in self.buf:
            data, fds, _, _ = socket.recv_fds(self.sock, 1 << 16, 4)
            for x in fds:
                if fd is None:
                    fd = x
                else:
                    os.close(x)
            if not data:
                raise EOFError("connection closed")
            self.buf += data
        line, self.buf = self.buf.split(b"\n", 1)
        return json.loads(line), fd

    def send_raw(self, data):
        self.sock.sendall(data)

    def req(self, cmd, **args):
        msg = {"cmd": cmd, "id": args.pop("_id", 1)}
        msg.update(args)
        self.sock.sendall((json.dumps(msg) + "\n").encode())
        return self.read()

    def close(self):
        self.sock.close()


class Daemon:
    """acquisitiond on a temporary state directory and socket; stopped (SIGTERM, then SIGKILL) by stop()."""

    def __init__(self, extra_daemon="", devices=None, sections="", tmp=None):
        self.tmp = tmp or tempfile.mkdtemp(prefix="acqd.")
        os.chmod(self.tmp, 0o755)
        self.state = os.path.join(self.tmp, "state")
        self.sock = os.path.join(self.tmp, "acq.sock")
        self.conf = os.path.join(self.tmp, "acq.yaml")
        if devices is None:
            devices = "devices:\n  spectrometer: {backend: sim}\n  laser: {}\n"
        with open(self.conf, "w") as f:
            f.write("bench:\n  laser_radius_mm: 400\n" + devices + "sim: {}\n" +
                    "daemon:\n  state_dir: %s\n  socket: {path: %s, mode: \"0666\"}\n  log_level: debug\n"
                    "  device_retry_s: 0.5\n" % (self.state, self.sock) + extra_daemon + sections)
        self.proc = None
        self.log = os.path.join(self.tmp, "daemon.log")

    def start(self, wait=True, args=(), env=None):
        self.logf = open(self.log, "ab")
        self.proc = subprocess.Popen([DAEMON, "-f", "-c", self.conf] + list(args), stdout=self.logf,
                                     stderr=subprocess.STDOUT, env=env)
        if wait:
            deadline = time.time() + 10
            while time.time() < deadline:
                if self.proc.poll() is not None:
                    raise AssertionError("daemon exited %d:\n%s" % (self.proc.returncode, self.logtext()))
                try:
                    Client(self.sock, 1).close()
                    return self
                except OSError:
                    time.sleep(0.02)
            raise AssertionError("daemon did not start:\n" + self.logtext())
        return self

    def logtext(self):
        try:
            return open(self.log, errors="replace").read()
        except OSError:
            return ""

    def client(self):
        return Client(self.sock)

    def stop(self, sig=signal.SIGTERM, timeout=10):
        if self.proc and self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        rc = self.proc.returncode if self.proc else None
        return rc

    def cleanup(self):
        self.stop(signal.SIGKILL)
        shutil.rmtree(self.tmp, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        """`with Daemon(...) as d:` a failure prints the daemon's last log lines; cleaned up either way."""
        if kind is not None:
            print(self.logtext()[-3000:])
        self.cleanup()
        return False


def acqctl(sock, *args, timeout=20, env=None):
    return subprocess.run([ACQCTL, "-s", sock] + list(args), capture_output=True, text=True, timeout=timeout,
                          env=env)


def recv_line(sock, bufsize=65536):
    """Bytes from sock up to and including the first newline (or all it sent before closing; the rest is dropped)."""
    buf = b""
    while b"\n" not in buf:
        chunk = sock.recv(bufsize)
        if not chunk:
            break
        buf += chunk
    return buf


def fake_daemon(path, reply, version="0"):
    """A listener at path that greets as acquisitiond does (protocol 1, the given version), reads one request line
    per connection and sends reply(line) (bytes, or None to send nothing); serves until the socket is closed."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(path)
    s.listen(4)
    hello = ('{"version":"%s","protocol":1,"server":"acquisitiond","max_line":65536}\n' % version).encode()

    def serve():
        while True:
            try:
                conn, _ = s.accept()
            except OSError:
                return
            with conn:
                conn.sendall(hello)
                buf = recv_line(conn)
                if b"\n" in buf:
                    out = reply(buf.split(b"\n", 1)[0])
                    if out:
                        conn.sendall(out)
    threading.Thread(target=serve, daemon=True).start()
    return s
