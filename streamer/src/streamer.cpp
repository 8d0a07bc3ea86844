// The streamer: planning on the render thread, loading on a worker pool, a
// RAM cache with a hard byte budget, and the per-frame GPU hand-off, for a
// scene of one or more layers.
//
// Locking: one mutex (m_mutex) guards the queue, the cache map, the rank
// map, the failure map and the counters. Workers take it to pop a request
// and reserve room (placeholder insert), drop it for fetch() (I/O, decode,
// conversion), and take it again to publish the tile. The render thread
// takes it briefly in update(), takeReady() and stats(); it never waits on
// I/O because no one holds the lock across I/O.
//
// Deterministic I/O (StreamerConfig::deterministic_io): the render thread
// pops and admits the requests itself, at most reads_per_frame an update(),
// and hands them to the workers as tickets (io_work); a worker reads and
// decodes a ticket without touching the cache or the counters, and the
// render thread publishes it in the update() of its due frame, in issue
// order, waiting for it if need be. Every change to the cache, the queue
// and the counters then happens on the render thread at a point fixed by
// the frame count, so the run does not depend on thread timing.
//
// Layers: every key in the shared maps is a LayerTile (layer, level, x, y).
// Each layer keeps its own plan, windows, counters and MaxTextureLOD; the
// cache, the budget, the queue and the rank order are one for all layers.
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>

#include <clipstream/store/output_file.h>

#include "eviction.h"
#include "lookahead.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <limits>
#include <system_error>
#include <mutex>
#include <thread>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

namespace clipstream {
namespace {

using Clock = std::chrono::steady_clock;

// Latency samples kept for the p50/p99 estimate: the most recent ones.
constexpr size_t kLatencySamples = 4096;
// Distinct failing tiles logged to stderr before logging goes quiet.
constexpr uint32_t kMaxLoggedFailures = 16;
// Back-off for transient (kUnavailable) failures: the n-th failure of a tile
// waits kRetryBaseS * 2^n, so 1 s, 2 s, 4 s ... capped at kRetryMaxS.
constexpr double kRetryBaseS = 0.5;
constexpr double kRetryMaxS = 30.0;
// Batches for sources that read neighbours together (TileSource::maxBatch):
// at most this many tiles, found among this many requests at the queue's
// front (a bounded scan under the lock; deeper requests rank too low to be
// worth pulling forward).
constexpr size_t kMaxBatchTiles = 64;
constexpr size_t kBatchScanRequests = 256;

// Side of the aligned square of tiles one batch is drawn from: the largest
// power of two whose square holds at most `max_batch` tiles (4 for 16, 8 for
// 64: one index page). Aligned squares of a power-of-two side lie together
// in a store whose payloads follow a space-filling curve (docs/tile-store.md).
uint32_t batchSide(size_t max_batch) {
  uint32_t side = 1;
  while (size_t(side) * 2 * side * 2 <= max_batch) side *= 2;
  return side;
}
// Camera history used to estimate velocity for the prefetch.
constexpr double kHistoryS = 0.5;
constexpr double kMinHistoryS = 0.05;
// Predicted moves longer than this many finest-level windows are teleports.
constexpr double kTeleportWindows = 2.0;

static_assert(sizeof(LayerTile) == 16, "LayerTile is hashed as four words: no padding allowed");

// Hash for the streamer's own maps, which are probed thousands of times per
// plan change: a multiply-xorshift of the four fields is several times
// cheaper than hashing 16 bytes with XXH3 and mixes as well for grid
// coordinates. The layer shares the level's word (levels stay below 64).
struct FastKeyHash {
  size_t operator()(const LayerTile& t) const noexcept {
    const TileKey& k = t.key;
    uint64_t h = (uint64_t(k.x) << 32 | k.y) * 0x9E3779B97F4A7C15ull;
    h ^= (uint64_t(k.level) | uint64_t(t.layer) << 32) * 0xC2B2AE3D27D4EB4Full;
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
  LayerTile key;
  uint32_t rank = 0;
  Clock::time_point queued_at;
};

// Deterministic I/O: one read issued on the simulated clock. The render
// thread owns the ticket's key, due_frame and reread; a worker writes the
// result fields unlocked, then sets `done` under the streamer's mutex, after
// which only the render thread touches them.
struct IoTicket {
  LayerTile key;
  uint64_t due_frame = 0;  // published in the update() of this frame
  bool reread = false;
  bool done = false;       // guarded by the mutex
  Status status;
  FetchInfo info;
  std::shared_ptr<std::vector<uint8_t>> pixels = std::make_shared<std::vector<uint8_t>>();
  std::shared_ptr<const TileDetail> detail;
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
    if (x.needed != y.needed || x.window != y.window || x.visible != y.visible ||
        x.sampled != y.sampled)
      return false;
  }
  return true;
}

bool finitePositive(double v) { return std::isfinite(v) && v > 0.0; }

// The order of roles among equally coarse tiles: elevation first.
int roleOrder(LayerRole role) { return role == LayerRole::kElevation ? 0 : 1; }

const PyramidGeometry kNoGeometry{};
const ClipmapPlan kNoPlan{};

}  // namespace

namespace {

// checkStreamLayers() for one layer, named by its index in the scene.
Status checkLayer(const StreamLayer& l, size_t index) {
  const std::string name = "scene layer " + std::to_string(index);
  if (!l.source) return Status::error(ErrorCode::kInvalidArgument, name + " has no source");
  const std::string what = name + " (" + l.source->describe() + ")";
  if (!finitePositive(l.texels_per_unit.x) || !finitePositive(l.texels_per_unit.y))
    return Status::error(ErrorCode::kInvalidArgument,
                         what + ": texels per world unit (" + std::to_string(l.texels_per_unit.x) +
                             ", " + std::to_string(l.texels_per_unit.y) +
                             ") must be finite and positive");
  if (!std::isfinite(l.origin_texel.x) || !std::isfinite(l.origin_texel.y))
    return Status::error(ErrorCode::kInvalidArgument, what + ": the origin texel is not finite");
  const TileContent content = l.source->content();
  if (l.role == LayerRole::kColour && content != TileContent::kRgba8 && content != TileContent::kBc1)
    return Status::error(ErrorCode::kInvalidArgument,
                         what + " is a colour layer but its source hands out heights");
  if (l.role == LayerRole::kElevation && content != TileContent::kHeightF32)
    return Status::error(ErrorCode::kInvalidArgument,
                         what + " is an elevation layer but its source hands out colour");
  if (!(std::isfinite(l.world_per_height) && l.world_per_height >= 0.0))
    return Status::error(ErrorCode::kInvalidArgument,
                         what + " has a height scale that is not finite and >= 0");
  return okStatus();
}

}  // namespace

Status checkStreamLayers(const std::vector<StreamLayer>& layers) {
  for (size_t i = 0; i < layers.size(); ++i)
    if (Status s = checkLayer(layers[i], i); !s) return s;
  return okStatus();
}

Camera layerCamera(const StreamLayer& layer, const Camera& world) {
  const glm::dvec2 k = layer.texels_per_unit;
  if (k == glm::dvec2(1.0, 1.0) && layer.origin_texel == glm::dvec2(0.0, 0.0)) return world;
  const double s = std::sqrt(k.x * k.y);
  Camera c = world;
  c.position.x = layer.origin_texel.x + k.x * world.position.x;
  c.position.z = layer.origin_texel.y + k.y * world.position.z;
  c.position.y = world.position.y * s;
  c.near_dist = world.near_dist * s;
  return c;
}

struct Streamer::Impl {
  struct Layer {
    // Immutable after construction.
    StreamLayer spec;           // source null: an empty layer (plans and loads nothing)
    PyramidGeometry geometry;
    uint64_t tile_bytes = 0;    // payload handed out: tileContentBytes()
    uint64_t entry_bytes = 0;   // payload + overhead charged per cache entry
    double log2_units_per_texel = 0.0;  // world units a level-0 texel spans, log2
    int role_order = 1;         // roleOrder(spec.role)

