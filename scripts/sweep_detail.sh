#!/usr/bin/env bash
# Detail beyond the data (docs/terrain.md, issue #34): per-pixel lighting
# against the vertices' lighting over the terrain sweep's scenes
# (scripts/terrain_scenes.sh), as the triangles vary (clipmap ring, quadtree
# bound), every run judged against one reference: the full-resolution mesh
# with the ideal texture, lit per pixel from the full-resolution heights.
#
#   bash scripts/sweep_detail.sh               # about 15 minutes on 2 cores
#   bash scripts/sweep_detail.sh --charts-only # redraw from docs/data/terrain_detail.csv
#   bash scripts/sweep_detail.sh --quick       # fewer settings and frames (smoke run)
#
# Per run (clipstream-fly --reference --reference-lighting pixel, 1280x720):
# triangles a frame, frame time, PSNR (mean and lowest). Then what lighting by
# pixel costs a frame against lighting by vertex, the two alternated in one
# run (bench_renderer_terrain_detail over the scenes' DEMs), and a low view
# over St Helens lit each way, with the reference (docs/images/detail_*.png).
# Writes docs/data/terrain_detail.csv and terrain_detail_cost.tsv,
# docs/charts/terrain_detail.png and the part of docs/terrain.md between
# <!-- detail-sweep:begin --> and <!-- detail-sweep:end -->.
set -euo pipefail
cd "$(dirname "$0")/.."

# shellcheck source=scripts/sweep_lib.sh
source scripts/sweep_lib.sh "$@"
BUILD=${BUILD_DIR:-build}
WORK=${SWEEP_WORK:-out/sweep}/terrain
DOCS=${SWEEP_DOCS:-docs}
SIZE=${SWEEP_TERRAIN_SIZE:-1280x720}
FRAMES=60; EVERY=15
RINGS="32 64 128 256"; ERRORS="4 10 24"
if (( QUICK )); then FRAMES=20; EVERY=10; RINGS="128"; ERRORS="10"; fi
mkdir -p "$WORK" "$DOCS/data" "$DOCS/charts" "$DOCS/images"
start=$(date +%s)
CSV=$DOCS/data/terrain_detail.csv
COST=$DOCS/data/terrain_detail_cost.tsv
# shellcheck source=scripts/terrain_scenes.sh
source scripts/terrain_scenes.sh

if (( ! CHARTS_ONLY )); then
scripts/deps.sh --bench
cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$BUILD" -j "$(nproc)" --target clipstream-tile clipstream-fly bench_renderer_terrain_detail >/dev/null
make_terrain_scenes

# ---- runs -------------------------------------------------------------------
tmp_csv=$CSV.tmp.$$
trap 'rm -f "$tmp_csv"' EXIT
echo "scene,method,setting,lighting,triangles,frame_ms,psnr_db,psnr_min_db" >"$tmp_csv"
run() {  # scene method setting, then clipstream-fly arguments
  local scene=$1 method=$2 setting=$3 lighting
  shift 3
  for lighting in vertex pixel; do
    local out="$WORK/detail_${scene}_${method}_${setting}_$lighting"
    # shellcheck disable=SC2086  # the scene's words
    "$BUILD/eval/clipstream-fly" ${SCENE[$scene]} --speed "${SPEED[$scene]}" --frames "$FRAMES" --rest-frames 2 \
      --warmup-frames 30 --size "$SIZE" --reference --reference-every "$EVERY" --reference-lighting pixel \
      --terrain "$method" --terrain-lighting "$lighting" "$@" --save-frames 0 --out "$out" >/dev/null 2>&1
    printf '%s,%s,%s,%s,%s,%s,%s,%s\n' "$scene" "$method" "$setting" "$lighting" \
      "$(value "$out" judged_triangles_mean)" "$(value "$out" frame_ms_mean)" "$(value "$out" psnr_mean_db)" \
      "$(value "$out" psnr_min_db)" >>"$tmp_csv"
    echo "  $(tail -n 1 "$tmp_csv")"
  done
}
for scene in $SCENES; do
  echo "== $scene"
  for n in $RINGS; do run "$scene" clipmap "$n" --terrain-ring "$n"; done
  for e in $ERRORS; do run "$scene" quadtree "$e" --terrain-error "$e"; done
