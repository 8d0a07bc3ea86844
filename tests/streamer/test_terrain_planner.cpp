// The height-bounds planner (docs/terrain.md, "Planning against the
// terrain"): per-tile bounds loaded from an elevation store's index and from
// the procedural heights, and plans over terrain: flat ground plans as the
// plane, a wall in front hides the ground behind it, the finest level
// follows the distance to the nearest visible slope, and a streamer over a
// scene plans every layer against the terrain.
#include "streamer_test_util.h"

#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/terrain_bounds.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>

namespace clipstream {
namespace {

using test::kPi;
using test::TempDir;

using HeightFn = std::function<float(uint64_t x, uint64_t y)>;

// Heights of a function of the level-0 sample, decimated per level, with
// exact per-tile bounds of the ground under each tile (computed at level 0,
// merged upwards, as the tiler does).
class FieldSource final : public TileSource {
 public:
  FieldSource(uint64_t w, uint64_t h, uint32_t tile_px, HeightFn f) : m_f(std::move(f)) {
    EXPECT_TRUE(makePyramidGeometry(w, h, tile_px, PixelFormat::kF32, &m_g));
    m_bounds.resize(m_g.levelCount());
    for (uint32_t l = 0; l < m_g.levelCount(); ++l) {
      const LevelInfo& info = m_g.levels[l];
      m_bounds[l].assign(size_t(info.tiles_x) * info.tiles_y, {INFINITY, -INFINITY});
    }
    for (uint64_t y = 0; y < h; ++y)
      for (uint64_t x = 0; x < w; ++x) {
        const float v = m_f(x, y);
        glm::vec2& b = m_bounds[0][size_t(y / tile_px) * m_g.levels[0].tiles_x + x / tile_px];
        b = {std::min(b.x, v), std::max(b.y, v)};
      }
    for (uint32_t l = 1; l < m_g.levelCount(); ++l)
      for (uint32_t y = 0; y < m_g.levels[l - 1].tiles_y; ++y)
        for (uint32_t x = 0; x < m_g.levels[l - 1].tiles_x; ++x) {
          const glm::vec2 c = m_bounds[l - 1][size_t(y) * m_g.levels[l - 1].tiles_x + x];
          glm::vec2& b = m_bounds[l][size_t(y / 2) * m_g.levels[l].tiles_x + x / 2];
          b = {std::min(b.x, c.x), std::max(b.y, c.y)};
        }
  }
  const PyramidGeometry& geometry() const override { return m_g; }
  TileContent content() const override { return TileContent::kHeightF32; }
  Status tileHeightBounds(const TileKey& key, TileHeightBounds* out) const override {
    if (!m_g.contains(key)) return Status::error(ErrorCode::kOutOfRange, "outside");
    const glm::vec2 b = m_bounds[key.level][size_t(key.y) * m_g.levels[key.level].tiles_x + key.x];
    // The decimated samples' surface lies within the bounds: their width
    // bounds its distance to the ground.
    *out = {b.x, b.y, key.level == 0 ? 0.0f : b.y - b.x};
    return okStatus();
  }
  Status fetch(const TileKey& key, std::vector<uint8_t>* out) override {
    if (!m_g.contains(key)) return Status::error(ErrorCode::kOutOfRange, "outside");
    const uint32_t t = m_g.tile_px;
    out->resize(size_t(t) * t * 4);
    for (uint32_t j = 0; j < t; ++j)
      for (uint32_t i = 0; i < t; ++i) {
        const uint64_t x = std::min<uint64_t>(uint64_t(key.x) * t + i, m_g.levels[key.level].width_px - 1) << key.level;
        const uint64_t y = std::min<uint64_t>(uint64_t(key.y) * t + j, m_g.levels[key.level].height_px - 1) << key.level;
        const float v = m_f(x, y);
        std::memcpy(out->data() + (size_t(j) * t + i) * 4, &v, 4);
      }
    return okStatus();
  }
  std::string describe() const override { return "field"; }

