// The steps of PlanScope::kSampled (sampled_scope.h), each alone: the
// screen's cell corners, the pyramid of blocks of cells, and the marking
// of one level's window, which must equal marking cell by cell; over
// terrain (markSeen()), the ground a frame showed. Whole plans
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

// The pyramid of a 65536^2 texture of 128^2 tiles.
PyramidGeometry texture64k() {
  PyramidGeometry geometry;
  EXPECT_TRUE(makePyramidGeometry(1 << 16, 1 << 16, 128, PixelFormat::kRGBA8, &geometry));
  return geometry;
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
  const PyramidGeometry geometry = texture64k();
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


// Over terrain (markSeen()): the ground a frame showed, here cast on the
// CPU. `hit` takes a ray (origin, direction) and gives the point it shows,
// or false for sky.
template <typename Hit>
GroundSeen seenBy(const Camera& camera, const Viewport& viewport, Hit hit) {
  GroundSeen seen;
  seen.camera = camera;
  seen.viewport = viewport;
  groundSeenGrid(viewport, &seen.xs, &seen.ys);
  const double tan_half = std::tan(camera.vfov_rad * 0.5);
  const glm::dvec3 right = camera.right() * (tan_half * viewport.width_px / viewport.height_px);
  const glm::dvec3 up = camera.up() * tan_half;
  for (double y : seen.ys)
    for (double x : seen.xs) {
      const glm::dvec3 d = camera.forward() + right * (2.0 * x / viewport.width_px - 1.0) +
                           up * (1.0 - 2.0 * y / viewport.height_px);
      glm::dvec3 p(NAN);
      if (!hit(camera.position, d, &p)) p = glm::dvec3(NAN);
      seen.points.push_back(p);
    }
  return seen;
}

bool planeHit(const glm::dvec3& o, const glm::dvec3& d, glm::dvec3* p) {
  if (d.y >= 0.0) return false;
  *p = o + d * (-o.y / d.y);
  return true;
}

size_t marked(const ClipLevelPlan& lp) { return size_t(std::count(lp.sampled.begin(), lp.sampled.end(), 1)); }

TEST(SeenScope, FlatGroundSeenMarksWhatThePlaneMarks) {
  const PyramidGeometry geometry = texture64k();
  const Viewport viewport{320, 180};
  size_t both = 0, plane_only = 0, seen_only = 0;
  for (const double pitch : {-1.5707963267948966, -0.9, -0.45, -0.25}) {
    Camera camera;
    camera.position = {30000.0, 600.0, 31000.0};
    camera.heading_rad = 0.7;
    camera.pitch_rad = pitch;
    PlannerConfig config;
    config.scope = PlanScope::kWindow;
    ClipmapPlan plane = planClipmap(geometry, viewport, camera, config);
    ClipmapPlan seen = plane;
    markSampled(geometry, viewport, camera, 2.0 * 65536.0 + 600.0, &plane);
    // With the plane's lead, to compare like with like.
    markSeen(geometry.tile_px, viewport, camera, seenBy(camera, viewport, planeHit), &seen, kSampleLeadTiles);
    for (size_t l = 0; l < plane.stack.size(); ++l) {
      const ClipLevelPlan &a = plane.stack[l], &b = seen.stack[l];
      if (!a.needed) continue;
      ASSERT_EQ(a.sampled.size(), b.sampled.size()) << l;
      for (size_t k = 0; k < a.sampled.size(); ++k) {
        both += a.sampled[k] && b.sampled[k];
        plane_only += a.sampled[k] && !b.sampled[k];
        seen_only += !a.sampled[k] && b.sampled[k];
      }
    }
  }
  std::printf("plane and seen: %zu tiles, the plane's alone %zu, the seen ground's alone %zu\n", both, plane_only,
              seen_only);
  ASSERT_GT(both, 150u);
  // On a plane the two agree but at the margins: the plane's grid also
  // stands for the ground beyond the horizon, the seen grid only for what
  // its points showed; the seen ground's larger slack (kSeenLodSlack)
  // marks a few more tiles where the level lies near the next.
  EXPECT_LE(seen_only * 10, both);
  EXPECT_LE(plane_only * 20, both);
}

TEST(SeenScope, GroundHiddenBehindARidgeIsNotMarked) {
  const PyramidGeometry geometry = texture64k();
  const Viewport viewport{320, 180};
  // Looking north (-z) from 300 up at a wall facing the camera 2,000 ahead,
  // 250 high, with the plain beyond it: the ray over the wall's top meets
  // the plain 12,000 ahead, so the plain from 2,000 to 12,000 is hidden.
  Camera camera;
  camera.position = {30000.0, 300.0, 40000.0};
  camera.pitch_rad = -0.05;
  const double wall_z = 38000.0, wall_top = 250.0;
  auto ridge = [&](const glm::dvec3& o, const glm::dvec3& d, glm::dvec3* p) {
    if (d.z < 0.0) {
      const double t = (wall_z - o.z) / d.z;
      const glm::dvec3 at = o + d * t;
      if (at.y >= 0.0 && at.y <= wall_top && (!(d.y < 0.0) || -o.y / d.y >= t)) {
        *p = at;
        return true;
      }
    }
    return planeHit(o, d, p);
  };
  PlannerConfig config;
  config.scope = PlanScope::kWindow;
  ClipmapPlan plan = planClipmap(geometry, viewport, camera, config);
  markSeen(geometry.tile_px, viewport, camera, seenBy(camera, viewport, ridge), &plan);
  // The wall's level: its face seen square on, a pixel spans its distance
  // times the pixel's angle.
  const double pixel = 2.0 * std::tan(camera.vfov_rad * 0.5) / viewport.height_px;
  const uint32_t wall_level = uint32_t(std::floor(std::log2(2000.0 * pixel)));
  size_t wall_tiles = 0, hidden_tiles = 0;
  ASSERT_LT(wall_level + 2, plan.stack.size());
  for (uint32_t level = wall_level; level < plan.stack.size(); ++level) {
    const ClipLevelPlan& lp = plan.stack[level];
    ASSERT_TRUE(lp.needed) << level;
    const double tile = 128.0 * std::ldexp(1.0, int(level));
    for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
      for (int64_t x = lp.window.x0; x < lp.window.x1; ++x) {
        if (!lp.wants(x, y)) continue;
        if (y * tile <= wall_z && (y + 1) * tile > wall_z - 1.0) ++wall_tiles;
        // Wholly within the hidden plain, a tile clear of both ends and of
        // the lead the wall's ground reaches ahead (kSeenLeadTiles).
        if ((y + 1) * tile < wall_z - (kSeenLeadTiles + 0.5) * tile && y * tile > camera.position.z - 11000.0)
          ++hidden_tiles;
      }
  }
  EXPECT_GT(wall_tiles, 0u);
  EXPECT_EQ(hidden_tiles, 0u);
}

// The level of detail of the flat plane's pixel at (px, py) for `camera`:
// log2 of the longer ground step to the next pixel across and up (the
// shader's rule), from rays cast one pixel apart.
double planeLod(const Camera& camera, const Viewport& viewport, double px, double py) {
  glm::dvec2 at, across, up;
  EXPECT_TRUE(groundHit(camera, viewport, px, py, &at));
  EXPECT_TRUE(groundHit(camera, viewport, px + 1.0, py, &across));
  EXPECT_TRUE(groundHit(camera, viewport, px, py - 1.0, &up));
  return std::log2(std::max(glm::length(across - at), glm::length(up - at)));
}

// Where world point p lies on the screen of `camera` (pixels, y down).
glm::dvec2 project(const Camera& camera, const Viewport& viewport, const glm::dvec3& p) {
  const glm::dvec3 d = p - camera.position;
  const double z = glm::dot(d, camera.forward());
  const double tan_half = std::tan(camera.vfov_rad * 0.5);
  const double aspect = double(viewport.width_px) / viewport.height_px;
  const double x = glm::dot(d, camera.right()) / (z * tan_half * aspect);
  const double y = glm::dot(d, camera.up()) / (z * tan_half);
  return {(x + 1.0) * 0.5 * viewport.width_px, (1.0 - y) * 0.5 * viewport.height_px};
}

TEST(SeenScope, AGridPointsLevelIsThePixelsSeenFromThePlannedCamera) {
  const Viewport viewport{320, 180};
  Camera camera;
  camera.position = {30000.0, 600.0, 31000.0};
  camera.heading_rad = 0.3;
  camera.pitch_rad = -0.6;
  const GroundSeen seen = seenBy(camera, viewport, planeHit);
  const size_t w = seen.xs.size(), h = seen.ys.size();
  // From the camera that saw it: the shader's level at that pixel (its
  // one-pixel step), within what the grid's steps (2 px each way) tell.
  const std::vector<SeenCorner> same = seenCorners(seen, viewport, camera);
  // From the next frame's camera (a step of 20 units ahead and a little
  // turned, as at 1,200 units a second): the level its own pixel there has.
  Camera other = camera;
  other.position += 20.0 * glm::dvec3(std::sin(camera.heading_rad), 0.0, -std::cos(camera.heading_rad));
  other.heading_rad += 0.01;
  other.pitch_rad -= 0.005;
  const std::vector<SeenCorner> moved = seenCorners(seen, viewport, other);
  size_t compared = 0, compared_moved = 0;
  double worst_coarser = -INFINITY, worst_finer = INFINITY;
  for (size_t j = 2; j + 2 < h; j += 3)
    for (size_t i = 2; i + 2 < w; i += 3) {
      const SeenCorner& c = same[j * w + i];
      if (!std::isfinite(c.lod)) continue;
      EXPECT_NEAR(c.lod, planeLod(camera, viewport, seen.xs[i], seen.ys[j]), 0.1) << i << "," << j;
      ++compared;
      const glm::dvec2 at = project(other, viewport, seen.points[j * w + i]);
      if (at.x < 1.0 || at.y < 1.0 || at.x > viewport.width_px - 2.0 || at.y > viewport.height_px - 2.0) continue;
      // Within the slack the marking allows (kSeenLodSlack): coarser would
      // leave a sampled tile out, finer loads one more.
      const double error = moved[j * w + i].lod - planeLod(other, viewport, at.x, at.y);
      EXPECT_LE(error, kSeenLodSlack) << i << "," << j;
      EXPECT_GE(error, -kSeenLodSlack) << i << "," << j;
      worst_coarser = std::max(worst_coarser, error);
      worst_finer = std::min(worst_finer, error);
      ++compared_moved;
    }
  EXPECT_GT(compared, 100u);
  EXPECT_GT(compared_moved, 50u);
  std::printf("levels from the next frame's camera against its pixels': %.3f coarser at most, %.3f finer at "
              "most\n", worst_coarser, -worst_finer);
  // From a camera 300 units back along the view (the distance grows by a
  // third to a half, as for the prefetch's camera half a second ahead at
  // 600 units a second): the distance carries the level to within a third
  // of a level (the view's changed obliquity, left out; without the
  // distance the error is up to 0.8).
  Camera back = camera;
  back.position -= 300.0 * camera.forward();
  const std::vector<SeenCorner> far = seenCorners(seen, viewport, back);
  double back_coarser = -INFINITY, back_finer = INFINITY;
  size_t compared_back = 0;
  for (size_t j = 2; j + 2 < h; j += 3)
    for (size_t i = 2; i + 2 < w; i += 3) {
      if (!std::isfinite(far[j * w + i].lod)) continue;
      const glm::dvec2 at = project(back, viewport, seen.points[j * w + i]);
      const double error = far[j * w + i].lod - planeLod(back, viewport, at.x, at.y);
      EXPECT_LE(std::abs(error), 0.35) << i << "," << j;
      back_coarser = std::max(back_coarser, error);
      back_finer = std::min(back_finer, error);
      ++compared_back;
    }
  EXPECT_GT(compared_back, 100u);
  std::printf("from 300 units back: %.3f coarser at most, %.3f finer at most\n", back_coarser, -back_finer);
}

TEST(SeenScope, OneRowOfGroundMarksItsTilesAndNoGroundLeavesTheWindowsWhole) {
  const PyramidGeometry geometry = texture64k();
  const Viewport viewport{320, 180};
  Camera camera;
  camera.position = {30000.0, 600.0, 31000.0};
  camera.pitch_rad = -0.6;
  const GroundSeen seen = seenBy(camera, viewport, planeHit);
  PlannerConfig config;
  config.scope = PlanScope::kWindow;
  const ClipmapPlan windows = planClipmap(geometry, viewport, camera, config);
  // A single row of the grid shows ground (a ridge's crest between sky
  // above and a hole below): its points have neighbours across only, and
  // still mark the ground under them.
  GroundSeen row = seen;
  const size_t w = seen.xs.size(), keep = seen.ys.size() / 2;
  for (size_t k = 0; k < row.points.size(); ++k)
    if (k / w != keep) row.points[k] = glm::dvec3(NAN);
  ClipmapPlan plan = windows;
  markSeen(geometry.tile_px, viewport, camera, row, &plan);
  const glm::dvec3 middle = seen.points[keep * w + w / 2];
  size_t levels_marked = 0;
  for (const ClipLevelPlan& lp : plan.stack) {
    if (!lp.needed || lp.sampled.empty()) continue;
    const double tile = 128.0 * std::ldexp(1.0, int(lp.level));
    if (marked(lp) > 0) ++levels_marked;
    // Every level down to the row's is sampled at its middle point.
    if (double(lp.level) + 1.0 > seenCorners(row, viewport, camera)[keep * w + w / 2].lod) {
      EXPECT_TRUE(lp.wants(int64_t(middle.x / tile), int64_t(middle.z / tile))) << lp.level;
    }
  }
  EXPECT_GT(levels_marked, 0u);
  // A frame that showed no ground (drawn before any height was resident)
  // says nothing: the windows stay whole.
  GroundSeen sky = seen;
  std::fill(sky.points.begin(), sky.points.end(), glm::dvec3(NAN));
  plan = windows;
  markSeen(geometry.tile_px, viewport, camera, sky, &plan);
  size_t needed = 0;
  for (const ClipLevelPlan& lp : plan.stack)
    if (lp.needed) {
      ++needed;
      EXPECT_TRUE(lp.sampled.empty()) << lp.level;
      EXPECT_EQ(lp.wantedCount(), uint64_t(lp.window.width()) * uint64_t(lp.window.height())) << lp.level;
    }
  EXPECT_GT(needed, 0u);
}

// Two needed stack levels of 8 x 8 tiles of 32 samples (an elevation
// layer's texels are its samples), with nothing marked yet.
ClipmapPlan heightPlan() {
  ClipmapPlan plan;
  plan.pyramid_level = 2;
  plan.stack.resize(2);
  for (uint32_t l = 0; l < 2; ++l) {
    plan.stack[l].level = l;
    plan.stack[l].needed = true;
    plan.stack[l].window = {0, 0, 8, 8};
  }
  return plan;
}

std::vector<glm::i64vec2> wantedTiles(const ClipLevelPlan& lp) {
  std::vector<glm::i64vec2> out;
  for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
    for (int64_t x = lp.window.x0; x < lp.window.x1; ++x)
      if (lp.wants(x, y)) out.push_back({x, y});
  return out;
}

TEST(HeightReadsScope, ALevelWantsTheTilesUnderItsReadsAndNothingElse) {
  Camera camera;
  camera.position = {100.0, 50.0, 100.0};
  HeightReads reads;
  reads.camera = camera;
  reads.rects.push_back({0, {10, 40}, {40, 60}});  // level-0 tiles x 0..1, y 1
  ClipmapPlan plan = heightPlan();
  markHeightReads(32, camera, reads, &plan);
  EXPECT_EQ(wantedTiles(plan.stack[0]), (std::vector<glm::i64vec2>{{0, 1}, {1, 1}}));
  // Level 1 was read nowhere: it wants nothing (not its whole window).
  ASSERT_EQ(plan.stack[1].sampled.size(), 64u);
  EXPECT_TRUE(wantedTiles(plan.stack[1]).empty());
  // A rect's samples are its last included: one more reaches the next tile.
  reads.rects[0].s1.x = 64;
  plan = heightPlan();
  markHeightReads(32, camera, reads, &plan);
  EXPECT_EQ(wantedTiles(plan.stack[0]), (std::vector<glm::i64vec2>{{0, 1}, {1, 1}, {2, 1}}));
}

TEST(HeightReadsScope, ReadsAreSweptToThePlannedCameraAtEachLevelsScale) {
  Camera seen_from;
  seen_from.position = {100.0, 50.0, 100.0};
  HeightReads reads;
  reads.camera = seen_from;
  reads.rects.push_back({0, {10, 40}, {40, 60}});
  reads.rects.push_back({1, {5, 40}, {20, 50}});
  // The planned camera 64 samples along +x: the level-0 rect sweeps to
  // x 10..104 (tiles 0..3), level 1's by 32 of its samples to 5..52 (0..1).
  Camera planned = seen_from;
  planned.position.x += 64.0;
  ClipmapPlan plan = heightPlan();
  markHeightReads(32, planned, reads, &plan);
  EXPECT_EQ(wantedTiles(plan.stack[0]), (std::vector<glm::i64vec2>{{0, 1}, {1, 1}, {2, 1}, {3, 1}}));
  EXPECT_EQ(wantedTiles(plan.stack[1]), (std::vector<glm::i64vec2>{{0, 1}, {1, 1}}));
  // A level the plan does not need keeps no mask; reads without rects
  // leave every window whole.
  plan = heightPlan();
  plan.stack[0].needed = false;
  markHeightReads(32, planned, reads, &plan);
  EXPECT_TRUE(plan.stack[0].sampled.empty());
  EXPECT_EQ(wantedTiles(plan.stack[1]).size(), 2u);
  plan = heightPlan();
  markHeightReads(32, planned, HeightReads{}, &plan);
  EXPECT_TRUE(plan.stack[0].sampled.empty() && plan.stack[1].sampled.empty());
  EXPECT_EQ(plan.stack[1].wantedCount(), 64u);
}

}  // namespace
}  // namespace clipstream
