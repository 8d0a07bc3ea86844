// Terrain flights through the one frame loop (runFlight with a terrain
// layer): both layers stream through one cache, the camera keeps above the
// ground, no frame waits on I/O, and no background pixel shows where the
// terrain must be, moving and at rest. Headless llvmpipe.
#include "test_helpers.h"

#include <clipstream/eval/flight_run.h>
#include <clipstream/renderer/config.h>
#include <clipstream/streamer/bc1.h>
#include <clipstream/streamer/flight_path.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/test_data.h>
#include <clipstream/tiler/tiler.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>

namespace clipstream {
namespace {

constexpr uint32_t kDemSide = 512;
const Viewport kTerrainViewport{320, 180};

// The DEM of the scenarios: hills and a 50-unit cliff across the flight;
// with `spikes`, single samples 300 units high every 37 samples.
// With `rough`, every sample is moved by up to +-60 units of white noise.
float demHeight(uint64_t x, uint64_t y, bool spikes, double cliff = 50.0, bool rough = false) {
  double v = 60.0 + 40.0 * std::sin(x * 0.031) * std::cos(y * 0.027) + 20.0 * std::abs(std::sin(x * 0.011 + y * 0.017));
  if (x > 300) v += cliff;  // a cliff across the flight
  if (spikes && x % 37 == 5 && y % 37 == 11) v += 300.0;
  if (rough) v += 60.0 + 60.0 * (double((x * 73856093u ^ y * 19349663u) % 2001) / 1000.0 - 1.0);
  return float(v);
}

Status writeDem(const std::string& path, bool spikes, double cliff = 50.0, bool rough = false) {
  return test::writeElevationStore(path, kDemSide, kDemSide, [spikes, cliff, rough](uint64_t x, uint64_t y) {
    return demHeight(x, y, spikes, cliff, rough);
  });
}

struct Scenario {
  const char* path = "pass";
  double speed = 1.0;
  uint32_t frames = 40;
  uint32_t rest_frames = 20;
  bool spikes = false;
  double cliff = 50.0;            // height of the cliff across the flight
  double height = 0.0;            // > 0: every keyframe this high above the ground
  double world_per_sample = 4.0;  // the DEM spans 2048 world units at 4 (the texture)
  // An elevation store to fly over instead of the synthetic DEM, with its
  // size in samples, its heights' scale, and the lowest ground of its valid
  // samples in world units (the crack test's plane lies below it, and no
  // frame's ground may lie below it).
  std::string dem_store;
  uint64_t dem_width = kDemSide, dem_height = kDemSide;
  double world_per_height = 1.0;
  double lowest_ground = 20.0;
  std::vector<Keyframe> keyframes;  // non-empty: this path instead of `path`
  TerrainMethod method = TerrainMethod::kClipmap;
  uint64_t ram_budget_bytes = uint64_t(24) << 20;
  bool rough_noise = false;  // every sample off by up to +-60 units (white noise)
  // The quadtree's triangle budget: config.h's rule (twice a full clipmap
  // ring) at these scenarios' 64-cell rings, 2 x 2 x 64^2: about what the
  // clipmap draws here (12k-18k).
  uint64_t triangle_budget = 16384;
  uint32_t synthesized_levels = 0;  // synthesized relief below the DEM (synthesizeRelief())
};

struct Outcome {
  FlightRun run;
  size_t checked = 0, cracks = 0, ground = 0;
};

// Flies `sc` over a 2048^2 white texture (lit ground is grey, the background
// is not) and counts, every 10th frame, background pixels whose ray meets
// the plane below the lowest ground inside the DEM and the texture.
void flyScenario(const Scenario& sc, Outcome* out) {
  test::TempDir dir;
  std::string dem = sc.dem_store;
  if (dem.empty()) {
    dem = dir.file("dem.cst");
    ASSERT_TRUE(writeDem(dem, sc.spikes, sc.cliff, sc.rough_noise).ok());
  }
  Status s;
  TerrainLayerConfig terrain;
  terrain.source = openElevationSource(dem, &s);
  ASSERT_TRUE(terrain.source) << s.toString();
  auto colour = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
  terrain.alignment.world_per_sample = {sc.world_per_sample, sc.world_per_sample};
  terrain.alignment.sample0_world = {0.5 * sc.world_per_sample, 0.5 * sc.world_per_sample};
  terrain.alignment.world_per_height = sc.world_per_height;
  terrain.ring_cells = 64;
  terrain.method = sc.method;
  terrain.triangle_budget = sc.triangle_budget;
  ASSERT_TRUE(synthesizeRelief(sc.synthesized_levels, &terrain).ok());
  const double field = std::min(2048.0, double(std::min(sc.dem_width, sc.dem_height)) * sc.world_per_sample);

  FlightRunOptions o;
  o.source = colour;
  if (sc.keyframes.empty()) {
    ASSERT_TRUE(FlightPath::builtin(sc.path, colour->geometry(), &o.path, 10).ok());
  } else {
    o.path.keyframes = sc.keyframes;
  }
  if (sc.height > 0.0)
    for (auto& k : o.path.keyframes) k.position.y = sc.height;
  o.frames = sc.frames;
  o.rest_frames = sc.rest_frames;
  o.speed = sc.speed;
  o.viewport = kTerrainViewport;
  o.reference_every = 0;
  o.sample_tiles = false;
  o.streamer.ram_budget_bytes = sc.ram_budget_bytes;
  o.terrain = terrain;
  o.on_frame = [&](const FrameSample& f, const OffscreenTarget& target, double*) -> Status {
    if (f.frame % 10 != 9) return okStatus();
    // The camera of this frame, as runFlight placed it.
    const double t = std::min<double>(f.frame, o.frames - 1) * renderer_config::kSimulatedFrameSeconds * o.speed;
    const Camera camera = cameraAboveGround(o.path.sample(t), f.ground_height);
    std::vector<uint8_t> rgba;
    target.readRgba(&rgba);
    // Below the lowest ground, inside the DEM and the texture.
    size_t ground = 0;
    std::vector<uint8_t> marked;
    const size_t cracks =
        test::terrainCracks(rgba, camera, kTerrainViewport, sc.lowest_ground - 1.0, 8.0, field - 8.0, &ground, &marked);
    if (cracks > 0) test::dumpPpm("terrain_cracks_" + std::to_string(f.frame), marked, kTerrainViewport);
    out->cracks += cracks;
    out->ground += ground;
    ++out->checked;
    return okStatus();
  };
  s = runFlight(o, &out->run);
  ASSERT_TRUE(s.ok()) << s.toString();
}

// What every scenario must keep: no crack or hole, no frame waiting on I/O,
// the budget, terrain drawn every frame with the camera above the ground.
void checkScenario(const Scenario& sc, const Outcome& r) {
  const FlightRun& run = r.run;
  ASSERT_EQ(run.frames.size(), size_t(sc.frames + sc.rest_frames));
  EXPECT_GT(r.checked, 0u);
  EXPECT_GT(r.ground, r.checked * kTerrainViewport.width_px * kTerrainViewport.height_px / 4) << "looked at too little terrain";
  EXPECT_EQ(r.cracks, 0u) << "background where the terrain must be";
  EXPECT_EQ(run.render_thread_fetches, 0u) << "a frame waited on a source";
  EXPECT_LE(run.streamer.ram_peak_bytes, run.streamer.ram_budget_bytes);
  ASSERT_EQ(run.streamer.layers.size(), 2u);
  EXPECT_GT(run.streamer.layers[1].total.loads, 0u) << "no height tile streamed";
  for (const FlightRunFrame& f : run.frames) {
    EXPECT_GT(f.sample.terrain_rings, 0u) << "frame " << f.sample.frame << " drew no terrain";
    EXPECT_GE(f.sample.ground_height, sc.lowest_ground - 1.0) << "frame " << f.sample.frame;
    if (sc.method == TerrainMethod::kQuadtree && sc.triangle_budget > 0) {
      EXPECT_LE(f.sample.terrain_triangles, sc.triangle_budget) << "frame " << f.sample.frame;
    }
  }
}

// Flies one scenario and makes the shared checks; returns its outcome for
// checks of its own.
Outcome flyAndCheck(const Scenario& sc) {
  Outcome r;
  flyScenario(sc, &r);
  checkScenario(sc, r);
  // What docs/terrain.md's stability table records for each scenario; for
  // the quadtree also the bound it met (mean and largest) and its node
  // selection's share of the draw (means).
  double worst_ms = 0.0, select_ms = 0.0, draw_ms = 0.0;
  uint64_t triangles = 0;
  for (const FlightRunFrame& f : r.run.frames) {
    worst_ms = std::max(worst_ms, f.sample.frame_ms);
    triangles = std::max(triangles, f.sample.terrain_triangles);
    select_ms += f.sample.terrain_select_ms / double(r.run.frames.size());
    draw_ms += f.sample.draw_ms / double(r.run.frames.size());
  }
  std::printf("  %s: %zu crack pixels in %zu checked frames, frame ms p99 %.1f max %.1f, most triangles %llu, "
              "mean %.0f; bound px mean %.2f max %.2f; select ms %.2f of draw ms %.2f\n",
              terrainMethodName(sc.method), r.cracks, r.checked, r.run.summary.frame_ms_p99, worst_ms,
              static_cast<unsigned long long>(triangles), r.run.terrain_triangles_mean, r.run.terrain_error_px_mean,
              r.run.terrain_error_px_max, select_ms, draw_ms);
  return r;
}

// Every terrain scenario flies with both methods.
class TerrainStability : public ::testing::TestWithParam<TerrainMethod> {};
class TerrainFlight : public ::testing::TestWithParam<TerrainMethod> {};
std::string methodName(const ::testing::TestParamInfo<TerrainMethod>& info) {
  return terrainMethodName(info.param);
}
INSTANTIATE_TEST_SUITE_P(Methods, TerrainStability,
                         ::testing::Values(TerrainMethod::kClipmap, TerrainMethod::kQuadtree), methodName);
INSTANTIATE_TEST_SUITE_P(Methods, TerrainFlight,
                         ::testing::Values(TerrainMethod::kClipmap, TerrainMethod::kQuadtree), methodName);

TEST_P(TerrainFlight, FliesAboveTheGroundThroughOneCacheWithoutHoles) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.method = GetParam();
  Outcome r;
  flyScenario(sc, &r);
  checkScenario(sc, r);
  EXPECT_EQ(r.checked, 6u);
  EXPECT_GT(r.run.streamer.layers[0].total.loads, 0u) << "no colour tile streamed";
  EXPECT_GT(r.run.height_texture_bytes, 0u);
  // At rest the finest ring is level 0: the heights under the camera arrived.
  EXPECT_EQ(r.run.frames.back().sample.terrain_finest_level, 0u);
}

// The stability scenarios over terrain (docs/terrain.md): each must degrade
// to coarser rings, never to a crack, a hole or a crash.
// Synthesized relief two levels below the DEM: rings and nodes over the
// finer levels stitch as over the DEM's, the camera stays above the
// synthesized ground, and at rest the geometry is drawn finer than the
// DEM's level 0 (the clipmap down to the synthesis's level 0; the quadtree
// as far as its triangle budget lets it).
TEST_P(TerrainStability, SynthesizedReliefTwoLevelsBelowTheDem) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.method = GetParam();
  sc.synthesized_levels = 2;
  sc.lowest_ground = 0.0;  // the synthesis may dip below the DEM's lowest sample
  const Outcome r = flyAndCheck(sc);
  EXPECT_LT(r.run.frames.back().sample.terrain_finest_level, sc.synthesized_levels);
  if (sc.method == TerrainMethod::kClipmap) {
    EXPECT_EQ(r.run.frames.back().sample.terrain_finest_level, 0u);
  }
}