 private:
  PyramidGeometry m_g;
  HeightFn m_f;
  std::vector<std::vector<glm::vec2>> m_bounds;
};

// A height source without bounds (the TileSource default).
class NoBoundsSource final : public TileSource {
 public:
  NoBoundsSource() { EXPECT_TRUE(makePyramidGeometry(256, 256, 32, PixelFormat::kF32, &m_g)); }
  const PyramidGeometry& geometry() const override { return m_g; }
  TileContent content() const override { return TileContent::kHeightF32; }
  Status fetch(const TileKey&, std::vector<uint8_t>* out) override {
    out->assign(size_t(m_g.tile_px) * m_g.tile_px * 4, 0);
    return okStatus();
  }
  std::string describe() const override { return "no-bounds"; }

 private:
  PyramidGeometry m_g;
};

PyramidGeometry colourGeometry(uint64_t side) {
  PyramidGeometry g;
  EXPECT_TRUE(makePyramidGeometry(side, side, 128, PixelFormat::kRGBA8, &g));
  return g;
}

// The terrain of `source` with samples `spacing` world units apart from
// the world origin (sample i's centre at spacing * (i + 0.5)), heights in
// world units: the TerrainView of a colour layer with the identity map.
TerrainView viewOf(const TileSource& source, double spacing) {
  TerrainView v;
  EXPECT_TRUE(loadTerrainBounds(source, kTerrainBoundsMaxLevelTiles, &v.bounds).ok());
  v.sample_origin = {0.5 * spacing, 0.5 * spacing};
  v.units_per_sample = {spacing, spacing};
  v.units_per_height = 1.0;
  return v;
}

Camera looking(glm::dvec3 position, double heading, double pitch) {
  Camera c;
  c.position = position;
  c.heading_rad = heading;
  c.pitch_rad = pitch;
  return c;
}

// The finest level planClipmap() gives for ground `dist` away.
uint32_t levelAt(double dist, const Viewport& vp, const Camera& c, double oversample = 2.0) {
  const double pixel_angle = 2.0 * std::tan(c.vfov_rad * 0.5) / double(vp.height_px);
  const double ratio = dist * pixel_angle / oversample;
  return ratio <= 1.0 ? 0u : uint32_t(std::ceil(std::log2(ratio)));
}

// A DEM of 1024 x 1024 samples 32 world units apart (32768 units, the
// colour texture's side), flat at 0 but for a wall across x: its face
// rises from 0 at x = 12000 to `top` at x = 12400, its top stays there up
// to x = 16000 (the wall's far side) and the ground behind it is flat at 0.
constexpr double kSpacing = 32.0;
constexpr double kFaceX = 12000.0, kTopX = 12400.0, kFarSideX = 16000.0;
HeightFn wall(double top) {
  return [top](uint64_t i, uint64_t) {
    const double x = (double(i) + 0.5) * kSpacing;
    if (x < kFaceX || x >= kFarSideX) return 0.0f;
    return float(top * std::min(1.0, (x - kFaceX) / (kTopX - kFaceX)));
  };
}

TEST(TerrainBounds, LoadedFromAnElevationStoreAreItsIndex) {
  TempDir dir;
  // Heights that differ in every tile, so a neighbour's range shows.
  auto height = [](uint64_t x, uint64_t y) { return float(std::sin(x * 0.05) * 40.0 + y * 0.25 + (x > 300 ? 90.0 : 0.0)); };
  ASSERT_TRUE(test::writeElevationStore(dir.file("dem.cst"), 500, 300, height).ok());
  Status s;
  auto source = openElevationSource(dir.file("dem.cst"), &s);
  ASSERT_TRUE(source) << s.toString();
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(dir.file("dem.cst"), &reader).ok());
  std::shared_ptr<const TerrainBounds> b;
  ASSERT_TRUE(loadTerrainBounds(*source, kTerrainBoundsMaxLevelTiles, &b).ok());
  const PyramidGeometry& g = source->geometry();
  ASSERT_EQ(b->levels.size(), g.levelCount());
  EXPECT_EQ(b->finest_level, 0u);
  EXPECT_EQ(b->tile_px, g.tile_px);
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    const TerrainBounds::Level& lv = b->levels[l];
    ASSERT_EQ(lv.tiles_x, g.levels[l].tiles_x);
    ASSERT_EQ(lv.tiles_y, g.levels[l].tiles_y);
    for (uint32_t y = 0; y < lv.tiles_y; ++y)
      for (uint32_t x = 0; x < lv.tiles_x; ++x) {
        TileLocation loc;
        ASSERT_TRUE(reader->locate({l, x, y}, &loc).ok());
        EXPECT_EQ(lv.range[size_t(y) * lv.tiles_x + x], glm::vec2(loc.min_height, loc.max_height))
            << l << " " << x << " " << y;
        EXPECT_EQ(lv.error[size_t(y) * lv.tiles_x + x], loc.error) << l << " " << x << " " << y;
        // Every level-0 height under the tile lies in its range.
        const uint64_t span = uint64_t(g.tile_px) << l;
        for (uint64_t j = y * span; j < std::min<uint64_t>((y + 1) * span, g.height_px); j += 7)
          for (uint64_t i = x * span; i < std::min<uint64_t>((x + 1) * span, g.width_px); i += 7) {
            ASSERT_GE(height(i, j), loc.min_height);
            ASSERT_LE(height(i, j), loc.max_height);
          }
      }
  }
  EXPECT_EQ(b->range, b->levels.back().range[0]);
  // Levels over the tile limit are left to their ancestors'.
  std::shared_ptr<const TerrainBounds> coarse;
  ASSERT_TRUE(loadTerrainBounds(*source, 2, &coarse).ok());
  EXPECT_EQ(coarse->finest_level, 2u);
  EXPECT_TRUE(coarse->levels[0].range.empty());
  EXPECT_EQ(coarse->levels[2].range, b->levels[2].range);
  // A source without bounds says so; a colour store's source too.
  NoBoundsSource none;
  EXPECT_EQ(loadTerrainBounds(none, kTerrainBoundsMaxLevelTiles, &b).code, ErrorCode::kUnsupported);
  EXPECT_FALSE(b);
  EXPECT_EQ(loadTerrainBounds(*test::procedural(1024, 128), 64, &b).code, ErrorCode::kUnsupported);
}

