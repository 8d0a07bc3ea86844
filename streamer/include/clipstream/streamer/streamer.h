// The streamer: plans what each frame needs, loads tiles on worker threads
// into a RAM cache with a hard byte budget, and hands ready tiles to the
// renderer under a per-frame budget. No GL here.
//
// A streamer serves a scene of layers (colour, elevation; StreamLayer):
// each layer has its own clip stack, planned from the camera mapped into
// its texels, with its own residency and MaxTextureLOD; all layers share
// one RAM cache, one hard byte budget, one load queue and one priority
// order (docs/architecture.md, "Layers"). The one-source constructor is a
// scene of one colour layer.
//
// Thread rule: update(), takeReady(), takeReadyAll(), setPathHint(),
// resetGpuResidency(), plan() and settled() are for the render thread only
// and never block on I/O (no source call ever runs on it; nor does
// PathHint::camera_at run anywhere else), except that with
// DeterministicIo::enabled update() waits for the reads due that frame
// (a benchmark mode; the source is still only called on the workers). stats(), queuedTiles() and
// queuedLayerTiles() are thread-safe; layerCount(), layer(), geometry(),
// plansOnTerrain() and terrainBounds() return what the constructor fixed,
// on any thread.
// Shutdown order: shutdown() stops accepting work, cancels queued requests,
// lets in-flight reads finish, joins the workers; the destructor calls it.
#pragma once

#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/stats.h>
#include <clipstream/streamer/terrain_bounds.h>
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

// Deterministic I/O (DeterministicIo): the simulated device's defaults.
// 16 reads a frame is 960 tiles/s at 60 frames/s (60 MiB/s of 128-px RGBA8
// tiles): what two loaders on 2 busy cores delivered in real time on the
// sweep's line at x100 (3756 loads in 240 frames, 15.6 a frame), so the
// deterministic speed curve falls where the real-time one does (99 dB to
// x20, 98 at x50, 42 at x100 against 51-57 in real time; 8 reads a frame
// already lost x20: 92.6 dB; docs/benchmarks.md, "Repeatable sweeps").
// 2 frames of latency: a tile asked for in frame f is drawn from frame
// f + 2 at the earliest, one frame later than a real read that lands
// while frame f draws.
inline constexpr uint32_t kDefaultIoReadsPerFrame = 16;
inline constexpr uint32_t kDefaultIoLatencyFrames = 2;

// A benchmark mode in which a run gives the same frames every time, on any
// machine (docs/architecture.md, "Deterministic I/O"). The loader threads
// still read and decode every tile, but the render thread decides, on a
// simulated I/O clock counted in update() calls, what is read and when it
// lands: each update() issues at most reads_per_frame requests from the
// front of the load queue (admitted, with room made, on the render thread),
// and a request issued in frame f becomes a tile in RAM in update() of
// frame f + latency_frames, which waits for its real read if it has not
// finished. Results then depend on the request order only, never on thread
// timing; frame times still measure the machine. Off (the default) the
// loaders take requests as fast as they can, as an application wants.
struct DeterministicIo {
  bool enabled = false;
  uint32_t reads_per_frame = kDefaultIoReadsPerFrame;  // at least 1 (0 counts as 1)
  uint32_t latency_frames = kDefaultIoLatencyFrames;   // at least 1 (0 counts as 1)
};

