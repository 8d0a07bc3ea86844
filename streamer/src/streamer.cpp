// The streamer: planning on the render thread, loading on a worker pool, a
// RAM cache with a hard byte budget, and the per-frame GPU hand-off.
//
// Locking: one mutex (m_mutex) guards the queue, the cache map, the rank
// map, the failure map and the counters. Workers take it to pop a request
// and reserve room (placeholder insert), drop it for fetch() (I/O, decode,
// conversion), and take it again to publish the tile. The render thread
// takes it briefly in update(), takeReady() and stats(); it never waits on
// I/O because no one holds the lock across I/O.
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>

#include <clipstream/store/output_file.h>

#include "eviction.h"
#include "lookahead.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <system_error>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <unordered_set>

namespace clipstream {
namespace {

using Clock = std::chrono::steady_clock;

// Latency samples kept for the p50/p99 estimate: the most recent ones.
constexpr size_t kLatencySamples = 4096;
// Distinct failing tiles logged to stderr before logging goes quiet.
constexpr uint32_t kMaxLoggedFailures = 16;
// Back-off for transient (kUnavailable) failures: 0.5 s doubling to 30 s.
constexpr double kRetryBaseS = 0.5;
constexpr double kRetryMaxS = 30.0;
// Batches for sources that read neighbours together (TileSource::maxBatch):
// at most this many tiles, found among this many requests at the queue's
// front (a bounded scan under the lock; deeper requests rank too low to be
// worth pulling forward).
constexpr size_t kMaxBatchTiles = 64;
constexpr size_t kBatchScanRequests = 256;
// Camera history used to estimate velocity for the prefetch.
constexpr double kHistoryS = 0.5;
constexpr double kMinHistoryS = 0.05;
// Predicted moves longer than this many finest-level windows are teleports.
constexpr double kTeleportWindows = 2.0;

// Hash for the streamer's own maps, which are probed thousands of times per
// plan change: a multiply-xorshift of the three fields is several times
// cheaper than hashing 12 bytes with XXH3 (TileKeyHash) and mixes as well
// for grid coordinates.
struct FastKeyHash {
  size_t operator()(const TileKey& k) const noexcept {
    uint64_t h = (uint64_t(k.x) << 32 | k.y) * 0x9E3779B97F4A7C15ull;
    h ^= uint64_t(k.level) * 0xC2B2AE3D27D4EB4Full;
    h ^= h >> 29;
    h *= 0xBF58476D1CE4E5B9ull;
    return size_t(h ^ (h >> 32));
  }
};

enum class EntryState : uint8_t { kLoading, kReady };

struct CacheEntry {
  EntryState state = EntryState::kLoading;
  bool gpu = false;                 // handed to the renderer, tile still wanted
  uint64_t last_wanted_frame = 0;   // last plan rebuild that wanted this tile
  std::shared_ptr<const std::vector<uint8_t>> rgba;
};

struct FailedTile {
  ErrorCode code = ErrorCode::kOk;
  uint32_t count = 0;
  double retry_at_s = 0.0;  // kUnavailable only; others are never retried
};

struct Request {
  TileKey key;
  uint32_t rank = 0;
  Clock::time_point queued_at;
};

// True when a plan made from the path hint matches the real one: the same
// levels needed, and each needed window within a tile of the real one.
bool hintAgrees(const ClipmapPlan& hinted, const ClipmapPlan& real) {
  if (hinted.pyramid_level != real.pyramid_level || hinted.clip_tiles != real.clip_tiles ||
      hinted.stack.size() != real.stack.size())
    return false;
  for (size_t i = 0; i < real.stack.size(); ++i) {
    const ClipLevelPlan &h = hinted.stack[i], &r = real.stack[i];
    if (h.needed != r.needed) return false;
    if (r.needed && (std::abs(h.window.x0 - r.window.x0) > 1 || std::abs(h.window.y0 - r.window.y0) > 1))
      return false;
  }
  return true;
}

bool sameWindows(const ClipmapPlan& a, const ClipmapPlan& b) {
  if (a.pyramid_level != b.pyramid_level || a.clip_tiles != b.clip_tiles ||
      a.stack.size() != b.stack.size() || a.pyramid != b.pyramid)
    return false;
  for (size_t i = 0; i < a.stack.size(); ++i) {
    const ClipLevelPlan &x = a.stack[i], &y = b.stack[i];
    if (x.needed != y.needed || x.window != y.window || x.visible != y.visible) return false;
  }
  return true;
}

}  // namespace

struct Streamer::Impl {
  // Immutable after construction.
  std::shared_ptr<TileSource> source;
  PyramidGeometry geometry;
  StreamerConfig config;
  uint64_t entry_bytes = 0;  // payload + overhead charged per cache entry

