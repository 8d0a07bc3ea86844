#!/usr/bin/env bash
# Over-fetch over terrain: the default plan (height bounds, loading the
# tiles under the ground the last frame showed, --plan-scope sampled)
# against the whole clip windows (--plan-scope window) and against the
# plane under the camera with the resident heights' relief
# (--no-terrain-bounds, the ground seen), on the same flights:
#  - orbit:        the demo scene (the bundled orthophoto over the bundled
#                  St Helens DEM, stretched, half height), built-in orbit;
#  - valley:       the same scene, the low valley path;
#  - mountainside: Mount Rainier (../shared/data/mt_rainier_90m.tif, SRTM)
#                  stretched under a 65536^2 procedural texture, a path at
#                  600 units above the ground towards and along its slopes,
#                  looking level or a little up at them.
# Per run: colour tiles loaded (pyramid included), colour tiles sampled
# (from the frames' ground points), the over-fetch ratio, the same for the
# clip levels alone (without the coarse pyramid, loaded whole once), the
# judged frames' mean PSNR against the full-resolution mesh with the ideal
# texture and the frames below 30 dB, the frames whose plan needed a level
# coarser / finer than the nearest ground shown asks for, and the
# streamer's and the whole frame's mean time (the sampled scope's depth
# read-back is in the frame).
# Usage: scripts/bench_terrain_planning.sh [WIDTHxHEIGHT] (default 1280x720).
# Needs a built build/. Prints a Markdown table (docs/benchmarks.md).
set -euo pipefail
cd "$(dirname "$0")/.."
size=${1:-1280x720}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
build/tiler/clipstream-tile data/autzen.jpg "$work/autzen.cstore" --quiet --no-fsync
build/tiler/clipstream-tile data/mount_st_helens_30m.tif "$work/helens.cstore" --quiet --no-fsync
rainier=../shared/data/mt_rainier_90m.tif
[ -f "$rainier" ] && build/tiler/clipstream-tile "$rainier" "$work/rainier.cstore" --quiet --no-fsync
cat > "$work/mountainside.json" <<'EOF'
{"keyframes": [
 {"t": 0,  "x": 15750, "y": 600, "z": 42000, "heading_deg": 0,   "pitch_deg": 2},
 {"t": 10, "x": 15750, "y": 600, "z": 24000, "heading_deg": 0,   "pitch_deg": 4},
 {"t": 16, "x": 9000,  "y": 600, "z": 17000, "heading_deg": 60,  "pitch_deg": 2},
 {"t": 24, "x": 22000, "y": 600, "z": 16000, "heading_deg": 0,   "pitch_deg": 4},
 {"t": 30, "x": 26000, "y": 900, "z": 9000,  "heading_deg": -90, "pitch_deg": -2}
]}
EOF
value() { awk -F'\t' -v k="$2" 'NR==1{for(i=1;i<=NF;i++) c[$i]=i} NR==2{print $(c[k])}' "$1/summary.tsv"; }
json() { grep -o "\"$2\": *[0-9.e+-]*" "$1/frames.json" | tail -1 | sed 's/.*: *//'; }
column_mean() {
  awk -F, -v k="$2" 'NR==1{for(i=1;i<=NF;i++) if($i==k) c=i; next} {s+=$c; n++} END{printf "%.2f", s/n}' "$1/frames.csv"
}
echo "| flight | plan | colour tiles loaded | tiles sampled | over-fetch | clip levels: loaded / sampled = over-fetch | PSNR mean dB (frames < 30 dB) | frames planned coarser / finer than seen | streamer / frame ms |"
echo "|---|---|---:|---:|---:|---:|---:|---:|---:|"
fly() {  # name, then clipstream-fly arguments
  local name=$1
  shift
  for planner in sampled window relief; do
    local flag=() label
    case $planner in
      sampled) label="height bounds, ground seen"; flag=(--plan-scope sampled) ;;
      window) label="height bounds, whole windows"; flag=(--plan-scope window) ;;
      relief) label="relief planes, ground seen"; flag=(--no-terrain-bounds) ;;
    esac
    build/eval/clipstream-fly "$@" "${flag[@]}" --size "$size" --reference --reference-every 30 \
      --save-frames 0 --out "$work/run" >/dev/null 2>&1
    local sampled ratio
    sampled=$(value "$work/run" tiles_sampled)
    ratio=$(value "$work/run" over_fetch_ratio)
    local loads
    loads=$(awk -v r="$ratio" -v s="$sampled" 'BEGIN{printf "%.0f", r * s}')
    printf '| %s | %s | %s | %s | %.2f | %s / %s = %.2f | %.2f (%s) | %s / %s | %s / %s |\n' "$name" "$label" "$loads" \
      "$sampled" "$ratio" "$(value "$work/run" tiles_loaded_stack)" "$(value "$work/run" tiles_sampled_stack)" \
      "$(value "$work/run" over_fetch_stack_ratio)" "$(value "$work/run" psnr_mean_db)" \
      "$(value "$work/run" frames_below_30db)" \
      "$(value "$work/run" needed_coarser_frames)" "$(value "$work/run" needed_finer_frames)" \
      "$(column_mean "$work/run" streamer_ms)" "$(column_mean "$work/run" frame_ms)"
  done
}
scene=("$work/autzen.cstore" --elevation "$work/helens.cstore" --stretch-elevation --vertical-scale 0.5)
fly "orbit (St Helens, 120 frames)" "${scene[@]}" --path orbit --frames 120
fly "valley (St Helens, 240 frames)" "${scene[@]}" --path valley --frames 240 --speed 4
if [ -f "$work/rainier.cstore" ]; then
  fly "mountainside (Rainier, 180 frames)" --procedural 65536 --elevation "$work/rainier.cstore" \
    --stretch-elevation --path "$work/mountainside.json" --frames 180 --speed 10
fi
