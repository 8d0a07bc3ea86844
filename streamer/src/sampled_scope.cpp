// PlanScope::kSampled: the screen's cells (on the flat plane from rays, over
// terrain from the ground a frame showed), their level of detail and ground,
// a pyramid of blocks of cells, and per needed level the window tiles they
// sample (sampled_scope.h).
#include "sampled_scope.h"

#include <algorithm>
#include <utility>

namespace clipstream {
namespace {

// Level l's texel in level-0 texels (planner.cpp's rule).
double levelScale(uint32_t level) { return std::ldexp(1.0, int(level)); }

// The tiles in both rects; empty ({}) when none (planner.cpp's rule).
TileRect intersect(const TileRect& a, const TileRect& b) {
  TileRect r{std::max(a.x0, b.x0), std::max(a.y0, b.y0), std::min(a.x1, b.x1),
             std::min(a.y1, b.y1)};
  if (r.empty()) return {};
  return r;
}

// The view rays through screen points (pixels, y down) and where they meet
// the plane y = 0. An immutable value: any thread may call it.
class ScreenRays {
 public:
  ScreenRays(const Viewport& viewport, const Camera& camera)
      : m_w(viewport.width_px), m_h(viewport.height_px), m_height(camera.position.y),
        m_fwd(camera.forward()), m_nadir{camera.position.x, camera.position.z} {
    const double tan_half = std::tan(camera.vfov_rad * 0.5);
    m_right = camera.right() * (tan_half * m_w / m_h);
    m_up = camera.up() * tan_half;
  }
  // The ray through (px, py), not normalized.
  glm::dvec3 ray(double px, double py) const {
    return m_fwd + m_right * (2.0 * px / m_w - 1.0) + m_up * (1.0 - 2.0 * py / m_h);
  }
  // Where the ray through (px, py) meets the ground, into *p; false (and *p
  // untouched) when it does not go down or the camera is not above it.
  bool hit(double px, double py, glm::dvec2* p) const {
    const glm::dvec3 d = ray(px, py);
    if (d.y >= -1e-12 || m_height <= 0.0) return false;
    const double t = -m_height / d.y;
    *p = m_nadir + t * glm::dvec2(d.x, d.z);
    return true;
  }
  glm::dvec2 nadir() const { return m_nadir; }

