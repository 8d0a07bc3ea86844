// The steps of the trace replay (trace_replay.h), each alone: the tiles
// numbered, the GPU residency that decides which entries are accesses, and
// the per-policy replays. replayTrace() as a whole is in test_trace.cpp.
#include "../../streamer/src/trace_replay.h"  // private: the steps under test

#include <gtest/gtest.h>

#include <vector>

namespace clipstream {
namespace {

TraceEvent entry(uint64_t frame, TileKey key) { return {frame, key, false}; }
TraceEvent leave(uint64_t frame, TileKey key) { return {frame, key, true}; }

TraceEvent windowLine(uint64_t frame, uint32_t level, TileRect rect, uint8_t kind) {
  TraceEvent e;
  e.frame = frame;
  e.window = kTraceWindowTag;
  e.key.level = level;
  e.rect = rect;
  e.kind = kind;
  return e;
}

TraceEvent timeLine(uint64_t frame) {
  TraceEvent e;
  e.frame = frame;
  e.window = kTraceTimeTag;
  e.time_s = 0.25;
  e.viewport = {64, 64};
  return e;
}

// One entry a frame of each key in turn, no window lines: every entry is
// an access.
std::vector<TraceEvent> entries(const std::vector<TileKey>& keys) {
  std::vector<TraceEvent> events;
  for (size_t i = 0; i < keys.size(); ++i) events.push_back(entry(i + 1, keys[i]));
  return events;
}

const TileKey kA{0, 0, 0}, kB{0, 1, 0}, kC{0, 2, 0};

TEST(TraceReplay, TilesAreNumberedInOrderOfFirstAppearance) {
  const std::vector<TraceEvent> events = {timeLine(1), windowLine(1, 0, {0, 0, 4, 4}, 1),
                                          entry(1, kC), entry(1, kA), leave(2, kC), entry(2, kB),
                                          entry(3, kC)};
  const TraceTiles tiles = numberTraceTiles(events);
  EXPECT_EQ(tiles.key_of, (std::vector<TileKey>{kC, kA, kB}));
  // Window and time events get 0; a leave and a later entry keep the id.
  EXPECT_EQ(tiles.id_of, (std::vector<uint32_t>{0, 0, 0, 1, 0, 2, 0}));
}

TEST(TraceReplay, AnEntryBackInItsNeededWindowIsServedByTheGpu) {
  const TileRect near{0, 0, 4, 4}, far{8, 0, 12, 4};
  const TileKey t{0, 1, 1};
  const std::vector<TraceEvent> events = {
      windowLine(1, 0, near, 1), entry(1, t),  // handed to the GPU
      leave(2, t),                             // leaves the wanted set, not its window
      entry(3, t),                             // the GPU still holds it
      windowLine(4, 0, far, 1), leave(4, t),   // leaves with its window gone
      windowLine(5, 0, far, 1), entry(5, t)};  // read again
  const TraceTiles tiles = numberTraceTiles(events);
  ReplayResult result;
  const std::vector<uint8_t> access = markAccesses(events, tiles, &result);
  EXPECT_EQ(access, (std::vector<uint8_t>{0, 1, 0, 0, 0, 0, 0, 1}));
  EXPECT_EQ(result.accesses, 2u);
  EXPECT_EQ(result.gpu_reentries, 1u);

  // Step by step: the tile is off the GPU only once the plan change that
  // took its window away has closed (at frame 5's first line).
  GpuResidency gpu(events, tiles);
  EXPECT_FALSE(gpu.step(0));
  EXPECT_FALSE(gpu.onGpu(0));
  for (size_t i = 1; i < 6; ++i) {
    EXPECT_EQ(gpu.step(i), i == 3) << i;
    EXPECT_TRUE(gpu.onGpu(0)) << i;
  }
  EXPECT_FALSE(gpu.step(6));
  EXPECT_FALSE(gpu.onGpu(0));
  EXPECT_FALSE(gpu.step(7));
  EXPECT_TRUE(gpu.onGpu(0));  // handed over again at its access
}

TEST(TraceReplay, OptAndLruCountHitsOverTheAccessesOnly) {
  // A B A C A B with room for two: LRU evicts B for C and misses it at the
  // end (hits: A, A); OPT lets C bypass (used never again) and hits A, A, B.
  const std::vector<TraceEvent> events = entries({kA, kB, kA, kC, kA, kB});
  const TraceTiles tiles = numberTraceTiles(events);
  ReplayResult result;
  const std::vector<uint8_t> access = markAccesses(events, tiles, &result);
  ASSERT_EQ(result.accesses, 6u);
  EXPECT_EQ(replayLru(tiles, access, 2), 2u);
  EXPECT_EQ(replayOpt(tiles, access, 2), 3u);
  // Room for all: every repeat hits.
  EXPECT_EQ(replayLru(tiles, access, 3), 3u);
  EXPECT_EQ(replayOpt(tiles, access, 3), 3u);
  // Events not marked as accesses are not seen: without the second A the
  // accesses are A B C A B, where LRU always evicts the tile needed next
  // and OPT lets C bypass (A and B hit).
  std::vector<uint8_t> fewer = access;
  fewer[2] = 0;
  EXPECT_EQ(replayLru(tiles, fewer, 2), 0u);
  EXPECT_EQ(replayOpt(tiles, fewer, 2), 2u);
}

TEST(TraceReplay, ProtectGpuNeverEvictsAPyramidTileGpuFirstDoes) {
  // A pyramid tile P, then a stack tile S outside every window that leaves
  // and comes back (off the GPU by then: an access), with room for one.
  const TileKey p{1, 0, 0}, s{0, 5, 5};
  const std::vector<TraceEvent> events = {
      windowLine(1, 0, {0, 0, 4, 4}, 1), windowLine(1, 1, {0, 0, 1, 1}, 2),
      entry(1, p), entry(1, s), leave(2, s), entry(3, s)};
  const TraceTiles tiles = numberTraceTiles(events);
  ReplayResult result;
  const std::vector<uint8_t> access = markAccesses(events, tiles, &result);
  ASSERT_EQ(result.accesses, 3u);
  // kProtectGpu: P is no candidate, so S bypasses the cache both times.
  EXPECT_EQ(replayPlanAware(events, tiles, access, 1, EvictionMode::kProtectGpu, nullptr), 0u);
  // kGpuFirst: P (on the GPU) goes first; S stays and hits when it returns.
  EXPECT_EQ(replayPlanAware(events, tiles, access, 1, EvictionMode::kGpuFirst, nullptr), 1u);
  // With room for both, both modes hit S.
  EXPECT_EQ(replayPlanAware(events, tiles, access, 2, EvictionMode::kProtectGpu, nullptr), 1u);
  EXPECT_EQ(replayPlanAware(events, tiles, access, 2, EvictionMode::kGpuFirst, nullptr), 1u);
}

}  // namespace
}  // namespace clipstream