  // Render thread only.
  ClipmapPlan plan;
  bool have_plan = false;
  ClipmapPlan predicted_plan;
  uint64_t frame = 0;
  double now_s = 0.0;
  bool force_rebuild = false;
  std::deque<std::pair<double, glm::dvec3>> history;
  PathHint hint;               // camera_at empty: none
  PathLookahead lookahead;     // windows along the hint
  bool hint_used = false;      // this frame's plan came with a trusted hint
  bool hint_used_by_plan = false;  // the last rebuild's
  std::vector<TileKey> wanted;                         // plan tiles, rank order
  std::unordered_set<TileKey, FastKeyHash> wanted_set; // same, for lookups
  std::vector<TileKey> prefetch;                       // predicted tiles, after wanted
  std::unordered_set<TileKey, FastKeyHash> gpu;        // handed off and still wanted
  std::vector<TileKey> pending;                        // wanted, not yet handed off (rank order)
  uint32_t lod = 0;
  uint32_t lod_ready_frames = 0;
  // The trace: text buffered here, appended to trace_file in blocks and
  // published at shutdown(). `tracing` is false without a trace or after a
  // failure (trace_status says which).
  uint32_t loader_threads = 0;  // set once by the constructor
  bool tracing = false;
  std::string trace;
  std::unique_ptr<OutputFile> trace_file;
  Status trace_status;
  void flushTrace(bool publish);

  // Shared; guarded by mutex.
  mutable std::mutex mutex;
  std::condition_variable work_cv;
  std::deque<Request> queue;  // rank order, front first
  std::unordered_map<TileKey, CacheEntry, FastKeyHash> cache;
  std::unordered_map<TileKey, uint32_t, FastKeyHash> rank;  // wanted + prefetch ranks
  std::unordered_map<TileKey, FailedTile, FastKeyHash> failed;
  std::unordered_set<TileKey, FastKeyHash> ever_read;
  std::vector<LevelCounters> counters;
  uint64_t ram_bytes = 0;
  uint64_t ram_peak = 0;
  uint64_t in_flight = 0;
  double decode_ms_total = 0.0;
  std::vector<double> latency_ms;  // ring of the last kLatencySamples
  size_t latency_next = 0;
  uint32_t logged_failures = 0;
  PlanWindows windows;            // current plan, for eviction scores
  PlanWindows predicted_windows;  // predicted plan (empty without prefetch)
  std::shared_ptr<const LookaheadSnapshot> ahead;  // hinted path's windows, or null
  uint64_t hint_frames = 0;
  uint64_t hint_ignored_frames = 0;
  // Eviction candidates sorted best victim first, rebuilt lazily after a
  // plan change or when exhausted; entries are re-checked when popped.
  std::vector<TileKey> victims;
  size_t victims_next = 0;
  // Wanted tiles that only a better-ranked newcomer may evict: worst first.
  std::vector<std::pair<uint32_t, TileKey>> pinned;
  size_t pinned_next = 0;
  bool victims_dirty = true;
  double shared_now_s = 0.0;  // copy of now_s for workers (retry times)
  uint64_t shared_frame = 0;  // copy of frame for workers
  uint32_t published_lod = 0;
  bool stopping = false;

  std::vector<std::thread> workers;

