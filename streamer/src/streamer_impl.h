// The streamer's state, Streamer::Impl, shared by its two halves:
// streamer.cpp, the render thread's (planning, the queue's order, the
// hand-off, statistics), and streamer_load.cpp, the loaders' (admitting,
// reading and publishing tiles, the deterministic I/O device's tickets,
// the throttle). Internal to the library.
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
// and hands them to the workers as tickets of the I/O device (io_device.h),
// which publishes them in the update() of their due frame.
//
// Layers: every key in the shared maps is a LayerTile (layer, level, x, y).
// Each layer keeps its own plan, windows, counters and MaxTextureLOD; the
// cache, the budget, the queue and the rank order are one for all layers.
#pragma once

#include <clipstream/streamer/streamer.h>

#include "eviction.h"
#include "io_device.h"
#include "layer_tile_hash.h"
#include "loader_pool.h"
#include "lookahead.h"
#include "motion.h"
#include "ram_cache.h"
#include "trace_recorder.h"

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <limits>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

namespace clipstream {

// checkStreamLayers() for one layer, named by its index in the scene
// (stream_layer.cpp).
Status checkStreamLayer(const StreamLayer& layer, size_t index);

struct Streamer::Impl {
  using Clock = std::chrono::steady_clock;

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
    std::shared_ptr<const GroundSeen> seen;  // colour layers: the last frame's ground in its texels
    std::shared_ptr<const HeightReads> reads;  // elevation layers: the geometry's last reads (its camera mapped)
    PathHint hint;              // the streamer's hint seen through layerCamera()
    PathLookahead lookahead;    // windows along that hint

    // Guarded by the streamer's mutex.
    std::vector<LevelCounters> counters;
    uint32_t published_lod = 0;

    bool active() const { return spec.source && geometry.levelCount() != 0; }
    // The layer's planner settings; `with_seen` false leaves the ground the
    // last frame showed out (whole windows over terrain): for the path
    // hint's lookahead, seconds ahead, where that frame's ground says
    // little of what the view will show.
    PlannerConfig planner(const PlannerConfig& base, bool with_seen = true) const {
      PlannerConfig c = base;
      if (spec.clip_tiles != 0) c.clip_tiles = spec.clip_tiles;
      c.terrain = terrain;
      if (with_seen) {
        c.seen = seen;
        c.reads = reads;
      }
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
  MotionPredictor motion;
  PathHint hint;               // camera_at empty: none
  bool hint_used = false;      // this frame's plans came with a trusted hint
  bool hint_used_by_plan = false;  // the last rebuild's
  std::vector<LayerTile> wanted;                         // plan tiles, rank order
  std::unordered_set<LayerTile, FastKeyHash> wanted_set; // same, for lookups
  std::vector<LayerTile> prefetch;                       // predicted tiles, after wanted
  std::unordered_set<LayerTile, FastKeyHash> gpu;        // handed off and still wanted
  std::vector<LayerTile> pending;                        // wanted, not yet handed off (rank order)
  uint64_t upload_budget = 0;  // the last non-zero hand-off budget (tiles); 0: none seen
  uint32_t loader_threads = 0;  // set once by the constructor
  TraceRecorder trace;          // layer 0's requests (the format has no layer field)

  // Shared; guarded by mutex.
  mutable std::mutex mutex;
  std::condition_variable work_cv;
  std::deque<Request> queue;  // rank order, front first
  // Reads the throttle still allows until the next hand-off (setReadAllowance());
  // the loaders and issueReads() take one per tile they read.
  int64_t read_allowance = std::numeric_limits<int64_t>::max();
  std::unique_ptr<RamCache> cache;  // made by the constructor
  std::unordered_map<LayerTile, FailedTile, FastKeyHash> failed;
  std::unordered_set<LayerTile, FastKeyHash> ever_read;
  uint64_t in_flight = 0;
  double decode_ms_total = 0.0;
  std::vector<double> latency_ms;  // ring of the last kLatencySamples
  size_t latency_next = 0;
  uint32_t logged_failures = 0;
  uint64_t hint_frames = 0;
  uint64_t hint_ignored_frames = 0;
  // Detail of terrain tiles the loaders read since the last update().
  std::vector<std::pair<TileKey, std::shared_ptr<const TileDetail>>> new_detail;
  double shared_now_s = 0.0;  // copy of now_s for workers (retry times)
  uint64_t shared_frame = 0;  // copy of frame for workers
  bool stopping = false;
  IoDevice io;  // deterministic I/O only
  bool deterministic() const { return config.deterministic_io.enabled; }

  LoaderPool loaders;

  LevelCounters& counters(const LayerTile& t) { return layers[t.layer].counters[t.key.level]; }
  void loadTerrain();
  void workerLoop();
  void readTicket(std::unique_lock<std::mutex>& lock, std::vector<float>* floats);
  void gatherBatch(const Request& request, std::vector<LayerTile>* tiles, std::vector<bool>* rereads);
  std::shared_ptr<const TileDetail> detailOf(const Layer& layer, const LayerTile& key, const Status& status,
                                             const std::vector<uint8_t>& pixels, std::vector<float>* floats) const;
  void publishLocked(const LayerTile& key, const Status& status, std::shared_ptr<std::vector<uint8_t>> pixels,
                     const FetchInfo& info, bool reread, std::shared_ptr<const TileDetail> tile_detail);
  void publishDueReads(bool all);
  void issueReads();
  bool admit(const Request& request, bool neighbour, bool* reread, bool* no_room);
  std::vector<LayerTile> rankScene() const;
  std::vector<LayerTile> rankPrefetch(const std::unordered_set<LayerTile, FastKeyHash>& wanted_now) const;
  void rebuild(const Viewport& viewport);
  bool requeue(const std::vector<LayerTile>& new_wanted, const std::vector<LayerTile>& new_prefetch,
               RamCache::Ranks new_rank, std::vector<PlanWindows> new_windows,
               std::vector<PlanWindows> new_predicted,
               std::vector<std::shared_ptr<const LookaheadSnapshot>> new_ahead);
  std::vector<ClipmapPlan> predictPlans(const Camera& camera, const Viewport& viewport, double time_s,
                                        const std::vector<ClipmapPlan>& next);
  void planAll(const Camera& cam, const Viewport& viewport, std::vector<ClipmapPlan>* plans) const;
  bool trustHint(const Viewport& viewport, double time_s, const std::vector<ClipmapPlan>& next);
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
  void layerResidency(uint32_t index, FrameHandoff* h) const;
};

}  // namespace clipstream