TEST(TerrainBounds, ProceduralHeightsLieWithinTheirTilesBounds) {
  ProceduralSpec spec;
  spec.width_px = spec.height_px = uint64_t(1) << 20;
  spec.tile_px = 64;
  auto source = makeProceduralHeightSource(spec);
  ASSERT_TRUE(source);
  const ElevationInfo info = source->elevationInfo();
  size_t checked = 0;
  // Tiles across the cliff (every 2^14 columns) and elsewhere, level 0 to
  // level 8; every level-0 sample on a grid under each tile.
  for (uint32_t level : {0u, 1u, 3u, 5u, 8u}) {
    const uint64_t span = uint64_t(spec.tile_px) << level;
    for (uint64_t x0 : {uint64_t(0), (uint64_t(1) << 14) - span / 2, uint64_t(300000), (uint64_t(1) << 20) - span}) {
      const TileKey key{level, uint32_t(x0 / span), uint32_t(x0 / span / 2)};
      TileHeightBounds b;
      ASSERT_TRUE(source->tileHeightBounds(key, &b).ok());
      const float lo = b.min_height, hi = b.max_height;
      EXPECT_GE(lo, float(info.min_height) - 1.0f);
      EXPECT_LE(hi, float(info.max_height) + 1.0f);
      const uint64_t step = std::max<uint64_t>(1, span / 64);
      for (uint64_t j = 0; j < span; j += step)
        for (uint64_t i = 0; i < span; i += step) {
          const float v = float(proceduralHeight(spec, uint64_t(key.x) * span + i, uint64_t(key.y) * span + j));
          ASSERT_GE(v, lo) << "level " << level;
          ASSERT_LE(v, hi) << "level " << level;
          ++checked;
        }
      // Bounds of the corner values, not of the whole amplitude: a level-0
      // tile spans far less than the amplitudes' sum.
      if (level == 0) {
        EXPECT_LT(hi - lo, 0.5f * float(info.max_height - info.min_height));
      }
    }
  }
  EXPECT_GT(checked, 10000u);
  TileHeightBounds b;
  EXPECT_EQ(source->tileHeightBounds({0, 1u << 14, 0}, &b).code, ErrorCode::kOutOfRange);
}

