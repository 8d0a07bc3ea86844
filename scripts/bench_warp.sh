#!/usr/bin/env bash
# Reprojection by clipstream-tile --t-srs against gdalwarp, same resampling
# (bilinear) and grid (GDAL's suggestion): accuracy (level 0 of clipstream's
# store against gdalwarp's GeoTIFF, sample by sample: bench/tiler_warp_diff)
# and time (clipstream-tile: warp, whole pyramid, zstd; gdalwarp: level 0
# only, an uncompressed GeoTIFF), median of ROUNDS, alternated. Inputs: the
# shared Rainier DEM (EPSG:4326) to its UTM zone, and the shared globe
# placed in EPSG:4326 (80 S to 80 N) to Web Mercator. docs/tiler.md,
# "Reprojection".
#
#   scripts/bench_warp.sh [BUILD_DIR] [ROUNDS]
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build}
ROUNDS=${2:-3}
TILE="$BUILD/tiler/clipstream-tile"
INFO="$BUILD/store/clipstream-info"
DIFF="$BUILD/bench/tiler_warp_diff"
SHARED=${CLIPSTREAM_SHARED_DATA_DIR:-../shared/data}
for exe in "$TILE" "$INFO" "$DIFF"; do [[ -x "$exe" ]] || { echo "missing $exe: build it first" >&2; exit 1; }; done
command -v gdalwarp >/dev/null || { echo "gdalwarp missing: scripts/deps.sh" >&2; exit 1; }
DATA="$BUILD/bench-data/warp"
mkdir -p "$DATA"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Rows 228..3867 of 4096: 79.98 S to 79.98 N (Web Mercator stops short of the poles).
globe="$DATA/globe4326.tif"
[[ -f "$globe" ]] || gdal_translate -q -a_srs EPSG:4326 -srcwin 0 228 8192 3640 \
  -a_ullr -180 79.98046875 180 -79.98046875 -co TILED=YES -co COMPRESS=DEFLATE \
  "$SHARED/fg_globe_colors_8192x4096.jpg" "$globe"

seconds() { local t0 t1; t0=$(date +%s.%N); "$@" >/dev/null 2>&1; t1=$(date +%s.%N); echo "$t1 - $t0" | bc; }
source scripts/bench_lib.sh  # median

printf 'input\ttarget\tsize\tclip_s\tgdalwarp_s\tclip_over_gdalwarp\tsamples\tmax_diff\tmean_diff\tshare_differing\torigin_offset_px\n'
while read -r name input target; do
  clip_t=() warp_t=() extra=()
  # An RGB input gains alpha in clipstream (docs/tiler.md): gdalwarp likewise.
  [[ $name == globe ]] && extra=(-dstalpha)
  for ((r = 0; r < ROUNDS; r++)); do
    clip_t+=("$(seconds "$TILE" -q --no-fsync --force "$input" "$work/clip.cst" --t-srs "$target")")
    rm -f "$work/ref.tif"
    warp_t+=("$(seconds gdalwarp -q -t_srs "$target" -r bilinear "${extra[@]}" "$input" "$work/ref.tif")")
  done
  read -r samples largest mean share offset < <("$DIFF" "$work/clip.cst" "$work/ref.tif")
  size=$("$INFO" "$work/clip.cst" | awk '/^image/ {print $2 "x" $4}')
  ct=$(printf '%s\n' "${clip_t[@]}" | median) wt=$(printf '%s\n' "${warp_t[@]}" | median)
  printf '%s\t%s\t%s\t%.2f\t%.2f\t%.2f\t%s\t%s\t%s\t%s\t%s\n' "$name" "$target" "$size" "$ct" "$wt" \
    "$(echo "$ct / $wt" | bc -l)" "$samples" "$largest" "$mean" "$share" "$offset"
done <<EOF
rainier_90m $SHARED/mt_rainier_90m.tif EPSG:32610
globe $globe EPSG:3857
EOF
