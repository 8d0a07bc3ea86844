#!/usr/bin/env bash
# Frame cost of terrain against the flat plane, side by side in one run:
# the same orbit over the bundled orthophoto at 1280x720, flown flat and
# over the bundled DEM (stretched under it, half height), alternated N times
# so both see the same machine load. Prints a Markdown table and the median
# ratio of the paired mean frame times (docs/terrain.md quotes it).
# Usage: scripts/bench_terrain.sh [PAIRS] (default 3). Needs a built build/.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/bench_lib.sh  # median
pairs=${1:-3}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
build/tiler/clipstream-tile data/autzen.jpg "$work/autzen.cstore" --quiet --no-fsync
build/tiler/clipstream-tile data/mount_st_helens_30m.tif "$work/dem.cstore" --quiet --no-fsync
# The stack in both: terrain draws through it, and the flat flight would
# otherwise take the pool (--texture-memory auto) and change two things at once.
common=(--path orbit --frames 300 --size 1280x720 --save-frames 0 --texture-memory stack)
value() { awk -F'\t' -v k="$2" 'NR==1{for(i=1;i<=NF;i++) c[$i]=i} NR==2{print $(c[k])}' "$1/summary.tsv"; }
echo "| pair | flat frame ms (mean / p99) | terrain frame ms (mean / p99) | ratio of means | triangles / frame | height stack MiB |"
echo "|---:|---:|---:|---:|---:|---:|"
ratios=()
for i in $(seq 1 "$pairs"); do
  build/eval/clipstream-fly "$work/autzen.cstore" "${common[@]}" --out "$work/flat" >/dev/null
  build/eval/clipstream-fly "$work/autzen.cstore" "${common[@]}" --out "$work/terrain" \
    --elevation "$work/dem.cstore" --stretch-elevation --vertical-scale 0.5 >/dev/null 2>&1
  fm=$(value "$work/flat" frame_ms_mean); fp=$(value "$work/flat" frame_ms_p99)
  tm=$(value "$work/terrain" frame_ms_mean); tp=$(value "$work/terrain" frame_ms_p99)
  tri=$(value "$work/terrain" terrain_triangles_mean); mib=$(value "$work/terrain" height_texture_mib)
  ratio=$(awk -v a="$tm" -v b="$fm" 'BEGIN{printf "%.2f", a / b}')
  ratios+=("$ratio")
  printf '| %d | %.1f / %.1f | %.1f / %.1f | %s | %.0f | %.1f |\n' "$i" "$fm" "$fp" "$tm" "$tp" "$ratio" "$tri" "$mib"
done
median=$(printf '%s\n' "${ratios[@]}" | median)
echo
echo "median ratio terrain / flat: $median"