// Flat ground at 0 under cameras that see no horizon (the last one's top
// rays meet the ground past the far limit): the same plan as the
// plane, level by level (the flat planner is unchanged; the terrain planner
// agrees with it where the terrain is the plane).
TEST(TerrainPlanner, FlatGroundPlansAsThePlane) {
  const PyramidGeometry g = colourGeometry(32768);
  FieldSource flat(1024, 1024, 32, [](uint64_t, uint64_t) { return 0.0f; });
  PlannerConfig terrain;
  terrain.terrain = viewOf(flat, kSpacing);
  const Viewport vp{640, 360};
  for (const Camera& c : {test::lookingDown(5000.3, 7000.2, 300.0),
                          looking({8000.7, 2000.0, 9000.2}, 0.3, -0.9),
                          looking({3000.1, 800.0, 12000.9}, 2.0, -1.2),
                          looking({20000.4, 150.0, 20000.6}, -2.5, -1.0),
                          // Nearly level: the nearest ground is 1.14 times the height away.
                          looking({12000.3, 2300.0, 14000.8}, 1.2, -0.55)}) {
    const ClipmapPlan a = planClipmap(g, vp, c, PlannerConfig{});
    const ClipmapPlan b = planClipmap(g, vp, c, terrain);
    ASSERT_TRUE(a.ground_visible);
    EXPECT_EQ(b.ground_visible, a.ground_visible);
    EXPECT_EQ(b.finest_level, a.finest_level) << "camera y " << c.position.y;
    EXPECT_EQ(b.focus_texel, a.focus_texel);
    ASSERT_EQ(b.stack.size(), a.stack.size());
    for (size_t l = 0; l < a.stack.size(); ++l) {
      EXPECT_EQ(b.stack[l].needed, a.stack[l].needed) << l;
      EXPECT_EQ(b.stack[l].window, a.stack[l].window) << l;
      EXPECT_EQ(b.stack[l].visible, a.stack[l].visible) << l;
    }
  }
}

// A camera low in the valley, looking up at the wall (every ray rises):
// the plane sees nothing, the relief planes see the wall's top plane out
// to far behind it; the terrain planner needs the level of the wall's
// distance and keeps the footprint to the near side of the wall's far side.
TEST(TerrainPlanner, AWallInFrontHidesTheGroundBehindIt) {
  const PyramidGeometry g = colourGeometry(32768);
  FieldSource dem(1024, 1024, 32, wall(3000.0));
  PlannerConfig terrain;
  terrain.terrain = viewOf(dem, kSpacing);
  const Viewport vp{640, 360};
  const Camera c = looking({8000.0, 20.0, 16000.0}, kPi / 2, 0.6);  // east, up

  const ClipmapPlan plane = planClipmap(g, vp, c, PlannerConfig{});
  EXPECT_FALSE(plane.ground_visible);
  const ClipmapPlan plan = planClipmap(g, vp, c, terrain);
  ASSERT_TRUE(plan.ground_visible);
  // The nearest ground seen: where the middle of the bottom edge (0.076
  // rad up) meets the face, 4044 units east and 308 up.
  const double up = c.pitch_rad - 0.5 * c.vfov_rad;
  const double x = (c.position.y + kFaceX * 7.5 - c.position.x * std::tan(up)) / (7.5 - std::tan(up));
  const double dist = (x - c.position.x) / std::cos(up);
  const uint32_t expected = levelAt(dist, vp, c);
  EXPECT_LE(plan.finest_level, expected);
  EXPECT_GE(plan.finest_level + 1, expected) << "more than a level finer than the wall needs";

  PlannerConfig relief;
  relief.ground_above = 3000.0;
  const ClipmapPlan planes = planClipmap(g, vp, c, relief);
  bool planes_past = false;
  size_t seen = 0;
  for (size_t l = 0; l < plan.stack.size(); ++l) {
    const double tile = 128.0 * std::ldexp(1.0, int(l));
    if (!plan.stack[l].needed) continue;
    const TileRect& v = plan.stack[l].visible;
    // A level's window may end short of the wall (finer levels reach
    // less far ahead); where it reaches the face, the face is visible.
    if (double(plan.stack[l].window.x1) * tile > kTopX) {
      ASSERT_FALSE(v.empty()) << "level " << l;
      EXPECT_GT(double(v.x1) * tile, kFaceX) << "level " << l << ": the face is not in view";
      ++seen;
    }
    if (!v.empty()) {
      EXPECT_LT(double(v.x1 - 1) * tile, kFarSideX) << "level " << l << ": visible tiles behind the wall";
    }
    const TileRect& p = planes.stack[l].visible;
    if (planes.stack[l].needed && !p.empty() && double(p.x1 - 1) * tile >= kFarSideX) planes_past = true;
  }
  EXPECT_GE(seen, 2u);
  EXPECT_TRUE(planes_past) << "the relief planes were expected to see past the wall";
}

