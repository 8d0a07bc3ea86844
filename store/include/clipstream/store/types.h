// Plain types shared by every component: pixel formats, tile keys and store
// geometry; with them the Status every fallible call returns
// (clipstream/util/status.h).
//
// Thread-safe: plain data and pure functions only.
#pragma once

#include <clipstream/util/status.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace clipstream {

// Pixel layout of a store's tiles. Channels are interleaved, multi-byte
// samples are little-endian. The numeric values are part of the on-disk
// format. I16 and F32 hold heights (elevation stores, format version 2);
// R16 is a 16-bit grey image or unsigned heights.
enum class PixelFormat : uint32_t {
  kR8 = 1,
  kR16 = 2,
  kRGB8 = 3,
  kRGBA8 = 4,
  kI16 = 5,  // signed 16-bit (two's complement)
  kF32 = 6,  // IEEE-754 binary32
};

uint32_t channelCount(PixelFormat format);   // 1, 1, 3, 4, 1, 1
uint32_t bytesPerPixel(PixelFormat format);  // 1, 2, 3, 4, 2, 4
const char* pixelFormatName(PixelFormat format);  // "R8", "R16", "RGB8", "RGBA8", "I16", "F32"
bool isValidPixelFormat(uint32_t raw);
// True for the formats a colour store may use (R8, R16, RGB8, RGBA8).
bool isColourFormat(PixelFormat format);
// True for the formats an elevation store may use (R16, I16, F32).
bool isHeightFormat(PixelFormat format);

// Filter used to build each coarser level from the one below it. Values are
// part of the on-disk format (recorded in the header, informational only).
enum class DownsampleFilter : uint32_t {
  kBox = 0,      // exact 2x2 average, odd edges handled (see docs/tile-store.md)
  kLanczos3 = 1, // separable Lanczos-3, optionally in linear light
  kDecimate = 2, // every other sample of the finer level (elevation stores)
};
const char* downsampleFilterName(DownsampleFilter filter);

// Identifies one tile. Level 0 is the finest; x and y count tiles from the
// top-left corner of that level.
struct TileKey {
  uint32_t level = 0;
  uint32_t x = 0;
  uint32_t y = 0;

  friend bool operator==(const TileKey&, const TileKey&) = default;
};
static_assert(sizeof(TileKey) == 12, "TileKey is hashed whole: no padding allowed");

struct TileKeyHash {
  size_t operator()(const TileKey& key) const noexcept;  // hashes all 12 bytes
};

// Size of one level of the pyramid. Level l has width max(1, ceil(w / 2^l))
// (same for height); tiles_x = ceil(width_px / tile_px).
struct LevelInfo {
  uint64_t width_px = 0;
  uint64_t height_px = 0;
  uint32_t tiles_x = 0;
  uint32_t tiles_y = 0;
};

// Affine georeference, GDAL order: for pixel corner (col, row) of level 0,
//   X = t[0] + col * t[1] + row * t[2];  Y = t[3] + col * t[4] + row * t[5].
struct GeoReference {
  bool present = false;
  double transform[6] = {0, 1, 0, 0, 0, 1};
  std::string crs;  // coordinate system text (WKT or "EPSG:nnnn"); may be empty
};

// Metres one unit of a CRS spans on the ground, along x and y.
struct CrsUnitMetres {
  double x = 1.0;
  double y = 1.0;
  bool assumed = true;  // the unit is not known here: metres taken
};

// The ground size of a CRS unit at `latitude_deg` (which matters for
// geographic CRSs only). WKT: the projected CRS's last UNIT/LENGTHUNIT, or
// degrees for a geographic one; "EPSG:4xxx": geographic; the UTM, ETRS89
// and Web Mercator EPSG codes: metres; any other EPSG code, or an empty
// CRS: metres, assumed. The one place the programs turn
// georeferences into ground distances (the tiler's relief shading, the
// streamer's layer alignment).
CrsUnitMetres metresPerCrsUnit(const std::string& crs, double latitude_deg);

// Geometry of a pyramid: everything a reader needs to address tiles.
struct PyramidGeometry {
  uint64_t width_px = 0;   // level 0
  uint64_t height_px = 0;  // level 0
  uint32_t tile_px = 128;
  PixelFormat format = PixelFormat::kRGB8;
  std::vector<LevelInfo> levels;  // levels[0] finest; last level is one tile

  uint32_t levelCount() const { return static_cast<uint32_t>(levels.size()); }
  size_t tileBytes() const { return size_t(tile_px) * tile_px * bytesPerPixel(format); }
  bool contains(const TileKey& key) const;
};

// Computes the full level list down to (and including) the first level that
// fits in one tile. Returns false for zero sizes or tile_px of 0.
bool makePyramidGeometry(uint64_t width_px, uint64_t height_px, uint32_t tile_px,
                         PixelFormat format, PyramidGeometry* out);

}  // namespace clipstream
