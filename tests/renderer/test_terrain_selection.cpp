// The quadtree's node selection (terrain_quadtree.cpp): the
// restriction's worklist leaves exactly the leaves of the full rescan it
// replaced, over random cameras, bounds and residency on the bundled St
// Helens DEM and a rough procedural one; the triangle budget holds on noisy
// ground and raises the bound only when it binds; a flight reads the
// elevation layer's height bounds once, for the planner and the quadtree
// both. Headless llvmpipe; GL tests skip without EGL.
#include "terrain_fixtures.h"

#include <clipstream/renderer/flight.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/tiler/tiler.h>

#include <gtest/gtest.h>

#include <atomic>
#include <random>
#include <sstream>
#include <thread>

namespace clipstream {
namespace {

using namespace terrain_test;

// A DEM to select over: its store's heights and bounds under a 2048^2
// white colour layer, stretched over it.
struct DemScene {
  std::shared_ptr<TileSource> heights;
  std::shared_ptr<const TerrainBounds> bounds;
  std::vector<std::pair<TileKey, std::vector<uint8_t>>> tiles;  // every tile, read once, finest first
  std::shared_ptr<TileSource> colour_source;
  std::unique_ptr<ClipmapRenderer> colour;
  std::unique_ptr<OffscreenTarget> target;
  TerrainConfig config;  // the quadtree over the DEM, no budget
};

void makeDemScene(const std::string& store, double world_per_height, DemScene* s) {
  Status st;
  s->heights = openElevationSource(store, &st);
  ASSERT_TRUE(s->heights) << st.toString();
  ASSERT_TRUE(loadTerrainBounds(*s->heights, kTerrainBoundsMaxLevelTiles, &s->bounds).ok());
  const PyramidGeometry& g = s->heights->geometry();
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        s->tiles.emplace_back(TileKey{l, x, y}, std::vector<uint8_t>());
        ASSERT_TRUE(s->heights->fetch({l, x, y}, &s->tiles.back().second).ok());
      }
  s->colour_source = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
  const ClipmapPlan plan = planClipmap(s->colour_source->geometry(), kViewport, overField(1024, 1024, 300, 0, -0.5), {});
  RendererConfig rc{plan.clip_tiles, plan.pyramid_level, Buffering::kSingle};
  ASSERT_TRUE(ClipmapRenderer::create(s->colour_source->geometry(), rc, &s->colour).ok());
  test::loadPlan(*s->colour, *s->colour_source, plan);
  ASSERT_TRUE(OffscreenTarget::create(kViewport, &s->target).ok());
  s->config.method = TerrainMethod::kQuadtree;
  s->config.ring_cells = 64;
  s->config.clip_tiles = std::max(g.levels[0].tiles_x, g.levels[0].tiles_y);  // every tile its own slot
  const double spacing = 2048.0 / double(std::max(g.width_px, g.height_px));
  s->config.mapping.world_per_sample = {spacing, spacing};
  s->config.mapping.sample0_world = {0.5 * spacing, 0.5 * spacing};
  s->config.mapping.world_per_height = world_per_height;
  s->config.triangle_budget = 0;
}

std::unique_ptr<TerrainRenderer> makeQuadtree(const DemScene& s, const TerrainConfig& config) {
  std::unique_ptr<TerrainRenderer> t;
  const Status st = TerrainRenderer::create(s.heights->geometry(), config, &t);
  EXPECT_TRUE(st.ok()) << st.toString();
  if (t) t->setBounds(s.bounds);
  return t;
}

void upload(TerrainRenderer& t, const TileKey& key, const std::vector<uint8_t>& bytes) {
  t.uploadTile(key, reinterpret_cast<const float*>(bytes.data()));
}

void uploadAll(TerrainRenderer& t, const DemScene& s) {
  for (const auto& [key, bytes] : s.tiles) upload(t, key, bytes);
}

void draw(TerrainRenderer& t, DemScene& s, const Camera& camera) {
  s.target->bind();
  ClipmapRenderer::clearSky();
  t.draw(camera, kViewport, *s.colour);
}

// A camera over the DEM's part of the image, `above` world units over the
// ground there, looking somewhere down.
Camera randomCamera(std::mt19937& rng, const TerrainRenderer& t, const DemScene& s, double above) {
  const PyramidGeometry& g = s.heights->geometry();
  const glm::dvec2 extent = glm::dvec2(double(g.width_px), double(g.height_px)) * s.config.mapping.world_per_sample;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Camera c = overField(extent.x * u(rng), extent.y * u(rng), 0.0, 6.2831853 * u(rng), -0.05 - 1.45 * u(rng));
  double ground = 0.0;
  if (!t.groundHeight({c.position.x, c.position.z}, &ground)) ground = 0.0;
  c.position.y = ground + above;
  return c;
}

// The first difference between two selections, or "" when they are the same.
std::string differ(const TerrainRenderer& a, const TerrainRenderer& b) {
  const std::vector<TerrainNode>& x = a.lastNodes();
  const std::vector<TerrainNode>& y = b.lastNodes();
  std::ostringstream out;
  if (x.size() != y.size()) out << x.size() << " leaves against " << y.size() << "; ";
  for (size_t i = 0; i < std::min(x.size(), y.size()); ++i) {
    const TerrainNode& p = x[i];
    const TerrainNode& q = y[i];
    if (p.level != q.level || p.x != q.x || p.y != q.y || p.coarse_sides != q.coarse_sides || p.drawn != q.drawn) {
      out << "leaf " << i << ": level " << p.level << " (" << p.x << ", " << p.y << ") sides " << p.coarse_sides
          << " against level " << q.level << " (" << q.x << ", " << q.y << ") sides " << q.coarse_sides;
      break;
    }
  }
  const TerrainFrame& f = a.lastFrame();
  const TerrainFrame& r = b.lastFrame();
  if (f.triangles != r.triangles || f.forced_splits != r.forced_splits || f.fallback_nodes != r.fallback_nodes ||
      f.coarsened_nodes != r.coarsened_nodes)
    out << " frames: " << f.triangles << "/" << f.forced_splits << "/" << f.fallback_nodes << "/"
        << f.coarsened_nodes << " against " << r.triangles << "/" << r.forced_splits << "/" << r.fallback_nodes << "/"
        << r.coarsened_nodes;
  return out.str();
}

// What the comparisons over one DEM went through.
struct Exercised {
  uint32_t cases = 0, forced = 0, coarsened = 0, fallbacks = 0, drawn_nodes = 0;
};

// Which tiles a residency pattern holds: every tile (pattern 0); a level
// missing from the middle of its columns on, every other level whole
// (patterns 2, 5, ...: finer leaves there border coarse nodes that cannot
// split, so the restriction coarsens them, and again the leaves it
// coarsened next to); or each level from `whole_from` up whole and, finer,
// a window of up to 5 x 5 tiles around `centre` (as a streamer's windows
// hold them; odd patterns also move each level's window by up to a tile,
// so a finer level is resident where its parent is not), less a tile in
// eight.
struct Residency {
  int pattern = 0;
  uint32_t whole_from = 0, gap_level = 0;
  glm::dvec2 centre{0.0};  // level-0 samples
};

bool resident(const Residency& r, const TileKey& key, const PyramidGeometry& g, std::mt19937& rng) {
  if (r.pattern == 0) return true;
  const glm::dvec2 c = r.centre / std::ldexp(double(g.tile_px), int(key.level));
  if (r.pattern % 3 == 2) return key.level != r.gap_level || double(key.x) < std::floor(c.x);
  if (key.level >= r.whole_from) return true;
  const int64_t half = int64_t(rng() % 3), shift = r.pattern % 2 ? int64_t(rng() % 3) - 1 : 0;
  const bool inside = std::abs(int64_t(key.x) - int64_t(c.x) - shift) <= half &&
                      std::abs(int64_t(key.y) - int64_t(c.y) + shift) <= half;
  return inside && rng() % 8 != 0;
}

// Over `patterns` residency patterns (resident()) and `cameras` random
// cameras (half of them over the windows' centre) and bounds each, the
// selection (budget 0) leaves exactly the leaves of the reference (the
// former selection: depth first, restriction by full rescans).
Exercised compareWithReference(DemScene& s, uint32_t seed, int patterns, int cameras) {
  Exercised ex;
  std::mt19937 rng(seed);
  const PyramidGeometry& g = s.heights->geometry();
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int pattern = 0; pattern < patterns; ++pattern) {
    std::unique_ptr<TerrainRenderer> worklist = makeQuadtree(s, s.config);
    std::unique_ptr<TerrainRenderer> reference = makeQuadtree(s, s.config);
    if (!worklist || !reference) return ex;
    reference->impl().setReferenceSelection(true);
    Residency r;
    r.pattern = pattern;
    r.whole_from = 1 + uint32_t(rng() % std::max(1u, g.levelCount() - 1));
    r.gap_level = 1 + uint32_t(rng() % std::max(1u, g.levelCount() - 2));
    r.centre = {u(rng) * double(g.width_px), u(rng) * double(g.height_px)};
    if (pattern % 3 == 2) {  // the gap's edge: the middle tile column's
      const double span = std::ldexp(double(g.tile_px), int(r.gap_level));
      r.centre.x = std::max(1.0, std::floor(double(g.levels[r.gap_level].tiles_x) / 2.0)) * span;
    }
    const glm::dvec2 centre = r.centre;
    for (const auto& [key, bytes] : s.tiles) {
      if (!resident(r, key, g, rng)) continue;
      upload(*worklist, key, bytes);
      upload(*reference, key, bytes);
    }
    for (int c = 0; c < cameras; ++c) {
      const double above = std::exp(std::uniform_real_distribution<double>(std::log(3.0), std::log(800.0))(rng));
      Camera camera = randomCamera(rng, *worklist, s, above);
      if (c % 2) {
        const glm::dvec2 at = (centre + 0.5) * s.config.mapping.world_per_sample +
                              glm::dvec2(u(rng) - 0.5, u(rng) - 0.5) * 300.0;
        double ground = 0.0;
        if (!worklist->groundHeight(at, &ground)) ground = 0.0;
        camera.position = {at.x, ground + above, at.y};
      }
      const double error_px = std::exp(std::uniform_real_distribution<double>(std::log(0.3), std::log(40.0))(rng));
      worklist->setErrorBound(error_px);
      reference->setErrorBound(error_px);
      draw(*worklist, s, camera);
      draw(*reference, s, camera);
      EXPECT_EQ(differ(*worklist, *reference), "")
          << "pattern " << pattern << ", camera " << c << " at (" << camera.position.x << ", " << camera.position.y
          << ", " << camera.position.z << "), " << error_px << " px";
      const TerrainFrame& f = worklist->lastFrame();
      ++ex.cases;
      ex.forced += f.forced_splits;
      ex.coarsened += f.coarsened_nodes;
      ex.fallbacks += f.fallback_nodes;
      ex.drawn_nodes += f.nodes;
      // No budget: the bound asked for is the bound met.
      EXPECT_EQ(f.achieved_error_px, error_px);
    }
  }
  return ex;
}

