#!/usr/bin/env bash
# Runs the test suites and prints one closing line "N passed, N failed, N skipped".
# Usage: tests/run-tests.sh [unit|integration|fuzz]...   (default: all three)
# Environment (set by `make check`): ACQ_BUILD, ACQ_SRC, ACQ_SEED.
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}" "${ACQ_SEED:=1}"
suites=("$@"); [ ${#suites[@]} -gt 0 ] || suites=(unit fuzz integration)
logdir="$ACQ_BUILD/test-logs"; mkdir -p "$logdir"
passed=0; failed=0; skipped=0; failures=()
TEST_TIMEOUT=${TEST_TIMEOUT:-300}

report_fail() { failures+=("$1"); echo "FAIL $1 (log: $2)"; tail -n 30 "$2" | sed 's/^/    | /'; }

run_unit() {
  local t name log p f s
  for t in "$ACQ_BUILD"/tests/test_*; do
    [ -x "$t" ] || continue
    name=$(basename "$t"); log="$logdir/$name.log"
    if timeout "$TEST_TIMEOUT" "$t" >"$log" 2>&1; then rc=0; else rc=$?; fi
    # cmocka prints "[  PASSED  ] N test(s)." and "[  FAILED  ] N test(s)" per group.
    p=$(grep -E '^\[  PASSED  \] [0-9]+ test' "$log" | awk '{s+=$4} END{print s+0}')
    f=$(grep -E '^\[  FAILED  \] [0-9]+ test' "$log" | awk '{s+=$4} END{print s+0}')
    # a skipped case counts as skipped (not as passed), with the reason the test printed ("skip: ...")
    s=$(grep -E '^\[  SKIPPED \] [0-9]+ test' "$log" | awk '{s+=$4} END{print s+0}')
    passed=$((passed + p)); failed=$((failed + f)); skipped=$((skipped + s))
    if [ "$rc" -ne 0 ]; then
      [ "$f" -gt 0 ] || failed=$((failed + 1))
      report_fail "unit/$name (exit $rc)" "$log"
    else
      echo "ok   unit/$name ($p cases$([ "$s" -eq 0 ] || echo ", $s skipped: $(grep '^skip: ' "$log" | sort -u | tr '\n' ' ')"))"
    fi
  done
}

run_fuzz() {
  local t name corpus log
  for t in "$ACQ_BUILD"/fuzz-replay/fuzz_*; do
    [ -x "$t" ] || continue
    name=$(basename "$t"); corpus="$ACQ_SRC/tests/fuzz/corpus/$name"; log="$logdir/$name.log"
    if timeout "$TEST_TIMEOUT" "$t" --seed "$ACQ_SEED" --mutations 3000 "$corpus" >"$log" 2>&1; then
      passed=$((passed + 1)); echo "ok   fuzz/$name ($(tail -n 1 "$log"))"
    else
      failed=$((failed + 1)); report_fail "fuzz/$name" "$log"
    fi
  done
}

run_integration() {
  local t name log rc
  for t in "$ACQ_SRC"/tests/integration/test_*; do
    [ -x "$t" ] || continue
    name=$(basename "$t"); log="$logdir/$name.log"
    if (cd "$ACQ_SRC" && timeout "$TEST_TIMEOUT" "$t") >"$log" 2>&1; then rc=0; else rc=$?; fi
    case $rc in
      0)  passed=$((passed + 1)); echo "ok   integration/$name";;
      77) skipped=$((skipped + 1)); echo "skip integration/$name: $(tail -n 1 "$log")";;
      *)  failed=$((failed + 1)); report_fail "integration/$name (exit $rc)" "$log";;
    esac
  done
}

for s in "${suites[@]}"; do "run_$s"; done
echo
[ ${#failures[@]} -eq 0 ] || { echo "failed:"; printf '  %s\n' "${failures[@]}"; }
echo "$passed passed, $failed failed, $skipped skipped"
[ "$failed" -eq 0 ]
