// CPU tile fills shared by the stack's and the pool's pyramid fallbacks.
//
// Thread-safe: pure functions.
#pragma once

#include <cstdint>

namespace clipstream {

// Magnifies the w x h texel region at (x0, y0) of `src` (RGBA8 rows of
// `src_stride` texels) bilinearly onto a tile_px x tile_px RGBA8 tile:
// texel centres map 2:1 (a parent's quarter over its child), clamped to
// the region. Writes red, green and blue; alpha is left as it is.
void magnifyQuarter(const uint8_t* src, uint32_t src_stride, uint32_t x0, uint32_t y0, uint32_t w,
                    uint32_t h, uint32_t tile_px, uint8_t* tile);

}  // namespace clipstream
