#!/usr/bin/env bash
# The tiler's own readers (libtiff, libjpeg-turbo, libpng) against GDAL
# (--reader gdal) on the same files: whole clipstream-tile runs, alternated
# so both see the same machine, median of ROUNDS. Inputs are made from the
# shared 8192 x 4096 globe by gdal_translate (scripts/deps.sh --bench).
# Prints a TSV: kind, input MB, own reader's and GDAL's wall time and peak
# RSS, GDAL's time over ours. docs/tiler.md, "Any raster GDAL reads".
#
#   scripts/bench_readers.sh [BUILD_DIR] [ROUNDS]
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build}
ROUNDS=${2:-3}
TILE="$BUILD/tiler/clipstream-tile"
SRC=${CLIPSTREAM_SHARED_DATA_DIR:-../shared/data}/fg_globe_colors_8192x4096.jpg
[[ -x "$TILE" ]] || { echo "missing $TILE: build clipstream-tile first" >&2; exit 1; }
[[ -f "$SRC" ]] || { echo "missing $SRC (the shared data)" >&2; exit 1; }
command -v gdal_translate >/dev/null || { echo "gdal_translate missing: scripts/deps.sh --bench" >&2; exit 1; }
DATA="$BUILD/bench-data/readers"
mkdir -p "$DATA"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

make_input() {  # KIND -> path
  local kind=$1 out
  case $kind in
    tiff_strips_deflate) out="$DATA/globe_strips.tif"; opts=(-of GTiff -co COMPRESS=DEFLATE) ;;
    tiff_tiled_lzw) out="$DATA/globe_tiled.tif"; opts=(-of GTiff -co TILED=YES -co COMPRESS=LZW) ;;
    jpeg) out="$DATA/globe.jpg"; opts=(-of JPEG -co QUALITY=90) ;;
    png) out="$DATA/globe.png"; opts=(-of PNG) ;;
  esac
  [[ -f "$out" ]] || gdal_translate -q "${opts[@]}" "$SRC" "$out"
  echo "$out"
}

# run READER INPUT -> "wall_s rss_MB"
run() {
  local reader=$1 in=$2
  "$TILE" -q --no-fsync --force --reader "$reader" "$in" "$work/out.cst" --json-summary "$work/s.json"
  python3 -c 'import json,sys; s=json.load(open(sys.argv[1])); print(s["wall_s"], s["peak_rss_bytes"] / 2**20)' "$work/s.json"
}

source scripts/bench_lib.sh  # median

printf 'kind\tinput_MB\town_s\tgdal_s\tgdal_over_own\town_rss_MB\tgdal_rss_MB\n'
for kind in tiff_strips_deflate tiff_tiled_lzw jpeg png; do
  in=$(make_input "$kind")
  own_t=() gdal_t=() own_m=() gdal_m=()
  for ((r = 0; r < ROUNDS; r++)); do
    read -r t m < <(run auto "$in"); own_t+=("$t"); own_m+=("$m")
    read -r t m < <(run gdal "$in"); gdal_t+=("$t"); gdal_m+=("$m")
  done
  ot=$(printf '%s\n' "${own_t[@]}" | median) gt=$(printf '%s\n' "${gdal_t[@]}" | median)
  om=$(printf '%s\n' "${own_m[@]}" | median) gm=$(printf '%s\n' "${gdal_m[@]}" | median)
  awk -v k="$kind" -v mb="$(stat -c %s "$in")" -v ot="$ot" -v gt="$gt" -v om="$om" -v gm="$gm" \
    'BEGIN { printf "%s\t%.1f\t%.2f\t%.2f\t%.2f\t%.0f\t%.0f\n", k, mb / 1e6, ot, gt, gt / ot, om, gm }'
done
