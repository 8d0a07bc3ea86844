// RAM-cache eviction: which tiles the policy gives up first, in the trace
// replay and in the streamer itself (eviction.h).
#include "streamer_test_util.h"
#include "../../streamer/src/eviction.h"  // private: the victim order under test

#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>

#include <gtest/gtest.h>

#include <memory>
#include <vector>

namespace clipstream {
namespace {

using test::expectCountersAddUp;
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
  const double pyramid = evictionScore(p, w, none, EvictionMode::kGpuFirst, true);
  const double inside = evictionScore({0, 2, 0}, w, none, EvictionMode::kGpuFirst, true);
  const double outside = evictionScore(a, w, none, EvictionMode::kGpuFirst, true);
  const double inside_off_gpu = evictionScore({0, 2, 0}, w, none, EvictionMode::kGpuFirst, false);
  EXPECT_GT(pyramid, inside);
  EXPECT_GT(inside, outside);
  EXPECT_GT(outside, inside_off_gpu);
  // The predicted plan one tile east of the current: outside both, a tile
  // the window moves away from (west) is scored past either distance, one
  // it moves towards (east) nearer than either, at twice the prediction's
  // horizon; inside the predicted window the smaller score still wins.
  PlanWindows east = w;
  east.rects[0] = TileRect{2, 0, 5, 1};
  east.finish();
  const TileKey behind{0, 0, 0}, ahead{0, 8, 0};  // 1 and 5 tiles out of w; 2 and 4 of east
  EXPECT_EQ(evictionScore(behind, w, none, EvictionMode::kGpuFirst, true), 1.0);
  EXPECT_EQ(evictionScore(behind, w, east, EvictionMode::kGpuFirst, true), 3.0);  // 2 x 2 - 1
  EXPECT_EQ(evictionScore(ahead, w, none, EvictionMode::kGpuFirst, true), 5.0);
  EXPECT_EQ(evictionScore(ahead, w, east, EvictionMode::kGpuFirst, true), 3.0);   // 2 x 4 - 5
  // (4, 0): out of w, in east and off the GPU: kept like an inside tile.
  EXPECT_LT(evictionScore({0, 4, 0}, w, east, EvictionMode::kGpuFirst, false), 1.0);
  EXPECT_LT(pyramid, kNoPlanScore);
  EXPECT_TRUE(scoredOnGpu(p, w, EvictionMode::kGpuFirst));
  EXPECT_FALSE(scoredOnGpu(p, w, EvictionMode::kProtectGpu));
  EXPECT_TRUE(scoredOnGpu(a, w, EvictionMode::kProtectGpu));
}

// With the sampled scope a window can come back over a tile that no frame
// samples yet: the tile is in RAM but no longer on the GPU, so the next
// frame that samples it reads that copy. Room for two: A leaves with its
// window, the window comes back over it while C (outside now) is cached and
// D needs room. C goes, A stays and hits when it is sampled again (as with
// OPT); evicting A first, as tiles inside a window on the GPU are, would
// read it again, and LRU does.
TEST(Eviction, ATileInsideItsWindowButOffTheGpuIsKept) {
  const TileKey a{0, 0, 0}, c{0, 5, 0}, d{0, 1, 0};
  const std::vector<TraceEvent> ev = {
      windowLine(1, 0, {0, 0, 1, 1}, 1), tileLine(1, a, false),
      windowLine(2, 0, {5, 0, 6, 1}, 1), tileLine(2, a, true),  tileLine(2, c, false),
      windowLine(3, 0, {0, 0, 2, 1}, 1), tileLine(3, c, true),  tileLine(3, d, false),
      windowLine(4, 0, {0, 0, 2, 1}, 1), tileLine(4, a, false)};
  const ReplayResult r = replayTrace(ev, 2);
  EXPECT_EQ(r.accesses, 4u);
  EXPECT_EQ(r.gpu_reentries, 0u);  // A left its window: the GPU dropped it
  EXPECT_EQ(r.hits_opt, 1u);
  EXPECT_EQ(r.hits_gpu_first, 1u);
  EXPECT_EQ(r.hits_lru, 0u);
}

// Budget = exactly the wanted set, everything handed to the GPU, then one
// step east (only level 0's window moves) and back: the tiles that enter
// need room. GPU-first takes it from tiles already on the GPU that the plan
// still wants (the pyramid first, never leaving), so the column that left is
// still in RAM when it re-enters; protect-GPU never touches the pyramid,
// evicts that column and reads it again. The budget holds either way and
// the pyramid stays on the GPU, so MaxTextureLOD does not move.
struct StepResult {
  bool window_moved = false;          // level 0's window moved one tile east
  uint64_t entered = 0;               // tiles read for the step east
  uint64_t pyramid_evictions = 0;
  uint64_t stack_evictions = 0;
  uint64_t left_column_rereads = 0;   // reads, on the way back, of the column that left
  uint64_t reads_back = 0;            // all reads on the way back
  uint64_t level0_ram_hits = 0;
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
  cfg.planner.scope = PlanScope::kWindow;  // whole columns enter and leave
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
  out.window_moved = s.plan().stack[0].window.x0 == left_x + 1;
  EXPECT_TRUE(waitIdle(s));
  (void)s.takeReady(100000);
  out.entered = rec->keys().size() - before_step;
  EXPECT_EQ(s.takeReady(0).max_texture_lod, lod_before);
  const size_t before_back = rec->keys().size();
  s.update(a, vp, 0.2);
  EXPECT_TRUE(waitIdle(s));
  const std::vector<TileKey> keys = rec->keys();
  out.reads_back = keys.size() - before_back;
  for (size_t i = before_back; i < keys.size(); ++i)
    out.left_column_rereads += keys[i].level == 0 && keys[i].x == left_x;
  const StreamerStats st = s.stats();
  for (const LevelCounters& c : st.levels) {
    (&c - st.levels.data() >= pyramid_level ? out.pyramid_evictions : out.stack_evictions) += c.evictions;
  }
  out.level0_ram_hits = st.levels[0].ram_hits;
  expectCountersAddUp(st);
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

TEST(Streamer, GpuFirstEvictionKeepsTheTilesThatJustLeft) {
  const StepResult r = stepEastAndBack(EvictionMode::kGpuFirst);
  ASSERT_TRUE(r.window_moved);
  EXPECT_EQ(r.left_column_rereads, 0u);
  EXPECT_EQ(r.reads_back, 0u);
  EXPECT_EQ(r.level0_ram_hits, 8u);
}

TEST(Streamer, ProtectGpuEvictionKeepsWindowTilesAndRereadsTheLeftColumn) {
  const StepResult r = stepEastAndBack(EvictionMode::kProtectGpu);
  ASSERT_TRUE(r.window_moved);
  EXPECT_EQ(r.left_column_rereads, 8u);
  EXPECT_EQ(r.reads_back, 8u);
  EXPECT_EQ(r.level0_ram_hits, 0u);
}

TEST(Trace, EvictionModesDifferOnTilesInsideTheWindow) {
  // Level 0 window slides right one tile and back; the tile that left (A)
  // re-enters. GPU-first keeps A (an in-window tile goes instead); protect
  // keeps the in-window tiles and loses A.
  auto window = [](uint64_t frame, int64_t x0) {
    TraceEvent e;
    e.frame = frame;
    e.window = 'w';
    e.key.level = 0;
    e.rect = {x0, 0, x0 + 3, 1};
    e.kind = 1;
    return e;
  };
  auto tile = [](uint64_t frame, uint32_t x, bool leave) {
    TraceEvent e;
    e.frame = frame;
    e.key = {0, x, 0};
    e.leave = leave;
    return e;
  };
  const std::vector<TraceEvent> ev = {window(1, 0),    tile(1, 0, false), tile(1, 1, false),
                                      tile(1, 2, false), window(2, 1),    tile(2, 3, false),
                                      tile(2, 0, true),  window(3, 0),    tile(3, 0, false),
                                      tile(3, 3, true)};
  const ReplayResult r = replayTrace(ev, 3);
  EXPECT_EQ(r.accesses, 5u);
  EXPECT_EQ(r.hits_opt, 1u);
  EXPECT_EQ(r.hits_gpu_first, 1u);
  EXPECT_EQ(r.hits_plan, 0u);
  EXPECT_EQ(r.hits_lru, 0u);
}

TEST(Trace, EqualScoresEvictTheMostRecentlyWantedTileFirst) {
  // Window fixed on tile 10. A (x 8) and B (x 12) are both two tiles out:
  // equal scores. When C arrives in a full cache, the most recently wanted
  // of the tie (B) goes, so the subset kept is stable and A hits when it
  // comes back. Least-recently-wanted ties would evict A and miss.
  TraceEvent w;
  w.frame = 1;
  w.window = 'w';
  w.key.level = 0;
  w.rect = {10, 0, 11, 1};
  w.kind = 1;
  auto tile = [](uint64_t frame, uint32_t x, bool leave) {
    TraceEvent e;
    e.frame = frame;
    e.key = {0, x, 0};
    e.leave = leave;
    return e;
  };
  const std::vector<TraceEvent> ev = {w,  tile(1, 8, false),  tile(1, 8, true),
                                      tile(2, 12, false), tile(2, 12, true),
                                      tile(3, 14, false), tile(3, 14, true),
                                      tile(4, 8, false)};
  const ReplayResult r = replayTrace(ev, 2);
  EXPECT_EQ(r.accesses, 4u);
  EXPECT_EQ(r.hits_gpu_first, 1u);
  EXPECT_EQ(r.hits_plan, 1u);
  EXPECT_EQ(r.hits_lru, 0u);
  // The streamer sorts with the same rule.
  EXPECT_TRUE(evictsBefore(2.0, 7, 2.0, 3));
  EXPECT_FALSE(evictsBefore(2.0, 3, 2.0, 7));
  EXPECT_TRUE(evictsBefore(3.0, 3, 2.0, 7));
  // Without a plan, recency is all there is: least recently wanted first.
  EXPECT_TRUE(evictsBefore(kNoPlanScore, 3, kNoPlanScore, 7));
}

}  // namespace
}  // namespace clipstream