TEST_P(TerrainStability, SpikesAtTheHundredfoldSpeed) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.method = GetParam();
  sc.spikes = true;
  sc.speed = 100.0;
  sc.frames = 60;
  flyAndCheck(sc);
}

TEST_P(TerrainStability, TeleportsLandOnTheGround) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.method = GetParam();
  sc.path = "teleport";
  sc.frames = 60;
  flyAndCheck(sc);
}

TEST_P(TerrainStability, LowValleyFlightAcrossTheCliff) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.method = GetParam();
  sc.path = "valley";
  sc.speed = 3.0;
  sc.frames = 60;
  flyAndCheck(sc);
}

TEST_P(TerrainStability, AThousandUnitCliffAtGroundLevel) {
  CLIPSTREAM_REQUIRE_GL();
  // The pass crosses a 1000-unit wall two units above the ground: the
  // camera climbs it (never inside it), the wall fills the view, no crack.
  Scenario sc;
  sc.method = GetParam();
  sc.cliff = 1000.0;
  sc.height = 2.0;
  sc.speed = 10.0;  // the whole pass, across the cliff
  sc.frames = 60;
  const Outcome r = flyAndCheck(sc);
  double highest = 0.0;
  for (const FlightRunFrame& f : r.run.frames) highest = std::max(highest, f.sample.ground_height);
  EXPECT_GT(highest, 1000.0) << "the flight never reached the top of the cliff";
}

