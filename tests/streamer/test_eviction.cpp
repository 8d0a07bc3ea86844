// RAM-cache eviction: which tiles the policy gives up first, in the trace
// replay and in the streamer itself (eviction.h).
#include "test_helpers.h"
#include "../../streamer/src/eviction.h"  // private: the victim order under test

#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

namespace clipstream {
namespace {

using test::lookingDown;
using test::procedural;
using test::waitIdle;

TraceEvent windowLine(uint64_t frame, uint32_t level, TileRect rect, uint8_t kind) {
  TraceEvent e;
  e.frame = frame;
  e.window = 'w';
  e.key.level = level;
  e.rect = rect;
  e.kind = kind;
  return e;
}

TraceEvent tileLine(uint64_t frame, TileKey key, bool leave) {
  TraceEvent e;
  e.frame = frame;
  e.key = key;
  e.leave = leave;
  return e;
}

// Room for two tiles: the pyramid's single tile P and level 0's one-tile
// window. The window steps east and back, so tile A leaves and returns.
// P is on the GPU and never leaves its window: GPU-first gives it up for
// the newcomer and keeps A (as OPT does); protect-GPU keeps P and loses A.
TEST(Eviction, PyramidTilesOnTheGpuGoBeforeATileThatWillReturn) {
  const TileKey p{1, 0, 0}, a{0, 0, 0}, b{0, 1, 0};
  const std::vector<TraceEvent> ev = {
      windowLine(1, 0, {0, 0, 1, 1}, 1), windowLine(1, 1, {0, 0, 1, 1}, 2),
      tileLine(1, p, false),             tileLine(1, a, false),
      windowLine(2, 0, {1, 0, 2, 1}, 1), windowLine(2, 1, {0, 0, 1, 1}, 2),
      tileLine(2, b, false),             tileLine(2, a, true),
      windowLine(3, 0, {0, 0, 1, 1}, 1), windowLine(3, 1, {0, 0, 1, 1}, 2),
      tileLine(3, a, false),             tileLine(3, b, true)};
  const ReplayResult r = replayTrace(ev, 2);
  EXPECT_EQ(r.accesses, 4u);
  EXPECT_EQ(r.hits_opt, 1u);
  EXPECT_EQ(r.hits_gpu_first, 1u);
  EXPECT_EQ(r.hits_plan, 0u);

  // The score behind it: pyramid first, then inside tiles, then outside.
  PlanWindows w;
  w.rects = {TileRect{1, 0, 4, 1}, TileRect{0, 0, 1, 1}};
  w.kinds = {PlanWindows::kNeeded, PlanWindows::kPyramid};
  w.finish();
  const PlanWindows none;
  const double pyramid = evictionScore(p, w, none, EvictionMode::kGpuFirst);
  const double inside = evictionScore({0, 2, 0}, w, none, EvictionMode::kGpuFirst);
  const double outside = evictionScore(a, w, none, EvictionMode::kGpuFirst);
  EXPECT_GT(pyramid, inside);
  EXPECT_GT(inside, outside);
  EXPECT_LT(pyramid, kNoPlanScore);
  EXPECT_TRUE(scoredOnGpu(p, w, EvictionMode::kGpuFirst));
  EXPECT_FALSE(scoredOnGpu(p, w, EvictionMode::kProtectGpu));
  EXPECT_TRUE(scoredOnGpu(a, w, EvictionMode::kProtectGpu));
}

// Budget = exactly the wanted set, everything handed to the GPU, then one
// step east: the tiles that enter need room. GPU-first takes it from the
// pyramid (on the GPU, never leaving) and keeps the column that left;
// protect-GPU never touches the pyramid. The budget holds either way and
// the pyramid stays on the GPU, so MaxTextureLOD does not move.
struct StepResult {
  uint64_t entered = 0;
  uint64_t pyramid_evictions = 0;
  uint64_t stack_evictions = 0;
  uint64_t left_column_rereads = 0;
};

StepResult stepEastAndBack(EvictionMode mode) {
  StepResult out;
  const Viewport vp{800, 600};
  const Camera a = lookingDown(4032.0, 4032.0, 60.0), east = lookingDown(4160.0, 4032.0, 60.0);
  StreamerConfig cfg;
  cfg.io_threads = 1;
  cfg.prefetch = false;
  cfg.planner.clip_tiles = 8;
  cfg.eviction = mode;
  cfg.lod_hysteresis_frames = 1;
  auto base = procedural(8192);
  const size_t wanted = rankPlanTiles(base->geometry(), planClipmap(base->geometry(), vp, a, cfg.planner)).size();
  cfg.ram_budget_bytes = wanted * (128 * 128 * 4 + kCacheEntryOverheadBytes);
  auto rec = std::make_shared<test::RecordingSource>(base);
  Streamer s(rec, cfg);
  s.update(a, vp, 0.0);
  EXPECT_TRUE(waitIdle(s));
  EXPECT_EQ(s.takeReady(100000).tiles.size(), wanted);
  const uint32_t lod_before = s.takeReady(0).max_texture_lod;
  const uint32_t pyramid_level = s.plan().pyramid_level;
  const int64_t left_x = s.plan().stack[0].window.x0;
  const size_t before_step = rec->keys().size();
  s.update(east, vp, 0.1);
  EXPECT_TRUE(waitIdle(s));
  (void)s.takeReady(100000);
  out.entered = rec->keys().size() - before_step;
  EXPECT_EQ(s.takeReady(0).max_texture_lod, lod_before);
  const size_t before_back = rec->keys().size();
  s.update(a, vp, 0.2);
  EXPECT_TRUE(waitIdle(s));
  const std::vector<TileKey> keys = rec->keys();
  for (size_t i = before_back; i < keys.size(); ++i)
    out.left_column_rereads += keys[i].level == 0 && keys[i].x == left_x;
  const StreamerStats st = s.stats();
  for (const LevelCounters& c : st.levels) {
    (&c - st.levels.data() >= pyramid_level ? out.pyramid_evictions : out.stack_evictions) += c.evictions;
  }
  EXPECT_LE(st.ram_peak_bytes, st.ram_budget_bytes);
  return out;
}

TEST(Eviction, StreamerGivesUpPyramidTilesOnTheGpuFirst) {
  const StepResult gpu_first = stepEastAndBack(EvictionMode::kGpuFirst);
  ASSERT_GT(gpu_first.entered, 0u);
  EXPECT_EQ(gpu_first.pyramid_evictions, gpu_first.entered);  // room came from the pyramid
  EXPECT_EQ(gpu_first.stack_evictions, 0u);
  EXPECT_EQ(gpu_first.left_column_rereads, 0u);  // the column that left was kept

  const StepResult protect = stepEastAndBack(EvictionMode::kProtectGpu);
  EXPECT_EQ(protect.pyramid_evictions, 0u);
  EXPECT_GT(protect.stack_evictions, 0u);
}

}  // namespace
}  // namespace clipstream