    // Render thread only.
    ClipmapPlan plan;
    ClipmapPlan predicted_plan;
    TerrainView terrain;        // the scene's terrain in this layer's texels (bounds null: flat)
    PathHint hint;              // the streamer's hint seen through layerCamera()
    PathLookahead lookahead;    // windows along that hint

    // Guarded by the streamer's mutex.
    std::vector<LevelCounters> counters;
    uint64_t ram_bytes = 0;
    uint64_t ram_entries = 0;
    PlanWindows windows;            // current plan, for eviction scores
    PlanWindows predicted_windows;  // predicted plan (empty without prefetch)
    std::shared_ptr<const LookaheadSnapshot> ahead;  // hinted path's windows, or null
    uint32_t published_lod = 0;

    bool active() const { return spec.source && geometry.levelCount() != 0; }
    PlannerConfig planner(const PlannerConfig& base) const {
      PlannerConfig c = base;
      if (spec.clip_tiles != 0) c.clip_tiles = spec.clip_tiles;
      c.terrain = terrain;
      // Relief in world units, scaled like layerCamera() scales heights.
      const double s = std::sqrt(spec.texels_per_unit.x * spec.texels_per_unit.y);
      c.ground_above *= s;
      c.ground_below *= s;
      return c;
    }
    // Coarseness of one of this layer's levels in world space: log2 of the
    // world units its texel spans, rounded, so levels of two layers within
    // a factor of sqrt(2) are equally coarse.
    int64_t coarseness(uint32_t level) const {
      return std::lround(double(level) + log2_units_per_texel);
    }
  };

  // Immutable after construction (the vector; see Layer for its fields).
  std::vector<Layer> layers;
  StreamerConfig config;
  bool any_active = false;
  int terrain_layer = -1;  // the elevation layer whose bounds plan every layer; -1: none

  // Render thread only: the detail of the terrain layer's tiles read so far
  // (the most recent kTerrainDetailTiles), and its snapshot for the plans.
  std::unordered_map<TileKey, std::shared_ptr<const TileDetail>, TileKeyHash> detail;
  std::deque<TileKey> detail_order;  // insertion order, oldest first
  void takeDetail();

  // Render thread only.
  bool have_plan = false;
  uint64_t frame = 0;
  double now_s = 0.0;
  bool force_rebuild = false;
  std::deque<std::pair<double, glm::dvec3>> history;
  PathHint hint;               // camera_at empty: none
  bool hint_used = false;      // this frame's plans came with a trusted hint
  bool hint_used_by_plan = false;  // the last rebuild's
  std::vector<LayerTile> wanted;                         // plan tiles, rank order
  std::unordered_set<LayerTile, FastKeyHash> wanted_set; // same, for lookups
  std::vector<LayerTile> prefetch;                       // predicted tiles, after wanted
  std::unordered_set<LayerTile, FastKeyHash> gpu;        // handed off and still wanted
  std::vector<LayerTile> pending;                        // wanted, not yet handed off (rank order)
  uint64_t upload_budget = 0;  // the last non-zero hand-off budget (tiles); 0: none seen
  // The trace (layer 0's requests): text buffered here, appended to
  // trace_file in blocks and published at shutdown(). `tracing` is false
  // without a trace or after a failure (trace_status says which).
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
  // Reads the throttle still allows until the next hand-off (setReadAllowance());
  // the loaders and issueReads() take one per tile they read.
  int64_t read_allowance = std::numeric_limits<int64_t>::max();
  std::unordered_map<LayerTile, CacheEntry, FastKeyHash> cache;
  std::unordered_map<LayerTile, uint32_t, FastKeyHash> rank;  // wanted + prefetch ranks
  std::unordered_map<LayerTile, FailedTile, FastKeyHash> failed;
  std::unordered_set<LayerTile, FastKeyHash> ever_read;
  uint64_t ram_bytes = 0;
  uint64_t ram_peak = 0;
  uint64_t in_flight = 0;
  double decode_ms_total = 0.0;
  std::vector<double> latency_ms;  // ring of the last kLatencySamples
  size_t latency_next = 0;
  uint32_t logged_failures = 0;
  uint64_t hint_frames = 0;
  uint64_t hint_ignored_frames = 0;
  // Eviction candidates sorted best victim first, rebuilt lazily after a
  // plan change or when exhausted; entries are re-checked when popped.
  std::vector<LayerTile> victims;
  size_t victims_next = 0;
  // Wanted tiles that only a better-ranked newcomer may evict: worst first.
  std::vector<std::pair<uint32_t, LayerTile>> pinned;
  size_t pinned_next = 0;
  bool victims_dirty = true;
  // Detail of terrain tiles the loaders read since the last update().
  std::vector<std::pair<TileKey, std::shared_ptr<const TileDetail>>> new_detail;
  double shared_now_s = 0.0;  // copy of now_s for workers (retry times)
  uint64_t shared_frame = 0;  // copy of frame for workers
  bool stopping = false;
  // Deterministic I/O: tickets not yet taken by a worker, issue order;
  // io_done_cv is signalled whenever a ticket is done.
  std::deque<std::shared_ptr<IoTicket>> io_work;
  std::condition_variable io_done_cv;

  // Render thread only (deterministic I/O): tickets issued and not yet
  // published, issue order (so due frames never decrease).
  std::deque<std::shared_ptr<IoTicket>> io_issued;
  bool deterministic() const { return config.deterministic_io.enabled; }

  std::vector<std::thread> workers;

