#!/usr/bin/env bash
# Detail beyond the data (docs/terrain.md, issue #34): per-pixel lighting
# against the vertices' lighting over the terrain sweep's scenes
# (scripts/terrain_scenes.sh), as the triangles vary (clipmap ring, quadtree
# bound), every run judged against one reference: the full-resolution mesh
# with the ideal texture, lit per pixel from the full-resolution heights;
# synthesized relief (1-2 levels) on St Helens and the rough DEM; the detail
# textures' on-screen texel density on the low pass over St Helens.
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
# Writes docs/data/terrain_detail.csv, terrain_relief.csv, terrain_density.csv
# and terrain_detail_cost.tsv, docs/charts/terrain_detail.png, docs/images/
# detail_*.png and the part of docs/terrain.md between
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
RINGS="32 64 128 256"; ERRORS="3 6 16"
if (( QUICK )); then FRAMES=20; EVERY=10; RINGS="128"; ERRORS="6"; fi
mkdir -p "$WORK" "$DOCS/data" "$DOCS/charts" "$DOCS/images"
start=$(date +%s)
CSV=$DOCS/data/terrain_detail.csv
RELIEF=$DOCS/data/terrain_relief.csv
DENSITY=$DOCS/data/terrain_density.csv
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

# ---- synthesized relief, against the synthesis and against the DEM alone ------
# (Rainier is left out: its reference mesh at 2 levels, 23M samples, takes
# minutes a judged frame on llvmpipe.)
# St Helens on the low pass (data/helens_low_pass.json), where the view
# asks for heights finer than the DEM's; the rough DEM on its orbit.
SCENE[helens_low]="$WORK/autzen.cstore --elevation $WORK/helens.cstore --stretch-elevation --path data/helens_low_pass.json"
SPEED[helens_low]=1
echo "scene,method,levels,triangles,frame_ms,psnr_db,geo_mean_px,geo_p95_px,data_mean_px,data_p95_px" >"$tmp_csv"
for scene in helens_low rough; do
  for method in clipmap quadtree; do
    for levels in 0 1 2; do
      [ "$scene" = rough ] && [ "$levels" = 2 ] && continue
      out="$WORK/relief_${scene}_${method}_$levels"
      args=(); (( levels > 0 )) && args=(--synthesize-relief "$levels")
      # shellcheck disable=SC2086
      "$BUILD/eval/clipstream-fly" ${SCENE[$scene]} --speed "${SPEED[$scene]}" --frames "$FRAMES" --rest-frames 2 \
        --warmup-frames 30 --size "$SIZE" --reference --reference-every "$EVERY" --terrain "$method" \
        --terrain-lighting pixel "${args[@]}" --save-frames 0 --out "$out" >/dev/null 2>&1
      printf '%s,%s,%s,%s,%s,%s,%s,%s,%s,%s\n' "$scene" "$method" "$levels" "$(value "$out" judged_triangles_mean)" \
        "$(value "$out" frame_ms_mean)" "$(value "$out" psnr_mean_db)" "$(value "$out" geo_error_mean_px)" \
        "$(value "$out" geo_error_p95_px)" "$(value "$out" geo_error_data_mean_px)" \
        "$(value "$out" geo_error_data_p95_px)" >>"$tmp_csv"
      echo "  $(tail -n 1 "$tmp_csv")"
    done
  done
done
mv "$tmp_csv" "$RELIEF"

# ---- the low pass: texel density, and frames lit each way -------------------
echo "setting,texel_density_median,texel_density_p5,detail_density_median,detail_density_p5,psnr_db,frame_ms" >"$tmp_csv"
low() {  # name, then clipstream-fly arguments
  local name=$1 out="$WORK/low_$1"
  shift
  "$BUILD/eval/clipstream-fly" "$WORK/autzen.cstore" --elevation "$WORK/helens.cstore" --stretch-elevation \
    --path data/helens_low_pass.json --frames "$FRAMES" --rest-frames 2 --size "$SIZE" --reference \
    --reference-every "$EVERY" "$@" --save-frames 0 --out "$out" >/dev/null 2>&1
  printf '%s,%s,%s,%s,%s,%s,%s\n' "$name" "$(value "$out" texel_density_median)" "$(value "$out" texel_density_p5)" \
    "$(value "$out" detail_texel_density_median)" "$(value "$out" detail_texel_density_p5)" \
    "$(value "$out" psnr_mean_db)" "$(value "$out" frame_ms_mean)" >>"$tmp_csv"
}
low plain
low detail --terrain-detail
mv "$tmp_csv" "$DENSITY"

# ---- frame cost, one run alternating the two --------------------------------
dems=()
for scene in $SCENES; do dems+=("$WORK/$scene.cstore"); done
"$BUILD/bench/bench_renderer_terrain_detail" --size "$SIZE" --cameras "$( (( QUICK )) && echo 6 || echo 24)" \
  --tsv "$COST" "${dems[@]}"

