#!/usr/bin/env bash
# Walks the README as a new user does: runs its shell blocks (```sh) in the
# order written, read from README.md itself so that the walk follows the
# README when it changes, then checks what each step should have left.
# Called by scripts/test.sh right after the demo's build, as root on a
# Debian 12 machine, offline.
#
# Three departures from the text, each the least that lets a test run it:
# - `bash scripts/test.sh` is skipped: it is the command running this walk.
# - The install prefix /opt/clipstream becomes a temporary folder, removed
#   at the end, so that the walk leaves nothing outside the clone.
# - The Debian packages are installed as written (apt-get, under /usr) and
#   removed again at the end, unless they were installed before the walk.
#
# The README's CMake block (find_package, target_link_libraries) is built by
# scripts/test.sh's embedding example against an install of the same tree.
# Usage: scripts/readme_walk.sh
set -euo pipefail
cd "$(dirname "$0")/.."

prefix=$(mktemp -d)
preinstalled=$(dpkg-query -W -f '${Status}\n' clipstream libclipstream-dev 2>/dev/null |
  grep -c 'install ok installed' || true)
cleanup() {
  # nginx, if its block failed before its `kill %1`
  if [[ -s /tmp/stores/nginx.pid ]]; then kill "$(cat /tmp/stores/nginx.pid)" 2>/dev/null || true; fi
  rm -rf "$prefix" /tmp/stores
  if [[ "$preinstalled" == 0 ]]; then
    apt-get remove -y -qq clipstream libclipstream-dev >/dev/null 2>&1 || true
  fi
}
trap cleanup EXIT

# Every ```sh block, in order; a NUL ends each block.
mapfile -d '' blocks < <(awk '
  /^```sh$/ { inside = 1; next }
  /^```/ && inside { inside = 0; printf "%c", 0; next }
  inside { print }
' README.md)
((${#blocks[@]} >= 3)) || { echo "README walk: expected 3 or more sh blocks in README.md, found ${#blocks[@]}" >&2; exit 1; }

step=0
for block in "${blocks[@]}"; do
  step=$((step + 1))
  script=$(sed -e '/^bash scripts\/test\.sh/d' -e "s|/opt/clipstream|$prefix|g" <<<"$block")
  # Continuation lines of the comments above leave nothing to run.
  if ! grep -qEv '^[[:space:]]*(#|$)' <<<"$script"; then continue; fi
  echo "== README, block $step =="
  sed 's/^/  $ /' <<<"$script" | grep -Ev '^\s+\$\s+#'
  start=$SECONDS
  if ! bash -euo pipefail -c "$script" >"$prefix/step$step.log" 2>&1; then
    tail -n 30 "$prefix/step$step.log" >&2
    echo "README walk: block $step failed (log above)" >&2
    exit 1
  fi
  echo "   ok, $((SECONDS - start)) s"
done

# What the steps should have left, beyond their exit status.
# field FILE NAME: a column of a summary.tsv (a header row, a value row).
field() {
  awk -F '\t' -v name="$2" 'NR == 1 { for (i = 1; i <= NF; ++i) if ($i == name) c = i }
    NR == 2 && c { print $c }' "$1" 2>/dev/null || true
}
failures=0
fail() { echo "README walk: $*" >&2; failures=$((failures + 1)); }
for run in fly terrain; do
  [[ -s out/demo/$run/summary.tsv ]] || fail "the demo wrote no out/demo/$run/summary.tsv"
  [[ -s out/demo/$run/frame_time.png ]] || fail "the demo wrote no out/demo/$run/frame_time.png"
  ls out/demo/$run/frame_*.png >/dev/null 2>&1 || fail "the demo saved no frames in out/demo/$run/"
done
[[ "$(field out/demo/terrain/summary.tsv psnr_mean_db)" =~ ^[0-9] ]] ||
  fail "the demo's terrain flight has no PSNR (it flies with --reference)"
requests=$(field out/fly-http/summary.tsv http_requests)
[[ "${requests:-0}" =~ ^[0-9]+$ && "${requests:-0}" -gt 0 ]] ||
  fail "the flight over nginx made no HTTP request (out/fly-http/summary.tsv: '${requests:-}')"
for program in clipstream-tile clipstream-merge clipstream-info clipstream-fly clipstream-view clipstream-trace; do
  "$prefix/bin/$program" --version >/dev/null || fail "the installed $program does not run"
  [[ "$(command -v "$program")" == /usr/bin/$program ]] || fail "the Debian package did not install /usr/bin/$program"
  page=/usr/share/man/man1/$program.1.gz
  dpkg -L clipstream | grep -qxF "$page" || fail "the Debian package does not list $page"
  # (a machine whose dpkg excludes manual pages lists it but has no file)
  if [[ -e "$page" ]]; then man -w "$program" >/dev/null 2>&1 || fail "man $program finds no page"; fi
done
pkg-config --exists clipstream || fail "pkg-config does not know clipstream after libclipstream-dev"

((failures == 0)) || exit 1
echo "README walk: every block ran as written, in order, and left what it should"