  LevelCounters& counters(const LayerTile& t) { return layers[t.layer].counters[t.key.level]; }
  bool scoredWhenOnGpu(const LayerTile& t) const {
    return scoredOnGpu(t.key, layers[t.layer].windows, config.eviction);
  }
  void loadTerrain();
  void workerLoop();
  std::shared_ptr<const TileDetail> detailOf(const Layer& layer, const LayerTile& key, const Status& status,
                                             const std::vector<uint8_t>& pixels, std::vector<float>* floats) const;
  void publishLocked(const LayerTile& key, const Status& status, std::shared_ptr<std::vector<uint8_t>> pixels,
                     const FetchInfo& info, bool reread, std::shared_ptr<const TileDetail> tile_detail);
  void publishDueReads(bool all);
  void issueReads();
  bool admit(const Request& request, bool neighbour, bool* reread, bool* no_room);
  bool reserveRoom(uint32_t incoming_rank, uint64_t incoming_bytes);
  void buildVictimLists();
  std::vector<LayerTile> rankScene() const;
  void rebuild(const Viewport& viewport);
  uint32_t servedLod(const Layer& layer, uint32_t index) const;
  void setReadAllowance(uint64_t budget);
  // The tile lies in its layer's current plan: a pyramid tile, or inside
  // a needed stack level's window (where the renderer keeps its slot).
  bool inNeededWindow(const LayerTile& k) const {
    if (k.layer >= layers.size()) return false;
    const ClipmapPlan& plan = layers[k.layer].plan;
    if (k.key.level >= plan.pyramid_level) return k.key.level - plan.pyramid_level < plan.pyramid.size();
    if (k.key.level >= plan.stack.size()) return false;
    const ClipLevelPlan& lp = plan.stack[k.key.level];
    return lp.needed && lp.window.contains(k.key.x, k.key.y);
  }
  std::vector<FrameHandoff> handOff(size_t layer_count, size_t max_tiles, size_t max_bytes);
};

// ---------------------------------------------------------------------------
// Workers

// Sorts the eviction candidates once per change (plan rebuild, hand-off),
// so each eviction is amortised O(1) instead of a scan of the cache. Tiles
// of every layer compete in one list, each scored against its own layer's
// windows. Caller holds the mutex.
void Streamer::Impl::buildVictimLists() {
  struct Candidate {
    double score;
    uint64_t stamp;
    LayerTile key;
  };
  std::vector<Candidate> scored_list;
  pinned.clear();
  for (const auto& [key, e] : cache) {
    if (e.state != EntryState::kReady) continue;  // placeholders are never evicted
    const auto r = rank.find(key);
    if (r == rank.end() || (e.gpu && scoredWhenOnGpu(key))) {
      const Layer& layer = layers[key.layer];
      scored_list.push_back({evictionScoreAhead(key.key, layer.windows, layer.predicted_windows,
                                                config.eviction, e.gpu, layer.ahead.get()),
                             e.last_wanted_frame, key});
    } else {
      pinned.emplace_back(r->second, key);
    }
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

// Makes room for one entry of incoming_bytes. Candidates, in order:
//  1. tiles that are not wanted, or wanted and already on the GPU (pyramid
//     tiles only with kGpuFirst), by plan-distance score (eviction.h);
//  2. wanted tiles still waiting for the GPU (and, with kProtectGpu,
//     pyramid tiles), only for a better-ranked newcomer, worst rank first,
//     so a budget below the needed set keeps the coarse levels and the
//     finest levels stay missing instead of thrashing.
// Placeholders are never evicted. Lists are re-checked as they are consumed
// (an entry may have been handed off, evicted or re-ranked since). Caller
// holds the mutex.
bool Streamer::Impl::reserveRoom(uint32_t incoming_rank, uint64_t incoming_bytes) {
  auto evict = [&](std::unordered_map<LayerTile, CacheEntry, FastKeyHash>::iterator it) {
    Layer& layer = layers[it->first.layer];
    layer.counters[it->first.key.level].evictions++;
    ram_bytes -= layer.entry_bytes;
    layer.ram_bytes -= layer.entry_bytes;
    layer.ram_entries--;
    cache.erase(it);
  };
  while (ram_bytes + incoming_bytes > config.ram_budget_bytes) {
    if (victims_dirty) buildVictimLists();
    bool evicted = false;
    while (!evicted && victims_next < victims.size()) {
      const LayerTile key = victims[victims_next++];
      auto it = cache.find(key);
      if (it == cache.end() || it->second.state != EntryState::kReady) continue;
      const auto r = rank.find(key);
      if (r != rank.end() && (!it->second.gpu || !scoredWhenOnGpu(key)))
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
  const LayerTile key = request.key;
  Layer& layer = layers[key.layer];
  LevelCounters& level_counters = layer.counters[key.key.level];
  if (neighbour && cache.count(key) == 0 && ram_bytes + layer.entry_bytes > config.ram_budget_bytes) {
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
  if (!reserveRoom(request.rank, layer.entry_bytes)) {
    level_counters.budget_skips++;
    return false;
  }
  // Placeholder first so nobody reads this tile twice, then read unlocked.
  cache.emplace(key, CacheEntry{});
  ram_bytes += layer.entry_bytes;
  layer.ram_bytes += layer.entry_bytes;
  layer.ram_entries++;
  ram_peak = std::max(ram_peak, ram_bytes);
  if (config.on_ram_insert) config.on_ram_insert(ram_bytes, config.ram_budget_bytes);
  in_flight++;
  *reread = !ever_read.insert(key).second;
  return true;
}

void Streamer::Impl::workerLoop() {
  std::vector<LayerTile> tiles;
  std::vector<TileKey> keys;
  std::vector<bool> rereads;
  std::vector<std::shared_ptr<std::vector<uint8_t>>> pixels;
  std::vector<std::vector<uint8_t>*> outs;
  std::vector<Status> statuses;
  std::vector<FetchInfo> infos;
  std::vector<size_t> taken;
  std::vector<std::shared_ptr<const TileDetail>> details;
  std::vector<float> floats;
  std::unique_lock<std::mutex> lock(mutex);
  for (;;) {
    // With deterministic I/O the queue is the render thread's to issue
    // from; workers take only tickets, and finish them before they stop.
    work_cv.wait(lock, [&] {
      return stopping || !io_work.empty() || (!deterministic() && !queue.empty() && read_allowance > 0);
    });
    if (!io_work.empty()) {
      const std::shared_ptr<IoTicket> ticket = std::move(io_work.front());
      io_work.pop_front();
      const Layer& layer = layers[ticket->key.layer];
      lock.unlock();
      ticket->status = layer.spec.source->fetchWithInfo(ticket->key.key, ticket->pixels.get(), &ticket->info);
      ticket->detail = detailOf(layer, ticket->key, ticket->status, *ticket->pixels, &floats);
      lock.lock();
      ticket->done = true;
      io_done_cv.notify_all();
      continue;
    }
    if (stopping) return;
    const Request request = queue.front();
    queue.pop_front();
    tiles.clear();
    rereads.clear();
    bool reread = false, no_room = false;
    if (!admit(request, false, &reread, &no_room)) continue;
    tiles.push_back(request.key);
    rereads.push_back(reread);
    Layer& layer = layers[request.key.layer];
    // A source that reads neighbours in one request (a store over HTTP)
    // gets more queued tiles of the popped tile's layer and level: those of
    // its row within max_batch columns, or those of its aligned square of
    // batchSide(max_batch) tiles, as the source's file favours (written row
    // by row, or along a curve). The source reads what lies together with
    // one range request and the rest at the same time. Only the front of
    // the queue is searched, so the batch stays among the best-ranked tiles
    // and the scan is bounded.
    const size_t max_batch = std::clamp<size_t>(layer.spec.source->maxBatch(), 1, kMaxBatchTiles);
    if (max_batch > 1) {
      taken.clear();
      const TileKey& first = request.key.key;
      const bool squares = layer.spec.source->batchShape() == BatchShape::kSquare;
      const uint32_t side = batchSide(max_batch);
      const size_t scan = std::min(queue.size(), kBatchScanRequests);
      for (size_t i = 0; i < scan && tiles.size() < max_batch && !no_room; ++i) {
        const LayerTile& t = queue[i].key;
        if (t.layer != request.key.layer || t.key.level != first.level) continue;
        const bool near = squares ? t.key.x / side == first.x / side && t.key.y / side == first.y / side
                                  : t.key.y == first.y &&
                                        std::abs(int64_t(t.key.x) - int64_t(first.x)) < int64_t(max_batch);
        if (!near) continue;
        if (admit(queue[i], true, &reread, &no_room)) {
          tiles.push_back(t);
          rereads.push_back(reread);
        }
        if (!no_room) taken.push_back(i);
      }
      for (size_t j = taken.size(); j-- > 0;) queue.erase(queue.begin() + std::ptrdiff_t(taken[j]));
    }
    read_allowance -= int64_t(tiles.size());
    lock.unlock();

    const size_t n = tiles.size();
    keys.resize(n);
    pixels.resize(n);
    outs.resize(n);
    statuses.assign(n, okStatus());
    infos.assign(n, FetchInfo{});
    for (size_t i = 0; i < n; ++i) {
      keys[i] = tiles[i].key;
      pixels[i] = std::make_shared<std::vector<uint8_t>>();
      outs[i] = pixels[i].get();
    }
    if (n == 1) {
      statuses[0] = layer.spec.source->fetchWithInfo(keys[0], outs[0], &infos[0]);
    } else {
      layer.spec.source->fetchBatch(keys, outs, statuses, infos);
    }
    // The terrain's tiles also refine the planner's bounds: the ranges of
    // their cells (their samples, widened by the tile's error from the
    // index, which the read has just used).
    details.assign(n, nullptr);
    for (size_t i = 0; i < n; ++i) details[i] = detailOf(layer, tiles[i], statuses[i], *pixels[i], &floats);

    lock.lock();
    for (size_t i = 0; i < n; ++i)
      publishLocked(tiles[i], statuses[i], std::move(pixels[i]), infos[i], rereads[i], std::move(details[i]));
  }
}

// The terrain's tiles also refine the planner's bounds: the ranges of their
// cells (their samples, widened by the tile's error from the index, which
// the read has just used). Null for other layers' tiles and failed reads.
// No lock needed: reads only what the constructor fixed.
std::shared_ptr<const TileDetail> Streamer::Impl::detailOf(const Layer& layer, const LayerTile& key,
                                                           const Status& status,
                                                           const std::vector<uint8_t>& pixels,
                                                           std::vector<float>* floats) const {
  if (int(key.layer) != terrain_layer || !status || pixels.size() != layer.tile_bytes) return nullptr;
  TileHeightBounds hb;
  if (!layer.spec.source->tileHeightBounds(key.key, &hb)) return nullptr;
  floats->resize(pixels.size() / sizeof(float));
  std::memcpy(floats->data(), pixels.data(), pixels.size());
  return makeTileDetail(layer.geometry.tile_px, floats->data(), hb.error);
}

// A finished read into the cache (its placeholder becomes the tile) or, when
// it failed, into the failure map. Caller holds the mutex.
void Streamer::Impl::publishLocked(const LayerTile& key, const Status& status,
                                   std::shared_ptr<std::vector<uint8_t>> pixels, const FetchInfo& info,
                                   bool reread, std::shared_ptr<const TileDetail> tile_detail) {
  Layer& layer = layers[key.layer];
  const bool good = status.ok() && pixels->size() == layer.tile_bytes;
  LevelCounters& level_counters = layer.counters[key.key.level];
  in_flight--;
  level_counters.bytes_read += info.bytes_read;
  decode_ms_total += info.decode_ms;
  if (reread) level_counters.redundant_reads++;
  auto it = cache.find(key);
  if (good) {
    if (tile_detail) new_detail.emplace_back(key.key, std::move(tile_detail));
    level_counters.loads++;
    it->second.state = EntryState::kReady;
    it->second.rgba = std::move(pixels);
    it->second.last_wanted_frame = shared_frame;
  } else {
    ram_bytes -= layer.entry_bytes;
    layer.ram_bytes -= layer.entry_bytes;
    layer.ram_entries--;
    cache.erase(it);
    level_counters.failures++;
    FailedTile& f = failed[key];
    f.code = status.ok() ? ErrorCode::kCorruptTile : status.code;
    f.count++;
    f.retry_at_s = shared_now_s + std::min(kRetryMaxS, kRetryBaseS * double(1u << std::min(f.count, 16u)));
    if (f.count == 1 && logged_failures < kMaxLoggedFailures) {
      logged_failures++;
      const std::string why = status.ok() ? "tile has the wrong size" : status.toString();
      std::fprintf(stderr, "clipstream: %s: level %u tile (%u, %u) failed: %s%s\n",
                   layer.spec.source->describe().c_str(), key.key.level, key.key.x, key.key.y, why.c_str(),
                   logged_failures == kMaxLoggedFailures ? " (further failures not logged)" : "");
    }
  }
}

// Deterministic I/O, render thread: publishes the issued reads due by this
// frame (all of them with `all`, at shutdown), in issue order, waiting for
// the workers to finish each. The wait is the point of the mode: a slow
// machine takes longer per frame but shows the same frames.
void Streamer::Impl::publishDueReads(bool all) {
  std::unique_lock<std::mutex> lock(mutex, std::defer_lock);
  while (!io_issued.empty() && (all || io_issued.front()->due_frame <= frame)) {
    const std::shared_ptr<IoTicket> ticket = std::move(io_issued.front());
    io_issued.pop_front();
    if (!lock.owns_lock()) lock.lock();
    io_done_cv.wait(lock, [&] { return ticket->done; });
    shared_now_s = now_s;  // retry times of failures count from this frame
    publishLocked(ticket->key, ticket->status, std::move(ticket->pixels), ticket->info, ticket->reread,
                  std::move(ticket->detail));
  }
}

// Deterministic I/O, render thread: this frame's reads. Pops the queue's
// front as a worker would (admit(): cancellation, budget, eviction,
// placeholder) until reads_per_frame reads are issued, each due
// latency_frames frames from now. One tile a read: batching changes how
// fast a store over HTTP is read, not what a frame shows.
void Streamer::Impl::issueReads() {
  const uint32_t reads = std::max(1u, config.deterministic_io.reads_per_frame);
  const uint64_t due = frame + std::max(1u, config.deterministic_io.latency_frames);
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (stopping || loader_threads == 0) return;  // no worker would ever finish a ticket
    for (uint32_t issued = 0; issued < reads && !queue.empty() && read_allowance > 0;) {
      const Request request = queue.front();
      queue.pop_front();
      bool reread = false, no_room = false;
      if (!admit(request, false, &reread, &no_room)) continue;
      auto ticket = std::make_shared<IoTicket>();
      ticket->key = request.key;
      ticket->due_frame = due;
      ticket->reread = reread;
      io_issued.push_back(ticket);
      io_work.push_back(std::move(ticket));
      ++issued;
      --read_allowance;
    }
  }
  work_cv.notify_all();
}

// ---------------------------------------------------------------------------
// Render thread

// Every layer's wanted tiles in the one load order (docs/architecture.md,
// "Layers"): every layer's pyramid before any stack level; then, in each
// group, coarse to fine by world-space coarseness; among equally coarse
// levels elevation before colour, then layer order; inside a layer's level
// rankPlanTiles()'s order (visible first, near the focus first). With one
// layer this is rankPlanTiles() itself.
std::vector<LayerTile> Streamer::Impl::rankScene() const {
  struct Ranked {
    int stack;               // 0: pyramid, 1: stack
    int64_t neg_coarseness;  // coarse first
    int role;
    uint32_t layer;
    LayerTile tile;
  };
  size_t active = 0;
  for (const Layer& layer : layers) active += layer.active() ? 1 : 0;
  if (active == 1) {
    // rankPlanTiles() already lists one layer in this order: skip the sort.
    std::vector<LayerTile> out;
    for (uint32_t i = 0; i < layers.size(); ++i) {
      if (!layers[i].active()) continue;
      const std::vector<TileKey> keys =
          rankPlanTiles(layers[i].geometry, layers[i].plan, config.frustum_priority);
      out.reserve(keys.size());
      for (const TileKey& k : keys) out.push_back({i, k});
    }
    return out;
  }
  std::vector<Ranked> ranked;
  for (uint32_t i = 0; i < layers.size(); ++i) {
    const Layer& layer = layers[i];
    if (!layer.active()) continue;
    for (const TileKey& k : rankPlanTiles(layer.geometry, layer.plan, config.frustum_priority))
      ranked.push_back({k.level < layer.plan.pyramid_level ? 1 : 0, -layer.coarseness(k.level),
                        layer.role_order, i, {i, k}});
  }
  // Stable: inside one layer's level rankPlanTiles()'s order stays.
  std::stable_sort(ranked.begin(), ranked.end(), [](const Ranked& a, const Ranked& b) {
    return std::tie(a.stack, a.neg_coarseness, a.role, a.layer) <
           std::tie(b.stack, b.neg_coarseness, b.role, b.layer);
  });
  std::vector<LayerTile> out;
  out.reserve(ranked.size());
  for (const Ranked& r : ranked) out.push_back(r.tile);
  return out;
}

// Recomputes the wanted list, ranks, pending hand-offs and the queue after
// the plans (or the predictions) changed. Cancels queued requests that are
// no longer wanted; counts RAM hits/misses for tiles that became wanted
// (GPU re-entries for those still on the GPU).
void Streamer::Impl::rebuild(const Viewport& viewport) {
  std::vector<LayerTile> new_wanted = rankScene();
  std::unordered_set<LayerTile, FastKeyHash> new_set(new_wanted.begin(), new_wanted.end());
  std::vector<LayerTile> new_prefetch;
  if (config.prefetch && have_plan) {
    struct Predicted {
      int64_t neg_coarseness;
      int role;
      uint32_t layer;
      LayerTile tile;
    };
    std::vector<Predicted> predicted;
    for (uint32_t i = 0; i < layers.size(); ++i) {
      const Layer& layer = layers[i];
      if (!layer.active()) continue;
      for (const TileKey& k : diffPlans(layer.plan, layer.predicted_plan).entered)
        if (new_set.count({i, k}) == 0)
          predicted.push_back({-layer.coarseness(k.level), layer.role_order, i, {i, k}});
    }
    // Coarse levels first: their tiles cover the most ground.
    std::stable_sort(predicted.begin(), predicted.end(), [](const Predicted& a, const Predicted& b) {
      return std::tie(a.neg_coarseness, a.role, a.layer) < std::tie(b.neg_coarseness, b.role, b.layer);
    });
    for (const Predicted& p : predicted) new_prefetch.push_back(p.tile);
  }
  std::unordered_map<LayerTile, uint32_t, FastKeyHash> new_rank;
  new_rank.reserve(new_wanted.size() + new_prefetch.size());
  uint32_t next_rank = 0;
  for (const LayerTile& k : new_wanted) new_rank.emplace(k, next_rank++);
  for (const LayerTile& k : new_prefetch) new_rank.emplace(k, next_rank++);

  // GPU residency survives while the tile stays in its needed window (or
  // the pyramid): the renderer reuses a slot as soon as its tile leaves the
  // window, and keeps it until then, so a tile that is no longer sampled
  // (PlanScope::kSampled) but still in the window is drawn again, without
  // a new upload, when it is sampled again.
  for (auto it = gpu.begin(); it != gpu.end();) {
    if (new_set.count(*it) == 0 && !inNeededWindow(*it)) it = gpu.erase(it); else ++it;
  }
  pending.clear();
  for (const LayerTile& k : new_wanted)
    if (gpu.count(k) == 0) pending.push_back(k);

  std::vector<PlanWindows> new_windows(layers.size()), new_predicted(layers.size());
  std::vector<std::shared_ptr<const LookaheadSnapshot>> new_ahead(layers.size());
  for (size_t i = 0; i < layers.size(); ++i) {
    Layer& layer = layers[i];
    new_windows[i] = planWindows(layer.plan);
    if (config.prefetch && have_plan) new_predicted[i] = planWindows(layer.predicted_plan);
    if (hint_used && config.eviction == EvictionMode::kGpuFirst) new_ahead[i] = layer.lookahead.snapshot();
  }
  hint_used_by_plan = hint_used;
  if (tracing && !layers.empty()) {
    // The trace records layer 0 (its format has no layer field).
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
    windowLines(kTraceWindowTag, new_windows[0]);
    windowLines(kTracePredictedTag, new_predicted[0]);
    TraceEvent tile_line;
    tile_line.frame = frame;
    for (const LayerTile& k : new_wanted) {
      if (k.layer != 0 || wanted_set.count(k) != 0) continue;
      tile_line.key = k.key;
      appendTraceLine(tile_line, &trace);
    }
    tile_line.leave = true;
    for (const LayerTile& k : wanted) {
      if (k.layer != 0 || new_set.count(k) != 0) continue;
      tile_line.key = k.key;
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
    for (const LayerTile& k : new_wanted) {
      auto c = cache.find(k);
      if (c != cache.end()) c->second.last_wanted_frame = frame;
      if (wanted_set.count(k) == 0) {
        // A tile back in the wanted set that never left its needed window
        // is still on the GPU: drawn again, not read from RAM.
        if (gpu.count(k) != 0) counters(k).gpu_reentries++;
        else if (c != cache.end() && c->second.state == EntryState::kReady) counters(k).ram_hits++;
        else counters(k).ram_misses++;
      }
    }
    std::unordered_map<LayerTile, Clock::time_point, FastKeyHash> queued_at;
    for (const Request& r : queue) queued_at.emplace(r.key, r.queued_at);
    std::deque<Request> new_queue;
    std::unordered_set<LayerTile, FastKeyHash> kept;
    auto consider = [&](const LayerTile& k) {
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
        counters(k).requests++;
        new_queue.push_back({k, new_rank[k], now});
      }
    };
    for (const LayerTile& k : new_wanted) consider(k);
    for (const LayerTile& k : new_prefetch) consider(k);
    for (const Request& r : queue)
      if (kept.count(r.key) == 0) counters(r.key).cancellations++;
    queue.swap(new_queue);
    rank.swap(new_rank);
    for (size_t i = 0; i < layers.size(); ++i) {
      layers[i].windows = std::move(new_windows[i]);
      layers[i].predicted_windows = std::move(new_predicted[i]);
      layers[i].ahead = std::move(new_ahead[i]);
    }
    victims_dirty = true;
  }
  work_cv.notify_all();
  wanted.swap(new_wanted);
  wanted_set.swap(new_set);
  prefetch.swap(new_prefetch);
}

// MaxTextureLOD with throttling on (docs/decisions.md, "Throttling"): the
// finest needed level that streaming serves now, i.e. that has a wanted
// tile on the GPU or in RAM or on its way there; the pyramid level (always
// resident) when none has. Levels finer than that have nothing to draw, so
// the clamp never hides a tile the renderer holds: the per-tile fallback
// (the usable map) draws every missing tile from its finest resident
// ancestor, and a uniform clamp that hid resident tiles was measured to
// cost 5-7 dB at x50-x100. What
// throttling does is on the reads (setReadAllowance()); this level shows it.
uint32_t Streamer::Impl::servedLod(const Layer& layer, uint32_t index) const {
  const uint32_t levels = layer.geometry.levelCount();
  if (levels == 0) return 0;
  const ClipmapPlan& plan = layer.plan;
  std::lock_guard<std::mutex> lock(mutex);  // for the cache
  for (uint32_t l = plan.finest_level; l < plan.pyramid_level && l < plan.stack.size(); ++l) {
    const ClipLevelPlan& lp = plan.stack[l];
    if (!lp.needed) continue;
    for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
      for (int64_t x = lp.window.x0; x < lp.window.x1; ++x) {
        if (!lp.wants(x, y)) continue;
        const LayerTile k{index, {l, uint32_t(x), uint32_t(y)}};
        if (gpu.count(k) != 0 || cache.count(k) != 0) return l;
      }
  }
  return std::min(plan.pyramid_level, levels - 1);
}

// The throttle (docs/decisions.md, "Throttling"): with an upload budget of
// B tiles a frame, the loaders read no further ahead of the uploads than
// throttle_read_ahead_frames x B wanted tiles waiting in RAM (or on their
// way) for the GPU. Reads go in load order, coarse levels first, so when
// the uploads cannot keep up the finer levels wait to be read instead of
// being read, decoded and evicted unseen, and every read of a coarse tile
// entering the view finds a loader free. Set once a frame by handOff(),
// under the lock; no budget seen yet, or throttling off: no limit.
void Streamer::Impl::setReadAllowance(uint64_t budget) {
  if (!config.throttle || budget == 0) {
    read_allowance = std::numeric_limits<int64_t>::max();
    return;
  }
  const uint64_t frames = std::max<uint64_t>(config.throttle_read_ahead_frames, 1);
  const uint64_t limit = budget > uint64_t(std::numeric_limits<int64_t>::max()) / frames
                             ? uint64_t(std::numeric_limits<int64_t>::max())
                             : budget * frames;
  uint64_t backlog = 0;
  for (const LayerTile& k : pending)
    if (cache.count(k) != 0) ++backlog;
  read_allowance = backlog >= limit ? 0 : int64_t(limit - backlog);
}

// One colour layer with the identity map (elevation if the source hands out
// heights: a single source is streamed as what it is).
Streamer::Streamer(std::shared_ptr<TileSource> source, const StreamerConfig& config)
    : Streamer(
          [&] {
            StreamLayer layer;
            layer.role = source && source->content() == TileContent::kHeightF32 ? LayerRole::kElevation
                                                                                : LayerRole::kColour;
            layer.source = std::move(source);
            return std::vector<StreamLayer>{std::move(layer)};
          }(),
          config) {}

Streamer::Streamer(std::vector<StreamLayer> layers, const StreamerConfig& config)
    : m_impl(std::make_unique<Impl>()) {
  Impl& s = *m_impl;
  s.config = config;
  s.layers.resize(layers.size());
  for (size_t i = 0; i < layers.size(); ++i) {
    Impl::Layer& layer = s.layers[i];
    layer.spec = std::move(layers[i]);
    if (layer.spec.source) {
      const Status check = checkLayer(layer.spec, i);
      if (!check) {
        std::fprintf(stderr, "clipstream: %s; the layer stays empty\n", check.toString().c_str());
        layer.spec.source = nullptr;
      }
    }
    if (layer.spec.source) layer.geometry = layer.spec.source->geometry();
    layer.tile_bytes =
        tileContentBytes(layer.spec.source ? layer.spec.source->content() : TileContent::kRgba8,
                         layer.geometry.tile_px);
    layer.entry_bytes = layer.tile_bytes + kCacheEntryOverheadBytes;
    const glm::dvec2 k = layer.spec.texels_per_unit;
    layer.log2_units_per_texel = layer.spec.source ? -0.5 * std::log2(k.x * k.y) : 0.0;
    layer.role_order = roleOrder(layer.spec.role);
    layer.counters.resize(layer.geometry.levelCount());
    layer.published_lod = layer.geometry.levelCount() ? layer.geometry.levelCount() - 1 : 0;
    s.any_active = s.any_active || layer.spec.source != nullptr;
  }
  s.loadTerrain();
  if (!config.trace_path.empty()) {
    OutputOptions trace_options;
    trace_options.existing = ExistingOutput::kReplaceRegular;
    s.trace_status = OutputFile::create(config.trace_path, trace_options, &s.trace_file);
    s.tracing = s.trace_status.ok();
    if (s.tracing) {
      s.trace = kTraceHeader;
      s.trace += '\n';
    }
  }
  if (!s.any_active) return;  // nothing to load; update() plans nothing
  // Unless told, one loader per core, or what the sources ask for (a store
  // over HTTP: one per connection, each waiting out its round trips).
  unsigned suggested = 0;
  for (const Impl::Layer& layer : s.layers)
    if (layer.spec.source) suggested = std::max(suggested, layer.spec.source->suggestedLoaderThreads());
  unsigned threads = config.io_threads ? config.io_threads
                     : suggested        ? suggested
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

// The first elevation layer with a height scale and bounds is the scene's
// terrain; each layer sees it through its own map (as layerCamera() maps
// the camera: x and z by the map, heights by the mean scale).
void Streamer::Impl::loadTerrain() {
  if (!config.terrain_bounds) return;
  for (const Layer& e : layers) {
    if (!e.active() || e.spec.role != LayerRole::kElevation || e.spec.world_per_height <= 0.0) continue;
    std::shared_ptr<const TerrainBounds> bounds;
    const Status st = loadTerrainBounds(*e.spec.source, kTerrainBoundsMaxLevelTiles, &bounds);
    if (!st) {
      if (st.code != ErrorCode::kUnsupported)
        std::fprintf(stderr, "clipstream: %s; planning against the plane\n", st.toString().c_str());
      continue;
    }
    // The elevation's texel under world x is origin + k x, and sample i's
    // centre is its texel i + 0.5.
    const glm::dvec2 k = e.spec.texels_per_unit;
    const glm::dvec2 world_origin = (glm::dvec2(0.5) - e.spec.origin_texel) / k;
    for (Layer& layer : layers) {
      if (!layer.active()) continue;
      const glm::dvec2 kl = layer.spec.texels_per_unit;
      layer.terrain.bounds = bounds;
      layer.terrain.sample_origin = layer.spec.origin_texel + kl * world_origin;
      layer.terrain.units_per_sample = kl / k;
      layer.terrain.units_per_height = std::sqrt(kl.x * kl.y) * e.spec.world_per_height;
    }
    terrain_layer = int(&e - layers.data());
    return;
  }
}

// New detail into the render thread's map (the oldest dropped past
// kTerrainDetailTiles), and a new snapshot for every layer's plans.
void Streamer::Impl::takeDetail() {
  if (terrain_layer < 0) return;
  std::vector<std::pair<TileKey, std::shared_ptr<const TileDetail>>> incoming;
  {
    std::lock_guard<std::mutex> lock(mutex);
    incoming.swap(new_detail);
  }
  if (incoming.empty()) return;
  for (auto& [key, d] : incoming) {
    if (detail.insert_or_assign(key, std::move(d)).second) detail_order.push_back(key);
  }
  while (detail.size() > kTerrainDetailTiles && !detail_order.empty()) {
    detail.erase(detail_order.front());
    detail_order.pop_front();
  }
  auto snapshot = std::make_shared<TerrainDetail>();
  snapshot->tiles = detail;
  for (Layer& layer : layers)
    if (layer.terrain.bounds) layer.terrain.detail = snapshot;
}

bool Streamer::plansOnTerrain() const {
  for (const Impl::Layer& layer : m_impl->layers)
    if (layer.terrain.bounds) return true;
  return false;
}

Status Streamer::traceStatus() const { return m_impl->trace_status; }

void Streamer::discardTrace() {
  Impl& s = *m_impl;
  s.tracing = false;
  s.trace.clear();
  s.trace_file.reset();  // removes the temporary
}

Streamer::~Streamer() { shutdown(); }

size_t Streamer::layerCount() const { return m_impl->layers.size(); }

const StreamLayer& Streamer::layer(size_t layer) const {
  assert(layer < m_impl->layers.size());
  return m_impl->layers[layer].spec;
}

const PyramidGeometry& Streamer::geometry(size_t layer) const {
  const Impl& s = *m_impl;
  assert(layer < s.layers.size() || (layer == 0 && s.layers.empty()));
  return layer < s.layers.size() ? s.layers[layer].geometry : kNoGeometry;
}

void Streamer::update(const Camera& camera, const Viewport& viewport, double time_s) {
  Impl& s = *m_impl;
  bool any_levels = false;
  for (const Impl::Layer& layer : s.layers) any_levels = any_levels || layer.active();
  if (!any_levels) return;
  s.frame++;
  s.now_s = time_s;
  if (s.deterministic()) s.publishDueReads(false);
  s.takeDetail();
  const size_t n = s.layers.size();
  // Plans every active layer for `cam` (a world camera) into *plans.
  auto planAll = [&](const Camera& cam, std::vector<ClipmapPlan>* plans) {
    plans->resize(n);
    for (size_t i = 0; i < n; ++i) {
      const Impl::Layer& layer = s.layers[i];
      if (layer.active())
        (*plans)[i] = planClipmap(layer.geometry, viewport, layerCamera(layer.spec, cam), layer.planner(s.config.planner));
    }
  };
  std::vector<ClipmapPlan> next;
  planAll(camera, &next);

  // The path hint counts only while it agrees with the real camera, on
  // every layer.
  s.hint_used = false;
  if (s.hint.camera_at && std::isfinite(time_s)) {
    const Camera hinted = s.hint.camera_at(time_s);
    s.hint_used = finiteCamera(hinted);
    for (size_t i = 0; i < n && s.hint_used; ++i) {
      const Impl::Layer& layer = s.layers[i];
      if (layer.active())
        s.hint_used = hintAgrees(
            planClipmap(layer.geometry, viewport, layerCamera(layer.spec, hinted), layer.planner(s.config.planner)), next[i]);
    }
    // The lookahead serves eviction by return time, which only kGpuFirst does.
    if (s.hint_used && s.config.eviction == EvictionMode::kGpuFirst)
      for (Impl::Layer& layer : s.layers)
        if (layer.active()) layer.lookahead.advance(layer.geometry, viewport, layer.planner(s.config.planner), layer.hint, time_s);
  }

  // Velocity from the camera history; the predicted camera keeps today's
  // orientation and moves on at that velocity for prefetch_ahead_s. With a
  // trusted hint the predicted camera is the hinted one instead.
  s.history.emplace_back(time_s, camera.position);
  while (s.history.size() > 2 && time_s - s.history.front().first > kHistoryS) s.history.pop_front();
  std::vector<ClipmapPlan> predicted = next;
  const Camera hinted_ahead =
      s.config.prefetch && s.hint_used ? s.hint.camera_at(time_s + s.config.prefetch_ahead_s) : camera;
  if (s.config.prefetch && s.hint_used && finiteCamera(hinted_ahead)) {
    planAll(hinted_ahead, &predicted);
  } else if (s.config.prefetch && s.history.size() >= 2) {
    const double dt = s.history.back().first - s.history.front().first;
    if (dt >= kMinHistoryS) {
      const glm::dvec3 velocity = (s.history.back().second - s.history.front().second) / dt;
      const glm::dvec3 step = velocity * s.config.prefetch_ahead_s;
      // A jump since the last frame farther than two windows of the finest
      // needed level (of any layer, in its texels) is a teleport, not
      // motion: forget the history instead of prefetching a path nobody
      // flies. (Measured on the predicted move, the rule took fast flight
      // for teleports: x50 moves 2500 texels in prefetch_ahead_s.)
      const glm::dvec3 jump = s.history.back().second - s.history[s.history.size() - 2].second;
      bool teleport = false;
      for (size_t i = 0; i < n; ++i) {
        const Impl::Layer& layer = s.layers[i];
        if (!layer.active()) continue;
        const glm::dvec2 k = layer.spec.texels_per_unit;
        const double window_texels = double(next[i].clip_tiles) * double(layer.geometry.tile_px) *
                                     std::ldexp(1.0, int(next[i].finest_level));
        if (glm::length(glm::dvec2(jump.x * k.x, jump.z * k.y)) > kTeleportWindows * window_texels)
          teleport = true;
      }
      if (teleport) {
        s.history.clear();
        s.history.emplace_back(time_s, camera.position);
      } else {
        Camera ahead = camera;
        ahead.position += step;
        ahead.position.y = std::max(ahead.position.y, camera.near_dist);
        planAll(ahead, &predicted);
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
  bool changed = !s.have_plan || s.force_rebuild || retry_due || s.hint_used != s.hint_used_by_plan;
  for (size_t i = 0; i < n; ++i) {
    Impl::Layer& layer = s.layers[i];
    changed = changed || !sameWindows(layer.plan, next[i]) ||
              !sameWindows(layer.predicted_plan, predicted[i]);
    layer.plan = std::move(next[i]);
    layer.predicted_plan = std::move(predicted[i]);
  }
  if (changed) {
    s.have_plan = true;
    s.force_rebuild = false;
    s.rebuild(viewport);
  }
  if (s.deterministic()) s.issueReads();
}

// Hands off ready tiles of layers [0, layer_count) in rank order within one
// shared per-frame budget, then each layer's MaxTextureLOD and residency.
std::vector<FrameHandoff> Streamer::Impl::handOff(size_t layer_count, size_t max_tiles,
                                                  size_t max_bytes) {
  std::vector<FrameHandoff> out(layer_count);
  for (size_t i = 0; i < layer_count; ++i) out[i].layer = uint32_t(i);
  {
    std::lock_guard<std::mutex> lock(mutex);
    size_t bytes = 0, tiles = 0;
    std::vector<LayerTile> still_pending;
    still_pending.reserve(pending.size());
    for (const LayerTile& k : pending) {
      if (k.layer >= layer_count) {
        still_pending.push_back(k);
        continue;
      }
      const size_t tile_bytes = layers[k.layer].tile_bytes;
      const bool room = tiles < max_tiles && (max_bytes == 0 || bytes + tile_bytes <= max_bytes);
      auto c = room ? cache.find(k) : cache.end();
      if (c == cache.end() || c->second.state != EntryState::kReady) {
        still_pending.push_back(k);
        continue;
      }
      c->second.gpu = true;
      victims_dirty = true;  // it may be scored for eviction now
      gpu.insert(k);
      counters(k).gpu_handoffs++;
      out[k.layer].tiles.push_back({k.key, c->second.rgba});
      ++tiles;
      bytes += tile_bytes;
    }
    pending.swap(still_pending);
    // A budget of 0 hands nothing and tells nothing of the renderer's rate.
    if (max_tiles > 0) upload_budget = max_tiles;
    setReadAllowance(upload_budget);
  }
  work_cv.notify_all();  // the loaders may read again

  for (uint32_t i = 0; i < layer_count; ++i) {
    Layer& layer = layers[i];
    FrameHandoff& h = out[i];
    h.max_texture_lod = config.throttle ? servedLod(layer, i) : layer.plan.finest_level;
    {
      std::lock_guard<std::mutex> lock(mutex);
      layer.published_lod = h.max_texture_lod;
    }

    h.residency.reserve(layer.plan.stack.size());
    for (const ClipLevelPlan& lp : layer.plan.stack) {
      LevelResidency r;
      r.level = lp.level;
      r.window = lp.window;
      r.resident.assign(size_t(lp.window.width() * lp.window.height()), 0);
      if (lp.needed) {
        size_t j = 0;
        for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
          for (int64_t x = lp.window.x0; x < lp.window.x1; ++x, ++j)
            r.resident[j] = gpu.count({i, {lp.level, uint32_t(x), uint32_t(y)}}) ? 1 : 0;
        if (!lp.sampled.empty()) {
          r.unread.assign(r.resident.size(), 0);
          j = 0;
          for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
            for (int64_t x = lp.window.x0; x < lp.window.x1; ++x, ++j) r.unread[j] = lp.wants(x, y) ? 0 : 1;
        }
      }
      h.residency.push_back(std::move(r));
    }
  }
  return out;
}

FrameHandoff Streamer::takeReady(size_t max_tiles, size_t max_bytes) {
  Impl& s = *m_impl;
  if (s.layers.empty()) return {};
  return std::move(s.handOff(1, max_tiles, max_bytes).front());
}

std::vector<FrameHandoff> Streamer::takeReadyAll(size_t max_tiles, size_t max_bytes) {
  Impl& s = *m_impl;
  return s.handOff(s.layers.size(), max_tiles, max_bytes);
}

void Streamer::setGroundRelief(double above, double below) {
  Impl& s = *m_impl;
  s.config.planner.ground_above = std::isfinite(above) ? std::max(above, 0.0) : 0.0;
  s.config.planner.ground_below = std::isfinite(below) ? std::max(below, 0.0) : 0.0;
}

void Streamer::setPathHint(PathHint hint) {
  Impl& s = *m_impl;
  s.hint = std::move(hint);
  for (Impl::Layer& layer : s.layers) {
    layer.lookahead.reset();
    layer.hint = s.hint;
    if (s.hint.camera_at) {
      // The layer's lookahead plans in its texels: the hinted camera mapped.
      StreamLayer map = layer.spec;
      map.source = nullptr;
      layer.hint.camera_at = [camera_at = s.hint.camera_at, map](double t_s) {
        return layerCamera(map, camera_at(t_s));
      };
    }
  }
  s.hint_used = false;
  s.force_rebuild = true;  // the next update() plans with (or without) the new hint
  std::lock_guard<std::mutex> lock(s.mutex);
  for (Impl::Layer& layer : s.layers) layer.ahead = nullptr;  // no eviction by the old path meanwhile
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
}

const ClipmapPlan& Streamer::plan(size_t layer) const {
  const Impl& s = *m_impl;
  assert(layer < s.layers.size() || (layer == 0 && s.layers.empty()));
  return layer < s.layers.size() ? s.layers[layer].plan : kNoPlan;
}

bool Streamer::settled() const {
  const Impl& s = *m_impl;
  if (!s.have_plan) return false;
  std::lock_guard<std::mutex> lock(s.mutex);
  for (const LayerTile& k : s.pending) {
    const auto f = s.failed.find(k);
    if (f == s.failed.end() || f->second.code == ErrorCode::kUnavailable) return false;
  }
  return true;
}

namespace {

void addCounters(const LevelCounters& c, LevelCounters* sum) {
  sum->requests += c.requests;
  sum->ram_hits += c.ram_hits;
  sum->ram_misses += c.ram_misses;
  sum->gpu_reentries += c.gpu_reentries;
  sum->gpu_handoffs += c.gpu_handoffs;
  sum->cancellations += c.cancellations;
  sum->evictions += c.evictions;
  sum->redundant_reads += c.redundant_reads;
  sum->bytes_read += c.bytes_read;
  sum->failures += c.failures;
  sum->loads += c.loads;
  sum->budget_skips += c.budget_skips;
}

}  // namespace

StreamerStats Streamer::stats() const {
  const Impl& s = *m_impl;
  StreamerStats out;
  std::vector<double> lat;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    out.layers.resize(s.layers.size());
    for (size_t i = 0; i < s.layers.size(); ++i) {
      const Impl::Layer& layer = s.layers[i];
      LayerStats& ls = out.layers[i];
      ls.levels = layer.counters;
      ls.ram_bytes = layer.ram_bytes;
      ls.ram_entries = layer.ram_entries;
      ls.max_texture_lod = layer.published_lod;
    }
    out.ram_bytes = s.ram_bytes;
    out.ram_peak_bytes = s.ram_peak;
    out.queue_depth = s.queue.size();
    out.in_flight = s.in_flight;
    out.decode_ms_total = s.decode_ms_total;
    out.max_texture_lod = s.layers.empty() ? 0 : s.layers[0].published_lod;
    out.ram_entries = s.cache.size();
    out.path_hint_frames = s.hint_frames;
    out.path_hint_ignored_frames = s.hint_ignored_frames;
    out.loader_threads = s.loader_threads;
    lat = s.latency_ms;
  }
  out.ram_budget_bytes = s.config.ram_budget_bytes;
  out.entry_overhead_bytes = kCacheEntryOverheadBytes;
  for (LayerStats& ls : out.layers) {
    if (out.levels.size() < ls.levels.size()) out.levels.resize(ls.levels.size());
    for (size_t l = 0; l < ls.levels.size(); ++l) {
      addCounters(ls.levels[l], &ls.total);
      addCounters(ls.levels[l], &out.levels[l]);
    }
  }
  for (const LevelCounters& c : out.levels) addCounters(c, &out.total);
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
  for (const Request& r : s.queue) out.push_back(r.key.key);
  return out;
}

std::vector<LayerTile> Streamer::queuedLayerTiles() const {
  const Impl& s = *m_impl;
  std::lock_guard<std::mutex> lock(s.mutex);
  std::vector<LayerTile> out;
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
      for (const Request& r : s.queue) s.counters(r.key).cancellations++;
      s.queue.clear();
    }
  }
  s.work_cv.notify_all();
  // Workers finish the read they are in, publish it, then see `stopping`
  // (with deterministic I/O: finish every ticket issued, which this thread
  // then publishes).
  for (std::thread& t : s.workers)
    if (t.joinable()) t.join();
  s.workers.clear();
  s.publishDueReads(true);
  s.flushTrace(true);
}

}  // namespace clipstream
