// Usable map: the residency the shader may trust. See clipmap.h.
#include <clipstream/renderer/clipmap.h>

namespace clipstream {

UsableMap computeUsableMap(const PyramidGeometry& geometry, uint32_t clip_tiles,
                           uint32_t pyramid_level, const std::vector<LevelResidency>& residency) {
  UsableMap map;
  map.clip_tiles = clip_tiles;
  map.pyramid_level = pyramid_level;
  const size_t slots = size_t(clip_tiles) * clip_tiles;
  map.windows.assign(pyramid_level, TileRect{});
  map.usable.assign(pyramid_level, std::vector<uint8_t>(slots, 0));
  map.finest.assign(pyramid_level, std::vector<uint8_t>(slots, uint8_t(pyramid_level)));
  if (clip_tiles == 0) return map;

  // Resident flags by level, addressed through the window.
  std::vector<const LevelResidency*> by_level(pyramid_level, nullptr);
  for (const LevelResidency& r : residency) {
    if (r.level >= pyramid_level) continue;
    const size_t n = size_t(r.window.width()) * size_t(r.window.height());
    // A window wider than the clip would alias slots; a flag array of the
    // wrong size is a caller bug we refuse rather than read past.
    if (r.window.width() > int64_t(clip_tiles) || r.window.height() > int64_t(clip_tiles) ||
        r.resident.size() != n)
      continue;
    by_level[r.level] = &r;
    map.windows[r.level] = r.window;
  }

  for (int64_t level = int64_t(pyramid_level) - 1; level >= 0; --level) {
    const LevelResidency* r = by_level[size_t(level)];
    if (r == nullptr || r->window.empty()) continue;
    const TileRect& w = r->window;
    const LevelInfo& info = geometry.levels[size_t(level)];
    const bool any_unread = r->unread.size() == r->resident.size();
    auto resident = [&](int64_t x, int64_t y) {
      if (x < 0 || y < 0 || x >= int64_t(info.tiles_x) || y >= int64_t(info.tiles_y))
        return true;  // outside the image: only edge padding is read there
      if (!w.contains(x, y)) return false;
      return r->resident[size_t(y - w.y0) * size_t(w.width()) + size_t(x - w.x0)] != 0;
    };
    // A neighbour the filter may read: resident, or one no tap of the
    // frame reads (LevelResidency::unread).
    auto readable = [&](int64_t x, int64_t y) {
      if (resident(x, y)) return true;
      return any_unread && w.contains(x, y) &&
             r->unread[size_t(y - w.y0) * size_t(w.width()) + size_t(x - w.x0)] != 0;
    };
    const bool parent_is_pyramid = uint32_t(level) + 1 >= pyramid_level;
    const TileRect& pw = parent_is_pyramid ? TileRect{} : map.windows[size_t(level) + 1];
    for (int64_t y = w.y0; y < w.y1; ++y) {
      for (int64_t x = w.x0; x < w.x1; ++x) {
        bool ok = resident(x, y);
        for (int64_t dy = -1; dy <= 1 && ok; ++dy)
          for (int64_t dx = -1; dx <= 1 && ok; ++dx) ok = readable(x + dx, y + dy);
        if (ok && !parent_is_pyramid) {
          const int64_t px = x / 2, py = y / 2;
          ok = pw.contains(px, py) &&
               map.usable[size_t(level) + 1][size_t(toroidalSlot(py, clip_tiles)) * clip_tiles +
                                             toroidalSlot(px, clip_tiles)] != 0;
        }
        const size_t slot = size_t(toroidalSlot(y, clip_tiles)) * clip_tiles + toroidalSlot(x, clip_tiles);
        if (ok) {
          map.usable[size_t(level)][slot] = 1;
          map.finest[size_t(level)][slot] = uint8_t(level);
        } else if (!parent_is_pyramid && pw.contains(x / 2, y / 2)) {
          map.finest[size_t(level)][slot] =
              map.finest[size_t(level) + 1][size_t(toroidalSlot(y / 2, clip_tiles)) * clip_tiles +
                                            toroidalSlot(x / 2, clip_tiles)];
        }
      }
    }
  }
  return map;
}

}  // namespace clipstream
