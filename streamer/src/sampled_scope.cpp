// PlanScope::kSampled on the flat plane: the screen's cells, their level of
// detail and ground, a pyramid of blocks of cells, and per needed level the
// window tiles they sample (sampled_scope.h).
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
                      ClipLevelPlan* lp) {
  struct Block {
    size_t grid, i, j;
  };
  const double reach = double(lp->level) + 1.0;  // a cell with lod - slack below it samples the level
  const double tile_texels = double(tile_px) * levelScale(lp->level);
  const double tap = 0.5 * levelScale(lp->level);  // bilinear: half a texel of the level
  const glm::dvec2 lead = ahead * (kSampleLeadTiles * tile_texels);
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
  const double W = viewport.width_px, H = viewport.height_px;
  const double step = std::max(kSampleStepMinPx, std::max(W, H) / kSampleCellsMax);
  const std::vector<double> xs = sampleCornerPositions(W, step);
  const std::vector<double> ys = sampleCornerPositions(H, step);
  const std::vector<Corner> corners = sampleCorners(ScreenRays(viewport, camera), xs, ys, far_h);

  const std::vector<ClipLevelPlan*> levels = startMasks(plan);
  if (levels.empty()) return;
  // The cells, then blocks of 2x2 cells (blocks of blocks...), so that
  // marking costs what the tiles do, not the cells times the levels.
  const std::vector<SampleGrid> pyramid = buildCellPyramid(cellsOf(corners, xs.size(), ys.size()));
  const glm::dvec2 ahead = horizontalAhead(camera);
  for (ClipLevelPlan* lp : levels) markSampledLevel(pyramid, geometry.tile_px, ahead, lp);
}

}  // namespace clipstream
