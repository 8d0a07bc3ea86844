// Clipmap planning. Pure functions; every coordinate is a double in level-0
// texels until it is snapped to a level's tile grid, so a 2^26-texel texture
// plans exactly (doubles hold integers up to 2^53). The sampled scope's
// tiles are marked in sampled_scope.cpp.
#include <clipstream/streamer/planner.h>

#include "footprint.h"
#include "sampled_scope.h"

#include <algorithm>
#include <cmath>
#include <tuple>

namespace clipstream {
namespace {

// Screen border samples per edge for the ground footprint polygon. Eight per
// edge follows the horizon closely enough for tile-sized decisions.
constexpr int kFootprintSamplesPerEdge = 8;

double levelScale(uint32_t level) { return std::ldexp(1.0, int(level)); }

// Far limit for rays that pass above the horizon or hit very far away: past
// twice the texture's larger side there is nothing to load.
double farLimit(const PyramidGeometry& geometry, const Camera& camera) {
  return 2.0 * double(std::max(geometry.width_px, geometry.height_px)) +
         std::abs(camera.position.y);
}

bool pointInPolygon(const std::vector<glm::dvec2>& poly, glm::dvec2 p) {
  bool inside = false;
  for (size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const glm::dvec2 a = poly[i], b = poly[j];
    if ((a.y > p.y) != (b.y > p.y)) {
      const double x = a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y);
      if (p.x < x) inside = !inside;
    }
  }
  return inside;
}

double distToSegment(glm::dvec2 p, glm::dvec2 a, glm::dvec2 b) {
  const glm::dvec2 ab = b - a;
  const double len2 = glm::dot(ab, ab);
  double t = len2 > 0.0 ? glm::dot(p - a, ab) / len2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return glm::length(p - (a + t * ab));
}

Footprint computeFootprint(const PyramidGeometry& geometry, const Viewport& viewport,
                           const Camera& camera) {
  Footprint fp;
  const double far_h = farLimit(geometry, camera);
  const glm::dvec2 nadir{camera.position.x, camera.position.z};
  const double w = viewport.width_px, h = viewport.height_px;
  auto sample = [&](double px, double py) {
    glm::dvec2 hit;
    if (groundHit(camera, viewport, px, py, &hit)) {
      fp.any_hit = true;
      const glm::dvec2 d = hit - nadir;
      const double len = glm::length(d);
      if (len > far_h) hit = nadir + d * (far_h / len);
      fp.points.push_back(hit);
      return;
    }
    // Above the horizon: clamp to the far limit along the ray's azimuth.
    const double aspect = w / (h > 0 ? h : 1.0);
    const double tan_half = std::tan(camera.vfov_rad * 0.5);
    const glm::dvec3 dir = camera.forward() +
                           camera.right() * ((2.0 * px / w - 1.0) * tan_half * aspect) +
                           camera.up() * ((1.0 - 2.0 * py / h) * tan_half);
    glm::dvec2 dxz{dir.x, dir.z};
    const double len = glm::length(dxz);
    if (len < 1e-12) return;
    fp.points.push_back(nadir + dxz * (far_h / len));
  };
  const int n = kFootprintSamplesPerEdge;
  for (int i = 0; i < n; ++i) sample(w * i / n, 0.0);
  for (int i = 0; i < n; ++i) sample(w, h * i / n);
  for (int i = 0; i < n; ++i) sample(w - w * i / n, h);
  for (int i = 0; i < n; ++i) sample(0.0, h - h * i / n);
  if (!fp.any_hit || fp.points.size() < 3) {
    fp.any_hit = false;
    fp.points.clear();
    return fp;
  }
  const double height = std::max(camera.position.y, 0.0);
  if (pointInPolygon(fp.points, nadir)) {
    fp.nearest_dist = height;
  } else {
    double best = INFINITY;
    for (size_t i = 0, j = fp.points.size() - 1; i < fp.points.size(); j = i++)
      best = std::min(best, distToSegment(nadir, fp.points[j], fp.points[i]));
    fp.nearest_dist = std::sqrt(height * height + best * best);
  }
  return fp;
}

TileRect levelGrid(const LevelInfo& info) {
  return {0, 0, int64_t(info.tiles_x), int64_t(info.tiles_y)};
}

TileRect intersect(const TileRect& a, const TileRect& b) {
  TileRect r{std::max(a.x0, b.x0), std::max(a.y0, b.y0), std::min(a.x1, b.x1),
             std::min(a.y1, b.y1)};
  if (r.empty()) return {};
  return r;
}

// Window origin along one axis: centred, snapped, shifted to lie inside.
int64_t windowOrigin(double centre_tiles, uint32_t clip_tiles, uint32_t level_tiles) {
  if (level_tiles <= clip_tiles) return 0;
  const double start = std::floor(centre_tiles - double(clip_tiles) * 0.5 + 0.5);
  const double max_origin = double(level_tiles - clip_tiles);
  return int64_t(std::clamp(start, 0.0, max_origin));
}

// The rect that holds every tile the plan wants of a level: the full grid
// for pyramid levels, the window for needed stack levels, empty otherwise.
TileRect wantedRect(const ClipmapPlan& plan, uint32_t level) {
  if (level < plan.stack.size()) {
    const ClipLevelPlan& l = plan.stack[level];
    return l.needed ? l.window : TileRect{};
  }
  if (level >= plan.pyramid_level && level - plan.pyramid_level < plan.pyramid.size())
    return plan.pyramid[level - plan.pyramid_level];
  return {};
}

bool planWants(const ClipmapPlan& plan, uint32_t level, int64_t x, int64_t y) {
  if (level < plan.stack.size()) return plan.stack[level].wants(x, y);
  return wantedRect(plan, level).contains(x, y);
}

}  // namespace

