// Loading an elevation layer's per-tile height bounds, and the detail of a
// height tile. See terrain_bounds.h.
#include <clipstream/streamer/terrain_bounds.h>

#include <algorithm>
#include <cmath>

namespace clipstream {

Status loadTerrainBounds(const TileSource& source, uint64_t max_level_tiles,
                         std::shared_ptr<const TerrainBounds>* out) {
  out->reset();
  const PyramidGeometry& g = source.geometry();
  if (g.levelCount() == 0 || g.tile_px == 0)
    return Status::error(ErrorCode::kInvalidArgument, source.describe() + ": empty pyramid");
  auto bounds = std::make_shared<TerrainBounds>();
  bounds->tile_px = g.tile_px;
  bounds->width_samples = g.width_px;
  bounds->height_samples = g.height_px;
  bounds->levels.resize(g.levelCount());
  const uint32_t coarsest = g.levelCount() - 1;
  bounds->finest_level = coarsest + 1;
  for (uint32_t l = coarsest + 1; l-- > 0;) {
    const LevelInfo& info = g.levels[l];
    if (uint64_t(info.tiles_x) * info.tiles_y > max_level_tiles && l != coarsest) break;
    TerrainBounds::Level level;
    level.tiles_x = info.tiles_x;
    level.tiles_y = info.tiles_y;
    level.range.resize(size_t(info.tiles_x) * info.tiles_y);
    level.error.resize(size_t(info.tiles_x) * info.tiles_y);
    Status status;
    for (uint32_t y = 0; y < info.tiles_y && status; ++y)
      for (uint32_t x = 0; x < info.tiles_x && status; ++x) {
        TileHeightBounds b;
        status = source.tileHeightBounds(TileKey{l, x, y}, &b);
        if (status && !(std::isfinite(b.min_height) && std::isfinite(b.max_height) && b.min_height <= b.max_height))
          status = Status::error(ErrorCode::kCorruptIndex, source.describe() + ": tile bounds not a range");
        level.range[size_t(y) * info.tiles_x + x] = {b.min_height, b.max_height};
        level.error[size_t(y) * info.tiles_x + x] = std::isnan(b.error) ? INFINITY : std::max(b.error, 0.0f);
      }
    if (!status) {
      if (l == coarsest) return status;
      break;  // plan with the coarser levels' bounds
    }
    bounds->levels[l] = std::move(level);
    bounds->finest_level = l;
  }
  // A parent holds its children's ground (the store's rule); enforced here
  // so that skipping a parent the ray passes above can never skip a child.
  for (uint32_t l = bounds->finest_level; l < coarsest; ++l) {
    const TerrainBounds::Level& child = bounds->levels[l];
    TerrainBounds::Level& parent = bounds->levels[l + 1];
    for (uint32_t y = 0; y < child.tiles_y; ++y)
      for (uint32_t x = 0; x < child.tiles_x; ++x) {
        glm::vec2& p = parent.range[size_t(y / 2) * parent.tiles_x + x / 2];
        const glm::vec2 c = child.range[size_t(y) * child.tiles_x + x];
        p = {std::min(p.x, c.x), std::max(p.y, c.y)};
      }
  }
  const TerrainBounds::Level& top = bounds->levels[coarsest];
  bounds->range = top.range[0];
  for (const glm::vec2& r : top.range) bounds->range = {std::min(bounds->range.x, r.x), std::max(bounds->range.y, r.y)};
  *out = std::move(bounds);
  return okStatus();
}

std::shared_ptr<const TileDetail> makeTileDetail(uint32_t tile_px, const float* heights, float error) {
  auto d = std::make_shared<TileDetail>();
  uint32_t log2 = 0;
  while (log2 < kTileDetailLog2 && (2u << log2) <= tile_px) ++log2;
  d->log2 = log2;
  const uint32_t n = 1u << log2, cell = tile_px / n;
  std::vector<glm::vec2>& fine = d->cells[log2];
  fine.assign(size_t(n) * n, {INFINITY, -INFINITY});
  for (uint32_t y = 0; y < n * cell; ++y)
    for (uint32_t x = 0; x < n * cell; ++x) {
      const float h = heights[size_t(y) * tile_px + x];
      glm::vec2& r = fine[size_t(y / cell) * n + x / cell];
      r = {std::min(r.x, h), std::max(r.y, h)};
    }
  const float e = std::max(error, 0.0f);
  for (glm::vec2& r : fine) r = {r.x - e, r.y + e};
  for (uint32_t k = log2; k-- > 0;) {
    const uint32_t side = 1u << k;
    const std::vector<glm::vec2>& finer = d->cells[k + 1];
    std::vector<glm::vec2>& coarse = d->cells[k];
    coarse.assign(size_t(side) * side, {INFINITY, -INFINITY});
    for (uint32_t y = 0; y < 2 * side; ++y)
      for (uint32_t x = 0; x < 2 * side; ++x) {
        const glm::vec2 c = finer[size_t(y) * 2 * side + x];
        glm::vec2& r = coarse[size_t(y / 2) * side + x / 2];
        r = {std::min(r.x, c.x), std::max(r.y, c.y)};
      }
  }
  return d;
}

}  // namespace clipstream