struct StreamerConfig {
  uint64_t ram_budget_bytes = uint64_t(256) << 20;  // hard: never exceeded
  unsigned io_threads = 0;       // 0 = the source's suggestion (a URL store: one per
                                 // connection), else the number of cores; at most kMaxIoThreads
  bool prefetch = true;          // velocity-predictive prefetch
  bool frustum_priority = true;  // visible tiles before hidden ones
  // Throttling (docs/decisions.md D60, D61): reads no further ahead of
  // the uploads than throttle_read_ahead_frames of the hand-off budget, and
  // MaxTextureLOD as the finest level streaming serves. Off: reads as fast
  // as the loaders go, MaxTextureLOD the plan's finest level.
  bool throttle = true;
  // Plan against an elevation layer's per-tile height bounds when it has
  // them (StreamLayer::world_per_height, plansOnTerrain()). false: against
  // the plane, with the relief planes a caller sets (setGroundRelief()):
  // nothing read at open, but more tiles loaded over relief (measured in
  // docs/terrain.md, "Planning against the terrain").
  bool terrain_bounds = true;
  // With throttling: at most this many frames of the upload budget (the
  // last non-zero max_tiles of takeReady()), and never fewer than
  // throttle_read_ahead_min_tiles, wait in RAM, or on their way, for the
  // GPU; past that the loaders wait (docs/decisions.md D61, D299).
  // 4 frames: over terrain the wanted set turns over faster than 16
  // uploads a frame take it, and with 32 frames (512 tiles) the loaders
  // read 68 tiles a frame on Rainier's mountainside, 4 for each upload, on
  // the cores llvmpipe draws with: its frame 58.6 ms against 46.4 with 4
  // frames (27 tiles a frame), the same PSNR. 32 tiles at least: at one
  // upload a frame the tiles read ahead are the ones the uploads need next,
  // and 8 cost 2 dB there.
  uint32_t throttle_read_ahead_frames = 4;
  uint32_t throttle_read_ahead_min_tiles = 32;
  PlannerConfig planner;
  // Non-empty: record the request stream here (written under OutputFile's
  // rule: a temporary name, published at shutdown(); a regular file there
  // is replaced). See traceStatus().
  std::string trace_path;
  double prefetch_ahead_s = 0.5; // how far ahead the predicted camera is placed
  EvictionMode eviction = EvictionMode::kGpuFirst;
  // Off by default: loads land as fast as the loaders read them.
  DeterministicIo deterministic_io;
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

// A decoded tile ready for upload, tileContentBytes() of its layer's
// source: RGBA8 or BC1 blocks for a colour layer, float32 heights for an
// elevation layer (TileContent).
struct ReadyTile {
  TileKey key;
  std::shared_ptr<const std::vector<uint8_t>> rgba;
};

// Which tiles of a level's clip window are handed to the GPU.
struct LevelResidency {
  uint32_t level = 0;
  TileRect window;
  std::vector<uint8_t> resident;  // window.width() * window.height(), row-major, 1 = handed off
  // Window tiles no filter reads this frame, row-major like `resident` (1 =
  // unread): the plan does not want them (PlanScope::kSampled wants every
  // tile a tap of the frame reads), so a missing one does not keep its
  // neighbours from being drawn (computeUsableMap()). Empty: any window
  // tile may be read.
  std::vector<uint8_t> unread;
};

// One layer's hand-off for a frame. Levels, tiles and windows are the
// layer's own (its store's pyramid).
struct FrameHandoff {
  std::vector<ReadyTile> tiles;           // upload all of these this frame, in order
  uint32_t max_texture_lod = 0;           // finest level the shader may sample
  std::vector<LevelResidency> residency;  // stack levels, after these tiles
  uint32_t layer = 0;                     // which layer of the streamer
};

// What a layer is to the scene. Colour layers are textures; elevation
// layers hold the heights the geometry is made of. Among tiles equally
// coarse in world space, elevation loads first: a missing height is a hole
// or a wrong silhouette, a missing colour texel only a blurrier one.
enum class LayerRole : uint8_t { kColour, kElevation };

// One layer of a scene: a source, its role and where it lies in the world.
// World space is that of camera.h: x and z in the colour layer's level-0
// texels, y up. The layer's level-0 texel under world point (x, z) is
//   origin_texel + texels_per_unit * (x, z)      (component-wise),
// so a DEM of 30 m samples under a 1 m orthophoto has texels_per_unit 1/30
// and origin_texel = the orthophoto's top-left corner in DEM samples.
// texels_per_unit must be finite and > 0 (checkStreamLayers()).
struct StreamLayer {
  std::shared_ptr<TileSource> source;
  LayerRole role = LayerRole::kColour;
  glm::dvec2 texels_per_unit{1.0, 1.0};
  glm::dvec2 origin_texel{0.0, 0.0};
  // Clip size of this layer's windows (tiles a side); 0: the streamer's
  // PlannerConfig::clip_tiles. A renderer that reads less than a
  // viewport's worth of a layer (the terrain's rings read about n samples
  // per level) asks for less, and the layer costs that much less memory.
  uint32_t clip_tiles = 0;
  // Elevation layers: world units per height unit, the vertical scale
  // included (LayerAlignment::world_per_height). When > 0 and the source
  // has per-tile height bounds (TileSource::tileHeightBounds()), the
  // streamer loads them when it is made and plans every layer against the
  // terrain (plansOnTerrain()); 0: layers are planned against the plane
  // y = 0. Finite and >= 0 (checkStreamLayers()).
  double world_per_height = 0.0;
};

// Ok when every layer can be streamed: a source; a finite, positive map;
// a colour layer's source hands out RGBA8 or BC1 and an elevation layer's heights
// (TileContent). Otherwise kInvalidArgument naming the layer and the
// problem. The Streamer constructor runs it and leaves a failing layer
// empty (it plans and loads nothing, and the reason goes to stderr), so an
// application checks first to report the problem itself.
Status checkStreamLayers(const std::vector<StreamLayer>& layers);

// The world camera as `layer` sees it: position (x, z) mapped into the
// layer's level-0 texels; height and near distance multiplied by the
// layer's mean scale s = sqrt(texels_per_unit.x * texels_per_unit.y);
// heading, pitch and field of view unchanged. For a map of equal scales on
// both axes (square texels on both layers, the georeferenced case) this is
// the same view in the layer's units, so the planner's pixel footprints and
// windows are exact; for unequal scales the height uses their geometric
// mean. The identity map returns the camera unchanged. Pure.
Camera layerCamera(const StreamLayer& layer, const Camera& world);

// A tile of one layer of the streamer.
struct LayerTile {
  uint32_t layer = 0;
  TileKey key;
  friend bool operator==(const LayerTile&, const LayerTile&) = default;
};

class Streamer {
 public:
  // One colour layer with the identity map: the texture streamer.
  Streamer(std::shared_ptr<TileSource> source, const StreamerConfig& config);
  // A scene of layers, in this order (layer 0 is what takeReady(), plan()
  // and geometry() without an index mean). Layers failing
  // checkStreamLayers() stay empty. An empty list streams nothing.
  Streamer(std::vector<StreamLayer> layers, const StreamerConfig& config);
  ~Streamer();
  Streamer(const Streamer&) = delete;
  Streamer& operator=(const Streamer&) = delete;

