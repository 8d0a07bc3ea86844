// CPU reference of what the ground shader draws, computed from the source
// pyramid directly (no clipmap, no residency): one ray per pixel, the same
// level choice from the level-0 texel derivatives (as the GPU's 2x2 pixel
// quads difference them), bilinear within a level and linear across levels.
// Used by tests to judge GPU frames with PSNR.
//
// Thread-safe: pure functions; `texel` is called from the calling thread.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

namespace clipstream {

// Writes the RGBA8 value of texel (x, y) of `level`; x and y are already
// clamped to the level's tile grid.
using TexelFunction = std::function<void(uint32_t level, uint64_t x, uint64_t y, uint8_t rgba[4])>;

struct ReferenceOptions {
  uint32_t min_level = 0;  // MaxTextureLOD / forced fallback: never sample finer
};

// Renders viewport.width_px * height_px RGBA8 pixels, top row first, into
// *rgba. Pixels whose ray misses the texture get renderer_config::kSkyRgba.
void renderReference(const PyramidGeometry& geometry, const TexelFunction& texel,
                     const Camera& camera, const Viewport& viewport,
                     const ReferenceOptions& options, std::vector<uint8_t>* rgba);

// A TexelFunction over a TileSource, caching whole tiles it fetched (for
// tests; fetch failures give magenta texels). A BC1 source's blocks are
// decoded (decodeBc1Tile()): the texels a GPU samples from them.
TexelFunction texelsFromSource(std::shared_ptr<TileSource> source);

}  // namespace clipstream
