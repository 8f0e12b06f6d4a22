#!/usr/bin/python3
"""Integration: 10 000 malformed lines (garbage, broken JSON, wrong shapes and types, unknown commands) and
oversized lines (70 KB, 1 MB, one sent in pieces) from one client: the daemon answers each with the right
error code, in order, while a second client keeps getting its status replies; both connections live on.
Prints the figures (lines per second, worst latency seen by the other client)."""
import json
import os
import random
import socket
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from acqtest import Daemon, check  # noqa: E402

N = 10000


def make_lines(rng):
    kinds = [
        (lambda: bytes(rng.randrange(1, 256) for _ in range(rng.randrange(1, 60))).replace(b"\n", b"?"), None),
        (lambda: b'{"cmd": "status", ', "parse"),
        (lambda: b"[1, 2, 3]", "invalid"),
        (lambda: b'"just a string"', "invalid"),
        (lambda: b'{"cmd": 42, "id": 1}', "invalid"),
        (lambda: b'{"id": 3}', "invalid"),
        (lambda: ('{"cmd": "x%d"}' % rng.randrange(10 ** 6)).encode(), "unknown_command"),
        (lambda: b'{"cmd": "move", "laser_theta": "north"}', "invalid"),
        (lambda: b'{"cmd": "sweep.show", "sweep": -4}', "invalid"),
        (lambda: b'{"cmd": "status", "id": [1]}', "invalid"),
        (lambda: b'{"cmd": "status", "cmd": "status"}', "parse"),
        (lambda: b'{"cmd": "config", "text": 1, "id": "t"}', "invalid"),
        (lambda: b"\xff\xfe{\"cmd\":\"status\"}", "parse"),
    ]
    out = []
    for i in range(N):
        gen, code = kinds[i % len(kinds)]
        line = gen()
        if not line.strip() or line.strip() in (b"\r",):
            line = b"#"
        out.append((line, code))
    return out


def reader(sock, expect, result):
    buf = b""
    got = 0
    banner = False
    try:
        while got < expect:
            chunk = sock.recv(1 << 20)
            if not chunk:
                break
            buf += chunk
            *lines, buf = buf.split(b"\n")
            for l in lines:
                msg = json.loads(l)
                if not banner:
                    banner = True
                    continue
                result.append(msg)
                got += 1
    except Exception as e:  # reported by the main thread
        result.append({"exception": repr(e)})


def main():
    seed = int(os.environ.get("ACQ_SEED", "1"))
    rng = random.Random(seed)
    print("seed", seed)
    with Daemon() as d:
        d.start()
        lines = make_lines(rng)
        big = [b"y" * 70000, b"z" * (1 << 20)]
        flood = socket.socket(socket.AF_UNIX)
        flood.connect(d.sock)
        replies = []
        expect = N + len(big) + 2 + 1  # + the piecewise line + a valid request at the end
        t = threading.Thread(target=reader, args=(flood, expect, replies))
        t.start()

        other = d.client()
        worst = 0.0
        stop = False
        lat_count = [0]

        def poll_other():
            nonlocal worst
            while not stop:
                t0 = time.time()
                r = other.req("status", _id=lat_count[0])
                dt = time.time() - t0
                check(r["ok"] and r["id"] == lat_count[0], "other client reply %r" % r)
                worst = max(worst, dt)
                lat_count[0] += 1
                time.sleep(0.005)

        pt = threading.Thread(target=poll_other)
        pt.start()
        t0 = time.time()
        first = b"".join(l + b"\n" for l, _ in lines[: N // 2])
        second = b"".join(l + b"\n" for l, _ in lines[N // 2:])
        flood.sendall(first)
        flood.sendall(big[0] + b"\n")
        flood.sendall(second)
        flood.sendall(big[1] + b"\n")
        for _ in range(3):  # 3 × 30 000 bytes in separate writes: one oversized line
            flood.sendall(b"w" * 30000)
            time.sleep(0.01)
        flood.sendall(b"\n")
        flood.sendall(b'{"cmd":"x"}\n')
        flood.sendall(b'{"cmd":"version","id":"last"}\n')
        t.join(60)
        elapsed = time.time() - t0
        stop = True
        pt.join(10)
        check(not t.is_alive(), "flood replies incomplete: %d of %d" % (len(replies), expect))
        check(all("exception" not in r for r in replies), "reader failed: %r" % replies[-1:])
        check(len(replies) == expect, "replies %d, expected %d" % (len(replies), expect))
        check(replies[-1].get("id") == "last" and replies[-1]["ok"] is True, "still serving: %r" % replies[-1])
        codes = [r["error"]["code"] for r in replies[:-1]]
        check(codes.count("too_long") == 3, "too_long count %d" % codes.count("too_long"))
        check(codes[-1] == "unknown_command", "after the oversized lines: %r" % codes[-3:])
        # Replies come in order: the malformed lines' expected codes, with too_long where the big lines were.
        plain = [c for c in codes if c != "too_long"][:N]
        for i, (line, want) in enumerate(lines):
            if want is not None:
                check(plain[i] == want, "line %d %r: got %s, want %s" % (i, line[:40], plain[i], want))
            else:
                check(plain[i] in ("parse", "invalid", "unknown_command"), "garbage line %d: %s" % (i, plain[i]))
        check(all(r["ok"] is False for r in replies[:-1]), "an error reply for every bad line")
        check(lat_count[0] >= 3, "the other client was served %d times" % lat_count[0])
        check(worst < 2.0, "the other client waited %.2f s during the flood" % worst)
        r = other.req("version", _id="after")
        check(r["id"] == "after", "other client after the flood")
        print("figures: %d malformed + 3 oversized lines answered in %.2f s (%.0f lines/s); other client served "
              "%d times, worst latency %.1f ms" % (N, elapsed, (N + 3) / elapsed, lat_count[0], worst * 1000))
        other.close()
        flood.close()
        check(d.stop() == 0, "clean stop")


if __name__ == "__main__":
    main()
