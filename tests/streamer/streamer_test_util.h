// Helpers the streamer's test files share: waiting for the loaders, a
// source that records every fetch, and the counter identities every
// streamer test checks. Cameras, the procedural source, synthetic stores
// and temporary directories come from clipstream_test_support.
//
// Thread rule: waitIdle() and expectCountersAddUp() run on the test thread;
// RecordingSource is thread-safe (its fetch runs on the loader threads).
#pragma once

#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace clipstream::test {

// Polls until nothing is in flight and nothing queued that the loaders may
// read before the next hand-off (the throttle holds the rest:
// StreamerStats::reads_held). Sleeps in short steps; the timeout only turns
// a hang into a failure.
inline bool waitIdle(const Streamer& s, double timeout_s = 30.0) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (std::chrono::steady_clock::now() < end) {
    const StreamerStats st = s.stats();
    if ((st.queue_depth == 0 || st.reads_held) && st.in_flight == 0) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return false;
}

// Per-level counters add up to the totals, every request has one outcome
// (or is still queued or in flight), and RAM stayed within the budget.
inline void expectCountersAddUp(const StreamerStats& st) {
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

// Records every fetch (key, thread) in call order; optional extra latency.
class RecordingSource final : public TileSource {
 public:
  explicit RecordingSource(std::shared_ptr<TileSource> inner, double latency_ms = 0.0)
      : m_inner(std::move(inner)), m_latency_ms(latency_ms) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  TileContent content() const override { return m_inner->content(); }
  ElevationInfo elevationInfo() const override { return m_inner->elevationInfo(); }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    FetchInfo info;
    return fetchWithInfo(key, rgba, &info);
  }
  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) override {
    {
      std::lock_guard<std::mutex> lock(m_mutex);
      m_keys.push_back(key);
      m_threads.push_back(std::this_thread::get_id());
    }
    if (m_latency_ms > 0.0)
      std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(m_latency_ms));
    return m_inner->fetchWithInfo(key, rgba, info);
  }
  std::string describe() const override { return "recording:" + m_inner->describe(); }

  std::vector<TileKey> keys() const {
    std::lock_guard<std::mutex> lock(m_mutex);
    return m_keys;
  }
  std::vector<std::thread::id> threads() const {
    std::lock_guard<std::mutex> lock(m_mutex);
    return m_threads;
  }

 private:
  std::shared_ptr<TileSource> m_inner;
  double m_latency_ms;
  mutable std::mutex m_mutex;  // guards m_keys and m_threads
  std::vector<TileKey> m_keys;
  std::vector<std::thread::id> m_threads;
};

}  // namespace clipstream::test