done
mv "$tmp_csv" "$CSV"

# ---- frame cost, one run alternating the two --------------------------------
dems=()
for scene in $SCENES; do dems+=("$WORK/$scene.cstore"); done
"$BUILD/bench/bench_renderer_terrain_detail" --size "$SIZE" --cameras "$( (( QUICK )) && echo 6 || echo 24)" \
  --tsv "$COST" "${dems[@]}"

# ---- a low view over St Helens, lit each way, and the reference -------------
cat >"$WORK/detail_low.json" <<'EOF'
{"keyframes": [
 {"t": 0, "x": 1500, "y": 400, "z": 3300, "heading_deg": 20, "pitch_deg": -25},
 {"t": 1, "x": 1500, "y": 400, "z": 3300, "heading_deg": 20, "pitch_deg": -25}
]}
EOF
for lighting in vertex pixel; do
  out="$WORK/detail_frame_$lighting"
  # shellcheck disable=SC2086
  "$BUILD/eval/clipstream-fly" $WORK/autzen.cstore --elevation $WORK/helens.cstore --stretch-elevation \
    --path "$WORK/detail_low.json" --frames 2 --rest-frames 20 --size 640x360 --terrain-lighting "$lighting" \
    --save-frames 1000 --out "$out" >/dev/null 2>&1
  cp "$(ls "$out"/frame_*.png | tail -n 1)" "$DOCS/images/detail_lit_by_$lighting.png"
done
fi  # ! CHARTS_ONLY

# ---- chart ------------------------------------------------------------------
if gnuplot -e 'set terminal' 2>&1 | grep -q pngcairo; then term="pngcairo size 1500,500 font 'sans,9'"
else term="png size 1500,500"; fi
png=$DOCS/charts/terrain_detail.png
{
  echo "set terminal $term"
  echo "set output \"$png.tmp\""
  echo 'set datafile separator ","'
  echo "set multiplot layout 1,$(wc -w <<<"$SCENES") title \"Lit by vertex and by pixel, both judged against the full mesh lit per pixel ($SIZE, llvmpipe)\""
  echo "set key bottom right"
  echo "set grid"
  echo "set logscale x"
  echo "set xlabel \"triangles / frame (log)\""
  echo "set ylabel \"PSNR against the reference lit per pixel (dB)\""
  for scene in $SCENES; do
    echo "sel(m, l) = (strcol(1) eq \"$scene\" && strcol(2) eq m && strcol(4) eq l) ? 1 : 0"
    echo "set title \"$scene\""
    echo "plot \"$CSV\" using (sel(\"clipmap\", \"vertex\") ? \$5 : 1/0):7 with linespoints pt 7 dt 2 title \"clipmap, by vertex\", \
      \"\" using (sel(\"clipmap\", \"pixel\") ? \$5 : 1/0):7 with linespoints pt 7 title \"clipmap, by pixel\", \
      \"\" using (sel(\"quadtree\", \"vertex\") ? \$5 : 1/0):7 with linespoints pt 5 dt 2 title \"quadtree, by vertex\", \
      \"\" using (sel(\"quadtree\", \"pixel\") ? \$5 : 1/0):7 with linespoints pt 5 title \"quadtree, by pixel\""
  done
  echo "unset multiplot"
} | gnuplot
mv "$png.tmp" "$png"

