#include "height_bounds.h"

#include <algorithm>
#include <cmath>

namespace clipstream {

HeightBoundsTracker::HeightBoundsTracker(const PyramidGeometry& geometry,
                                         const ElevationInfo& elevation)
    : m_geometry(geometry), m_elevation(elevation) {}

TileHeights HeightBoundsTracker::add(const TileKey& key, std::span<const uint8_t> pixels) {
  const uint32_t n = m_geometry.tile_px;
  const size_t bpp = bytesPerPixel(m_geometry.format);
  m_heights.resize(size_t(n) * n);
  float lo = INFINITY, hi = -INFINITY;
  for (size_t i = 0; i < m_heights.size(); ++i) {
    const float h = float(heightOfSample(m_geometry.format, m_elevation, pixels.data() + i * bpp));
    m_heights[i] = h;
    lo = std::min(lo, h);
    hi = std::max(hi, h);
  }
  TileHeights out{lo, hi, 0.0f};
  if (auto it = m_pending.find(key); it != m_pending.end()) {
    out.min_height = std::min(out.min_height, it->second.min_height);
    out.max_height = std::max(out.max_height, it->second.max_height);
    out.error = it->second.error;
    m_pending.erase(it);
  }
  if (key.level + 1 >= m_geometry.levelCount()) return out;

  // Deviation of the odd samples from the surface of the even ones.
  auto at = [&](uint32_t x, uint32_t y) { return m_heights[size_t(y) * n + x]; };
  auto even = [&](uint32_t v) { return std::min(v, n - 2); };  // last even sample in the tile
  float deviation = 0.0f;
  for (uint32_t y = 0; y < n; ++y) {
    const bool odd_y = (y & 1) != 0;
    for (uint32_t x = 0; x < n; ++x) {
      const bool odd_x = (x & 1) != 0;
      if (!odd_x && !odd_y) continue;
      const uint32_t x0 = odd_x ? x - 1 : x, x1 = odd_x ? even(x + 1) : x;
      const uint32_t y0 = odd_y ? y - 1 : y, y1 = odd_y ? even(y + 1) : y;
      const float surface = 0.25f * (at(x0, y0) + at(x1, y0) + at(x0, y1) + at(x1, y1));
      deviation = std::max(deviation, std::abs(at(x, y) - surface));
    }
  }
  Pending& parent = m_pending[TileKey{key.level + 1, key.x / 2, key.y / 2}];
  if (!parent.any) {
    parent.min_height = out.min_height;
    parent.max_height = out.max_height;
    parent.any = true;
  } else {
    parent.min_height = std::min(parent.min_height, out.min_height);
    parent.max_height = std::max(parent.max_height, out.max_height);
  }
  parent.error = std::max(parent.error, deviation + out.error);
  return out;
}

}  // namespace clipstream
