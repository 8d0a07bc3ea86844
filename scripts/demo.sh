#!/usr/bin/env bash
# The main job, from a fresh Debian 12 machine: installs what is missing,
# builds, tiles the bundled orthophoto and DEM into tile stores (the DEM
# twice: its heights, and a shaded relief drawn from them), verifies them,
# flies over the orthophoto headless, then over the mountain, then low over
# its slopes as they are and with the detail beyond the data (lit per pixel,
# detail textures, synthesized relief), and writes stats, frames and charts
# to out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh

jobs=$(nproc)
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
# The programs and libraries (not the tests): what `cmake --install build` installs.
cmake --build build -j "$jobs" --target installables

out=out/demo
mkdir -p "$out"
store="$out/autzen.cstore"
dem="$out/helens.cstore"
relief="$out/helens_relief.cstore"

echo "== Tiling data/autzen.jpg =="
build/tiler/clipstream-tile data/autzen.jpg "$store" --force
echo "== Tiling data/mount_st_helens_30m.tif (an elevation store) =="
build/tiler/clipstream-tile data/mount_st_helens_30m.tif "$dem" --force
echo "== Drawing the DEM as a shaded relief, 8 pixels a sample (the terrain's texture) =="
build/tiler/clipstream-tile data/mount_st_helens_30m.tif "$relief" --relief --relief-scale 8 --force
echo "== Verifying the stores =="
build/store/clipstream-info "$store" --verify
build/store/clipstream-info "$dem" --verify
build/store/clipstream-info "$relief" --verify

# An orbit a tenth of the photo's side above the ground, looking at the
# stadium: high enough that the photo's detail (about 8 ft under its 1 ft
# pixels) is not smeared across the screen.
echo "== Flying over the orthophoto headless =="
build/eval/clipstream-fly "$store" --path orbit --frames 600 --size 1280x720 \
  --out "$out/fly" --save-frames 150

# The relief lies on the DEM's heights by their georeferences (the same
# grid, 8 pixels a sample). The orbit (data/helens_relief_orbit.json) circles the
# mountain looking at the crater; every 30th frame is judged against the
# full-resolution mesh with the ideal texture (PSNR, geometric error).
echo "== Flying over the mountain headless =="
build/eval/clipstream-fly "$relief" --elevation "$dem" \
  --path data/helens_relief_orbit.json --speed 3 --frames 600 --rest-frames 30 --size 1280x720 \
  --reference --reference-every 30 --out "$out/terrain" --save-frames 150

# Low over the slopes (data/helens_relief_low_pass.json, 40 texels above the
# ground), where the relief's texels span several pixels and the DEM's 30 m
# cells are flat facets: first as they are, then lit per pixel with the
# detail textures and two levels of synthesized relief (docs/terrain.md,
# "Detail beyond the data").
echo "== A low pass over the slopes, as they are =="
build/eval/clipstream-fly "$relief" --elevation "$dem" --path data/helens_relief_low_pass.json \
  --frames 200 --rest-frames 10 --size 1280x720 --out "$out/low_pass" --save-frames 100
echo "== The same pass with the detail beyond the data =="
build/eval/clipstream-fly "$relief" --elevation "$dem" --path data/helens_relief_low_pass.json \
  --frames 200 --rest-frames 10 --size 1280x720 --terrain-lighting pixel --terrain-detail --synthesize-relief 2 \
  --out "$out/low_pass_detail" --save-frames 100

echo "== Charts =="
# Written under a temporary name and renamed when whole (docs/cli.md).
trap 'rm -f "$out"/*/frame_time.png.tmp' EXIT
for run in fly terrain low_pass low_pass_detail; do
  gnuplot -e "csv='$out/$run/frames.csv'; png='$out/$run/frame_time.png.tmp'" scripts/plot_frames.gp
  mv -f "$out/$run/frame_time.png.tmp" "$out/$run/frame_time.png"
done
echo "Wrote $out/fly/, $out/terrain/, $out/low_pass/ and $out/low_pass_detail/ (stats CSV/JSON, frames PNG, frame_time.png)"
