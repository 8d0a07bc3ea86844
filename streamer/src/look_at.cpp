#include <clipstream/streamer/look_at.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <tuple>
#include <vector>

namespace clipstream {

Status mapToWorld(const GeoReference& colour, const glm::dvec2& map, glm::dvec2* world) {
  if (!colour.present) {
    *world = map;
    return okStatus();
  }
  const double* t = colour.transform;
  if (t[2] != 0.0 || t[4] != 0.0 || t[1] == 0.0 || t[5] == 0.0 || !std::isfinite(t[1]) || !std::isfinite(t[5]))
    return Status::error(ErrorCode::kInvalidArgument,
                         "the colour layer's georeference is rotated or degenerate: no map coordinates");
  // Map = t0 + texel x * t1 (texel corners; the world's texel x is its x).
  *world = {(map.x - t[0]) / t[1], (map.y - t[3]) / t[5]};
  return okStatus();
}

Status groundHeightAt(TileSource& heights, const LayerAlignment& alignment, const glm::dvec2& world_xz,
                      double* world_y) {
  const PyramidGeometry& g = heights.geometry();
  const LevelInfo& l0 = g.levels[0];
  const glm::dvec2 s = (world_xz - alignment.sample0_world) / alignment.world_per_sample;
  const double last_x = double(l0.width_px) - 1.0, last_y = double(l0.height_px) - 1.0;
  const double x = std::clamp(s.x, 0.0, last_x), y = std::clamp(s.y, 0.0, last_y);
  const int64_t i0 = int64_t(std::floor(x)), j0 = int64_t(std::floor(y));
  const int64_t i1 = std::min<int64_t>(i0 + 1, int64_t(last_x)), j1 = std::min<int64_t>(j0 + 1, int64_t(last_y));
  std::vector<uint8_t> bytes;
  TileKey held{0, UINT32_MAX, UINT32_MAX};
  auto at = [&](int64_t i, int64_t j, double* h) -> Status {
    const TileKey k{0, uint32_t(i / g.tile_px), uint32_t(j / g.tile_px)};
    if (!(k.x == held.x && k.y == held.y)) {
      if (Status st = heights.fetch(k, &bytes); !st) return st;
      held = k;
    }
    float v = 0.0f;
    std::memcpy(&v, bytes.data() + 4 * (size_t(j % g.tile_px) * g.tile_px + size_t(i % g.tile_px)), 4);
    *h = v;
    return okStatus();
  };
  double a = 0, b = 0, c = 0, d = 0;
  for (auto [i, j, h] : {std::tuple{i0, j0, &a}, std::tuple{i1, j0, &b}, std::tuple{i0, j1, &c}, std::tuple{i1, j1, &d}})
    if (Status st = at(i, j, h); !st) return st;
  const double fx = x - double(i0), fy = y - double(j0);
  *world_y = ((a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy) * alignment.world_per_height;
  return okStatus();
}

Status pathFromMapUnits(const GeoReference& colour, const LayerAlignment* elevation, FlightPath* path) {
  for (Keyframe& k : path->keyframes) {
    glm::dvec2 world;
    if (Status s = mapToWorld(colour, {k.position.x, k.position.z}, &world); !s) return s;
    const double y = elevation ? k.position.y * elevation->world_per_height : k.position.y / std::abs(colour.transform[1]);
    k.position = {world.x, y, world.y};
  }
  return okStatus();
}

Camera lookAtCamera(const glm::dvec3& target, double distance, double heading_rad, double pitch_rad) {
  Camera c;
  c.heading_rad = heading_rad;
  c.pitch_rad = pitch_rad;
  c.position = target - c.forward() * distance;
  return c;
}

}  // namespace clipstream
