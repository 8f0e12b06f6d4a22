#!/usr/bin/env bash
# The AvaSpec golden files and fuzz seeds are what their generators write: regenerating them changes nothing.
# The files are also checked against a second, independent derivation from the protocol fact sheet
# (tests/golden/avaspec/check_golden.py: host frames written out by hand, answers decoded by the sheet's rules),
# and that check is shown to catch a changed byte.
# To regenerate after a deliberate protocol change: tests/golden/avaspec/gen_golden.py &&
# tests/fuzz/corpus/gen_avaspec_corpus.py, then review `git diff --stat` and rerun make check.
set -euo pipefail
: "${ACQ_SRC:?}"
[ -x /usr/bin/python3 ] || { echo "no /usr/bin/python3"; exit 77; }
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
/usr/bin/python3 "$ACQ_SRC/tests/golden/avaspec/gen_golden.py" "$tmp"
n=0
for f in "$tmp"/*; do
  name=$(basename "$f")
  cmp -s "$f" "$ACQ_SRC/tests/golden/avaspec/$name" || { echo "golden file $name differs from its generator's output"; exit 1; }
  n=$((n + 1))
done
extra=$(comm -13 <(ls "$tmp") <(ls "$ACQ_SRC/tests/golden/avaspec" | grep -E '\.(ioctl|umockdev)$') || true)
[ -z "$extra" ] || { echo "golden files no generator writes: $extra"; exit 1; }
echo "$n golden files match their generator"
/usr/bin/python3 "$ACQ_SRC/tests/golden/avaspec/check_golden.py" "$ACQ_SRC/tests/golden/avaspec" ||
  { echo "the golden files disagree with the fact sheet (drivers/avaspec-usb.md)"; exit 1; }
# the check can fail: the prepare's integration time 10.0 ms (41200000) made 9.0 ms (41100000), and a reply's
# command byte (0x85, prepare's) made 0x86
for edit in 's/20032B000500000007FF41200000/20032B000500000007FF41100000/' 's/ 210002008500$/ 210002008600/'; do
  cp "$ACQ_SRC"/tests/golden/avaspec/*.ioctl "$ACQ_SRC"/tests/golden/avaspec/avaspec.umockdev "$tmp"/
  sed -i "$edit" "$tmp/cycle.ioctl"
  cmp -s "$tmp/cycle.ioctl" "$ACQ_SRC/tests/golden/avaspec/cycle.ioctl" && { echo "edit $edit changed nothing"; exit 1; }
  if /usr/bin/python3 "$ACQ_SRC/tests/golden/avaspec/check_golden.py" "$tmp" >/dev/null; then
    echo "the fact-sheet check missed an altered cycle.ioctl ($edit)"; exit 1
  fi
done
echo "fact-sheet check catches an altered host frame and an altered reply"
