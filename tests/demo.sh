#!/usr/bin/env bash
# make demo: the end-to-end run on the simulated bench — acq-sim + acquisitiond with state in build/demo/ (fresh
# each run, outputs kept), the paper's 10 x 10 x 10 plan on a simulated sample (DEMO_SAMPLE, default green-paint;
# any `acq-sim truth --help` material) at a time scale that takes about a minute (DEMO_TIME_SCALE, default 35),
# progress from `acqctl watch`, the reconstruction, its DHR at 8 deg against a simulated spectrophotometer
# (integrating sphere) measurement with the share of wavelengths that agree (|z| < 2), and where the
# database, the MERL table, the DHR table/plot and the previews are. Everything it starts, it stops (also on
# Ctrl-C): tests/demo.py owns the processes; this wrapper checks what is needed and forwards signals.
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}"
export ACQ_BUILD ACQ_SRC
for p in acq-sim acquisitiond acqctl; do
  [ -x "$ACQ_BUILD/$p" ] || { echo "make demo: $ACQ_BUILD/$p is not built" >&2; exit 1; }
done
[ -x "$ACQ_BUILD/brdf-recon" ] || echo "make demo: note: $ACQ_BUILD/brdf-recon is not built: the sweep will be \
measured and calibrated, and the daemon will say that no reconstruction ran" >&2
/usr/bin/python3 -c 'import numpy' 2>/dev/null || { echo "make demo: /usr/bin/python3 with numpy is needed" >&2; exit 1; }
/usr/bin/python3 "$ACQ_SRC/tests/demo.py" &
pid=$!
trap 'kill -TERM $pid 2>/dev/null; wait $pid; exit 130' INT TERM
wait $pid
