#!/usr/bin/env bash
# make bench: runs every benchmark program (build/bench/bench_*) and script (tests/bench/bench_*.sh|py);
# each writes its tables and plots under $ACQ_BENCH_OUT (build/bench/) and prints a summary.
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}"
export ACQ_BENCH_OUT=${ACQ_BENCH_OUT:-$ACQ_BUILD/bench}
mkdir -p "$ACQ_BENCH_OUT"
status=0
for b in "$ACQ_BUILD"/bench/bench_* "$ACQ_SRC"/tests/bench/bench_*.sh "$ACQ_SRC"/tests/bench/bench_*.py; do
  [ -x "$b" ] || continue
  echo "== $(basename "$b")"
  start=$(date +%s)
  if ! "$b"; then echo "bench $(basename "$b") FAILED"; status=1; fi
  echo "   ($(( $(date +%s) - start )) s)"
done
echo "bench outputs in $ACQ_BENCH_OUT"
exit $status
