#include <clipstream/testing/synthetic_store.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <utility>

namespace clipstream::test {
namespace {

// The stamp: marker, level, x and y little-endian, then a 16-bit check of
// those ten bytes, one byte per pixel of row 0.
constexpr uint32_t kStampPixels = 12;
constexpr uint8_t kStampMarker = 0xC5;
using Stamp = std::array<uint8_t, kStampPixels>;

// The byte of a pixel that a store source keeps in R (and G, B) when it
// converts to RGBA8: R16 keeps its high byte, every other format its first.
uint32_t keyByte(PixelFormat format) { return format == PixelFormat::kR16 ? 1 : 0; }

uint16_t stampCheck(const uint8_t* bytes, size_t count) {
  uint32_t h = 2166136261u;  // FNV-1a, folded to 16 bits
  for (size_t i = 0; i < count; ++i) h = (h ^ bytes[i]) * 16777619u;
  return uint16_t(h ^ (h >> 16));
}

Stamp stampOf(const TileKey& key) {
  Stamp s{};
  s[0] = kStampMarker;
  s[1] = uint8_t(key.level);
  for (int i = 0; i < 4; ++i) {
    s[2 + i] = uint8_t(key.x >> (8 * i));
    s[6 + i] = uint8_t(key.y >> (8 * i));
  }
  const uint16_t check = stampCheck(s.data(), 10);
  s[10] = uint8_t(check);
  s[11] = uint8_t(check >> 8);
  return s;
}

}  // namespace

bool isConstantTile(const TileKey& key) { return (key.x * 7 + key.y * 3 + key.level) % 5 == 0; }

void syntheticPixel(PixelFormat format, const TileKey& key, uint32_t px, uint32_t py, uint8_t* out,
                    ConstantTiles constant) {
  const uint32_t bpp = bytesPerPixel(format);
  const bool flat = constant == ConstantTiles::kSome && isConstantTile(key);
  const uint32_t base = key.level * 41 + key.x * 13 + key.y * 29;
  const uint32_t place = flat ? 0 : px * 3 + py * 5 + ((px * py) >> 4);
  for (uint32_t c = 0; c < bpp; ++c) {
    const uint32_t v = base + place + c * 53;
    out[c] = uint8_t(v ^ (v >> 8));
  }
  if (!flat && py == 0 && px < kStampPixels) out[keyByte(format)] = stampOf(key)[px];
}

void syntheticRgba(PixelFormat format, const TileKey& key, uint32_t px, uint32_t py,
                   uint8_t rgba[4], ConstantTiles constant) {
  uint8_t raw[4] = {0, 0, 0, 0};
  syntheticPixel(format, key, px, py, raw, constant);
  switch (format) {
    case PixelFormat::kR8: rgba[0] = rgba[1] = rgba[2] = raw[0]; rgba[3] = 255; break;
    case PixelFormat::kR16: rgba[0] = rgba[1] = rgba[2] = raw[1]; rgba[3] = 255; break;
    case PixelFormat::kRGB8: rgba[0] = raw[0]; rgba[1] = raw[1]; rgba[2] = raw[2]; rgba[3] = 255; break;
    case PixelFormat::kRGBA8: for (int c = 0; c < 4; ++c) rgba[c] = raw[c]; break;
    case PixelFormat::kI16:
    case PixelFormat::kF32: break;  // heights: no colour
  }
}

std::vector<uint8_t> syntheticTile(const PyramidGeometry& geometry, const TileKey& key,
                                   ConstantTiles constant) {
  const uint32_t bpp = bytesPerPixel(geometry.format);
  std::vector<uint8_t> pixels(geometry.tileBytes());
  for (uint32_t py = 0; py < geometry.tile_px; ++py)
    for (uint32_t px = 0; px < geometry.tile_px; ++px)
      syntheticPixel(geometry.format, key, px, py,
                     &pixels[(size_t(py) * geometry.tile_px + px) * bpp], constant);
  return pixels;
}

bool syntheticTileKey(PixelFormat format, std::span<const uint8_t> pixels, TileKey* key) {
  const uint32_t bpp = bytesPerPixel(format);
  if (pixels.size() < size_t(kStampPixels) * bpp) return false;
  Stamp s{};
  for (uint32_t i = 0; i < kStampPixels; ++i) s[i] = pixels[size_t(i) * bpp + keyByte(format)];
  const uint16_t check = stampCheck(s.data(), 10);
  if (s[0] != kStampMarker || s[10] != uint8_t(check) || s[11] != uint8_t(check >> 8)) return false;
  TileKey found;
  found.level = s[1];
  for (int i = 0; i < 4; ++i) {
    found.x |= uint32_t(s[2 + i]) << (8 * i);
    found.y |= uint32_t(s[6 + i]) << (8 * i);
  }
  *key = found;
  return true;
}

Status writeStore(const std::string& path, const PyramidGeometry& geometry,
                  const WriterOptions& options, const TileFill& fill) {
  std::unique_ptr<TileStoreWriter> writer;
  if (Status s = TileStoreWriter::create(path, geometry, options, &writer); !s) return s;
  std::vector<uint8_t> pixels;
  for (uint32_t level = 0; level < geometry.levelCount(); ++level) {
    for (uint32_t y = 0; y < geometry.levels[level].tiles_y; ++y) {
      for (uint32_t x = 0; x < geometry.levels[level].tiles_x; ++x) {
        const TileKey key{level, x, y};
        if (Status s = fill(key, &pixels); !s) return s;
        EncodedTile encoded;
        if (Status s = encodeTile(geometry, options.encoding, key, pixels, &encoded); !s) return s;
        if (Status s = writer->write(std::move(encoded)); !s) return s;
      }
    }
  }
  return writer->finish();
}

Status writeElevationStore(const std::string& path, uint64_t w, uint64_t h,
                           const std::function<float(uint64_t x, uint64_t y)>& height) {
  PyramidGeometry g;
  if (!makePyramidGeometry(w, h, 128, PixelFormat::kF32, &g))
    return Status::error(ErrorCode::kInvalidArgument, "writeElevationStore: bad size");
  WriterOptions options;
  options.fsync = false;
  options.encoding.filter = DownsampleFilter::kDecimate;
  options.elevation.present = true;
  std::unique_ptr<TileStoreWriter> writer;
  if (Status s = TileStoreWriter::create(path, g, options, &writer); !s) return s;
  float lo = INFINITY, hi = -INFINITY;
  const uint32_t t = g.tile_px;
  // Bounds of the previous (finer) level's tiles, merged into their
  // parents: a tile's bounds hold all level-0 ground under it.
  std::vector<std::pair<float, float>> finer;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    std::vector<std::pair<float, float>> here(size_t(g.levels[l].tiles_x) * g.levels[l].tiles_y);
    for (uint32_t ty = 0; ty < g.levels[l].tiles_y; ++ty)
      for (uint32_t tx = 0; tx < g.levels[l].tiles_x; ++tx) {
        std::vector<uint8_t> pixels(g.tileBytes());
        float tmin = INFINITY, tmax = -INFINITY;
        for (uint32_t y = 0; y < t; ++y)
          for (uint32_t x = 0; x < t; ++x) {
            const uint64_t sx = std::min<uint64_t>((uint64_t(tx) * t + x) << l, w - 1);
            const uint64_t sy = std::min<uint64_t>((uint64_t(ty) * t + y) << l, h - 1);
            const float v = height(sx, sy);
            std::memcpy(pixels.data() + (size_t(y) * t + x) * 4, &v, 4);
            tmin = std::min(tmin, v), tmax = std::max(tmax, v);
          }
        if (l > 0)
          for (uint32_t cy = 2 * ty; cy < std::min(2 * ty + 2, g.levels[l - 1].tiles_y); ++cy)
            for (uint32_t cx = 2 * tx; cx < std::min(2 * tx + 2, g.levels[l - 1].tiles_x); ++cx) {
              const auto& c = finer[size_t(cy) * g.levels[l - 1].tiles_x + cx];
              tmin = std::min(tmin, c.first), tmax = std::max(tmax, c.second);
            }
        here[size_t(ty) * g.levels[l].tiles_x + tx] = {tmin, tmax};
        lo = std::min(lo, tmin), hi = std::max(hi, tmax);
        // The tile's geometric error, as the tiler records it: the largest
        // distance of the level-0 heights under it from the bilinear
        // surface of its level's samples (here exactly, by brute force).
        float error = 0.0f;
        const uint64_t span = uint64_t(t) << l;
        auto sample = [&](uint64_t i, uint64_t j) {
          return double(height(std::min<uint64_t>(i << l, w - 1), std::min<uint64_t>(j << l, h - 1)));
        };
        for (uint64_t y = uint64_t(ty) * span; l > 0 && y < std::min<uint64_t>((uint64_t(ty) + 1) * span, h); ++y)
          for (uint64_t x = uint64_t(tx) * span; x < std::min<uint64_t>((uint64_t(tx) + 1) * span, w); ++x) {
            const uint64_t i = x >> l, j = y >> l;
            const double u = double(x - (i << l)) / double(1u << l), v = double(y - (j << l)) / double(1u << l);
            const double b = (1 - u) * (1 - v) * sample(i, j) + u * (1 - v) * sample(i + 1, j) +
                             (1 - u) * v * sample(i, j + 1) + u * v * sample(i + 1, j + 1);
            error = std::max(error, float(std::abs(double(height(x, y)) - b)));
          }
        EncodedTile encoded;
        if (Status s = encodeTile(g, options.encoding, {l, tx, ty}, pixels, &encoded); !s) return s;
        encoded.location.min_height = tmin;
        encoded.location.max_height = tmax;
        encoded.location.error = error;
        if (Status s = writer->write(std::move(encoded)); !s) return s;
      }
    finer = std::move(here);
  }
  if (Status s = writer->setElevationFigures(0, 0.0, lo, hi); !s) return s;
  return writer->finish();
}

Status writeSyntheticStore(const std::string& path, const PyramidGeometry& geometry,
                           const WriterOptions& options, ConstantTiles constant) {
  return writeStore(path, geometry, options, [&](const TileKey& key, std::vector<uint8_t>* pixels) {
    *pixels = syntheticTile(geometry, key, constant);
    return okStatus();
  });
}

Status writeSyntheticStore(const std::string& path, const SyntheticStoreSpec& spec) {
  PyramidGeometry geometry;
  if (!makePyramidGeometry(spec.width_px, spec.height_px, spec.tile_px, spec.format, &geometry)) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "writeSyntheticStore: no pyramid of " + std::to_string(spec.width_px) +
                             " x " + std::to_string(spec.height_px) + " px in " +
                             std::to_string(spec.tile_px) + " px tiles");
  }
  WriterOptions options;
  options.fsync = false;
  return writeSyntheticStore(path, geometry, options, spec.constant);
}

}  // namespace clipstream::test
