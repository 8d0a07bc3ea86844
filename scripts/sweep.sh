#!/usr/bin/env bash
# Speed against accuracy: the whole sweep in one command.
#
#   bash scripts/sweep.sh            # full sweep (38 min 40 s on 2 cores with SWEEP_ASAN=0, 2026-12-06: docs/benchmarks.md)
#   bash scripts/sweep.sh --quick    # fewer frames, for a smoke run (CSV/charts still written)
#   bash scripts/sweep.sh --charts-only  # redraw from the last run's outputs
#   SWEEP_ASAN=0 bash scripts/sweep.sh --quick  # without the soak under ASan (its row says "not run")
#   SWEEP_TERRAIN=0 bash scripts/sweep.sh       # without the terrain methods (scripts/sweep_terrain.sh, ~25 min)
#   SWEEP_PAGED=0 bash scripts/sweep.sh         # without stack against paged at four viewports (scripts/sweep_paged.sh, ~8 min)
#
# Builds what it needs (into $BUILD_DIR, default build/), tiles data/autzen.jpg
# once, runs every experiment with clipstream-fly --reference (each frame's
# PSNR against the ideal reference), the accuracy experiments with
# --deterministic (reads land on a simulated I/O clock, so two sweeps give
# the same accuracy tables on any machine) and again $SWEEP_REALTIME_RUNS
# times (default 2) in real time, reported beside as ranges; replays a request trace with
# clipstream-trace, runs the stability scenarios (tests/eval/
# test_stability.cpp, with the 10,000-frame soak at default settings), runs
# the soak again under AddressSanitizer + UBSan with leak checking (built in
# $ASAN_BUILD_DIR, default build-asan, when missing), writes docs/data/*.csv
# (with sweep_setup.tsv and sweep_commands.tsv: what the page says of the
# runs), draws docs/charts/*.png with gnuplot and renders docs/benchmarks.md
# (scripts/gen_benchmarks.sh; the sweep's part between <!-- sweep:begin -->
# and <!-- sweep:end -->).
# What each metric and chart means: docs/accuracy.md.
set -euo pipefail
cd "$(dirname "$0")/.."

# shellcheck source=scripts/sweep_lib.sh
source scripts/sweep_lib.sh "$@"
BUILD=${BUILD_DIR:-build}
ASAN_BUILD=${ASAN_BUILD_DIR:-build-asan}
WORK=${SWEEP_WORK:-out/sweep}
DOCS=${SWEEP_DOCS:-docs}
DATA=$DOCS/data
CHARTS=$DOCS/charts
SIZE=${SWEEP_SIZE:-320x180}
JOBS=$(nproc)
FRAMES=240; LONG=300; TRACE_FRAMES=600; SOAK=10000
# Real-time repeats of the speed, upload and throttle runs: their spread is
# what a reader of a real-time figure must allow for.
RT_RUNS=${SWEEP_REALTIME_RUNS:-2}
ASAN=${SWEEP_ASAN:-1}
# The simulated I/O of the deterministic runs (clipstream-fly's defaults
# unless set: docs/architecture.md, "Deterministic I/O").
DET="--deterministic${SWEEP_IO_READS:+ --io-reads-per-frame $SWEEP_IO_READS}${SWEEP_IO_LATENCY:+ --io-latency-frames $SWEEP_IO_LATENCY}"
if (( QUICK )); then FRAMES=60; LONG=60; TRACE_FRAMES=120; SOAK=600; fi
mkdir -p "$WORK" "$DATA" "$CHARTS"

# ---- build ------------------------------------------------------------------
scripts/deps.sh
need=()
for t in tiler/clipstream-tile eval/clipstream-fly streamer/clipstream-trace tests/eval/test_eval_stability; do
  [[ -x "$BUILD/$t" ]] || need+=("$(basename "$t")")
done
if [[ ! -f "$BUILD/build.ninja" ]]; then
  cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
fi
echo "sweep: building ${need[*]:-(up to date check)}"
cmake --build "$BUILD" -j "$JOBS" --target clipstream-tile clipstream-fly clipstream-trace test_eval_stability >/dev/null
# The soak also runs under ASan + UBSan: reuse $ASAN_BUILD, configure it if
# missing; building brings it up to date (a no-op when it is).
if (( ! CHARTS_ONLY && ASAN )); then
  if [[ ! -f "$ASAN_BUILD/build.ninja" ]]; then
    cmake -S . -B "$ASAN_BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      -DCLIPSTREAM_SANITIZE=address -DCLIPSTREAM_BUILD_BENCH=OFF >/dev/null
  fi
  echo "sweep: building test_eval_stability under ASan in $ASAN_BUILD (minutes when it is new)"
  cmake --build "$ASAN_BUILD" -j "$JOBS" --target test_eval_stability >/dev/null
fi
FLY=${SWEEP_FLY:-$BUILD/eval/clipstream-fly}
TRACE_TOOL="$BUILD/streamer/clipstream-trace"
STORE="$WORK/autzen.cstore"
if [[ ! -f "$STORE" ]]; then
  "$BUILD/tiler/clipstream-tile" data/autzen.jpg "$STORE" --force >/dev/null
fi
GL=$("$FLY" "$STORE" --frames 1 --size 64x64 --out "$WORK/probe" 2>/dev/null | head -1 | sed 's/.* on //')

