#!/usr/bin/env bash
# The AvaSpec golden files and fuzz seeds are what their generators write: regenerating them changes nothing.
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
