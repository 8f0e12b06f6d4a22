#!/usr/bin/env bash
# Integration: `acquisitiond --check-config` accepts the shipped examples (exit 0, notes for devices whose
# driver is not there yet) and rejects broken files with exit 1 and a file:line:col message naming the
# expected form; --sim with a bad ports file is rejected naming it; usage errors exit 2.
set -u
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}"
D="$ACQ_BUILD/acquisitiond"
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

for f in "$ACQ_SRC/config/bench-sim.yaml" "$ACQ_SRC/config/bench-real.yaml"; do
  out=$("$D" --check-config "$f" 2>&1) || fail "$f rejected: $out"
  grep -q ": ok$" <<<"$out" || fail "$f: no ok line: $out"
done

# the bench section's old axis keys (laser_theta: ...) are accepted with a deprecation warning naming the new key
sed -e 's/^  laser\.theta: /  laser_theta: /' "$ACQ_SRC/config/bench-sim.yaml" > "$tmp/old-keys.yaml"
out=$("$D" --check-config "$tmp/old-keys.yaml" 2>&1) || fail "old bench keys rejected: $out"
grep -q "^warning: deprecated keys (still accepted): bench.laser_theta is now bench.laser.theta$" <<<"$out" \
  || fail "no deprecation warning for bench.laser_theta: $out"
out=$("$D" --check-config "$ACQ_SRC/config/bench-sim.yaml" 2>&1)
grep -q "deprecated" <<<"$out" && fail "bench-sim.yaml uses deprecated keys: $out"

# bad file → exit 1, message "file:line:col: ..." with the expected form
check_bad() { # name, yaml, expected-location, expected-words
  printf '%s' "$2" > "$tmp/$1.yaml"
  out=$("$D" --check-config "$tmp/$1.yaml" 2>&1); rc=$?
  [ $rc -eq 1 ] || fail "$1: exit $rc (want 1): $out"
  grep -qF "$tmp/$1.yaml:$3:" <<<"$out" || fail "$1: location $3 missing: $out"
  grep -qF "$4" <<<"$out" || fail "$1: '$4' missing: $out"
}
check_bad unknown $'daemon:\n  socket_path: /x\n' 2:3 "expected one of"
check_bad mode $'daemon:\n  socket:\n    mode: rwx\n' 3:11 'octal mode such as "0660"'
check_bad port $'daemon:\n  tcp_port: -1\n' 2:13 "tcp_port"
check_bad sweep $'sweep:\n  target_peak: 2\n' 2:16 "target_peak"
check_bad recon $'recon:\n  threads: many\n' 2:12 "threads"
check_bad top $'bench: {}\nbogus: 1\n' 2:1 "bogus"
check_bad yaml $'daemon: [\n' 2:1 ""
check_bad arm $'devices:\n  detector_arm: {axes: [1]}\n' 2:24 "mapping"

# a damaged file (its tail NUL bytes, as a crash can leave it) is refused where the NULs start, not read up to
# them (the rest of the file silently lost: "ok" before); an empty file is named
head -c 2000 "$ACQ_SRC/config/bench-sim.yaml" > "$tmp/nul.yaml"; head -c 512 /dev/zero >> "$tmp/nul.yaml"
out=$("$D" --check-config "$tmp/nul.yaml" 2>&1); rc=$?
[ $rc -eq 1 ] || fail "a file with NUL bytes: exit $rc (want 1): $out"
line=$(head -c 2000 "$ACQ_SRC/config/bench-sim.yaml" | wc -l)
grep -qF "$tmp/nul.yaml:$((line + 1)):" <<<"$out" && grep -qF "NUL byte" <<<"$out" || fail "NUL bytes not located: $out"
: > "$tmp/empty.yaml"
out=$("$D" --check-config "$tmp/empty.yaml" 2>&1) && fail "an empty file accepted"
grep -qF "$tmp/empty.yaml: empty configuration" <<<"$out" || fail "the empty file is not named: $out"
# the simulator reads the same file: the same two refusals ("devices: expected a mapping, found nothing" before)
for f in nul empty; do
  out=$(timeout 20 "$ACQ_BUILD/acq-sim" -c "$tmp/$f.yaml" --ports-file "$tmp/sim-ports.json" 2>&1); rc=$?
  [ $rc -eq 1 ] && grep -qF "$tmp/$f.yaml:" <<<"$out" || fail "acq-sim -c $f.yaml: exit $rc: $out"
done

# a sim ports file that is not JSON, or has a bad port
echo '{"laser_arm": {"port": 0}}' > "$tmp/ports.json"
out=$("$D" --check-config "$ACQ_SRC/config/bench-sim.yaml" --sim "$tmp/ports.json" 2>&1) && fail "bad port accepted"
grep -q "ports.json.*laser_arm" <<<"$out" || fail "bad ports message: $out"
echo '{"laser_arm": {"port": 1502}, "detector_arm": {"port": 1503}, "laser": {"device": "/dev/pts/9"},
 "spectrometer": {"socket": "/tmp/x.sock"}, "control": {"socket": "/tmp/c.sock"}}' > "$tmp/ports.json"
"$D" --check-config "$ACQ_SRC/config/bench-sim.yaml" --sim "$tmp/ports.json" >/dev/null 2>&1 \
  || fail "valid ports file rejected"
"$D" --check-config "$tmp/none.yaml" >/dev/null 2>&1; [ $? -eq 1 ] || fail "missing file must exit 1"
"$D" >/dev/null 2>&1; [ $? -eq 2 ] || fail "no arguments must exit 2"
"$D" --bogus >/dev/null 2>&1; [ $? -eq 2 ] || fail "unknown option must exit 2"
echo "ok: examples valid, 8 broken files and a damaged one located, an empty one named, ports file checked"
