#!/usr/bin/env bash
# Installation: `make install-files` (what `make install` runs after building) into a temporary prefix, then
# - the installed unit passes `systemd-analyze verify` (its ExecStart= points at the installed programs), its
#   Documentation= names man pages that are installed, and it has no systemd-udev-settle ordering;
# - every man page (the five programs, the configuration format) renders with `man -l` without warnings;
# - sysusers.d and tmpfiles.d entries parse (systemd-sysusers/-tmpfiles --cat-config style dry runs), the udev
#   rule is group-based without uaccess, the completion script loads in bash, the docs and schemas are there;
# - `make uninstall` then leaves no file behind.
set -uo pipefail
: "${ACQ_BUILD:?}" "${ACQ_SRC:?}"
for t in systemd-analyze man scdoc; do command -v $t >/dev/null || { echo "$t absent (make deps)"; exit 77; }; done
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
prefix="$tmp/usr"
mk() { make -s --no-print-directory -C "$ACQ_SRC" BUILD="$ACQ_BUILD" PREFIX="$prefix" SYSCONFDIR="$tmp/etc" "$@"; }
mk install-files >"$tmp/install.log" 2>&1 || { cat "$tmp/install.log"; fail "make install-files"; }

unit="$prefix/lib/systemd/system/acquisitiond.service"
[ -f "$unit" ] || fail "no unit installed"
grep -q "ExecStart=$prefix/bin/acquisitiond" "$unit" || fail "ExecStart does not point at the installed program"
grep -q "systemd-udev-settle" "$unit" && fail "the unit still orders after systemd-udev-settle"
# verify runs `man` on each Documentation= page: found only in the installed tree
out=$(MANPATH="$prefix/share/man" systemd-analyze verify "$unit" 2>&1); rc=$?
if [ $rc -ne 0 ] || grep -qi "unknown\|invalid\|failed to parse\|ignoring\|not executable\|no such file" <<<"$out"; then
  echo "$out"; fail "systemd-analyze verify of the installed unit (rc $rc)"
fi
docs=$(sed -n 's/^Documentation=//p' "$unit")
[ -n "$docs" ] || fail "no Documentation="
for d in $docs; do
  case $d in
    man:*) page=${d#man:}; name=${page%%(*}; sec=${page#*(}; sec=${sec%)}
           [ -f "$prefix/share/man/man$sec/$name.$sec" ] || fail "Documentation=$d: page not installed";;
    file://*) [ -f "${d#file://}" ] || fail "Documentation=$d: not installed";;
  esac
done

pages=0
for page in acqctl.1 acq-sim.1 brdf-recon.1 acq-nexus.1 acquisitiond.8 acquisitiond.yaml.5; do
  f=$(ls "$prefix"/share/man/man*/"$page" 2>/dev/null) || fail "man page $page not installed"
  warn=$(MANWIDTH=100 man --warnings -l "$f" 2>&1 >"$tmp/page.txt")
  [ -z "$warn" ] || fail "man -l $page: $warn"
  name=${page%.*}
  grep -q "^NAME" "$tmp/page.txt" && grep -q "$name" "$tmp/page.txt" || fail "man -l $page: no NAME section"
  pages=$((pages + 1))
done

rules="$prefix/lib/udev/rules.d/60-avaspec.rules"
grep -q 'GROUP="acquisitiond"' "$rules" || fail "udev rule not group-based"
grep -v "^#" "$rules" | grep -q uaccess && fail "udev rule still tags uaccess"
# the spectrometer's group is one the daemon runs with (Group= or SupplementaryGroups=), and no other device group
ugrp=$(grep -v "^#" "$rules" | grep -o 'GROUP="[^"]*"' | cut -d'"' -f2)
ugroups=" $(sed -n 's/^Group=//p; s/^SupplementaryGroups=//p' "$unit" | tr '\n' ' ') "
[[ $ugroups == *" $ugrp "* ]] || fail "udev GROUP=$ugrp is not among the unit's groups:$ugroups"
[[ $ugroups != *" plugdev "* ]] || fail "the unit asks for plugdev, which the udev rule does not use"
sysusers="$prefix/lib/sysusers.d/acquisitiond.conf"
for w in "u acquisitiond" "g acquisition " "g acquisition-view"; do grep -q "^$w" "$sysusers" || fail "sysusers: $w"; done
if systemd-sysusers --help 2>&1 | grep -q -- "--dry-run"; then
  systemd-sysusers --dry-run --root="$tmp/sysroot" "$sysusers" >"$tmp/su.log" 2>&1 || { cat "$tmp/su.log"; fail "sysusers dry run"; }
fi
tmpfiles="$prefix/lib/tmpfiles.d/acquisitiond.conf"
mkdir -p "$tmp/troot"
# applied to an empty root: every line must parse; only the users/groups (made by sysusers) may be missing there
systemd-tmpfiles --root="$tmp/troot" --create "$tmpfiles" >/dev/null 2>"$tmp/tf.log"
bad=$(grep -vi "resolve user\|resolve group\|unknown user\|unknown group" "$tmp/tf.log" || true)
[ -z "$bad" ] || fail "tmpfiles: $bad"
bash -c "_init_completion() { :; }; source '$prefix/share/bash-completion/completions/acqctl'; complete -p acqctl" \
  >/dev/null || fail "completion does not load"
for f in share/acquisitiond/schema.sql share/acquisitiond/acqctl-replies.schema.json share/doc/acquisitiond/README.md \
         share/acquisitiond/config/bench-sim.yaml bin/acqctl bin/acquisitiond bin/acq-sim bin/brdf-recon; do
  [ -f "$prefix/$f" ] || fail "$f not installed"
done
# every installed program has its man page (acq-nexus had none), and the docs the pages point at are installed
for b in "$prefix"/bin/*; do
  ls "$prefix"/share/man/man[18]/"$(basename "$b")".[18] >/dev/null 2>&1 || fail "no man page for bin/$(basename "$b")"
done
[ -f "$prefix/share/doc/acquisitiond/nexus.md" ] || fail "share/doc/acquisitiond/nexus.md (acq-nexus(1)) not installed"
"$prefix/bin/acqctl" --version >/dev/null || fail "installed acqctl does not run"
n=$(find "$tmp/usr" "$tmp/etc" -type f | wc -l)

mk uninstall >"$tmp/uninstall.log" 2>&1 || { cat "$tmp/uninstall.log"; fail "make uninstall"; }
left=$(find "$tmp/usr" "$tmp/etc" -type f 2>/dev/null)
[ -z "$left" ] || fail "uninstall left: $left"
echo "ok: $n files installed, unit verified, $pages man pages render, uninstall complete"