  void workerLoop();
  bool admit(const Request& request, bool neighbour, bool* reread, bool* no_room);
  bool reserveRoom(uint32_t incoming_rank);
  void buildVictimLists();
  void rebuild(const Viewport& viewport);
  uint32_t computeLod() const;
};

// ---------------------------------------------------------------------------
// Workers

// Sorts the eviction candidates once per change (plan rebuild, hand-off),
// so each eviction is amortised O(1) instead of a scan of the cache.
// Caller holds the mutex.
void Streamer::Impl::buildVictimLists() {
  struct Candidate {
    double score;
    uint64_t stamp;
    TileKey key;
  };
  std::vector<Candidate> scored_list;
  pinned.clear();
  for (const auto& [key, e] : cache) {
    if (e.state != EntryState::kReady) continue;  // placeholders are never evicted
    const auto r = rank.find(key);
    if (r == rank.end() || (e.gpu && scoredOnGpu(key, windows, config.eviction)))
      scored_list.push_back(
          {evictionScoreAhead(key, windows, predicted_windows, config.eviction, ahead.get()),
           e.last_wanted_frame, key});
    else
      pinned.emplace_back(r->second, key);
  }
  std::sort(scored_list.begin(), scored_list.end(), [](const Candidate& x, const Candidate& y) {
    return evictsBefore(x.score, x.stamp, y.score, y.stamp);
  });
  std::sort(pinned.begin(), pinned.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
  victims.clear();
  for (const Candidate& c : scored_list) victims.push_back(c.key);
  victims_next = 0;
  pinned_next = 0;
  victims_dirty = false;
}

// Makes room for one entry. Candidates, in order:
//  1. tiles that are not wanted, or wanted and already on the GPU (pyramid
//     tiles only with kGpuFirst), by plan-distance score (eviction.h);
//  2. wanted tiles still waiting for the GPU (and, with kProtectGpu,
//     pyramid tiles), only for a better-ranked newcomer, worst rank first,
//     so a budget below the needed set keeps the coarse levels and the
//     finest levels stay missing instead of thrashing.
// Placeholders are never evicted. Lists are re-checked as they are consumed
// (an entry may have been handed off, evicted or re-ranked since). Caller
// holds the mutex.
bool Streamer::Impl::reserveRoom(uint32_t incoming_rank) {
  auto evict = [&](std::unordered_map<TileKey, CacheEntry, FastKeyHash>::iterator it) {
    counters[it->first.level].evictions++;
    ram_bytes -= entry_bytes;
    cache.erase(it);
  };
  while (ram_bytes + entry_bytes > config.ram_budget_bytes) {
    if (victims_dirty) buildVictimLists();
    bool evicted = false;
    while (!evicted && victims_next < victims.size()) {
      const TileKey key = victims[victims_next++];
      auto it = cache.find(key);
      if (it == cache.end() || it->second.state != EntryState::kReady) continue;
      const auto r = rank.find(key);
      if (r != rank.end() && (!it->second.gpu || !scoredOnGpu(key, windows, config.eviction)))
        continue;  // pinned now
      evict(it);
      evicted = true;
    }
    while (!evicted && pinned_next < pinned.size()) {
      const auto [worst_rank, key] = pinned[pinned_next];
      if (worst_rank <= incoming_rank) return false;  // nothing ranks below the newcomer
      ++pinned_next;
      auto it = cache.find(key);
      const auto r = rank.find(key);
      if (it == cache.end() || it->second.state != EntryState::kReady || r == rank.end() ||
          r->second != worst_rank)
        continue;
      evict(it);
      evicted = true;
    }
    if (!evicted) return false;
  }
  return true;
}

// Takes a popped request for loading: counts its wait, cancels it if
// another path loaded it, reserves room and inserts its placeholder.
// Returns false when there is nothing to read. A neighbour (taken along
// with another request) that does not fit the budget is left in the queue
// instead: *no_room tells the caller to stop taking neighbours. Caller
// holds the mutex.
bool Streamer::Impl::admit(const Request& request, bool neighbour, bool* reread, bool* no_room) {
  const TileKey key = request.key;
  LevelCounters& level_counters = counters[key.level];
  if (neighbour && cache.count(key) == 0 && ram_bytes + entry_bytes > config.ram_budget_bytes) {
    *no_room = true;  // eviction is the popped request's business, not a neighbour's
    return false;
  }
  const double waited_ms =
      std::chrono::duration<double, std::milli>(Clock::now() - request.queued_at).count();
  if (latency_ms.size() < kLatencySamples) {
    latency_ms.push_back(waited_ms);
  } else {
    latency_ms[latency_next] = waited_ms;
    latency_next = (latency_next + 1) % kLatencySamples;
  }
  if (cache.count(key) != 0) {
    // Queued before another path loaded it; nothing to read.
    level_counters.cancellations++;
    return false;
  }
  if (!reserveRoom(request.rank)) {
    level_counters.budget_skips++;
    return false;
  }
  // Placeholder first so nobody reads this tile twice, then read unlocked.
  cache.emplace(key, CacheEntry{});
  ram_bytes += entry_bytes;
  ram_peak = std::max(ram_peak, ram_bytes);
  if (config.on_ram_insert) config.on_ram_insert(ram_bytes, config.ram_budget_bytes);
  in_flight++;
  *reread = !ever_read.insert(key).second;
  return true;
}

void Streamer::Impl::workerLoop() {
  // A source that reads neighbours in one request (a store over HTTP) gets
  // up to max_batch queued tiles of the popped tile's level and row.
  const size_t max_batch = std::clamp<size_t>(source->maxBatch(), 1, kMaxBatchTiles);
  std::vector<TileKey> keys;
  std::vector<bool> rereads;
  std::vector<std::shared_ptr<std::vector<uint8_t>>> pixels;
  std::vector<std::vector<uint8_t>*> outs;
  std::vector<Status> statuses;
  std::vector<FetchInfo> infos;
  std::vector<size_t> taken;
  std::unique_lock<std::mutex> lock(mutex);
  for (;;) {
    work_cv.wait(lock, [&] { return stopping || !queue.empty(); });
    if (stopping) return;
    const Request request = queue.front();
    queue.pop_front();
    keys.clear();
    rereads.clear();
    bool reread = false, no_room = false;
    if (!admit(request, false, &reread, &no_room)) continue;
    keys.push_back(request.key);
    rereads.push_back(reread);
    if (max_batch > 1) {
      // Same level and row, within a batch of columns: the tiles most
      // likely to lie next to it in the file (the tiler writes rows in
      // order). Only the front of the queue is searched, so the batch stays
      // among the best-ranked tiles and the scan is bounded.
      taken.clear();
      const size_t scan = std::min(queue.size(), kBatchScanRequests);
      for (size_t i = 0; i < scan && keys.size() < max_batch && !no_room; ++i) {
        const TileKey& k = queue[i].key;
        if (k.level != request.key.level || k.y != request.key.y ||
            std::abs(int64_t(k.x) - int64_t(request.key.x)) >= int64_t(max_batch))
          continue;
        if (admit(queue[i], true, &reread, &no_room)) {
          keys.push_back(k);
          rereads.push_back(reread);
        }
        if (!no_room) taken.push_back(i);
      }
      for (size_t j = taken.size(); j-- > 0;) queue.erase(queue.begin() + std::ptrdiff_t(taken[j]));
    }
    lock.unlock();

    const size_t n = keys.size();
    pixels.resize(n);
    outs.resize(n);
    statuses.assign(n, Status::ok());
    infos.assign(n, FetchInfo{});
    for (size_t i = 0; i < n; ++i) {
      pixels[i] = std::make_shared<std::vector<uint8_t>>();
      outs[i] = pixels[i].get();
    }
    if (n == 1) {
      statuses[0] = source->fetchWithInfo(keys[0], outs[0], &infos[0]);
    } else {
      source->fetchBatch(keys, outs, statuses, infos);
    }
    const size_t expected = size_t(geometry.tile_px) * geometry.tile_px * 4;

    lock.lock();
    for (size_t i = 0; i < n; ++i) {
      const TileKey key = keys[i];
      const Status& status = statuses[i];
      const FetchInfo& info = infos[i];
      const bool good = status.isOk() && pixels[i]->size() == expected;
      LevelCounters& level_counters = counters[key.level];
      in_flight--;
      level_counters.bytes_read += info.bytes_read;
      decode_ms_total += info.decode_ms;
      if (rereads[i]) level_counters.redundant_reads++;
      auto it = cache.find(key);
      if (good) {
        level_counters.loads++;
        it->second.state = EntryState::kReady;
        it->second.rgba = std::move(pixels[i]);
        it->second.last_wanted_frame = shared_frame;
      } else {
        ram_bytes -= entry_bytes;
        cache.erase(it);
        level_counters.failures++;
        FailedTile& f = failed[key];
        f.code = status.isOk() ? ErrorCode::kCorruptTile : status.code;
        f.count++;
        f.retry_at_s = shared_now_s + std::min(kRetryMaxS, kRetryBaseS * double(1u << std::min(f.count, 16u)));
        if (f.count == 1 && logged_failures < kMaxLoggedFailures) {
          logged_failures++;
          const std::string why = status.isOk() ? "tile has the wrong size" : status.toString();
          std::fprintf(stderr, "clipstream: %s: level %u tile (%u, %u) failed: %s%s\n",
                       source->describe().c_str(), key.level, key.x, key.y, why.c_str(),
                       logged_failures == kMaxLoggedFailures ? " (further failures not logged)" : "");
        }
      }
    }
  }
}

// ---------------------------------------------------------------------------
// Render thread

// Recomputes the wanted list, ranks, pending hand-offs and the queue after
// the plan (or the prediction) changed. Cancels queued requests that are no
// longer wanted; counts RAM hits/misses for tiles that became wanted.
void Streamer::Impl::rebuild(const Viewport& viewport) {
  std::vector<TileKey> new_wanted = rankPlanTiles(geometry, plan, config.frustum_priority);
  std::unordered_set<TileKey, FastKeyHash> new_set(new_wanted.begin(), new_wanted.end());
  std::vector<TileKey> new_prefetch;
  if (config.prefetch && have_plan) {
    for (const TileKey& k : diffPlans(plan, predicted_plan).entered)
      if (new_set.count(k) == 0) new_prefetch.push_back(k);
    // Coarse levels first: their tiles cover the most ground.
    std::stable_sort(new_prefetch.begin(), new_prefetch.end(),
                     [](const TileKey& a, const TileKey& b) { return a.level > b.level; });
  }
  std::unordered_map<TileKey, uint32_t, FastKeyHash> new_rank;
  new_rank.reserve(new_wanted.size() + new_prefetch.size());
  uint32_t next_rank = 0;
  for (const TileKey& k : new_wanted) new_rank.emplace(k, next_rank++);
  for (const TileKey& k : new_prefetch) new_rank.emplace(k, next_rank++);

  // GPU residency survives only while the tile stays wanted: the renderer
  // reuses a slot as soon as its tile leaves the window.
  for (auto it = gpu.begin(); it != gpu.end();) {
    if (new_set.count(*it) == 0) it = gpu.erase(it); else ++it;
  }
  pending.clear();
  for (const TileKey& k : new_wanted)
    if (gpu.count(k) == 0) pending.push_back(k);

  PlanWindows new_windows = planWindows(plan);
  PlanWindows new_predicted;
  if (config.prefetch && have_plan) new_predicted = planWindows(predicted_plan);
  std::shared_ptr<const LookaheadSnapshot> new_ahead =
      hint_used && config.eviction == EvictionMode::kGpuFirst ? lookahead.snapshot() : nullptr;
  hint_used_by_plan = hint_used;
  if (tracing) {
    // Time and viewport first: the replay re-plans the hint with them.
    TraceEvent time_line;
    time_line.window = kTraceTimeTag;
    time_line.frame = frame;
    time_line.time_s = now_s;
    time_line.kind = hint_used ? 1 : 0;
    time_line.viewport = viewport;
    appendTraceLine(time_line, &trace);
    auto windowLines = [&](char tag, const PlanWindows& w) {
      TraceEvent line;
      line.window = tag;
      line.frame = frame;
      for (size_t l = 0; l < w.rects.size(); ++l) {
        line.key.level = uint32_t(l);
        line.rect = w.rects[l];
        line.kind = w.kinds[l];
        appendTraceLine(line, &trace);
      }
    };
    windowLines(kTraceWindowTag, new_windows);
    windowLines(kTracePredictedTag, new_predicted);
    TraceEvent tile_line;
    tile_line.frame = frame;
    for (const TileKey& k : new_wanted) {
      if (wanted_set.count(k) != 0) continue;
      tile_line.key = k;
      appendTraceLine(tile_line, &trace);
    }
    tile_line.leave = true;
    for (const TileKey& k : wanted) {
      if (new_set.count(k) != 0) continue;
      tile_line.key = k;
      appendTraceLine(tile_line, &trace);
    }
    constexpr size_t kTraceBlockBytes = size_t(1) << 20;
    if (trace.size() >= kTraceBlockBytes) flushTrace(false);
  }

  const auto now = Clock::now();
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (stopping) return;
    shared_now_s = now_s;
    shared_frame = frame;
    for (auto it = cache.begin(); it != cache.end(); ++it) {
      it->second.gpu = gpu.count(it->first) != 0;
    }
    for (const TileKey& k : new_wanted) {
      auto c = cache.find(k);
      if (c != cache.end()) c->second.last_wanted_frame = frame;
      if (wanted_set.count(k) == 0) {
        if (c != cache.end() && c->second.state == EntryState::kReady) counters[k.level].ram_hits++;
        else counters[k.level].ram_misses++;
      }
    }
    std::unordered_map<TileKey, Clock::time_point, FastKeyHash> queued_at;
    for (const Request& r : queue) queued_at.emplace(r.key, r.queued_at);
    std::deque<Request> new_queue;
    std::unordered_set<TileKey, FastKeyHash> kept;
    auto consider = [&](const TileKey& k) {
      if (gpu.count(k) != 0 || cache.count(k) != 0) return;
      auto f = failed.find(k);
      if (f != failed.end()) {
        if (f->second.code != ErrorCode::kUnavailable || now_s < f->second.retry_at_s) return;
      }
      const auto q = queued_at.find(k);
      if (q != queued_at.end()) {
        kept.insert(k);
        new_queue.push_back({k, new_rank[k], q->second});
      } else {
        counters[k.level].requests++;
        new_queue.push_back({k, new_rank[k], now});
      }
    };
    for (const TileKey& k : new_wanted) consider(k);
    for (const TileKey& k : new_prefetch) consider(k);
    for (const Request& r : queue)
      if (kept.count(r.key) == 0) counters[r.key.level].cancellations++;
    queue.swap(new_queue);
    rank.swap(new_rank);
    windows = std::move(new_windows);
    predicted_windows = std::move(new_predicted);
    ahead = std::move(new_ahead);
    victims_dirty = true;
  }
  work_cv.notify_all();
  wanted.swap(new_wanted);
  wanted_set.swap(new_set);
  prefetch.swap(new_prefetch);
}

// Finest level l such that every level from the coarsest down to l is
// ready: a pyramid level with all its tiles on the GPU, a stack level with
// at least lod_min_coverage of its visible tiles. The missing tiles of a
// ready level are drawn from their finest usable ancestor (the renderer's
// usable map), so no tile that is not loaded is ever sampled; demanding
// every visible tile (coverage 1) kept the whole view several levels too
// coarse at speed (docs/accuracy.md, "Throttling"). Tiles that failed for
// good count as done: the renderer shows their ancestor, and one bad tile
// must not pin the whole view to the coarsest level.
uint32_t Streamer::Impl::computeLod() const {
  const uint32_t levels = geometry.levelCount();
  if (levels == 0) return 0;
  std::lock_guard<std::mutex> lock(mutex);  // for `failed`
  auto done = [&](const TileKey& k) {
    if (gpu.count(k) != 0) return true;
    const auto f = failed.find(k);
    return f != failed.end() && f->second.code != ErrorCode::kUnavailable;
  };
  uint32_t finest = levels;
  for (uint32_t l = levels; l-- > 0;) {
    TileRect rect;
    if (l >= plan.pyramid_level) {
      rect = plan.pyramid[l - plan.pyramid_level];
    } else {
      const ClipLevelPlan& lp = plan.stack[l];
      if (!lp.needed) break;
      rect = lp.visible;
    }
    // Pyramid levels need every tile (they are loaded first and kept);
    // a stack level is ready with lod_min_coverage of its visible tiles.
    uint64_t total = 0, ready = 0;
    for (int64_t y = rect.y0; y < rect.y1; ++y)
      for (int64_t x = rect.x0; x < rect.x1; ++x, ++total)
        if (done({l, uint32_t(x), uint32_t(y)})) ++ready;
    const double need =
        l >= plan.pyramid_level ? 1.0 : std::clamp(config.lod_min_coverage, 0.0, 1.0);
    if (double(ready) < need * double(total)) break;
    finest = l;
  }
  return std::min(finest, levels - 1);
}

Streamer::Streamer(std::shared_ptr<TileSource> source, const StreamerConfig& config)
    : m_impl(std::make_unique<Impl>()) {
  Impl& s = *m_impl;
  s.source = std::move(source);
  s.config = config;
  if (s.source) s.geometry = s.source->geometry();
  s.entry_bytes = uint64_t(s.geometry.tile_px) * s.geometry.tile_px * 4 + kCacheEntryOverheadBytes;
  s.counters.resize(s.geometry.levelCount());
  s.lod = s.geometry.levelCount() ? s.geometry.levelCount() - 1 : 0;
  s.published_lod = s.lod;
  if (!config.trace_path.empty()) {
    OutputOptions trace_options;
    trace_options.existing = ExistingOutput::kReplaceRegular;
    s.trace_status = OutputFile::create(config.trace_path, trace_options, &s.trace_file);
    s.tracing = s.trace_status.isOk();
    if (s.tracing) {
      s.trace = kTraceHeader;
      s.trace += '\n';
    }
  }
  if (!s.source) return;  // nothing to load; update() plans nothing
  unsigned threads = config.io_threads               ? config.io_threads
                     : s.source->suggestedLoaderThreads() ? s.source->suggestedLoaderThreads()
                                                          : std::thread::hardware_concurrency();
  threads = std::clamp(threads, 1u, kMaxIoThreads);
  for (unsigned i = 0; i < threads; ++i) {
    try {
      s.workers.emplace_back([this] { m_impl->workerLoop(); });
    } catch (const std::system_error&) {
      break;  // the system's thread limit: run with the loaders that started
    }
  }
  s.loader_threads = uint32_t(s.workers.size());
}

void Streamer::Impl::flushTrace(bool publish) {
  if (!tracing) return;
  Status status = trace_file->append(trace);
  trace.clear();  // keeps its capacity for the next block
  if (status && publish) status = trace_file->commit();
  if (!status) {
    trace_status = status;
    tracing = false;
    trace_file.reset();  // removes the temporary
  } else if (publish) {
    tracing = false;
    trace_file.reset();
  }
}

Status Streamer::traceStatus() const { return m_impl->trace_status; }

void Streamer::discardTrace() {
  Impl& s = *m_impl;
  s.tracing = false;
  s.trace.clear();
  s.trace_file.reset();  // removes the temporary
}

Streamer::~Streamer() { shutdown(); }

const PyramidGeometry& Streamer::geometry() const { return m_impl->geometry; }

void Streamer::update(const Camera& camera, const Viewport& viewport, double time_s) {
  Impl& s = *m_impl;
  if (!s.source || s.geometry.levelCount() == 0) return;
  s.frame++;
  s.now_s = time_s;
  ClipmapPlan next = planClipmap(s.geometry, viewport, camera, s.config.planner);

  // The path hint counts only while it agrees with the real camera.
  s.hint_used = false;
  if (s.hint.camera_at && std::isfinite(time_s)) {
    const Camera hinted = s.hint.camera_at(time_s);
    s.hint_used =
        finiteCamera(hinted) && hintAgrees(planClipmap(s.geometry, viewport, hinted, s.config.planner), next);
    // The lookahead serves eviction by return time, which only kGpuFirst does.
    if (s.hint_used && s.config.eviction == EvictionMode::kGpuFirst)
      s.lookahead.advance(s.geometry, viewport, s.config.planner, s.hint, time_s);
  }

  // Velocity from the camera history; the predicted camera keeps today's
  // orientation and moves on at that velocity for prefetch_ahead_s. With a
  // trusted hint the predicted camera is the hinted one instead.
  s.history.emplace_back(time_s, camera.position);
  while (s.history.size() > 2 && time_s - s.history.front().first > kHistoryS) s.history.pop_front();
  ClipmapPlan predicted = next;
  const Camera hinted_ahead =
      s.config.prefetch && s.hint_used ? s.hint.camera_at(time_s + s.config.prefetch_ahead_s) : camera;
  if (s.config.prefetch && s.hint_used && finiteCamera(hinted_ahead)) {
    predicted = planClipmap(s.geometry, viewport, hinted_ahead, s.config.planner);
  } else if (s.config.prefetch && s.history.size() >= 2) {
    const double dt = s.history.back().first - s.history.front().first;
    if (dt >= kMinHistoryS) {
      const glm::dvec3 velocity = (s.history.back().second - s.history.front().second) / dt;
      const glm::dvec3 step = velocity * s.config.prefetch_ahead_s;
      // A jump farther than two windows of the finest needed level is a
      // teleport, not motion: forget the history instead of prefetching a
      // path nobody flies.
      const double window_texels = double(next.clip_tiles) * double(s.geometry.tile_px) *
                                   std::ldexp(1.0, int(next.finest_level));
      if (glm::length(glm::dvec2(step.x, step.z)) > kTeleportWindows * window_texels) {
        s.history.clear();
        s.history.emplace_back(time_s, camera.position);
      } else {
        Camera ahead = camera;
        ahead.position += step;
        ahead.position.y = std::max(ahead.position.y, camera.near_dist);
        predicted = planClipmap(s.geometry, viewport, ahead, s.config.planner);
      }
    }
  }

  bool retry_due = false;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    s.shared_now_s = time_s;
    if (s.hint.camera_at) (s.hint_used ? s.hint_frames : s.hint_ignored_frames)++;
    for (const auto& [key, f] : s.failed) {
      if (f.code == ErrorCode::kUnavailable && time_s >= f.retry_at_s && s.wanted_set.count(key)) {
        retry_due = true;
        break;
      }
    }
  }
  const bool changed = !s.have_plan || s.force_rebuild || retry_due || !sameWindows(s.plan, next) ||
                       !sameWindows(s.predicted_plan, predicted) || s.hint_used != s.hint_used_by_plan;
  s.plan = std::move(next);
  s.predicted_plan = std::move(predicted);
  if (changed) {
    s.have_plan = true;
    s.force_rebuild = false;
    s.rebuild(viewport);
  }
}

