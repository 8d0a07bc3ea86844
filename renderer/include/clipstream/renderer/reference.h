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
// tests; fetch failures give magenta texels).
TexelFunction texelsFromSource(std::shared_ptr<TileSource> source);

// PSNR over RGB (alpha ignored) of two equally sized RGBA8 images, in dB;
// +infinity when identical. `mask` (optional, one byte per pixel) limits
// the comparison to pixels where it is non-zero.
double psnrRgb(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b,
               const std::vector<uint8_t>* mask = nullptr);

// Largest absolute difference of any RGB channel.
int maxAbsDiffRgb(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b);

// An in-memory TileSource over an RGBA8 image (top row first): level 0 is
// the image, each coarser level the 2x2 box average of the one below (edge
// texels repeated for odd sizes), tile padding is black. For tests,
// benchmarks and clipstream-view's demo mode.
std::shared_ptr<TileSource> makeImageSource(std::vector<uint8_t> rgba, uint32_t width_px,
                                            uint32_t height_px, uint32_t tile_px);

}  // namespace clipstream
