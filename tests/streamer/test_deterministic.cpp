// Deterministic I/O (StreamerConfig::deterministic_io): the same flight gives
// the same hand-offs and counters every run whatever the loaders' timing,
// at most reads_per_frame reads land in a frame and none before its
// latency, and the settings change the flight. The real-time default is
// what every other streamer test runs.
#include "streamer_test_util.h"

#include <clipstream/streamer/streamer.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/streamer/testing/faulty_source.h>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <random>
#include <thread>
#include <vector>

namespace clipstream {
namespace {

using test::expectCountersAddUp;
using test::lookingDown;
using test::procedural;

// Sleeps a random time (0..max_us, seeded from the machine, so every run
// times its reads differently) before each fetch, and counts the fetches
// that have finished. Thread-safe.
class JitterSource final : public TileSource {
 public:
  JitterSource(std::shared_ptr<TileSource> inner, uint32_t max_us)
      : m_inner(std::move(inner)), m_max_us(max_us), m_seed(std::random_device{}()) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  TileContent content() const override { return m_inner->content(); }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    FetchInfo info;
    return fetchWithInfo(key, rgba, &info);
  }
  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) override {
    if (m_max_us > 0) {
      std::minstd_rand rng(m_seed + m_calls.fetch_add(1));
      std::this_thread::sleep_for(std::chrono::microseconds(rng() % (m_max_us + 1)));
    }
    const Status s = m_inner->fetchWithInfo(key, rgba, info);
    m_finished.fetch_add(1);
    return s;
  }
  std::string describe() const override { return "jitter:" + m_inner->describe(); }
  uint64_t finished() const { return m_finished.load(); }

 private:
  std::shared_ptr<TileSource> m_inner;
  uint32_t m_max_us;
  uint32_t m_seed;
  std::atomic<uint32_t> m_calls{0};
  std::atomic<uint64_t> m_finished{0};
};

// What a frame hands the renderer and what the counters say after it.
struct HandoffRecord {
  std::vector<TileKey> tiles;
  uint32_t max_texture_lod = 0;
  uint64_t loads = 0, failures = 0, evictions = 0, cancellations = 0, budget_skips = 0, ram_hits = 0,
           ram_bytes = 0, queue_depth = 0, in_flight = 0;
  bool operator==(const HandoffRecord&) const = default;
};

struct DeterministicFlight {
  uint32_t reads_per_frame = kDefaultIoReadsPerFrame;
  uint32_t latency_frames = kDefaultIoLatencyFrames;
  uint32_t jitter_us = 400;
  unsigned threads = 3;
  uint32_t frames = 90;
};

// A flight that exercises every path a frame's result depends on: prefetch,
// a RAM budget of a few windows (evictions, budget skips), 5 % corrupt tiles
// (failures), a per-frame upload limit (and the throttle it drives).
std::vector<HandoffRecord> fly(const DeterministicFlight& d, StreamerStats* final_stats = nullptr) {
  constexpr uint32_t kTilePx = 32;
  FaultSpec fault;
  fault.fail_fraction = 0.05;
  auto source = std::make_shared<JitterSource>(makeFaultySource(procedural(1 << 16, kTilePx), fault), d.jitter_us);
  StreamerConfig cfg;
  cfg.io_threads = d.threads;
  cfg.planner.clip_tiles = 8;
  cfg.ram_budget_bytes = 160 * (uint64_t(kTilePx) * kTilePx * 4 + kCacheEntryOverheadBytes);
  cfg.deterministic_io.enabled = true;
  cfg.deterministic_io.reads_per_frame = d.reads_per_frame;
  cfg.deterministic_io.latency_frames = d.latency_frames;
  // 32 frames of the 6 uploads (192 tiles) may wait: the throttle binds
  // only after the first updates, whose reads the rate test counts.
  cfg.throttle_read_ahead_frames = 32;
  Streamer s(source, cfg);
  const Viewport vp{256, 160};
  std::vector<HandoffRecord> out;
  for (uint32_t f = 0; f < d.frames; ++f) {
    Camera c = lookingDown(20000.0 + 40.0 * f, 30000.0, 120.0);
    c.pitch_rad = -0.6;
    s.update(c, vp, f / 60.0);
    const FrameHandoff h = s.takeReady(6);
    HandoffRecord r;
    for (const ReadyTile& t : h.tiles) r.tiles.push_back(t.key);
    r.max_texture_lod = h.max_texture_lod;
    const StreamerStats st = s.stats();
    r.loads = st.total.loads;
    r.failures = st.total.failures;
    r.evictions = st.total.evictions;
    r.cancellations = st.total.cancellations;
    r.budget_skips = st.total.budget_skips;
    r.ram_hits = st.total.ram_hits;
    r.ram_bytes = st.ram_bytes;
    r.queue_depth = st.queue_depth;
    r.in_flight = st.in_flight;
    out.push_back(std::move(r));
  }
  s.shutdown();
  if (final_stats) *final_stats = s.stats();
  return out;
}

