// Pixel conversion to the GPU layout. Pure functions; thread-safe.
#pragma once

#include <clipstream/store/types.h>

#include <cstddef>
#include <cstdint>
#include <span>

namespace clipstream {

// Converts pixel_count pixels of `format` (as stored: interleaved, 16-bit
// little-endian) to RGBA8 at dst (pixel_count * 4 bytes, caller-owned).
// R8/R16 become grey (R16 keeps the high byte), RGB8 gets A = 255.
// kInvalidArgument if src is too small; kUnsupported for unknown formats.
Status convertToRgba8(PixelFormat format, std::span<const uint8_t> src, uint8_t* dst,
                      size_t pixel_count);

}  // namespace clipstream
