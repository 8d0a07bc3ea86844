// Loading an elevation layer's per-tile height bounds. See terrain_bounds.h.
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
    Status status;
    for (uint32_t y = 0; y < info.tiles_y && status; ++y)
      for (uint32_t x = 0; x < info.tiles_x && status; ++x) {
        float lo = 0.0f, hi = 0.0f;
        status = source.tileHeightBounds(TileKey{l, x, y}, &lo, &hi);
        if (status && !(std::isfinite(lo) && std::isfinite(hi) && lo <= hi))
          status = Status::error(ErrorCode::kCorruptIndex, source.describe() + ": tile bounds not a range");
        level.range[size_t(y) * info.tiles_x + x] = {lo, hi};
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
  // Each tile's range widened by its +x, +z and +x+z neighbours' (see
  // TerrainBounds): the surface between two tiles is made of both.
  for (uint32_t l = bounds->finest_level; l <= coarsest; ++l) {
    TerrainBounds::Level& level = bounds->levels[l];
    const std::vector<glm::vec2> own = level.range;
    for (uint32_t y = 0; y < level.tiles_y; ++y)
      for (uint32_t x = 0; x < level.tiles_x; ++x) {
        glm::vec2 r = own[size_t(y) * level.tiles_x + x];
        for (uint32_t dy = 0; dy < 2 && y + dy < level.tiles_y; ++dy)
          for (uint32_t dx = 0; dx < 2 && x + dx < level.tiles_x; ++dx) {
            const glm::vec2 n = own[size_t(y + dy) * level.tiles_x + x + dx];
            r = {std::min(r.x, n.x), std::max(r.y, n.y)};
          }
        level.range[size_t(y) * level.tiles_x + x] = r;
      }
  }
  const TerrainBounds::Level& top = bounds->levels[coarsest];
  bounds->range = top.range[0];
  for (const glm::vec2& r : top.range) bounds->range = {std::min(bounds->range.x, r.x), std::max(bounds->range.y, r.y)};
  *out = std::move(bounds);
  return Status::ok();
}

}  // namespace clipstream
