// Planner and camera: windows, level choice, edges, deltas, ranking, and a
// 2^26-texel texture planned without precision loss.
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/testing/cameras.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <tuple>

namespace clipstream {
namespace {

using test::kPi;
using test::lookingDown;

PyramidGeometry geometryOf(uint64_t w, uint64_t h, uint32_t tile_px = 128) {
  PyramidGeometry g;
  EXPECT_TRUE(makePyramidGeometry(w, h, tile_px, PixelFormat::kRGB8, &g));
  return g;
}

TEST(Camera, BasisFollowsWorldConventions) {
  Camera c;
  c.pitch_rad = 0.0;
  c.heading_rad = 0.0;
  EXPECT_NEAR(c.forward().z, -1.0, 1e-12);
  EXPECT_NEAR(c.right().x, 1.0, 1e-12);
  EXPECT_NEAR(c.up().y, 1.0, 1e-12);
  c.heading_rad = kPi / 2;
  EXPECT_NEAR(c.forward().x, 1.0, 1e-12);
  EXPECT_NEAR(c.right().z, 1.0, 1e-12);
  c.pitch_rad = -0.7;
  EXPECT_NEAR(glm::dot(c.forward(), c.right()), 0.0, 1e-12);
  EXPECT_NEAR(glm::dot(c.forward(), c.up()), 0.0, 1e-12);
  EXPECT_NEAR(glm::length(c.up()), 1.0, 1e-12);
}

TEST(Camera, GroundHitOfCentrePixelFollowsTheViewRay) {
  Camera c;
  c.position = {100.0, 50.0, 100.0};
  c.pitch_rad = -kPi / 4;
  Viewport vp{800, 600};
  glm::dvec2 hit;
  ASSERT_TRUE(groundHit(c, vp, 400.0, 300.0, &hit));
  EXPECT_NEAR(hit.x, 100.0, 1e-9);
  EXPECT_NEAR(hit.y, 50.0, 1e-9);  // 45 degrees down from height 50, looking north (-z)
  c.pitch_rad = 0.2;
  EXPECT_FALSE(groundHit(c, vp, 400.0, 0.0, &hit));
  // Projection * view maps the forward point to the screen centre.
  Camera d;
  d.position = {0, 10, 0};
  const glm::dmat4 m = cameraProjection(d, vp, 1000.0) * cameraRelativeView(d);
  const glm::dvec4 p = m * glm::dvec4(d.forward() * 10.0, 1.0);
  EXPECT_NEAR(p.x / p.w, 0.0, 1e-9);
  EXPECT_NEAR(p.y / p.w, 0.0, 1e-9);
}

TEST(Planner, WindowIsCentredOnTheGroundPointAndSnapped) {
  const PyramidGeometry g = geometryOf(1 << 16, 1 << 16);
  PlannerConfig cfg;
  cfg.clip_tiles = 16;
  const ClipmapPlan plan = planClipmap(g, Viewport{1024, 768}, lookingDown(5000.3, 7000.2, 300.0), cfg);
  ASSERT_GT(plan.stack.size(), 3u);
  for (const ClipLevelPlan& lp : plan.stack) {
    const double tile_texels = 128.0 * std::ldexp(1.0, int(lp.level));
    const double cx = 5000.3 / tile_texels, cz = 7000.2 / tile_texels;
    EXPECT_EQ(lp.window.width(), 16) << "level " << lp.level;
    EXPECT_EQ(lp.window.height(), 16) << "level " << lp.level;
    // Straight down: no forward shift, so the centre is within half a tile
    // of the ground point, unless the window had to shift inside the level.
    const double tiles = double(g.levels[lp.level].tiles_x);
    const double ex = std::clamp(std::floor(cx - 8.0 + 0.5), 0.0, tiles - 16.0);
    const double ez = std::clamp(std::floor(cz - 8.0 + 0.5), 0.0, tiles - 16.0);
    EXPECT_EQ(double(lp.window.x0), ex) << "level " << lp.level;
    EXPECT_EQ(double(lp.window.y0), ez) << "level " << lp.level;
    if (ex > 0.0) {
      EXPECT_LE(std::abs(double(lp.window.x0) + 8.0 - cx), 0.5 + 1e-9);
    }
    EXPECT_EQ(lp.origin_tx, lp.window.x0);
    EXPECT_TRUE(lp.visible.empty() || (lp.window.contains(lp.visible.x0, lp.visible.y0) &&
                                       lp.window.contains(lp.visible.x1 - 1, lp.visible.y1 - 1)));
  }
  // Level 0 tile under the camera is visible.
  EXPECT_TRUE(plan.stack[2].visible.contains(int64_t(5000.3 / 512), int64_t(7000.2 / 512)));
}

// A viewport one pixel wide or high (a window being resized, a thin strip)
// plans without reading outside its grid of screen cells: the pyramid is
// wanted, as always, and a one-pixel-wide column samples the stack tiles
// it sees. (A one-pixel-high row needs no stack level: the planner finds no
// visible ground footprint in it, so it is drawn from the pyramid.)
TEST(Planner, AViewportOnePixelWideOrHighPlans) {
  const PyramidGeometry g = geometryOf(1 << 16, 1 << 16);
  PlannerConfig cfg;
  cfg.clip_tiles = 16;
  ASSERT_EQ(cfg.scope, PlanScope::kSampled);
  for (const Viewport vp : {Viewport{1, 180}, Viewport{320, 1}, Viewport{1, 1}}) {
    SCOPED_TRACE(std::to_string(vp.width_px) + "x" + std::to_string(vp.height_px));
    Camera cam = lookingDown(5000.3, 7000.2, 300.0);
    cam.pitch_rad = -1.2;
    const ClipmapPlan plan = planClipmap(g, vp, cam, cfg);
    ASSERT_FALSE(plan.pyramid.empty());
    EXPECT_FALSE(rankPlanTiles(g, plan, true).empty());
    size_t sampled_tiles = 0;
    for (const ClipLevelPlan& lp : plan.stack) {
      if (!lp.needed) continue;
      for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
        for (int64_t x = lp.window.x0; x < lp.window.x1; ++x) sampled_tiles += lp.wants(x, y) ? 1 : 0;
    }
    if (vp.height_px > 1) {
      EXPECT_GT(sampled_tiles, 0u);
    }
  }
}

TEST(Planner, WindowsStayInsideTheTextureAtItsEdges) {
  const PyramidGeometry g = geometryOf(1 << 15, 1 << 15);
  PlannerConfig cfg;
  cfg.clip_tiles = 10;
  const ClipmapPlan at_origin = planClipmap(g, Viewport{800, 600}, lookingDown(1.0, 1.0, 200.0), cfg);
  for (const ClipLevelPlan& lp : at_origin.stack) {
    EXPECT_EQ(lp.window, (TileRect{0, 0, 10, 10})) << "level " << lp.level;
  }
  const double far = double(1 << 15) - 1.0;
  const ClipmapPlan at_corner = planClipmap(g, Viewport{800, 600}, lookingDown(far, far, 200.0), cfg);
  for (const ClipLevelPlan& lp : at_corner.stack) {
    const int64_t tiles = g.levels[lp.level].tiles_x;
    EXPECT_EQ(lp.window, (TileRect{tiles - 10, tiles - 10, tiles, tiles})) << "level " << lp.level;
  }
}

TEST(Planner, NonPowerOfTwoStoreHasConsistentLevels) {
  const PyramidGeometry g = geometryOf(3248, 4385);  // 26 x 35 tiles at level 0
  PlannerConfig cfg;
  cfg.clip_tiles = 12;
  const ClipmapPlan plan = planClipmap(g, Viewport{640, 480}, lookingDown(3000.0, 4300.0, 50.0), cfg);
  // Level 1: 13 x 18 tiles (no fit), level 2: 7 x 9 (fits).
  EXPECT_EQ(plan.pyramid_level, 2u);
  ASSERT_EQ(plan.stack.size(), 2u);
  ASSERT_EQ(plan.pyramid.size(), g.levelCount() - 2);
  EXPECT_EQ(plan.pyramid[0], (TileRect{0, 0, 7, 9}));
  // Level 1 is 13 tiles wide: the window shifts inside, 12 wide.
  EXPECT_EQ(plan.stack[1].window.x1, 13);
  EXPECT_EQ(plan.stack[1].window.width(), 12);
  EXPECT_EQ(plan.stack[1].window.y1, 18);
  EXPECT_EQ(plan.stack[0].window, (TileRect{14, 23, 26, 35}));
}

TEST(Planner, FinestLevelFollowsTexelDensity) {
  const PyramidGeometry g = geometryOf(1 << 20, 1 << 20);
  PlannerConfig cfg;
  cfg.clip_tiles = 16;
  cfg.max_oversample = 2.0;
  const Viewport vp{1000, 1000};
  const double pixel_angle = 2.0 * std::tan(Camera{}.vfov_rad / 2) / 1000.0;
  // Straight down: the nearest visible point is the nadir at distance h.
  struct Case {
    double footprint_texels;
    uint32_t finest;
  } cases[] = {{0.5, 0}, {2.0, 0}, {3.0, 1}, {12.0, 3}, {100.0, 6}};
  for (const Case& c : cases) {
    const double h = c.footprint_texels / pixel_angle;
    const ClipmapPlan plan = planClipmap(g, vp, lookingDown(500000.0, 500000.0, h), cfg);
    EXPECT_EQ(plan.finest_level, c.finest) << "footprint " << c.footprint_texels;
    for (const ClipLevelPlan& lp : plan.stack) EXPECT_EQ(lp.needed, lp.level >= c.finest);
  }
}

TEST(Planner, LookingAtTheSkyNeedsNoStackLevel) {
  const PyramidGeometry g = geometryOf(1 << 16, 1 << 16);
  Camera c = lookingDown(1000.0, 1000.0, 100.0);
  c.pitch_rad = 0.9;  // 30 degree half-fov: the lowest ray still points up
  const ClipmapPlan plan = planClipmap(g, Viewport{800, 600}, c, PlannerConfig{});
  EXPECT_FALSE(plan.ground_visible);
  for (const ClipLevelPlan& lp : plan.stack) EXPECT_FALSE(lp.needed);
}

TEST(Planner, FarCornerOf2To26TextureKeepsSubTexelPrecision) {
  const uint64_t side = uint64_t(1) << 26;
  const PyramidGeometry g = geometryOf(side, side);
  PlannerConfig cfg;
  cfg.clip_tiles = 8;
  const double x = double(side) - 200.25, z = double(side) - 1000.75;
  Camera c = lookingDown(x, z, 100.0);
  c.pitch_rad = -kPi / 2 + 1e-3;  // almost straight down, heading north
  glm::dvec2 hit;
  ASSERT_TRUE(groundHit(c, Viewport{800, 800}, 400.0, 400.0, &hit));
  EXPECT_NEAR(hit.x, x, 1e-6);
  EXPECT_NEAR(hit.y, z - 100.0 * std::tan(1e-3), 1e-6);
  const ClipmapPlan plan = planClipmap(g, Viewport{800, 800}, c, cfg);
  const uint32_t tiles0 = g.levels[0].tiles_x;  // 2^19
  ASSERT_EQ(tiles0, 1u << 19);
  const ClipLevelPlan& l0 = plan.stack[0];
  EXPECT_EQ(l0.window.x1, int64_t(tiles0));
  EXPECT_EQ(l0.window.x0, int64_t(tiles0) - 8);
  // z: 1000.75 texels from the edge = tile 2^19 - 8 (7.8 tiles in); centred window fits.
  EXPECT_TRUE(l0.visible.contains(int64_t(x / 128.0), int64_t(z / 128.0)));
  EXPECT_EQ(l0.visible.x1 - 1, int64_t(x / 128.0) + (std::fmod(x, 128.0) > 127 ? 1 : 0));
  EXPECT_TRUE(l0.needed);
  const std::vector<TileKey> ranked = rankPlanTiles(g, plan);
  ASSERT_FALSE(ranked.empty());
  EXPECT_EQ(ranked.back().level, 0u);
  // The nearest level-0 tile is the camera's own tile: it is the first level-0 tile ranked.
  for (const TileKey& k : ranked) {
    if (k.level != 0) continue;
    EXPECT_EQ(k.x, uint32_t(x / 128.0));
    EXPECT_EQ(k.y, uint32_t(z / 128.0));
    break;
  }
}

TEST(Planner, DiffPlansReportsTheColumnsThatEnterAndLeave) {
  const PyramidGeometry g = geometryOf(1 << 16, 1 << 16);
  PlannerConfig cfg;
  cfg.clip_tiles = 8;
  cfg.scope = PlanScope::kWindow;  // whole windows
  const Viewport vp{800, 600};
  const ClipmapPlan a = planClipmap(g, vp, lookingDown(20000.0 + 64, 20000.0 + 64, 4.0), cfg);
  const ClipmapPlan b = planClipmap(g, vp, lookingDown(20000.0 + 64 + 128, 20000.0 + 64, 4.0), cfg);
  const PlanDelta d = diffPlans(a, b);
  // Level 0 moves one tile east; coarser levels may or may not move.
  size_t entered0 = 0, left0 = 0;
  for (const TileKey& k : d.entered) {
    if (k.level != 0) continue;
    ++entered0;
    EXPECT_EQ(int64_t(k.x), b.stack[0].window.x1 - 1);
  }
  for (const TileKey& k : d.left) {
    if (k.level != 0) continue;
    ++left0;
    EXPECT_EQ(int64_t(k.x), a.stack[0].window.x0);
  }
  EXPECT_EQ(entered0, 8u);
  EXPECT_EQ(left0, 8u);
  EXPECT_EQ(b.stack[0].window.x0, a.stack[0].window.x0 + 1);
  // Every entered tile is in b's wanted windows and not in a's.
  for (const TileKey& k : d.entered) {
    if (k.level >= b.pyramid_level) continue;
    EXPECT_TRUE(b.stack[k.level].window.contains(k.x, k.y));
    EXPECT_FALSE(a.stack[k.level].needed && a.stack[k.level].window.contains(k.x, k.y));
  }
  EXPECT_TRUE(diffPlans(a, a).entered.empty());
  EXPECT_TRUE(diffPlans(a, a).left.empty());
}

TEST(Planner, RankPutsPyramidFirstThenCoarseToFineVisibleFirstNearFirst) {
  const PyramidGeometry g = geometryOf(1 << 16, 1 << 16);
  PlannerConfig cfg;
  cfg.clip_tiles = 8;
  cfg.scope = PlanScope::kWindow;  // whole windows
  Camera c = lookingDown(30000.0, 30000.0, 30.0);
  c.pitch_rad = -0.6;
  c.heading_rad = 0.4;
  const ClipmapPlan plan = planClipmap(g, Viewport{800, 600}, c, cfg);
  const std::vector<TileKey> ranked = rankPlanTiles(g, plan);
  size_t expected = 0;
  for (const TileRect& r : plan.pyramid) expected += size_t(r.width() * r.height());
  for (const ClipLevelPlan& lp : plan.stack)
    if (lp.needed) expected += size_t(lp.window.width() * lp.window.height());
  ASSERT_EQ(ranked.size(), expected);
  std::set<std::tuple<uint32_t, uint32_t, uint32_t>> unique;
  int last_hidden = 0;
  double last_dist = -1.0;
  uint32_t last_level = UINT32_MAX;
  bool saw_hidden = false;
  for (const TileKey& k : ranked) {
    unique.insert({k.level, k.x, k.y});
    ASSERT_LE(k.level, last_level);
    const bool pyramid = k.level >= plan.pyramid_level;
    const int hidden = pyramid ? 0 : !plan.stack[k.level].visible.contains(k.x, k.y);
    if (k.level != last_level) {
      last_hidden = 0;
      last_dist = -1.0;
    }
    ASSERT_GE(hidden, last_hidden) << "visible after hidden in level " << k.level;
    if (hidden != last_hidden) last_dist = -1.0;
    const double t = 128.0 * std::ldexp(1.0, int(k.level));
    const double dx = k.x + 0.5 - plan.focus_texel.x / t, dy = k.y + 0.5 - plan.focus_texel.y / t;
    const double dist = dx * dx + dy * dy;
    ASSERT_GE(dist, last_dist - 1e-9);
    saw_hidden |= hidden != 0;
    last_dist = dist;
    last_hidden = hidden;
    last_level = k.level;
  }
  EXPECT_TRUE(saw_hidden);
  EXPECT_EQ(unique.size(), ranked.size());
}

TEST(Planner, ClipSizeCoversTwiceTheScreenPlusATile) {
  EXPECT_EQ(chooseClipTiles(Viewport{1280, 720}, 128), 21u);
  EXPECT_EQ(chooseClipTiles(Viewport{1920, 1080}, 256), 16u);
  EXPECT_EQ(chooseClipTiles(Viewport{64, 64}, 128), 4u);
}

}  // namespace
}  // namespace clipstream