TEST(QuadtreeRestriction, TheWorklistLeavesTheLeavesOfTheFullRescanOnStHelens) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  TilerOptions t;
  t.input_path = test::bundledDataPath("mount_st_helens_30m.tif");
  t.output_path = dir.file("helens.cst");
  t.fsync = false;
  TilerSummary summary;
  const Status st = tileImage(t, &summary);
  ASSERT_TRUE(st.ok()) << st.toString();
  DemScene s;
  ASSERT_NO_FATAL_FAILURE(makeDemScene(t.output_path, 0.5, &s));  // 682..2543 m: 341..1272 units
  const Exercised ex = compareWithReference(s, 33, 9, 16);
  std::printf("  St Helens: %u cases, %u leaves drawn, %u forced splits, %u coarsened, %u fallbacks\n", ex.cases,
              ex.drawn_nodes, ex.forced, ex.coarsened, ex.fallbacks);
  // Both of the restriction's mends happened, several times.
  EXPECT_GT(ex.forced, 5u);
  EXPECT_GT(ex.coarsened, 5u);
}

TEST(QuadtreeRestriction, TheWorklistLeavesTheLeavesOfTheFullRescanOnRoughGround) {
  CLIPSTREAM_REQUIRE_GL();
  // The hills, ridge and 40-unit cliff of the crack tests, with a sample
  // jitter, as an elevation store (1024^2 samples, 8 x 8 level-0 tiles).
  test::TempDir dir;
  const HeightField f = roughField(1024);
  ASSERT_TRUE(test::writeElevationStore(dir.file("rough.cst"), 1024, 1024, [&f](uint64_t x, uint64_t y) {
                return f.samples[size_t(y) * 1024 + x];
              }).ok());
  DemScene s;
  ASSERT_NO_FATAL_FAILURE(makeDemScene(dir.file("rough.cst"), 1.0, &s));
  const Exercised ex = compareWithReference(s, 7, 9, 12);
  std::printf("  rough: %u cases, %u leaves drawn, %u forced splits, %u coarsened, %u fallbacks\n", ex.cases,
              ex.drawn_nodes, ex.forced, ex.coarsened, ex.fallbacks);
  EXPECT_GT(ex.forced, 20u);
  EXPECT_GT(ex.coarsened, 5u);
}