TEST_P(TerrainStability, DemMuchCoarserOrFinerThanTheTexture) {
  CLIPSTREAM_REQUIRE_GL();
  for (double world_per_sample : {100.0, 0.5}) {
    // 100: a sample every 100 texels (512 samples over 51,200 world units;
    // the texture lies on 21 x 21 of them); 0.5: two samples a texel (the
    // DEM covers 256 world units of the texture).
    Scenario sc;
    sc.method = GetParam();
    sc.world_per_sample = world_per_sample;
    sc.frames = 30;
    sc.rest_frames = 10;
    Outcome r;
    flyScenario(sc, &r);
    if (world_per_sample < 1.0) {
      // The pass starts outside this small DEM: only require what holds
      // everywhere (no crash, no wait, the budget, terrain drawn).
      EXPECT_EQ(r.cracks, 0u);
      EXPECT_EQ(r.run.render_thread_fetches, 0u);
      EXPECT_LE(r.run.streamer.ram_peak_bytes, r.run.streamer.ram_budget_bytes);
      for (const FlightRunFrame& f : r.run.frames) EXPECT_GT(f.sample.terrain_rings, 0u);
    } else {
      checkScenario(sc, r);
    }
  }
}

TEST_P(TerrainStability, VeryRoughNoise) {
  CLIPSTREAM_REQUIRE_GL();
  // White noise of +-60 units on every sample: no level is a good model of
  // the one below, the quadtree refines everything in view.
  Scenario sc;
  sc.method = GetParam();
  sc.rough_noise = true;
  sc.speed = 3.0;
  sc.frames = 20;
  flyAndCheck(sc);
}

