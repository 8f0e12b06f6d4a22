#!/usr/bin/env bash
# Runs the test suites and prints one closing line "N passed, N failed, N skipped".
# Usage: tests/run-tests.sh [unit|integration|fuzz]...   (default: all three)
# Environment (set by `make check`): ACQ_BUILD, ACQ_SRC, ACQ_SEED; OPENBLAS_NUM_THREADS (1 unless set: see below).
#   ACQ_TEST_JOBS  tests run at once (default 2): unit tests, fuzz replays and the integration tests
#                  that are not timing-sensitive (see SERIAL below). 1 runs everything one at a time.
# Results are printed in a fixed order (unit, fuzz, integration; by name) whatever order the tests end
# in. Each test's wall and CPU seconds go to its log's last line and to $ACQ_BUILD/test-logs/times.tsv;
# the slowest are listed before the closing line.
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}" "${ACQ_SEED:=1}"
# One BLAS thread per test process (make check's TEST_ENV says so too; this covers a direct run): OpenBLAS's
# pthread build waits for its other threads, which on a busy machine costs ten times the wall time
# (`brdf-recon fit` of a 10x10x10 sharp lobe, two `yes` beside it: 8.6-9.7 s by default, 1.0 s with one thread).
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}
suites=("$@"); [ ${#suites[@]} -gt 0 ] || suites=(unit fuzz integration)
logdir="$ACQ_BUILD/test-logs"; mkdir -p "$logdir"
resdir=$(mktemp -d "$logdir/.results.XXXXXX") || exit 2
trap 'rm -rf "$resdir"' EXIT
passed=0; failed=0; skipped=0; failures=()
TEST_TIMEOUT=${TEST_TIMEOUT:-300}
JOBS=${ACQ_TEST_JOBS:-2}
SLOWEST=${ACQ_TEST_SLOWEST:-15}

# Tests that measure time or need the CPU at a given moment (latency bounds, a kill inside a window, a
# watchdog period; the unit tests against real-time device peers): they run alone, after the others, so a
# neighbour test cannot make them flake.
SERIAL=" test_acqctl.py test_adaptive_kill.py test_adaptive_seconds.py test_client_limits.py test_daemon_sim.py
 test_devices_throttle.py test_disk_full.py test_export.py test_laser_kill.py test_laser_sim.py test_malformed_flood.py
 test_plan_helper.py test_sd_notify.py test_sim_bench.py test_sweep_crash.py test_sweep_start_offloop.py
 test_sweep_step_kill.py test_watchdog.py
 test_axis_modbus test_axis_modbus_sim test_laser test_spectro_sim "

# The shared tests that use the most CPU (measured: build/test-logs/times.tsv), longest first: they start
# first, so that the two lanes end together instead of one long test running alone at the end.
FIRST=" test_recon_extremes test_dhr_trend_refit.py test_recon_honesty test_recon_honest_extremes test_recon_rgb
 test_sweep_full.py test_adaptive_budget.py test_material test_recon_cli.py test_laser_halt.py test_recon_rgl.py
 test_dhr_coat.py test_recon_render_hdr.py test_recon_trend test_recon_select test_recon_fit test_adaptive_target.py
 test_sim_truth.py "
# Shared tests that mostly wait (≤ 1 s of CPU in a make check, or ≤ a third of a core while they run: a file, a
# socket, a simulated device): they run beside the SERIAL tests, one at a time, instead of in the CPU-bound lanes.
# A SERIAL test then shares the machine with at most one such test (less than CI's two busy processes beside
# make check). A new test is not LIGHT until measured so. The SERIAL lane is the longer one (d2245c5 with two
# `yes`: 228 s of SERIAL tests, 74 s of LIGHT ones): the second row below (7 tests, 53 s of wall, 11 s of CPU)
# moved here from the CPU-bound lanes, where they held a lane that a heavy test could use.
LIGHT=" test_server test_devices test_job_helper test_store_ckpt test_plan_worker test_recon_sky test_sim_refdrift
 test_recon_model test_executor test_sim_sphere test_avaspec_usb test_recon_render test_store_crash test_sim_arm
 test_loop test_store test_store_sync test_exposure test_recon_plot
 fuzz_plan fuzz_simarm fuzz_axisreply fuzz_proto fuzz_laser
 test_slow_disk.py test_avaspec_golden.sh test_sim_sockets.py test_sim_arms_spectro.py test_store_schema.py
 test_systemd_unit.sh test_acqctl_golden.py test_sim_laser_spectro.py test_store_foreign.py
 test_plan_limits.py test_daemon_protocol.py test_recon_timeout_real.py test_sweep_faults.py
 test_adaptive_combined.py test_exposure_prior.py test_export_nexus.py "
# one space between names (a name at a line's end was followed by a newline, and did not match " NAME ")
SERIAL=" $(echo $SERIAL) " FIRST=" $(echo $FIRST) " LIGHT=" $(echo $LIGHT) "

# ---- one test: run it, keep its log, its times and its result line (read back in order later) ------------
# timed KEY LOG CMD...: runs CMD with stdout+stderr to LOG; writes "rc wall user sys" to $resdir/KEY.t.
timed() {
  local key=$1 log=$2 rc; shift 2
  local TIMEFORMAT='%R %U %S'
  { time { "$@" >"$log" 2>&1; rc=$?; }; } 2>"$resdir/$key.time"
  echo "$rc $(cat "$resdir/$key.time")" >"$resdir/$key.t"
  read -r _ w u s <"$resdir/$key.t"
  echo "[time] wall ${w}s, cpu ${u}s user + ${s}s sys" >>"$log"
}

# Each job writes $resdir/KEY.r: "passed failed skipped" on the first line, then the lines to print.
job_unit() {
  local t=$1 key=$2 name log rc p f s
  name=$(basename "$t"); log="$logdir/$name.log"
  timed "$key" "$log" timeout "$TEST_TIMEOUT" "$t"; read -r rc _ <"$resdir/$key.t"
  # cmocka prints "[  PASSED  ] N test(s)." and "[  FAILED  ] N test(s)" per group.
  p=$(grep -E '^\[  PASSED  \] [0-9]+ test' "$log" | awk '{s+=$4} END{print s+0}')
  f=$(grep -E '^\[  FAILED  \] [0-9]+ test' "$log" | awk '{s+=$4} END{print s+0}')
  # a skipped case counts as skipped (not as passed), with the reason the test printed ("skip: ...")
  s=$(grep -E '^\[  SKIPPED \] [0-9]+ test' "$log" | awk '{s+=$4} END{print s+0}')
  {
    if [ "$rc" -ne 0 ]; then
      [ "$f" -gt 0 ] || f=$((f + 1))
      echo "$p $f $s"; echo "FAIL unit/$name (exit $rc)|$log"
    else
      echo "$p $f $s"
      echo "ok   unit/$name ($p cases$([ "$s" -eq 0 ] || echo ", $s skipped: $(grep '^skip: ' "$log" | sort -u | tr '\n' ' ')"))"
    fi
  } >"$resdir/$key.r"
}

job_fuzz() {
  local t=$1 key=$2 name corpus log rc
  name=$(basename "$t"); corpus="$ACQ_SRC/tests/fuzz/corpus/$name"; log="$logdir/$name.log"
  timed "$key" "$log" timeout "$TEST_TIMEOUT" "$t" --seed "$ACQ_SEED" --mutations 3000 "$corpus"
  read -r rc _ <"$resdir/$key.t"
  if [ "$rc" -eq 0 ]; then
    printf '1 0 0\nok   fuzz/%s (%s)\n' "$name" "$(tail -n 2 "$log" | head -n 1)"
  else
    printf '0 1 0\nFAIL fuzz/%s|%s\n' "$name" "$log"
  fi >"$resdir/$key.r"
}

job_integration() {
  local t=$1 key=$2 name log rc
  name=$(basename "$t"); log="$logdir/$name.log"
  timed "$key" "$log" run_in_src timeout "$TEST_TIMEOUT" "$t"; read -r rc _ <"$resdir/$key.t"
  case $rc in
    0)  printf '1 0 0\nok   integration/%s\n' "$name";;
    77) printf '0 0 1\nskip integration/%s: %s\n' "$name" "$(tail -n 2 "$log" | head -n 1)";;
    *)  printf '0 1 0\nFAIL integration/%s (exit %s)|%s\n' "$name" "$rc" "$log";;
  esac >"$resdir/$key.r"
}
run_in_src() { cd "$ACQ_SRC" && "$@"; }

