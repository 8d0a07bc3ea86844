#!/usr/bin/env bash
# Builds the Debian packages from build/ (cpack) and checks them: the layout
# (programs, module, manual pages and completion in clipstream; static
# libraries, headers, CMake and pkg-config files in the multiarch folder in
# libclipstream-dev, and nothing of one in the other), that the unpacked
# programs run and find their module, and lintian. Called by scripts/test.sh.
# Usage: scripts/check_packages.sh [BUILD_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
build=${1:-build}
multiarch=$(dpkg-architecture -qDEB_HOST_MULTIARCH)

rm -f "$build"/clipstream_*.deb "$build"/libclipstream-dev_*.deb
(cd "$build" && cpack -G DEB) | grep -F 'package:'
programs_deb=$(ls "$build"/clipstream_*.deb)
dev_deb=$(ls "$build"/libclipstream-dev_*.deb)
for deb in "$programs_deb" "$dev_deb"; do
  dpkg-deb --field "$deb" Package Version Section Depends
done

failures=0
fail() { echo "package layout: $*" >&2; failures=$((failures + 1)); }
contents() { dpkg-deb --contents "$1" | awk '{print $6}' | sed 's|^\./|/|'; }
has() {  # has LIST REGEX WHAT
  grep -Eq "$2" <<<"$1" || fail "$3"
}
lacks() {
  if grep -Eq "$2" <<<"$1"; then fail "$3: $(grep -E "$2" <<<"$1" | head -n 3 | tr '\n' ' ')"; fi
}

p=$(contents "$programs_deb")
d=$(contents "$dev_deb")
for program in clipstream-tile clipstream-merge clipstream-info clipstream-fly clipstream-view clipstream-trace; do
  has "$p" "^/usr/bin/$program\$" "clipstream lacks /usr/bin/$program"
  has "$p" "^/usr/share/man/man1/$program\.1\.gz\$" "clipstream lacks the manual page of $program"
  has "$p" "^/usr/share/bash-completion/completions/$program\$" "clipstream lacks the completion of $program"
done
for module in oiio gdal; do
  has "$p" "^/usr/lib/$multiarch/clipstream/libclipstream_tiler_$module\.so\$" \
    "clipstream lacks the $module module in /usr/lib/$multiarch/clipstream"
done
has "$p" "^/usr/share/doc/clipstream/copyright\$" "clipstream lacks its copyright file"
lacks "$p" "^/usr/include/|\.a\$|/cmake/|/pkgconfig/" "clipstream carries development files"
for name in util store tiler streamer renderer; do
  has "$d" "^/usr/lib/$multiarch/libclipstream_$name\.a\$" "libclipstream-dev lacks libclipstream_$name.a"
  has "$d" "^/usr/include/clipstream/$name/" "libclipstream-dev lacks the headers of $name"
done
has "$d" "^/usr/lib/$multiarch/cmake/clipstream/clipstreamConfig\.cmake\$" "libclipstream-dev lacks the CMake package"
has "$d" "^/usr/lib/$multiarch/pkgconfig/clipstream\.pc\$" "libclipstream-dev lacks clipstream.pc"
has "$d" "^/usr/share/doc/libclipstream-dev/copyright\$" "libclipstream-dev lacks its copyright file"
lacks "$d" "^/usr/bin/|^/usr/share/man/|\.so\$" "libclipstream-dev carries the programs' files"
lacks "$p$d" "^/usr/lib/[^/]+\.(a|so)\$" "a library outside the multiarch folder"

# The unpacked programs run, and the tiler finds its OpenImageIO module
# relative to itself: a PPM is read by no native reader, only the module.
root=$(mktemp -d)
trap 'rm -rf "$root"' EXIT
dpkg-deb -x "$programs_deb" "$root"
"$root/usr/bin/clipstream-tile" --version
{ printf 'P6\n300 200\n255\n'; head -c 180000 /dev/urandom; } >"$root/noise.ppm"
CLIPSTREAM_TILER_OIIO_MODULE='' LD_DEBUG=files \
  "$root/usr/bin/clipstream-tile" -q --no-fsync "$root/noise.ppm" "$root/noise.cst" 2>"$root/loader.log"
grep -qF "file=$root/usr/bin/../lib/$multiarch/clipstream/libclipstream_tiler_oiio.so " "$root/loader.log" ||
  fail "the unpacked clipstream-tile did not load the module from /usr/lib/$multiarch/clipstream"
# ... and its GDAL module: a VRT goes to GDAL.
{
  echo '<VRTDataset rasterXSize="300" rasterYSize="200">'
  for b in 1 2 3; do
    echo "<VRTRasterBand dataType=\"Byte\" band=\"$b\"><SimpleSource><SourceFilename relativeToVRT=\"1\">noise.ppm</SourceFilename><SourceBand>$b</SourceBand></SimpleSource></VRTRasterBand>"
  done
  echo '</VRTDataset>'
} >"$root/noise.vrt"
CLIPSTREAM_TILER_GDAL_MODULE='' LD_DEBUG=files \
  "$root/usr/bin/clipstream-tile" -q --no-fsync "$root/noise.vrt" "$root/noise-vrt.cst" 2>"$root/loader.log"
grep -qF "file=$root/usr/bin/../lib/$multiarch/clipstream/libclipstream_tiler_gdal.so " "$root/loader.log" ||
  fail "the unpacked clipstream-tile did not load the GDAL module from /usr/lib/$multiarch/clipstream"
"$root/usr/bin/clipstream-info" --verify "$root/noise.cst" | tail -n 1
zcat "$root/usr/share/man/man1/clipstream-tile.1.gz" | grep -qF 'memory\-mb' ||
  fail "the manual page of clipstream-tile does not list --memory-mb"

if ((failures > 0)); then
  echo "package layout: $failures problem(s)" >&2
  exit 1
fi
echo "package layout: as Debian lays it out"

# lintian: errors and warnings fail; the tags left are explained in
# docs/deployment.md ("Debian packages").
lintian --fail-on error,warning --suppress-tags-from-file scripts/lintian-suppressed \
  "$programs_deb" "$dev_deb"
echo "lintian: clean but for the explained tags (scripts/lintian-suppressed)"
