#!/usr/bin/env bash
# `make fuzz`: runs every libFuzzer target within one combined budget and grows the saved corpus.
#   FUZZ_BUDGET=S   total seconds for all targets (default 660), shared equally; FUZZ_SECONDS=S per target
#                   instead (the old knob). FUZZ_JOBS=N targets at once (default 1: timings stay honest).
#   FUZZ_SAVE=0     do not merge new inputs back into tests/fuzz/corpus/<target>/ (default: merge).
# Each target starts from tests/fuzz/corpus/<target>/ plus what earlier runs found (build/fuzz-work/<target>/);
# afterwards `-merge=1` copies into the saved corpus only the inputs that add coverage, so it grows and
# `make check` replays it. Crashes stop the run with the reproducer's path (libFuzzer writes crash-*).
# Prints, and writes to build/fuzz-report.txt, per target: executions, coverage (edges: libFuzzer's cov),
# features, corpus size before/after.
set -euo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}"
n=$#
[ "$n" -gt 0 ] || { echo "run-fuzzers: no targets"; exit 2; }
if [ -n "${FUZZ_SECONDS:-}" ]; then per=$FUZZ_SECONDS; budget=$((per * n)); else
  budget=${FUZZ_BUDGET:-660}; per=$((budget / n)); [ "$per" -ge 1 ] || per=1; fi
save=${FUZZ_SAVE:-1}
report="$ACQ_BUILD/fuzz-report.txt"
echo "fuzz: $n targets, ${per}s each (budget ${budget}s), seed ${ACQ_SEED:-0}, corpus saved: $save" | tee "$report"
printf '%-22s %12s %10s %8s %9s %9s\n' target executions exec/s edges corpus new | tee -a "$report"
fail=0
for f in "$@"; do
  name=$(basename "$f"); saved="$ACQ_SRC/tests/fuzz/corpus/$name"; work="$ACQ_BUILD/fuzz-work/$name"
  mkdir -p "$work" "$saved"
  cp -n "$saved/"* "$work/" 2>/dev/null || true
  before=$(find "$saved" -maxdepth 1 -type f | wc -l)
  log="$ACQ_BUILD/fuzz-work/$name.log"
  if ! "$f" -max_total_time="$per" -seed="${ACQ_SEED:-0}" -print_final_stats=1 \
       -artifact_prefix="$ACQ_BUILD/fuzz-work/$name-" "$work" >"$log" 2>&1; then
    echo "FAIL $name: libFuzzer found a crash (log $log):"; grep -E "ERROR|crash-|SUMMARY" "$log" | head -5; fail=1
  fi
  execs=$(grep -oE 'stat::number_of_executed_units:[[:space:]]*[0-9]+' "$log" | awk '{print $2}' | tail -1)
  rate=$(grep -oE 'stat::average_exec_per_sec:[[:space:]]*[0-9]+' "$log" | awk '{print $2}' | tail -1)
  edges=$(grep -oE 'cov: [0-9]+' "$log" | tail -1 | awk '{print $2}')
  if [ "$save" = 1 ]; then
    "$f" -merge=1 "$saved" "$work" >"$log.merge" 2>&1 || { echo "FAIL $name: merge (log $log.merge)"; fail=1; }
  fi
  after=$(find "$saved" -maxdepth 1 -type f | wc -l)
  printf '%-22s %12s %10s %8s %9s %9s\n' "$name" "${execs:-?}" "${rate:-?}" "${edges:-?}" "$after" \
    "+$((after - before))" | tee -a "$report"
done
echo "report: $report"
exit $fail
