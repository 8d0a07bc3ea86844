// Tile sources and images the streamer's and the renderer's tests share.
// Header-only: a binary that includes it links clipstream::streamer itself.
//
// Thread rule: the functions may be called from any thread;
// writeStoreFromSource() calls source.fetch() on the calling thread only.
#pragma once

#include <clipstream/streamer/tile_source.h>
#include <clipstream/testing/synthetic_store.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace clipstream::test {

// The procedural source over a square texture of `side_px` texels.
inline std::shared_ptr<TileSource> procedural(uint64_t side_px, uint32_t tile_px = 128) {
  ProceduralSpec spec;
  spec.width_px = spec.height_px = side_px;
  spec.tile_px = tile_px;
  return makeProceduralSource(spec);
}

// A width x height RGBA8 image (top row first) whose texels encode their
// position: smooth waves in R and G plus an 8-texel checker in B, so any
// misplaced tile or texel shows in a comparison. A = 255.
inline std::vector<uint8_t> patternImage(uint32_t width_px, uint32_t height_px) {
  std::vector<uint8_t> rgba(size_t(width_px) * height_px * 4);
  for (uint32_t y = 0; y < height_px; ++y) {
    for (uint32_t x = 0; x < width_px; ++x) {
      uint8_t* p = rgba.data() + (size_t(y) * width_px + x) * 4;
      p[0] = uint8_t(128 + 100 * std::sin(x * 0.071) * std::cos(y * 0.053));
      p[1] = uint8_t(128 + 90 * std::sin((x + 2.0 * y) * 0.019));
      p[2] = ((x / 8 + y / 8) & 1) ? 200 : 60;
      p[3] = 255;
    }
  }
  return rgba;
}

// Writes every tile of `source` into a new store at `path` with the
// writer's default encoding (zstd, left-delta predictor) and no fsync.
// kInvalidArgument unless the source's geometry is RGBA8 (what fetch()
// returns); otherwise writeStore()'s errors, a failed fetch included.
inline Status writeStoreFromSource(TileSource& source, const std::string& path) {
  const PyramidGeometry& geometry = source.geometry();
  if (geometry.format != PixelFormat::kRGBA8)
    return Status::error(ErrorCode::kInvalidArgument, "writeStoreFromSource: source is not RGBA8");
  WriterOptions options;
  options.fsync = false;
  return writeStore(path, geometry, options, [&](const TileKey& key, std::vector<uint8_t>* pixels) {
    return source.fetch(key, pixels);
  });
}

}  // namespace clipstream::test
