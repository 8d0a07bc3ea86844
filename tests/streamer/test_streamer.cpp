// The streamer: load order, cancellation, prefetch, the hard RAM budget,
// failures, shutdown, hand-off limits, MaxTextureLOD hysteresis, stats.
// Eviction policy: test_eviction.cpp; the trace: test_trace.cpp.
#include "streamer_test_util.h"

#include <clipstream/streamer/streamer.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>
#include <clipstream/streamer/testing/faulty_source.h>

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
using test::expectCountersAddUp;
using test::kPi;
using test::lookingDown;
using test::procedural;
using test::waitIdle;

StreamerConfig baseConfig(unsigned threads, uint32_t clip_tiles) {
  StreamerConfig cfg;
  cfg.io_threads = threads;
  cfg.prefetch = false;
  cfg.planner.clip_tiles = clip_tiles;
  return cfg;
}

// The classic clipmap's plan, for the tests of whole windows entering and
// leaving: every tile of every needed window wanted (PlanScope::kWindow).
StreamerConfig windowConfig(unsigned threads, uint32_t clip_tiles) {
  StreamerConfig cfg = baseConfig(threads, clip_tiles);
  cfg.planner.scope = PlanScope::kWindow;
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
  Streamer s(rec, windowConfig(1, 8));
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
  StreamerConfig cfg = windowConfig(1, 8);
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
  std::atomic<uint64_t> violations{0};
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
  // The peak is taken at every insert (the placeholder's, before the read).
  EXPECT_LE(st.ram_peak_bytes, cfg.ram_budget_bytes);
  EXPECT_GT(st.ram_peak_bytes + entry, cfg.ram_budget_bytes) << "the budget never filled";
  EXPECT_GE(st.total.loads + st.total.failures, 1000u);
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
  const test::TempDir dir("stream_corrupt");
  const std::string path = dir.file("store.cst");
  ASSERT_TRUE(test::writeSyntheticStore(path, {.width_px = 512, .height_px = 512, .tile_px = 64,
                                               .format = PixelFormat::kRGB8})
                  .ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());
  TileLocation loc;
  ASSERT_TRUE(reader->locate({0, 3, 4}, &loc).ok());
  ASSERT_FALSE(loc.constant) << "the damaged tile needs a payload";
  reader.reset();
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(loc.offset + 1));
    const char garbage[4] = {'\x11', '\x22', '\x33', '\x44'};
    f.write(garbage, 4);
  }
  Status status;
  auto source = openStoreSource(path, &status);
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
  Streamer s(procedural(8192), windowConfig(2, 8));
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

