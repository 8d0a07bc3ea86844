#!/usr/bin/env bash
# Tiling benchmark: clipstream-tile vs GDAL COG vs vips dzsave on one
# deterministic SIZE x SIZE RGB TIFF (autzen.jpg mirror-tiled at native
# resolution + noise; see bench/tiler_make_input.cpp). Prints a
# tab-separated table: best of REPEAT runs per tool (by wall time).
#
#   scripts/bench_tile.sh [BUILD_DIR]      env: SIZE (16384), REPEAT (1), THREADS (all)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD=${1:-build-tiler}
SIZE=${SIZE:-16384}
REPEAT=${REPEAT:-1}
DATA="$BUILD/bench-data"
SRC="${CLIPSTREAM_SHARED_DATA_DIR:-../shared/data}/autzen.jpg"
TILE="$BUILD/tiler/clipstream-tile"
MAKE="$BUILD/bench/tiler_make_input"
for exe in "$TILE" "$MAKE"; do
  [[ -x "$exe" ]] || { echo "missing $exe: build clipstream-tile and tiler_make_input first" >&2; exit 1; }
done
for tool in gdal_translate vips /usr/bin/time; do
  command -v "$tool" >/dev/null || { echo "missing $tool" >&2; exit 1; }
done

mkdir -p "$DATA"
IN="$DATA/ortho_${SIZE}.tif"
if [[ ! -f "$IN" ]]; then
  echo "generating $IN ..." >&2
  if [[ -f "$SRC" ]]; then "$MAKE" "$IN.part" "$SIZE" "$SRC"; else "$MAKE" "$IN.part" "$SIZE"; fi
  mv "$IN.part" "$IN"
fi
# Warm the page cache so every tool reads the input from memory.
cat "$IN" > /dev/null

LOAD_BEFORE=$(cut -d' ' -f1-3 /proc/loadavg)
WORK=$(mktemp -d "${TMPDIR:-/tmp}/bench-tile-XXXXXX")
trap 'rm -rf "$WORK"' EXIT
THREAD_ARGS=()
[[ -n "${THREADS:-}" ]] && THREAD_ARGS=(--threads "$THREADS")

# run NAME OUTPUT CMD...: best-of-REPEAT wall time; records wall, peak RSS and output bytes.
declare -A WALL RSS BYTES CPU
run() {
  local name=$1 output=$2; shift 2
  local best=""
  for ((i = 0; i < REPEAT; i++)); do
    rm -rf "$output"
    /usr/bin/time -v -o "$WORK/$name.time" "$@" > "$WORK/$name.log" 2>&1 || {
      echo "$name failed:" >&2; cat "$WORK/$name.log" >&2; exit 1; }
    local wall rss cpu
    wall=$(awk -F': ' '/Elapsed \(wall clock\)/ {n=split($2,a,":"); s=0; for(i=1;i<=n;i++) s=s*60+a[i]; print s}' "$WORK/$name.time")
    rss=$(awk -F': ' '/Maximum resident set size/ {print $2}' "$WORK/$name.time")
    cpu=$(awk -F': ' '/User time|System time/ {s+=$2} END {print s}' "$WORK/$name.time")
    if [[ -z "$best" ]] || awk "BEGIN{exit !($wall < $best)}"; then
      best=$wall; WALL[$name]=$wall; RSS[$name]=$rss; CPU[$name]=$cpu
      BYTES[$name]=$(du -sb "$output" | cut -f1)
    fi
  done
}

run clipstream "$WORK/out.cst" "$TILE" "$IN" "$WORK/out.cst" --quiet --force "${THREAD_ARGS[@]}"
run gdal "$WORK/gdal.tif" gdal_translate -q -of COG -co BLOCKSIZE=128 -co COMPRESS=ZSTD -co LEVEL=1 \
  -co PREDICTOR=YES -co RESAMPLING=AVERAGE -co NUM_THREADS=ALL_CPUS "$IN" "$WORK/gdal.tif"
run vips "$WORK/vips" vips dzsave "$IN" "$WORK/vips" --tile-size 128 --overlap 0 --depth onepixel \
  --suffix '.tif[compression=zstd,level=1]' --container zip

MP=$(awk "BEGIN{print $SIZE * $SIZE / 1e6}")
echo "# input: $IN (${SIZE}x${SIZE} RGB8, $(stat -c %s "$IN") bytes), $(nproc) cores, best of $REPEAT"
echo "# load average before: $LOAD_BEFORE"
printf 'tool\twall_s\tcpu_s\tMP_per_s\tpeak_rss_MB\toutput_bytes\tspeed_vs_gdal\tcpu_vs_gdal\trss_vs_gdal\tbytes_vs_gdal\n'
for name in clipstream gdal vips; do
  awk -v n="$name" -v w="${WALL[$name]}" -v c="${CPU[$name]}" -v r="${RSS[$name]}" -v b="${BYTES[$name]}" \
      -v mp="$MP" -v gw="${WALL[gdal]}" -v gc="${CPU[gdal]}" -v gr="${RSS[gdal]}" -v gb="${BYTES[gdal]}" 'BEGIN {
    printf "%s\t%.2f\t%.2f\t%.1f\t%.0f\t%d\t%.2f\t%.2f\t%.2f\t%.3f\n", n, w, c, mp / w, r / 1024, b, gw / w, gc / c, r / gr, b / gb }'
done
