#!/usr/bin/env bash
# The README's "simulated bench by hand" block, run as written: the lines between the by-hand markers, with only
# the paths moved into a private temporary directory (bench-sim.yaml's /tmp/acquisitiond-sim and the ports
# file, so parallel runs on one machine do not meet) and build/ pointing at $ACQ_BUILD (build/san too).
# Every command must succeed; the sweep must complete and the exported CSV hold its rows.
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}"
for p in acq-sim acquisitiond acqctl brdf-recon; do [ -x "$ACQ_BUILD/$p" ] || { echo "FAIL: $ACQ_BUILD/$p not built"; exit 1; }; done
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

block=$(sed -n '/<!-- by-hand: begin -->/,/<!-- by-hand: end -->/p' "$ACQ_SRC/README.md" | grep -v '^<!--' | grep -v '^```')
[ "$(printf '%s\n' "$block" | grep -c .)" -ge 10 ] || fail "no by-hand block in README.md"
sed "s|/tmp/acquisitiond-sim|$tmp/acquisitiond-sim|g" "$ACQ_SRC/config/bench-sim.yaml" >"$tmp/bench-sim.yaml"
# the recon program is found next to acquisitiond (ACQ_BUILD)
{
  echo 'set -e'
  echo 'trap '"'"'kill $(jobs -p) 2>/dev/null || true'"'"' EXIT'
  printf '%s\n' "$block" |
    sed -e "s|/tmp/acquisitiond-sim|$tmp/acquisitiond-sim|g" -e "s|/tmp/acq-sim.ports|$tmp/acq-sim.ports|g" \
        -e "s|config/bench-sim.yaml|$tmp/bench-sim.yaml|g" -e "s|config/plan-|$ACQ_SRC/config/plan-|g" \
        -e "s|build/|$ACQ_BUILD/|g"
  echo 'wait'
} >"$tmp/block.sh"
(cd "$tmp" && env -u ACQ_SOCKET -u ACQ_SIM_PORTS bash "$tmp/block.sh") >"$tmp/out" 2>&1
rc=$?
cat "$tmp/out"
[ $rc -eq 0 ] || fail "the README block failed (exit $rc)"
grep -q "completed" "$tmp/out" || fail "the sweep did not complete"
rows=$(grep -vc '^#' "$tmp/samples.csv")
[ "$rows" -ge 10 ] || fail "samples.csv has $rows lines"
echo "ok: README block ran; samples.csv $rows lines"