  size_t layerCount() const;
  // Layer `layer` as given to the constructor (source null if it failed
  // checkStreamLayers()). layer < layerCount().
  const StreamLayer& layer(size_t layer) const;
  // The layer's pyramid (empty for an empty layer). layer < layerCount(),
  // or 0 on a streamer without layers (an empty geometry).
  const PyramidGeometry& geometry(size_t layer = 0) const;

  // Render thread. Plans every layer for this (world) camera, queues what
  // is missing, cancels what the plans no longer need, and queues predicted
  // tiles at low priority. With DeterministicIo::enabled it first publishes
  // the reads due this frame (waiting for them) and last issues this
  // frame's reads.
  void update(const Camera& camera, const Viewport& viewport, double time_s);

  // Render thread. Sets (or, with an empty camera_at, clears) the path hint.
  void setPathHint(PathHint hint);

  // Render thread. Terrain without per-tile bounds: how far the ground
  // within view rises above and falls below the plane of the camera's
  // ground (world units), for the next update()s' plans
  // (PlannerConfig::ground_above / ground_below, scaled into each layer's
  // texels). 0 and 0 (the default): flat. Ignored while plansOnTerrain().
  void setGroundRelief(double above, double below);

  // Render thread. The ground the last drawn frame showed, in world space
  // (GroundSeen, read back by TerrainRenderer::readGroundSeen()): over
  // terrain with PlanScope::kSampled the next update()s plan each colour
  // layer's windows to the tiles under it (the elevation layers are planned
  // by what the geometry reads: setHeightReads()). Null clears it:
  // whole windows, as after a jump of the camera, when the last frame's
  // ground says nothing of the next one's. Ignored over the flat plane.
  void setGroundSeen(std::shared_ptr<const GroundSeen> seen);