uint32_t finestLevelAt(double distance, const Viewport& viewport, const Camera& camera,
                       const PlannerConfig& config, uint32_t level_count) {
  if (level_count == 0 || viewport.height_px == 0) return 0;
  const double pixel_angle = 2.0 * std::tan(camera.vfov_rad * 0.5) / double(viewport.height_px);
  const double footprint_texels = std::max(distance, 1e-9) * pixel_angle;
  const double oversample = config.max_oversample > 0.0 ? config.max_oversample : 1.0;
  const double ratio = footprint_texels / oversample;
  const uint32_t finest = ratio <= 1.0 ? 0u : uint32_t(std::ceil(std::log2(ratio) - 1e-9));
  return std::min(finest, level_count - 1);
}

uint32_t chooseClipTiles(const Viewport& viewport, uint32_t tile_px) {
  if (tile_px == 0) return 4;
  const uint64_t span_px = 2 * uint64_t(std::max(viewport.width_px, viewport.height_px));
  const uint64_t tiles = (span_px + tile_px - 1) / tile_px + 1;
  return uint32_t(std::clamp<uint64_t>(tiles, 4, 256));
}

namespace {

// The pyramid's finest level: the first level whose whole grid fits in
// `fit` tiles a side; the coarsest level when none does.
uint32_t pyramidLevelFor(const PyramidGeometry& geometry, uint32_t fit) {
  const uint32_t level_count = geometry.levelCount();
  for (uint32_t l = 0; l < level_count; ++l) {
    if (geometry.levels[l].tiles_x <= fit && geometry.levels[l].tiles_y <= fit) return l;
  }
  return level_count - 1;
}

// The ground the view sees over the terrain bounds (config.terrain.bounds
// non-null): the far limit counts from the lowest ground, as the flat one
// counts from the plane.
Footprint terrainViewFootprint(const PyramidGeometry& geometry, const Viewport& viewport,
                               const Camera& camera, const PlannerConfig& config) {
  const double lowest = double(config.terrain.bounds->range.x) * config.terrain.units_per_height;
  const double far_h = 2.0 * double(std::max(geometry.width_px, geometry.height_px)) +
                       std::abs(camera.position.y - lowest);
  return terrainFootprint(config.terrain, viewport, camera, far_h);
}

// The ground the view sees on the plane y = 0, united with the footprints
// on the lowest and highest ground in view when the config gives the
// relief (PlannerConfig::ground_above / ground_below).
Footprint planeFootprint(const PyramidGeometry& geometry, const Viewport& viewport,
                         const Camera& camera, const PlannerConfig& config) {
  Footprint fp = computeFootprint(geometry, viewport, camera);
  auto merge = [&](const Footprint& other) {
    if (!other.any_hit) return;
    fp.nearest_dist = fp.any_hit ? std::min(fp.nearest_dist, other.nearest_dist) : other.nearest_dist;
    fp.any_hit = true;
    fp.points.insert(fp.points.end(), other.points.begin(), other.points.end());
  };
  if (config.ground_below > 0.0 && std::isfinite(config.ground_below)) {
    Camera low = camera;
    low.position.y += config.ground_below;
    merge(computeFootprint(geometry, viewport, low));
  }
  if (config.ground_above > 0.0 && std::isfinite(config.ground_above)) {
    Camera high = camera;
    if (camera.position.y > config.ground_above) {
      high.position.y -= config.ground_above;
    } else {
      // The camera is below the top: the rays that rise meet the upper
      // plane; mirrored, they are a camera looking down on it.
      high.position.y = config.ground_above - camera.position.y + 1e-6;
      high.pitch_rad = -camera.pitch_rad;
    }
    merge(computeFootprint(geometry, viewport, high));
  }
  return fp;
}

// Places every stack level of *plan (levels [0, plan->pyramid_level); its
// clip_tiles and focus_texel set): the window centred a quarter of its
// extent ahead of the camera's ground point, snapped and kept inside the
// level; the visible tiles under the footprint's bounding box; needed from
// finest_level (and first_stack) on while the ground is visible.
void placeStackLevels(const PyramidGeometry& geometry, const Camera& camera, const Footprint& fp,
                      uint32_t finest, uint32_t first_stack, ClipmapPlan* plan) {
  glm::dvec2 fp_min{INFINITY}, fp_max{-INFINITY};
  for (const glm::dvec2& p : fp.points) {
    fp_min = glm::min(fp_min, p);
    fp_max = glm::max(fp_max, p);
  }
  const glm::dvec2 nadir = plan->focus_texel;
  const glm::dvec3 fwd = camera.forward();
  const glm::dvec2 ahead{fwd.x, fwd.z};  // length cos(pitch)

  plan->stack.resize(plan->pyramid_level);
  for (uint32_t l = 0; l < plan->pyramid_level; ++l) {
    ClipLevelPlan& lp = plan->stack[l];
    const LevelInfo& info = geometry.levels[l];
    lp.level = l;
    lp.needed = fp.any_hit && l >= finest && l >= first_stack;
    const double tile_texels = double(geometry.tile_px) * levelScale(l);
    const double extent = double(plan->clip_tiles) * tile_texels;
    const glm::dvec2 centre = nadir + ahead * (0.25 * extent);
    lp.origin_tx = windowOrigin(centre.x / tile_texels, plan->clip_tiles, info.tiles_x);
    lp.origin_ty = windowOrigin(centre.y / tile_texels, plan->clip_tiles, info.tiles_y);
    lp.window = intersect({lp.origin_tx, lp.origin_ty, lp.origin_tx + plan->clip_tiles,
                           lp.origin_ty + plan->clip_tiles},
                          levelGrid(info));
    if (fp.any_hit) {
      const TileRect fp_rect{int64_t(std::floor(fp_min.x / tile_texels)),
                             int64_t(std::floor(fp_min.y / tile_texels)),
                             int64_t(std::floor(fp_max.x / tile_texels)) + 1,
                             int64_t(std::floor(fp_max.y / tile_texels)) + 1};
      lp.visible = intersect(fp_rect, lp.window);
    }
  }
}

}  // namespace