TEST(DeterministicIo, IsOffByDefault) {
  EXPECT_FALSE(StreamerConfig{}.deterministic_io.enabled);
}

TEST(DeterministicIo, SameFlightGivesTheSameHandOffsAndCountersEveryRun) {
  StreamerStats first_stats, second_stats;
  const std::vector<HandoffRecord> first = fly({}, &first_stats);
  // Other thread counts and other read timings: only the request order counts.
  DeterministicFlight other;
  other.threads = 1;
  other.jitter_us = 1500;
  const std::vector<HandoffRecord> second = fly(other, &second_stats);
  ASSERT_EQ(first.size(), second.size());
  for (size_t f = 0; f < first.size(); ++f) ASSERT_EQ(first[f], second[f]) << "frame " << f;
  // The flight went through what could have made it differ.
  EXPECT_GT(first.back().evictions, 0u);
  EXPECT_GT(first.back().failures, 0u);
  EXPECT_GT(first.back().loads, 200u);
  EXPECT_EQ(first_stats.total.loads, second_stats.total.loads);
  EXPECT_EQ(first_stats.in_flight, 0u);  // shutdown published every read issued
  expectCountersAddUp(first_stats);
  expectCountersAddUp(second_stats);
}

TEST(DeterministicIo, AtMostReadsPerFrameLandInAFrameAndNoneBeforeTheLatency) {
  DeterministicFlight d;
  d.reads_per_frame = 3;
  d.latency_frames = 4;
  const std::vector<HandoffRecord> frames = fly(d);
  uint64_t before = 0;
  for (size_t f = 0; f < frames.size(); ++f) {
    const uint64_t landed = frames[f].loads + frames[f].failures;
    // update() f + 1 publishes the reads issued by update() f + 1 - 4.
    if (f < 4) {
      EXPECT_EQ(landed, 0u) << "frame " << f;
    }
    EXPECT_LE(landed - before, 3u) << "frame " << f;
    EXPECT_LE(frames[f].in_flight, 3u * 4u) << "frame " << f;
    before = landed;
  }
  EXPECT_EQ(frames[4].loads + frames[4].failures, 3u);  // the loaders had work to do
}

TEST(DeterministicIo, FinishedReadsWaitForTheirFrame) {
  // The loaders are done long before the due frame: the tiles still land
  // only there. (Without the gating they would be in RAM, and handed off,
  // at the next update().)
  auto source = std::make_shared<JitterSource>(procedural(1 << 14, 32), 0);
  StreamerConfig cfg;
  cfg.io_threads = 2;
  cfg.prefetch = false;
  cfg.planner.clip_tiles = 8;
  cfg.deterministic_io.enabled = true;
  cfg.deterministic_io.reads_per_frame = 5;
  cfg.deterministic_io.latency_frames = 3;
  Streamer s(source, cfg);
  const Viewport vp{256, 160};
  const Camera c = lookingDown(8000.0, 8000.0, 60.0);
  s.update(c, vp, 0.0);
  for (int frame = 2; frame <= 4; ++frame) {
    // Every read issued so far has finished on the loaders.
    const uint64_t issued = 5u * uint64_t(frame - 1);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (source->finished() < issued && std::chrono::steady_clock::now() < deadline)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    ASSERT_EQ(source->finished(), issued);
    s.update(c, vp, frame / 60.0);
    const FrameHandoff h = s.takeReady(100);
    const uint64_t expected = frame < 4 ? 0u : 5u;
    EXPECT_EQ(s.stats().total.loads, expected) << "update " << frame;
    EXPECT_EQ(h.tiles.size(), expected) << "update " << frame;
  }
  expectCountersAddUp(s.stats());
}

TEST(DeterministicIo, TheReadRateAndLatencyChangeTheFlight) {
  DeterministicFlight slow, fast, late;
  slow.reads_per_frame = 2;
  fast.reads_per_frame = 16;
  late.reads_per_frame = 16;
  late.latency_frames = 6;
  const std::vector<HandoffRecord> a = fly(slow), b = fly(fast), c = fly(late);
  EXPECT_LT(a.back().loads, b.back().loads);
  EXPECT_NE(a, b);
  EXPECT_NE(b, c);
  // By update 11, 9 frames of reads have landed at latency 2, 5 at latency 6.
  EXPECT_EQ(b[10].loads + b[10].failures, 9u * 16u);
  EXPECT_EQ(c[10].loads + c[10].failures, 5u * 16u);
}

}  // namespace
}  // namespace clipstream