// MaxTextureLOD is the finest needed level streaming serves: one with a
// wanted tile on the GPU, in RAM or being read. Reads held back (here: one
// a frame, deterministic) leave the finer levels unserved; once they land
// the clamp is the plan's finest level.
TEST(Streamer, MaxTextureLodIsTheFinestLevelStreamingServes) {
  StreamerConfig cfg = baseConfig(2, 8);
  cfg.deterministic_io.enabled = true;
  cfg.deterministic_io.reads_per_frame = 1;
  cfg.deterministic_io.latency_frames = 1;
  Streamer s(procedural(8192), cfg);
  const Viewport vp{800, 600};
  const Camera cam = lookingDown(4000.0, 4000.0, 60.0);
  s.update(cam, vp, 0.0);
  ASSERT_EQ(s.plan().finest_level, 0u);
  const uint32_t pyramid = s.plan().pyramid_level;
  // One read issued, of the coarsest pyramid tile: no stack level served.
  EXPECT_EQ(s.takeReady(100000).max_texture_lod, std::min(pyramid, s.geometry().levelCount() - 1));
  uint32_t previous = s.geometry().levelCount();
  bool went_finer = false;
  for (uint32_t f = 1; f < 400 && !s.settled(); ++f) {
    s.update(cam, vp, f / 60.0);
    const uint32_t lod = s.takeReady(100000).max_texture_lod;
    EXPECT_LE(lod, previous) << "coarse to fine, never back, frame " << f;
    went_finer = went_finer || lod < previous;
    previous = lod;
  }
  ASSERT_TRUE(s.settled());
  EXPECT_TRUE(went_finer);
  EXPECT_EQ(s.takeReady(0).max_texture_lod, 0u);
  StreamerConfig off = cfg;
  off.throttle = false;
  Streamer t(procedural(8192), off);
  t.update(cam, vp, 0.0);
  EXPECT_EQ(t.takeReady(100000).max_texture_lod, 0u) << "no throttle: the plan's finest level";
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

// The clamp never hides a tile on the GPU: with every wanted tile of the
// finest level missing but one, MaxTextureLOD is still that level (the
// renderer draws the missing ones from their ancestors); with all of them
// missing, the next level. The rule it replaced (a level needed half of
// its visible tiles) hid the one resident tile (docs/decisions.md D58, D60).
TEST(Streamer, MaxTextureLodNeverHidesATileOnTheGpu) {
  const Viewport vp{800, 600};
  Camera cam = lookingDown(4000.0, 4000.0, 200.0);
  cam.pitch_rad = -0.8;
  auto source = procedural(8192);
  const StreamerConfig cfg = baseConfig(2, 8);
  const ClipmapPlan plan = planClipmap(source->geometry(), vp, cam, cfg.planner);
  const ClipLevelPlan& finest = plan.stack[plan.finest_level];
  std::vector<TileKey> wanted;
  for (int64_t y = finest.window.y0; y < finest.window.y1; ++y)
    for (int64_t x = finest.window.x0; x < finest.window.x1; ++x)
      if (finest.wants(x, y)) wanted.push_back({finest.level, uint32_t(x), uint32_t(y)});
  ASSERT_GE(wanted.size(), 2u);
  for (bool keep_one : {true, false}) {
    KeySet missing(wanted.begin() + (keep_one ? 1 : 0), wanted.end());
    Streamer s(std::make_shared<MissingTilesSource>(source, missing), cfg);
    s.update(cam, vp, 0.0);
    ASSERT_TRUE(waitIdle(s));
    EXPECT_EQ(s.stats().total.failures, missing.size());
    EXPECT_EQ(s.takeReady(100000).max_texture_lod, plan.finest_level + (keep_one ? 0 : 1))
        << (keep_one ? "one tile resident" : "none resident");
  }
}

// The throttle's rule: with an upload budget of B tiles a frame, at most
// throttle_read_ahead_frames x B wanted tiles, or
// throttle_read_ahead_min_tiles if more, wait in RAM for the GPU (the first
// frame, before any budget is seen, may read a frame's worth more); without
// throttling the loaders read as fast as they may. Reads go in load order,
// so the tiles that wait are the finest.
TEST(Streamer, ThrottleReadsNoFurtherAheadOfTheUploadsThanItsFrames) {
  const Viewport vp{800, 600};
  Camera cam = lookingDown(4000.0, 4000.0, 300.0);
  cam.pitch_rad = -0.7;
  auto run = [&](bool throttle, uint32_t min_tiles, uint64_t* most_waiting, uint64_t* frames_to_settle) {
    StreamerConfig cfg = baseConfig(2, 8);
    cfg.throttle = throttle;
    cfg.throttle_read_ahead_frames = 4;
    cfg.throttle_read_ahead_min_tiles = min_tiles;
    cfg.deterministic_io.enabled = true;
    cfg.deterministic_io.reads_per_frame = 16;
    cfg.deterministic_io.latency_frames = 2;
    Streamer s(procedural(8192), cfg);
    *most_waiting = 0;
    uint64_t f = 0;
    for (; f < 2000; ++f) {
      s.update(cam, vp, double(f) / 60.0);
      (void)s.takeReady(2);
      const StreamerStats st = s.stats();
      if (f >= 1) *most_waiting = std::max(*most_waiting, st.total.loads - st.total.gpu_handoffs);
      if (s.settled()) break;
    }
    *frames_to_settle = f;
    EXPECT_TRUE(s.settled());
    EXPECT_EQ(s.stats().total.gpu_handoffs, rankPlanTiles(s.geometry(), s.plan()).size());
  };
  uint64_t waiting_on = 0, waiting_floor = 0, waiting_off = 0, frames_on = 0, frames_floor = 0, frames_off = 0;
  run(true, 0, &waiting_on, &frames_on);
  run(true, 48, &waiting_floor, &frames_floor);
  run(false, 0, &waiting_off, &frames_off);
  std::printf("  tiles waiting at most: %llu with 4 frames of 2, %llu with a floor of 48, %llu unthrottled\n",
              static_cast<unsigned long long>(waiting_on), static_cast<unsigned long long>(waiting_floor),
              static_cast<unsigned long long>(waiting_off));
  EXPECT_LE(waiting_on, 4u * 2u + 16u);
  // The floor, when above the frames' share: more wait, but no more than it.
  EXPECT_GT(waiting_floor, 4u * 2u + 16u) << "the floor must bind in this test";
  EXPECT_LE(waiting_floor, 48u + 16u);
  EXPECT_GT(waiting_off, 48u + 16u) << "the rule must bind in this test";
  // Holding reads back costs no upload: all hand the same tiles at 2 a frame.
  EXPECT_LE(frames_on, frames_off + 4);
  EXPECT_LE(frames_floor, frames_off + 4);
}

TEST(Streamer, BudgetBelowTheNeededSetKeepsCoarseLevelsAndDoesNotThrash) {
  const uint64_t entry = 128 * 128 * 4 + kCacheEntryOverheadBytes;
  StreamerConfig cfg = windowConfig(2, 8);
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

TEST(Streamer, StatsJsonParsesAndMatchesTheSnapshot) {
  Streamer s(procedural(8192), windowConfig(2, 8));
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

}  // namespace
}  // namespace clipstream

namespace clipstream {
namespace {

// A source that asks for batches (as a store over HTTP does) and records
// each batch it is given.
class BatchingSource final : public TileSource {
 public:
  BatchingSource(std::shared_ptr<TileSource> inner, size_t max_batch,
                 BatchShape shape = BatchShape::kRow)
      : m_inner(std::move(inner)), m_max_batch(max_batch), m_shape(shape) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    record({key});
    return m_inner->fetch(key, rgba);
  }
  size_t maxBatch() const override { return m_max_batch; }
  BatchShape batchShape() const override { return m_shape; }
  void fetchBatch(std::span<const TileKey> keys, std::span<std::vector<uint8_t>* const> rgba,
                  std::span<Status> statuses, std::span<FetchInfo> infos) override {
    record(std::vector<TileKey>(keys.begin(), keys.end()));
    for (size_t i = 0; i < keys.size(); ++i) {
      infos[i] = {};
      statuses[i] = m_inner->fetch(keys[i], rgba[i]);
    }
  }
  std::string describe() const override { return "batching"; }
  std::vector<std::vector<TileKey>> batches() const {
    std::lock_guard<std::mutex> lock(m_mutex);
    return m_batches;
  }

 private:
  void record(std::vector<TileKey> batch) {
    std::lock_guard<std::mutex> lock(m_mutex);
    m_batches.push_back(std::move(batch));
  }
  std::shared_ptr<TileSource> m_inner;
  size_t m_max_batch;
  BatchShape m_shape;
  mutable std::mutex m_mutex;  // guards m_batches
  std::vector<std::vector<TileKey>> m_batches;
};

// Batches take the shape the source asks for: a row segment (a store
// written row by row) or an aligned square (a store in curve order).
TEST(Streamer, BatchesHoldNeighboursOfTheSourcesShapeAndEveryTileIsReadOnce) {
  constexpr size_t kMaxBatch = 6;  // rows: 6 columns; squares: 2 x 2 (the largest that fits)
  constexpr uint32_t kSide = 2;
  for (const BatchShape shape : {BatchShape::kRow, BatchShape::kSquare}) {
    SCOPED_TRACE(shape == BatchShape::kRow ? "rows" : "squares");
    auto source = std::make_shared<BatchingSource>(procedural(8192), kMaxBatch, shape);
    Streamer s(source, baseConfig(3, 8));
    const Viewport vp{800, 600};
    Camera cam = lookingDown(4000.0, 4000.0, 60.0);
    cam.pitch_rad = -1.0;
    s.update(cam, vp, 0.0);
    ASSERT_TRUE(waitIdle(s));
    const std::vector<TileKey> ranked = rankPlanTiles(s.geometry(), s.plan());
    KeySet read;
    size_t multi = 0, across_rows = 0;
    for (const std::vector<TileKey>& batch : source->batches()) {
      ASSERT_FALSE(batch.empty());
      ASSERT_LE(batch.size(), shape == BatchShape::kRow ? kMaxBatch : kSide * kSide);
      if (batch.size() > 1) ++multi;
      for (const TileKey& key : batch) {
        EXPECT_EQ(key.level, batch[0].level);
        if (shape == BatchShape::kRow) {
          EXPECT_EQ(key.y, batch[0].y);
          EXPECT_LT(std::abs(int64_t(key.x) - int64_t(batch[0].x)), int64_t(kMaxBatch));
        } else {
          EXPECT_EQ(key.x / kSide, batch[0].x / kSide);
          EXPECT_EQ(key.y / kSide, batch[0].y / kSide);
          across_rows += key.y != batch[0].y;
        }
        EXPECT_TRUE(read.insert(key).second) << "tile read twice";
      }
    }
    EXPECT_EQ(read.size(), ranked.size());
    for (const TileKey& key : ranked) EXPECT_EQ(read.count(key), 1u);
    EXPECT_GT(multi, 0u) << "no batch of more than one tile";
    if (shape == BatchShape::kSquare) {
      EXPECT_GT(across_rows, 0u) << "no square spans two rows";
    }
    const StreamerStats st = s.stats();
    EXPECT_EQ(st.total.loads, ranked.size());
    expectCountersAddUp(st);
  }
}

TEST(Streamer, BatchNeighboursNeverPushTheRamBudget) {
  auto source = std::make_shared<BatchingSource>(procedural(8192), 16);
  StreamerConfig cfg = baseConfig(4, 8);
  cfg.ram_budget_bytes = 40 * (128 * 128 * 4 + 4096);  // a few dozen tiles
  Streamer s(source, cfg);
  const Viewport vp{800, 600};
  Camera cam = lookingDown(4000.0, 4000.0, 60.0);
  cam.pitch_rad = -1.0;
  for (int i = 0; i < 40; ++i) {
    cam.position.x += 300.0;
    s.update(cam, vp, i * 0.1);
    s.takeReady(1000);
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  ASSERT_TRUE(waitIdle(s));
  EXPECT_LE(s.stats().ram_peak_bytes, cfg.ram_budget_bytes);  // the peak is taken at every insert
  expectCountersAddUp(s.stats());
}

}  // namespace
}  // namespace clipstream
