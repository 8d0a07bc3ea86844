// The frame loop's step: the clock, warm-up and cut rules, per-frame
// counter deltas and GPU hits.
#include "test_helpers.h"

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/streamer/tile_source.h>

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

namespace clipstream {
namespace {

TEST(IsCut, ContinuousMotionIsNotACutButATeleportIs) {
  Camera a, b, c;
  a.position = {100, 50, 100};
  b.position = {110, 50, 100};  // 10 texels, like the step before
  c.position = {5000, 50, 100};
  EXPECT_FALSE(isCut(a, b, 10.0));
  EXPECT_TRUE(isCut(b, c, 10.0));
  EXPECT_TRUE(isCut(a, c, 0.0)) << "a jump after standing still";
}

TEST(IsCut, ASnapTurnIsACutButAFastContinuousTurnIsNot) {
  Camera a, b, c, d;
  b.heading_rad = a.heading_rad + 0.1;  // 6 degrees a frame: 360 deg/s
  c.heading_rad = a.heading_rad + 1.6;  // 90 degrees at once
  d.heading_rad = 6.2;                  // across the wrap: 4.6 degrees from 0
  EXPECT_FALSE(isCut(a, b, 0.0));
  EXPECT_TRUE(isCut(a, c, 0.0));
  EXPECT_FALSE(isCut(a, d, 0.0)) << "the turn is measured the short way round";
  Camera e = a;
  e.pitch_rad = a.pitch_rad - 0.7;
  EXPECT_TRUE(isCut(a, e, 0.0)) << "a pitch snap";
}

Camera overTheMiddle(double x_offset = 0.0) {
  Camera c;
  c.position = {double(1 << 19) + x_offset, 300.0, double(1 << 19)};
  c.pitch_rad = -0.6;
  return c;
}

TEST(Flight, FollowsTheClockWarmUpAndCutRules) {
  CLIPSTREAM_REQUIRE_GL();
  FlightConfig config;
  config.viewport = {160, 96};
  config.streamer.io_threads = 2;
  config.warmup_frames = 2;
  std::unique_ptr<Flight> flight;
  ASSERT_TRUE(Flight::create(test::procedural(uint64_t(1) << 20), config, overTheMiddle(), &flight).ok());
  ASSERT_NE(flight->target(), nullptr);
  const double dt = renderer_config::kSimulatedFrameSeconds;
  for (uint32_t w = 0; w < 2; ++w) {
    const FrameSample s = flight->step(overTheMiddle());
    EXPECT_TRUE(s.warmup);
    EXPECT_FALSE(s.cut);
    EXPECT_EQ(s.frame, w);
    EXPECT_DOUBLE_EQ(s.clock_s, w * dt) << "the clock runs through warm-up";
  }
  const FrameSample first = flight->step(overTheMiddle());
  EXPECT_FALSE(first.warmup);
  EXPECT_EQ(first.frame, 0u);
  EXPECT_FALSE(first.cut) << "a warmed-up first frame is no cut";
  EXPECT_DOUBLE_EQ(first.clock_s, 2 * dt);
  const FrameSample moved = flight->step(overTheMiddle(2.0));
  EXPECT_FALSE(moved.cut) << "a small step";
  const FrameSample jumped = flight->step(overTheMiddle(100000.0));
  EXPECT_TRUE(jumped.cut) << "a teleport";
  EXPECT_EQ(jumped.frame, 2u);
  EXPECT_DOUBLE_EQ(flight->step(overTheMiddle(100000.0), 123.0).clock_s, 123.0) << "the host's clock";
  flight->finish();
}

TEST(Flight, FirstFrameWithoutWarmUpIsACut) {
  CLIPSTREAM_REQUIRE_GL();
  FlightConfig config;
  config.viewport = {160, 96};
  config.streamer.io_threads = 2;
  std::unique_ptr<Flight> flight;
  ASSERT_TRUE(Flight::create(test::procedural(uint64_t(1) << 20), config, overTheMiddle(), &flight).ok());
  EXPECT_TRUE(flight->step(overTheMiddle()).cut);
  EXPECT_FALSE(flight->step(overTheMiddle()).cut);
  flight->finish();
}

// Holding still, the frames' deltas add up to the streamer's totals, and
// as the windows load, GPU misses turn into hits.
TEST(Flight, DeltasAddUpAndAStillCameraTurnsGpuMissesIntoHits) {
  CLIPSTREAM_REQUIRE_GL();
  FlightConfig config;
  config.viewport = {160, 96};
  config.streamer.io_threads = 2;
  config.upload_tiles = 64;
  std::unique_ptr<Flight> flight;
  ASSERT_TRUE(Flight::create(test::procedural(uint64_t(1) << 20), config, overTheMiddle(), &flight).ok());
  uint64_t loads = 0, ram_hits = 0, ram_misses = 0;
  FrameSample first, last;
  for (int i = 0; i < 400; ++i) {
    last = flight->step(overTheMiddle());
    if (i == 0) first = last;
    loads += last.tiles_loaded;
    ram_hits += last.total.ram_hits;
    ram_misses += last.total.ram_misses;
    uint64_t level_misses = 0;
    for (const LevelFrame& l : last.levels) level_misses += l.ram_misses;
    ASSERT_EQ(level_misses, last.total.ram_misses) << "frame " << i;
    if (i > 30 && flight->streamer().settled()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  const StreamerStats stats = flight->finish();
  // Before the first frame only the pyramid is on the GPU: the first frame's
  // hits are tiles that frame uploaded (a loader may finish a read between
  // the frame's update and its hand-off), never more.
  EXPECT_LE(first.total.gpu_hits, first.tiles_uploaded) << "nothing but the pyramid is on the GPU before the first frame";
  EXPECT_GT(first.total.gpu_misses, 0u);
  EXPECT_GT(last.total.gpu_hits, 0u);
  // Not every miss turns: a visible tile of a coarser needed level that a
  // finer level covers stays a miss (docs/renderer.md, GPU hits).
  EXPECT_GT(last.total.gpu_hits, last.total.gpu_misses)
      << "a still camera's tiles never reached the GPU (" << last.total.gpu_hits << " hits, "
      << last.total.gpu_misses << " misses)";
  EXPECT_LE(loads, stats.total.loads) << "a read after the last frame may still land";
  EXPECT_EQ(ram_misses, stats.total.ram_misses);
  EXPECT_EQ(ram_hits, stats.total.ram_hits);
  EXPECT_EQ(flight->preloadFailures(), 0u);
}

}  // namespace
}  // namespace clipstream
