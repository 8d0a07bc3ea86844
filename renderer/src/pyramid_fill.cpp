// The colour stack's coarse pyramid (kStack): its tiles in the pyramid
// layer's mip chain, loaded once, and the fallbacks that fill a tile the
// source could not give (from its parent, its children, or mid grey), on
// the GPU for RGBA8 and on the CPU for BC1. The CPU fill is shared with
// the paged pool's pyramid (tile_fill.h).
#include "clipmap_renderer_impl.h"

#include "gl.h"
#include "tile_fill.h"

#include <clipstream/streamer/bc1.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace clipstream {

void ClipmapRenderer::Impl::uploadPyramid(const TileKey& key, const uint8_t* pixels) {
  // Level pyramid_level + k is mip k of the pyramid layer. It has fewer
  // tiles than the slot period, so slot == tile position (unless a test
  // bias shifts it), and its tiles may overhang the smaller mips: only the
  // part inside the mip is uploaded (the rest is padding).
  const uint32_t tp = m_geometry.tile_px;
  const uint32_t mip = key.level - m_config.pyramid_level;
  if (mip >= m_mips) return;
  const uint64_t size = (uint64_t(m_slots) * tp) >> mip;
  const uint64_t x = uint64_t(slot(key.x, m_slots)) * tp, y = uint64_t(slot(key.y, m_slots)) * tp;
  if (x >= size || y >= size) return;
  const uint32_t w = uint32_t(std::min<uint64_t>(tp, size - x));
  const uint32_t h = uint32_t(std::min<uint64_t>(tp, size - y));
  if (compressed()) {
    // The blocks covering w x h (a partial width or height reaches the
    // mip's edge, where GL takes a partial block), packed row by row.
    const uint32_t row_blocks = tp / kBc1BlockPx;
    const uint32_t bw = (w + kBc1BlockPx - 1) / kBc1BlockPx, bh = (h + kBc1BlockPx - 1) / kBc1BlockPx;
    std::vector<uint8_t> packed;
    const uint8_t* data = pixels;
    if (bw != row_blocks || bh != row_blocks) {
      packed.resize(size_t(bw) * bh * kBc1BlockBytes);
      for (uint32_t by = 0; by < bh; ++by)
        std::memcpy(packed.data() + size_t(by) * bw * kBc1BlockBytes,
                    pixels + size_t(by) * row_blocks * kBc1BlockBytes, size_t(bw) * kBc1BlockBytes);
      data = packed.data();
    }
    for (uint32_t set = 0; set < stackSets(); ++set)
      glCompressedTextureSubImage3D(m_stack[set], GLint(mip), GLint(x), GLint(y), GLint(m_config.pyramid_level),
                                    GLsizei(w), GLsizei(h), 1, kBc1Format,
                                    GLsizei(size_t(bw) * bh * kBc1BlockBytes), data);
    return;
  }
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, GLint(tp));
  for (uint32_t set = 0; set < stackSets(); ++set)
    glTextureSubImage3D(m_stack[set], GLint(mip), GLint(x), GLint(y), GLint(m_config.pyramid_level),
                        GLsizei(w), GLsizei(h), 1, GL_RGBA, GL_UNSIGNED_BYTE, pixels);
  glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
}

uint32_t ClipmapRenderer::Impl::loadPyramid(const PyramidTileFn& tile) {
  uint32_t failed = 0;
  for (uint32_t l = m_config.pyramid_level; l < m_geometry.levelCount(); ++l)
    for (uint32_t y = 0; y < m_geometry.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < m_geometry.levels[l].tiles_x; ++x) {
        const TileKey key{l, x, y};
        if (auto px = tile(key)) uploadTile(key, std::move(px));
        else ++failed;
      }
  if (paged()) fillMissingPyramidPages();
  else fillMissingPyramidTiles();
  return failed;
}

