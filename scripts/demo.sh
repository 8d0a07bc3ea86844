#!/usr/bin/env bash
# The main job, from a fresh Debian 12 machine: installs what is missing,
# builds, tiles the bundled orthophoto and DEM into tile stores, verifies
# them, flies through the texture headless and then over the terrain, and
# writes stats, frames and charts to out/demo/.
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

echo "== Tiling data/autzen.jpg =="
build/tiler/clipstream-tile data/autzen.jpg "$store" --force
echo "== Tiling data/mount_st_helens_30m.tif (an elevation store) =="
build/tiler/clipstream-tile data/mount_st_helens_30m.tif "$dem" --force
echo "== Verifying the stores =="
build/store/clipstream-info "$store" --verify
build/store/clipstream-info "$dem" --verify

echo "== Flying through it headless =="
build/eval/clipstream-fly "$store" --path pass --frames 600 --size 1280x720 \
  --out "$out/fly" --save-frames 150

# The bundled DEM is of another place (Mount St. Helens): it is stretched
# under the orthophoto, keeping its own proportions. The orbit keeps far
# enough from the ground that the orthophoto (about 8 ft of detail under
# its 1 ft pixels) is not magnified; every 30th frame is judged against the
# full-resolution mesh with the ideal texture (PSNR, geometric error).
echo "== Flying over the terrain headless =="
build/eval/clipstream-fly "$store" --elevation "$dem" --stretch-elevation \
  --path data/helens_orbit.json --speed 12 --frames 600 --rest-frames 30 --size 1280x720 \
  --reference --reference-every 30 --out "$out/terrain" --save-frames 150

echo "== Charts =="
# Written under a temporary name and renamed when whole (docs/cli.md).
trap 'rm -f "$out/fly/frame_time.png.tmp" "$out/terrain/frame_time.png.tmp"' EXIT
for run in fly terrain; do
  gnuplot -e "csv='$out/$run/frames.csv'; png='$out/$run/frame_time.png.tmp'" scripts/plot_frames.gp
  mv -f "$out/$run/frame_time.png.tmp" "$out/$run/frame_time.png"
done
echo "Wrote $out/fly/ and $out/terrain/ (stats CSV/JSON, frames PNG, frame_time.png)"
