// The streamer: plans what each frame needs, loads tiles on worker threads
// into a RAM cache with a hard byte budget, and hands ready tiles to the
// renderer under a per-frame budget. No GL here.
//
// Thread rule: update(), takeReady(), setPathHint(), resetGpuResidency(),
// plan() and settled() are for the render thread only and never block on
// I/O (no source call ever runs on it; nor does PathHint::camera_at run
// anywhere else). stats() and queuedTiles() are thread-safe.
// Shutdown order: shutdown() stops accepting work, cancels queued requests,
// lets in-flight reads finish, joins the workers; the destructor calls it.
#pragma once

#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/stats.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace clipstream {

// What the RAM cache does with tiles that are on the GPU and still inside a
// window (docs/architecture.md, "Eviction"). kGpuFirst is the default: on
// the benchmark flights at 256-512 MiB it gets 3-13x the RAM hits of
// kProtectGpu, because such a tile cannot be wanted again before it leaves
// its window; kProtectGpu trades that for re-uploading from RAM after a
// renderer resize (resetGpuResidency()).
enum class EvictionMode : uint8_t {
  kGpuFirst,     // evict them first (pyramid tiles before all): RAM is a victim cache behind the GPU
  kProtectGpu,   // keep them longest, after every tile outside the windows; pyramid tiles kept
};

// Most loader threads a streamer starts: reads in flight beyond this gain
// nothing even on a slow network disk, and each thread costs a stack.
inline constexpr unsigned kMaxIoThreads = 256;

struct StreamerConfig {
  uint64_t ram_budget_bytes = uint64_t(256) << 20;  // hard: never exceeded
  unsigned io_threads = 0;       // 0 = the source's suggestion (a URL store: one per
                                 // connection), else the number of cores; at most kMaxIoThreads
  bool prefetch = true;          // velocity-predictive prefetch
  bool frustum_priority = true;  // visible tiles before hidden ones
  bool throttle = true;          // compute MaxTextureLOD from residency
  uint32_t lod_hysteresis_frames = 8;  // frames a finer LOD must be ready before use
  // A stack level is ready for MaxTextureLOD when at least this fraction of
  // its visible tiles is on the GPU (or failed for good); the rest are drawn
  // from their ancestors per tile. 1 = every visible tile (strict). 0.5 was
  // measured best (docs/decisions.md, Streamer).
  double lod_min_coverage = 0.5;
  PlannerConfig planner;
  // Non-empty: record the request stream here (written under OutputFile's
  // rule: a temporary name, published at shutdown(); a regular file there
  // is replaced). See traceStatus().
  std::string trace_path;
  double prefetch_ahead_s = 0.5; // how far ahead the predicted camera is placed
  EvictionMode eviction = EvictionMode::kGpuFirst;
  // Test hook: called after every RAM insert (placeholder reservation) with
  // the accounted bytes and the budget, under the cache lock, on the thread
  // that inserted. Must not call back into the streamer.
  std::function<void(uint64_t ram_bytes, uint64_t budget_bytes)> on_ram_insert;
};

// The camera's future, for applications that know it: a scripted flight, a
// camera spline, a guided tour. Optional; without it the streamer predicts
// from the camera's recent motion only. While the hinted camera agrees with
// the one passed to update() (the same clip windows, within a tile per
// level), the streamer uses it
//  - for eviction: tiles are kept by when the hinted path next needs them
//    (EvictionMode::kGpuFirst only), and
//  - for prefetch: the predicted plan is the hinted camera's at
//    time_s + prefetch_ahead_s, so a jump in the path is prefetched too.
// When they disagree the hint is ignored for that frame (counted in
// StreamerStats::path_hint_ignored_frames) and the streamer behaves as if
// it had none.
struct PathHint {
  // The camera at time t_s, on the clock of update()'s time_s. Called on the
  // render thread only, from update(): at time_s, at time_s +
  // prefetch_ahead_s, and on the sample grid up to horizon_s ahead. It must
  // not call back into the streamer. A pose with a non-finite field ends the
  // hinted path there (at time_s: the hint is not used that frame).
  std::function<Camera(double t_s)> camera_at;
  // How far ahead eviction looks: at most 1024 samples (68 s at the default
  // step); a non-finite value means the default, a negative one 0.
  double horizon_s = 5.0;
  // Spacing of the planned poses; below 1 ms or non-finite: the default.
  double step_s = 1.0 / 15.0;
};

// Bytes counted per RAM cache entry on top of its RGBA payload: the map
// node, key, shared_ptr control block and vector header, rounded up.
constexpr uint64_t kCacheEntryOverheadBytes = 256;

// A decoded tile ready for upload: RGBA8, tile_px * tile_px * 4 bytes.
struct ReadyTile {
  TileKey key;
  std::shared_ptr<const std::vector<uint8_t>> rgba;
};

// Which tiles of a level's clip window are handed to the GPU.
struct LevelResidency {
  uint32_t level = 0;
  TileRect window;
  std::vector<uint8_t> resident;  // window.width() * window.height(), row-major, 1 = handed off
};

struct FrameHandoff {
  std::vector<ReadyTile> tiles;           // upload all of these this frame, in order
  uint32_t max_texture_lod = 0;           // finest level the shader may sample
  std::vector<LevelResidency> residency;  // stack levels, after these tiles
};

class Streamer {
 public:
  Streamer(std::shared_ptr<TileSource> source, const StreamerConfig& config);
  ~Streamer();
  Streamer(const Streamer&) = delete;
  Streamer& operator=(const Streamer&) = delete;

  const PyramidGeometry& geometry() const;

  // Render thread. Plans for this camera, queues what is missing, cancels
  // what the plan no longer needs, and queues predicted tiles at low priority.
  void update(const Camera& camera, const Viewport& viewport, double time_s);

  // Render thread. Sets (or, with an empty camera_at, clears) the path hint.
  void setPathHint(PathHint hint);

  // Render thread. Up to max_tiles tiles and max_bytes bytes (0 = no byte
  // limit) that are decoded and needed, in priority order; marks them as
  // resident on the GPU. Also the MaxTextureLOD and residency after them.
  FrameHandoff takeReady(size_t max_tiles, size_t max_bytes = 0);

  // Render thread. Forgets GPU residency (e.g. after the renderer recreates
  // its textures on a viewport resize); tiles are handed off again.
  void resetGpuResidency();

  const ClipmapPlan& plan() const;

  // True when every tile the current plan needs is handed off (tiles that
  // failed and are not being retried count as done).
  bool settled() const;

  StreamerStats stats() const;  // thread-safe snapshot

  // Thread-safe. Snapshot of the load queue, front (next to load) first:
  // for diagnostics overlays and tests of priority and prefetch.
  std::vector<TileKey> queuedTiles() const;
  // Render thread. Stops and joins the loader threads, then publishes the
  // trace (if any). Idempotent; the destructor calls it.
  void shutdown();

  // Render thread. Ok without a trace; else why the trace could not be
  // created or, after shutdown(), written and published (kIo / kNoSpace /
  // kAlreadyExists naming the path).
  Status traceStatus() const;

  // Render thread. Drops the trace being recorded: nothing is published at
  // shutdown() (a run that failed leaves no trace that looks whole).
  void discardTrace();

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

}  // namespace clipstream
