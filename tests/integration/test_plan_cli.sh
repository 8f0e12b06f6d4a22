#!/usr/bin/env bash
# acqctl plan (dry run): the example plans plan, JSON has the promised fields and consistent figures,
# bad inputs exit 1 with a located message, the default bench config is found.
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}"
acqctl="$ACQ_BUILD/acqctl"
[ -x "$acqctl" ] || { echo "FAIL: $acqctl not built"; exit 1; }
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

for plan in plan-paper-10x10x10 plan-fibonacci; do
  "$acqctl" plan "$ACQ_SRC/config/$plan.yaml" --config "$ACQ_SRC/config/bench-sim.yaml" --json --points \
    >"$tmp/$plan.json" 2>"$tmp/err" || fail "$plan: exit $? ($(cat "$tmp/err"))"
  /usr/bin/python3 - "$tmp/$plan.json" <<'PY' || fail "$plan: JSON check"
import json, sys
d = json.load(open(sys.argv[1]))
assert d["ok"] is True and d["source"] == "local", d.keys()
d = d["plan"]
for k in ("kept", "dropped", "moved", "duration_s", "raster_s", "lower_bound_s", "requested", "duplicates"):
    assert k in d, k
assert d["kept"] + d["moved"] + d["dropped"] + d["duplicates"] == d["requested"], d
assert d["measured"] == d["kept"] + d["moved"] == len(d["steps"])
assert len(d["dropped_points"]) == d["dropped"] and len(d["moved_points"]) == d["moved"]
assert 0 < d["lower_bound_s"] <= d["duration_s"] <= d["raster_s"], d
# one name per axis (README "Names, one per thing"): the arms' pose and travel by the axes' names
axes = {"laser.theta", "detector.theta", "detector.phi"}
assert set(d["travel_deg"]) == axes, d["travel_deg"]
assert all(axes <= set(s) and "theta_i" not in s for s in d["steps"]), d["steps"][0]
assert all(set(p["requested"]) == axes for p in d["dropped_points"] + d["moved_points"])
# the prediction's parts: the host's time per point is reported apart (0 < host_s < predicted_s)
assert 0 < d["host_s"] < d["predicted_s"] and 0 < d["darks_s"] < d["predicted_s"], d
# auto exposure, no prior (a local dry run has no database): the duration's interval from the policy's reach
if d["integration_mode"] == "auto":
    iv = d["interval"]
    assert iv["basis"] == "policy" and 0 < iv["low_s"] <= d["predicted_s"] < iv["high_s"], iv
else:  # fixed integration: the times are known
    assert "interval" not in d, d["interval"]
# the step times add up to the estimate
steps = d["steps"]
end = steps[-1]["t_start_s"] + steps[-1]["move_s"] + steps[-1]["settle_s"] + d["point_dwell_s"]
assert abs(end - d["duration_s"]) < 1e-6 * d["duration_s"], (end, d["duration_s"])
print(sys.argv[1].rsplit("/", 1)[-1], "requested", d["requested"], "kept", d["kept"], "moved", d["moved"],
      "dropped", d["dropped"], "planned %.1f raster %.1f bound %.1f" % (d["duration_s"], d["raster_s"], d["lower_bound_s"]))
PY
done
python3 -c 'import json,sys; d=json.load(open(sys.argv[1]))["plan"]; assert d["requested"] == 1000' "$tmp/plan-paper-10x10x10.json" \
  || fail "paper plan is not 1000 requests"

# text output and the default bench configuration (found through ACQ_SRC, then next to the executable)
"$acqctl" plan "$ACQ_SRC/config/plan-paper-10x10x10.yaml" >"$tmp/out" || fail "text output"
grep -q "estimated duration" "$tmp/out" || fail "no duration in text output"
grep -q "^  interval .* no exposure of the sample known yet" "$tmp/out" || fail "no interval in text output"
cp "$ACQ_SRC/config/plan-paper-10x10x10.yaml" "$tmp/p.yaml"
(unset ACQ_SRC ACQ_BENCH_CONFIG; cd /; "$acqctl" plan "$tmp/p.yaml" --json >"$tmp/def.json") \
  || fail "default bench configuration not found relative to the executable"

# bad plan: located error, exit 1
printf 'incidence: {theta_deg: [0, 10]}\nobservation: {theta_deg: 5, phi_deg: {from: 0, to: 90, step: 0}}\n' >"$tmp/bad.yaml"
"$acqctl" plan "$tmp/bad.yaml" >"$tmp/out" 2>"$tmp/err"; rc=$?
[ $rc -eq 1 ] || fail "bad plan: exit $rc"
grep -q "bad.yaml:2:62" "$tmp/err" || fail "bad plan: message not located: $(cat "$tmp/err")"
# bad bench section: located error, exit 1
printf 'bench:\n  laser_radius_mm: -3\n' >"$tmp/bench.yaml"
"$acqctl" plan "$tmp/p.yaml" --config "$tmp/bench.yaml" >"$tmp/out" 2>"$tmp/err"; rc=$?
[ $rc -eq 1 ] || fail "bad bench: exit $rc"
grep -q "bench.yaml:2:" "$tmp/err" || fail "bad bench: message not located: $(cat "$tmp/err")"
# missing file, usage
"$acqctl" plan "$tmp/none.yaml" >"$tmp/out" 2>"$tmp/err"; rc=$?
[ $rc -eq 66 ] && grep -q "none.yaml" "$tmp/err" || fail "missing plan: exit $rc, $(cat "$tmp/err")"
"$acqctl" plan >"$tmp/out" 2>&1; [ $? -eq 64 ] || fail "no argument should be a usage error (64)"
echo "ok"