# ---- the pool: at most JOBS jobs at once; results read back in the order the tests were listed ----------
queue=()    # "suite key test", in print order
first=()    # indices into queue of the shared tests that start first (FIRST, in its order)
shared=()   # ... of the other tests that may run beside others
light=()    # ... of the shared tests that run beside the SERIAL ones (LIGHT)
alone=()    # ... and of those that run alone (SERIAL)
enqueue() {   # enqueue SUITE TEST: into queue, and into first, shared, light or alone by its name
  local i=${#queue[@]} name; name=$(basename "$2")
  queue+=("$1 $(printf 'k%04d' "$i") $2")
  case " $SERIAL $LIGHT $FIRST " in
    *" $name "*) ;;
    *) shared+=("$i"); return;;
  esac
  case $SERIAL in *" $name "*) alone+=("$i"); return;; esac
  case $LIGHT in *" $name "*) light+=("$i"); return;; esac
  first+=("$i")
}
first_order() {   # the indices of first, in FIRST's order
  local f i
  for f in $FIRST; do
    for i in "${first[@]}"; do
      [ "$(basename "${queue[i]##* }")" = "$f" ] && echo "$i"
    done
  done
}

run_pool() {   # run_pool NJOBS INDEX...: runs those queue entries with at most NJOBS at once
  local n=$1 i suite key t; shift
  for i in "$@"; do
    read -r suite key t <<<"${queue[i]}"
    while [ "$(jobs -rp | wc -l)" -ge "$n" ]; do wait -n; done
    "job_$suite" "$t" "$key" &
  done
  wait
}

print_results() {
  local q suite key t line log c1 c2 c3
  for q in "${queue[@]}"; do
    read -r suite key t <<<"$q"
    if [ ! -s "$resdir/$key.r" ]; then   # the job itself died: count it as a failure
      failed=$((failed + 1)); failures+=("$suite/$(basename "$t") (no result)")
      echo "FAIL $suite/$(basename "$t") (no result)"
      continue
    fi
    { read -r c1 c2 c3; read -r line; } <"$resdir/$key.r"
    passed=$((passed + c1)); failed=$((failed + c2)); skipped=$((skipped + c3))
    case $line in
      FAIL*) log=${line##*|}; line=${line%|*}; failures+=("${line#FAIL }")
             echo "$line (log: $log)"; tail -n 30 "$log" | sed 's/^/    | /';;
      *)     echo "$line";;
    esac
  done
}

for s in "${suites[@]}"; do
  case $s in
    unit)        for t in "$ACQ_BUILD"/tests/test_*; do [ -x "$t" ] && enqueue unit "$t"; done;;
    fuzz)        for t in "$ACQ_BUILD"/fuzz-replay/fuzz_*; do [ -x "$t" ] && enqueue fuzz "$t"; done;;
    integration) for t in "$ACQ_SRC"/tests/integration/test_*; do [ -x "$t" ] && enqueue integration "$t"; done;;
    *) echo "run-tests.sh: unknown suite '$s' (unit, integration or fuzz)" >&2; exit 2;;
  esac
