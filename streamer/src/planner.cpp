// Clipmap planning. Pure functions; every coordinate is a double in level-0
// texels until it is snapped to a level's tile grid, so a 2^26-texel texture
// plans exactly (doubles hold integers up to 2^53).
#include <clipstream/streamer/planner.h>

#include "footprint.h"

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

// PlanScope::kSampled. Screen cells of at least kSampleStepMinPx pixels,
// at most kSampleCellsMax along the longer side: the cell bounds are exact,
// so the grid only trades tightness for time (320x180: 80 x 45 cells,
// 1920x1080: 96 x 54; a plan costs 0.17 / 0.40 ms on this machine against
// 3-6 us for the whole window: bench_streamer_plan).
constexpr double kSampleStepMinPx = 4.0;
constexpr double kSampleCellsMax = 96.0;
// Levels of detail are compared with this much slack: the GPU forms its
// derivatives per 2x2 quad, from pixel pairs a little apart from the ones
// sampled here.
constexpr double kSampleLodSlack = 0.05;
// Each cell's ground also reaches this many tiles of the level ahead along
// the horizontal view direction: a camera that starts to move forward
// finds the next tiles loaded (the prefetch needs a few frames of motion
// to see it). Measured on the sweep's line, deterministic (docs/decisions.md
// D67): none lost 1-3 frames below 30 dB at
// each start from rest (x10: 98.7 dB mean, x50: 97.1), half a tile one
// (x50: 97.8), one tile none (99.0, 98.4) for an over-fetch of 1.85 at x1
// instead of 1.27.
constexpr double kSampleLeadTiles = 1.0;
// A block of cells over at most this many window tiles that are all marked
// already is not searched further (a larger one costs more to check than
// its search saves).
constexpr int64_t kSampleMarkedCheckTiles = 64;