# ---- a low view over St Helens, lit each way, and the reference -------------
cat >"$WORK/detail_low.json" <<'EOF'
{"keyframes": [
 {"t": 0, "x": 1600, "y": 25, "z": 2500, "heading_deg": 37.6, "pitch_deg": -10},
 {"t": 1, "x": 1600, "y": 25, "z": 2500, "heading_deg": 37.6, "pitch_deg": -10}
]}
EOF
frame() {  # name, then clipstream-fly arguments
  local name=$1 out="$WORK/detail_frame_$1"
  shift
  "$BUILD/eval/clipstream-fly" "$WORK/autzen.cstore" --elevation "$WORK/helens.cstore" --stretch-elevation \
    --path "$WORK/detail_low.json" --frames 2 --rest-frames 20 --size 640x360 "$@" \
    --save-frames 1000 --out "$out" >/dev/null 2>&1
  cp "$(ls "$out"/frame_*.png | tail -n 1)" "$DOCS/images/detail_$name.png"
}
frame lit_by_vertex
frame lit_by_pixel --terrain-lighting pixel
frame all --terrain-lighting pixel --terrain-detail --synthesize-relief 2
fi  # ! CHARTS_ONLY

# ---- chart ------------------------------------------------------------------
if gnuplot -e 'set terminal' 2>&1 | grep -q pngcairo; then term="pngcairo size 1500,500 font 'sans,9'"
else term="png size 1500,500"; fi
png=$DOCS/charts/terrain_detail.png
# One block a curve (scene by scene: clipmap by vertex, by pixel, quadtree by
# vertex, by pixel), its points by triangles, for gnuplot's index.
series=$WORK/detail_series.dat
for scene in $SCENES; do
  for curve in "clipmap vertex" "clipmap pixel" "quadtree vertex" "quadtree pixel"; do
    read -r method lighting <<<"$curve"
    awk -F, -v s="$scene" -v m="$method" -v l="$lighting" '$1 == s && $2 == m && $4 == l { print $5 "," $7 }' "$CSV" | sort -t, -k1,1g
    printf '\n\n'
  done
