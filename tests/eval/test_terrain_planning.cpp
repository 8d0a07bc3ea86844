// The height-bounds planner over a real DEM (docs/terrain.md, "Planning
// against the terrain"): the bundled Mount St. Helens DEM, tiled here and
// stretched under a procedural texture, looked at from low orbits around
// the crater. Every colour tile a frame samples (from the ground points its
// pixels show, sampledTilesOfPositions()) must lie in a window the plan
// loads: a pyramid level, or a tile a needed stack level's plan wants (the
// ground the last frame showed). The loads stay within twice the tiles the
// frames sample. And the tiles sampled over terrain are those of the
// frame's own ground points.
// Headless llvmpipe.
#include "test_helpers.h"

#include <clipstream/eval/flight_run.h>
#include <clipstream/eval/metrics.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/streamer/flight_path.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>
#include <clipstream/testing/test_data.h>
#include <clipstream/tiler/tiler.h>

#include <gtest/gtest.h>

#include <cmath>
#include <unordered_set>

namespace clipstream {
namespace {

TileKey unpackTileKey(uint64_t k) {
  return {uint32_t(k >> 58), uint32_t(k & 0x1FFFFFFFu), uint32_t((k >> 29) & 0x1FFFFFFFu)};
}

// Tiles of `sampled` that the plan does not load: finer than the pyramid
// (counted in *stack), and at a level the plan needs but outside its window
// (*outside) or inside it but not wanted (*unmarked: the ground seen missed
// it), or at a level finer than the plan needs (*finer).
void unplannedTiles(const std::unordered_set<uint64_t>& sampled, const ClipmapPlan& plan, size_t* outside,
                    size_t* unmarked, size_t* finer, size_t* stack) {
  for (uint64_t k : sampled) {
    const TileKey t = unpackTileKey(k);
    if (t.level >= plan.pyramid_level) continue;
    ++*stack;
    const ClipLevelPlan& l = plan.stack[t.level];
    if (!l.needed) {
      ++*finer;
    } else if (!l.window.contains(t.x, t.y)) {
      ++*outside;
    } else if (!l.wants(t.x, t.y)) {
      ++*unmarked;
    }
  }
}

// Tiles the plan wants at its stack levels.
size_t wantedStackTiles(const ClipmapPlan& plan) {
  size_t n = 0;
  for (const ClipLevelPlan& l : plan.stack) n += l.wantedCount();
  return n;
}

struct Orbit {
  size_t frames = 0, sampled = 0;
  size_t outside = 0;      // tiles sampled at a needed level, outside its window
  size_t unmarked = 0;     // ... inside it, but not wanted
  size_t sampled_stack = 0, wanted_stack = 0;  // finer than the pyramid: sampled, and wanted by the plan
  size_t finer_tiles = 0;  // tiles sampled at a level the plan does not need
  // Frames whose plan needs a level coarser (finer) than the planner's
  // rule gives for the nearest ground the frame shows.
  size_t coarser_frames = 0, finer_frames = 0;
};

// Low orbits around the crater, looking at the mountain's slopes, with
// the terrain planner (terrain = true) or the relief planes.
Orbit flyOrbit(const std::string& dem, bool terrain_planning) {
  Orbit out;
  auto colour = test::procedural(8192, 128);
  TerrainLayerConfig tl;
  std::vector<std::string> warnings;
  Status s = openTerrainLayer("", colour->geometry(), dem, 1.0, true, 64, &tl, &warnings);
  EXPECT_TRUE(s.ok()) << s.toString();
  if (!s) return out;
  FlightConfig fc;
  fc.viewport = {320, 180};
  fc.offscreen = true;
  fc.streamer.ram_budget_bytes = uint64_t(64) << 20;
  fc.streamer.io_threads = 2;
  fc.terrain = tl;
  fc.streamer.terrain_bounds = terrain_planning;
  const glm::dvec2 centre{4096.0, 4096.0};
  auto cameraAt = [&](double angle, double radius, double above, double pitch, const Flight* f) {
    Camera c;
    c.position = {centre.x + radius * std::cos(angle), 0.0, centre.y + radius * std::sin(angle)};
    double ground = 0.0;
    if (f) f->groundHeight({c.position.x, c.position.z}, &ground);
    c.position.y = ground + above;
    // Heading toward the crater: heading 0 looks to -z, +pi/2 to +x.
    const glm::dvec2 to = centre - glm::dvec2(c.position.x, c.position.z);
    c.heading_rad = std::atan2(to.x, -to.y);
    c.pitch_rad = pitch;
    return c;
  };
  std::unique_ptr<Flight> flight;
  s = Flight::create(colour, fc, cameraAt(0.0, 2600.0, 2000.0, -0.1, nullptr), &flight);
  EXPECT_TRUE(s.ok()) << s.toString();
  if (!s) return out;
  EXPECT_EQ(flight->streamer().plansOnTerrain(), terrain_planning);
  std::vector<float> xyzw;
  for (int i = 0; i < 16; ++i) {
    const double angle = i * (2.0 * test::kPi / 16);
    for (const auto& [radius, above, pitch] : {std::tuple{3800.0, 400.0, -0.15}, std::tuple{3000.0, 150.0, 0.0},
                                               std::tuple{3800.0, 1200.0, -0.35}, std::tuple{2000.0, 60.0, 0.1}}) {
      const Camera c = cameraAt(angle, radius, above, pitch, flight.get());
      for (int k = 0; k < 3; ++k) flight->step(c);
      EXPECT_TRUE(flight->terrain()->readPositions(c, flight->viewport(), flight->renderer(), &xyzw).ok());
      std::unordered_set<uint64_t> sampled;
      sampledTilesOfPositions(colour->geometry(), xyzw, c, flight->viewport(), &sampled);
      const ClipmapPlan& plan = flight->streamer().plan(0);
      unplannedTiles(sampled, plan, &out.outside, &out.unmarked, &out.finer_tiles, &out.sampled_stack);
      out.wanted_stack += wantedStackTiles(plan);
      const double nearest = nearestPositionDistance(xyzw);
      EXPECT_TRUE(std::isfinite(nearest)) << "no terrain in view";
      const uint32_t seen = finestLevelAt(nearest, flight->viewport(), c, fc.streamer.planner,
                                          colour->geometry().levelCount());
      out.frames += 1;
      out.sampled += sampled.size();
      out.coarser_frames += plan.finest_level > seen;
      out.finer_frames += plan.finest_level < seen;
    }
  }
  flight->finish();
  return out;
}

std::string tileDem(const test::TempDir& dir, uint32_t tile_px = 128) {
  TilerOptions opt;
  opt.input_path = test::bundledDataPath("mount_st_helens_30m.tif");
  opt.output_path = dir.file("helens" + std::to_string(tile_px) + ".cst");
  opt.tile_px = tile_px;
  opt.threads = 2;
  opt.fsync = false;
  TilerSummary summary;
  const Status s = tileImage(opt, &summary);
  EXPECT_TRUE(s.ok()) << s.toString();
  return opt.output_path;
}

TEST(TerrainPlanning, EveryTileSampledOverMountainSlopesIsPlanned) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  const std::string dem = tileDem(dir);
  const Orbit t = flyOrbit(dem, true);
  EXPECT_EQ(t.frames, 64u);
  EXPECT_GT(t.sampled, t.frames * 20) << "the frames sampled too little to judge";
  // No frame shows ground nearer than its plan's finest level is for.
  EXPECT_EQ(t.coarser_frames, 0u);
  // Conservative, but not blindly: most frames need the level the nearest
  // ground asks for, the rest one finer.
  EXPECT_LE(t.finer_frames * 2, t.frames);
  // Tiles sampled at a level the plan needs lie in that level's window,
  // but for the odd one at a window's side edge (windows are twice the
  // screen, which the flat planner's rule also leaves this close). Pixels
  // off the view's axis see ground at a smaller footprint than its
  // distance gives (the flat rule shares this too): their tiles may be a
  // level finer than needed, a few in a hundred.
  EXPECT_LE(t.outside * 100, t.sampled);
  EXPECT_LE(t.finer_tiles * 20, t.sampled);
  // Inside the windows, the plan wants what the frames sample but for a
  // tile in a hundred of the clip levels' (a level within the slack of the
  // next, kSeenLodSlack, sampled with little weight).
  EXPECT_LE(t.unmarked * 100, t.sampled_stack);
  // And the plan wants little more than the frames sample: the tiles under
  // the ground the last frame showed (GroundSeen), with a tile's margin.
  EXPECT_LE(t.wanted_stack, 2 * t.sampled_stack);
  EXPECT_GT(t.sampled_stack, t.frames * 5) << "the clip levels were sampled too little to judge";
  // The same orbits planned with the relief planes, for comparison.
  const Orbit r = flyOrbit(dem, false);
  std::printf("St Helens orbits, %zu frames: terrain bounds: plan coarser than the nearest ground in %zu "
              "frames, finer in %zu; of %zu tiles sampled, %zu outside the windows, %zu in them but not "
              "wanted, %zu at levels not needed; clip levels: %zu wanted for %zu sampled; relief planes: %zu, "
              "%zu; %zu, %zu, %zu\n",
              t.frames, t.coarser_frames, t.finer_frames, t.sampled, t.outside, t.unmarked, t.finer_tiles,
              t.wanted_stack, t.sampled_stack, r.coarser_frames, r.finer_frames, r.sampled, r.outside,
              r.finer_tiles);
}

// A flight low around the crater of `dem` stretched under a 16384^2
// procedural texture (vertical scale 0.5, rings of `ring_cells`), looking
// `pitch_deg` down at the slopes: keyframes `step` radians and `dt_s`
// apart, at `radius` and `height`. 320x180.
FlightRunOptions craterOrbit(const std::string& dem, uint32_t ring_cells, int keys, double step, double dt_s,
                             double radius, double height, double pitch_deg) {
  FlightRunOptions o;
  o.source = test::procedural(16384, 128);
  std::vector<std::string> warnings;
  TerrainLayerConfig tl;
  const Status s = openTerrainLayer("", o.source->geometry(), dem, 0.5, true, ring_cells, &tl, &warnings);
  EXPECT_TRUE(s.ok()) << s.toString();
  if (s) o.terrain = tl;
  for (int i = 0; i < keys; ++i) {
    const double angle = i * step;
    Keyframe key;
    key.t_s = i * dt_s;
    key.position = {8192.0 + radius * std::cos(angle), height, 8192.0 + radius * std::sin(angle)};
    key.heading_deg = std::atan2(-std::cos(angle), std::sin(angle)) * 180.0 / test::kPi;
    key.pitch_deg = pitch_deg;
    o.path.keyframes.push_back(key);
  }
  o.viewport = {320, 180};
  o.streamer.io_threads = 2;
  return o;
}

// Over-fetch over terrain (docs/terrain.md, "Over-fetch over terrain"): an
// orbit around St Helens loads at most twice the clip-level tiles its
// frames sample when the plan follows the ground the frames show, at the
// PSNR of loading whole windows, which load several times more.
TEST(TerrainPlanning, LoadsAtMostTwiceTheTilesTheFramesSample) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  const std::string dem = tileDem(dir);
  FlightRun runs[2];
  for (int k = 0; k < 2; ++k) {
    FlightRunOptions o = craterOrbit(dem, 64, 7, test::kPi / 18, 0.25, 4000.0, 500.0, -12.0);
    ASSERT_TRUE(o.terrain.has_value());
    o.frames = 90;
    o.reference_every = 10;
    o.sample_tiles = true;
    o.streamer.planner.scope = k == 0 ? PlanScope::kSampled : PlanScope::kWindow;
    ASSERT_TRUE(runFlight(o, &runs[k]).ok());
  }
  const RunSummary &seen = runs[0].summary, &window = runs[1].summary;
  std::printf("orbit, clip levels: ground seen %llu loaded / %llu sampled = %.2f, PSNR %.2f dB; whole windows "
              "%llu / %llu = %.2f, %.2f dB\n",
              (unsigned long long)seen.tiles_loaded_stack, (unsigned long long)seen.tiles_sampled_stack,
              seen.over_fetch_stack_ratio, seen.psnr_mean_db, (unsigned long long)window.tiles_loaded_stack,
              (unsigned long long)window.tiles_sampled_stack, window.over_fetch_stack_ratio, window.psnr_mean_db);
  ASSERT_GT(seen.tiles_sampled_stack, 20u) << "the clip levels were sampled too little to judge";
  EXPECT_LE(seen.over_fetch_stack_ratio, 2.0);
  EXPECT_GT(window.over_fetch_stack_ratio, 2.0 * seen.over_fetch_stack_ratio);
  EXPECT_GE(seen.psnr_mean_db, window.psnr_mean_db - 0.5);
}

