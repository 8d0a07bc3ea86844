// The steps of PlanScope::kSampled (sampled_scope.h), each alone: the
// screen's cell corners, the pyramid of blocks of cells, and the marking
// of one level's window, which must equal marking cell by cell. Whole plans
// with the sampled scope are in test_planner.cpp and the eval tests.
#include "../../streamer/src/sampled_scope.h"  // private: the steps under test

#include <clipstream/streamer/planner.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace clipstream {
namespace {

TEST(SampledScope, CornersArePixelCentresAStepApartEndingAtTheLast) {
  EXPECT_EQ(sampleCornerPositions(10.0, 4.0), (std::vector<double>{0.5, 4.5, 8.5, 9.5}));
  // A step that lands on the last centre does not list it twice.
  EXPECT_EQ(sampleCornerPositions(9.0, 4.0), (std::vector<double>{0.5, 4.5, 8.5}));
  EXPECT_EQ(sampleCornerPositions(2.0, 4.0), (std::vector<double>{0.5, 1.5}));
  // One pixel: its centre twice, so there is one cell (of no width).
  EXPECT_EQ(sampleCornerPositions(1.0, 4.0), (std::vector<double>{0.5, 0.5}));
  const std::vector<double> wide = sampleCornerPositions(1920.0, 20.0);
  EXPECT_EQ(wide.size(), 97u);  // 96 cells across
  EXPECT_EQ(wide.back(), 1919.5);
}

// A w x h grid whose cell (i, j) has level of detail lod(i, j) and the box
// [i, i + 1] x [j, j + 1] (texels).
SampleGrid grid(size_t w, size_t h, double (*lod)(size_t, size_t)) {
  SampleGrid g;
  g.w = w;
  g.h = h;
  g.cells.resize(w * h);
  for (size_t j = 0; j < h; ++j)
    for (size_t i = 0; i < w; ++i) {
      SampleCell& c = g.cells[j * w + i];
      c.lod = lod(i, j);
      if (std::isfinite(c.lod)) c.lo = {double(i), double(j)}, c.hi = {double(i + 1), double(j + 1)};
    }
  return g;
}

TEST(SampledScope, EachBlockHoldsTheLeastLodAndTheUnionOfItsCells) {
  // 5 x 3 cells: lod i + 10 j, but the cell (4, 2) sees no ground.
  const std::vector<SampleGrid> pyramid = buildCellPyramid(grid(5, 3, [](size_t i, size_t j) {
    return i == 4 && j == 2 ? INFINITY : double(i + 10 * j);
  }));
  ASSERT_EQ(pyramid.size(), 4u);
  const size_t sizes[4][2] = {{5, 3}, {3, 2}, {2, 1}, {1, 1}};
  for (size_t k = 0; k < 4; ++k) {
    EXPECT_EQ(pyramid[k].w, sizes[k][0]) << k;
    EXPECT_EQ(pyramid[k].h, sizes[k][1]) << k;
    EXPECT_EQ(pyramid[k].cells.size(), sizes[k][0] * sizes[k][1]) << k;
  }
  // Block (1, 0) of the first level holds cells (2..3, 0..1).
  const SampleCell& b = pyramid[1].cells[1];
  EXPECT_EQ(b.lod, 2.0);
  EXPECT_EQ(b.lo, glm::dvec2(2.0, 0.0));
  EXPECT_EQ(b.hi, glm::dvec2(4.0, 2.0));
  // The last block of the first level holds the cell with no ground alone.
  const SampleCell& edge = pyramid[1].cells[5];
  EXPECT_TRUE(std::isinf(edge.lod));
  EXPECT_GT(edge.lo.x, edge.hi.x);  // empty box
  // The top block holds every cell.
  const SampleCell& top = pyramid[3].cells[0];
  EXPECT_EQ(top.lod, 0.0);
  EXPECT_EQ(top.lo, glm::dvec2(0.0, 0.0));
  EXPECT_EQ(top.hi, glm::dvec2(5.0, 3.0));
  // A single cell is its own pyramid.
  EXPECT_EQ(buildCellPyramid(grid(1, 1, [](size_t, size_t) { return 1.0; })).size(), 1u);
}

// The window tiles the cells of `cells` sample, marked cell by cell (the
// rule markSampledLevel() applies through the block pyramid).
std::vector<uint8_t> markedCellByCell(const SampleGrid& cells, uint32_t tile_px, glm::dvec2 ahead,
                                      const ClipLevelPlan& lp) {
  std::vector<uint8_t> mask(size_t(lp.window.width()) * size_t(lp.window.height()), 0);
  const double texel = std::ldexp(1.0, int(lp.level));
  const double tile = double(tile_px) * texel;
  const glm::dvec2 lead = ahead * (kSampleLeadTiles * tile);
  for (const SampleCell& c : cells.cells) {
    if (!(c.lod - kSampleLodSlack < double(lp.level) + 1.0)) continue;
    const glm::dvec2 lo = glm::min(c.lo, c.lo + lead) - 0.5 * texel;
    const glm::dvec2 hi = glm::max(c.hi, c.hi + lead) + 0.5 * texel;
    for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
      for (int64_t x = lp.window.x0; x < lp.window.x1; ++x) {
        // The tile's texels [x tile, (x + 1) tile) meet the box.
        const bool touches = double(x + 1) * tile > lo.x && double(x) * tile <= hi.x &&
                             double(y + 1) * tile > lo.y && double(y) * tile <= hi.y;
        if (touches) mask[size_t(y - lp.window.y0) * size_t(lp.window.width()) + size_t(x - lp.window.x0)] = 1;
      }
  }
  return mask;
}

TEST(SampledScope, MarkingThroughTheBlocksEqualsMarkingCellByCell) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const uint32_t tile_px = 16;
  int marked_levels = 0;
  for (int trial = 0; trial < 300; ++trial) {
    // Cells of random size scattered over a 40-tile square of level 0,
    // levels of detail from -1 to 6, some with no ground.
    SampleGrid cells;
    cells.w = 1 + size_t(unit(rng) * 12);
    cells.h = 1 + size_t(unit(rng) * 9);
    cells.cells.resize(cells.w * cells.h);
    for (SampleCell& c : cells.cells) {
      if (unit(rng) < 0.1) continue;
      c.lod = -1.0 + 7.0 * unit(rng);
      const glm::dvec2 at{unit(rng) * 640.0, unit(rng) * 640.0};
      const glm::dvec2 size = glm::dvec2{unit(rng), unit(rng)} * (unit(rng) < 0.5 ? 8.0 : 200.0);
      c.lo = at;
      c.hi = at + size;
    }
    const std::vector<SampleGrid> pyramid = buildCellPyramid(cells);
    const double angle = unit(rng) * 6.283185307179586;
    const glm::dvec2 ahead = trial % 5 == 0 ? glm::dvec2{0.0, 0.0} : glm::dvec2{std::cos(angle), std::sin(angle)};
    for (uint32_t level = 0; level < 4; ++level) {
      ClipLevelPlan lp;
      lp.level = level;
      lp.needed = true;
      const int64_t side = int64_t(40 >> level);
      const int64_t x0 = int64_t(unit(rng) * double(side)), y0 = int64_t(unit(rng) * double(side));
      lp.window = {x0, y0, x0 + 1 + int64_t(unit(rng) * double(side)), y0 + 1 + int64_t(unit(rng) * double(side))};
      lp.sampled.assign(size_t(lp.window.width()) * size_t(lp.window.height()), 0);
      markSampledLevel(pyramid, tile_px, ahead, &lp);
      const std::vector<uint8_t> expected = markedCellByCell(cells, tile_px, ahead, lp);
      ASSERT_EQ(lp.sampled, expected) << "trial " << trial << " level " << level;
      if (std::count(expected.begin(), expected.end(), 1) > 0) ++marked_levels;
    }
  }
  EXPECT_GT(marked_levels, 600);  // the comparison saw marks, not empty masks
}