# ---- docs -------------------------------------------------------------------
GEN=$WORK/detail_section.md
{
  echo "<!-- detail-sweep:begin -->"
  echo "Generated by \`bash scripts/sweep_detail.sh\` ($(date -u +%Y-%m-%d), $SIZE, $FRAMES frames judged every $EVERY; this"
  echo "machine, llvmpipe). Every run is judged against the full-resolution mesh with the ideal texture lit per"
  echo "pixel; triangles are the judged frames' mean."
  echo
  echo "| scene | method | setting | triangles | PSNR by vertex dB | PSNR by pixel dB | gain dB | frame ms by vertex / by pixel |"
  echo "|---|---|---:|---:|---:|---:|---:|---:|"
  awk -F, 'FNR>1 { k = $1 SUBSEP $2 SUBSEP $3
                   if ($4 == "vertex") { tri[k] = $5; pv[k] = $7; fv[k] = $6; order[++n] = k }
                   else { pp[k] = $7; fp[k] = $6 } }
           END { for (i = 1; i <= n; ++i) { k = order[i]; split(k, a, SUBSEP)
                   set = (a[2] == "clipmap") ? "ring " a[3] : a[3] " px"
                   printf "| %s | %s | %s | %.0f | %.2f | %.2f | %+.2f | %.1f / %.1f |\n",
                          a[1], a[2], set, tri[k], pv[k], pp[k], pp[k] - pv[k], fv[k], fp[k] } }' "$CSV"
  echo
  echo "The fewest triangles that reach a PSNR: for each scene and method, the PSNR its default reaches lit"
  echo "by vertex (ring 128, bound 10 px), and the fewest triangles of the settings above that reach it lit"
  echo "each way (– : none does)."
  echo
  echo "| scene | method | target dB (default, by vertex) | fewest triangles by vertex | fewest triangles by pixel |"
  echo "|---|---|---:|---:|---:|"
  awk -F, 'FNR>1 { k = $1 SUBSEP $2; row[++n] = $0
                   if (($2 == "clipmap" && $3 == 128 || $2 == "quadtree" && $3 == 10) && $4 == "vertex") target[k] = $7 }
           END { for (i = 1; i <= n; ++i) { split(row[i], r, ",")
                   k = r[1] SUBSEP r[2]
                   if (!(k in target) || r[7] < target[k]) continue
                   if (!((k, r[4]) in best) || r[5] < best[k, r[4]]) best[k, r[4]] = r[5]
                   if (!(k in seen)) { seen[k] = 1; keys[++m] = k } }
                 for (i = 1; i <= m; ++i) { k = keys[i]; split(k, a, SUBSEP)
                   bv = ((k, "vertex") in best) ? sprintf("%.0f", best[k, "vertex"]) : "–"
                   bp = ((k, "pixel") in best) ? sprintf("%.0f", best[k, "pixel"]) : "–"
                   printf "| %s | %s | %.2f | %s | %s |\n", a[1], a[2], target[k], bv, bp } }' "$CSV"
  echo
  echo "What each costs a frame against the frame without it (lit by vertex, no detail), the three alternated"
  echo "draw by draw in one run over random cameras 20-1000 units above a white 2048^2 image, every height tile"
  echo "resident (\`bench_renderer_terrain_detail\`; video memory: the gradients beside the height stack at the"
  echo "default window):"
  echo
  echo "| DEM | method | cameras | triangles | plain frame ms | lit by pixel ms | ratio | detail textures ms | ratio | gradients MiB |"
  echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"
  awk -F'\t' 'NR>1 { printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", $1, $2, $3, $4, $5, $6, $7, $8, $9, $10 }' "$COST"
  echo
  echo "![lit by vertex and by pixel](charts/terrain_detail.png)"
  echo
  echo "A low view over St Helens (640x360), lit by vertex, then by pixel:"
  echo
  echo "![lit by vertex](images/detail_lit_by_vertex.png) ![lit by pixel](images/detail_lit_by_pixel.png)"
  echo "<!-- detail-sweep:end -->"
} >"$GEN"
TM=$DOCS/terrain.md
put_block "$TM" detail-sweep "$GEN" || { echo; cat "$GEN"; } >>"$TM"
echo "sweep_detail: wrote $CSV, $COST, $png and the detail-sweep section of $TM in $(( $(date +%s) - start ))s"