// White noise of +-60 units on every sample over hills (the stability
// scenarios' very rough DEM): every node in view wants level 0.
float noiseHeight(uint64_t x, uint64_t y) {
  const double hills = 60.0 + 40.0 * std::sin(x * 0.031) * std::cos(y * 0.027);
  return float(hills + 60.0 * (double((x * 73856093u ^ y * 19349663u) % 2001) / 1000.0 - 1.0));
}

TEST(QuadtreeBudget, HoldsOnNoiseAndRaisesTheBoundOnlyWhenItBinds) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  ASSERT_TRUE(test::writeElevationStore(dir.file("noise.cst"), 512, 512, noiseHeight).ok());
  DemScene s;
  ASSERT_NO_FATAL_FAILURE(makeDemScene(dir.file("noise.cst"), 1.0, &s));
  const uint64_t patch_triangles = 2ull * s.config.patch_cells * s.config.patch_cells;
  // Every tile resident: the restriction only splits, and more splits
  // never draw fewer nodes.
  std::unique_ptr<TerrainRenderer> none = makeQuadtree(s, s.config);
  ASSERT_TRUE(none);
  uploadAll(*none, s);
  const uint64_t budgets[] = {8192, 32768, 131072};
  std::vector<std::unique_ptr<TerrainRenderer>> budgeted;
  for (uint64_t b : budgets) {
    TerrainConfig c = s.config;
    c.triangle_budget = b;
    budgeted.push_back(makeQuadtree(s, c));
    ASSERT_TRUE(budgeted.back());
    uploadAll(*budgeted.back(), s);
  }
  std::mt19937 rng(3);
  uint32_t bound = 0, free = 0;
  for (int c = 0; c < 16; ++c) {
    const Camera camera = randomCamera(rng, *none, s, c % 2 ? 40.0 : 400.0);
    const double error_px = c % 3 ? 10.0 : 2.0;
    none->setErrorBound(error_px);
    draw(*none, s, camera);
    const uint64_t unbudgeted = uint64_t(none->lastFrame().nodes) * patch_triangles;
    for (size_t i = 0; i < budgeted.size(); ++i) {
      TerrainRenderer& t = *budgeted[i];
      t.setErrorBound(error_px);
      draw(t, s, camera);
      const TerrainFrame& f = t.lastFrame();
      SCOPED_TRACE("camera " + std::to_string(c) + ", budget " + std::to_string(budgets[i]));
      EXPECT_LE(f.triangles, budgets[i]);
      EXPECT_LE(uint64_t(f.nodes) * patch_triangles, budgets[i]);
      if (unbudgeted <= budgets[i]) {
        // The budget does not bind: the selection is the unbudgeted one.
        ++free;
        EXPECT_EQ(differ(t, *none), "");
        EXPECT_EQ(f.achieved_error_px, error_px);
        continue;
      }
      ++bound;
      EXPECT_GT(f.achieved_error_px, error_px);
      EXPECT_LT(f.triangles, none->lastFrame().triangles);
      // The bound is met: without a budget at the achieved bound, the
      // frame fits the budget too (nodes split there were split here).
      if (f.achieved_error_px >= kMaxTerrainErrorPx) continue;
      std::unique_ptr<TerrainRenderer> at_bound = makeQuadtree(s, s.config);
      uploadAll(*at_bound, s);
      at_bound->setErrorBound(std::min(f.achieved_error_px * 1.0001, kMaxTerrainErrorPx));
      draw(*at_bound, s, camera);
      EXPECT_LE(uint64_t(at_bound->lastFrame().nodes) * patch_triangles, budgets[i]);
    }
  }
  std::printf("  budget bound in %u frames, free in %u\n", bound, free);
  EXPECT_GT(bound, 8u);
  EXPECT_GT(free, 2u);
}