// High above the valley, looking almost level at a mountain rising above
// the camera: the plane under the camera puts the nearest ground 6400
// units away, the mountain's face is nearer, and the terrain planner needs
// the finer level the face's distance asks for.
TEST(TerrainPlanner, FinestLevelFollowsANearerSlopeThanThePlane) {
  const PyramidGeometry g = colourGeometry(32768);
  FieldSource dem(1024, 1024, 32, wall(5000.0));
  PlannerConfig terrain;
  terrain.terrain = viewOf(dem, kSpacing);
  const Viewport vp{640, 360};
  const Camera c = looking({8000.0, 4000.0, 16000.0}, kPi / 2, -0.15);
  const ClipmapPlan plane = planClipmap(g, vp, c, PlannerConfig{});
  const ClipmapPlan plan = planClipmap(g, vp, c, terrain);
  ASSERT_TRUE(plane.ground_visible);
  ASSERT_TRUE(plan.ground_visible);
  // The face at the camera's height, straight ahead (the frustum holds the
  // level ray): 4320 units.
  const double dist = kFaceX + 4000.0 / 12.5 - c.position.x;
  const uint32_t expected = levelAt(dist, vp, c);
  EXPECT_LT(expected, plane.finest_level);
  EXPECT_LE(plan.finest_level, expected);
  EXPECT_GE(plan.finest_level + 1, expected);
  EXPECT_LT(plan.finest_level, plane.finest_level);
}

TEST(TerrainBounds, TileDetailHoldsItsCellsSamplesWidenedByTheError) {
  constexpr uint32_t kTile = 64;
  std::vector<float> h(kTile * kTile);
  for (uint32_t y = 0; y < kTile; ++y)
    for (uint32_t x = 0; x < kTile; ++x) h[y * kTile + x] = float(x * 3 + y * 100 % 37) - 50.0f;
  const auto d = makeTileDetail(kTile, h.data(), 2.5f);
  ASSERT_EQ(d->log2, kTileDetailLog2);
  for (uint32_t k = 0; k <= d->log2; ++k) {
    const uint32_t n = 1u << k, cell = kTile / n;
    ASSERT_EQ(d->cells[k].size(), size_t(n) * n);
    for (uint32_t cy = 0; cy < n; ++cy)
      for (uint32_t cx = 0; cx < n; ++cx) {
        float lo = INFINITY, hi = -INFINITY;
        for (uint32_t y = cy * cell; y < (cy + 1) * cell; ++y)
          for (uint32_t x = cx * cell; x < (cx + 1) * cell; ++x) {
            lo = std::min(lo, h[y * kTile + x]);
            hi = std::max(hi, h[y * kTile + x]);
          }
        EXPECT_EQ(d->cells[k][cy * n + cx], glm::vec2(lo - 2.5f, hi + 2.5f)) << k << " " << cx << " " << cy;
      }
  }
  // A tile smaller than the cells: one sample a cell.
  EXPECT_EQ(makeTileDetail(4, h.data(), 0.0f)->log2, 2u);
}

