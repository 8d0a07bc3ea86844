// The quadtree's node errors (TerrainRendererImpl, terrain_impl.h): the
// bound of a node's distance from the full-resolution ground, from the
// store's per-tile errors, tightened by the exact distance of the resident
// finer level; cached per node and forgotten when a tile under the node
// changes. docs/terrain.md, "Geometry: a restricted quadtree", explains it.
//
// GL thread, as the rest of TerrainRendererImpl (no GL call here).
#include "terrain_impl.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace clipstream {

bool TerrainRendererImpl::cpuHeight(uint32_t level, int64_t i, int64_t j, float* h) const {
  const uint32_t last = m_geometry.levelCount() - 1;
  if (level > last) {
    i *= int64_t(1) << (level - last);
    j *= int64_t(1) << (level - last);
    level = last;
  }
  return m_stack->sample(level, i, j, h);
}

bool TerrainRendererImpl::readSamples(uint32_t level, const glm::i64vec2& s0, int64_t size, float* out) const {
  // Inside one held tile of a stored level (most nodes): row by row from
  // the tile's copy; elsewhere sample by sample (clamped, across tiles).
  const int64_t tile = m_geometry.tile_px;
  if (level < m_geometry.levelCount() && s0.x >= 0 && s0.y >= 0) {
    const LevelInfo& info = m_geometry.levels[level];
    const int64_t tx = s0.x / tile, ty = s0.y / tile;
    const bool one_tile = (s0.x + size - 1) / tile == tx && (s0.y + size - 1) / tile == ty &&
                          s0.x + size <= int64_t(info.width_px) && s0.y + size <= int64_t(info.height_px);
    if (one_tile) {
      const float* heights = m_stack->tileHeights(level, tx, ty);
      if (!heights) return false;
      for (int64_t j = 0; j < size; ++j) {
        const float* row = heights + (s0.y + j - ty * tile) * tile + (s0.x - tx * tile);
        std::copy(row, row + size, out + j * size);
      }
      return true;
    }
  }
  for (int64_t j = 0; j < size; ++j)
    for (int64_t i = 0; i < size; ++i)
      if (!cpuHeight(level, s0.x + i, s0.y + j, &out[j * size + i])) return false;
  return true;
}

double TerrainRendererImpl::nodeError(uint32_t level, int64_t x, int64_t y) {
  if (level == 0) return 0.0;
  if (m_exact_node_error) return m_exact_node_error(level, x, y);
  const auto cached = m_error_cache.find(NodeId{level, x, y});
  if (cached != m_error_cache.end()) return double(cached->second);
  double error = tileErrorBound(level, x, y);
  // Where the next finer level is resident under the node: the exact
  // largest distance of its samples from this node's surface (the two
  // surfaces are piecewise linear on the finer grid, whose triangles lie
  // inside the coarser ones, so the largest distance is at a finer
  // sample), plus the children's own bounds.
  const int64_t p = m_config.patch_cells;
  const glm::i64vec2 f0(2 * x * p, 2 * y * p);
  // Only nodes over the field (beyond it the resident edge tiles would
  // make a whole unbounded margin look resident).
  const uint32_t stored = std::min(level - 1, m_geometry.levelCount() - 1);
  const int64_t scale = int64_t(1) << (level - 1 - stored);
  const LevelInfo& fine_level = m_geometry.levels[stored];
  const bool inside = f0.x >= 0 && f0.y >= 0 && f0.x * scale < int64_t(fine_level.width_px) - 1 &&
                      f0.y * scale < int64_t(fine_level.height_px) - 1;
  if (error > 0.0 && inside && samplesResident(level - 1, f0, f0 + glm::i64vec2(2 * p, 2 * p))) {
    double local = 0.0;
    // The node's own (P + 1)^2 samples and the finer level's (2P + 1)^2
    // under it, each read once.
    const int64_t n = p + 1, m = 2 * p + 1;
    std::vector<float> coarse(size_t(n * n)), fine(size_t(m * m));
    bool ok = readSamples(level, {x * p, y * p}, n, coarse.data()) && readSamples(level - 1, f0, m, fine.data());
    for (int64_t j = 0; j < m && ok; ++j)
      for (int64_t i = 0; i < m; ++i) {
        // The coarser surface at finer sample (i, j): the coarse cell's
        // diagonal cut (terrain.vert's coarseAt()), the mean of coarse
        // samples (i >> 1, j >> 1) and ((i + 1) >> 1, (j + 1) >> 1).
        const float c0 = coarse[size_t((j >> 1) * n + (i >> 1))];
        const float c1 = coarse[size_t(((j + 1) >> 1) * n + ((i + 1) >> 1))];
        local = std::max(local, std::abs(double(fine[size_t(j * m + i)]) - 0.5 * (double(c0) + double(c1))));
      }
    // The children's bounds only while they can still make it tighter
    // (each is a recursion down to the finest resident level).
    double children = 0.0;
    for (int c = 0; c < 4 && ok && local + children < error; ++c)
      children = std::max(children, nodeError(level - 1, 2 * x + (c & 1), 2 * y + (c >> 1)));
    if (ok) error = std::min(error, local + children);
  }
  // As cached, so that a bound never depends on whether it was cached.
  const float rounded = float(error);
  m_error_cache[NodeId{level, x, y}] = rounded;
  return double(rounded);
}