// The height layer over terrain: the plans want the samples the geometry
// read (Streamer::setHeightReads()), not whole windows. St Helens tiled in
// tiles of 32 samples, so that its two finest levels are clip levels of
// the rings' windows (5 tiles a side for rings of 32 cells), flown low
// around the crater: the clipmap's rings load at most twice the height
// tiles they read, under half what whole windows load, and draw the same
// geometry (no frame's finest ring coarser, the geometric error as with
// whole windows).
TEST(TerrainPlanning, HeightLoadsAreTheTilesTheRingsRead) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  const std::string dem = tileDem(dir, 32);
  FlightRun runs[2];
  for (int k = 0; k < 2; ++k) {
    FlightRunOptions o = craterOrbit(dem, 32, 9, test::kPi / 12, 0.5, 3500.0, 400.0, -10.0);
    ASSERT_TRUE(o.terrain.has_value());
    o.frames = 120;
    o.reference_every = 20;
    o.streamer.planner.scope = k == 0 ? PlanScope::kSampled : PlanScope::kWindow;
    ASSERT_TRUE(runFlight(o, &runs[k]).ok());
  }
  const FlightRun &read = runs[0], &window = runs[1];
  std::printf("height clip levels: reads %llu loaded / %llu read = %.2f, geometric error %.3f / %.3f px; whole "
              "windows %llu / %llu = %.2f, %.3f / %.3f px\n",
              (unsigned long long)read.summary.height_tiles_loaded_stack,
              (unsigned long long)read.summary.height_tiles_sampled_stack, read.summary.height_over_fetch_stack_ratio,
              read.geometry_mean_px, read.geometry_p95_px,
              (unsigned long long)window.summary.height_tiles_loaded_stack,
              (unsigned long long)window.summary.height_tiles_sampled_stack,
              window.summary.height_over_fetch_stack_ratio, window.geometry_mean_px, window.geometry_p95_px);
  // No frame draws coarser rings than with whole windows.
  for (size_t i = 0; i < read.frames.size() && i < window.frames.size(); ++i)
    EXPECT_LE(read.frames[i].sample.terrain_finest_level, window.frames[i].sample.terrain_finest_level) << "frame " << i;
  ASSERT_GT(read.summary.height_tiles_sampled_stack, 12u) << "the height clip levels were read too little to judge";
  EXPECT_LE(read.summary.height_over_fetch_stack_ratio, 2.0);
  EXPECT_GT(window.summary.height_over_fetch_stack_ratio, 2.0 * read.summary.height_over_fetch_stack_ratio);
  EXPECT_LE(read.geometry_p95_px, window.geometry_p95_px * 1.05 + 0.01);
}

