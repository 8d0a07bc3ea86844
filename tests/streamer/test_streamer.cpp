// The streamer: load order, cancellation, prefetch, the hard RAM budget,
// failures, shutdown, hand-off limits, MaxTextureLOD hysteresis, stats.
#include "test_helpers.h"
#include "../../streamer/src/eviction.h"  // private: the victim order under test

#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <atomic>
#include <cmath>
#include <fstream>
#include <random>
#include <unordered_set>

namespace clipstream {
namespace {

using KeySet = std::unordered_set<TileKey, TileKeyHash>;
using test::kPi;
using test::lookingDown;
using test::procedural;
using test::waitIdle;

void expectCountersAddUp(const StreamerStats& st) {
  LevelCounters sum;
  for (const LevelCounters& c : st.levels) {
    sum.requests += c.requests;
    sum.loads += c.loads;
    sum.failures += c.failures;
    sum.cancellations += c.cancellations;
    sum.budget_skips += c.budget_skips;
    sum.gpu_handoffs += c.gpu_handoffs;
    sum.evictions += c.evictions;
  }
  EXPECT_EQ(sum.requests, st.total.requests);
  EXPECT_EQ(sum.loads, st.total.loads);
  EXPECT_EQ(sum.gpu_handoffs, st.total.gpu_handoffs);
  EXPECT_EQ(sum.evictions, st.total.evictions);
  EXPECT_EQ(st.total.requests, st.total.loads + st.total.failures + st.total.cancellations +
                                   st.total.budget_skips + st.queue_depth + st.in_flight);
  EXPECT_LE(st.ram_bytes, st.ram_budget_bytes);
  EXPECT_LE(st.ram_peak_bytes, st.ram_budget_bytes);
}

StreamerConfig baseConfig(unsigned threads, uint32_t clip_tiles) {
  StreamerConfig cfg;
  cfg.io_threads = threads;
  cfg.prefetch = false;
  cfg.planner.clip_tiles = clip_tiles;
  return cfg;
}

TEST(Streamer, LoadsInPlanRankOrderPyramidFirstThenCoarseToFine) {
  auto rec = std::make_shared<test::RecordingSource>(
      makeFaultySource(procedural(8192), FaultSpec{1.0, 0.0, ErrorCode::kCorruptTile, 7}));
  Streamer s(rec, baseConfig(1, 8));
  const Viewport vp{800, 600};
  Camera cam = lookingDown(4000.0, 4000.0, 60.0);
  cam.pitch_rad = -1.0;
  s.update(cam, vp, 0.0);
  ASSERT_TRUE(waitIdle(s));
  const std::vector<TileKey> ranked = rankPlanTiles(s.geometry(), s.plan());
  const std::vector<TileKey> fetched = rec->keys();
  ASSERT_EQ(fetched.size(), ranked.size());
  for (size_t i = 0; i < ranked.size(); ++i) {
    ASSERT_EQ(fetched[i], ranked[i]) << "fetch " << i;
  }
  EXPECT_GE(fetched.front().level, s.plan().pyramid_level);
  EXPECT_EQ(fetched.back().level, s.plan().finest_level);
  expectCountersAddUp(s.stats());
}

TEST(Streamer, CancelsQueuedRequestsTheNewPlanNoLongerNeeds) {
  auto rec = std::make_shared<test::RecordingSource>(
      makeFaultySource(procedural(8192), FaultSpec{4.0, 0.0, ErrorCode::kCorruptTile, 7}));
  Streamer s(rec, baseConfig(1, 8));
  const Viewport vp{800, 600};
  s.update(lookingDown(500.0, 500.0, 20.0), vp, 0.0);
  while (rec->keys().size() < 3) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  s.update(lookingDown(7600.0, 7600.0, 20.0), vp, 0.1);
  const size_t at_teleport = rec->keys().size();
  const std::vector<TileKey> ranked = rankPlanTiles(s.geometry(), s.plan());
  const KeySet wanted(ranked.begin(), ranked.end());
  ASSERT_TRUE(waitIdle(s));
  const std::vector<TileKey> fetched = rec->keys();
  // One fetch may have been popped just before the teleport and recorded after it.
  for (size_t i = at_teleport + 1; i < fetched.size(); ++i)
    EXPECT_TRUE(wanted.count(fetched[i])) << "stale tile fetched after the plan moved: level "
                                          << fetched[i].level << " (" << fetched[i].x << ", "
                                          << fetched[i].y << ")";
  const StreamerStats st = s.stats();
  EXPECT_GT(st.total.cancellations, 50u);
  EXPECT_EQ(st.total.loads, fetched.size());
  expectCountersAddUp(st);
}

TEST(Streamer, PrefetchQueuesTheTilesAheadOfTheMotion) {
  auto slow = makeFaultySource(procedural(1 << 20), FaultSpec{20.0, 0.0, ErrorCode::kCorruptTile, 7});
  StreamerConfig cfg = baseConfig(1, 8);
  cfg.prefetch = true;
  Streamer s(slow, cfg);
  const Viewport vp{800, 600};
  // Moving east at 2000 texels/s: 0.5 s ahead is 1000 texels (8 level-0 tiles).
  for (int i = 0; i <= 3; ++i) s.update(lookingDown(300000.0 + 200.0 * i, 400000.0, 25.0), vp, 0.1 * i);
  const std::vector<TileKey> ranked = rankPlanTiles(s.geometry(), s.plan());
  const KeySet wanted(ranked.begin(), ranked.end());
  const std::vector<TileKey> queued = s.queuedTiles();
  size_t prefetched = 0, prefetched_level0 = 0;
  bool seen_prefetch = false;
  for (const TileKey& k : queued) {
    if (wanted.count(k)) {
      EXPECT_FALSE(seen_prefetch) << "prefetch must come after every wanted tile";
      continue;
    }
    seen_prefetch = true;
    ++prefetched;
    prefetched_level0 += k.level == 0;
    ASSERT_LT(k.level, s.plan().pyramid_level);
    const ClipLevelPlan& lp = s.plan().stack[k.level];
    EXPECT_GE(int64_t(k.x), lp.window.x1) << "prefetched tile is not east of the window, level "
                                          << k.level;
    EXPECT_GE(int64_t(k.y), lp.window.y0);
    EXPECT_LT(int64_t(k.y), lp.window.y1);
  }
  EXPECT_GE(prefetched_level0, 8u * 7u);  // about 8 columns of the 8-tile window
  EXPECT_GT(prefetched, prefetched_level0);
  s.shutdown();

  // Without prefetch nothing outside the plan is queued.
  cfg.prefetch = false;
  Streamer plain(slow, cfg);
  for (int i = 0; i <= 3; ++i) plain.update(lookingDown(300000.0 + 200.0 * i, 400000.0, 25.0), vp, 0.1 * i);
  const std::vector<TileKey> ranked2 = rankPlanTiles(plain.geometry(), plain.plan());
  const KeySet wanted2(ranked2.begin(), ranked2.end());
  for (const TileKey& k : plain.queuedTiles()) EXPECT_TRUE(wanted2.count(k));
}

TEST(Streamer, RamBudgetIsNeverExceededUnderRandomLoad) {
  constexpr uint32_t kTilePx = 32;
  const uint64_t entry = uint64_t(kTilePx) * kTilePx * 4 + kCacheEntryOverheadBytes;
  StreamerConfig cfg = baseConfig(4, 8);
  cfg.prefetch = true;
  cfg.ram_budget_bytes = 200 * entry + entry / 2;  // not a multiple: the check is on bytes
  std::atomic<uint64_t> inserts{0}, violations{0};
  const uint64_t budget = cfg.ram_budget_bytes;
  cfg.on_ram_insert = [&](uint64_t ram_bytes, uint64_t budget_bytes) {
    inserts++;
    if (ram_bytes > budget || budget_bytes != budget) violations++;
  };
  Streamer s(procedural(1 << 18, kTilePx), cfg);
  std::atomic<bool> stop{false};
  std::thread reader([&] {
    while (!stop.load()) {
      const StreamerStats st = s.stats();
      if (st.ram_bytes > st.ram_budget_bytes) violations++;
      std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
  });
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> pos(0.0, double(1 << 18));
  std::uniform_real_distribution<double> height(3.0, 3000.0);
  std::uniform_real_distribution<double> angle(-kPi, kPi);
  const Viewport vp{320, 240};
  double t = 0.0;
  for (int frame = 0; frame < 150; ++frame) {
    Camera c = lookingDown(pos(rng), pos(rng), height(rng));
    c.heading_rad = angle(rng);
    c.pitch_rad = -0.3 - 0.4 * std::abs(angle(rng)) / kPi;
    s.update(c, vp, t += 1.0 / 60.0);
    (void)s.takeReady(16);
    if (frame % 8 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_TRUE(waitIdle(s));
  stop = true;
  reader.join();
  const StreamerStats st = s.stats();
  EXPECT_EQ(violations.load(), 0u);
  EXPECT_GE(inserts.load(), 1000u);
  EXPECT_EQ(inserts.load(), st.total.loads + st.total.failures);
  EXPECT_GT(st.total.evictions, 0u);
  EXPECT_EQ(st.ram_bytes, st.ram_entries * entry);
  expectCountersAddUp(st);
}

TEST(Streamer, SlowAndFailingSourcesNeverRunOnTheRenderThreadAndFailOnce) {
  FaultSpec fault{50.0, 0.3, ErrorCode::kCorruptTile, 11};
  auto rec = std::make_shared<test::RecordingSource>(makeFaultySource(procedural(1024), fault));
  StreamerConfig cfg = baseConfig(4, 0);
  Streamer s(rec, cfg);
  const Viewport vp{1280, 720};
  const Camera cam = lookingDown(512.0, 512.0, 100.0);
  double t = 0.0;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (!s.settled() && std::chrono::steady_clock::now() < deadline) {
    s.update(cam, vp, t += 0.016);
    (void)s.takeReady(8);
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_TRUE(s.settled());
  const std::vector<TileKey> ranked = rankPlanTiles(s.geometry(), s.plan());
  size_t expected_failures = 0;
  for (const TileKey& k : ranked) expected_failures += failsTile(fault, k);
  ASSERT_GT(expected_failures, 0u);
  const size_t fetches = rec->keys().size();
  EXPECT_EQ(fetches, ranked.size());
  EXPECT_EQ(s.stats().total.failures, expected_failures);
  for (int i = 0; i < 20; ++i) {
    s.update(cam, vp, t += 0.016);
    (void)s.takeReady(8);
  }
  ASSERT_TRUE(waitIdle(s));
  EXPECT_EQ(rec->keys().size(), fetches) << "failed tiles were retried";
  // Tiles that failed for good do not hold MaxTextureLOD back.
  EXPECT_EQ(s.takeReady(0).max_texture_lod, 0u);
  EXPECT_EQ(s.stats().total.failures, expected_failures);
  for (const std::thread::id& id : rec->threads()) EXPECT_NE(id, std::this_thread::get_id());
  expectCountersAddUp(s.stats());
}

TEST(Streamer, UnavailableTilesAreRetriedOnlyAfterTheBackOff) {
  FaultSpec fault{0.0, 1.0, ErrorCode::kUnavailable, 3};
  auto rec = std::make_shared<test::RecordingSource>(makeFaultySource(procedural(256), fault));
  Streamer s(rec, baseConfig(2, 0));
  const Viewport vp{640, 480};
  const Camera cam = lookingDown(128.0, 128.0, 50.0);
  s.update(cam, vp, 0.0);
  ASSERT_TRUE(waitIdle(s));
  const size_t tiles = rec->keys().size();
  EXPECT_EQ(tiles, 5u);  // 2x2 + 1
  for (double t = 0.05; t < 0.9; t += 0.05) {
    s.update(cam, vp, t);
    ASSERT_TRUE(waitIdle(s));
  }
  EXPECT_EQ(rec->keys().size(), tiles);
  EXPECT_FALSE(s.settled());  // transient failures are still outstanding
  s.update(cam, vp, 1.5);
  ASSERT_TRUE(waitIdle(s));
  EXPECT_EQ(rec->keys().size(), 2 * tiles);
  EXPECT_EQ(s.stats().total.failures, 2 * tiles);
  expectCountersAddUp(s.stats());
}

TEST(Streamer, CorruptTileInAStoreIsCountedOnceAndTheRestArrives) {
  test::TempFile file("stream_corrupt.cts");
  ASSERT_TRUE(test::writeSyntheticStore(file.path, 512, 512, 64, PixelFormat::kRGB8).isOk());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(file.path, &reader).isOk());
  TileLocation loc;
  ASSERT_TRUE(reader->locate({0, 3, 4}, &loc).isOk());
  reader.reset();
  {
    std::fstream f(file.path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(loc.offset + 1));
    const char garbage[4] = {'\x11', '\x22', '\x33', '\x44'};
    f.write(garbage, 4);
  }
  Status status;
  auto source = openStoreSource(file.path, &status);
  ASSERT_TRUE(source) << status.toString();
  Streamer s(source, baseConfig(2, 0));
  const Viewport vp{1280, 720};
  const Camera cam = lookingDown(256.0, 256.0, 30.0);
  size_t handed = 0;
  for (int frame = 0; frame < 2000 && !s.settled(); ++frame) {
    s.update(cam, vp, frame * 0.016);
    handed += s.takeReady(100).tiles.size();
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_TRUE(s.settled());
  const StreamerStats st = s.stats();
  EXPECT_EQ(st.total.failures, 1u);
  EXPECT_EQ(st.levels[0].failures, 1u);
  EXPECT_EQ(handed, rankPlanTiles(s.geometry(), s.plan()).size() - 1);
  EXPECT_EQ(st.total.gpu_handoffs, handed);
  EXPECT_GT(st.total.bytes_read, 0u);
}

TEST(Streamer, ShutdownWithReadsInFlightIsClean) {
  auto slow = makeFaultySource(procedural(1 << 16), FaultSpec{30.0, 0.0, ErrorCode::kCorruptTile, 7});
  auto s = std::make_unique<Streamer>(slow, baseConfig(2, 8));
  s->update(lookingDown(30000.0, 30000.0, 10.0), Viewport{800, 600}, 0.0);
  while (s->stats().in_flight == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  s->shutdown();
  const StreamerStats st = s->stats();
  EXPECT_EQ(st.in_flight, 0u);
  EXPECT_EQ(st.queue_depth, 0u);
  EXPECT_GT(st.total.cancellations, 0u);
  expectCountersAddUp(st);
  s->update(lookingDown(100.0, 100.0, 10.0), Viewport{800, 600}, 0.1);  // harmless after shutdown
  s.reset();  // destructor after shutdown
  // Destroying without an explicit shutdown also joins cleanly.
  auto t = std::make_unique<Streamer>(slow, baseConfig(2, 8));
  t->update(lookingDown(30000.0, 30000.0, 10.0), Viewport{800, 600}, 0.0);
  t.reset();
}

TEST(Streamer, TakeReadyHandsOffInRankOrderWithinTileAndByteLimits) {
  Streamer s(procedural(8192), baseConfig(2, 8));
  const Viewport vp{800, 600};
  s.update(lookingDown(4000.0, 4000.0, 60.0), vp, 0.0);
  ASSERT_TRUE(waitIdle(s));
  const std::vector<TileKey> ranked = rankPlanTiles(s.geometry(), s.plan());
  const FrameHandoff a = s.takeReady(5);
  ASSERT_EQ(a.tiles.size(), 5u);
  const size_t tile_bytes = 128 * 128 * 4;
  const FrameHandoff b = s.takeReady(100, 3 * tile_bytes + 10);
  ASSERT_EQ(b.tiles.size(), 3u);
  for (size_t i = 0; i < 5; ++i) EXPECT_EQ(a.tiles[i].key, ranked[i]);
  for (size_t i = 0; i < 3; ++i) EXPECT_EQ(b.tiles[i].key, ranked[5 + i]);
  ASSERT_TRUE(a.tiles[0].rgba);
  EXPECT_EQ(a.tiles[0].rgba->size(), tile_bytes);
  const FrameHandoff rest = s.takeReady(100000);
  EXPECT_EQ(rest.tiles.size(), ranked.size() - 8);
  EXPECT_TRUE(s.settled());
  for (const LevelResidency& r : rest.residency) {
    const bool needed = s.plan().stack[r.level].needed;
    ASSERT_EQ(r.resident.size(), size_t(r.window.width() * r.window.height()));
    for (uint8_t v : r.resident) EXPECT_EQ(v, needed ? 1 : 0) << "level " << r.level;
  }
  EXPECT_EQ(s.stats().total.gpu_handoffs, ranked.size());
}

TEST(Streamer, MaxTextureLodGoesFinerAfterHysteresisAndCoarserAtOnce) {
  StreamerConfig cfg = baseConfig(2, 8);
  cfg.lod_hysteresis_frames = 3;
  Streamer s(procedural(8192), cfg);
  const Viewport vp{800, 600};
  s.update(lookingDown(4000.0, 4000.0, 60.0), vp, 0.0);
  ASSERT_TRUE(waitIdle(s));
  const uint32_t coarsest = s.geometry().levelCount() - 1;
  ASSERT_EQ(s.plan().finest_level, 0u);
  EXPECT_EQ(s.takeReady(100000).max_texture_lod, coarsest);  // all ready; 1st frame
  EXPECT_EQ(s.takeReady(0).max_texture_lod, coarsest);       // 2nd
  EXPECT_EQ(s.takeReady(0).max_texture_lod, 0u);             // 3rd: finer now
  // Teleport: level-0 tiles are not resident any more; coarser at once.
  s.update(lookingDown(7000.0, 1000.0, 60.0), vp, 0.1);
  const FrameHandoff h = s.takeReady(0);
  EXPECT_GT(h.max_texture_lod, 0u);
  EXPECT_LE(h.max_texture_lod, s.plan().pyramid_level);
  // After a GPU reset everything is handed again.
  ASSERT_TRUE(waitIdle(s));
  s.resetGpuResidency();
  EXPECT_EQ(s.takeReady(0).max_texture_lod, coarsest);
  s.update(lookingDown(7000.0, 1000.0, 60.0), vp, 0.2);
  ASSERT_TRUE(waitIdle(s));
  EXPECT_EQ(s.takeReady(100000).tiles.size(), rankPlanTiles(s.geometry(), s.plan()).size());
}

// A source whose tiles in `missing` are unavailable (kUnavailable: retried
// only after a back-off, so missing while the clock stands still).
class MissingTilesSource final : public TileSource {
 public:
  MissingTilesSource(std::shared_ptr<TileSource> inner, KeySet missing)
      : m_inner(std::move(inner)), m_missing(std::move(missing)) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    if (m_missing.count(key)) return Status::error(ErrorCode::kUnavailable, "test: tile missing");
    return m_inner->fetch(key, rgba);
  }
  std::string describe() const override { return "missing:" + m_inner->describe(); }

 private:
  std::shared_ptr<TileSource> m_inner;
  KeySet m_missing;
};

// MaxTextureLOD the rule's way: the finest level with every coarser level
// ready, a pyramid level with all its tiles, a stack level with `coverage`
// of its visible tiles.
uint32_t expectedLod(const PyramidGeometry& g, const ClipmapPlan& plan, const KeySet& missing,
                     double coverage) {
  uint32_t finest = g.levelCount();
  for (uint32_t l = g.levelCount(); l-- > 0;) {
    const bool pyramid = l >= plan.pyramid_level;
    if (!pyramid && !plan.stack[l].needed) break;
    const TileRect rect = pyramid ? plan.pyramid[l - plan.pyramid_level] : plan.stack[l].visible;
    uint64_t total = 0, ready = 0;
    for (int64_t y = rect.y0; y < rect.y1; ++y)
      for (int64_t x = rect.x0; x < rect.x1; ++x, ++total)
        if (missing.count({l, uint32_t(x), uint32_t(y)}) == 0) ++ready;
    if (double(ready) < (pyramid ? 1.0 : coverage) * double(total)) break;
    finest = l;
  }
  return std::min(finest, g.levelCount() - 1);
}

// Visible tiles that stay missing hold a level back only while they are
// more than 1 - lod_min_coverage of its visible tiles: the renderer draws
// them from their ancestors. Coverage 1 is the strict rule.
TEST(Streamer, MaxTextureLodNeedsOnlyTheCoverageOfVisibleTiles) {
  const Viewport vp{800, 600};
  const Camera cam = lookingDown(4000.0, 4000.0, 60.0);
  auto source = procedural(8192);
  const StreamerConfig base = baseConfig(2, 8);
  const ClipmapPlan plan = planClipmap(source->geometry(), vp, cam, base.planner);
  // Every third visible tile of every needed stack level is missing (not
  // where a level sees only one tile).
  KeySet missing;
  for (const ClipLevelPlan& lp : plan.stack) {
    if (!lp.needed || lp.visible.width() * lp.visible.height() < 2) continue;
    for (int64_t y = lp.visible.y0; y < lp.visible.y1; ++y)
      for (int64_t x = lp.visible.x0; x < lp.visible.x1; ++x)
        if ((x + 2 * y) % 3 == 0) missing.insert({lp.level, uint32_t(x), uint32_t(y)});
  }
  ASSERT_FALSE(missing.empty());
  const uint32_t strict = expectedLod(source->geometry(), plan, missing, 1.0);
  const uint32_t half = expectedLod(source->geometry(), plan, missing, 0.5);
  ASSERT_EQ(half, plan.finest_level);
  ASSERT_GT(strict, half);
  for (double coverage : {1.0, 0.75, 0.5}) {
    StreamerConfig cfg = base;
    cfg.lod_hysteresis_frames = 1;
    cfg.lod_min_coverage = coverage;
    Streamer s(std::make_shared<MissingTilesSource>(source, missing), cfg);
    s.update(cam, vp, 0.0);
    ASSERT_TRUE(waitIdle(s));
    EXPECT_EQ(s.stats().total.failures, missing.size());
    EXPECT_EQ(s.takeReady(100000).max_texture_lod,
              expectedLod(s.geometry(), s.plan(), missing, coverage))
        << "coverage " << coverage;
  }
  // The default is the measured choice (docs/decisions.md).
  EXPECT_EQ(StreamerConfig{}.lod_min_coverage, 0.5);
}

TEST(Streamer, BudgetBelowTheNeededSetKeepsCoarseLevelsAndDoesNotThrash) {
  const uint64_t entry = 128 * 128 * 4 + kCacheEntryOverheadBytes;
  StreamerConfig cfg = baseConfig(2, 8);
  cfg.ram_budget_bytes = (85 + 40) * entry;  // pyramid (85 tiles) + 40 of the 192 stack tiles
  Streamer s(procedural(8192), cfg);
  const Viewport vp{800, 600};
  const Camera cam = lookingDown(4000.0, 4000.0, 60.0);
  for (int i = 0; i < 5; ++i) {
    s.update(cam, vp, 0.01 * i);
    ASSERT_TRUE(waitIdle(s));
  }
  const StreamerStats st = s.stats();
  EXPECT_EQ(st.ram_entries, 125u);
  EXPECT_EQ(st.total.evictions, 0u);  // nothing wanted was thrown out for a worse tile
  EXPECT_EQ(st.total.loads, 125u);
  EXPECT_EQ(st.total.budget_skips, 192u - 40u);
  const FrameHandoff h = s.takeReady(100000);
  ASSERT_EQ(h.tiles.size(), 125u);
  // All 40 spare entries went to the coarsest stack level (2); the finer
  // levels simply stay missing.
  size_t level2 = 0, finer = 0;
  for (const ReadyTile& t : h.tiles) {
    level2 += t.key.level == 2;
    finer += t.key.level < 2;
  }
  EXPECT_EQ(level2, 40u);
  EXPECT_EQ(finer, 0u);
  expectCountersAddUp(st);
}

// Budget = exactly the wanted set. Step one level-0 tile east (only level
// 0's window moves) and back. GPU-first evicts in-window tiles already on
// the GPU, so the column that left is still in RAM when it re-enters;
// protect-GPU evicts that column and reads it again.
void stepEastAndBack(EvictionMode mode, size_t expected_rereads) {
  const Viewport vp{800, 600};
  const Camera a = lookingDown(4032.0, 4032.0, 60.0), east = lookingDown(4160.0, 4032.0, 60.0);
  StreamerConfig cfg = baseConfig(1, 8);
  cfg.eviction = mode;
  auto base = procedural(8192);
  const ClipmapPlan plan_a = planClipmap(base->geometry(), vp, a, cfg.planner);
  const size_t wanted = rankPlanTiles(base->geometry(), plan_a).size();
  cfg.ram_budget_bytes = wanted * (128 * 128 * 4 + kCacheEntryOverheadBytes);
  auto rec = std::make_shared<test::RecordingSource>(base);
  Streamer s(rec, cfg);
  s.update(a, vp, 0.0);
  ASSERT_TRUE(waitIdle(s));
  ASSERT_EQ(s.takeReady(100000).tiles.size(), wanted);
  const int64_t left_x = s.plan().stack[0].window.x0;
  s.update(east, vp, 0.1);
  ASSERT_EQ(s.plan().stack[0].window.x0, left_x + 1);
  ASSERT_TRUE(waitIdle(s));
  (void)s.takeReady(100000);
  const size_t before = rec->keys().size();
  s.update(a, vp, 0.2);
  ASSERT_TRUE(waitIdle(s));
  size_t rereads = 0;
  const std::vector<TileKey> keys = rec->keys();
  for (size_t i = before; i < keys.size(); ++i) rereads += keys[i].level == 0 && keys[i].x == left_x;
  EXPECT_EQ(rereads, expected_rereads);
  EXPECT_EQ(keys.size() - before, expected_rereads);
  const StreamerStats st = s.stats();
  EXPECT_EQ(st.levels[0].ram_hits, 8u - expected_rereads);
  expectCountersAddUp(st);
}

TEST(Streamer, GpuFirstEvictionKeepsTheTilesThatJustLeft) { stepEastAndBack(EvictionMode::kGpuFirst, 0); }

TEST(Streamer, ProtectGpuEvictionKeepsWindowTilesAndRereadsTheLeftColumn) {
  stepEastAndBack(EvictionMode::kProtectGpu, 8);
}

TEST(Streamer, StatsJsonParsesAndMatchesTheSnapshot) {
  Streamer s(procedural(8192), baseConfig(2, 8));
  const Viewport vp{800, 600};
  s.update(lookingDown(1000.0, 1000.0, 60.0), vp, 0.0);
  s.update(lookingDown(7000.0, 7000.0, 60.0), vp, 0.1);
  ASSERT_TRUE(waitIdle(s));
  (void)s.takeReady(50);
  const StreamerStats st = s.stats();
  expectCountersAddUp(st);
  const nlohmann::json j = nlohmann::json::parse(st.toJson());
  EXPECT_EQ(j["total"]["requests"].get<uint64_t>(), st.total.requests);
  EXPECT_EQ(j["total"]["loads"].get<uint64_t>(), st.total.loads);
  EXPECT_EQ(j["total"]["gpu_handoffs"].get<uint64_t>(), 50u);
  EXPECT_EQ(j["levels"].size(), st.levels.size());
  uint64_t level_requests = 0;
  for (const auto& l : j["levels"]) level_requests += l["requests"].get<uint64_t>();
  EXPECT_EQ(level_requests, st.total.requests);
  EXPECT_EQ(j["ram_bytes"].get<uint64_t>(), st.ram_bytes);
  EXPECT_EQ(j["ram_budget_bytes"].get<uint64_t>(), st.ram_budget_bytes);
  EXPECT_GE(j["queue_latency_p99_ms"].get<double>(), j["queue_latency_p50_ms"].get<double>());
  EXPECT_EQ(st.total.ram_hits + st.total.ram_misses,
            2 * rankPlanTiles(s.geometry(), s.plan()).size() - 85 /* pyramid stays */);
}

TEST(Streamer, TraceRecordsEveryAccessAndReplays) {
  test::TempFile file("trace.txt");
  StreamerConfig cfg = baseConfig(2, 8);
  cfg.trace_path = file.path;
  uint64_t accesses = 0;
  {
    Streamer s(procedural(1 << 16), cfg);
    const Viewport vp{800, 600};
    for (int i = 0; i < 30; ++i) {
      s.update(lookingDown(20000.0 + 300.0 * i, 20000.0, 40.0), vp, i / 30.0);
      ASSERT_TRUE(waitIdle(s));
    }
    const StreamerStats st = s.stats();
    accesses = st.total.ram_hits + st.total.ram_misses;
  }
  std::vector<TraceEvent> events;
  ASSERT_TRUE(readTrace(file.path, &events).isOk());
  uint64_t enters = 0, leaves = 0, windows = 0;
  for (const TraceEvent& e : events) {
    if (e.window) windows++;
    else (e.leave ? leaves : enters)++;
  }
  EXPECT_GT(windows, 0u);
  EXPECT_EQ(enters, accesses);
  EXPECT_GT(leaves, 0u);
  const ReplayResult r = replayTrace(events, 300);
  EXPECT_EQ(r.accesses, accesses);
  EXPECT_GE(r.hits_opt, r.hits_lru);
  EXPECT_GE(r.hits_opt, r.hits_plan);
  EXPECT_GE(r.hits_opt, r.hits_gpu_first);
}

TEST(Trace, ReplayMatchesHandComputedHitCounts) {
  // Accesses A B C A B with room for two tiles.
  const TileKey a{0, 0, 0}, b{0, 1, 0}, c{0, 2, 0};
  std::vector<TraceEvent> ev = {{1, a, false}, {1, b, false}, {2, c, false},
                                {3, a, false}, {3, b, false}};
  ReplayResult r = replayTrace(ev, 2);
  EXPECT_EQ(r.accesses, 5u);
  EXPECT_EQ(r.distinct_tiles, 3u);
  EXPECT_EQ(r.hits_lru, 0u);  // C evicts A, A evicts B, B evicts C
  EXPECT_EQ(r.hits_opt, 2u);  // C bypasses: A and B hit
  // No window lines: the plan-aware policy falls back to least recently
  // wanted, where leaving counts as wanted. A leaves (refreshed) before C
  // arrives, so B is the victim and A hits when it re-enters; LRU evicts A.
  std::vector<TraceEvent> ev2 = {{1, a, false}, {2, b, false}, {3, a, true},
                                 {4, c, false}, {5, a, false}};
  r = replayTrace(ev2, 2);
  EXPECT_EQ(r.hits_plan, 1u);
  EXPECT_EQ(r.hits_gpu_first, 1u);
  EXPECT_EQ(r.hits_lru, 0u);
  EXPECT_EQ(r.hits_opt, 1u);
  test::TempFile bad("bad_trace.txt");
  {
    std::ofstream f(bad.path);
    f << kTraceHeader << "\n1 0 2 3\nnot a line\n";
  }
  std::vector<TraceEvent> parsed;
  const Status st = readTrace(bad.path, &parsed);
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(st.message.find(":3:"), std::string::npos) << st.message;
  EXPECT_EQ(readTrace("/nonexistent/trace", &parsed).code, ErrorCode::kNotFound);
}

// clipstream-trace accepted an empty or truncated trace and echoed raw bytes
// (terminal escapes included) in its error.
TEST(Trace, EmptyTruncatedForeignOrNonRegularTracesAreRefused) {
  test::TempFile file("hostile.trace");
  auto readText = [&](const std::string& text) {
    std::ofstream(file.path, std::ios::binary) << text;
    std::vector<TraceEvent> events;
    return readTrace(file.path, &events);
  };
  const std::string header = std::string(kTraceHeader) + "\n";
  EXPECT_TRUE(readText(header).isOk()) << "a header alone is a trace of no frames";
  EXPECT_TRUE(readText(header + "1 0 2 3\n").isOk());
  Status st = readText("");
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(st.message.find("empty"), std::string::npos) << st.message;
  st = readText(header + "1 0 2 3\n2 0 2");
  EXPECT_EQ(st.code, ErrorCode::kTruncated) << st.toString();
  EXPECT_NE(st.message.find(":3:"), std::string::npos) << st.message;
  st = readText("1 0 2 3\n");
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument) << "no header";
  st = readText(std::string(1 << 20, '\0'));  // no newline anywhere: refused from its first bytes
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument) << st.toString();
  st = readText("# clipstream trace v9: from the future\n");
  EXPECT_EQ(st.code, ErrorCode::kUnsupported) << st.toString();
  st = readText(header + "1 0 \x1b[31mred\x07\n");
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument);
  for (char c : st.message) EXPECT_GE(static_cast<unsigned char>(c), 0x20) << st.message;
  EXPECT_NE(st.message.find("?[31mred?"), std::string::npos) << st.message;
  const std::string fifo = file.path + ".fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  std::vector<TraceEvent> events;
  EXPECT_EQ(readTrace(fifo, &events).code, ErrorCode::kIo);
  ::unlink(fifo.c_str());
}

// clipstream-trace: NaN and other absurd numbers, and a bad trace, exit
// with the documented codes and one plain line.
TEST(Trace, ClipstreamTraceRejectsAbsurdArgumentsAndBadTraces) {
  test::TempFile file("cli.trace");
  std::ofstream(file.path) << kTraceHeader << "\n1 0 2 3\n2 0 2 3\n1 0 2 3\n";
  auto run = [&](const std::string& args, std::string* output) {
    const std::string cmd = std::string("{ '") + CLIPSTREAM_TRACE_EXE + "' " + args + "; } 2>&1";
    FILE* pipe = ::popen(cmd.c_str(), "r");
    char buffer[4096];
    size_t got;
    output->clear();
    while ((got = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) output->append(buffer, got);
    const int status = ::pclose(pipe);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  };
  std::string out;
  EXPECT_EQ(run("--budget-mb 1 '" + file.path + "'", &out), 0) << out;
  EXPECT_NE(out.find("opt\t"), std::string::npos) << out;
  for (const char* bad : {"--budget-mb nan", "--budget-mb 0", "--budget-mb -5", "--budget-mb 1e999",
                          "--budget-mb 1 --tile-bytes 0", "--budget-mb 1 --no-such-flag"}) {
    EXPECT_EQ(run(std::string(bad) + " '" + file.path + "'", &out), 2) << bad << ": " << out;
    EXPECT_LT(out.size(), 300u) << out;
  }
  EXPECT_EQ(run("--budget-mb 1 '" + file.path + "' >/dev/full", &out), 1) << out;
  EXPECT_NE(out.find("cannot write standard output"), std::string::npos) << out;
  std::ofstream(file.path, std::ios::trunc);  // empty
  EXPECT_EQ(run("--budget-mb 1 '" + file.path + "'", &out), 1) << out;
  EXPECT_NE(out.find("empty"), std::string::npos) << out;
}

// The trace is written under OutputFile's rule: nothing under its name until
// shutdown(), then the whole trace; an unwritable path is reported, not
// printed and ignored.
TEST(Trace, TheTraceAppearsWholeAtShutdownAndFailuresAreReported) {
  test::TempFile file("streamer.trace");
  {
    StreamerConfig cfg;
    cfg.io_threads = 1;
    cfg.trace_path = file.path;
    Streamer streamer(test::procedural(4096), cfg);
    const Viewport vp{320, 240};
    for (int f = 0; f < 5; ++f) streamer.update(test::lookingDown(2048, 2048, 300.0 + f), vp, f / 60.0);
    EXPECT_FALSE(std::filesystem::exists(file.path)) << "visible before shutdown";
    streamer.shutdown();
    EXPECT_TRUE(streamer.traceStatus().isOk()) << streamer.traceStatus().toString();
  }
  std::vector<TraceEvent> events;
  ASSERT_TRUE(readTrace(file.path, &events).isOk());
  EXPECT_GT(events.size(), 5u);
  StreamerConfig cfg;
  cfg.trace_path = "/nonexistent-dir/streamer.trace";
  Streamer streamer(test::procedural(4096), cfg);
  streamer.shutdown();
  EXPECT_EQ(streamer.traceStatus().code, ErrorCode::kNotFound) << streamer.traceStatus().toString();
}

// --io-threads 100000 aborted clipstream-fly: the streamer starts at most
// kMaxIoThreads loaders and never throws when the system refuses more.
TEST(Streamer, AnAbsurdLoaderCountIsCappedNotFatal) {
  StreamerConfig cfg;
  cfg.io_threads = 100000;
  Streamer streamer(test::procedural(4096), cfg);
  const Viewport vp{320, 240};
  for (int f = 0; f < 3; ++f) streamer.update(test::lookingDown(2048, 2048, 300.0), vp, f / 60.0);
  EXPECT_TRUE(test::waitIdle(streamer));
  EXPECT_GT(streamer.stats().total.loads, 0u);
  EXPECT_EQ(streamer.stats().loader_threads, kMaxIoThreads);
  streamer.shutdown();
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