// Tiles of 256 samples (8192 units): the index box under a camera 1500
// units above the plain also holds the wall's foot next door, so without
// detail the camera is inside it and every level down to 0 is needed. The
// detail of the tiles read bounds the plain cell by cell: the plan needs
// the level of the plain's distance.
TEST(TerrainPlanner, DetailOfReadTilesRefinesCoarseBounds) {
  const PyramidGeometry g = colourGeometry(32768);
  FieldSource dem(1024, 1024, 256, wall(3000.0));
  const Viewport vp{640, 360};
  const Camera c = looking({8000.0, 1500.0, 16000.0}, kPi / 2, 0.0);
  PlannerConfig cfg;
  cfg.terrain = viewOf(dem, kSpacing);
  EXPECT_EQ(planClipmap(g, vp, c, cfg).finest_level, 0u);
  auto detail = std::make_shared<TerrainDetail>();
  const PyramidGeometry& hg = dem.geometry();
  for (uint32_t l = 0; l < hg.levelCount(); ++l)
    for (uint32_t y = 0; y < hg.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < hg.levels[l].tiles_x; ++x) {
        std::vector<uint8_t> px;
        ASSERT_TRUE(dem.fetch({l, x, y}, &px).ok());
        std::vector<float> f(px.size() / 4);
        std::memcpy(f.data(), px.data(), px.size());
        TileHeightBounds b;
        ASSERT_TRUE(dem.tileHeightBounds({l, x, y}, &b).ok());
        detail->tiles[{l, x, y}] = makeTileDetail(hg.tile_px, f.data(), b.error);
      }
  cfg.terrain.detail = detail;
  // The plain below, along the bottom edge's middle (30 degrees down).
  const uint32_t expected = levelAt(1500.0 / std::sin(c.vfov_rad / 2), vp, c);
  ASSERT_GE(expected, 2u);
  const ClipmapPlan plan = planClipmap(g, vp, c, cfg);
  EXPECT_LE(plan.finest_level, expected);
  EXPECT_GE(plan.finest_level + 1, expected);
}

// The streamer keeps the detail of the terrain tiles its loaders read and
// plans with it: the coarse-tiled scene above, streamed, ends up needing
// the plain's level instead of level 0.
TEST(TerrainPlanner, StreamerPlansWithTheDetailOfTheTilesItRead) {
  auto colour = test::procedural(32768, 128);
  auto dem = std::make_shared<FieldSource>(1024, 1024, 256, wall(3000.0));
  StreamerConfig cfg;
  cfg.io_threads = 2;
  cfg.prefetch = false;
  cfg.ram_budget_bytes = uint64_t(128) << 20;
  StreamLayer heights{dem, LayerRole::kElevation, {1.0 / kSpacing, 1.0 / kSpacing}, {0.0, 0.0}, 4, 1.0};
  Streamer streamer({StreamLayer{colour}, heights}, cfg);
  ASSERT_TRUE(streamer.plansOnTerrain());
  const Viewport vp{640, 360};
  const Camera c = looking({8000.0, 1500.0, 16000.0}, kPi / 2, 0.0);
  streamer.update(c, vp, 0.0);
  EXPECT_EQ(streamer.plan(0).finest_level, 0u);
  const uint32_t expected = levelAt(1500.0 / std::sin(c.vfov_rad / 2), vp, c);
  ASSERT_GE(expected, 2u);
  // Frames until the plan settles with the detail of what it loaded.
  for (int frame = 1; frame < 20; ++frame) {
    ASSERT_TRUE(test::waitIdle(streamer));
    (void)streamer.takeReadyAll(1000);
    streamer.update(c, vp, frame / 60.0);
  }
  EXPECT_LE(streamer.plan(0).finest_level, expected);
  EXPECT_GE(streamer.plan(0).finest_level + 1, expected);
  streamer.shutdown();
}

// Looking at the sky over terrain: nothing in view, nothing needed.
TEST(TerrainPlanner, SkyAboveTheHighestGroundNeedsNoStackLevel) {
  const PyramidGeometry g = colourGeometry(32768);
  FieldSource dem(1024, 1024, 32, wall(3000.0));
  PlannerConfig terrain;
  terrain.terrain = viewOf(dem, kSpacing);
  const ClipmapPlan plan = planClipmap(g, Viewport{640, 360}, looking({8000.0, 3500.0, 16000.0}, 1.0, 0.8), terrain);
  EXPECT_FALSE(plan.ground_visible);
  for (const ClipLevelPlan& l : plan.stack) EXPECT_FALSE(l.needed);
}

