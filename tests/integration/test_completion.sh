#!/usr/bin/env bash
# The bash completion (systemd/acqctl.bash-completion, installed for acqctl and acq-sim) offers what the programs
# take, read from the programs themselves so that the two cannot drift apart:
# - every command and sub-command `acqctl --help` lists, and every option it names (--format too);
# - `move` and `home`: the axes' one name (laser.theta=, ...; README "Names, one per thing"), never the old
#   laser_theta spelling; measure/dark/reference: the keys --help gives each;
# - `acq-sim ctl sample`: every material `acq-sim truth --help` lists.
# bash-completion's helpers are replaced by stand-ins (the package need not be installed).
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}"
fail() { echo "FAIL: $*"; exit 1; }
help=$("$ACQ_BUILD/acqctl" --help) || fail "acqctl --help"
simhelp=$("$ACQ_BUILD/acq-sim" truth --help 2>&1)

_init_completion() { words=("${COMP_WORDS[@]}"); cword=$COMP_CWORD; cur=${COMP_WORDS[COMP_CWORD]}
                     prev=${COMP_WORDS[COMP_CWORD-1]}; }
_filedir() { :; }
compopt() { :; }
# shellcheck source=/dev/null
source "$ACQ_SRC/systemd/acqctl.bash-completion"
# offered FUNC WORD... : the completion's candidates with the cursor on the last (possibly empty) word
offered() { local f=$1; shift; COMP_WORDS=("$@"); COMP_CWORD=$(($# - 1)); COMPREPLY=(); "$f"; echo " ${COMPREPLY[*]} "; }
has() { [[ $1 == *" $2 "* ]]; }

top=$(offered _acqctl acqctl "")
n=0
while read -r w1 w2 _; do          # "  sweep start   FILE ..." / "  status"
  has "$top" "$w1" || fail "acqctl <TAB> does not offer '$w1' (acqctl --help lists it): $top"
  if [[ -n ${w2:-} && $w2 =~ ^[a-z]+$ ]]; then
    sub=$(offered _acqctl acqctl "$w1" "")
    has "$sub" "$w2" || fail "acqctl $w1 <TAB> does not offer '$w2': $sub"
  fi
  n=$((n + 1))
done < <(grep -E '^  [a-z]' <<<"$help")
[ "$n" -ge 20 ] || fail "only $n commands read from acqctl --help"

opts=$(offered _acqctl acqctl --)
for o in $(grep -oE -- '--[a-z][a-z-]+' <<<"$help" | sort -u); do
  has "$opts" "$o" || fail "acqctl --<TAB> does not offer $o (acqctl --help names it): $opts"
done
fmt=$(offered _acqctl acqctl export 1 --format "")
has "$fmt" csv && has "$fmt" nexus || fail "--format <TAB>: $fmt"

for c in move measure dark reference; do
  want=$(grep -E "^  $c " <<<"$help" | grep -oE '\[[a-z_.]+=' | tr -d '[' | sort)
  [ -n "$want" ] || fail "no keys for $c in acqctl --help"
  got=$(offered _acqctl acqctl "$c" "" | tr ' ' '\n' | grep . | sort)
  [ "$got" = "$want" ] || fail "acqctl $c <TAB> offers [$(echo $got)], acqctl --help takes [$(echo $want)]"
done
axes=$(grep -E '^  move ' <<<"$help" | grep -oE '\[[a-z_.]+=' | tr -d '[=' | sort)
got=$(offered _acqctl acqctl home "" | tr ' ' '\n' | grep . | sort)
[ "$got" = "$axes" ] || fail "acqctl home <TAB> offers [$(echo $got)], the axes are [$(echo $axes)]"
for c in move home; do
  [[ $(offered _acqctl acqctl "$c" "") != *_theta* && $(offered _acqctl acqctl "$c" "") != *_phi* ]] ||
    fail "acqctl $c <TAB> offers an old axis spelling"
done

mats=$(sed -n '/MATERIAL:/,/actions/p' <<<"$simhelp" | grep -oE '[a-z]+(-[a-z]+)?' |
       grep -vxE 'material|or|paint|merl|file|a|binary|table|upsampled|to|spectra|sim|h|actions|exactly|one|c' | sort -u)
[ "$(wc -w <<<"$mats")" -ge 8 ] || fail "materials read from acq-sim truth --help: $mats"
got=$(offered _acq_sim acq-sim ctl sample "")
for m in $mats; do has "$got" "$m" || fail "acq-sim ctl sample <TAB> does not offer $m: $got"; done
echo "ok: $n commands, every option, axes and keys, $(wc -w <<<"$mats") materials offered"