double TerrainRendererImpl::tileErrorBound(uint32_t level, int64_t x, int64_t y) const {
  const int64_t p = m_config.patch_cells, tile = m_geometry.tile_px;
  const uint32_t levels = m_geometry.levelCount();
  if (level >= levels) {
    // Coarser than the pyramid: no stored bound; the whole height range.
    if (m_bounds) return double(m_bounds->range.y - m_bounds->range.x);
    return INFINITY;
  }
  const LevelInfo& info = m_geometry.levels[level];
  // Beyond a corner of the field the surface is the corner's height, flat:
  // no error (beyond one side it is the edge's profile, the edge tiles').
  const bool beyond_x = (x + 1) * p <= 0 || x * p >= int64_t(info.width_px) - 1;
  const bool beyond_y = (y + 1) * p <= 0 || y * p >= int64_t(info.height_px) - 1;
  if (beyond_x && beyond_y) return 0.0;
  // The tiles under the node (clamped to the level: beyond the field the
  // surface is the edge's).
  const int64_t tx0 = std::clamp<int64_t>(x * p, 0, int64_t(info.width_px) - 1) / tile;
  const int64_t tx1 = std::clamp<int64_t>((x + 1) * p - 1, 0, int64_t(info.width_px) - 1) / tile;
  const int64_t ty0 = std::clamp<int64_t>(y * p, 0, int64_t(info.height_px) - 1) / tile;
  const int64_t ty1 = std::clamp<int64_t>((y + 1) * p - 1, 0, int64_t(info.height_px) - 1) / tile;
  double error = 0.0;
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      // The index's bound of |level-0 ground - bilinear surface of the
      // tile's samples|; for a level finer than the bounds hold, the
      // height range of its ancestor at the finest level held (the level-0
      // ground and the node's samples both lie in it). No bounds: none
      // (the exact pass in nodeError() may give one).
      double e = INFINITY;
      if (m_bounds && !m_bounds->levels.empty()) {
        const uint32_t bl = std::max(level, m_bounds->finest_level);
        const TerrainBounds::Level& lv = m_bounds->levels[bl];
        if (!lv.error.empty()) {
          const int64_t bx = std::min<int64_t>(tx >> (bl - level), lv.tiles_x - 1);
          const int64_t by = std::min<int64_t>(ty >> (bl - level), lv.tiles_y - 1);
          const size_t t = size_t(by) * lv.tiles_x + size_t(bx);
          e = bl == level ? double(lv.error[t]) : double(lv.range[t].y - lv.range[t].x);
        }
      }
      // The mesh cuts cells along a diagonal: add the distance between
      // that surface and the bilinear one (a quarter of the cell's twist).
      if (m_stack->holds(level, tx, ty) && !m_stack->tileTwist(level, tx, ty).empty()) {
        const std::vector<float>& twist = m_stack->tileTwist(level, tx, ty);
        const int64_t block = std::min<int64_t>(p, tile), blocks = tile / block;
        const int64_t i0 = std::max<int64_t>(x * p - tx * tile, 0) / block;
        const int64_t i1 = std::min<int64_t>((x + 1) * p - 1 - tx * tile, tile - 1) / block;
        const int64_t j0 = std::max<int64_t>(y * p - ty * tile, 0) / block;
        const int64_t j1 = std::min<int64_t>((y + 1) * p - 1 - ty * tile, tile - 1) / block;
        float t = 0.0f;
        for (int64_t j = j0; j <= j1; ++j)
          for (int64_t i = i0; i <= i1; ++i) t = std::max(t, twist[size_t(j * blocks + i)]);
        e += double(t);
      }
      error = std::max(error, e);
    }
  return error;
}

void TerrainRendererImpl::forgetNodeErrors(const TileKey& key) {
  // Node errors that read this tile: nodes at its level or coarser whose
  // ground (clamped to the field: nodes beyond it read its edge) meets
  // the tile's, one sample around (their bounds take their children's).
  const int64_t p = m_config.patch_cells, w = int64_t(m_geometry.width_px), h = int64_t(m_geometry.height_px);
  const int64_t span0 = int64_t(m_geometry.tile_px) << key.level, margin = int64_t(1) << key.level;
  const int64_t tx0 = int64_t(key.x) * span0 - margin, tx1 = (int64_t(key.x) + 1) * span0 + margin;
  const int64_t ty0 = int64_t(key.y) * span0 - margin, ty1 = (int64_t(key.y) + 1) * span0 + margin;
  // Bounded: nodes of tiles long evicted are never asked again.
  if (m_error_cache.size() > kMaxCachedNodeErrors) m_error_cache.clear();
  for (auto it = m_error_cache.begin(); it != m_error_cache.end();) {
    const NodeId& n = it->first;
    const int64_t span = p << n.level;
    const int64_t nx0 = std::clamp<int64_t>(n.x * span, 0, w - 1), nx1 = std::clamp<int64_t>((n.x + 1) * span, 0, w - 1);
    const int64_t ny0 = std::clamp<int64_t>(n.y * span, 0, h - 1), ny1 = std::clamp<int64_t>((n.y + 1) * span, 0, h - 1);
    const bool meets = n.level >= key.level && nx1 >= tx0 && nx0 <= tx1 && ny1 >= ty0 && ny0 <= ty1;
    it = meets ? m_error_cache.erase(it) : std::next(it);
  }
}

}  // namespace clipstream