// The tiles sampled over terrain follow the ground points: a flat terrain
// seen from above samples the tiles the flat reference samples.
TEST(TerrainPlanning, SampledTilesOfFlatTerrainAreThePlanes) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  ASSERT_TRUE(test::writeElevationStore(dir.file("flat.cst"), 256, 256, [](uint64_t, uint64_t) { return 0.0f; }).ok());
  auto colour = test::procedural(4096, 128);
  TerrainLayerConfig tl;
  Status s;
  tl.source = openElevationSource(dir.file("flat.cst"), &s);
  ASSERT_TRUE(tl.source) << s.toString();
  tl.alignment.world_per_sample = {16.0, 16.0};
  tl.alignment.sample0_world = {8.0, 8.0};
  tl.alignment.world_per_height = 1.0;
  tl.ring_cells = 64;
  FlightConfig fc;
  fc.viewport = {320, 180};
  fc.offscreen = true;
  fc.streamer.io_threads = 2;
  fc.terrain = tl;
  Camera c;
  c.position = {2000.3, 150.0, 2500.7};
  c.heading_rad = 0.4;
  c.pitch_rad = -0.5;
  std::unique_ptr<Flight> flight;
  ASSERT_TRUE(Flight::create(colour, fc, c, &flight).ok());
  for (int k = 0; k < 5; ++k) flight->step(c);
  std::vector<float> xyzw;
  ASSERT_TRUE(flight->terrain()->readPositions(c, flight->viewport(), flight->renderer(), &xyzw).ok());
  std::unordered_set<uint64_t> terrain, plane;
  sampledTilesOfPositions(colour->geometry(), xyzw, c, flight->viewport(), &terrain);
  sampledTiles(colour->geometry(), c, flight->viewport(), &plane);
  ASSERT_GT(plane.size(), 20u);
  // Positions pass through float: a tap on a tile border may land on
  // either side, so a few tiles may differ.
  size_t common = 0;
  for (uint64_t k : terrain) common += plane.count(k);
  EXPECT_GE(common, plane.size() * 95 / 100);
  EXPECT_GE(common, terrain.size() * 95 / 100);
  flight->finish();
}

}  // namespace
}  // namespace clipstream