 private:
  double m_w, m_h, m_height;
  glm::dvec3 m_fwd, m_right, m_up;
  glm::dvec2 m_nadir;
};

// A corner of the cell grid: its ground point and level of detail
// (INFINITY when its ray, or one a pixel across or up, misses the ground).
struct Corner {
  glm::dvec2 ground;
  double lod = INFINITY;
};

// The corners at xs x ys (row-major, x fastest). A corner above the
// horizon stands for the ground far_h from the nadir along its azimuth.
std::vector<Corner> sampleCorners(const ScreenRays& rays, const std::vector<double>& xs,
                                  const std::vector<double>& ys, double far_h) {
  std::vector<Corner> corners(xs.size() * ys.size());
  for (size_t j = 0; j < ys.size(); ++j) {
    for (size_t i = 0; i < xs.size(); ++i) {
      Corner& c = corners[j * xs.size() + i];
      if (!rays.hit(xs[i], ys[j], &c.ground)) {
        const glm::dvec3 d = rays.ray(xs[i], ys[j]);
        const glm::dvec2 dxz{d.x, d.z};
        const double len = glm::length(dxz);
        c.ground = len > 1e-12 ? rays.nadir() + dxz * (far_h / len) : rays.nadir();
        continue;
      }
      glm::dvec2 across, above;
      if (rays.hit(xs[i] + 1.0, ys[j], &across) && rays.hit(xs[i], ys[j] - 1.0, &above)) {
        const double rho = std::max(glm::length(across - c.ground), glm::length(above - c.ground));
        c.lod = std::log2(std::max(rho, 1e-30));
      }
    }
  }
  return corners;
}

// The cells between the corners of a corners_w x corners_h grid (at least
// 2 x 2): each one's least level of detail over its four corners and, when
// that is finite, the bounding box of their ground points.
SampleGrid cellsOf(const std::vector<Corner>& corners, size_t corners_w, size_t corners_h) {
  SampleGrid grid;
  grid.w = corners_w - 1;
  grid.h = corners_h - 1;
  grid.cells.resize(grid.w * grid.h);
  for (size_t j = 0; j < grid.h; ++j) {
    for (size_t i = 0; i < grid.w; ++i) {
      const Corner* q[4] = {&corners[j * corners_w + i], &corners[j * corners_w + i + 1],
                            &corners[(j + 1) * corners_w + i], &corners[(j + 1) * corners_w + i + 1]};
      SampleCell& cell = grid.cells[j * grid.w + i];
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
  return grid;
}

// The needed stack levels of *plan with a non-empty window, each given an
// all-zero sampled mask over its window.
std::vector<ClipLevelPlan*> startMasks(ClipmapPlan* plan) {
  std::vector<ClipLevelPlan*> levels;
  for (ClipLevelPlan& lp : plan->stack) {
    if (!lp.needed || lp.window.empty()) continue;
    lp.sampled.assign(size_t(lp.window.width()) * size_t(lp.window.height()), 0);
    levels.push_back(&lp);
  }
  return levels;
}

// The horizontal view direction, unit length; zero looking straight down
// or up.
glm::dvec2 horizontalAhead(const Camera& camera) {
  const glm::dvec3 fwd = camera.forward();
  glm::dvec2 ahead{fwd.x, fwd.z};
  if (glm::length(ahead) > 1e-9) ahead = glm::normalize(ahead); else ahead = {0.0, 0.0};
  return ahead;
}

// lp->sampled's entry for window tile (x, y).
uint8_t& maskAt(ClipLevelPlan* lp, int64_t x, int64_t y) {
  return lp->sampled[size_t(y - lp->window.y0) * size_t(lp->window.width()) + size_t(x - lp->window.x0)];
}

// Marks every tile of r (within lp->window).
void markTiles(ClipLevelPlan* lp, const TileRect& r) {
  for (int64_t y = r.y0; y < r.y1; ++y)
    for (int64_t x = r.x0; x < r.x1; ++x) maskAt(lp, x, y) = 1;
}

// True when every tile of r (within lp->window) is marked.
bool allMarked(ClipLevelPlan* lp, const TileRect& r) {
  bool all = true;
  for (int64_t y = r.y0; y < r.y1 && all; ++y)
    for (int64_t x = r.x0; x < r.x1 && all; ++x) all = maskAt(lp, x, y) != 0;
  return all;
}

}  // namespace

// The corners of a grid over the viewport: at least min_px apart, at most
// cells_max cells along the longer side.
static void cornerGrid(const Viewport& viewport, double min_px, double cells_max, std::vector<double>* xs,
                       std::vector<double>* ys) {
  const double W = viewport.width_px, H = viewport.height_px;
  const double step = std::max(min_px, std::max(W, H) / cells_max);
  *xs = sampleCornerPositions(W, step);
  *ys = sampleCornerPositions(H, step);
}

void groundSeenGrid(const Viewport& viewport, std::vector<double>* xs, std::vector<double>* ys) {
  cornerGrid(viewport, kSeenStepMinPx, kSeenCellsMax, xs, ys);
}

std::vector<double> sampleCornerPositions(double size_px, double step_px) {
  std::vector<double> positions;
  for (double p = 0.5; p < size_px - 0.5; p += step_px) positions.push_back(p);
  positions.push_back(size_px - 0.5);
  // A side of one pixel still has two corners, the same centre twice: one
  // cell of no width, which samples what that column (or row) sees.
  if (positions.size() < 2) positions.push_back(size_px - 0.5);
  return positions;
}

std::vector<SampleGrid> buildCellPyramid(SampleGrid cells) {
  std::vector<SampleGrid> grids;
  grids.push_back(std::move(cells));
  while (grids.back().w > 1 || grids.back().h > 1) {
    const SampleGrid& fine = grids.back();
    SampleGrid coarse;
    coarse.w = (fine.w + 1) / 2;
    coarse.h = (fine.h + 1) / 2;
    coarse.cells.resize(coarse.w * coarse.h);
    for (size_t j = 0; j < fine.h; ++j)
      for (size_t i = 0; i < fine.w; ++i) {
        const SampleCell& c = fine.cells[j * fine.w + i];
        SampleCell& b = coarse.cells[(j / 2) * coarse.w + i / 2];
        b.lod = std::min(b.lod, c.lod);
        b.lo = glm::min(b.lo, c.lo);
        b.hi = glm::max(b.hi, c.hi);
      }
    grids.push_back(std::move(coarse));
  }
  return grids;
}

// From the top block down: a block none of whose cells reaches the level's
// detail is skipped; a block whose widened box lies within one tile marks
// that tile (every cell of it that reaches the level would mark that tile
// and no other); any other block goes down to its four. A cell marks the
// window tiles its widened box touches.
void markSampledLevel(const std::vector<SampleGrid>& pyramid, uint32_t tile_px, glm::dvec2 ahead,
                      ClipLevelPlan* lp, double lead_tiles) {
  struct Block {
    size_t grid, i, j;
  };
  const double reach = double(lp->level) + 1.0;  // a cell with lod - slack below it samples the level
  const double tile_texels = double(tile_px) * levelScale(lp->level);
  const double tap = 0.5 * levelScale(lp->level);  // bilinear: half a texel of the level
  const glm::dvec2 lead = ahead * (lead_tiles * tile_texels);
  std::vector<Block> todo(1, Block{pyramid.size() - 1, 0, 0});
  while (!todo.empty()) {
    const Block b = todo.back();
    todo.pop_back();
    const SampleGrid& grid = pyramid[b.grid];
    const SampleCell& c = grid.cells[b.j * grid.w + b.i];
    if (!(c.lod - kSampleLodSlack < reach)) continue;
    const glm::dvec2 lo = glm::min(c.lo, c.lo + lead), hi = glm::max(c.hi, c.hi + lead);
    const TileRect whole{int64_t(std::floor((lo.x - tap) / tile_texels)),
                         int64_t(std::floor((lo.y - tap) / tile_texels)),
                         int64_t(std::floor((hi.x + tap) / tile_texels)) + 1,
                         int64_t(std::floor((hi.y + tap) / tile_texels)) + 1};
    const TileRect r = intersect(whole, lp->window);
    if (r.empty()) continue;
    if (b.grid == 0 || (whole.width() == 1 && whole.height() == 1)) {
      markTiles(lp, r);
      continue;
    }
    // Nothing left to mark under a small block whose tiles are all marked.
    if (r.width() * r.height() <= kSampleMarkedCheckTiles && allMarked(lp, r)) continue;
    const SampleGrid& finer = pyramid[b.grid - 1];
    for (size_t dj = 0; dj < 2; ++dj)
      for (size_t di = 0; di < 2; ++di) {
        const size_t i = b.i * 2 + di, j = b.j * 2 + dj;
        if (i < finer.w && j < finer.h) todo.push_back({b.grid - 1, i, j});
      }
  }
}

void markSampled(const PyramidGeometry& geometry, const Viewport& viewport, const Camera& camera,
                 double far_h, ClipmapPlan* plan) {
  std::vector<double> xs, ys;
  cornerGrid(viewport, kSampleStepMinPx, kSampleCellsMax, &xs, &ys);
  const std::vector<Corner> corners = sampleCorners(ScreenRays(viewport, camera), xs, ys, far_h);

  const std::vector<ClipLevelPlan*> levels = startMasks(plan);
  if (levels.empty()) return;
  // The cells, then blocks of 2x2 cells (blocks of blocks...), so that
  // marking costs what the tiles do, not the cells times the levels.
  const std::vector<SampleGrid> pyramid = buildCellPyramid(cellsOf(corners, xs.size(), ys.size()));
  const glm::dvec2 ahead = horizontalAhead(camera);
  for (ClipLevelPlan* lp : levels) markSampledLevel(pyramid, geometry.tile_px, ahead, lp);
}

// One screen axis at a grid point: the ground vectors to its two
// neighbours and their steps per pixel (INFINITY: no neighbour on the
// screen, or one that shows no ground). settle() drops a side whose step is
// over kSeenEdgeRatio times the other's (a jump across an edge of the
// relief, not the surface's step) and stands in for each side it has not
// kept by the other's vector turned back. (Twice that where an edge lies
// between the grid points, for the surface that may reach on toward the
// neighbour, missed as many sampled tiles on the St Helens orbits of
// tests/eval/test_terrain_planning.cpp and loaded a third more on the
// valley flight: the silhouettes against the sky are the far ground's.)
struct SeenAxis {
  glm::dvec2 to[2]{glm::dvec2(0.0), glm::dvec2(0.0)};
  double step[2]{INFINITY, INFINITY};
  bool kept[2]{false, false};
  bool any() const { return kept[0] || kept[1]; }
  void settle() {
    kept[0] = std::isfinite(step[0]);
    kept[1] = std::isfinite(step[1]);
    if (kept[0] && kept[1]) {
      if (step[1] > kSeenEdgeRatio * step[0]) kept[1] = false;
      else if (step[0] > kSeenEdgeRatio * step[1]) kept[0] = false;
    }
    for (int k = 0; k < 2; ++k)
      if (!kept[k] && kept[1 - k]) {
        to[k] = -to[1 - k];
        step[k] = step[1 - k];
      }
  }
  // The surface's step per pixel: the mean of the two sides (the ground
  // recedes, so the step behind is smaller and the one ahead larger).
  double perPixel() const {
    return std::isfinite(step[0]) && std::isfinite(step[1]) ? 0.5 * (step[0] + step[1]) : INFINITY;
  }
  // The other axis' stand-in where this one has no neighbour on its surface:
  // as far, at a right angle, with its steps (nothing kept: no neighbour of
  // this axis is on the surface).
  SeenAxis turned() const {
    SeenAxis t = *this;
    for (glm::dvec2& v : t.to) v = {-v.y, v.x};
    t.kept[0] = t.kept[1] = false;
    return t;
  }
};

std::vector<SeenCorner> seenCorners(const GroundSeen& seen, const Viewport& viewport, const Camera& camera) {
  const size_t w = seen.xs.size(), h = seen.ys.size();
  std::vector<SeenCorner> corners(w * h);
  const auto shown = [&](size_t i, size_t j) { return std::isfinite(seen.points[j * w + i].x); };
  const auto groundAt = [&](size_t i, size_t j) {
    const glm::dvec3& q = seen.points[j * w + i];
    return glm::dvec2(q.x, q.z);
  };
  // A pixel's angle then and now: a resized view sees the same ground at
  // other levels.
  const auto pixelAngle = [](const Camera& c, const Viewport& v) {
    return 2.0 * std::tan(c.vfov_rad * 0.5) / std::max(1.0, double(v.height_px));
  };
  const double angle_ratio = pixelAngle(camera, viewport) / pixelAngle(seen.camera, seen.viewport);
  for (size_t j = 0; j < h; ++j) {
    for (size_t i = 0; i < w; ++i) {
      if (!shown(i, j)) continue;
      SeenCorner& c = corners[j * w + i];
      c.shown = true;
      c.ground = groundAt(i, j);
      // Per axis, the ground vectors to the two neighbours (none: not shown)
      // and their steps per pixel.
      SeenAxis axis[2];
      const auto side = [&](SeenAxis* a, int k, bool has, size_t ni, size_t nj, double px) {
        if (!has || !shown(ni, nj) || !(px > 0.0)) return;
        a->to[k] = groundAt(ni, nj) - c.ground;
        a->step[k] = glm::length(a->to[k]) / px;
      };
      side(&axis[0], 0, i > 0, i - 1, j, i > 0 ? seen.xs[i] - seen.xs[i - 1] : 0.0);
      side(&axis[0], 1, i + 1 < w, i + 1, j, i + 1 < w ? seen.xs[i + 1] - seen.xs[i] : 0.0);
      side(&axis[1], 0, j > 0, i, j - 1, j > 0 ? seen.ys[j] - seen.ys[j - 1] : 0.0);
      side(&axis[1], 1, j + 1 < h, i, j + 1, j + 1 < h ? seen.ys[j + 1] - seen.ys[j] : 0.0);
      for (SeenAxis& a : axis) a.settle();
      if (!axis[0].any() && !axis[1].any()) continue;  // a lone point: no level of its own
      if (!axis[0].any()) axis[0] = axis[1].turned();
      if (!axis[1].any()) axis[1] = axis[0].turned();
      // The ground halfway to the neighbours on the screen: the box of the
      // four diagonal midpoints (exact on a plane).
      c.lo = c.hi = c.ground;
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b) {
          const glm::dvec2 q = c.ground + 0.5 * (axis[0].to[a] + axis[1].to[b]);
          c.lo = glm::min(c.lo, q);
          c.hi = glm::max(c.hi, q);
        }
      for (int k = 0; k < 2; ++k) {
        c.continuous[0][k] = axis[0].kept[k];
        c.continuous[1][k] = axis[1].kept[k];
      }
      // Seen from the camera being planned: a pixel's ground grows with its
      // distance. (Not with the obliquity to the surface as well: that is
      // exact for a plane, but from a surface normal taken across the grid's
      // steps the valley flight of scripts/bench_terrain_planning.sh loaded
      // twice the tiles, 4.1x those sampled against 2.2x: the prefetch's
      // camera half a second ahead sees the far ground steeper than it is.)
      double rho = std::max(axis[0].perPixel(), axis[1].perPixel());
      const glm::dvec3& p = seen.points[j * w + i];
      const double then = glm::length(p - seen.camera.position);
      const double now = glm::length(p - camera.position);
      if (then > 0.0) rho *= now / then;
      rho *= angle_ratio;
      c.lod = std::log2(std::max(rho, 1e-30));
    }
  }
  return corners;
}

void markSeen(uint32_t tile_px, const Viewport& viewport, const Camera& camera, const GroundSeen& seen,
              ClipmapPlan* plan, double lead_tiles) {
  const size_t w = seen.xs.size(), h = seen.ys.size();
  if (w < 2 || h < 2 || seen.points.size() != w * h) return;  // no grid: the whole windows
  const std::vector<SeenCorner> corners = seenCorners(seen, viewport, camera);
  // A frame that showed no ground (drawn before any height was resident,
  // or looking at the sky) says nothing of what to load: whole windows.
  if (std::none_of(corners.begin(), corners.end(), [](const SeenCorner& c) { return std::isfinite(c.lod); }))
    return;
  const std::vector<ClipLevelPlan*> levels = startMasks(plan);
  if (levels.empty()) return;
  // A cell per grid point: its ground halfway to its neighbours, at the
  // least level of detail over it (the level halfway to each neighbour on
  // its surface lies between theirs).
  SampleGrid grid;
  grid.w = w;
  grid.h = h;
  grid.cells.resize(w * h);
  for (size_t j = 0; j < h; ++j) {
    for (size_t i = 0; i < w; ++i) {
      const SeenCorner& c = corners[j * w + i];
      if (!std::isfinite(c.lod)) continue;  // no ground shown with a level of its own
      SampleCell& cell = grid.cells[j * w + i];
      cell.lod = c.lod;
      const auto halfway = [&](bool kept, size_t ni, size_t nj) {
        if (kept && std::isfinite(corners[nj * w + ni].lod))
          cell.lod = std::min(cell.lod, 0.5 * (c.lod + corners[nj * w + ni].lod));
      };
      if (i > 0) halfway(c.continuous[0][0], i - 1, j);
      if (i + 1 < w) halfway(c.continuous[0][1], i + 1, j);
      if (j > 0) halfway(c.continuous[1][0], i, j - 1);
      if (j + 1 < h) halfway(c.continuous[1][1], i, j + 1);
      // markSampledLevel() takes kSampleLodSlack off; over terrain the
      // slack is kSeenLodSlack in all.
      cell.lod -= kSeenLodSlack - kSampleLodSlack;
      cell.lo = c.lo;
      cell.hi = c.hi;
    }
  }
  const std::vector<SampleGrid> pyramid = buildCellPyramid(std::move(grid));
  const glm::dvec2 ahead = horizontalAhead(camera);
  for (ClipLevelPlan* lp : levels) markSampledLevel(pyramid, tile_px, ahead, lp, lead_tiles);
}

void markHeightReads(uint32_t tile_px, const Camera& camera, const HeightReads& reads, ClipmapPlan* plan) {
  if (reads.rects.empty() || tile_px == 0) return;
  for (ClipLevelPlan& lp : plan->stack)
    if (lp.needed && !lp.window.empty()) lp.sampled.assign(size_t(lp.window.width() * lp.window.height()), 0);
  const glm::dvec2 moved{camera.position.x - reads.camera.position.x, camera.position.z - reads.camera.position.z};
  const double tile = double(tile_px);
  for (const HeightReads::Rect& r : reads.rects) {
    if (r.level >= plan->stack.size()) continue;
    ClipLevelPlan& lp = plan->stack[r.level];
    if (lp.sampled.empty()) continue;  // not needed, or no window
    const glm::dvec2 d = moved * std::ldexp(1.0, -int(r.level));
    const glm::dvec2 lo = glm::min(glm::dvec2(r.s0), glm::dvec2(r.s0) + d);
    const glm::dvec2 hi = glm::max(glm::dvec2(r.s1), glm::dvec2(r.s1) + d);
    markTiles(&lp, intersect({int64_t(std::floor(lo.x / tile)), int64_t(std::floor(lo.y / tile)),
                              int64_t(std::floor(hi.x / tile)) + 1, int64_t(std::floor(hi.y / tile)) + 1},
                             lp.window));
  }
}

}  // namespace clipstream
