// Terrain flights through the one frame loop (runFlight with a terrain
// layer): both layers stream through one cache, the camera keeps above the
// ground, no frame waits on I/O, and no background pixel shows where the
// terrain must be, moving and at rest. Headless llvmpipe.
#include "test_helpers.h"

#include <clipstream/eval/flight_run.h>
#include <clipstream/renderer/config.h>
#include <clipstream/streamer/flight_path.h>
#include <clipstream/testing/synthetic_store.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace clipstream {
namespace {

constexpr uint32_t kDemSide = 512;
const Viewport kViewport{320, 180};

// The DEM of the scenarios: hills and a 50-unit cliff across the flight;
// with `spikes`, single samples 300 units high every 37 samples.
float demHeight(uint64_t x, uint64_t y, bool spikes, double cliff = 50.0) {
  double v = 60.0 + 40.0 * std::sin(x * 0.031) * std::cos(y * 0.027) + 20.0 * std::abs(std::sin(x * 0.011 + y * 0.017));
  if (x > 300) v += cliff;  // a cliff across the flight
  if (spikes && x % 37 == 5 && y % 37 == 11) v += 300.0;
  return float(v);
}

Status writeDem(const std::string& path, bool spikes, double cliff = 50.0) {
  return test::writeElevationStore(path, kDemSide, kDemSide, [spikes, cliff](uint64_t x, uint64_t y) {
    return demHeight(x, y, spikes, cliff);
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
  ASSERT_TRUE(writeDem(dir.file("dem.cst"), sc.spikes, sc.cliff).isOk());
  Status s;
  TerrainLayerConfig terrain;
  terrain.source = openElevationSource(dir.file("dem.cst"), &s);
  ASSERT_TRUE(terrain.source) << s.toString();
  auto colour = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
  terrain.alignment.world_per_sample = {sc.world_per_sample, sc.world_per_sample};
  terrain.alignment.sample0_world = {0.5 * sc.world_per_sample, 0.5 * sc.world_per_sample};
  terrain.alignment.world_per_height = 1.0;
  terrain.ring_cells = 64;
  const double field = std::min(2048.0, kDemSide * sc.world_per_sample);

  FlightRunOptions o;
  o.source = colour;
  ASSERT_TRUE(FlightPath::builtin(sc.path, colour->geometry(), &o.path, 10).isOk());
  if (sc.height > 0.0)
    for (auto& k : o.path.keyframes) k.position.y = sc.height;
  o.frames = sc.frames;
  o.rest_frames = sc.rest_frames;
  o.speed = sc.speed;
  o.viewport = kViewport;
  o.reference_every = 0;
  o.sample_tiles = false;
  o.streamer.ram_budget_bytes = uint64_t(24) << 20;
  o.terrain = terrain;
  o.on_frame = [&](const FrameSample& f, const OffscreenTarget& target, double*) -> Status {
    if (f.frame % 10 != 9) return Status::ok();
    // The camera of this frame, as runFlight placed it.
    const double t = std::min<double>(f.frame, o.frames - 1) * renderer_config::kSimulatedFrameSeconds * o.speed;
    const Camera camera = cameraAboveGround(o.path.sample(t), f.ground_height);
    std::vector<uint8_t> rgba;
    target.readRgba(&rgba);
    // Below the lowest ground (60 - 40 + 0), inside the DEM and the texture.
    size_t ground = 0;
    out->cracks += test::terrainCracks(rgba, camera, kViewport, 19.0, 8.0, field - 8.0, &ground);
    out->ground += ground;
    ++out->checked;
    return Status::ok();
  };
  s = runFlight(o, &out->run);
  ASSERT_TRUE(s.isOk()) << s.toString();
}

// What every scenario must keep: no crack or hole, no frame waiting on I/O,
// the budget, terrain drawn every frame with the camera above the ground.
void checkScenario(const Scenario& sc, const Outcome& r) {
  const FlightRun& run = r.run;
  ASSERT_EQ(run.frames.size(), size_t(sc.frames + sc.rest_frames));
  EXPECT_GT(r.checked, 0u);
  EXPECT_GT(r.ground, r.checked * kViewport.width_px * kViewport.height_px / 4) << "looked at too little terrain";
  EXPECT_EQ(r.cracks, 0u) << "background where the terrain must be";
  EXPECT_EQ(run.render_thread_fetches, 0u) << "a frame waited on a source";
  EXPECT_LE(run.streamer.ram_peak_bytes, run.streamer.ram_budget_bytes);
  ASSERT_EQ(run.streamer.layers.size(), 2u);
  EXPECT_GT(run.streamer.layers[1].total.loads, 0u) << "no height tile streamed";
  for (const FlightRunFrame& f : run.frames) {
    EXPECT_GT(f.sample.terrain_rings, 0u) << "frame " << f.sample.frame << " drew no terrain";
    EXPECT_GE(f.sample.ground_height, 19.0) << "frame " << f.sample.frame;
  }
}

// Flies one scenario and makes the shared checks; returns its outcome for
// checks of its own.
Outcome flyAndCheck(const Scenario& sc) {
  Outcome r;
  flyScenario(sc, &r);
  checkScenario(sc, r);
  return r;
}

TEST(TerrainFlight, FliesAboveTheGroundThroughOneCacheWithoutHoles) {
  CLIPSTREAM_REQUIRE_GL();
  const Scenario sc;
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
TEST(TerrainStability, SpikesAtTheHundredfoldSpeed) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.spikes = true;
  sc.speed = 100.0;
  sc.frames = 60;
  flyAndCheck(sc);
}

TEST(TerrainStability, TeleportsLandOnTheGround) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.path = "teleport";
  sc.frames = 60;
  flyAndCheck(sc);
}

TEST(TerrainStability, LowValleyFlightAcrossTheCliff) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.path = "valley";
  sc.speed = 3.0;
  sc.frames = 60;
  flyAndCheck(sc);
}

TEST(TerrainStability, AThousandUnitCliffAtGroundLevel) {
  CLIPSTREAM_REQUIRE_GL();
  // The pass crosses a 1000-unit wall two units above the ground: the
  // camera climbs it (never inside it), the wall fills the view, no crack.
  Scenario sc;
  sc.cliff = 1000.0;
  sc.height = 2.0;
  sc.speed = 10.0;  // the whole pass, across the cliff
  sc.frames = 60;
  const Outcome r = flyAndCheck(sc);
  double highest = 0.0;
  for (const FlightRunFrame& f : r.run.frames) highest = std::max(highest, f.sample.ground_height);
  EXPECT_GT(highest, 1000.0) << "the flight never reached the top of the cliff";
}

TEST(TerrainStability, DemMuchCoarserOrFinerThanTheTexture) {
  CLIPSTREAM_REQUIRE_GL();
  for (double world_per_sample : {100.0, 0.5}) {
    // 100: a sample every 100 texels (512 samples over 51,200 world units;
    // the texture lies on 21 x 21 of them); 0.5: two samples a texel (the
    // DEM covers 256 world units of the texture).
    Scenario sc;
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

}  // namespace
}  // namespace clipstream

namespace clipstream {
namespace {

TEST(TerrainAccuracy, GeometricErrorIsZeroOnTheSurfaceAndGrowsOffIt) {
  test::TempDir dir;
  ASSERT_TRUE(writeDem(dir.file("dem.cst"), false).isOk());
  Status s;
  auto heights = openElevationSource(dir.file("dem.cst"), &s);
  ASSERT_TRUE(heights) << s.toString();
  LayerAlignment a;
  a.world_per_sample = {4.0, 4.0};
  a.sample0_world = {2.0, 2.0};
  a.world_per_height = 1.0;
  std::unique_ptr<ReferenceSurface> surface;
  ASSERT_TRUE(ReferenceSurface::load(*heights, a, &surface).isOk());
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

TEST(TerrainAccuracy, AtRestTheGeometricErrorMeetsTheTarget) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  ASSERT_TRUE(writeDem(dir.file("dem.cst"), false).isOk());
  Status s;
  TerrainLayerConfig terrain;
  terrain.source = openElevationSource(dir.file("dem.cst"), &s);
  ASSERT_TRUE(terrain.source) << s.toString();
  terrain.alignment.world_per_sample = {4.0, 4.0};
  terrain.alignment.sample0_world = {2.0, 2.0};
  terrain.alignment.world_per_height = 1.0;
  FlightRunOptions o;
  o.source = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
  ASSERT_TRUE(FlightPath::builtin("orbit", o.source->geometry(), &o.path).isOk());
  o.frames = 20;
  o.rest_frames = 20;
  o.viewport = kViewport;
  o.reference_every = 5;
  o.sample_tiles = false;
  o.terrain = terrain;  // default ring size
  FlightRun run;
  s = runFlight(o, &run);
  ASSERT_TRUE(s.isOk()) << s.toString();
  ASSERT_GT(run.geometry_rest_frames, 0u);
  EXPECT_LE(run.geometry_rest_mean_px, 0.5);
  EXPECT_LE(run.geometry_rest_p95_px, 1.0);
  std::printf("  geometric error at rest: mean %.3f px, p95 %.3f px, max %.2f px\n",
              run.geometry_rest_mean_px, run.geometry_rest_p95_px, run.geometry_rest_max_px);
}

}  // namespace
}  // namespace clipstream