// An elevation source that counts the per-tile bounds asked of it on the
// thread that made it: loadTerrainBounds() runs there (opening a layer);
// the streamer's loaders also ask for the bounds of each tile they read
// (its detail, TileDetail), on their own threads.
class CountingHeights : public TileSource {
 public:
  explicit CountingHeights(std::shared_ptr<TileSource> inner) : m_inner(std::move(inner)) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  TileContent content() const override { return m_inner->content(); }
  ElevationInfo elevationInfo() const override { return m_inner->elevationInfo(); }
  Status tileHeightBounds(const TileKey& key, TileHeightBounds* out) const override {
    if (std::this_thread::get_id() == m_owner) ++m_bound_reads;
    return m_inner->tileHeightBounds(key, out);
  }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override { return m_inner->fetch(key, rgba); }
  std::string describe() const override { return "counting " + m_inner->describe(); }
  uint64_t boundReads() const { return m_bound_reads; }

 private:
  std::shared_ptr<TileSource> m_inner;
  const std::thread::id m_owner = std::this_thread::get_id();
  mutable std::atomic<uint64_t> m_bound_reads{0};
};

TEST(QuadtreeBounds, AFlightReadsTheHeightBoundsOnceForThePlannerAndTheQuadtree) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  ASSERT_TRUE(test::writeElevationStore(dir.file("dem.cst"), 512, 512, noiseHeight).ok());
  auto colour = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
  for (bool planner_bounds : {true, false}) {
    SCOPED_TRACE(planner_bounds ? "planning on the bounds" : "planning on the plane");
    Status st;
    auto counting = std::make_shared<CountingHeights>(openElevationSource(dir.file("dem.cst"), &st));
    uint64_t tiles = 0;  // one read of the index: each tile's bounds once
    for (const LevelInfo& l : counting->geometry().levels) tiles += uint64_t(l.tiles_x) * l.tiles_y;
    FlightConfig fc;
    fc.viewport = {320, 180};
    fc.streamer.terrain_bounds = planner_bounds;
    TerrainLayerConfig terrain;
    terrain.source = counting;
    terrain.alignment.world_per_sample = {4.0, 4.0};
    terrain.alignment.sample0_world = {2.0, 2.0};
    terrain.alignment.world_per_height = 1.0;
    terrain.method = TerrainMethod::kQuadtree;
    fc.terrain = terrain;
    const Camera first = overField(1024.0, 1024.0, 400.0, 0.3, -0.5);
    std::unique_ptr<Flight> flight;
    st = Flight::create(colour, fc, first, &flight);
    ASSERT_TRUE(st.ok()) << st.toString();
    EXPECT_EQ(counting->boundReads(), tiles);
    const std::shared_ptr<const TerrainBounds> used = flight->terrain()->impl().bounds();
    ASSERT_TRUE(used);
    // The planner's and the quadtree's are one object.
    EXPECT_EQ(flight->streamer().plansOnTerrain(), planner_bounds);
    EXPECT_EQ(flight->streamer().terrainBounds(), planner_bounds ? used : nullptr);
    flight->step(first);
    // A new viewport makes a new terrain renderer: the same bounds, not read again.
    ASSERT_TRUE(flight->resize({256, 144}, first).ok());
    flight->step(first);
    EXPECT_EQ(counting->boundReads(), tiles);
    EXPECT_EQ(flight->terrain()->impl().bounds(), used);
    flight->finish();
  }
}

}  // namespace
}  // namespace clipstream
