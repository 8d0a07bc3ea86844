#!/usr/bin/env bash
# Tiling benchmark matrix: clipstream-tile against GDAL's COG writer and
# vips dzsave, for each input kind (JPEG baseline and progressive, PNG, 8-
# and 16-bit GeoTIFF uncompressed / deflate / LZW / JPEG, striped and tiled,
# BigTIFF) at each size. Every input is made from one deterministic RGB
# photo mosaic (autzen.jpg mirror-tiled with noise, bench/tiler_make_input)
# by gdal_translate, so the kinds differ only in how they are stored.
#
# Each round runs the three tools back to back on the warm input; a row's
# speed ratio is the median over rounds of GDAL's wall time over ours (the
# ratio of paired runs, which a shared machine's load shifts less than
# either time). The decode floor is bench/tiler_decode: the same reader and
# conversion decoding the input once top to bottom, nothing else.
# A row is "decode"-bound when 1.2 x floor exceeds half of GDAL's time;
# its target is then 1.2 x floor, else half of GDAL's time (2x its speed).
#
#   scripts/bench_tile.sh [BUILD_DIR]
#   env: SIZES ("4096 16384"), KINDS (all), ROUNDS (3), THREADS (all cores),
#        DATA (BUILD_DIR/bench-data: inputs, kept between runs)
# Prints a tab-separated table on stdout; progress on stderr.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build}
SIZES=${SIZES:-4096 16384}
ROUNDS=${ROUNDS:-3}
ALL_KINDS="jpeg jpeg_progressive png tif8_none_strip tif8_deflate_strip tif8_lzw_strip tif8_jpeg_strip \
tif8_deflate_tiled tif8_jpeg_tiled tif16_none_strip tif16_lzw_strip tif16_deflate_tiled bigtiff8_deflate_tiled"
KINDS=${KINDS:-$ALL_KINDS}
DATA=${DATA:-$BUILD/bench-data}
SRC="${CLIPSTREAM_SHARED_DATA_DIR:-../shared/data}/autzen.jpg"
TILE="$BUILD/tiler/clipstream-tile"
MAKE="$BUILD/bench/tiler_make_input"
DECODE="$BUILD/bench/tiler_decode"
for exe in "$TILE" "$MAKE" "$DECODE"; do
  [[ -x "$exe" ]] || { echo "missing $exe: build clipstream-tile, tiler_make_input and tiler_decode first" >&2; exit 1; }
done
for tool in gdal_translate vips /usr/bin/time; do
  command -v "$tool" >/dev/null || { echo "missing $tool (scripts/deps.sh --bench)" >&2; exit 1; }
done
mkdir -p "$DATA"
WORK=$(mktemp -d "${TMPDIR:-/tmp}/bench-tile-XXXXXX")
trap 'rm -rf "$WORK"' EXIT
THREAD_ARGS=()
[[ -n "${THREADS:-}" ]] && THREAD_ARGS=(--threads "$THREADS")

# make_input KIND SIZE: the input's path (made on first use from the base TIFF).
make_input() {
  local kind=$1 size=$2 base="$DATA/ortho_$2.tif"
  if [[ ! -f "$base" ]]; then
    echo "generating $base ..." >&2
    local part="$DATA/part_ortho_$size.tif"
    if [[ -f "$SRC" ]]; then "$MAKE" "$part" "$size" "$SRC" >&2; else "$MAKE" "$part" "$size" >&2; fi
    mv "$part" "$base"
  fi
  local ext=tif opts=()
  local scale16=(-ot UInt16 -scale 0 255 0 65535)
  local tiled=(-co TILED=YES -co BLOCKXSIZE=256 -co BLOCKYSIZE=256)
  case $kind in
    jpeg) ext=jpg opts=(-of JPEG -co QUALITY=90) ;;
    jpeg_progressive) ext=jpg opts=(-of JPEG -co QUALITY=90 -co PROGRESSIVE=ON) ;;
    png) ext=png opts=(-of PNG -co ZLEVEL=6) ;;
    tif8_none_strip) opts=(-co COMPRESS=NONE) ;;
    tif8_deflate_strip) opts=(-co COMPRESS=DEFLATE -co PREDICTOR=2) ;;
    tif8_lzw_strip) opts=(-co COMPRESS=LZW -co PREDICTOR=2) ;;
    tif8_jpeg_strip) opts=(-co COMPRESS=JPEG -co PHOTOMETRIC=YCBCR -co JPEG_QUALITY=90) ;;
    tif8_deflate_tiled) opts=("${tiled[@]}" -co COMPRESS=DEFLATE -co PREDICTOR=2) ;;
    tif8_jpeg_tiled) opts=("${tiled[@]}" -co COMPRESS=JPEG -co PHOTOMETRIC=YCBCR -co JPEG_QUALITY=90) ;;
    tif16_none_strip) opts=("${scale16[@]}" -co COMPRESS=NONE) ;;
    tif16_lzw_strip) opts=("${scale16[@]}" -co COMPRESS=LZW -co PREDICTOR=2) ;;
    tif16_deflate_tiled) opts=("${scale16[@]}" "${tiled[@]}" -co COMPRESS=DEFLATE -co PREDICTOR=2) ;;
    bigtiff8_deflate_tiled) opts=(-co BIGTIFF=YES "${tiled[@]}" -co COMPRESS=DEFLATE -co PREDICTOR=2) ;;
    *) echo "unknown kind $kind" >&2; exit 2 ;;
  esac
  local out="$DATA/${kind}_${size}.$ext"
  if [[ ! -f "$out" ]]; then
    echo "generating $out ..." >&2
    GDAL_CACHEMAX=512 gdal_translate -q "${opts[@]}" "$base" "$out.part.$ext" >&2
    rm -f "$out.part.$ext.aux.xml"
    mv "$out.part.$ext" "$out"
  fi
  echo "$out"
}