done >"$series"
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
  block=0
  for scene in $SCENES; do
    echo "set title \"$scene\""
    echo "plot \"$series\" index $block using 1:2 with linespoints pt 7 dt 2 title \"clipmap, by vertex\", \
      \"\" index $((block + 1)) using 1:2 with linespoints pt 7 title \"clipmap, by pixel\", \
      \"\" index $((block + 2)) using 1:2 with linespoints pt 5 dt 2 title \"quadtree, by vertex\", \
      \"\" index $((block + 3)) using 1:2 with linespoints pt 5 title \"quadtree, by pixel\""
    block=$((block + 4))
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
  echo "by vertex (ring 128, bound 6 px), and the fewest triangles that reach it lit each way, interpolated"
  echo "along each lighting's curve of settings (in log triangles; – : no setting reaches it)."
  echo
  echo "| scene | method | target dB (default, by vertex) | fewest triangles by vertex | fewest triangles by pixel | ratio |"
  echo "|---|---|---:|---:|---:|---:|"
  awk -F, 'FNR>1 { k = $1 SUBSEP $2; row[++n] = $0; if (!(k in seen)) { seen[k] = 1; keys[++m] = k }
                   if (($2 == "clipmap" && $3 == 128 || $2 == "quadtree" && $3 == 6) && $4 == "vertex") target[k] = $7 }
           # The fewest triangles on curve (k, l) that reach PSNR t: points by triangles, the first that
           # reaches t, interpolated in log triangles from the point before it.
           function fewest(k, l, t,    i, c, r, tri, ps, j, x, y, best) {
             c = 0
             for (i = 1; i <= n; ++i) { split(row[i], r, ","); if (r[1] SUBSEP r[2] != k || r[4] != l) continue
               ++c; tri[c] = r[5]; ps[c] = r[7] }
             for (i = 1; i <= c; ++i) for (j = i + 1; j <= c; ++j) if (tri[j] < tri[i]) {
               x = tri[i]; tri[i] = tri[j]; tri[j] = x; y = ps[i]; ps[i] = ps[j]; ps[j] = y }
             best = -1
             for (i = 1; i <= c; ++i) if (ps[i] >= t) {
               if (i > 1 && ps[i - 1] < t && ps[i] > ps[i - 1])
                 best = exp(log(tri[i - 1]) + (t - ps[i - 1]) / (ps[i] - ps[i - 1]) * (log(tri[i]) - log(tri[i - 1])))
               else best = tri[i]
               break }
             return best }
           END { for (i = 1; i <= m; ++i) { k = keys[i]; split(k, a, SUBSEP); if (!(k in target)) continue
                   bv = fewest(k, "vertex", target[k]); bp = fewest(k, "pixel", target[k])
                   printf "| %s | %s | %.2f | %s | %s | %s |\n", a[1], a[2], target[k],
                          (bv > 0) ? sprintf("%.0f", bv) : "–", (bp > 0) ? sprintf("%.0f", bp) : "–",
                          (bv > 0 && bp > 0) ? sprintf("%.2f", bp / bv) : "" } }' "$CSV"
  echo
  echo "Synthesized relief (\`--synthesize-relief LEVELS\`, lit by pixel), judged against the reference that draws"
  echo "the same synthesis; beside it the error against the DEM alone (projection only). St Helens on the low pass"
  echo "(\`data/helens_low_pass.json\`, 60 texels above the ground), the rough DEM on its orbit; Rainier is not flown"
  echo "(its reference mesh at 2 levels, 23M samples, takes minutes a frame on llvmpipe):"
  echo
  echo "| scene | method | levels | triangles | frame ms | PSNR dB | geo mean / p95 px | against the DEM: mean / p95 px |"
  echo "|---|---|---:|---:|---:|---:|---:|---:|"
  awk -F, 'FNR>1 { data = ($3 > 0) ? sprintf("%.3f / %.3f", $9, $10) : "(the DEM)"
                   printf "| %s | %s | %s | %.0f | %.1f | %.2f | %.3f / %.3f | %s |\n", $1, $2, $3, $4, $5, $6, $7, $8, data }' "$RELIEF"
  echo
  echo "The detail textures on the low pass over St Helens (\`data/helens_low_pass.json\`, $SIZE): level-0 colour"
  echo "texels across a pixel (median, 5th percentile: the blurriest twentieth), and with the detail textures where"
  echo "the colour is magnified (8 detail texels to a colour texel); PSNR against the reference drawn the same way"
  echo "(with the detail, a pixel drawn from a coarser level than the reference's gets more of it):"
  echo
  echo "| setting | texels a pixel, median / p5 | with the detail, median / p5 | PSNR dB | frame ms |"
  echo "|---|---:|---:|---:|---:|"
  awk -F, 'FNR>1 { with = ($1 == "detail") ? sprintf("%.2f / %.2f", $4, $5) : "–"
                   printf "| %s | %.2f / %.2f | %s | %.2f | %.1f |\n", $1, $2, $3, with, $6, $7 }' "$DENSITY"
  echo
  # The megatexture of that density for the scene (the article's section 5-1 arithmetic).
  read -r cw ch < <("$BUILD/store/clipstream-info" "$WORK/autzen.cstore" | awk '/^image/ {print $2, $4}')
  awk -v w="$cw" -v h="$ch" -v d=8 -v tex=$((256 * 256 * 4 * 4 / 3)) -v store="$(stat -c %s "$WORK/autzen.cstore")" 'BEGIN {
    texels = w * d * h * d
    printf "What it costs: one 256^2 RGBA8 texture, %.0f KiB of video memory with its mips, nothing on disk (generated).\n", tex / 1024
    printf "A megatexture as dense everywhere (%d x %d colour texels at 8 detail texels to one: %.0f x %.0f texels) would\n", w, h, w * d, h * d
    printf "take %.1f GiB as RGBA8 and %.2f GiB as BC1, mips included (4/3), against %.1f MiB for the colour store.\n",
           texels * 4 * 4 / 3 / 2^30, texels * 0.5 * 4 / 3 / 2^30, store / 2^20 }'
  echo
  echo
  echo "What each costs a frame against the frame without it (lit by vertex, no detail, the DEM alone), the four"
  echo "alternated draw by draw in one run over random cameras 20-1000 units above a white 2048^2 image, every"
  echo "height tile resident (\`bench_renderer_terrain_detail\`; video memory: the gradients beside the height"
  echo "stack at the default window; relief: 2 synthesized levels, 1 where a stack of every tile of 2 would pass"
  echo "512 MiB):"
  echo
  echo "| DEM | method | cameras | triangles | plain frame ms | lit by pixel ms | ratio | detail textures ms | ratio | gradients MiB | relief levels | relief triangles | relief ms | ratio |"
  echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
  awk -F'\t' 'NR>1 { printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", $1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14 }' "$COST"
  echo
  echo "![lit by vertex and by pixel](charts/terrain_detail.png)"
  echo
  echo "A low view over St Helens (640x360, 25 texels above the slope): lit by vertex; lit by pixel; lit by pixel"
  echo "with the detail textures and 2 levels of synthesized relief:"
  echo
  echo "![lit by vertex](images/detail_lit_by_vertex.png) ![lit by pixel](images/detail_lit_by_pixel.png)"
  echo "![all three](images/detail_all.png)"
  echo "<!-- detail-sweep:end -->"
} >"$GEN"
TM=$DOCS/terrain.md
put_block "$TM" detail-sweep "$GEN" || { echo; cat "$GEN"; } >>"$TM"
echo "sweep_detail: wrote $CSV, $COST, $png and the detail-sweep section of $TM in $(( $(date +%s) - start ))s"