TEST(SampledScope, OnlyNeededLevelsGetAMaskAndTheGroundUnderTheViewIsMarked) {
  PyramidGeometry geometry;
  ASSERT_TRUE(makePyramidGeometry(1 << 16, 1 << 16, 128, PixelFormat::kRGBA8, &geometry));
  const Viewport viewport{320, 180};
  Camera camera;
  camera.position = {30000.0, 600.0, 30000.0};
  camera.pitch_rad = -1.5707963267948966;  // straight down
  PlannerConfig config;
  config.scope = PlanScope::kWindow;  // the windows alone; marked below
  ClipmapPlan plan = planClipmap(geometry, viewport, camera, config);
  ASSERT_TRUE(plan.ground_visible);
  ASSERT_GT(plan.finest_level, 0u);
  // The far limit planClipmap() gives: twice the texture's side plus the height.
  markSampled(geometry, viewport, camera, 2.0 * 65536.0 + 600.0, &plan);
  for (const ClipLevelPlan& lp : plan.stack) {
    if (!lp.needed) {
      EXPECT_TRUE(lp.sampled.empty()) << lp.level;
      continue;
    }
    ASSERT_EQ(lp.sampled.size(), size_t(lp.window.width()) * size_t(lp.window.height())) << lp.level;
    // Straight down, the tile under the camera is sampled at every needed level.
    const double tile = 128.0 * std::ldexp(1.0, int(lp.level));
    EXPECT_TRUE(lp.wants(int64_t(30000.0 / tile), int64_t(30000.0 / tile))) << lp.level;
  }
  // The finest needed level samples less than its whole window.
  const ClipLevelPlan& finest = plan.stack[plan.finest_level];
  EXPECT_LT(finest.wantedCount(), uint64_t(finest.window.width()) * uint64_t(finest.window.height()));
  // planClipmap() with the sampled scope marks the same tiles.
  config.scope = PlanScope::kSampled;
  const ClipmapPlan sampled = planClipmap(geometry, viewport, camera, config);
  ASSERT_EQ(sampled.stack.size(), plan.stack.size());
  for (size_t l = 0; l < plan.stack.size(); ++l) EXPECT_EQ(sampled.stack[l].sampled, plan.stack[l].sampled) << l;
}

}  // namespace
}  // namespace clipstream