uint32_t ClipmapRenderer::Impl::fillMissingPyramidTiles() {
  if (m_pyramid_missing == 0) return 0;
  const uint32_t pyramid = m_config.pyramid_level;
  const uint64_t tp = m_geometry.tile_px;
  // Levels past the stored mips are never sampled (draw() clamps to them).
  const uint32_t levels = std::min(m_geometry.levelCount() - pyramid, m_mips);
  auto have = [&](uint32_t mip, int64_t x, int64_t y) -> uint8_t* {
    const LevelInfo& info = m_geometry.levels[pyramid + mip];
    if (x < 0 || y < 0 || x >= int64_t(info.tiles_x) || y >= int64_t(info.tiles_y)) return nullptr;
    return &m_pyramid_have[m_pyramid_first[mip] + size_t(y) * info.tiles_x + size_t(x)];
  };
  GLuint fbo[2] = {0, 0};
  glCreateFramebuffers(2, fbo);
  glNamedFramebufferReadBuffer(fbo[0], GL_COLOR_ATTACHMENT0);
  const GLint layer = GLint(pyramid);
  auto blit = [&](uint32_t src_mip, const GLint src[4], uint32_t dst_mip, const GLint dst[4]) {
    for (uint32_t set = 0; set < stackSets(); ++set) {
      glNamedFramebufferTextureLayer(fbo[0], GL_COLOR_ATTACHMENT0, m_stack[set], GLint(src_mip),
                                     layer);
      glNamedFramebufferTextureLayer(fbo[1], GL_COLOR_ATTACHMENT0, m_stack[set], GLint(dst_mip),
                                     layer);
      glBlitNamedFramebuffer(fbo[0], fbo[1], src[0], src[1], src[2], src[3], dst[0], dst[1], dst[2],
                             dst[3], GL_COLOR_BUFFER_BIT, GL_LINEAR);
    }
  };
  uint32_t filled = 0;
  for (uint32_t mip = levels; mip-- > 0;) {
    const LevelInfo& info = m_geometry.levels[pyramid + mip];
    const uint64_t size = (uint64_t(m_slots) * tp) >> mip;
    for (uint32_t y = 0; y < info.tiles_y; ++y) {
      for (uint32_t x = 0; x < info.tiles_x; ++x) {
        uint8_t* mine = have(mip, x, y);
        if (*mine) continue;
        *mine = 1;
        --m_pyramid_missing;
        const uint64_t x0 = uint64_t(slot(x, m_slots)) * tp, y0 = uint64_t(slot(y, m_slots)) * tp;
        if (x0 >= size || y0 >= size) continue;  // beyond the mip: padding only
        const GLint dst[4] = {GLint(x0), GLint(y0), GLint(std::min(x0 + tp, size)),
                              GLint(std::min(y0 + tp, size))};
        ++filled;
        const uint8_t* parent = mip + 1 < levels ? have(mip + 1, x / 2, y / 2) : nullptr;
        bool children = mip > 0;
        for (int64_t j = 0; j < 2 && children; ++j)
          for (int64_t i = 0; i < 2 && children; ++i) {
            const uint8_t* c = have(mip - 1, 2 * int64_t(x) + i, 2 * int64_t(y) + j);
            children = c == nullptr || *c != 0;
          }
        if (compressed()) {
          const Fill fill = parent != nullptr && *parent ? Fill::kFromParent
                            : children                   ? Fill::kFromChildren
                                                         : Fill::kGrey;
          fillPyramidTileBc1({pyramid + mip, x, y}, fill);
        } else if (parent != nullptr && *parent) {
          const GLint src[4] = {dst[0] / 2, dst[1] / 2, dst[2] / 2, dst[3] / 2};
          blit(mip + 1, src, mip, dst);
        } else if (children) {
          // The coarsest stored level has no parent: average its children.
          const uint64_t below = size * 2;
          auto twice = [below](uint64_t v) { return GLint(std::min<uint64_t>(2 * v, below)); };
          const GLint src[4] = {twice(x0), twice(y0), twice(uint64_t(dst[2])),
                                twice(uint64_t(dst[3]))};
          blit(mip - 1, src, mip, dst);
        } else {
          const uint8_t grey[4] = {128, 128, 128, 255};
          for (uint32_t set = 0; set < stackSets(); ++set)
            glClearTexSubImage(m_stack[set], GLint(mip), dst[0], dst[1], layer, dst[2] - dst[0],
                               dst[3] - dst[1], 1, GL_RGBA, GL_UNSIGNED_BYTE, grey);
        }
      }
    }
  }
  glDeleteFramebuffers(2, fbo);
  m_changed = true;
  return filled;
}

std::vector<uint8_t> ClipmapRenderer::Impl::readPyramidRegion(uint32_t mip, uint32_t x, uint32_t y, uint32_t w,
                                                         uint32_t h) const {
  const uint32_t bw = (w + kBc1BlockPx - 1) / kBc1BlockPx, bh = (h + kBc1BlockPx - 1) / kBc1BlockPx;
  std::vector<uint8_t> blocks(size_t(bw) * bh * kBc1BlockBytes);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glGetCompressedTextureSubImage(m_stack[0], GLint(mip), GLint(x), GLint(y), GLint(m_config.pyramid_level),
                                 GLsizei(w), GLsizei(h), 1, GLsizei(blocks.size()), blocks.data());
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  std::vector<uint8_t> rgba(size_t(w) * h * 4);
  uint8_t texels[16 * 4];
  for (uint32_t by = 0; by < bh; ++by)
    for (uint32_t bx = 0; bx < bw; ++bx) {
      decodeBc1Block(blocks.data() + (size_t(by) * bw + bx) * kBc1BlockBytes, texels);
      for (uint32_t j = 0; j < kBc1BlockPx && by * 4 + j < h; ++j)
        for (uint32_t i = 0; i < kBc1BlockPx && bx * 4 + i < w; ++i)
          std::memcpy(&rgba[(size_t(by * 4 + j) * w + bx * 4 + i) * 4], &texels[(j * 4 + i) * 4], 4);
    }
  return rgba;
}

