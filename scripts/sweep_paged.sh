#!/usr/bin/env bash
# Texture memory side by side: the full clip stack against the paged pool at
# four viewports, and the paged pool's accuracy against its size.
#
#   bash scripts/sweep_paged.sh            # about 10 minutes on 2 cores
#   bash scripts/sweep_paged.sh --quick    # 1280x720 only, fewer frames (smoke run)
#   bash scripts/sweep_paged.sh --charts-only  # redraw from docs/data/paged_*.csv
#
# Flights (clipstream-fly --procedural 67108864 --reference --deterministic, each
# mode judged against a reference drawn the same way, docs/renderer.md):
#  - line: the sweep's line (200 texels up, 30 deg down) at x10, 120 frames;
#  - turns: the sweep's snap turns, 150 frames (quarter turns at frames 60
#    and 120, each a cut).
# At 1280x720, 1920x1080, 2560x1440 and 3840x2160, RGBA8: stack and paged
# (the default pool) where each fits; a stack the driver cannot allocate
# is recorded as refused with its message. Then the turns at 1280x720 with
# pools of 3 to 40 MiB (the knee: where over-subscription starts to cost).
# Every frame is judged; the over-fetch ratio, which no table here reads,
# is not measured (--no-over-fetch: its per-pixel trace of every frame took
# the sweep from 460 s to 2790 s, the same tables).
# Writes docs/data/paged_viewports.csv, docs/data/paged_pool.csv,
# docs/data/paged_setup.tsv and docs/charts/paged_*.png, and renders
# docs/benchmarks.md (scripts/gen_benchmarks.sh).
set -euo pipefail
cd "$(dirname "$0")/.."

# shellcheck source=scripts/sweep_lib.sh
source scripts/sweep_lib.sh "$@"
BUILD=${BUILD_DIR:-build}
WORK=${SWEEP_WORK:-out/sweep}/paged
DOCS=${SWEEP_DOCS:-docs}
SIZES="1280x720 1920x1080 2560x1440 3840x2160"
POOLS="3 8 16 20 24 40"
LINE_FRAMES=120; TURN_FRAMES=150; WARMUP=60
if (( QUICK )); then SIZES="1280x720"; POOLS="3 24"; LINE_FRAMES=30; TURN_FRAMES=90; WARMUP=30; fi
mkdir -p "$WORK" "$DOCS/data" "$DOCS/charts"
VCSV=$DOCS/data/paged_viewports.csv
PCSV=$DOCS/data/paged_pool.csv
start=$(date +%s)
# Half-written tables never stay behind (they are renamed when whole).
trap 'rm -f "$VCSV.tmp.$$" "$PCSV.tmp.$$" "$DOCS/data/paged_setup.tsv.tmp.$$"' EXIT

value() { awk -F'\t' -v k="$2" 'NR==1{for(i=1;i<=NF;i++) c[$i]=i} NR==2{print $(c[k])}' "$1/summary.tsv"; }
KEYS="gpu_texture_mib psnr_mean_db psnr_min_db frames_below_30db time_to_sharp_mean time_to_sharp_max frame_ms_p50 frame_ms_p99 tiles_uploaded pool_pages frames_pages_short pool_pages_wanted_max"

if (( ! CHARTS_ONLY )); then
scripts/deps.sh
cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$BUILD" -j "$(nproc)" --target clipstream-fly >/dev/null
FLY=$BUILD/eval/clipstream-fly

cat >"$WORK/line.json" <<JSON
{"interpolation": "smooth", "keyframes": [
  {"t": 0, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 90, "pitch_deg": -30},
  {"t": 1000, "x": 33654432, "y": 200, "z": 33554432, "heading_deg": 90, "pitch_deg": -30}]}
JSON
cat >"$WORK/turn.json" <<JSON
{"interpolation": "step", "keyframes": [
  {"t": 0, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 90, "pitch_deg": -30},
  {"t": 1, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 180, "pitch_deg": -30},
  {"t": 2, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 270, "pitch_deg": -30},
  {"t": 3, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 270, "pitch_deg": -30}]}
JSON
COMMON="--procedural 67108864 --io-threads 2 --reference --no-over-fetch --warmup-frames $WARMUP --deterministic --save-frames 0"
declare -A FLIGHT
FLIGHT[line]="--path $WORK/line.json --speed 10 --frames $LINE_FRAMES"
FLIGHT[turns]="--path $WORK/turn.json --frames $TURN_FRAMES"

# run NAME ARGS...: one flight into $WORK/NAME; 0 when it ran, 1 when the
# program refused it (its message in $WORK/NAME.log).
run() {
  local name=$1; shift
  rm -rf "${WORK:?}/$name"
  printf '%5ds  %s\n' $(( $(date +%s) - start )) "$name" >&2
  # shellcheck disable=SC2086  # COMMON is words
  if "$FLY" $COMMON "$@" --out "$WORK/$name" >"$WORK/$name.log" 2>&1; then return 0; fi
  [ -f "$WORK/$name/summary.tsv" ] && { echo "sweep_paged: $name failed after it ran: $WORK/$name.log" >&2; exit 1; }
  return 1
}

