#!/usr/bin/env bash
# Integration: Debian's mbpoll (a client we did not write) against build/acq-sim's arm controllers: read the
# detector arm's position registers, command an AZ direct-data move, and see it in the position registers;
# over Modbus TCP, then over RTU on a socat pty pair. Skips (77) while acq-sim cannot start (other services
# still placeholders) or a tool is missing.
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}" "${ACQ_SEED:=1}"
echo "seed $ACQ_SEED"
for t in mbpoll socat; do command -v $t >/dev/null || { echo "skip: $t not installed"; exit 77; }; done
# mbpoll's response timeout (1 s by default) scaled for busy machines (socat ptys, both cores loaded)
PEER_T=${ACQ_PEER_TIMEOUT_S:-5}
sim="$ACQ_BUILD/acq-sim"
[ -x "$sim" ] || { echo "FAIL: $sim not built"; exit 1; }
tmp=$(mktemp -d); pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null; wait "$p" 2>/dev/null; done; rm -rf "$tmp"; }
trap cleanup EXIT

# start acq-sim on config $1; sets simpid and port (detector arm) or exits 77 / 1
start_sim() {
  rm -f "$tmp/ports.json"
  "$sim" -c "$1" --time-scale 20 --seed "$ACQ_SEED" --ports-file "$tmp/ports.json" --control "$tmp/ctl.sock" \
    >"$tmp/sim.log" 2>&1 &
  simpid=$!; pids+=("$simpid")
  for _ in $(seq 100); do
    [ -s "$tmp/ports.json" ] && break
    if ! kill -0 "$simpid" 2>/dev/null; then
      echo "acq-sim failed:"; cat "$tmp/sim.log"; exit 1
    fi
    sleep 0.05
  done
  [ -s "$tmp/ports.json" ] || { echo "no ports file"; cat "$tmp/sim.log"; exit 1; }
  port=$(/usr/bin/python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); print(d["detector_arm"].get("port",0))' "$tmp/ports.json")
}

# value printed by mbpoll for a reference: "[204]: 	1000"
val() { sed -n "s/^\[$1\]:[[:space:]]*\(-\?[0-9]\+\).*/\1/p" | head -n 1; }

# check_move CONN...: read position, move to 42.37°, poll until the controller is idle again at the target.
# The simulated axis has positioning noise (bench noise_deg, 0.005° = 0.5 count): allow 3 counts.
check_move() {
  local before after st i
  before=$(mbpoll -o "$PEER_T" -a 1 -0 -r 204 -t 4:int -B -c 1 -1 "$@" | val 204)
  [ -n "$before" ] || { echo "FAIL: cannot read the position with mbpoll $*"; exit 1; }
  echo "position before: $before counts"
  mbpoll -o "$PEER_T" -a 1 -0 -r 88 -t 4:int -B "$@" 0 1 4237 2000 6000 6000 1000 1 | grep -q "Written 8 references" ||
    { echo "FAIL: move block not written"; exit 1; }
  for i in $(seq 300); do
    after=$(mbpoll -o "$PEER_T" -a 1 -0 -r 204 -t 4:int -B -c 1 -1 "$@" | val 204)
    st=$(mbpoll -o "$PEER_T" -a 1 -0 -r 127 -t 4 -c 1 -1 "$@" | val 127)
    if [ -n "$after" ] && [ -n "$st" ] && [ $(( after > 4237 ? after - 4237 : 4237 - after )) -le 3 ] &&
       [ $(( st & (1 << 8) )) -eq 0 ]; then
      break
    fi
    sleep 0.02
  done
  [ -n "$after" ] && [ $(( after > 4237 ? after - 4237 : 4237 - after )) -le 3 ] ||
    { echo "FAIL: position registers show $after, want 4237 ± 3"; exit 1; }
  [ $(( st & (1 << 7) )) -eq 0 ] && [ $(( st & (1 << 14) )) -ne 0 ] ||
    { echo "FAIL: status word $st: want in position (bit 14), no alarm (bit 7)"; exit 1; }
  echo "position after: $after counts, status 0x$(printf %04x "$st")"
}

cfg="$ACQ_SRC/config/bench-sim.yaml"
start_sim "$cfg"
echo "TCP: detector arm on port $port"
check_move -m tcp -p "$port" 127.0.0.1
kill "$simpid"; wait "$simpid" 2>/dev/null

# RTU: the detector arm's link becomes one end of a socat pty pair
socat -d -d pty,raw,echo=0,link="$tmp/ttyA" pty,raw,echo=0,link="$tmp/ttyB" 2>"$tmp/socat.log" &
pids+=($!)
for _ in $(seq 100); do [ -e "$tmp/ttyA" ] && [ -e "$tmp/ttyB" ] && break; sleep 0.05; done
awk -v dev="$tmp/ttyB" '
  /^  detector_arm:/ { inarm = 1 }
  inarm && /^    link:/ { print "    link: {type: rtu, device: " dev ", baud: 115200}"; inarm = 0; next }
  { print }' "$cfg" >"$tmp/rtu.yaml"
start_sim "$tmp/rtu.yaml"
echo "RTU: detector arm on $tmp/ttyB, mbpoll on $tmp/ttyA"
check_move -m rtu -b 115200 -P none "$tmp/ttyA"
echo "ok"