# timed NAME OUTPUT CMD...: one run; sets T_WALL T_RSS_MB T_BYTES.
timed() {
  local name=$1 output=$2; shift 2
  rm -rf "$output"
  /usr/bin/time -v -o "$WORK/$name.time" "$@" > "$WORK/$name.log" 2>&1 || {
    echo "$name failed: $*" >&2; tail -5 "$WORK/$name.log" >&2; T_WALL=nan T_RSS_MB=nan T_BYTES=0; return 0; }
  T_WALL=$(awk -F': ' '/Elapsed \(wall clock\)/ {n=split($2,a,":"); s=0; for(i=1;i<=n;i++) s=s*60+a[i]; print s}' "$WORK/$name.time")
  T_RSS_MB=$(awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$WORK/$name.time")
  T_BYTES=$(du -sb "$output" | cut -f1)
  rm -rf "$output"
}

source scripts/bench_lib.sh  # median

echo "# $(nproc) cores, load before: $(cut -d' ' -f1-3 /proc/loadavg), rounds: $ROUNDS, $(date -u +%F)"
printf 'size\tkind\tinput_MB\tdecoder\tfloor_s\tclip_s\tgdal_s\tvips_s\tspeed_vs_gdal\tspeed_vs_vips\tclip_rss_MB\tgdal_rss_MB\tvips_rss_MB\tclip_MB\tgdal_MB\tbytes_vs_gdal\tbound\ttarget_s\tmet\n'
for size in $SIZES; do
  for kind in $KINDS; do
    in=$(make_input "$kind" "$size") && [[ -f "$in" ]] || { echo "cannot make the $kind input of $size" >&2; exit 1; }
    cat "$in" > /dev/null  # warm the page cache: every tool reads from memory
    floors="" clips="" gdals="" vipss="" rg="" rv="" crss="" grss="" vrss="" cb=0 gb=0
    decoder=$("$DECODE" "$in" 0 | cut -f1)
    for ((r = 0; r < ROUNDS; r++)); do
      echo "$size $kind round $((r + 1))/$ROUNDS" >&2
      floors+=" $("$DECODE" "$in" 0 | cut -f3)"
      timed clip "$WORK/out.cst" "$TILE" "$in" "$WORK/out.cst" --quiet --force "${THREAD_ARGS[@]}"
      c=$T_WALL; clips+=" $c"; crss+=" $T_RSS_MB"; cb=$T_BYTES
      timed gdal "$WORK/gdal.tif" gdal_translate -q -of COG -co BLOCKSIZE=128 -co COMPRESS=ZSTD -co LEVEL=1 \
        -co PREDICTOR=YES -co RESAMPLING=AVERAGE -co NUM_THREADS=ALL_CPUS "$in" "$WORK/gdal.tif"
      g=$T_WALL; gdals+=" $g"; grss+=" $T_RSS_MB"; gb=$T_BYTES
      timed vips "$WORK/vips" vips dzsave "$in" "$WORK/vips" --tile-size 128 --overlap 0 --depth onepixel \
        --suffix '.tif[compression=zstd,level=1]' --container zip
      v=$T_WALL; vipss+=" $v"; vrss+=" $T_RSS_MB"
      rg+=" $(awk -v g="$g" -v c="$c" 'BEGIN{print (c > 0 && g == g) ? g / c : "nan"}')"
      rv+=" $(awk -v v="$v" -v c="$c" 'BEGIN{print (c > 0 && v == v) ? v / c : "nan"}')"
    done
    awk -v size="$size" -v kind="$kind" -v inb="$(stat -c %s "$in")" -v dec="$decoder" \
        -v f="$(echo "$floors" | median)" -v c="$(echo "$clips" | median)" -v g="$(echo "$gdals" | median)" \
        -v v="$(echo "$vipss" | median)" -v rg="$(echo "$rg" | median)" -v rv="$(echo "$rv" | median)" \
        -v cr="$(echo "$crss" | median)" -v gr="$(echo "$grss" | median)" -v vr="$(echo "$vrss" | median)" \
        -v cb="$cb" -v gb="$gb" 'BEGIN {
      bound = (1.2 * f > g / 2) ? "decode" : "tiling"
      target = (bound == "decode") ? 1.2 * f : g / 2
      met = (c <= target && cr <= 256 && cb <= gb) ? "yes" : "no"
      printf "%s\t%s\t%.1f\t%s\t%.2f\t%.2f\t%.2f\t%.2f\t%.2f\t%.2f\t%.0f\t%.0f\t%.0f\t%.1f\t%.1f\t%.3f\t%s\t%.2f\t%s\n",
        size, kind, inb / 1e6, dec, f, c, g, v, rg, rv, cr, gr, vr, cb / 1e6, gb / 1e6, (gb > 0 ? cb / gb : 0), bound, target, met
    }'
  done
done
