#!/usr/bin/env bash
# Terrain methods side by side: the geometry clipmap and the quadtree over the
# same flights, as the ring size (clipmap) and the error bound (quadtree) vary,
# with the flat plane and the full-resolution mesh as the two end points.
#
#   bash scripts/sweep_terrain.sh            # about 25 minutes on 2 cores
#   bash scripts/sweep_terrain.sh --charts-only  # redraw charts and the table from docs/data/terrain_methods.csv
#   bash scripts/sweep_terrain.sh --quick    # fewer settings and frames (smoke run)
#
# Scenes (each flown at 1280x720 with clipstream-fly --reference --fewest-triangles):
#  - helens:  the bundled orthophoto over the bundled St Helens DEM (stretched),
#             the demo's orbit (data/helens_orbit.json) at x12;
#  - rainier: Mount Rainier (../shared/data/mt_rainier_90m.tif, SRTM; skipped when
#             absent) under a 65536^2 procedural texture, 600 units above its slopes;
#  - rough:   a procedural rough DEM (scripts/make_rough_dem.py: ridged noise, a
#             300 m cliff, spikes) under a 16384^2 procedural texture, built-in orbit.
# Per run: triangles a frame, frame time and render-thread CPU time, geometric
# error (mean, p95) and PSNR against the full-resolution mesh with the ideal
# texture, coverage (ground in one frame, sky in the other) included, the
# silhouette figure (outline to outline), the fewest triangles that model each
# judged frame within its own p95 (FewestTriangles), the quadtree's achieved
# error bound (its triangle budget), the over-fetch of the colour layer's clip
# levels and of the height layer's (against the tiles the drawn geometry
# read); then the same setting on a slow stretch of the flight judged every
# frame: the mean per-pixel grey change between consecutive frames against the
# reference's own, and the geometry-only change (the drawn surface moving
# against the full-resolution one).
# Writes docs/data/terrain_methods.csv, docs/charts/terrain_*.png and the part of
# docs/terrain.md between <!-- terrain-sweep:begin --> and <!-- terrain-sweep:end -->.
# Needs gnuplot and, for the rough DEM, python3-gdal (scripts/deps.sh --bench).
set -euo pipefail
cd "$(dirname "$0")/.."

# shellcheck source=scripts/sweep_lib.sh
source scripts/sweep_lib.sh "$@"
BUILD=${BUILD_DIR:-build}
WORK=${SWEEP_WORK:-out/sweep}/terrain
DOCS=${SWEEP_DOCS:-docs}
SIZE=${SWEEP_TERRAIN_SIZE:-1280x720}
FRAMES=60; EVERY=15; SLOW=12
RINGS="32 64 128 256"; ERRORS="3 6 16"
if (( QUICK )); then FRAMES=20; EVERY=10; SLOW=4; RINGS="128"; ERRORS="6"; fi
mkdir -p "$WORK" "$DOCS/data" "$DOCS/charts"
start=$(date +%s)

CSV=$DOCS/data/terrain_methods.csv
# shellcheck source=scripts/terrain_scenes.sh
source scripts/terrain_scenes.sh
if (( ! CHARTS_ONLY )); then
scripts/deps.sh --bench
cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$BUILD" -j "$(nproc)" --target clipstream-tile clipstream-fly >/dev/null

make_terrain_scenes

# A number of frames.json's summary (its streamer and accuracy objects
# included), empty when absent.
jvalue() {
  /usr/bin/python3 - "$1/frames.json" "$2" <<'PY'
import json, sys
def find(o, k):
    if isinstance(o, dict):
        if k in o and not isinstance(o[k], (dict, list)): return o[k]
        for v in o.values():
            r = find(v, k)
            if r is not None: return r
    return None
v = find(json.load(open(sys.argv[1])).get("summary", {}), sys.argv[2])
print("" if v is None else v)
PY
}

