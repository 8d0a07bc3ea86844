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
float demHeight(uint64_t x, uint64_t y, bool spikes) {
  double v = 60.0 + 40.0 * std::sin(x * 0.031) * std::cos(y * 0.027) + 20.0 * std::abs(std::sin(x * 0.011 + y * 0.017));
  if (x > 300) v += 50.0;  // a cliff across the flight
  if (spikes && x % 37 == 5 && y % 37 == 11) v += 300.0;
  return float(v);
}

// An F32 elevation store of kDemSide^2 samples (decimated levels, each
// tile's own bounds).
Status writeDem(const std::string& path, bool spikes) {
  PyramidGeometry g;
  if (!makePyramidGeometry(kDemSide, kDemSide, 128, PixelFormat::kF32, &g))
    return Status::error(ErrorCode::kInvalidArgument, "geometry");
  WriterOptions options;
  options.fsync = false;
  options.encoding.filter = DownsampleFilter::kDecimate;
  options.elevation.present = true;
  std::unique_ptr<TileStoreWriter> writer;
  if (Status s = TileStoreWriter::create(path, g, options, &writer); !s) return s;
  float lo = INFINITY, hi = -INFINITY;
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t ty = 0; ty < g.levels[l].tiles_y; ++ty)
      for (uint32_t tx = 0; tx < g.levels[l].tiles_x; ++tx) {
        std::vector<uint8_t> pixels(g.tileBytes());
        float tmin = INFINITY, tmax = -INFINITY;
        for (uint32_t y = 0; y < 128; ++y)
          for (uint32_t x = 0; x < 128; ++x) {
            const uint64_t sx = std::min<uint64_t>((uint64_t(tx) * 128 + x) << l, kDemSide - 1);
            const uint64_t sy = std::min<uint64_t>((uint64_t(ty) * 128 + y) << l, kDemSide - 1);
            const float h = demHeight(sx, sy, spikes);
            std::memcpy(pixels.data() + (size_t(y) * 128 + x) * 4, &h, 4);
            tmin = std::min(tmin, h), tmax = std::max(tmax, h);
          }
        lo = std::min(lo, tmin), hi = std::max(hi, tmax);
        EncodedTile encoded;
        if (Status s = encodeTile(g, options.encoding, {l, tx, ty}, pixels, &encoded); !s) return s;
        encoded.location.min_height = tmin;
        encoded.location.max_height = tmax;
        if (Status s = writer->write(std::move(encoded)); !s) return s;
      }
  if (Status s = writer->setElevationFigures(0, 0.0, lo, hi); !s) return s;
  return writer->finish();
}

struct Scenario {
  const char* path = "pass";
  double speed = 1.0;
  uint32_t frames = 40;
  uint32_t rest_frames = 20;
  bool spikes = false;
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
  ASSERT_TRUE(writeDem(dir.file("dem.cst"), sc.spikes).isOk());
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
    Camera lowered = camera;
    lowered.position.y -= 19.0;  // below the lowest ground (60 - 40 + 0)
    for (uint32_t py = 0; py < kViewport.height_px; ++py)
      for (uint32_t px = 0; px < kViewport.width_px; ++px) {
        const uint8_t* p = rgba.data() + (size_t(py) * kViewport.width_px + px) * 4;
        const bool sky = std::equal(p, p + 3, renderer_config::kSkyRgba);
        if (!sky) ++out->ground;
        glm::dvec2 hit;
        if (!groundHit(lowered, kViewport, px + 0.5, py + 0.5, &hit)) continue;
        if (hit.x < 8 || hit.y < 8 || hit.x > field - 8 || hit.y > field - 8) continue;
        if (sky) ++out->cracks;
      }
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
  Outcome r;
  flyScenario(sc, &r);
  checkScenario(sc, r);
}

TEST(TerrainStability, TeleportsLandOnTheGround) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.path = "teleport";
  sc.frames = 60;
  Outcome r;
  flyScenario(sc, &r);
  checkScenario(sc, r);
}

TEST(TerrainStability, LowValleyFlightAcrossTheCliff) {
  CLIPSTREAM_REQUIRE_GL();
  Scenario sc;
  sc.path = "valley";
  sc.speed = 3.0;
  sc.frames = 60;
  Outcome r;
  flyScenario(sc, &r);
  checkScenario(sc, r);
}

TEST(TerrainStability, DemMuchCoarserOrFinerThanTheTexture) {
  CLIPSTREAM_REQUIRE_GL();
  for (double world_per_sample : {16.0, 0.5}) {
    // 16: 512 samples over 8192 world units (the texture covers a quarter
    // of the DEM); 0.5: the DEM covers 256 world units, finer than texels.
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