FrameHandoff Streamer::takeReady(size_t max_tiles, size_t max_bytes) {
  Impl& s = *m_impl;
  FrameHandoff out;
  const size_t tile_bytes = size_t(s.geometry.tile_px) * s.geometry.tile_px * 4;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    size_t bytes = 0;
    std::vector<TileKey> still_pending;
    still_pending.reserve(s.pending.size());
    for (const TileKey& k : s.pending) {
      const bool room = out.tiles.size() < max_tiles && (max_bytes == 0 || bytes + tile_bytes <= max_bytes);
      auto c = room ? s.cache.find(k) : s.cache.end();
      if (c == s.cache.end() || c->second.state != EntryState::kReady) {
        still_pending.push_back(k);
        continue;
      }
      c->second.gpu = true;
      s.victims_dirty = true;  // it may be scored for eviction now
      s.gpu.insert(k);
      s.counters[k.level].gpu_handoffs++;
      out.tiles.push_back({k, c->second.rgba});
      bytes += tile_bytes;
    }
    s.pending.swap(still_pending);
  }

  const uint32_t target = s.config.throttle ? s.computeLod() : s.plan.finest_level;
  if (target >= s.lod) {
    s.lod = target;  // coarser (or equal): at once
    s.lod_ready_frames = 0;
  } else if (++s.lod_ready_frames >= s.config.lod_hysteresis_frames) {
    s.lod = target;
    s.lod_ready_frames = 0;
  }
  out.max_texture_lod = s.lod;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    s.published_lod = s.lod;
  }

  out.residency.reserve(s.plan.stack.size());
  for (const ClipLevelPlan& lp : s.plan.stack) {
    LevelResidency r;
    r.level = lp.level;
    r.window = lp.window;
    r.resident.assign(size_t(lp.window.width() * lp.window.height()), 0);
    if (lp.needed) {
      size_t i = 0;
      for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
        for (int64_t x = lp.window.x0; x < lp.window.x1; ++x, ++i)
          r.resident[i] = s.gpu.count({lp.level, uint32_t(x), uint32_t(y)}) ? 1 : 0;
    }
    out.residency.push_back(std::move(r));
  }
  return out;
}