ClipmapPlan planClipmap(const PyramidGeometry& geometry, const Viewport& viewport,
                        const Camera& camera, const PlannerConfig& config) {
  ClipmapPlan plan;
  const uint32_t level_count = geometry.levelCount();
  if (level_count == 0 || geometry.tile_px == 0) return plan;
  plan.clip_tiles =
      config.clip_tiles ? config.clip_tiles : chooseClipTiles(viewport, geometry.tile_px);
  const uint32_t fit =
      config.pyramid_tiles != 0 ? std::min(config.pyramid_tiles, plan.clip_tiles) : plan.clip_tiles;
  plan.pyramid_level = pyramidLevelFor(geometry, fit);
  for (uint32_t l = plan.pyramid_level; l < level_count; ++l)
    plan.pyramid.push_back(levelGrid(geometry.levels[l]));

  plan.focus_texel = glm::dvec2{camera.position.x, camera.position.z};
  const Footprint fp = config.terrain.bounds ? terrainViewFootprint(geometry, viewport, camera, config)
                                             : planeFootprint(geometry, viewport, camera, config);
  plan.ground_visible = fp.any_hit;

  // Finest level: the nearest visible ground point has the densest texels.
  // A pixel there spans nearest_dist * pixel_angle texels (perpendicular to
  // the view, as anisotropic filtering sees it); level l is worth loading
  // while its texel covers at least 1/max_oversample of that pixel.
  uint32_t finest = plan.pyramid_level;
  if (fp.any_hit && viewport.height_px > 0)
    finest = finestLevelAt(fp.nearest_dist, viewport, camera, config, level_count);
  plan.finest_level = finest;

  uint32_t first_stack = 0;
  if (config.max_stack_levels != 0 && plan.pyramid_level > config.max_stack_levels)
    first_stack = plan.pyramid_level - config.max_stack_levels;
  placeStackLevels(geometry, camera, fp, finest, first_stack, &plan);

  const bool flat = !config.terrain.bounds && !(config.ground_above > 0.0) && !(config.ground_below > 0.0);
  if (config.scope == PlanScope::kSampled && fp.any_hit && viewport.height_px > 0) {
    if (config.reads && !config.reads->rects.empty())
      markHeightReads(geometry.tile_px, camera, *config.reads, &plan);
    else if (flat)
      markSampled(geometry, viewport, camera, farLimit(geometry, camera), &plan);
    else if (config.seen && !config.seen->points.empty())
      markSeen(geometry.tile_px, viewport, camera, *config.seen, &plan);
  }
  return plan;
}

