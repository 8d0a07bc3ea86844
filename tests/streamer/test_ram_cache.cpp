// The RAM cache on its own (ram_cache.h): accounting under the budget, the
// order it gives tiles up in, and what it never evicts. No threads, no I/O.
#include "../../streamer/src/ram_cache.h"  // private: the cache under test

#include <gtest/gtest.h>

#include <memory>
#include <vector>

namespace clipstream {
namespace {

constexpr uint64_t kEntry = 100;

LayerTile tile(uint32_t level, uint32_t x, uint32_t y, uint32_t layer = 0) { return {layer, {level, x, y}}; }

// A ready tile in the cache (placeholder, then filled), its room made first.
bool put(RamCache& cache, const LayerTile& key, uint32_t rank = 1000, uint64_t frame = 0) {
  if (!cache.reserveRoom(rank, cache.entryBytes(key.layer))) return false;
  cache.insertPlaceholder(key);
  cache.fill(key, std::make_shared<std::vector<uint8_t>>(4, uint8_t(key.key.x)), frame);
  return true;
}

// One needed level 0 window over tiles [x0, x1) x [y0, y1).
PlanWindows windowAt(int64_t x0, int64_t y0, int64_t x1, int64_t y1) {
  PlanWindows w;
  w.rects = {TileRect{x0, y0, x1, y1}};
  w.kinds = {PlanWindows::kNeeded};
  w.finish();
  return w;
}

TEST(RamCache, ChargesEachLayerAndKeepsThePeak) {
  RamCache cache(1000, EvictionMode::kGpuFirst, {kEntry, 3 * kEntry});
  ASSERT_TRUE(put(cache, tile(0, 0, 0, 0)));
  ASSERT_TRUE(put(cache, tile(0, 0, 0, 1)));
  EXPECT_EQ(cache.bytes(), 4 * kEntry);
  EXPECT_EQ(cache.layerBytes(0), kEntry);
  EXPECT_EQ(cache.layerBytes(1), 3 * kEntry);
  EXPECT_EQ(cache.layerEntries(1), 1u);
  cache.erase(tile(0, 0, 0, 1));
  EXPECT_EQ(cache.bytes(), kEntry);
  EXPECT_EQ(cache.layerEntries(1), 0u);
  EXPECT_EQ(cache.peakBytes(), 4 * kEntry);
  cache.erase(tile(0, 9, 9));  // not held: nothing changes
  EXPECT_EQ(cache.bytes(), kEntry);
  EXPECT_TRUE(cache.fitsWithoutEviction(1));
}

TEST(RamCache, NeverEvictsAPlaceholder) {
  RamCache cache(2 * kEntry, EvictionMode::kGpuFirst, {kEntry});
  cache.insertPlaceholder(tile(0, 0, 0));
  cache.insertPlaceholder(tile(0, 1, 0));
  EXPECT_FALSE(cache.fitsWithoutEviction(0));
  EXPECT_FALSE(cache.reserveRoom(0, kEntry));  // both are still being read
  EXPECT_EQ(cache.size(), 2u);
  cache.fill(tile(0, 1, 0), nullptr, 0);  // now ready, and wanted by nobody
  EXPECT_FALSE(cache.reserveRoom(0, kEntry));  // not a candidate before the order is rebuilt
  cache.invalidateOrder();
  EXPECT_TRUE(cache.reserveRoom(0, kEntry));
  EXPECT_EQ(cache.size(), 1u);
  EXPECT_TRUE(cache.contains(tile(0, 0, 0)));
}

TEST(RamCache, EvictsTheFarthestUnwantedTileFirst) {
  std::vector<LayerTile> evicted;
  RamCache cache(3 * kEntry, EvictionMode::kGpuFirst, {kEntry},
                 [&](const LayerTile& k) { evicted.push_back(k); });
  cache.setWindows(0, windowAt(0, 0, 4, 4), {}, nullptr);
  ASSERT_TRUE(put(cache, tile(0, 5, 0)));   // one tile outside the window
  ASSERT_TRUE(put(cache, tile(0, 40, 0)));  // far outside
  ASSERT_TRUE(put(cache, tile(0, 8, 0)));
  ASSERT_TRUE(put(cache, tile(0, 1, 1)));   // room for it: the farthest goes
  ASSERT_EQ(evicted.size(), 1u);
  EXPECT_EQ(evicted[0], tile(0, 40, 0));
  ASSERT_TRUE(put(cache, tile(0, 2, 2)));
  ASSERT_EQ(evicted.size(), 2u);
  EXPECT_EQ(evicted[1], tile(0, 8, 0));
  EXPECT_EQ(cache.bytes(), 3 * kEntry);
}

TEST(RamCache, AWantedTileGoesOnlyForABetterRankedNewcomerWorstRankFirst) {
  RamCache cache(2 * kEntry, EvictionMode::kGpuFirst, {kEntry});
  cache.setWindows(0, windowAt(0, 0, 4, 4), {}, nullptr);
  RamCache::Ranks ranks{{tile(0, 0, 0), 3}, {tile(0, 1, 0), 7}};
  cache.setRanks(ranks);
  ASSERT_TRUE(put(cache, tile(0, 0, 0), 3));
  ASSERT_TRUE(put(cache, tile(0, 1, 0), 7));
  // A newcomer ranked below both takes nothing: the budget keeps the better.
  EXPECT_FALSE(cache.reserveRoom(9, kEntry));
  EXPECT_EQ(cache.size(), 2u);
  cache.invalidateOrder();
  // Ranked between them: the worse-ranked (7) goes, the better (3) stays.
  EXPECT_TRUE(cache.reserveRoom(5, kEntry));
  EXPECT_TRUE(cache.contains(tile(0, 0, 0)));
  EXPECT_FALSE(cache.contains(tile(0, 1, 0)));
}

TEST(RamCache, AWantedPyramidTileOnTheGpuIsAVictimUnderGpuFirstOnly) {
  for (EvictionMode mode : {EvictionMode::kGpuFirst, EvictionMode::kProtectGpu}) {
    SCOPED_TRACE(mode == EvictionMode::kGpuFirst ? "gpu-first" : "protect-gpu");
    RamCache cache(1 * kEntry, mode, {kEntry});
    PlanWindows pyramid = windowAt(0, 0, 1, 1);
    pyramid.kinds[0] = PlanWindows::kPyramid;
    pyramid.finish();
    cache.setWindows(0, pyramid, {}, nullptr);
    cache.setRanks({{tile(0, 0, 0), 0}});
    ASSERT_TRUE(put(cache, tile(0, 0, 0), 0));
    cache.find(tile(0, 0, 0))->gpu = true;  // handed to the renderer
    cache.invalidateOrder();
    // A newcomer ranked below it: only a RAM copy the GPU already serves may go.
    EXPECT_EQ(cache.reserveRoom(5, kEntry), mode == EvictionMode::kGpuFirst);
  }
}

TEST(RamCache, FillKeepsTheFrameItWasLastWanted) {
  RamCache cache(kEntry, EvictionMode::kGpuFirst, {kEntry});
  cache.insertPlaceholder(tile(2, 1, 1));
  EXPECT_EQ(cache.find(tile(2, 1, 1))->state, EntryState::kLoading);
  cache.fill(tile(2, 1, 1), std::make_shared<std::vector<uint8_t>>(3, 7), 42);
  const CacheEntry* e = cache.find(tile(2, 1, 1));
  ASSERT_NE(e, nullptr);
  EXPECT_EQ(e->state, EntryState::kReady);
  EXPECT_EQ(e->last_wanted_frame, 42u);
  EXPECT_EQ(e->rgba->size(), 3u);
  EXPECT_EQ(cache.find(tile(2, 0, 0)), nullptr);
}

}  // namespace
}  // namespace clipstream