void Streamer::setPathHint(PathHint hint) {
  Impl& s = *m_impl;
  s.hint = std::move(hint);
  s.lookahead.reset();
  s.hint_used = false;
  s.force_rebuild = true;  // the next update() plans with (or without) the new hint
  std::lock_guard<std::mutex> lock(s.mutex);
  s.ahead = nullptr;  // no eviction by the old path meanwhile
  s.victims_dirty = true;
}

void Streamer::resetGpuResidency() {
  Impl& s = *m_impl;
  s.gpu.clear();
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    for (auto& [key, entry] : s.cache) entry.gpu = false;
  }
  s.force_rebuild = true;  // re-queue wanted tiles no longer in RAM
  s.pending = s.wanted;
  s.lod = s.geometry.levelCount() ? s.geometry.levelCount() - 1 : 0;
  s.lod_ready_frames = 0;
}

const ClipmapPlan& Streamer::plan() const { return m_impl->plan; }

bool Streamer::settled() const {
  const Impl& s = *m_impl;
  if (!s.have_plan) return false;
  std::lock_guard<std::mutex> lock(s.mutex);
  for (const TileKey& k : s.pending) {
    const auto f = s.failed.find(k);
    if (f == s.failed.end() || f->second.code == ErrorCode::kUnavailable) return false;
  }
  return true;
}