// Marks, for every needed stack level m, the window tiles under ground
// whose level of detail is below m + 1 (PlanScope::kSampled): per screen
// cell, the level of detail at its corners (log2 of the longer ground step
// to the next pixel across and up, as the renderer's shader and
// renderReference() form it), its least value over the corners, and the
// bounding box of the corners' ground points. On a plane the ground a cell
// sees is the convex quad of its corners, so the box holds it; a corner
// above the horizon stands for the ground out to far_h along its azimuth.
// Each box is widened by half a texel of the level (the bilinear taps) and
// stretched kSampleLeadTiles ahead along the horizontal view direction.
void markSampled(const PyramidGeometry& geometry, const Viewport& viewport, const Camera& camera,
                 double far_h, ClipmapPlan* plan) {
  const double W = viewport.width_px, H = viewport.height_px;
  const double step = std::max(kSampleStepMinPx, std::max(W, H) / kSampleCellsMax);
  std::vector<double> xs, ys;
  for (double x = 0.5; x < W - 0.5; x += step) xs.push_back(x);
  xs.push_back(W - 0.5);
  for (double y = 0.5; y < H - 0.5; y += step) ys.push_back(y);
  ys.push_back(H - 0.5);

  const double tan_half = std::tan(camera.vfov_rad * 0.5);
  const glm::dvec3 fwd = camera.forward();
  const glm::dvec3 right = camera.right() * (tan_half * W / H);
  const glm::dvec3 up = camera.up() * tan_half;
  const glm::dvec2 nadir{camera.position.x, camera.position.z};
  glm::dvec2 ahead{fwd.x, fwd.z};
  if (glm::length(ahead) > 1e-9) ahead = glm::normalize(ahead); else ahead = {0.0, 0.0};
  auto ray = [&](double px, double py) {
    return fwd + right * (2.0 * px / W - 1.0) + up * (1.0 - 2.0 * py / H);
  };
  auto hit = [&](double px, double py, glm::dvec2* p) {
    const glm::dvec3 d = ray(px, py);
    if (d.y >= -1e-12 || camera.position.y <= 0.0) return false;
    const double t = -camera.position.y / d.y;
    *p = nadir + t * glm::dvec2(d.x, d.z);
    return true;
  };
  struct Corner {
    glm::dvec2 ground;
    double lod = INFINITY;
  };
  std::vector<Corner> corners(xs.size() * ys.size());
  for (size_t j = 0; j < ys.size(); ++j) {
    for (size_t i = 0; i < xs.size(); ++i) {
      Corner& c = corners[j * xs.size() + i];
      if (!hit(xs[i], ys[j], &c.ground)) {
        const glm::dvec3 d = ray(xs[i], ys[j]);
        const glm::dvec2 dxz{d.x, d.z};
        const double len = glm::length(dxz);
        c.ground = len > 1e-12 ? nadir + dxz * (far_h / len) : nadir;
        continue;
      }
      glm::dvec2 across, above;
      if (hit(xs[i] + 1.0, ys[j], &across) && hit(xs[i], ys[j] - 1.0, &above)) {
        const double rho = std::max(glm::length(across - c.ground), glm::length(above - c.ground));
        c.lod = std::log2(std::max(rho, 1e-30));
      }
    }
  }

  std::vector<ClipLevelPlan*> levels;
  for (ClipLevelPlan& lp : plan->stack) {
    if (!lp.needed || lp.window.empty()) continue;
    lp.sampled.assign(size_t(lp.window.width()) * size_t(lp.window.height()), 0);
    levels.push_back(&lp);
  }
  if (levels.empty()) return;

  // The cells, then a pyramid of blocks of 2x2 cells (blocks of blocks...):
  // a block's level of detail is the least of its cells', its box the union
  // of the boxes of its cells that have one (a finite level of detail).
  struct Cell {
    double lod = INFINITY;
    glm::dvec2 lo{INFINITY}, hi{-INFINITY};
  };
  struct Grid {
    size_t w = 0, h = 0;
    std::vector<Cell> cells;
  };
  std::vector<Grid> grids(1);
  grids[0].w = xs.size() - 1;
  grids[0].h = ys.size() - 1;
  grids[0].cells.resize(grids[0].w * grids[0].h);
  for (size_t j = 0; j < grids[0].h; ++j) {
    for (size_t i = 0; i < grids[0].w; ++i) {
      const Corner* q[4] = {&corners[j * xs.size() + i], &corners[j * xs.size() + i + 1],
                            &corners[(j + 1) * xs.size() + i], &corners[(j + 1) * xs.size() + i + 1]};
      Cell& cell = grids[0].cells[j * grids[0].w + i];
      for (const Corner* c : q) cell.lod = std::min(cell.lod, c->lod);
      // No corner with a level of detail: the cell lies above the horizon
      // (a straight line on the screen), or only touches it, where every
      // level is finer than the pixels. It samples nothing.
      if (!std::isfinite(cell.lod)) continue;
      for (const Corner* c : q) {
        cell.lo = glm::min(cell.lo, c->ground);
        cell.hi = glm::max(cell.hi, c->ground);
      }
    }
  }
  while (grids.back().w > 1 || grids.back().h > 1) {
    const Grid& fine = grids.back();
    Grid coarse;
    coarse.w = (fine.w + 1) / 2;
    coarse.h = (fine.h + 1) / 2;
    coarse.cells.resize(coarse.w * coarse.h);
    for (size_t j = 0; j < fine.h; ++j)
      for (size_t i = 0; i < fine.w; ++i) {
        const Cell& c = fine.cells[j * fine.w + i];
        Cell& b = coarse.cells[(j / 2) * coarse.w + i / 2];
        b.lod = std::min(b.lod, c.lod);
        b.lo = glm::min(b.lo, c.lo);
        b.hi = glm::max(b.hi, c.hi);
      }
    grids.push_back(std::move(coarse));
  }

  // Per level, from the top block down: a block none of whose cells reaches
  // the level's detail is skipped; a block whose widened box lies within one
  // tile marks that tile (every cell of it that reaches the level would mark
  // that tile and no other); any other block goes down to its four. A cell
  // marks the window tiles its widened box touches. The result is exactly
  // that of marking cell by cell, at a cost that follows the tiles, not the
  // cells times the levels.
  struct Block {
    size_t grid, i, j;
  };
  std::vector<Block> todo;
  for (ClipLevelPlan* lp : levels) {
    const double reach = double(lp->level) + 1.0;  // a cell with lod - slack below it samples the level
    const double tile_texels = double(geometry.tile_px) * levelScale(lp->level);
    const double tap = 0.5 * levelScale(lp->level);  // bilinear: half a texel of the level
    const glm::dvec2 lead = ahead * (kSampleLeadTiles * tile_texels);
    const size_t w = size_t(lp->window.width());
    todo.assign(1, Block{grids.size() - 1, 0, 0});
    while (!todo.empty()) {
      const Block b = todo.back();
      todo.pop_back();
      const Grid& grid = grids[b.grid];
      const Cell& c = grid.cells[b.j * grid.w + b.i];
      if (!(c.lod - kSampleLodSlack < reach)) continue;
      const glm::dvec2 lo = glm::min(c.lo, c.lo + lead), hi = glm::max(c.hi, c.hi + lead);
      const TileRect whole{int64_t(std::floor((lo.x - tap) / tile_texels)),
                           int64_t(std::floor((lo.y - tap) / tile_texels)),
                           int64_t(std::floor((hi.x + tap) / tile_texels)) + 1,
                           int64_t(std::floor((hi.y + tap) / tile_texels)) + 1};
      const TileRect r = intersect(whole, lp->window);
      if (r.empty()) continue;
      if (b.grid == 0 || (whole.width() == 1 && whole.height() == 1)) {
        for (int64_t y = r.y0; y < r.y1; ++y)
          for (int64_t x = r.x0; x < r.x1; ++x)
            lp->sampled[size_t(y - lp->window.y0) * w + size_t(x - lp->window.x0)] = 1;
        continue;
      }
      // Nothing left to mark under a small block whose tiles are all marked.
      if (r.width() * r.height() <= kSampleMarkedCheckTiles) {
        bool all = true;
        for (int64_t y = r.y0; y < r.y1 && all; ++y)
          for (int64_t x = r.x0; x < r.x1 && all; ++x)
            all = lp->sampled[size_t(y - lp->window.y0) * w + size_t(x - lp->window.x0)] != 0;
        if (all) continue;
      }
      const Grid& finer = grids[b.grid - 1];
      for (size_t dj = 0; dj < 2; ++dj)
        for (size_t di = 0; di < 2; ++di) {
          const size_t i = b.i * 2 + di, j = b.j * 2 + dj;
          if (i < finer.w && j < finer.h) todo.push_back({b.grid - 1, i, j});
        }
    }
  }
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

ClipmapPlan planClipmap(const PyramidGeometry& geometry, const Viewport& viewport,
                        const Camera& camera, const PlannerConfig& config) {
  ClipmapPlan plan;
  const uint32_t level_count = geometry.levelCount();
  if (level_count == 0 || geometry.tile_px == 0) return plan;
  plan.clip_tiles =
      config.clip_tiles ? config.clip_tiles : chooseClipTiles(viewport, geometry.tile_px);
  plan.pyramid_level = level_count - 1;
  const uint32_t fit =
      config.pyramid_tiles != 0 ? std::min(config.pyramid_tiles, plan.clip_tiles) : plan.clip_tiles;
  for (uint32_t l = 0; l < level_count; ++l) {
    if (geometry.levels[l].tiles_x <= fit && geometry.levels[l].tiles_y <= fit) {
      plan.pyramid_level = l;
      break;
    }
  }
  for (uint32_t l = plan.pyramid_level; l < level_count; ++l)
    plan.pyramid.push_back(levelGrid(geometry.levels[l]));

  const glm::dvec2 nadir{camera.position.x, camera.position.z};
  plan.focus_texel = nadir;
  Footprint fp;
  if (config.terrain.bounds) {
    // Over terrain (the bounds hold the relief): the far limit counts from
    // the lowest ground, as the flat one counts from the plane.
    const double lowest = double(config.terrain.bounds->range.x) * config.terrain.units_per_height;
    const double far_h = 2.0 * double(std::max(geometry.width_px, geometry.height_px)) +
                         std::abs(camera.position.y - lowest);
    fp = terrainFootprint(config.terrain, viewport, camera, far_h);
  } else {
    fp = computeFootprint(geometry, viewport, camera);
    // Relief planes: the union with the footprints on the lowest and
    // highest ground in view (PlannerConfig::ground_above / ground_below).
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
  }
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

  glm::dvec2 fp_min{INFINITY}, fp_max{-INFINITY};
  for (const glm::dvec2& p : fp.points) {
    fp_min = glm::min(fp_min, p);
    fp_max = glm::max(fp_max, p);
  }
  const glm::dvec3 fwd = camera.forward();
  const glm::dvec2 ahead{fwd.x, fwd.z};  // length cos(pitch)

  plan.stack.resize(plan.pyramid_level);
  for (uint32_t l = 0; l < plan.pyramid_level; ++l) {
    ClipLevelPlan& lp = plan.stack[l];
    const LevelInfo& info = geometry.levels[l];
    lp.level = l;
    lp.needed = fp.any_hit && l >= finest && l >= first_stack;
    const double tile_texels = double(geometry.tile_px) * levelScale(l);
    const double extent = double(plan.clip_tiles) * tile_texels;
    const glm::dvec2 centre = nadir + ahead * (0.25 * extent);
    lp.origin_tx = windowOrigin(centre.x / tile_texels, plan.clip_tiles, info.tiles_x);
    lp.origin_ty = windowOrigin(centre.y / tile_texels, plan.clip_tiles, info.tiles_y);
    lp.window = intersect({lp.origin_tx, lp.origin_ty, lp.origin_tx + plan.clip_tiles,
                           lp.origin_ty + plan.clip_tiles},
                          levelGrid(info));
    if (fp.any_hit) {
      const TileRect fp_rect{int64_t(std::floor(fp_min.x / tile_texels)),
                             int64_t(std::floor(fp_min.y / tile_texels)),
                             int64_t(std::floor(fp_max.x / tile_texels)) + 1,
                             int64_t(std::floor(fp_max.y / tile_texels)) + 1};
      lp.visible = intersect(fp_rect, lp.window);
    }
  }
  const bool flat = !config.terrain.bounds && !(config.ground_above > 0.0) && !(config.ground_below > 0.0);
  if (config.scope == PlanScope::kSampled && flat && fp.any_hit && viewport.height_px > 0)
    markSampled(geometry, viewport, camera, farLimit(geometry, camera), &plan);
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