# ---- runs -------------------------------------------------------------------
tmp_csv=$CSV.tmp.$$
trap 'rm -f "$tmp_csv" "$WORK"/*.png.tmp' EXIT
echo "scene,method,setting,triangles,fewest_triangles,frame_ms,render_cpu_ms,geo_mean_px,geo_p95_px,psnr_db,change,reference_change,silhouette_mean_px,silhouette_p95_px,coverage_pixels,geometry_change_px,geometry_change_max_px,error_bound_px,over_fetch_clip,height_over_fetch" >"$tmp_csv"
run() {  # scene method setting, then clipstream-fly arguments
  local scene=$1 method=$2 setting=$3
  shift 3
  local out="$WORK/run_${scene}_${method}_${setting}"
  # shellcheck disable=SC2086  # the scene's words
  "$BUILD/eval/clipstream-fly" ${SCENE[$scene]} --speed "${SPEED[$scene]}" --frames "$FRAMES" --rest-frames 2 \
    --warmup-frames 30 \
    --size "$SIZE" --reference --reference-every "$EVERY" --fewest-triangles --terrain "$method" "$@" \
    --save-frames 0 --out "$out" >/dev/null 2>&1
  # The slow stretch: the same path at a fifth of the speed, every frame
  # judged (not for the full mesh: it is the reference).
  local slow_speed
  slow_speed=$(awk -v s="${SPEED[$scene]}" 'BEGIN{printf "%g", s / 5}')
  mkdir -p "$out/slow"
  printf 'change_mean\treference_change_mean\tgeometry_change_mean_px\tgeometry_change_max_px\n0\t0\t0\t0\n' \
    >"$out/slow/summary.tsv"
  # shellcheck disable=SC2086
  [ "$method" = full ] || "$BUILD/eval/clipstream-fly" ${SCENE[$scene]} --speed "$slow_speed" --frames "$SLOW" \
    --warmup-frames 10 --size "$SIZE" --reference --reference-every 1 --terrain "$method" "$@" \
    --save-frames 0 --out "$out/slow" >/dev/null 2>&1
  printf '%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s,%s\n' "$scene" "$method" "$setting" \
    "$(value "$out" judged_triangles_mean)" "$(value "$out" fewest_triangles_mean)" \
    "$(value "$out" frame_ms_mean)" "$(value "$out" render_cpu_ms_mean)" \
    "$(value "$out" geo_error_mean_px)" "$(value "$out" geo_error_p95_px)" "$(value "$out" psnr_mean_db)" \
    "$(value "$out/slow" change_mean)" "$(value "$out/slow" reference_change_mean)" \
    "$(value "$out" geo_silhouette_mean_px)" "$(value "$out" geo_silhouette_p95_px)" \
    "$(value "$out" geo_coverage_pixels_mean)" "$(value "$out/slow" geometry_change_mean_px)" \
    "$(value "$out/slow" geometry_change_max_px)" "$(value "$out" terrain_error_px_mean)" \
    "$(value "$out" over_fetch_stack_ratio)" "$(jvalue "$out" height_over_fetch_stack_ratio)" >>"$tmp_csv"
  echo "  $scene $method $setting: $(tail -n 1 "$tmp_csv")"
}
for scene in $SCENES; do
  echo "== $scene"
  run "$scene" flat 0
  for n in $RINGS; do run "$scene" clipmap "$n" --terrain-ring "$n"; done
  for e in $ERRORS; do run "$scene" quadtree "$e" --terrain-error "$e"; done
  run "$scene" full 0
done
mv "$tmp_csv" "$CSV"
fi  # ! CHARTS_ONLY

# ---- charts -----------------------------------------------------------------
if gnuplot -e 'set terminal' 2>&1 | grep -q pngcairo; then term="pngcairo size 1500,1100 font 'sans,9'"
else term="png size 1500,1100"; fi
# One chart per pair: triangles, frame time and render-thread CPU time (rows)
# against the geometric error's mean and p95 and the PSNR (columns).
panel() {  # y column, y label, y log (1/0), x column, x label, x kind (err|psnr)
  local yc=$1 yl=$2 ylog=$3 xc=$4 xl=$5 xk=$6 x
  if [ "$xk" = err ]; then x="err(\$$xc)"; echo "set logscale x"; else x="\$$xc"; echo "unset logscale x"; fi
  if [ "$ylog" = 1 ]; then echo "set logscale y"; else echo "unset logscale y"; fi
  echo "set xlabel \"$xl\""
  echo "set ylabel \"$yl\""
  local y="\$$yc" fewest=""
  [ "$yc" = 4 ] && [ "$xk" = err ] && [ "$xc" = 9 ] &&
    fewest="\"\" using ((sel(\"clipmap\") || sel(\"quadtree\")) ? err(\$9) : 1/0):5 with points pt 2 ps 1.5 title \"fewest at the same p95\", "
  echo "plot \"$CSV\" using (sel(\"clipmap\") ? $x : 1/0):($y > 0 ? $y : 1) with linespoints pt 7 title \"clipmap (ring 32..256)\", \
    \"\" using (sel(\"quadtree\") ? $x : 1/0):($y > 0 ? $y : 1) with linespoints pt 5 title \"quadtree (bound 16..3 px)\", \
    $fewest\"\" using (sel(\"flat\") ? $x : 1/0):($y > 0 ? $y : 1) with points pt 9 ps 2 title \"flat\", \
    \"\" using (sel(\"full\") ? $x : 1/0):($y > 0 ? $y : 1) with points pt 11 ps 2 title \"full mesh\""
}
for scene in $SCENES; do
  png="$DOCS/charts/terrain_$scene.png"
  {
    echo "set terminal $term"
    echo "set output \"$png.tmp\""
    echo 'set datafile separator ","'
    echo "set multiplot layout 3,3 title \"Terrain methods, $scene ($SIZE, llvmpipe): each point a setting; flat and full mesh are the end points (full mesh: error plotted at 0.01 px)\""
    echo "set key top right"
    echo "set grid"
    echo "sel(m) = (strcol(1) eq \"$scene\" && strcol(2) eq m) ? 1 : 0"
    echo "err(v) = v > 0.01 ? v : 0.01"
    for row in "4|triangles / frame (log)|1" "6|frame ms (mean)|0" "7|render-thread CPU ms / frame|0"; do
      IFS='|' read -r yc yl ylog <<<"$row"
      panel "$yc" "$yl" "$ylog" 8 "geometric error mean (px, log)" err
      panel "$yc" "$yl" "$ylog" 9 "geometric error p95 (px, log)" err
      panel "$yc" "$yl" "$ylog" 10 "PSNR against the full mesh, ideal texture (dB)" psnr
    done
    echo "unset multiplot"
  } | gnuplot
  mv "$png.tmp" "$png"