void ClipmapRenderer::Impl::fillPyramidTileBc1(const TileKey& key, Fill fill) {
  // The RGBA8 fallbacks of fillMissingPyramidTiles() (a linear blit of the
  // parent's quarter, a blit of the children's 2x2 average, mid grey) done
  // on the CPU over decoded blocks, then encoded and uploaded as a tile.
  const uint32_t tp = m_geometry.tile_px;
  const uint32_t mip = key.level - m_config.pyramid_level;
  const uint64_t size = (uint64_t(m_slots) * tp) >> mip;
  const uint64_t x0 = uint64_t(slot(key.x, m_slots)) * tp, y0 = uint64_t(slot(key.y, m_slots)) * tp;
  std::vector<uint8_t> tile(size_t(tp) * tp * 4, 128);
  for (size_t i = 3; i < tile.size(); i += 4) tile[i] = 255;
  if (fill == Fill::kFromParent) {
    // The parent's quarter over this tile, clamped to the parent mip.
    const uint64_t psize = size / 2;
    const uint32_t px = uint32_t(x0 / 2), py = uint32_t(y0 / 2);
    const uint32_t pw = uint32_t(std::min<uint64_t>(tp / 2, psize - px));
    const uint32_t ph = uint32_t(std::min<uint64_t>(tp / 2, psize - py));
    const std::vector<uint8_t> src = readPyramidRegion(mip + 1, px, py, pw, ph);
    magnifyQuarter(src.data(), pw, 0, 0, pw, ph, tp, tile.data());
  } else if (fill == Fill::kFromChildren) {
    // The four children's texels, 2x2 averaged, clamped to the finer mip.
    const uint64_t csize = size * 2;
    const uint32_t cx = uint32_t(std::min(x0 * 2, csize)), cy = uint32_t(std::min(y0 * 2, csize));
    const uint32_t cw = uint32_t(std::min<uint64_t>(2 * uint64_t(tp), csize - cx));
    const uint32_t ch = uint32_t(std::min<uint64_t>(2 * uint64_t(tp), csize - cy));
    if (cw >= 2 && ch >= 2) {
      const std::vector<uint8_t> src = readPyramidRegion(mip - 1, cx, cy, cw, ch);
      for (uint32_t j = 0; j < tp && 2 * j + 1 < ch; ++j)
        for (uint32_t i = 0; i < tp && 2 * i + 1 < cw; ++i)
          for (int c = 0; c < 3; ++c) {
            auto at = [&](uint32_t u, uint32_t v) { return uint32_t(src[(size_t(v) * cw + u) * 4 + size_t(c)]); };
            tile[(size_t(j) * tp + i) * 4 + size_t(c)] =
                uint8_t((at(2 * i, 2 * j) + at(2 * i + 1, 2 * j) + at(2 * i, 2 * j + 1) + at(2 * i + 1, 2 * j + 1) + 2) / 4);
          }
    }
  }
  std::vector<uint8_t> blocks;
  if (encodeBc1Tile(tile, tp, &blocks)) uploadPyramid(key, blocks.data());
}

void magnifyQuarter(const uint8_t* src, uint32_t src_stride, uint32_t x0, uint32_t y0, uint32_t w,
                    uint32_t h, uint32_t tile_px, uint8_t* tile) {
  for (uint32_t j = 0; j < tile_px; ++j)
    for (uint32_t i = 0; i < tile_px; ++i) {
      // Texel centres of the magnified tile in the region's texels.
      const double sx = std::clamp((i + 0.5) * 0.5 - 0.5, 0.0, double(w - 1));
      const double sy = std::clamp((j + 0.5) * 0.5 - 0.5, 0.0, double(h - 1));
      const uint32_t ix = uint32_t(sx), iy = uint32_t(sy);
      const uint32_t ix1 = std::min(ix + 1, w - 1), iy1 = std::min(iy + 1, h - 1);
      const double fx = sx - ix, fy = sy - iy;
      for (int c = 0; c < 3; ++c) {
        auto at = [&](uint32_t u, uint32_t v) {
          return double(src[(size_t(y0 + v) * src_stride + x0 + u) * 4 + size_t(c)]);
        };
        const double v = (at(ix, iy) * (1 - fx) + at(ix1, iy) * fx) * (1 - fy) +
                         (at(ix, iy1) * (1 - fx) + at(ix1, iy1) * fx) * fy;
        tile[(size_t(j) * tile_px + i) * 4 + size_t(c)] = uint8_t(std::lround(v));
      }
    }
}

}  // namespace clipstream
