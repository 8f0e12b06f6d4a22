#!/usr/bin/env bash
# Runs each libFuzzer binary for FUZZ_SECONDS (default 60) on a copy of its corpus. `make fuzz`.
set -euo pipefail
secs=${FUZZ_SECONDS:-60}
for f in "$@"; do
  name=$(basename "$f"); work="$ACQ_BUILD/fuzz-work/$name"; mkdir -p "$work"
  cp -n "$ACQ_SRC/tests/fuzz/corpus/$name/"* "$work/" 2>/dev/null || true
  echo "== $name for ${secs}s"
  "$f" -max_total_time="$secs" -seed="$ACQ_SEED" "$work"
done