uint64_t ClipLevelPlan::wantedCount() const {
  if (!needed) return 0;
  if (sampled.empty()) return uint64_t(window.width()) * uint64_t(window.height());
  return uint64_t(std::count(sampled.begin(), sampled.end(), uint8_t(1)));
}

PlanDelta diffPlans(const ClipmapPlan& before, const ClipmapPlan& after) {
  PlanDelta delta;
  const uint32_t levels = uint32_t(std::max(before.stack.size() + before.pyramid.size(),
                                            after.stack.size() + after.pyramid.size()));
  for (uint32_t l = 0; l < levels; ++l) {
    const TileRect a = wantedRect(before, l), b = wantedRect(after, l);
    static const std::vector<uint8_t> kWhole;
    const std::vector<uint8_t>& ma = l < before.stack.size() ? before.stack[l].sampled : kWhole;
    const std::vector<uint8_t>& mb = l < after.stack.size() ? after.stack[l].sampled : kWhole;
    if (a == b && ma == mb) continue;
    for (int64_t y = b.y0; y < b.y1; ++y)
      for (int64_t x = b.x0; x < b.x1; ++x)
        if (planWants(after, l, x, y) && !planWants(before, l, x, y))
          delta.entered.push_back({l, uint32_t(x), uint32_t(y)});
    for (int64_t y = a.y0; y < a.y1; ++y)
      for (int64_t x = a.x0; x < a.x1; ++x)
        if (planWants(before, l, x, y) && !planWants(after, l, x, y))
          delta.left.push_back({l, uint32_t(x), uint32_t(y)});
  }
  return delta;
}

std::vector<TileKey> rankPlanTiles(const PyramidGeometry& geometry, const ClipmapPlan& plan,
                                   bool frustum_first) {
  struct Ranked {
    uint32_t level;
    int hidden;
    double dist2;
    TileKey key;
  };
  std::vector<Ranked> ranked;
  auto add = [&](uint32_t level, const TileRect& rect, const TileRect& visible) {
    const double tile_texels = double(geometry.tile_px) * levelScale(level);
    const glm::dvec2 focus = plan.focus_texel / tile_texels;
    for (int64_t y = rect.y0; y < rect.y1; ++y) {
      for (int64_t x = rect.x0; x < rect.x1; ++x) {
        if (!planWants(plan, level, x, y)) continue;
        const double dx = double(x) + 0.5 - focus.x, dy = double(y) + 0.5 - focus.y;
        const int hidden = frustum_first && !visible.contains(x, y) ? 1 : 0;
        ranked.push_back({level, hidden, dx * dx + dy * dy, {level, uint32_t(x), uint32_t(y)}});
      }
    }
  };
  const size_t levels = plan.stack.size() + plan.pyramid.size();
  for (size_t l = 0; l < levels; ++l) {
    const uint32_t level = uint32_t(l);
    if (level >= plan.pyramid_level) {
      const TileRect r = wantedRect(plan, level);
      add(level, r, r);  // pyramid tiles all count as visible
    } else if (plan.stack[level].needed) {
      add(level, plan.stack[level].window, plan.stack[level].visible);
    }
  }
  std::stable_sort(ranked.begin(), ranked.end(), [](const Ranked& a, const Ranked& b) {
    return std::tie(b.level, a.hidden, a.dist2) < std::tie(a.level, b.hidden, b.dist2);
  });
  std::vector<TileKey> out;
  out.reserve(ranked.size());
  for (const Ranked& r : ranked) out.push_back(r.key);
  return out;
}

}  // namespace clipstream