namespace clipstream {
namespace {

// Height-aware planning (PlannerConfig::ground_above / ground_below): a
// camera low in a valley looking up at a slope sees no ground on its own
// plane, but the slope's top plane gives it a footprint, windows with
// visible tiles and a finest level; the flat case is unchanged.
TEST(Planner, ReliefInViewGivesASlopeSeenFromBelowAFootprint) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(16384, 16384, 128, PixelFormat::kRGBA8, &g));
  const Viewport vp{640, 360};
  Camera c;
  c.position = {8000.0, 10.0, 8000.0};
  c.pitch_rad = 0.6;  // every ray rises
  PlannerConfig flat;
  const ClipmapPlan none = planClipmap(g, vp, c, flat);
  EXPECT_FALSE(none.ground_visible);
  PlannerConfig relief = flat;
  relief.ground_above = 500.0;
  const ClipmapPlan slope = planClipmap(g, vp, c, relief);
  ASSERT_TRUE(slope.ground_visible);
  EXPECT_LT(slope.finest_level, slope.pyramid_level);
  size_t visible = 0;
  for (const ClipLevelPlan& l : slope.stack) visible += l.needed ? size_t(l.visible.width() * l.visible.height()) : 0;
  EXPECT_GT(visible, 0u);
  // Looking down from 100 texels with ground 60 texels below the plane
  // further away: the union keeps the near ground, so the finest level is
  // no coarser than the flat plan's, and the footprint no smaller.
  c.position.y = 100.0;
  c.pitch_rad = -0.4;
  const ClipmapPlan plain = planClipmap(g, vp, c, flat);
  PlannerConfig below = flat;
  below.ground_below = 60.0;
  const ClipmapPlan deep = planClipmap(g, vp, c, below);
  EXPECT_LE(deep.finest_level, plain.finest_level);
  for (size_t l = 0; l < plain.stack.size(); ++l) {
    EXPECT_GE(deep.stack[l].visible.width() * deep.stack[l].visible.height(),
              plain.stack[l].visible.width() * plain.stack[l].visible.height());
  }
  // Zero relief is the flat plan exactly.
  PlannerConfig zero = flat;
  zero.ground_above = 0.0;
  zero.ground_below = 0.0;
  const ClipmapPlan same = planClipmap(g, vp, c, zero);
  EXPECT_EQ(same.finest_level, plain.finest_level);
  for (size_t l = 0; l < plain.stack.size(); ++l) {
    EXPECT_EQ(same.stack[l].window, plain.stack[l].window);
    EXPECT_EQ(same.stack[l].visible, plain.stack[l].visible);
  }
}

}  // namespace
}  // namespace clipstream
