#include "terrain_height_stack.h"

#include "gl.h"
#include "gl_util.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace clipstream {

uint32_t TerrainHeightStack::slotsFor(const PyramidGeometry& heights, const TerrainConfig& config) {
  if (config.full_resolution) return std::max(heights.levels[0].tiles_x, heights.levels[0].tiles_y);
  const uint32_t n = config.ring_cells, tile = heights.tile_px;
  return std::max((n + 3 + tile - 1) / tile + 2, (config.clip_tiles / 2) * 2 + 2);
}

Status TerrainHeightStack::create(const PyramidGeometry& heights, uint32_t slots, uint32_t layers,
                                  std::unique_ptr<TerrainHeightStack>* out) {
  out->reset();
  std::unique_ptr<TerrainHeightStack> s(new TerrainHeightStack());
  s->m_geometry = heights;
  s->m_slots = slots;
  const uint32_t period = slots * heights.tile_px;
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  if (period > uint32_t(max_size)) {
    return Status::error(ErrorCode::kUnavailable, "terrain: height stack of " +
                                                      std::to_string(period) +
                                                      " texels exceeds GL_MAX_TEXTURE_SIZE");
  }
  gl_util::clearErrors();
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &s->m_texture);
  glTextureStorage3D(s->m_texture, 1, GL_R32F, GLsizei(period), GLsizei(period), GLsizei(layers));
  glTextureParameteri(s->m_texture, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(s->m_texture, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  const float zero = 0.0f;
  glClearTexImage(s->m_texture, 0, GL_RED, GL_FLOAT, &zero);
  s->m_texture_bytes = uint64_t(period) * period * 4 * uint64_t(layers);
  const size_t per_level = size_t(slots) * slots;
  s->m_slot_tile.assign(heights.levelCount(), std::vector<uint64_t>(per_level, kNoTile));
  s->m_slot_heights.assign(heights.levelCount(), std::vector<std::vector<float>>(per_level));
  s->m_slot_twist.assign(heights.levelCount(), std::vector<std::vector<float>>(per_level));
  s->m_slot_bounds.assign(heights.levelCount(), std::vector<glm::vec2>(per_level, glm::vec2(0.0f)));
  if (Status st = gl_util::checkCreated("the terrain's height stack (" +
                                        std::to_string(s->m_texture_bytes >> 20) + " MiB of R32F)");
      !st)
    return st;
  *out = std::move(s);
  return okStatus();
}

TerrainHeightStack::~TerrainHeightStack() { glDeleteTextures(1, &m_texture); }

void TerrainHeightStack::upload(const TileKey& key, const float* heights) {
  const uint32_t tile = m_geometry.tile_px;
  const uint32_t sx = slotOf(key.x), sy = slotOf(key.y);
  glTextureSubImage3D(m_texture, 0, GLint(sx * tile), GLint(sy * tile), GLint(key.level),
                      GLsizei(tile), GLsizei(tile), 1, GL_RED, GL_FLOAT, heights);
  const size_t slot = size_t(sy) * m_slots + sx;
  m_slot_tile[key.level][slot] = tileId(key.x, key.y);
  m_slot_heights[key.level][slot].assign(heights, heights + size_t(tile) * tile);
  const auto [lo, hi] = std::minmax_element(heights, heights + size_t(tile) * tile);
  m_slot_bounds[key.level][slot] = {*lo, *hi};
}

void TerrainHeightStack::storeTwist(const TileKey& key, const float* heights, uint32_t block_cells) {
  const uint32_t tile = m_geometry.tile_px, blocks = tile / block_cells;
  std::vector<float>& twist = m_slot_twist[key.level][slotIndex(key.x, key.y)];
  twist.assign(size_t(blocks) * blocks, 0.0f);
  for (uint32_t j = 0; j + 1 < tile; ++j)
    for (uint32_t i = 0; i + 1 < tile; ++i) {
      const float* a = heights + size_t(j) * tile + i;
      const float t = std::abs(a[0] - a[1] - a[tile] + a[tile + 1]) * 0.25f;
      float& b = twist[size_t(j / block_cells) * blocks + i / block_cells];
      b = std::max(b, t);
    }
}

bool TerrainHeightStack::sample(uint32_t level, int64_t i, int64_t j, float* h) const {
  const LevelInfo& info = m_geometry.levels[level];
  i = std::clamp<int64_t>(i, 0, int64_t(info.width_px) - 1);
  j = std::clamp<int64_t>(j, 0, int64_t(info.height_px) - 1);
  const int64_t tile = m_geometry.tile_px, tx = i / tile, ty = j / tile;
  if (!holds(level, tx, ty)) return false;
  *h = m_slot_heights[level][slotIndex(tx, ty)][size_t(j - ty * tile) * size_t(tile) + size_t(i - tx * tile)];
  return true;
}

glm::vec2 TerrainHeightStack::heightBounds(uint32_t ring_level, glm::i64vec2 s0, glm::i64vec2 s1) const {
  const uint32_t level = std::min(ring_level, m_geometry.levelCount() - 1);
  const int shift = int(ring_level - level);
  s0 *= int64_t(1) << shift;
  s1 *= int64_t(1) << shift;
  const LevelInfo& info = m_geometry.levels[level];
  const int64_t tile = m_geometry.tile_px;
  const int64_t tx0 = std::clamp<int64_t>(s0.x, 0, int64_t(info.width_px) - 1) / tile;
  const int64_t tx1 = std::clamp<int64_t>(s1.x, 0, int64_t(info.width_px) - 1) / tile;
  const int64_t ty0 = std::clamp<int64_t>(s0.y, 0, int64_t(info.height_px) - 1) / tile;
  const int64_t ty1 = std::clamp<int64_t>(s1.y, 0, int64_t(info.height_px) - 1) / tile;
  glm::vec2 b(INFINITY, -INFINITY);
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      // Not resident (the ring does not read it): no bound, never culled.
      if (!holds(level, tx, ty)) return {-INFINITY, INFINITY};
      const glm::vec2 t = tileBounds(level, tx, ty);
      b = {std::min(b.x, t.x), std::max(b.y, t.y)};
    }
  return b;
}

bool TerrainHeightStack::ringResident(uint32_t ring_level, const glm::i64vec2& ring_origin,
                                      uint32_t ring_cells) const {
  // A ring past the last stored level reads that level's samples 2^k apart.
  const uint32_t level = std::min(ring_level, m_geometry.levelCount() - 1);
  const int shift = int(ring_level - level);
  const glm::i64vec2 origin = ring_origin * (int64_t(1) << shift);
  const LevelInfo& info = m_geometry.levels[level];
  const int64_t tile = m_geometry.tile_px;
  const int64_t n = int64_t(ring_cells) << shift;
  auto tiles = [&](int64_t first, int64_t last, uint64_t size, int64_t* t0, int64_t* t1) {
    first = std::clamp<int64_t>(first, 0, int64_t(size) - 1);
    last = std::clamp<int64_t>(last, 0, int64_t(size) - 1);
    *t0 = first / tile;
    *t1 = last / tile;
  };
  int64_t tx0, tx1, ty0, ty1;
  tiles(origin.x - 1, origin.x + n + 1, info.width_px, &tx0, &tx1);
  tiles(origin.y - 1, origin.y + n + 1, info.height_px, &ty0, &ty1);
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx)
      if (!holds(level, tx, ty)) return false;
  return true;
}

}  // namespace clipstream