// A streamer over a scene plans every layer against the terrain when the
// elevation layer has a height scale and its source has bounds: each
// layer's plan is planClipmap's with the terrain placed in its texels.
TEST(TerrainPlanner, StreamerPlansEveryLayerAgainstTheTerrain) {
  auto colour = test::procedural(32768, 128);
  auto dem = std::make_shared<FieldSource>(1024, 1024, 32, wall(3000.0));
  StreamerConfig cfg;
  cfg.io_threads = 1;
  cfg.prefetch = false;
  cfg.ram_budget_bytes = uint64_t(64) << 20;
  // The DEM: a sample every 32 world units; heights in metres, a world
  // unit being 2 m (world_per_height 0.5).
  StreamLayer heights{dem, LayerRole::kElevation, {1.0 / kSpacing, 1.0 / kSpacing}, {0.0, 0.0}, 4, 0.5};
  Streamer streamer({StreamLayer{colour}, heights}, cfg);
  ASSERT_TRUE(streamer.plansOnTerrain());
  const Viewport vp{640, 360};
  const Camera c = looking({8000.0, 20.0, 16000.0}, kPi / 2, 0.6);
  streamer.update(c, vp, 0.0);
  // The expected plans, computed here from the bounds and the maps.
  TerrainView world;
  ASSERT_TRUE(loadTerrainBounds(*dem, kTerrainBoundsMaxLevelTiles, &world.bounds).ok());
  PlannerConfig colour_cfg;
  colour_cfg.terrain = world;
  colour_cfg.terrain.sample_origin = {16.0, 16.0};
  colour_cfg.terrain.units_per_sample = {32.0, 32.0};
  colour_cfg.terrain.units_per_height = 0.5;
  const ClipmapPlan expect_colour = planClipmap(streamer.geometry(0), vp, c, colour_cfg);
  EXPECT_TRUE(expect_colour.ground_visible);
  const ClipmapPlan& got = streamer.plan(0);
  EXPECT_EQ(got.finest_level, expect_colour.finest_level);
  ASSERT_EQ(got.stack.size(), expect_colour.stack.size());
  for (size_t l = 0; l < got.stack.size(); ++l) {
    EXPECT_EQ(got.stack[l].needed, expect_colour.stack[l].needed);
    EXPECT_EQ(got.stack[l].window, expect_colour.stack[l].window);
    EXPECT_EQ(got.stack[l].visible, expect_colour.stack[l].visible);
  }
  PlannerConfig dem_cfg;
  dem_cfg.clip_tiles = 4;
  dem_cfg.terrain = world;
  dem_cfg.terrain.sample_origin = {0.5, 0.5};
  dem_cfg.terrain.units_per_sample = {1.0, 1.0};
  dem_cfg.terrain.units_per_height = 0.5 / kSpacing;
  const ClipmapPlan expect_dem = planClipmap(streamer.geometry(1), vp, layerCamera(heights, c), dem_cfg);
  EXPECT_EQ(streamer.plan(1).finest_level, expect_dem.finest_level);
  for (size_t l = 0; l < expect_dem.stack.size(); ++l) {
    EXPECT_EQ(streamer.plan(1).stack[l].window, expect_dem.stack[l].window);
    EXPECT_EQ(streamer.plan(1).stack[l].visible, expect_dem.stack[l].visible);
  }
  streamer.shutdown();

  // Without a height scale, or with a source without bounds: the plane.
  heights.world_per_height = 0.0;
  Streamer flat({StreamLayer{colour}, heights}, cfg);
  EXPECT_FALSE(flat.plansOnTerrain());
  StreamLayer none{std::make_shared<NoBoundsSource>(), LayerRole::kElevation, {1.0, 1.0}, {0.0, 0.0}, 0, 1.0};
  Streamer without({StreamLayer{colour}, none}, cfg);
  EXPECT_FALSE(without.plansOnTerrain());
  // A height scale that is not a number is refused.
  heights.world_per_height = NAN;
  EXPECT_EQ(checkStreamLayers({StreamLayer{colour}, heights}).code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace clipstream
