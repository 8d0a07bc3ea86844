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
                                  bool gradients, std::unique_ptr<TerrainHeightStack>* out) {
  out->reset();
  std::unique_ptr<TerrainHeightStack> s(new TerrainHeightStack());
  s->m_geometry = heights;
  s->m_slots = slots;
  s->m_layers = layers;
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
  if (gradients)
    if (Status st = s->enableGradients(); !st) return st;
  *out = std::move(s);
  return okStatus();
}

Status TerrainHeightStack::enableGradients() {
  if (m_gradients_texture != 0) return okStatus();
  const uint32_t slots = m_slots, period = slots * m_geometry.tile_px;
  const uint32_t layers = m_layers;
  gl_util::clearErrors();
  // Every sample's gradient.
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &m_gradients_texture);
  glTextureStorage3D(m_gradients_texture, 1, GL_RG32F, GLsizei(period), GLsizei(period), GLsizei(layers));
  glTextureParameteri(m_gradients_texture, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTextureParameteri(m_gradients_texture, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  const float unset[2] = {kNoGradient, kNoGradient};
  glClearTexImage(m_gradients_texture, 0, GL_RG, GL_FLOAT, unset);
  const uint64_t bytes = uint64_t(period) * period * 8 * layers;
  if (Status st = gl_util::checkCreated("the terrain's height gradients (" + std::to_string(bytes >> 20) +
                                        " MiB of RG32F)");
      !st) {
    glDeleteTextures(1, &m_gradients_texture);
    m_gradients_texture = 0;
    return st;
  }
  m_texture_bytes += bytes;
  // The tiles already held (each tile's samples read its held neighbours).
  const uint32_t last = m_geometry.tile_px - 1;
  for (uint32_t level = 0; level < layers; ++level)
    for (uint32_t slot = 0; slot < slots * slots; ++slot) {
      const uint64_t id = m_slot_tile[level][slot];
      if (id == kNoTile) continue;
      writeGradients(level, int64_t(uint32_t(id)), int64_t(uint32_t(id >> 32)), 0, 0, last, last);
    }
  return okStatus();
}

TerrainHeightStack::~TerrainHeightStack() {
  glDeleteTextures(1, &m_texture);
  glDeleteTextures(1, &m_gradients_texture);
}

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
  if (m_gradients_texture == 0) return;
  // The tile's gradients, and those of the samples facing it in the four
  // slots beside its slot, whatever tiles they hold: theirs reach one
  // sample into this slot, so they become valid if they are its
  // neighbours and the sentinel if not.
  const uint32_t last = tile - 1;
  writeGradients(key.level, key.x, key.y, 0, 0, last, last);
  const std::vector<uint64_t>& held = m_slot_tile[key.level];
  auto beside = [&](int dx, int dy, uint32_t x0, uint32_t y0, uint32_t x1, uint32_t y1) {
    const uint64_t id = held[size_t(slotOf(int64_t(sy) + dy)) * m_slots + slotOf(int64_t(sx) + dx)];
    if (id == kNoTile) return;
    writeGradients(key.level, int64_t(uint32_t(id)), int64_t(uint32_t(id >> 32)), x0, y0, x1, y1);
  };
  beside(-1, 0, last, 0, last, last);
  beside(1, 0, 0, 0, 0, last);
  beside(0, -1, 0, last, last, last);
  beside(0, 1, 0, 0, last, 0);
}

void TerrainHeightStack::writeGradients(uint32_t level, int64_t tx, int64_t ty, uint32_t x0, uint32_t y0,
                                        uint32_t x1, uint32_t y1) {
  const LevelInfo& info = m_geometry.levels[level];
  const int64_t tile = m_geometry.tile_px;
  const std::vector<float>& own = m_slot_heights[level][slotIndex(tx, ty)];
  const int64_t w = int64_t(info.width_px), h = int64_t(info.height_px);
  // Level sample (i, j) clamped to the level, as the shader's heightAt();
  // from this tile's copy when it is there, else a resident neighbour's;
  // false when that is not resident.
  auto at = [&](int64_t i, int64_t j, float* v) {
    i = std::clamp<int64_t>(i, 0, w - 1);
    j = std::clamp<int64_t>(j, 0, h - 1);
    const int64_t li = i - tx * tile, lj = j - ty * tile;
    if (li >= 0 && li < tile && lj >= 0 && lj < tile) {
      *v = own[size_t(lj * tile + li)];
      return true;
    }
    return sample(level, i, j, v);
  };
  std::vector<float> out(size_t(x1 - x0 + 1) * (y1 - y0 + 1) * 2);
  size_t k = 0;
  for (uint32_t y = y0; y <= y1; ++y)
    for (uint32_t x = x0; x <= x1; ++x) {
      const int64_t i = tx * tile + x, j = ty * tile + y;
      float e = 0, wv = 0, s = 0, n = 0;
      const bool valid = at(i + 1, j, &e) && at(i - 1, j, &wv) && at(i, j + 1, &s) && at(i, j - 1, &n);
      // terrain_heights.glsl's gradientAt(), float for float.
      out[k++] = valid ? e - wv : kNoGradient;
      out[k++] = valid ? s - n : kNoGradient;
    }
  glTextureSubImage3D(m_gradients_texture, 0, GLint(slotOf(tx) * tile + x0), GLint(slotOf(ty) * tile + y0),
                      GLint(level), GLsizei(x1 - x0 + 1), GLsizei(y1 - y0 + 1), 1, GL_RG, GL_FLOAT, out.data());
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

glm::i64vec4 TerrainHeightStack::residentSamples(uint32_t level, const glm::i64vec2& camera) const {
  const LevelInfo& info = m_geometry.levels[level];
  const int64_t tile = m_geometry.tile_px;
  const int64_t last_x = int64_t(info.tiles_x) - 1, last_y = int64_t(info.tiles_y) - 1;
  const int64_t cx = std::clamp<int64_t>((camera.x >> level) / tile, 0, last_x);
  const int64_t cy = std::clamp<int64_t>((camera.y >> level) / tile, 0, last_y);
  if (!holds(level, cx, cy)) return {1, 1, 0, 0};
  int64_t x0 = cx, x1 = cx, y0 = cy, y1 = cy;
  auto column = [&](int64_t x) {
    for (int64_t y = y0; y <= y1; ++y)
      if (!holds(level, x, y)) return false;
    return true;
  };
  auto row = [&](int64_t y) {
    for (int64_t x = x0; x <= x1; ++x)
      if (!holds(level, x, y)) return false;
    return true;
  };
  // At most slots - 1 steps a side: beyond, tiles would share slots.
  const int64_t span = int64_t(m_slots) - 1;
  for (bool grew = true; grew;) {
    grew = false;
    if (x0 > 0 && x1 - x0 < span && column(x0 - 1)) --x0, grew = true;
    if (x1 < last_x && x1 - x0 < span && column(x1 + 1)) ++x1, grew = true;
    if (y0 > 0 && y1 - y0 < span && row(y0 - 1)) --y0, grew = true;
    if (y1 < last_y && y1 - y0 < span && row(y1 + 1)) ++y1, grew = true;
  }
  constexpr int64_t kFar = int64_t(1) << 30;
  return {x0 == 0 ? -kFar : x0 * tile, y0 == 0 ? -kFar : y0 * tile, x1 == last_x ? kFar : (x1 + 1) * tile - 1,
          y1 == last_y ? kFar : (y1 + 1) * tile - 1};
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
