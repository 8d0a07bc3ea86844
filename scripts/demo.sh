#!/usr/bin/env bash
# The main job, from a fresh Debian 12 machine: installs what is missing,
# builds, tiles the bundled orthophoto into a tile store, verifies it, flies
# through it headless and writes stats, frames and charts to out/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/deps.sh

jobs=$(nproc)
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
cmake --build build -j "$jobs" --target clipstream-tile clipstream-info clipstream-fly

out=out/demo
mkdir -p "$out"
store="$out/autzen.cstore"

echo "== Tiling data/autzen.jpg =="
build/tiler/clipstream-tile data/autzen.jpg "$store" --force
echo "== Verifying the store =="
build/store/clipstream-info "$store" --verify

echo "== Flying through it headless =="
build/eval/clipstream-fly "$store" --path pass --frames 600 --size 1280x720 \
  --out "$out/fly" --save-frames 150

echo "== Charts =="
# Written under a temporary name and renamed when whole (docs/cli.md).
trap 'rm -f "$out/fly/frame_time.png.tmp"' EXIT
gnuplot -e "csv='$out/fly/frames.csv'; png='$out/fly/frame_time.png.tmp'" scripts/plot_frames.gp
mv -f "$out/fly/frame_time.png.tmp" "$out/fly/frame_time.png"
echo "Wrote $out/fly/ (stats CSV/JSON, frames PNG, frame_time.png)"