TEST_P(TerrainStability, PitchStraightDown) {
  CLIPSTREAM_REQUIRE_GL();
  // Looking straight down from 150 units while crossing the cliff.
  Scenario sc;
  sc.method = GetParam();
  auto key = [](double time_s, double x) {
    Keyframe k;
    k.t_s = time_s;
    k.position = {x, 150.0, 1024.0};
    k.heading_deg = 90.0;
    k.pitch_deg = -90.0;
    return k;
  };
  sc.keyframes = {key(0.0, 700.0), key(1.0, 1500.0)};
  sc.height = 150.0;
  sc.frames = 40;
  flyAndCheck(sc);
}

TEST_P(TerrainStability, HeightBudgetTooSmallForTheView) {
  CLIPSTREAM_REQUIRE_GL();
  // 6 MiB for both layers (the colour pyramid alone takes 5.3): most height
  // tiles the view asks for cannot stay; the terrain must fall back to the
  // coarser levels it holds, never open a hole.
  Scenario sc;
  sc.method = GetParam();
  sc.ram_budget_bytes = uint64_t(6) << 20;
  sc.speed = 3.0;
  sc.frames = 40;
  flyAndCheck(sc);
}

}  // namespace
}  // namespace clipstream

namespace clipstream {
namespace {

TEST(TerrainAccuracy, GeometricErrorIsZeroOnTheSurfaceAndGrowsOffIt) {
  test::TempDir dir;
  ASSERT_TRUE(writeDem(dir.file("dem.cst"), false).ok());
  Status s;
  auto heights = openElevationSource(dir.file("dem.cst"), &s);
  ASSERT_TRUE(heights) << s.toString();
  LayerAlignment a;
  a.world_per_sample = {4.0, 4.0};
  a.sample0_world = {2.0, 2.0};
  a.world_per_height = 1.0;
  std::unique_ptr<ReferenceSurface> surface;
  ASSERT_TRUE(ReferenceSurface::load(*heights, a, &surface).ok());
  // A sample's centre is the sample; half-way between two, their mean.
  EXPECT_FLOAT_EQ(float(surface->heightAt(2.0 + 4.0 * 100, 2.0 + 4.0 * 77)), demHeight(100, 77, false));
  EXPECT_NEAR(surface->heightAt(2.0 + 4.0 * 100.5, 2.0 + 4.0 * 77),
              0.5 * (demHeight(100, 77, false) + demHeight(101, 77, false)), 1e-4);

  // Positions on the surface (each pixel's ray marched to it): no error.
  Camera camera;
  camera.position = {900.0, 250.0, 1100.0};
  camera.heading_rad = 0.7;
  camera.pitch_rad = -0.6;
  const Viewport vp{96, 64};
  // Each pixel's ray marched to the surface raised by `lift` (0: the
  // surface itself), as a renderer of that geometry would show it.
  auto positions = [&](double lift) {
    std::vector<float> xyzw(size_t(vp.width_px) * vp.height_px * 4, 0.0f);
    const double tan_half = std::tan(camera.vfov_rad * 0.5), aspect = double(vp.width_px) / vp.height_px;
    for (uint32_t py = 0; py < vp.height_px; ++py)
      for (uint32_t px = 0; px < vp.width_px; ++px) {
        const double nx = 2.0 * (px + 0.5) / vp.width_px - 1.0, ny = 1.0 - 2.0 * (py + 0.5) / vp.height_px;
        const glm::dvec3 d = glm::normalize(camera.forward() + camera.right() * (nx * tan_half * aspect) +
                                            camera.up() * (ny * tan_half));
        auto below = [&](double t) {
          const glm::dvec3 p = camera.position + d * t;
          return p.y <= surface->heightAt(p.x, p.z) + lift;
        };
        double t0 = 0.0, t1 = 0.0;
        for (double t = 1.0; t < 5000.0; t += 1.0) {  // march, then bisect
          if (below(t)) {
            t0 = t - 1.0, t1 = t;
            break;
          }
        }
        if (t1 == 0.0) continue;
        for (int k = 0; k < 60; ++k) {
          const double t = 0.5 * (t0 + t1);
          (below(t) ? t1 : t0) = t;
        }
        const glm::dvec3 rel = d * t1;
        float* o = xyzw.data() + (size_t(py) * vp.width_px + px) * 4;
        o[0] = float(rel.x), o[1] = float(rel.y), o[2] = float(rel.z), o[3] = 1.0f;
      }
    return xyzw;
  };
  const std::vector<float> on = positions(0.0), off = positions(5.0);
  const GeometryError exact = geometricError(on, camera, vp, *surface);
  ASSERT_TRUE(exact.measured);
  ASSERT_GT(exact.pixels, vp.width_px * vp.height_px / 2);
  EXPECT_LT(exact.max_px, 0.05);
  const GeometryError lifted = geometricError(off, camera, vp, *surface);
  EXPECT_GT(lifted.mean_px, 0.5);
  EXPECT_GT(lifted.max_px, lifted.mean_px);
  EXPECT_GE(lifted.p95_px, lifted.mean_px);
}

// The synthetic DEM at `path` as a terrain layer: 4 world units a sample
// (2048 over the 512 samples), heights 1:1, default ring size.
void openTestDem(const std::string& path, TerrainLayerConfig* terrain) {
  Status s;
  terrain->source = openElevationSource(path, &s);
  ASSERT_TRUE(terrain->source) << s.toString();
  terrain->alignment.world_per_sample = {4.0, 4.0};
  terrain->alignment.sample0_world = {2.0, 2.0};
  terrain->alignment.world_per_height = 1.0;
}

TEST_P(TerrainFlight, AtRestTheGeometricErrorMeetsTheTarget) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  ASSERT_TRUE(writeDem(dir.file("dem.cst"), false).ok());
  Status s;
  TerrainLayerConfig terrain;
  ASSERT_NO_FATAL_FAILURE(openTestDem(dir.file("dem.cst"), &terrain));
  terrain.method = GetParam();
  FlightRunOptions o;
  o.fewest_triangles = true;
  o.source = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
  ASSERT_TRUE(FlightPath::builtin("orbit", o.source->geometry(), &o.path).ok());
  o.frames = 20;
  o.rest_frames = 20;
  o.viewport = kTerrainViewport;
  o.reference_every = 5;
  o.sample_tiles = false;
  o.terrain = terrain;  // default ring size
  FlightRun run;
  s = runFlight(o, &run);
  ASSERT_TRUE(s.ok()) << s.toString();
  ASSERT_GT(run.geometry_rest_frames, 0u);
  EXPECT_LE(run.geometry_rest_mean_px, 0.5);
  EXPECT_LE(run.geometry_rest_p95_px, 1.0);
  std::printf("  %s, geometric error at rest: mean %.3f px, p95 %.3f px, max %.2f px; %.0f triangles, "
              "fewest %.0f\n",
              terrainMethodName(GetParam()), run.geometry_rest_mean_px, run.geometry_rest_p95_px,
              run.geometry_rest_max_px, run.judged_triangles_mean, run.fewest_triangles_mean);
  // The fewest triangles within the target are a lower bound of a method's
  // at about the same error.
  EXPECT_GT(run.fewest_triangles_mean, 0.0);
  EXPECT_LE(run.fewest_triangles_mean, run.judged_triangles_mean);
}

TEST_P(TerrainStability, NoDataHolesFlownTwoUnitsAboveTheGround) {
  CLIPSTREAM_REQUIRE_GL();
  // The bundled DEM (327 x 468 samples of 30 m) has 4151 no-data samples in
  // a band along its edges. Tiled by the tiler, they are filled from their
  // neighbours; flown along that band two units above the ground, no frame
  // shows a crack, a hole or ground below the lowest valid height (a
  // -32767 spike would put it 6000 units down).
  test::TempDir dir;
  TilerOptions t;
  t.input_path = test::bundledDataPath("mount_st_helens_30m.tif");
  t.output_path = dir.file("helens.cst");
  t.fsync = false;
  TilerSummary summary;
  Status s = tileImage(t, &summary);
  ASSERT_TRUE(s.ok()) << s.toString();
  Status o;
  auto store = openElevationSource(t.output_path, &o);
  ASSERT_TRUE(store) << o.toString();
  ASSERT_EQ(store->elevationInfo().filled_samples, 4151u);
  Scenario sc;
  sc.method = GetParam();
  sc.dem_store = t.output_path;
  sc.dem_width = 327;
  sc.dem_height = 468;
  sc.world_per_height = 0.2;                          // 682..2543 m -> 136..509 units
  sc.lowest_ground = store->elevationInfo().min_height * 0.2;  // of the valid samples
  sc.frames = 60;
  sc.rest_frames = 10;
  sc.speed = 1.0;
  // Straight along the northern band (row 0 is all no-data, rows 1-3 in
  // part), over sample row 1, looking south-east into the DEM: the ground
  // under the camera is filled ground all the way.
  auto key = [](double time_s, double x, double heading) {
    Keyframe k;
    k.t_s = time_s;
    k.position = {x, 2.0, 6.0};
    k.heading_deg = heading;
    k.pitch_deg = -15.0;
    return k;
  };
  sc.keyframes = {key(0.0, 40.0, 135.0), key(0.5, 640.0, 135.0), key(1.0, 1240.0, 135.0)};
  const Outcome r = flyAndCheck(sc);
  double lowest = INFINITY;
  for (const FlightRunFrame& f : r.run.frames) lowest = std::min(lowest, f.sample.ground_height);
  std::printf("  lowest ground under the camera %.1f units (valid samples from %.1f)\n", lowest,
              sc.lowest_ground);
}

// At rest the streamed terrain is judged against the full-resolution mesh
// with the ideal texture: where the finest ring lies, the geometry agrees
// with the reference to the bit, and there the texture must agree to the
// bit too; PSNR over the whole frame is reported.
// A texture with detail at every level (a flat colour would agree anyway).
std::shared_ptr<TileSource> detailedTexture() {
  std::vector<uint8_t> image(size_t(2048) * 2048 * 4);
  for (size_t y = 0; y < 2048; ++y)
    for (size_t x = 0; x < 2048; ++x) {
      uint8_t* p = &image[(y * 2048 + x) * 4];
      const uint32_t h = uint32_t(x * 73856093u) ^ uint32_t(y * 19349663u);
      p[0] = uint8_t(h >> 7);
      p[1] = uint8_t((x ^ y) * 3);
      p[2] = uint8_t(((x / 16) + (y / 16)) % 2 ? 200 : 40);
      p[3] = 255;
    }
  return makeImageSource(std::move(image), 2048, 2048, 128);
}

// Flies the orbit over the test DEM and rests, judging every 5th frame
// against the terrain reference drawn from `reference` (else `source`),
// lit by `lighting`, the reference by `reference_lighting` (unset: the same).
void flyOverTestDem(const std::shared_ptr<TileSource>& source, const std::shared_ptr<TileSource>& reference,
                    FlightRun* run, TerrainLighting lighting = TerrainLighting::kVertex,
                    std::optional<TerrainLighting> reference_lighting = std::nullopt) {
  test::TempDir dir;
  ASSERT_TRUE(writeDem(dir.file("dem.cst"), false).ok());
  TerrainLayerConfig terrain;
  ASSERT_NO_FATAL_FAILURE(openTestDem(dir.file("dem.cst"), &terrain));
  terrain.lighting = lighting;
  FlightRunOptions o;
  o.source = source;
  o.reference_source = reference;
  ASSERT_TRUE(FlightPath::builtin("orbit", o.source->geometry(), &o.path).ok());
  o.frames = 10;
  o.rest_frames = 20;
  o.viewport = kTerrainViewport;
  o.reference_every = 5;
  o.sample_tiles = false;
  o.terrain = terrain;  // default ring size
  o.reference_lighting = reference_lighting;
  const Status s = runFlight(o, run);
  ASSERT_TRUE(s.ok()) << s.toString();
  ASSERT_GT(run->geometry_rest_frames, 0u);
}

double lastFramePsnr(const FlightRun& run) {
  return run.frames.back().accuracy.measured ? run.frames.back().accuracy.error.psnr_db : 0.0;
}

TEST(TerrainAccuracy, AtRestTheTextureIsBitIdenticalWhereTheGeometryAgrees) {
  CLIPSTREAM_REQUIRE_GL();
  FlightRun run;
  ASSERT_NO_FATAL_FAILURE(flyOverTestDem(detailedTexture(), nullptr, &run));
  // Judged frames carry a PSNR (in the CSV, JSON and summary).
  uint32_t judged = 0;
  for (const FlightRunFrame& f : run.frames) judged += f.accuracy.measured;
  const double rest_psnr = lastFramePsnr(run);
  EXPECT_GE(judged, 4u);
  EXPECT_GT(run.summary.psnr_mean_db, 0.0);
  // Enough agreeing pixels to mean something: the finest ring fills much
  // of a low view.
  const uint64_t rest_pixels = uint64_t(run.geometry_rest_frames) * kTerrainViewport.width_px * kTerrainViewport.height_px;
  EXPECT_GT(run.terrain_rest_agree_pixels, rest_pixels / 10);
  EXPECT_EQ(run.terrain_rest_agree_mismatched, 0u);
  EXPECT_GT(rest_psnr, 25.0);
  std::printf("  at rest: %llu of %llu pixels agree in geometry, %llu of them differ in colour; last frame %.2f dB\n",
              (unsigned long long)run.terrain_rest_agree_pixels, (unsigned long long)rest_pixels,
              (unsigned long long)run.terrain_rest_agree_mismatched, rest_psnr);
}

// Per-pixel lighting: at rest, where the geometry agrees, the frame equals
// the reference lit per pixel from the full-resolution heights (within the
// rounding of the hardware's bilinear blend of the stored gradients,
// which the reference blends itself); against the reference lit by vertex
// it does not, and it comes closer to its reference than lighting by
// vertex does.
TEST(TerrainAccuracy, PixelLightingAtRestEqualsItsReferenceWhereTheGeometryAgrees) {
  CLIPSTREAM_REQUIRE_GL();
  const std::shared_ptr<TileSource> texture = detailedTexture();
  FlightRun pixel, pixel_on_vertex, vertex_on_pixel;
  ASSERT_NO_FATAL_FAILURE(flyOverTestDem(texture, nullptr, &pixel, TerrainLighting::kPixel));
  ASSERT_NO_FATAL_FAILURE(
      flyOverTestDem(texture, nullptr, &pixel_on_vertex, TerrainLighting::kPixel, TerrainLighting::kVertex));
  ASSERT_NO_FATAL_FAILURE(
      flyOverTestDem(texture, nullptr, &vertex_on_pixel, TerrainLighting::kVertex, TerrainLighting::kPixel));
  EXPECT_EQ(pixel.reference_lighting, "pixel");
  EXPECT_EQ(pixel_on_vertex.reference_lighting, "vertex");
  const uint64_t rest_pixels =
      uint64_t(pixel.geometry_rest_frames) * kTerrainViewport.width_px * kTerrainViewport.height_px;
  EXPECT_GT(pixel.terrain_rest_agree_pixels, rest_pixels / 10);
  EXPECT_LE(pixel.terrain_rest_agree_max_diff, 1u);
  EXPECT_LT(pixel.terrain_rest_agree_mismatched, pixel.terrain_rest_agree_pixels / 100);
  // The same frames judged against the vertex-lit reference: the lighting shows.
  EXPECT_GT(pixel_on_vertex.terrain_rest_agree_max_diff, 1u);
  EXPECT_GT(pixel_on_vertex.terrain_rest_agree_mismatched, pixel.terrain_rest_agree_mismatched * 10 + 100);
  EXPECT_GT(lastFramePsnr(pixel), lastFramePsnr(vertex_on_pixel));
  std::printf("  pixel lighting at rest: %llu of %llu agreeing pixels differ (largest %u); against the vertex-lit "
              "reference %llu (largest %u); last frame %.2f dB lit by pixel, %.2f dB by vertex\n",
              (unsigned long long)pixel.terrain_rest_agree_mismatched,
              (unsigned long long)pixel.terrain_rest_agree_pixels, pixel.terrain_rest_agree_max_diff,
              (unsigned long long)pixel_on_vertex.terrain_rest_agree_mismatched,
              pixel_on_vertex.terrain_rest_agree_max_diff, lastFramePsnr(pixel), lastFramePsnr(vertex_on_pixel));
}

// BC1 tiles over terrain: bit-identical at rest to the terrain reference
// made of the same blocks; against the RGBA8 one the compression shows.
TEST(TerrainAccuracy, Bc1TilesRestOnTheirReferenceAndShowAgainstRgba8) {
  CLIPSTREAM_REQUIRE_GL();
  const std::shared_ptr<TileSource> rgba8 = detailedTexture();
  Status st;
  const std::shared_ptr<TileSource> bc1 = makeBc1Source(rgba8, &st);
  ASSERT_TRUE(bc1) << st.toString();
  FlightRun same, against_rgba8;
  ASSERT_NO_FATAL_FAILURE(flyOverTestDem(bc1, nullptr, &same));
  ASSERT_NO_FATAL_FAILURE(flyOverTestDem(bc1, rgba8, &against_rgba8));
  EXPECT_EQ(same.tile_content, TileContent::kBc1);
  EXPECT_GT(same.terrain_rest_agree_pixels, 0u);
  EXPECT_EQ(same.terrain_rest_agree_mismatched, 0u);
  EXPECT_GT(against_rgba8.terrain_rest_agree_mismatched, 0u);
  EXPECT_GT(lastFramePsnr(against_rgba8), 20.0);
  EXPECT_LT(lastFramePsnr(against_rgba8), lastFramePsnr(same));
  std::printf("  bc1 at rest: %.2f dB on its own reference, %.2f dB on the RGBA8 one (%llu differing pixels)\n",
              lastFramePsnr(same), lastFramePsnr(against_rgba8),
              (unsigned long long)against_rgba8.terrain_rest_agree_mismatched);
}

TEST(TerrainAccuracy, ComparisonCountsColourDifferencesWhereGeometryAgrees) {
  // 4 x 2 pixels: two quads; the left one agrees in position everywhere,
  // the right one but for one pixel.
  const Viewport vp{4, 2};
  std::vector<float> a(4 * 2 * 4), b;
  for (size_t p = 0; p < 8; ++p) {
    a[p * 4 + 0] = float(p);
    a[p * 4 + 1] = 2.0f;
    a[p * 4 + 2] = 3.0f;
    a[p * 4 + 3] = 1.0f;
  }
  b = a;
  b[7 * 4 + 1] = 2.5f;  // bottom-right pixel
  const std::vector<uint8_t> c(4 * 2 * 4, 100);
  std::vector<uint8_t> d = c;
  TerrainFrameError e = compareTerrainFrames(c, a, d, b, vp);
  EXPECT_EQ(e.agree_pixels, 4u);
  EXPECT_EQ(e.agree_mismatched, 0u);
  d[4 * 4 + 1] = 101;  // bottom-left pixel: in the agreeing quad
  e = compareTerrainFrames(c, a, d, b, vp);
  EXPECT_EQ(e.agree_mismatched, 1u);
  d[4 * 4 + 1] = 100;
  d[2 * 4 + 0] = 7;  // top row, third pixel: its quad has a disagreeing pixel
  e = compareTerrainFrames(c, a, d, b, vp);
  EXPECT_EQ(e.agree_mismatched, 0u);
  EXPECT_LT(e.error.psnr_db, 99.0);
}

}  // namespace
}  // namespace clipstream
