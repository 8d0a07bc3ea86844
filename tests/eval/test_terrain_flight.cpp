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

float demHeight(uint64_t x, uint64_t y) {
  double v = 60.0 + 40.0 * std::sin(x * 0.031) * std::cos(y * 0.027) + 20.0 * std::abs(std::sin(x * 0.011 + y * 0.017));
  if (x > 300) v += 50.0;  // a cliff across the flight
  return float(v);
}

// An F32 elevation store of kDemSide^2 samples (decimated levels, each
// tile's own bounds).
Status writeDem(const std::string& path) {
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
            const float h = demHeight(sx, sy);
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

TEST(TerrainFlight, FliesAboveTheGroundThroughOneCacheWithoutHoles) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir;
  ASSERT_TRUE(writeDem(dir.file("dem.cst")).isOk());
  Status s;
  TerrainLayerConfig terrain;
  terrain.source = openElevationSource(dir.file("dem.cst"), &s);
  ASSERT_TRUE(terrain.source) << s.toString();
  // A white 2048^2 texture: lit ground is grey, the background is not.
  auto colour = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
  terrain.alignment.world_per_sample = {4.0, 4.0};
  terrain.alignment.sample0_world = {2.0, 2.0};
  terrain.alignment.world_per_height = 1.0;
  terrain.ring_cells = 64;

  FlightRunOptions o;
  o.source = colour;
  ASSERT_TRUE(FlightPath::builtin("pass", colour->geometry(), &o.path).isOk());
  o.frames = 40;
  o.rest_frames = 20;
  o.viewport = kViewport;
  o.reference_every = 0;
  o.sample_tiles = false;
  o.streamer.ram_budget_bytes = uint64_t(24) << 20;
  o.terrain = terrain;
  size_t checked = 0, cracks = 0, ground = 0;
  std::vector<Camera> cameras;
  o.on_frame = [&](const FrameSample& f, const OffscreenTarget& target, double*) -> Status {
    // The camera of this frame, as runFlight placed it.
    const double t = std::min<double>(f.frame, o.frames - 1) * renderer_config::kSimulatedFrameSeconds;
    const Camera camera = cameraAboveGround(o.path.sample(t), f.ground_height);
    if (f.frame % 10 != 9) return Status::ok();
    std::vector<uint8_t> rgba;
    target.readRgba(&rgba);
    Camera lowered = camera;
    lowered.position.y -= 40.0;  // below the lowest ground (about 40)
    for (uint32_t py = 0; py < kViewport.height_px; ++py)
      for (uint32_t px = 0; px < kViewport.width_px; ++px) {
        const uint8_t* p = rgba.data() + (size_t(py) * kViewport.width_px + px) * 4;
        const bool sky = std::equal(p, p + 3, renderer_config::kSkyRgba);
        if (!sky) ++ground;
        glm::dvec2 hit;
        if (!groundHit(lowered, kViewport, px + 0.5, py + 0.5, &hit)) continue;
        if (hit.x < 8 || hit.y < 8 || hit.x > 2040 || hit.y > 2040) continue;
        if (sky) ++cracks;
      }
    ++checked;
    return Status::ok();
  };
  FlightRun run;
  s = runFlight(o, &run);
  ASSERT_TRUE(s.isOk()) << s.toString();
  ASSERT_EQ(run.frames.size(), 60u);
  EXPECT_EQ(checked, 6u);
  EXPECT_GT(ground, checked * kViewport.width_px * kViewport.height_px / 4) << "looked at too little terrain";
  EXPECT_EQ(cracks, 0u) << "background where the terrain must be";
  EXPECT_EQ(run.render_thread_fetches, 0u) << "a frame waited on a source";
  EXPECT_LE(run.streamer.ram_peak_bytes, run.streamer.ram_budget_bytes);
  ASSERT_EQ(run.streamer.layers.size(), 2u);
  EXPECT_GT(run.streamer.layers[0].total.loads, 0u) << "no colour tile streamed";
  EXPECT_GT(run.streamer.layers[1].total.loads, 0u) << "no height tile streamed";
  EXPECT_GT(run.height_texture_bytes, 0u);
  for (const FlightRunFrame& f : run.frames) {
    EXPECT_GT(f.sample.terrain_rings, 0u) << "frame " << f.sample.frame << " drew no terrain";
    EXPECT_GT(f.sample.ground_height, 30.0) << "frame " << f.sample.frame;
  }
  // At rest the finest ring is level 0: the heights under the camera arrived.
  EXPECT_EQ(run.frames.back().sample.terrain_finest_level, 0u);
}

}  // namespace
}  // namespace clipstream
