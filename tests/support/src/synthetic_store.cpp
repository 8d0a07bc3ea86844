#include <clipstream/testing/synthetic_store.h>

#include <array>

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

Status writeSyntheticStore(const std::string& path, const PyramidGeometry& geometry,
                           const WriterOptions& options, ConstantTiles constant) {
  return writeStore(path, geometry, options, [&](const TileKey& key, std::vector<uint8_t>* pixels) {
    *pixels = syntheticTile(geometry, key, constant);
    return Status::ok();
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