{
  echo "viewport,flight,mode,refused,$(echo "$KEYS" | tr ' ' ',')"
  for size in $SIZES; do
    for flight in line turns; do
      for mode in stack paged; do
        name="${size}_${flight}_${mode}"
        # shellcheck disable=SC2086  # a flight is words
        if run "$name" --size "$size" --texture-memory "$mode" ${FLIGHT[$flight]}; then
          line="$size,$flight,$mode,"
          for k in $KEYS; do line="$line,$(value "$WORK/$name" "$k")"; done
        else
          # The driver's refusal, quoted (commas dropped for the CSV).
          why=$(grep -m1 -o -E '(cannot allocate|refused to create|exceeds? GL_MAX)[^:]*' "$WORK/$name.log" |
                tr -d ',' || true)
          [ -n "$why" ] || { echo "sweep_paged: $name failed: $WORK/$name.log" >&2; tail -3 "$WORK/$name.log" >&2; exit 1; }
          line="$size,$flight,$mode,$why"
          for _ in $KEYS; do line="$line,"; done
        fi
        echo "$line"
      done
    done
  done
} >"$VCSV.tmp.$$"
mv "$VCSV.tmp.$$" "$VCSV"

{
  echo "pool_mib,$(echo "$KEYS" | tr ' ' ',')"
  for mib in $POOLS; do
    name="pool_${mib}"
    # shellcheck disable=SC2086  # a flight is words
    run "$name" --size 1280x720 --texture-memory paged --pool-mb "$mib" ${FLIGHT[turns]} ||
      { echo "sweep_paged: $name refused: $WORK/$name.log" >&2; tail -3 "$WORK/$name.log" >&2; exit 1; }
    line="$mib"
    for k in $KEYS; do line="$line,$(value "$WORK/$name" "$k")"; done
    echo "$line"
  done
} >"$PCSV.tmp.$$"
mv "$PCSV.tmp.$$" "$PCSV"
# What the doc block says of the run, for --charts-only to repeat.
echo "$(date -u +%Y-%m-%d) $(( $(date +%s) - start )) $LINE_FRAMES $TURN_FRAMES $WARMUP" >"$WORK/run.info"
fi
read -r _ _ LINE_FRAMES TURN_FRAMES WARMUP <"$WORK/run.info"  # its date and run time are not shown
cuts=$(( (TURN_FRAMES - 1) / 60 ))

# ---- charts -------------------------------------------------------------------
if gnuplot -e 'set terminal' 2>&1 | grep -q pngcairo; then term="pngcairo size 900,480 font 'sans,10'"
else term="png size 900,480"; fi
# Columns: 1 viewport, 2 flight, 3 mode, 4 refused, 5 gpu_texture_mib, 6 psnr_mean_db, 7 psnr_min_db,
# 8 frames_below_30db, 9 time_to_sharp_mean, 10 time_to_sharp_max, 11 frame_ms_p50, ...
# A refused stack keeps its place (no bar).
awk -F, 'NR>1 && $2=="turns" {print $1, $3, ($4=="" ? $5 : "?"), ($4=="" ? $6 : "?")}' "$VCSV" >"$WORK/viewports.dat"
gnuplot <<EOF
set terminal $term
set output "$DOCS/charts/paged_viewports.png"
set title "Stack against paged: GPU texture memory and PSNR on the turns (RGBA8; no stack bar: refused)"
set style data histogram
set style histogram clustered gap 1
set style fill solid 0.8
set ylabel "GPU texture MiB (log)"
set logscale y
set y2label "PSNR mean, dB"
set y2range [0:100]
set y2tics
set key top left
plot "< awk '\$2==\"stack\"' $WORK/viewports.dat" using 3:xtic(1) title "stack MiB", \
     "< awk '\$2==\"paged\"' $WORK/viewports.dat" using 3:xtic(1) title "paged MiB", \
     "< awk '\$2==\"paged\"' $WORK/viewports.dat" using 0:4 axes x1y2 with linespoints lw 2 title "paged PSNR", \
     "< awk '\$2==\"stack\"' $WORK/viewports.dat" using 0:4 axes x1y2 with points pt 7 ps 1.5 title "stack PSNR"
EOF
# Pool columns: 1 pool_mib, 2 gpu_texture_mib, 3 psnr_mean_db, 4 psnr_min_db, 5 frames_below_30db,
# 6 time_to_sharp_mean, 7 time_to_sharp_max, ..., 11 pool_pages, 12 frames_pages_short
stack_turn=$(awk -F, '$1=="1280x720" && $2=="turns" && $3=="stack" {print $6}' "$VCSV")
# The stack's line only where the stack ran at 1280x720.
stack_plot=""
[ -n "$stack_turn" ] && stack_plot="$stack_turn with lines dt 2 title \"stack PSNR mean\", "

gnuplot <<EOF
set terminal $term
set output "$DOCS/charts/paged_pool.png"
set title "Paged pool size against accuracy: the turns at 1280x720 (RGBA8)"
set datafile separator ","
set xlabel "pool MiB (log)"
set logscale x
set ylabel "PSNR mean, dB"
set y2label "frames short of a page"
set y2tics
set key bottom right
plot "$PCSV" using 1:3 with linespoints lw 2 title "paged PSNR mean", $stack_plot\
     "$PCSV" using 1:12 axes x1y2 with linespoints title "frames short of a page"
EOF

# ---- docs ---------------------------------------------------------------------
# What the page says of the flights goes beside the data; the page is
# rendered from docs/benchmarks.md.in (scripts/gen_benchmarks.sh).
SETUP=$DOCS/data/paged_setup.tsv
printf 'key\tvalue\nline_frames\t%s\nturn_frames\t%s\ncuts\t%s\nwarmup_frames\t%s\n' \
  "$LINE_FRAMES" "$TURN_FRAMES" "$cuts" "$WARMUP" >"$SETUP.tmp.$$"
mv "$SETUP.tmp.$$" "$SETUP"
BM=$DOCS/benchmarks.md
scripts/gen_benchmarks.sh --data "$DOCS/data" --data docs/data --out "$BM" >/dev/null
echo "sweep_paged: done in $(( $(date +%s) - start )) s: $VCSV, $PCSV, $DOCS/charts/paged_*.png"
