#include <clipstream/streamer/look_at.h>

#include <proj.h>

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

namespace {

// The finest level of at most 16 tiles: where highestPoint() and
// roughestPoint() look at the whole DEM.
uint32_t wholeDemLevel(const PyramidGeometry& g) {
  uint32_t level = g.levelCount() - 1;
  while (level > 0 && uint64_t(g.levels[level - 1].tiles_x) * g.levels[level - 1].tiles_y <= 16) --level;
  return level;
}

}  // namespace

Status highestPoint(TileSource& heights, const LayerAlignment& alignment, glm::dvec3* world) {
  const PyramidGeometry& g = heights.geometry();
  uint32_t level = wholeDemLevel(g);
  std::vector<uint8_t> bytes;
  // The highest sample of `level` within [x0, x1] x [y0, y1] (clamped).
  auto highest = [&](uint32_t l, int64_t x0, int64_t y0, int64_t x1, int64_t y1, int64_t* bx, int64_t* by,
                     float* bh) -> Status {
    const LevelInfo& info = g.levels[l];
    x0 = std::max<int64_t>(x0, 0), y0 = std::max<int64_t>(y0, 0);
    x1 = std::min<int64_t>(x1, int64_t(info.width_px) - 1), y1 = std::min<int64_t>(y1, int64_t(info.height_px) - 1);
    *bh = -INFINITY;
    const int64_t tp = g.tile_px;
    for (int64_t ty = y0 / tp; ty <= y1 / tp; ++ty)
      for (int64_t tx = x0 / tp; tx <= x1 / tp; ++tx) {
        if (Status s = heights.fetch({l, uint32_t(tx), uint32_t(ty)}, &bytes); !s) return s;
        const float* f = reinterpret_cast<const float*>(bytes.data());
        for (int64_t j = std::max(y0, ty * tp); j <= std::min(y1, ty * tp + tp - 1); ++j)
          for (int64_t i = std::max(x0, tx * tp); i <= std::min(x1, tx * tp + tp - 1); ++i) {
            const float h = f[size_t((j - ty * tp) * tp + (i - tx * tp))];
            if (h > *bh) *bh = h, *bx = i, *by = j;
          }
      }
    return okStatus();
  };
  int64_t x = 0, y = 0;
  float h = 0.0f;
  if (Status s = highest(level, 0, 0, INT64_MAX / 2, INT64_MAX / 2, &x, &y, &h); !s) return s;
  while (level > 0) {
    --level;
    if (Status s = highest(level, 2 * x - 2, 2 * y - 2, 2 * x + 2, 2 * y + 2, &x, &y, &h); !s) return s;
  }
  const glm::dvec2 xz = alignment.sample0_world + glm::dvec2(double(x), double(y)) * alignment.world_per_sample;
  *world = {xz.x, double(h) * alignment.world_per_height, xz.y};
  return okStatus();
}