  // Render thread. The samples of the elevation layer the terrain's
  // geometry read to draw the last frame, and those it would have read
  // had they been resident (HeightReads, TerrainRenderer::heightReads();
  // rects in the elevation layer's own samples, the camera in world
  // space): with PlanScope::kSampled the next update()s plan each
  // elevation layer's windows to the tiles under them, swept to the
  // camera being planned (markHeightReads()). Null clears it: whole
  // windows, as after a jump of the camera.
  void setHeightReads(std::shared_ptr<const HeightReads> reads);

  // True when the constructor loaded an elevation layer's per-tile height
  // bounds (StreamLayer::world_per_height > 0 and a source that has them):
  // every layer is then planned against the terrain, and update()'s camera
  // must be the real one (its y the height in world units, not the height
  // above the ground). Fixed at construction; any thread.
  bool plansOnTerrain() const;

  // The per-tile height bounds the constructor read for the planner
  // (loadTerrainBounds() of the first elevation layer with world_per_height
  // > 0, once); null when it read none (plansOnTerrain() false). A renderer
  // that refines by them (the quadtree) takes these rather than reading
  // the index again. Fixed at construction; any thread. The bounds are
  // immutable and shared read-only (terrain_bounds.h's rule).
  std::shared_ptr<const TerrainBounds> terrainBounds() const;

  // Render thread. Layer 0's hand-off: up to max_tiles tiles and max_bytes
  // bytes (0 = no byte limit) of layer 0 that are decoded and needed, in
  // priority order; marks them as resident on the GPU. Also layer 0's
  // MaxTextureLOD and residency after them. Other layers' tiles stay
  // pending (takeReadyAll() serves every layer).
  FrameHandoff takeReady(size_t max_tiles, size_t max_bytes = 0);

  // Render thread. Every layer's hand-off, one FrameHandoff per layer
  // (index = layer): the ready tiles of all layers share max_tiles and
  // max_bytes (0 = no byte limit) and are taken in the one priority order,
  // so a tight per-frame budget goes to the coarsest tiles of every layer
  // first. Each layer's MaxTextureLOD and residency come after its tiles.
  std::vector<FrameHandoff> takeReadyAll(size_t max_tiles, size_t max_bytes = 0);

  // Render thread. Forgets GPU residency of every layer (e.g. after the
  // renderer recreates its textures on a viewport resize); tiles are handed
  // off again.
  void resetGpuResidency();

  // Render thread. The layer's plan of the last update(), in its texels.
  // layer < layerCount() (or 0 on a streamer without layers).
  const ClipmapPlan& plan(size_t layer = 0) const;

  // True when every tile the current plans need is handed off (tiles that
  // failed and are not being retried count as done).
  bool settled() const;

  StreamerStats stats() const;  // thread-safe snapshot

  // Thread-safe. Snapshot of the load queue, front (next to load) first:
  // for diagnostics overlays and tests of priority and prefetch.
  // queuedTiles() lists the keys of every layer without saying which.
  std::vector<TileKey> queuedTiles() const;
  std::vector<LayerTile> queuedLayerTiles() const;
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
