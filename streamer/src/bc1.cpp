// BC1 tiles: stb_dxt's encoder (the one place its implementation is
// compiled) and the decoder the tests and the renderer's pyramid fill use.
// Layout: bc1.h.
#include <clipstream/streamer/bc1.h>

#include <cstring>  // stb_dxt uses memcpy without including it

#define STB_DXT_STATIC
#define STB_DXT_IMPLEMENTATION
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wshadow"
#endif
#include <stb/stb_dxt.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

namespace clipstream {
namespace {

Status checkTilePx(uint32_t tile_px) {
  if (tile_px == 0 || tile_px % kBc1BlockPx != 0)
    return Status::error(ErrorCode::kInvalidArgument,
                         "BC1 tiles need a tile size that is a multiple of 4 (got " +
                             std::to_string(tile_px) + ")");
  return okStatus();
}

// 565 -> 888 by bit replication.
void expand565(uint16_t c, uint8_t out[3]) {
  const uint32_t r = (c >> 11) & 31, g = (c >> 5) & 63, b = c & 31;
  out[0] = uint8_t((r << 3) | (r >> 2));
  out[1] = uint8_t((g << 2) | (g >> 4));
  out[2] = uint8_t((b << 3) | (b >> 2));
}

}  // namespace

Status encodeBc1Tile(std::span<const uint8_t> rgba, uint32_t tile_px, std::vector<uint8_t>* blocks,
                     bool high_quality) {
  if (Status s = checkTilePx(tile_px); !s) return s;
  if (rgba.size() != size_t(tile_px) * tile_px * 4)
    return Status::error(ErrorCode::kInvalidArgument,
                         "BC1 encode: " + std::to_string(rgba.size()) + " bytes is not an RGBA8 tile of " +
                             std::to_string(tile_px) + " px");
  const uint32_t n = tile_px / kBc1BlockPx;
  blocks->resize(bc1TileBytes(tile_px));
  uint8_t texels[16 * 4];
  for (uint32_t by = 0; by < n; ++by)
    for (uint32_t bx = 0; bx < n; ++bx) {
      for (uint32_t j = 0; j < 4; ++j)
        std::memcpy(texels + j * 16, rgba.data() + (size_t(by * 4 + j) * tile_px + bx * 4) * 4, 16);
      stb_compress_dxt_block(blocks->data() + (size_t(by) * n + bx) * kBc1BlockBytes, texels, 0,
                             high_quality ? STB_DXT_HIGHQUAL : STB_DXT_NORMAL);
    }
  return okStatus();
}

void decodeBc1Block(const uint8_t block[kBc1BlockBytes], uint8_t rgba[16 * 4]) {
  const uint16_t c0 = uint16_t(block[0] | (block[1] << 8));
  const uint16_t c1 = uint16_t(block[2] | (block[3] << 8));
  const uint32_t bits = uint32_t(block[4]) | (uint32_t(block[5]) << 8) | (uint32_t(block[6]) << 16) |
                        (uint32_t(block[7]) << 24);
  uint8_t colour[4][3];
  expand565(c0, colour[0]);
  expand565(c1, colour[1]);
  for (int k = 0; k < 3; ++k) {
    const int a = colour[0][k], b = colour[1][k];
    if (c0 > c1) {
      colour[2][k] = uint8_t((2 * a + b) / 3);
      colour[3][k] = uint8_t((a + 2 * b) / 3);
    } else {
      colour[2][k] = uint8_t((a + b) / 2);
      colour[3][k] = 0;
    }
  }
  for (uint32_t t = 0; t < 16; ++t) {
    const uint32_t code = (bits >> (2 * t)) & 3;
    rgba[t * 4 + 0] = colour[code][0];
    rgba[t * 4 + 1] = colour[code][1];
    rgba[t * 4 + 2] = colour[code][2];
    rgba[t * 4 + 3] = 255;
  }
}

Status decodeBc1Tile(std::span<const uint8_t> blocks, uint32_t tile_px, std::vector<uint8_t>* rgba) {
  if (Status s = checkTilePx(tile_px); !s) return s;
  if (blocks.size() != bc1TileBytes(tile_px))
    return Status::error(ErrorCode::kInvalidArgument,
                         "BC1 decode: " + std::to_string(blocks.size()) + " bytes is not a BC1 tile of " +
                             std::to_string(tile_px) + " px");
  const uint32_t n = tile_px / kBc1BlockPx;
  rgba->resize(size_t(tile_px) * tile_px * 4);
  uint8_t texels[16 * 4];
  for (uint32_t by = 0; by < n; ++by)
    for (uint32_t bx = 0; bx < n; ++bx) {
      decodeBc1Block(blocks.data() + (size_t(by) * n + bx) * kBc1BlockBytes, texels);
      for (uint32_t j = 0; j < 4; ++j)
        std::memcpy(rgba->data() + (size_t(by * 4 + j) * tile_px + bx * 4) * 4, texels + j * 16, 16);
    }
  return okStatus();
}

}  // namespace clipstream