Status roughestPoint(TileSource& heights, const LayerAlignment& alignment, glm::dvec3* world) {
  const PyramidGeometry& g = heights.geometry();
  const uint32_t level = wholeDemLevel(g);
  const LevelInfo& info = g.levels[level];
  const int64_t w = int64_t(info.width_px), h = int64_t(info.height_px), tp = g.tile_px;
  std::vector<float> field(size_t(w * h));
  std::vector<uint8_t> bytes;
  for (uint32_t ty = 0; ty < info.tiles_y; ++ty)
    for (uint32_t tx = 0; tx < info.tiles_x; ++tx) {
      if (Status s = heights.fetch({level, tx, ty}, &bytes); !s) return s;
      const float* f = reinterpret_cast<const float*>(bytes.data());
      for (int64_t j = ty * tp; j < std::min(h, int64_t(ty + 1) * tp); ++j)
        for (int64_t i = tx * tp; i < std::min(w, int64_t(tx + 1) * tp); ++i)
          field[size_t(j * w + i)] = f[size_t((j - ty * tp) * tp + (i - tx * tp))];
    }
  // |Laplacian| in height units, edges repeated; a summed-area table of it.
  auto at = [&](int64_t i, int64_t j) {
    return double(field[size_t(std::clamp<int64_t>(j, 0, h - 1) * w + std::clamp<int64_t>(i, 0, w - 1))]);
  };
  std::vector<double> sat(size_t((w + 1) * (h + 1)), 0.0);
  for (int64_t j = 0; j < h; ++j)
    for (int64_t i = 0; i < w; ++i) {
      const double r = std::abs(at(i - 1, j) + at(i + 1, j) + at(i, j - 1) + at(i, j + 1) - 4.0 * at(i, j));
      sat[size_t((j + 1) * (w + 1) + i + 1)] = r + sat[size_t(j * (w + 1) + i + 1)] +
                                               sat[size_t((j + 1) * (w + 1) + i)] - sat[size_t(j * (w + 1) + i)];
    }
  const int64_t side = std::clamp<int64_t>(int64_t(std::lround(kRoughAreaFraction * double(std::max(w, h)))), 1,
                                           std::min(w, h));
  double best = -1.0;
  int64_t bx = 0, by = 0;
  for (int64_t j = 0; j + side <= h; ++j)
    for (int64_t i = 0; i + side <= w; ++i) {
      const double sum = sat[size_t((j + side) * (w + 1) + i + side)] - sat[size_t(j * (w + 1) + i + side)] -
                         sat[size_t((j + side) * (w + 1) + i)] + sat[size_t(j * (w + 1) + i)];
      if (sum > best) best = sum, bx = i, by = j;
    }
  // The square's middle, in level-0 samples (level sample i covers
  // level-0 samples [i 2^level, (i + 1) 2^level)), and the ground there:
  // the level's samples around it, averaged.
  const double mx = double(bx) + 0.5 * double(side - 1), my = double(by) + 0.5 * double(side - 1);
  const double scale = double(uint64_t(1) << level);
  const double cx = mx * scale + 0.5 * (scale - 1.0), cy = my * scale + 0.5 * (scale - 1.0);
  const int64_t i0 = int64_t(std::floor(mx)), j0 = int64_t(std::floor(my));
  const int64_t i1 = int64_t(std::ceil(mx)), j1 = int64_t(std::ceil(my));
  const double ground = 0.25 * (at(i0, j0) + at(i1, j0) + at(i0, j1) + at(i1, j1));
  const glm::dvec2 xz = alignment.sample0_world + glm::dvec2(cx, cy) * alignment.world_per_sample;
  *world = {xz.x, ground * alignment.world_per_height, xz.y};
  return okStatus();
}

Camera lookAtCamera(const glm::dvec3& target, double distance, double heading_rad, double pitch_rad) {
  Camera c;
  c.heading_rad = heading_rad;
  c.pitch_rad = pitch_rad;
  c.position = target - c.forward() * distance;
  return c;
}

Status lonLatToMap(const std::string& crs, const glm::dvec2& lon_lat, glm::dvec2* map) {
  if (crs.empty()) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "longitude and latitude need the colour store's coordinate system, and it "
                         "names none; give map coordinates");
  }
  if (!(std::abs(lon_lat.x) <= 180.0) || !(std::abs(lon_lat.y) <= 90.0)) {
    return Status::error(ErrorCode::kInvalidArgument, "longitude must be within -180..180 and latitude -90..90");
  }
  // One context per call: PROJ contexts are not shared between threads.
  PJ_CONTEXT* ctx = proj_context_create();
  proj_log_level(ctx, PJ_LOG_NONE);
  PJ* raw = proj_create_crs_to_crs(ctx, "EPSG:4326", crs.c_str(), nullptr);
  PJ* pj = raw != nullptr ? proj_normalize_for_visualization(ctx, raw) : nullptr;  // lon, lat / east, north
  Status result = okStatus();
  if (pj == nullptr) {
    result = Status::error(ErrorCode::kInvalidArgument,
                           "longitude and latitude: PROJ does not know the colour store's coordinate system (" +
                               std::string(proj_context_errno_string(ctx, proj_context_errno(ctx))) + ")");
  } else {
    const PJ_COORD c = proj_trans(pj, PJ_FWD, proj_coord(lon_lat.x, lon_lat.y, 0, 0));
    if (!std::isfinite(c.xy.x) || !std::isfinite(c.xy.y) || proj_errno(pj) != 0) {
      result = Status::error(ErrorCode::kInvalidArgument,
                             "longitude and latitude: the point has no place in the colour store's coordinate system");
    } else {
      *map = {c.xy.x, c.xy.y};
    }
  }
  if (pj != nullptr) proj_destroy(pj);
  if (raw != nullptr) proj_destroy(raw);
  proj_context_destroy(ctx);
  return result;
}

}  // namespace clipstream