done
png="$DOCS/charts/terrain_stability.png"
gnuplot <<EOF
set terminal $term
set output "$png.tmp"
set datafile separator ","
set multiplot layout 2,1
set title "Temporal stability on a slow flight: mean grey change between consecutive frames, streamed minus the reference's (popping shows above 0)"
set style data histograms
set style histogram clustered gap 1
set style fill solid 0.7 border -1
set ylabel "excess change per pixel (grey levels)"
set key bottom left
set xtics rotate by -45
set grid y
plot "$CSV" every ::1 using (\$11 - \$12):xtic(strcol(1)."/".strcol(2)."/".strcol(3)) title "streamed - reference"
set title "The geometry alone: mean change of each pixel's offset from the full-resolution surface between consecutive frames"
set ylabel "geometry change (px)"
set key top left
plot "$CSV" every ::1 using 16:xtic(strcol(1)."/".strcol(2)."/".strcol(3)) title "mean over the frame pairs", \
     "" every ::1 using 17 title "largest pair"
unset multiplot
EOF
mv "$png.tmp" "$png"

# ---- docs -------------------------------------------------------------------
GEN=$WORK/terrain_section.md
{
  echo "<!-- terrain-sweep:begin -->"
  echo "Generated by \`bash scripts/sweep_terrain.sh\` ($(date -u +%Y-%m-%d), $SIZE, $FRAMES frames judged every"
  echo "$EVERY, slow stretch $SLOW frames at a fifth of the speed judged every frame; this machine, llvmpipe)."
  echo "Triangles are the judged frames' mean; fewest: the fewest triangles that model each judged frame within"
  echo "its own p95 (the ratio is what a setting models beyond the frame's need); × flat: the frame time against the"
  echo "flat plane's; the geometric error counts coverage (ground in one frame, sky in the other); silhouette: each"
  echo "outline pixel's distance to the other frame's outline; grey change: the slow stretch's change between"
  echo "consecutive frames minus the reference's; geometry change: the drawn surface moving against the"
  echo "full-resolution one between consecutive frames (mean / largest pair); bound: the quadtree's achieved error"
  echo "bound (above its setting where the triangle budget binds); over-fetch: the clip levels' tiles loaded over"
  echo "those the frames sample (the coarse pyramid, loaded whole at the start, left out), colour / height; for the"
  echo "height, the tiles the drawn geometry read in every frame (–: no clip level, as on St Helens, whose flight needs"
  echo "none of the orthophoto and whose DEM fits the height windows whole)."
  echo
  echo "| scene | method | setting | triangles | fewest | ratio | frame ms | × flat | geo mean / p95 px | silhouette mean / p95 px | coverage px | PSNR dB | grey change | geometry change px | bound px | over-fetch |"
  echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
  awk -F, 'NR==FNR { if ($2 == "flat") flat[$1] = $6; next }
           FNR>1{ratio = ($5 > 0) ? sprintf("%.2f", $4 / $5) : "";
                set = ($2=="clipmap") ? "ring " $3 : ($2=="quadtree") ? $3 " px" : "";
                cost = (flat[$1] > 0) ? sprintf("%.2f", $6 / flat[$1]) : "";
                bound = ($2 == "quadtree" && $18 != "") ? sprintf("%.1f", $18) : "";
                cof = ($19 != "" && $19 > 0) ? sprintf("%.2f", $19) : "–";
                hof = ($20 != "" && $20 > 0) ? sprintf("%.2f", $20) : "–";
                printf "| %s | %s | %s | %.0f | %.0f | %s | %.1f | %s | %.3f / %.3f | %.2f / %.2f | %.0f | %.2f | %+.3f | %.4f / %.3f | %s | %s / %s |\n",
                $1, $2, set, $4, $5, ratio, $6, cost, $8, $9, $13, $14, $15, $10, $11 - $12, $16, $17, bound, cof, hof}' "$CSV" "$CSV"
  echo
  for scene in $SCENES; do echo "![terrain methods, $scene](charts/terrain_$scene.png)"; echo; done
  echo "![temporal stability](charts/terrain_stability.png)"
  echo "<!-- terrain-sweep:end -->"
} >"$GEN"
TM=$DOCS/terrain.md
put_block "$TM" terrain-sweep "$GEN" || { echo; cat "$GEN"; } >>"$TM"
echo "sweep_terrain: wrote $CSV, $DOCS/charts/terrain_*.png and the terrain-sweep section of $TM in $(( $(date +%s) - start ))s"