StreamerStats Streamer::stats() const {
  const Impl& s = *m_impl;
  StreamerStats out;
  std::vector<double> lat;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    out.levels = s.counters;
    out.ram_bytes = s.ram_bytes;
    out.ram_peak_bytes = s.ram_peak;
    out.queue_depth = s.queue.size();
    out.in_flight = s.in_flight;
    out.decode_ms_total = s.decode_ms_total;
    out.max_texture_lod = s.published_lod;
    out.ram_entries = s.cache.size();
    out.path_hint_frames = s.hint_frames;
    out.path_hint_ignored_frames = s.hint_ignored_frames;
    out.loader_threads = s.loader_threads;
    lat = s.latency_ms;
  }
  out.ram_budget_bytes = s.config.ram_budget_bytes;
  out.entry_overhead_bytes = kCacheEntryOverheadBytes;
  for (const LevelCounters& c : out.levels) {
    out.total.requests += c.requests;
    out.total.ram_hits += c.ram_hits;
    out.total.ram_misses += c.ram_misses;
    out.total.gpu_handoffs += c.gpu_handoffs;
    out.total.cancellations += c.cancellations;
    out.total.evictions += c.evictions;
    out.total.redundant_reads += c.redundant_reads;
    out.total.bytes_read += c.bytes_read;
    out.total.failures += c.failures;
    out.total.loads += c.loads;
    out.total.budget_skips += c.budget_skips;
  }
  if (!lat.empty()) {
    std::sort(lat.begin(), lat.end());
    out.queue_latency_p50_ms = lat[(lat.size() - 1) / 2];
    out.queue_latency_p99_ms = lat[std::min(lat.size() - 1, size_t(double(lat.size()) * 0.99))];
  }
  return out;
}

std::vector<TileKey> Streamer::queuedTiles() const {
  const Impl& s = *m_impl;
  std::lock_guard<std::mutex> lock(s.mutex);
  std::vector<TileKey> out;
  out.reserve(s.queue.size());
  for (const Request& r : s.queue) out.push_back(r.key);
  return out;
}

void Streamer::shutdown() {
  Impl& s = *m_impl;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    if (!s.stopping) {
      s.stopping = true;
      for (const Request& r : s.queue) s.counters[r.key.level].cancellations++;
      s.queue.clear();
    }
  }
  s.work_cv.notify_all();
  // Workers finish the read they are in, publish it, then see `stopping`.
  for (std::thread& t : s.workers)
    if (t.joinable()) t.join();
  s.workers.clear();
  s.flushTrace(true);
}

}  // namespace clipstream