# ---- the run list -------------------------------------------------------------
# Motion experiments fly a straight line over a 2^26-texel procedural texture
# (no revisits, so caching cannot hide speed), 200 texels up, looking 30 deg
# down, 100 texels/s at speed x1; 60 warm-up frames at the start position
# are not recorded. Real imagery (autzen) serves the ground-truth, teleport
# and cache-trace runs.
LINE="$WORK/line.json"
cat >"$LINE" <<JSON
{"interpolation": "smooth", "keyframes": [
  {"t": 0, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 90, "pitch_deg": -30},
  {"t": 1000, "x": 33654432, "y": 200, "z": 33554432, "heading_deg": 90, "pitch_deg": -30}]}
JSON
# Snap turns: the line's start, a quarter turn every second (60 frames at
# x1), each a cut (renderer/flight.h, isCut()); time to sharp after each.
TURN="$WORK/turn.json"
cat >"$TURN" <<JSON
{"interpolation": "step", "keyframes": [
  {"t": 0, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 90, "pitch_deg": -30},
  {"t": 1, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 180, "pitch_deg": -30},
  {"t": 2, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 270, "pitch_deg": -30},
  {"t": 3, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 0, "pitch_deg": -30},
  {"t": 4, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 90, "pitch_deg": -30},
  {"t": 5, "x": 33554432, "y": 200, "z": 33554432, "heading_deg": 90, "pitch_deg": -30}]}
JSON
RUNS=()
add() { RUNS+=("$1|$2|$3"); }
# realtime NAME WEIGHT ARGS: the same flight without --deterministic, run
# RT_RUNS times as rt1_NAME, rt2_NAME, ...
realtime() { local k; for ((k = 1; k <= RT_RUNS; k++)); do add "rt${k}_$1" "$2" "$3"; done; }
COMMON="--procedural 67108864 --path $LINE --size $SIZE --io-threads 2 --reference --warmup-frames 60"
# both NAME ARGS: a deterministic run and its real-time repeats.
both() { add "$1" 12 "$COMMON $DET $2"; realtime "$1" 12 "$COMMON $2"; }
# Each speed and upload budget also without throttling: throttling pays
# for itself there (docs/decisions.md D60, D61); and each speed with
# the whole clip window of every needed level (the classic clipmap) beside
# the default sampled scope, as the turns and teleports below.
for s in 1 2 5 10 20 50 100; do
  both "speed_$s" "--frames $FRAMES --speed $s"
  both "nothrottle_speed_$s" "--frames $FRAMES --speed $s --no-throttle"
  add "window_speed_$s" 12 "$COMMON $DET --frames $FRAMES --speed $s --plan-scope window"
done
for u in 1 2 4 8 16 32 64; do
  both "upload_$u" "--frames $FRAMES --speed 20 --upload-tiles $u"
  both "nothrottle_upload_$u" "--frames $FRAMES --speed 20 --upload-tiles $u --no-throttle"
done
TURNS="--procedural 67108864 --path $TURN --size $SIZE --io-threads 2 --reference --warmup-frames 60"
add "turn" 12 "$TURNS $DET --frames $LONG"
add "turn_window" 12 "$TURNS $DET --frames $LONG --plan-scope window"
# BC1 tiles (transcoded by the loaders), judged against the RGBA8 reference:
# compression and streaming error together, beside speed_S's streaming error.
for s in 1 10 100; do
  add "bc1_speed_$s" 12 "$COMMON $DET --frames $FRAMES --speed $s --tile-format bc1 --reference-tile-format rgba8"
done
# Paged texture memory beside the stack (docs/renderer.md, "Paged texture
# memory"): the same deterministic line and turns, each judged against a
# reference drawn the same way.
for s in 1 10 100; do
  add "paged_speed_$s" 12 "$COMMON $DET --frames $FRAMES --speed $s --texture-memory paged"
done
add "turn_paged" 12 "$TURNS $DET --frames $LONG --texture-memory paged"
# Buffering is about frame time: real time only.
add "buffering_single" 12 "$COMMON --frames $LONG --speed 20 --buffering single"
add "buffering_double" 12 "$COMMON --frames $LONG --speed 20 --buffering double-upload"
add "throttle_on" 12 "$COMMON $DET --frames $LONG --speed 50 --upload-tiles 4"
add "throttle_off" 12 "$COMMON $DET --frames $LONG --speed 50 --upload-tiles 4 --no-throttle"
realtime "throttle_on" 12 "$COMMON --frames $LONG --speed 50 --upload-tiles 4"
realtime "throttle_off" 12 "$COMMON --frames $LONG --speed 50 --upload-tiles 4 --no-throttle"
# Slow reads: in real time 20 ms added to each (two loaders: 100 reads/s);
# deterministic, 6 frames (100 ms at 60 frames/s) from request to RAM.
add "prefetch_on" 12 "$COMMON $DET --io-latency-frames 6 --frames $LONG --speed 20"
add "prefetch_off" 12 "$COMMON $DET --io-latency-frames 6 --frames $LONG --speed 20 --no-prefetch"
add "rt1_prefetch_on" 12 "$COMMON --frames $LONG --speed 20 --fault-latency-ms 20"
add "rt1_prefetch_off" 12 "$COMMON --frames $LONG --speed 20 --fault-latency-ms 20 --no-prefetch"
for s in 1 10 100; do
  add "frustum_on_$s" 12 "$COMMON $DET --frames $FRAMES --speed $s --cache-mb 16"
  add "frustum_off_$s" 12 "$COMMON $DET --frames $FRAMES --speed $s --cache-mb 16 --no-frustum-priority"