done
# everything that may share the CPU with another test, the heaviest first
run_pool "$JOBS" $(first_order) "${shared[@]}"
# then the timing-sensitive tests one at a time, each beside at most one test that mostly waits
if [ "$JOBS" -gt 1 ]; then
  run_pool 1 "${alone[@]}" &
  run_pool 1 "${light[@]}" &
  wait
else
  run_pool 1 "${light[@]}" "${alone[@]}"
fi
print_results

# ---- times: one row per test, and the slowest listed ----------------------------------------------------
{
  printf 'test\trc\twall_s\tuser_s\tsys_s\n'
  for q in "${queue[@]}"; do
    read -r suite key t <<<"$q"
    [ -s "$resdir/$key.t" ] && read -r rc w u s <"$resdir/$key.t" &&
      printf '%s/%s\t%s\t%s\t%s\t%s\n' "$suite" "$(basename "$t")" "$rc" "$w" "$u" "$s"
  done
} >"$logdir/times.tsv"
echo
echo "slowest (wall s, cpu s; all in $logdir/times.tsv):"
tail -n +2 "$logdir/times.tsv" | sort -t$'\t' -k3,3 -rn | head -n "$SLOWEST" |
  awk -F'\t' '{printf "  %7.2f %7.2f  %s\n", $3, $4 + $5, $1}'

echo
[ ${#failures[@]} -eq 0 ] || { echo "failed:"; printf '  %s\n' "${failures[@]}"; }
echo "$passed passed, $failed failed, $skipped skipped"
[ "$failed" -eq 0 ]
