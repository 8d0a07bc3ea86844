// BC1 (S3TC DXT1, RGB) tiles: the one definition of their bytes, the
// encoder (stb_dxt, Debian's libstb-dev) and a CPU decoder.
//
// A BC1 tile of tile_px x tile_px texels (tile_px a multiple of 4) is
// (tile_px / 4)^2 blocks of 8 bytes, row-major: block (bx, by) covers texels
// [4 bx, 4 bx + 4) x [4 by, 4 by + 4) (row 0 = the tile's top row, as in an
// RGBA8 tile) and starts at byte 8 (by * tile_px / 4 + bx). A block is two
// little-endian RGB565 end points c0, c1 and 32 bits of 2-bit indices
// (texel (i, j) of the block at bits 2 (4 j + i)), as
// EXT_texture_compression_s3tc defines COMPRESSED_RGB_S3TC_DXT1_EXT, so the
// tile is uploaded to such a texture as it is.
//
// Thread-safe: pure functions only.
#pragma once

#include <clipstream/store/types.h>

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace clipstream {

inline constexpr uint32_t kBc1BlockPx = 4;     // texels a block side
inline constexpr uint32_t kBc1BlockBytes = 8;  // bytes a block

// stb_dxt's refinement: its "high quality" mode (two refinement passes
// instead of one) costs about a tenth more CPU than the normal mode and is
// closer to the source (bench_streamer_bc1, docs/benchmarks.md, "BC1 tiles").
inline constexpr bool kBc1HighQuality = true;

// Bytes of one BC1 tile: (tile_px / 4)^2 * 8. tile_px must be a multiple of 4.
inline size_t bc1TileBytes(uint32_t tile_px) {
  const size_t blocks = size_t(tile_px / kBc1BlockPx);
  return blocks * blocks * kBc1BlockBytes;
}

// Encodes an RGBA8 tile (tile_px^2 * 4 bytes, top row first; alpha is
// ignored: BC1 here is opaque RGB) into *blocks (resized to
// bc1TileBytes()), with stb_dxt's high-quality mode or its normal one.
// kInvalidArgument if tile_px is 0 or not a multiple of 4, or `rgba` has
// the wrong size.
Status encodeBc1Tile(std::span<const uint8_t> rgba, uint32_t tile_px, std::vector<uint8_t>* blocks,
                     bool high_quality = kBc1HighQuality);

// Decodes one 8-byte block into 16 RGBA8 texels (row-major, alpha 255), as
// the S3TC extension specifies for COMPRESSED_RGB_S3TC_DXT1_EXT: end points
// expanded from 565 by bit replication; when c0 > c1 the two middle colours
// are (2 c0 + c1) / 3 and (c0 + 2 c1) / 3, otherwise (c0 + c1) / 2 and
// black (integer division, no rounding bias: Mesa's decoder and stb_dxt's
// encoder both use it).
void decodeBc1Block(const uint8_t block[kBc1BlockBytes], uint8_t rgba[16 * 4]);

// Decodes a whole BC1 tile into *rgba (resized to tile_px^2 * 4).
// kInvalidArgument if tile_px is 0 or not a multiple of 4, or `blocks` has
// the wrong size.
Status decodeBc1Tile(std::span<const uint8_t> blocks, uint32_t tile_px, std::vector<uint8_t>* rgba);

}  // namespace clipstream