done
AUTZEN="$STORE --size $SIZE --io-threads 2 --reference --warmup-frames 60"
add "ground_truth" 20 "$AUTZEN $DET --path orbit --loop --frames $FRAMES --speed 5 --ground-truth-every 10"
add "teleport" 12 "$AUTZEN $DET --path teleport --teleport-frames 30 --frames $FRAMES --rest-frames 60"
add "teleport_window" 12 "$AUTZEN $DET --path teleport --teleport-frames 30 --frames $FRAMES --rest-frames 60 --plan-scope window"
add "trace" 8 "$STORE --size $SIZE --io-threads 2 $DET --path orbit --loop --speed 5 --frames $TRACE_FRAMES --trace $WORK/orbit.trace"
# Weights are about 0.75 s each on 2 cores; the soak at 1280x720 costs
# about 17 ms a frame in the release build and 24 ms under ASan (most of it
# llvmpipe drawing).
STAB_WEIGHT=$(( 50 + SOAK * 17 / 750 ))
ASAN_WEIGHT=$(( SOAK * 24 / 750 ))

(( ASAN )) || ASAN_WEIGHT=0
total_weight=$((STAB_WEIGHT + ASAN_WEIGHT))
for r in "${RUNS[@]}"; do IFS='|' read -r _ w _ <<<"$r"; total_weight=$((total_weight + w)); done
runs_total=$(( ${#RUNS[@]} + 2 ))
start=$(date +%s)
done_weight=0
progress() {  # $1 = runs done, $2 = label
  local now elapsed pct eta bar
  now=$(date +%s); elapsed=$((now - start))
  pct=$(( 100 * done_weight / total_weight ))
  if (( done_weight > 0 )); then eta=$(( elapsed * (total_weight - done_weight) / done_weight )); else eta=0; fi
  bar=$(printf '%*s' $((pct / 4)) '' | tr ' ' '#')
  printf '\r[%-25s] %3d%%  %2d/%d runs  %3ds elapsed  ETA %3ds  %-24s' "$bar" "$pct" "$1" "$runs_total" \
    "$elapsed" "$eta" "$2"
}

i=0
(( CHARTS_ONLY )) && RUN_LIST=() || RUN_LIST=("${RUNS[@]}")
for r in "${RUN_LIST[@]+"${RUN_LIST[@]}"}"; do
  IFS='|' read -r name w args <<<"$r"
  # The stack unless a run says otherwise: clipstream-fly's own default
  # (auto) would page the flat plane, and the stack is what these rows
  # have always measured.
  [[ $args == *--texture-memory* ]] || args="$args --texture-memory stack"
  progress "$i" "$name"
  rm -rf "${WORK:?}/$name"
  # shellcheck disable=SC2086
  if ! "$FLY" $args --save-frames 0 --out "$WORK/$name" >"$WORK/$name.log" 2>&1; then
    echo; echo "sweep: run $name failed, see $WORK/$name.log"; tail -5 "$WORK/$name.log"; exit 1
  fi
  echo "$FLY $args --save-frames 0 --out $WORK/$name" >"$WORK/$name.cmd"
  i=$((i + 1)); done_weight=$((done_weight + w))
done
STAB_CMD="CLIPSTREAM_STABILITY_OUT=$WORK/stability.jsonl CLIPSTREAM_SOAK=full CLIPSTREAM_SOAK_FRAMES=$SOAK $BUILD/tests/eval/test_eval_stability --gtest_filter=Stability.*"
# The soak once more under ASan + UBSan: LeakSanitizer checks at exit, with
# the driver kept mapped (tests/renderer/lsan_keep_gl_driver.cpp) and
# tests/lsan.supp; any report makes the process fail (docs/accuracy.md).
ASAN_ENV=(ASAN_OPTIONS="detect_leaks=1 halt_on_error=1" LSAN_OPTIONS="suppressions=$PWD/tests/lsan.supp"
          UBSAN_OPTIONS="halt_on_error=1 print_stacktrace=1")
ASAN_SOAK_CMD="ASAN_OPTIONS='detect_leaks=1 halt_on_error=1' LSAN_OPTIONS=suppressions=tests/lsan.supp UBSAN_OPTIONS='halt_on_error=1 print_stacktrace=1' CLIPSTREAM_STABILITY_OUT=$WORK/soak_asan.jsonl CLIPSTREAM_SOAK=full CLIPSTREAM_SOAK_FRAMES=$SOAK $ASAN_BUILD/tests/eval/test_eval_stability --gtest_filter=Stability.SoakKeepsRssFlatAndTheBudget"
if (( ! CHARTS_ONLY )); then
progress "$i" "stability scenarios"
rm -f "$WORK/stability.jsonl"
if ! env CLIPSTREAM_STABILITY_OUT="$WORK/stability.jsonl" CLIPSTREAM_SOAK=full CLIPSTREAM_SOAK_FRAMES=$SOAK \
    "$BUILD/tests/eval/test_eval_stability" --gtest_filter='Stability.*' >"$WORK/stability.log" 2>&1; then
  echo; echo "sweep: a stability scenario failed (see $WORK/stability.log); its row says FAIL"
fi
done_weight=$((done_weight + STAB_WEIGHT))
progress "$((i + 1))" "soak under ASan"
rm -f "$WORK/soak_asan.jsonl"
if (( ! ASAN )); then
  echo "skipped" >"$WORK/soak_asan.rc"; : >"$WORK/soak_asan.log"
elif ! env "${ASAN_ENV[@]}" CLIPSTREAM_STABILITY_OUT="$WORK/soak_asan.jsonl" CLIPSTREAM_SOAK=full \
    CLIPSTREAM_SOAK_FRAMES=$SOAK "$ASAN_BUILD/tests/eval/test_eval_stability" \
    --gtest_filter=Stability.SoakKeepsRssFlatAndTheBudget >"$WORK/soak_asan.log" 2>&1; then
  echo "1" >"$WORK/soak_asan.rc"
  echo; echo "sweep: the soak under ASan failed or reported (see $WORK/soak_asan.log); its row says FAIL"
else
  echo "0" >"$WORK/soak_asan.rc"
fi
fi
done_weight=$total_weight
progress "$runs_total" "done"
echo

# ---- data --------------------------------------------------------------------
# field FILE NAME: a value from a run's summary.tsv by column name.
# Outputs follow the programs' rule (docs/cli.md): each is written under
# NAME.tmp.PID and renamed by publish NAME when whole; an interrupted or
# failed sweep removes its temporaries and leaves the previous outputs.
publish() { mv -f "$1.tmp.$$" "$1"; }
cleanup_temporaries() { rm -f "$DATA"/*.tmp.$$ "$CHARTS"/*.tmp.$$ "$DOCS"/*.tmp.$$; }
trap cleanup_temporaries EXIT
trap 'exit 130' INT; trap 'exit 143' TERM; trap 'exit 129' HUP
field() { awk -F'\t' -v k="$2" 'NR==1{for(i=1;i<=NF;i++)if($i==k)c=i} NR==2{print $c}' "$1"; }
# column DIR NAME...: per-frame columns of a run's frames.csv by name.
column() {
  local dir=$1; shift
  awk -F, -v names="$*" 'BEGIN{n=split(names,want," ")}
    NR==1{for(i=1;i<=NF;i++)idx[$i]=i; next}
    {line=""; for(j=1;j<=n;j++){v=$(idx[want[j]]); line=line (j>1?",":"") v}; print line}' "$dir/frames.csv"
}
S() { field "$WORK/$1/summary.tsv" "$2"; }
# R NAME KEY: "lo,hi" of KEY over the real-time repeats rt1_NAME .. rtK_NAME.
R() {
  local k
  for ((k = 1; k <= RT_RUNS; k++)); do S "rt${k}_$1" "$2"; done |
    awk 'NR==1{lo=$1; hi=$1} {if($1<lo)lo=$1; if($1>hi)hi=$1} END{printf "%s,%s", lo, hi}'
}

{
  echo "speed,psnr_mean_db,psnr_min_db,frames_below_30db,over_fetch_ratio,ram_hit_rate,rt_psnr_mean_db_lo,rt_psnr_mean_db_hi,rt_psnr_min_db_lo,rt_psnr_min_db_hi,rt_frame_ms_p99_lo,rt_frame_ms_p99_hi"
  for s in 1 2 5 10 20 50 100; do
    echo "$s,$(S speed_$s psnr_mean_db),$(S speed_$s psnr_min_db),$(S speed_$s frames_below_30db),$(S speed_$s over_fetch_ratio),$(S speed_$s ram_hit_rate),$(R speed_$s psnr_mean_db),$(R speed_$s psnr_min_db),$(R speed_$s frame_ms_p99)"
  done
} >"$DATA/psnr_vs_speed.csv.tmp.$$"
publish "$DATA/psnr_vs_speed.csv"
{
  echo "upload_tiles,psnr_mean_db,psnr_min_db,rt_psnr_mean_db_lo,rt_psnr_mean_db_hi,rt_frame_ms_p50_lo,rt_frame_ms_p50_hi,rt_frame_ms_p99_lo,rt_frame_ms_p99_hi,rt_frame_ms_max_lo,rt_frame_ms_max_hi"
  for u in 1 2 4 8 16 32 64; do
    echo "$u,$(S upload_$u psnr_mean_db),$(S upload_$u psnr_min_db),$(R upload_$u psnr_mean_db),$(R upload_$u frame_ms_p50),$(R upload_$u frame_ms_p99),$(R upload_$u frame_ms_max)"
  done
} >"$DATA/upload_budget.csv.tmp.$$"
publish "$DATA/upload_budget.csv"
{
  echo "speed,psnr_mean_rgba8,psnr_mean_bc1,psnr_min_bc1,frame_ms_p50_rgba8,frame_ms_p50_bc1,upload_ms_per_tile_rgba8,upload_ms_per_tile_bc1,decode_ms_per_tile_rgba8,decode_ms_per_tile_bc1,gpu_texture_mib_rgba8,gpu_texture_mib_bc1"
  for s in 1 10 100; do
    line="$s"
    for k in psnr_mean_db; do line="$line,$(S speed_$s $k),$(S bc1_speed_$s $k)"; done
    line="$line,$(S bc1_speed_$s psnr_min_db)"
    for k in frame_ms_p50 upload_ms_per_tile decode_ms_per_tile gpu_texture_mib; do
      line="$line,$(S speed_$s $k),$(S bc1_speed_$s $k)"
    done
    echo "$line"
  done
} >"$DATA/bc1.csv.tmp.$$"
publish "$DATA/bc1.csv"
{
  echo "run,psnr_mean_stack,psnr_mean_paged,psnr_min_stack,psnr_min_paged,frames_below_30db_stack,frames_below_30db_paged,time_to_sharp_max_stack,time_to_sharp_max_paged,frame_ms_p50_stack,frame_ms_p50_paged,gpu_texture_mib_stack,gpu_texture_mib_paged,frames_pages_short,pool_pages_wanted_max"
  for pair in "speed_1 paged_speed_1" "speed_10 paged_speed_10" "speed_100 paged_speed_100" "turn turn_paged"; do
    read -r a b <<<"$pair"
    line="$a"
    for k in psnr_mean_db psnr_min_db frames_below_30db time_to_sharp_max frame_ms_p50 gpu_texture_mib; do
      line="$line,$(S "$a" $k),$(S "$b" $k)"
    done
    echo "$line,$(S "$b" frames_pages_short),$(S "$b" pool_pages_wanted_max)"
  done
} >"$DATA/paged.csv.tmp.$$"
publish "$DATA/paged.csv"
{
  echo "budget_mib,opt_pct,lru_pct,ours_pct"
  for b in 1 2 4 8 16 32 64 128; do
    "$TRACE_TOOL" "$WORK/orbit.trace" --budget-mb "$b" >"$WORK/trace_$b.txt"
    awk -F'\t' -v b="$b" '$1=="opt"{o=$3} $1=="lru"{l=$3} $1=="ours"{u=$3} END{print b","o","l","u}' "$WORK/trace_$b.txt"
  done
} >"$DATA/cache_hitrate.csv.tmp.$$"
publish "$DATA/cache_hitrate.csv"
pair() {  # OUT A B TA TB: frame, A_frame_ms (from run TA), A_psnr_db, B_frame_ms (TB), B_psnr_db
  local out=$1 a=$2 b=$3 ta=$4 tb=$5
  {
    echo "frame,${a}_frame_ms,${a}_psnr_db,${b}_frame_ms,${b}_psnr_db"
    paste -d, <(column "$WORK/$ta" frame frame_ms) <(column "$WORK/$a" psnr_db) \
      <(column "$WORK/$tb" frame_ms) <(column "$WORK/$b" psnr_db)
  } >"$out.tmp.$$"
  publish "$out"
}
# Frame times from real-time runs (a deterministic frame also waits for its
# due reads), PSNR from the deterministic ones where there are.
pair "$DATA/frametime_buffering.csv" buffering_single buffering_double buffering_single buffering_double
pair "$DATA/frametime_throttle.csv" throttle_on throttle_off rt1_throttle_on rt1_throttle_off
pair "$DATA/frametime_prefetch.csv" prefetch_on prefetch_off rt1_prefetch_on rt1_prefetch_off
{
  echo "run,psnr_mean_db,psnr_min_db,frames_below_30db,rt_psnr_mean_db_lo,rt_psnr_mean_db_hi,rt_frames_below_30db_lo,rt_frames_below_30db_hi"
  for n in throttle_on throttle_off; do
    echo "$n,$(S $n psnr_mean_db),$(S $n psnr_min_db),$(S $n frames_below_30db),$(R $n psnr_mean_db),$(R $n frames_below_30db)"
  done
  for n in prefetch_on prefetch_off; do
    echo "$n,$(S $n psnr_mean_db),$(S $n psnr_min_db),$(S $n frames_below_30db),$(S rt1_$n psnr_mean_db),$(S rt1_$n psnr_mean_db),$(S rt1_$n frames_below_30db),$(S rt1_$n frames_below_30db)"
  done
} >"$DATA/throttle_prefetch.csv.tmp.$$"
publish "$DATA/throttle_prefetch.csv"
# Throttling on and off at every speed (default upload budget) and every
# upload budget (x20): accuracy from the deterministic runs, p99 frame time
# from the real-time ones (range of the repeats).
{
  echo "flight,psnr_mean_on,psnr_mean_off,frames_below_30db_on,frames_below_30db_off,rt_frame_ms_p99_on_lo,rt_frame_ms_p99_on_hi,rt_frame_ms_p99_off_lo,rt_frame_ms_p99_off_hi,tiles_loaded_on,tiles_loaded_off"
  row() {  # LABEL ON OFF
    echo "$1,$(S "$2" psnr_mean_db),$(S "$3" psnr_mean_db),$(S "$2" frames_below_30db),$(S "$3" frames_below_30db),$(R "$2" frame_ms_p99),$(R "$3" frame_ms_p99),$(S "$2" tiles_loaded),$(S "$3" tiles_loaded)"
  }
  for s in 1 2 5 10 20 50 100; do row "speed x$s" "speed_$s" "nothrottle_speed_$s"; done
  for u in 1 2 4 8 16 32 64; do row "x20 upload $u" "upload_$u" "nothrottle_upload_$u"; done
  row "x50 upload 4" throttle_on throttle_off
} >"$DATA/throttle.csv.tmp.$$"
publish "$DATA/throttle.csv"
# Over-fetch without the pyramid (clip levels' loads / their sampled tiles),
# PSNR and RAM hit rate: the sampled scope (the default) against the whole
# window, the same flights.
{
  echo "speed,over_fetch_sampled,over_fetch_window,psnr_mean_sampled,psnr_mean_window,ram_hit_rate_sampled,ram_hit_rate_window,tiles_loaded_stack_sampled,tiles_loaded_stack_window,tiles_sampled_stack"
  for s in 1 2 5 10 20 50 100; do
    echo "$s,$(S speed_$s over_fetch_stack_ratio),$(S window_speed_$s over_fetch_stack_ratio),$(S speed_$s psnr_mean_db),$(S window_speed_$s psnr_mean_db),$(S speed_$s ram_hit_rate),$(S window_speed_$s ram_hit_rate),$(S speed_$s tiles_loaded_stack),$(S window_speed_$s tiles_loaded_stack),$(S speed_$s tiles_sampled_stack)"
  done
} >"$DATA/plan_scope.csv.tmp.$$"
publish "$DATA/plan_scope.csv"
{
  echo "run,plan_scope,psnr_mean_db,psnr_min_db,frames_below_30db,time_to_sharp_mean,time_to_sharp_max,over_fetch_stack_ratio,tiles_loaded"
  for n in turn turn_window teleport teleport_window; do
    scope=sampled; [[ $n == *_window ]] && scope=window
    echo "$n,$scope,$(S $n psnr_mean_db),$(S $n psnr_min_db),$(S $n frames_below_30db),$(S $n time_to_sharp_mean),$(S $n time_to_sharp_max),$(S $n over_fetch_stack_ratio),$(S $n tiles_loaded)"
  done
} >"$DATA/cuts.csv.tmp.$$"
publish "$DATA/cuts.csv"
{
  echo "speed,over_fetch_on,over_fetch_off,psnr_mean_on,psnr_mean_off,tiles_loaded_on,tiles_loaded_off,tiles_sampled"
  for s in 1 10 100; do
    echo "$s,$(S frustum_on_$s over_fetch_ratio),$(S frustum_off_$s over_fetch_ratio),$(S frustum_on_$s psnr_mean_db),$(S frustum_off_$s psnr_mean_db),$(S frustum_on_$s tiles_loaded),$(S frustum_off_$s tiles_loaded),$(S frustum_on_$s tiles_sampled)"
  done
} >"$DATA/overfetch.csv.tmp.$$"
publish "$DATA/overfetch.csv"
{
  echo "run,io_mode,frames,psnr_mean_db,psnr_min_db,frames_below_30db,time_to_sharp_mean,time_to_sharp_max,frame_ms_p50,frame_ms_p99,frame_ms_max,bytes_read,tiles_uploaded,tiles_loaded,ram_hit_rate,gpu_hit_rate,peak_rss_mib,over_fetch_ratio,over_fetch_stack_ratio,ground_truth_psnr_mean_db"
  for r in "${RUNS[@]}"; do
    IFS='|' read -r name _ _ <<<"$r"
    [[ "$name" == trace ]] && continue
    line="$name"
    for k in io_mode frames psnr_mean_db psnr_min_db frames_below_30db time_to_sharp_mean time_to_sharp_max frame_ms_p50 frame_ms_p99 frame_ms_max bytes_read tiles_uploaded tiles_loaded ram_hit_rate gpu_hit_rate peak_rss_mib over_fetch_ratio over_fetch_stack_ratio ground_truth_psnr_mean_db; do
      line="$line,$(S "$name" "$k")"
    done
    echo "$line"
  done
} >"$DATA/runs.csv.tmp.$$"
publish "$DATA/runs.csv"
# Stability: one JSON line per scenario -> CSV (no jq needed: fixed keys).
jget() { sed -n "s/.*\"$2\":\([^,}]*\).*/\1/p" <<<"$1" | tr -d '"'; }
{
  echo "scenario,frames,psnr_min_db,psnr_mean_db,time_to_sharp_max,rest_frames_to_identical,frame_ms_p99,ram_peak_mib,ram_budget_mib,render_thread_fetches,result"
  while IFS= read -r l; do
    printf '%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s\n' "$(jget "$l" scenario)" "$(jget "$l" frames)" \
      "$(jget "$l" psnr_min_db)" "$(jget "$l" psnr_mean_db)" "$(jget "$l" time_to_sharp_max)" \
      "$(jget "$l" rest_frames_to_identical)" "$(jget "$l" frame_ms_p99)" \
      "$(awk -v b="$(jget "$l" ram_peak_bytes)" 'BEGIN{printf "%.1f", b/1048576}')" \
      "$(awk -v b="$(jget "$l" ram_budget_bytes)" 'BEGIN{printf "%.1f", b/1048576}')" \
      "$(jget "$l" render_thread_fetches)" "$(jget "$l" result)"
  done <"$WORK/stability.jsonl"
} >"$DATA/stability.csv.tmp.$$"
publish "$DATA/stability.csv"
# Soak: the release run (RSS, budget) and the ASan + UBSan run (leaks).
soak_row() {  # NAME JSONL LOG SANITIZED
  local l loaded leaks bytes suppressed reports result
  l=$(grep '"scenario":"soak (default settings)"' "$2" 2>/dev/null | tail -1 || true)
  loaded=$(sed -n 's/.* inserts, \([0-9.]*\) MiB loaded.*/\1/p' "$3" | tail -1)
  result=$(jget "$l" result)
  if (( $4 )) && [[ "$(cat "$WORK/soak_asan.rc" 2>/dev/null)" == skipped ]]; then
    leaks="not run"; bytes=""; suppressed=""; reports=""; result="not run (SWEEP_ASAN=0)"
  elif (( $4 )); then
    leaks=$(grep -cE '^(Direct|Indirect) leak of' "$3" || true)
    bytes=$(sed -n 's/^SUMMARY: AddressSanitizer: \([0-9]*\) byte(s) leaked.*/\1/p' "$3" | tail -1)
    bytes=${bytes:-0}
    suppressed=$(awk '/^Suppressions used:/{on=1; next} on && $1 ~ /^[0-9]+$/ {n += $1} END{print n+0}' "$3")
    reports=$(grep -cE 'runtime error:|ERROR: AddressSanitizer' "$3" || true)
    [[ "$(cat "$WORK/soak_asan.rc" 2>/dev/null)" == 0 && $leaks == 0 && $reports == 0 ]] || result=FAIL
  else
    leaks="not checked"; bytes=""; suppressed=""; reports=""
  fi
  printf '%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s\n' "$1" "$(jget "$l" frames)" \
    "$(awk -v b="$(jget "$l" ram_peak_bytes)" 'BEGIN{printf "%.1f", b/1048576}')" \
    "$(awk -v b="$(jget "$l" ram_budget_bytes)" 'BEGIN{printf "%.1f", b/1048576}')" "$loaded" \
    "$(awk -v b="$(jget "$l" rss_after_warmup_bytes)" 'BEGIN{printf "%.1f", b/1048576}')" \
    "$(awk -v b="$(jget "$l" rss_end_bytes)" 'BEGIN{printf "%.1f", b/1048576}')" \
    "$leaks" "$bytes" "$suppressed" "$reports" "${result:-FAIL}"
}
{
  echo "build,frames,ram_peak_mib,ram_budget_mib,loaded_mib,rss_after_quarter_mib,rss_end_mib,leaks_reported,leaked_bytes,suppressed_allocations,sanitizer_reports,result"
  soak_row release "$WORK/stability.jsonl" "$WORK/stability.log" 0
  soak_row asan+ubsan "$WORK/soak_asan.jsonl" "$WORK/soak_asan.log" 1
} >"$DATA/soak.csv.tmp.$$"
publish "$DATA/soak.csv"

# ---- charts ------------------------------------------------------------------
if gnuplot -e 'set terminal' 2>&1 | grep -q pngcairo; then TERM_LINE="pngcairo size 800,480 font 'sans,10'"
else TERM_LINE="png size 800,480"; fi
plot() {  # name, gnuplot body
  gnuplot <<EOF
set terminal $TERM_LINE
set output '$CHARTS/$1.png.tmp.$$'
set datafile separator ','
set key top right
set grid
$2
EOF
  publish "$CHARTS/$1.png"
}
plot psnr_vs_speed "
set title 'PSNR against the ideal reference vs camera speed (straight line over 2^{26} texels, default budgets)'
set logscale x; set xlabel 'camera speed (x path speed)'; set ylabel 'PSNR, dB (99 = identical)'
set yrange [0:100]; set key bottom left
plot '$DATA/psnr_vs_speed.csv' u 1:2 skip 1 w lp lw 2 t 'mean PSNR (deterministic)', '' u 1:3 skip 1 w lp lw 2 t 'min PSNR (deterministic)', \\
     '' u 1:((\$7+\$8)/2):7:8 skip 1 w yerrorbars lw 2 t 'mean PSNR, real time: range of $RT_RUNS runs', \\
     '$DATA/bc1.csv' u 1:3 skip 1 w lp lw 2 t 'BC1 mean PSNR (against RGBA8, deterministic)', 30 w l dt 2 t '30 dB'"
plot upload_budget "
set title 'PSNR and p99 frame time vs per-frame upload budget (straight line, speed x20)'
set logscale x 2; set xlabel 'tiles uploaded per frame'; set ylabel 'PSNR, dB'; set y2label 'p99 frame time, ms'
set ytics nomirror; set y2tics; set y2range [0:*]; set key bottom right
plot '$DATA/upload_budget.csv' u 1:2 skip 1 w lp lw 2 t 'mean PSNR (deterministic)', '' u 1:3 skip 1 w lp lw 2 t 'min PSNR (deterministic)', \\
     '' u 1:((\$4+\$5)/2):4:5 skip 1 w yerrorbars lw 2 t 'mean PSNR, real time: range of $RT_RUNS runs', \\
     '' u 1:9 skip 1 axes x1y2 w lp lw 2 t 'p99 frame ms, real time, worst run (right)'"
plot cache_hitrate "
set title 'RAM hit rate vs cache size (orbit trace replayed)'
set logscale x 2; set xlabel 'RAM budget, MiB'; set ylabel 'hit rate, %'; set yrange [0:100]; set key bottom right
plot '$DATA/cache_hitrate.csv' u 1:2 skip 1 w lp lw 2 t 'OPT (Belady)', '' u 1:3 skip 1 w lp lw 2 t 'LRU', '' u 1:4 skip 1 w lp lw 2 t 'ours'"
for pair_name in buffering:single:double throttle:on:off prefetch:on:off; do
  IFS=: read -r n a b <<<"$pair_name"
  plot "frametime_$n" "
set multiplot layout 2,1 title 'Frame time and PSNR: $n $a vs $b'
set ylabel 'frame ms'; unset xlabel
plot '$DATA/frametime_$n.csv' u 1:2 skip 1 w l t '$n $a', '' u 1:4 skip 1 w l t '$n $b'
set ylabel 'PSNR, dB'; set xlabel 'frame'; set yrange [0:100]
plot '$DATA/frametime_$n.csv' u 1:3 skip 1 w l t '$n $a', '' u 1:5 skip 1 w l t '$n $b'
unset multiplot"
done
plot throttle "
set multiplot layout 1,2 title 'Throttling on and off: mean PSNR (deterministic) by flight'
set style data histograms; set style histogram clustered gap 1; set style fill solid 0.6 border -1
set ylabel 'mean PSNR, dB'; set yrange [0:100]; set xtics rotate by -45 font ',8'; set key bottom left
plot '$DATA/throttle.csv' u 2:xtic(1) skip 1 t 'throttle on', '' u 3 skip 1 t 'off'
set ylabel 'p99 frame ms, real time (worst run)'; set yrange [0:*]
plot '$DATA/throttle.csv' u 7:xtic(1) skip 1 t 'throttle on', '' u 9 skip 1 t 'off'
unset multiplot"
plot plan_scope "
set multiplot layout 1,2 title 'Loading what the frames sample: sampled scope against the whole window'
set logscale x; set xlabel 'camera speed'; set ylabel 'over-fetch (clip levels: loaded / sampled)'; set yrange [0:*]
plot '$DATA/plan_scope.csv' u 1:2 skip 1 w lp lw 2 t 'sampled (default)', '' u 1:3 skip 1 w lp lw 2 t 'window', 2 w l dt 2 t '2x'
unset logscale x; set xlabel 'over-fetch'; set ylabel 'mean PSNR, dB / RAM hit rate x 100'; set yrange [0:100]; set key bottom right
plot '$DATA/plan_scope.csv' u 2:4 skip 1 w p pt 7 ps 1.5 t 'PSNR, sampled', '' u 3:5 skip 1 w p pt 5 ps 1.5 t 'PSNR, window', \
     '' u 2:(100*\$6) skip 1 w p pt 6 ps 1.5 t 'hit rate, sampled', '' u 3:(100*\$7) skip 1 w p pt 4 ps 1.5 t 'hit rate, window'
unset multiplot"
plot overfetch "
set title 'Over-fetch (tiles loaded / tiles sampled) with and without frustum-aware priorities'
set logscale x; set xlabel 'camera speed'; set ylabel 'over-fetch ratio'; set yrange [0:*]
plot '$DATA/overfetch.csv' u 1:2 skip 1 w lp lw 2 t 'frustum priority on', '' u 1:3 skip 1 w lp lw 2 t 'frustum priority off'"

# ---- docs/benchmarks.md -----------------------------------------------------------
# What the page says of this sweep (its set-up and the command of each table)
# goes to two key-value tables beside the data; scripts/gen_benchmarks.sh
# renders the page from docs/benchmarks.md.in and them. The tables of
# another folder ($SWEEP_DOCS) come first, docs/data/ fills in the rest.
{
  printf 'key\tvalue\n'
  printf 'cores\t%s\n' "$(nproc)"
  printf 'gl\t%s\n' "${GL:-unknown GL}"
  printf 'size\t%s\n' "$SIZE"
  printf 'deterministic\t%s\n' "$DET"
  printf 'realtime_runs\t%s\n' "$RT_RUNS"
  printf 'line\t%s\n' "$LINE"
  printf 'turn\t%s\n' "$TURN"
  printf 'store\t%s\n' "$STORE"
  printf 'work\t%s\n' "$WORK"
  printf 'soak_frames\t%s\n' "$SOAK"
} >"$DATA/sweep_setup.tsv.tmp.$$"
publish "$DATA/sweep_setup.tsv"
{
  printf 'use\tcommand\n'
  printf 'speed\t%s\n' "$(sed "s/--speed 10/--speed S/; s#$WORK/speed_10#DIR#" "$WORK/speed_10.cmd")"
  printf 'bc1_speed\t%s\n' "$(sed "s/--speed 10/--speed S/; s#$WORK/bc1_speed_10#DIR#" "$WORK/bc1_speed_10.cmd")"
  printf 'upload\t%s\n' "$(sed "s/--upload-tiles 16/--upload-tiles T/; s#$WORK/upload_16#DIR#" "$WORK/upload_16.cmd")"
  printf 'trace\t%s\n' "$(cat "$WORK/trace.cmd")"
  printf 'trace_replay\t%s\n' "$TRACE_TOOL $WORK/orbit.trace --budget-mb B"
  for n in buffering throttle prefetch; do
    for f in "$WORK/${n}"_*.cmd "$WORK/rt1_${n}"_*.cmd; do [[ -f "$f" ]] && printf '%s\t%s\n' "$n" "$(cat "$f")"; done
  done
  for n in turn turn_window teleport teleport_window; do printf 'cuts\t%s\n' "$(cat "$WORK/$n.cmd")"; done
  for f in "$WORK"/frustum_*_10.cmd; do printf 'frustum\t%s\n' "$(cat "$f")"; done
  printf 'stability\t%s\n' "$STAB_CMD"
  printf 'soak_asan\t%s\n' "$ASAN_SOAK_CMD"
} >"$DATA/sweep_commands.tsv.tmp.$$"
publish "$DATA/sweep_commands.tsv"
BM=$DOCS/benchmarks.md
scripts/gen_benchmarks.sh --data "$DATA" --data docs/data --out "$BM" >/dev/null
echo "sweep: wrote $DATA/*.csv, $CHARTS/*.png and $BM in $(( $(date +%s) - start ))s"

# The terrain methods side by side (docs/terrain.md); SWEEP_TERRAIN=0 skips them.
if [[ ${SWEEP_TERRAIN:-1} != 0 ]] && (( ! CHARTS_ONLY )); then
  if (( QUICK )); then bash scripts/sweep_terrain.sh --quick; else bash scripts/sweep_terrain.sh; fi
fi

# Texture memory side by side at four viewports, and the pool's size
# (docs/renderer.md, "Paged texture memory"); SWEEP_PAGED=0 skips it.
if [[ ${SWEEP_PAGED:-1} != 0 ]] && (( ! CHARTS_ONLY )); then
  if (( QUICK )); then bash scripts/sweep_paged.sh --quick; else bash scripts/sweep_paged.sh; fi
fi
