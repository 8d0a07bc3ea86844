// Pure helpers behind types.h: pixel format tables and pyramid geometry.
// No I/O here.
#include <clipstream/store/types.h>

#include <xxhash.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>

namespace clipstream {
namespace {

// Metres per degree of longitude and latitude (WGS84 mean, good to 0.5 %).
constexpr double kMetresPerDegreeLat = 110574.0;
constexpr double kMetresPerDegreeLonAtEquator = 111320.0;

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

// The factor of the last UNIT["...", f] or LENGTHUNIT["...", f] in WKT.
bool lastUnitFactor(const std::string& wkt, double* factor) {
  size_t at = std::string::npos;
  for (const char* key : {"LENGTHUNIT[", "UNIT["}) {
    const size_t k = wkt.rfind(key);
    if (k != std::string::npos && (at == std::string::npos || k > at)) at = k;
  }
  if (at == std::string::npos) return false;
  const size_t comma = wkt.find(',', at);
  if (comma == std::string::npos) return false;
  char* end = nullptr;
  const double v = std::strtod(wkt.c_str() + comma + 1, &end);
  if (end == wkt.c_str() + comma + 1 || !(v > 0.0) || !std::isfinite(v)) return false;
  *factor = v;
  return true;
}

bool isGeographic(const std::string& crs) {
  if (startsWith(crs, "GEOGCS[") || startsWith(crs, "GEOGCRS[")) return true;
  if (startsWith(crs, "EPSG:")) {
    const long code = std::strtol(crs.c_str() + 5, nullptr, 10);
    return code >= 4000 && code < 5000;
  }
  return false;
}

// EPSG codes of projected CRSs in metres that DEMs and photos commonly
// come in: UTM zones on WGS 84 (326xx north, 327xx south), NAD27 (267xx)
// and NAD83 (269xx), ETRS89 (258xx), and Web Mercator.
bool isMetreEpsg(long code) {
  return (code >= 32601 && code <= 32660) || (code >= 32701 && code <= 32760) ||
         (code >= 26701 && code <= 26722) || (code >= 26901 && code <= 26923) ||
         (code >= 25828 && code <= 25838) || code == 3857;
}

}  // namespace

CrsUnitMetres metresPerCrsUnit(const std::string& crs, double latitude_deg) {
  if (isGeographic(crs)) {
    const double lat = std::clamp(latitude_deg, -89.0, 89.0) * (3.14159265358979323846 / 180.0);
    return {kMetresPerDegreeLonAtEquator * std::cos(lat), kMetresPerDegreeLat, false};
  }
  double factor = 1.0;
  if ((startsWith(crs, "PROJCS[") || startsWith(crs, "PROJCRS[")) && lastUnitFactor(crs, &factor)) {
    return {factor, factor, false};
  }
  if (startsWith(crs, "EPSG:") && isMetreEpsg(std::strtol(crs.c_str() + 5, nullptr, 10))) {
    return {1.0, 1.0, false};
  }
  return {};
}

uint32_t channelCount(PixelFormat format) {
  switch (format) {
    case PixelFormat::kR8: return 1;
    case PixelFormat::kR16: return 1;
    case PixelFormat::kRGB8: return 3;
    case PixelFormat::kRGBA8: return 4;
    case PixelFormat::kI16: return 1;
    case PixelFormat::kF32: return 1;
  }
  return 0;
}

uint32_t bytesPerPixel(PixelFormat format) {
  switch (format) {
    case PixelFormat::kR8: return 1;
    case PixelFormat::kR16: return 2;
    case PixelFormat::kRGB8: return 3;
    case PixelFormat::kRGBA8: return 4;
    case PixelFormat::kI16: return 2;
    case PixelFormat::kF32: return 4;
  }
  return 0;
}

const char* pixelFormatName(PixelFormat format) {
  switch (format) {
    case PixelFormat::kR8: return "R8";
    case PixelFormat::kR16: return "R16";
    case PixelFormat::kRGB8: return "RGB8";
    case PixelFormat::kRGBA8: return "RGBA8";
    case PixelFormat::kI16: return "I16";
    case PixelFormat::kF32: return "F32";
  }
  return "unknown";
}

bool isValidPixelFormat(uint32_t raw) { return raw >= 1 && raw <= 6; }

bool isColourFormat(PixelFormat format) {
  return format == PixelFormat::kR8 || format == PixelFormat::kR16 ||
         format == PixelFormat::kRGB8 || format == PixelFormat::kRGBA8;
}

bool isHeightFormat(PixelFormat format) {
  return format == PixelFormat::kR16 || format == PixelFormat::kI16 || format == PixelFormat::kF32;
}

const char* downsampleFilterName(DownsampleFilter filter) {
  switch (filter) {
    case DownsampleFilter::kBox: return "box";
    case DownsampleFilter::kLanczos3: return "lanczos3";
    case DownsampleFilter::kDecimate: return "decimate";
  }
  return "unknown";
}

size_t TileKeyHash::operator()(const TileKey& key) const noexcept {
  // TileKey has no padding (static_assert in types.h), so hashing the raw
  // bytes is well defined and mixes all three fields.
  return static_cast<size_t>(XXH3_64bits(&key, sizeof(key)));
}

bool PyramidGeometry::contains(const TileKey& key) const {
  if (key.level >= levels.size()) return false;
  const LevelInfo& level = levels[key.level];
  return key.x < level.tiles_x && key.y < level.tiles_y;
}

bool makePyramidGeometry(uint64_t width_px, uint64_t height_px, uint32_t tile_px,
                         PixelFormat format, PyramidGeometry* out) {
  if (width_px == 0 || height_px == 0 || tile_px == 0 || out == nullptr) return false;
  if (!isValidPixelFormat(static_cast<uint32_t>(format))) return false;
  PyramidGeometry geometry;
  geometry.width_px = width_px;
  geometry.height_px = height_px;
  geometry.tile_px = tile_px;
  geometry.format = format;
  // ceil(w / 2^l) without overflow: (w - 1) >> l, plus one.
  for (uint32_t level = 0; level < 64; ++level) {
    LevelInfo info;
    info.width_px = ((width_px - 1) >> level) + 1;
    info.height_px = ((height_px - 1) >> level) + 1;
    const uint64_t tiles_x = (info.width_px - 1) / tile_px + 1;
    const uint64_t tiles_y = (info.height_px - 1) / tile_px + 1;
    // Tile coordinates are 32-bit everywhere (TileKey); larger grids are
    // not representable.
    if (tiles_x > std::numeric_limits<uint32_t>::max() ||
        tiles_y > std::numeric_limits<uint32_t>::max()) {
      return false;
    }
    info.tiles_x = static_cast<uint32_t>(tiles_x);
    info.tiles_y = static_cast<uint32_t>(tiles_y);
    geometry.levels.push_back(info);
    if (tiles_x == 1 && tiles_y == 1) {
      *out = std::move(geometry);
      return true;
    }
  }
  return false;
}

}  // namespace clipstream
