#!/usr/bin/env bash
# Installs the Debian 12 packages clipstream builds and tests with, only if
# some are missing. Usage: scripts/deps.sh [--bench]
#   --bench  also the tools the benchmark scripts compare against (GDAL, libvips)
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config
  dpkg-dev file  # the Debian packages: dpkg-shlibdeps, and CPack finds ELF files with file
  help2man lintian bash-completion  # manual pages, the packages' check, the completion's test
  libopenimageio-dev libzstd-dev libxxhash-dev
  libtiff-dev libjpeg62-turbo-dev libpng-dev  # the tiler reads TIFF, JPEG and PNG without OpenImageIO
  libxml2-dev           # ... and GDAL VRTs (mosaics) with a real XML parser
  libgdal-dev           # ... and every other raster, URLs and VRTs through GDAL (a module)
  gdal-bin              # gdalwarp and gdal_translate make the reprojection tests' references
  libcurl4-openssl-dev  # stores read over HTTP(S)
  nginx-light           # the HTTP tests serve stores from a real nginx on 127.0.0.1
  openssl               # ... and make a certificate for its https:// test
  libproj-dev           # longitude and latitude into a store's CRS (--look-at lonlat:)
  libcli11-dev nlohmann-json3-dev libglm-dev
  libstb-dev            # stb_dxt: the BC1 encoder of --tile-format bc1 (streamer/src/bc1.cpp)
  libglfw3-dev libegl-dev libgl-dev libopengl-dev libegl-mesa0 libgl1-mesa-dri
  libgtest-dev libgmock-dev libbenchmark-dev
  gnuplot-nox xvfb xauth
  xdotool               # clipstream-view's keys, pressed in the virtual X server by its test
  clang libclang-rt-dev
)
if [[ "${1:-}" == "--bench" ]]; then
  packages+=(python3-gdal libvips-tools time)
fi

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if ((${#missing[@]} == 0)); then
  exit 0
fi

echo "Installing missing packages: ${missing[*]}" >&2
sudo_cmd=()
if [[ $(id -u) -ne 0 ]]; then
  if command -v sudo >/dev/null; then
    sudo_cmd=(sudo)
  else
    echo "error: packages missing (${missing[*]}) and not running as root; run as root or install them" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -q
"${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}"
