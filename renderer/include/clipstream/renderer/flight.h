// The frame loop's one step: a streamer and a clipmap renderer driven
// together, one frame per step(), with the frame's timings, per-level
// counter deltas and GPU hits. clipstream-fly, the stability scenarios and
// the sweep (through eval's runFlight) and clipstream-view fly through this
// class; a host that wants its own loop uses Streamer and ClipmapRenderer
// directly (docs/api.md), as Flight does.
//
// The rules every flight follows (docs/architecture.md, "Frame loop"):
// - Clock: step n (counted from the first step, warm-up included) runs the
//   streamer at n * kSimulatedFrameSeconds unless the host passes its own
//   clock (an interactive viewer passes wall time).
// - Warm-up: the first FlightConfig::warmup_frames steps are warm-up: they
//   stream and draw like any frame but are flagged, and their counters are
//   folded into warmupLoads() rather than a recorded frame.
// - Cut: a recorded frame is a cut when it is the first recorded frame and
//   no warm-up preceded it, or when isCut() says the camera jumped.
// - Counters: a frame's streamer counters are sampled right after its
//   glFinish, before anything reads the frame back or judges it; reads that
//   land later count in the next frame.
//
// Thread rule: owned by the GL thread, like ClipmapRenderer: create it and
// call every method on the thread whose context is current. The streamer's
// workers read tiles; no step waits on I/O.
#pragma once

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/renderer/terrain.h>
#include <clipstream/store/remote.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/alignment.h>
#include <clipstream/streamer/look_at.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/stats.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace clipstream {

// Whether the camera jumped between two consecutive frames: it moved more
// than half its height above the ground AND more than 8 times the previous
// frame's movement (with at least one texel of that), or it turned (heading
// or pitch) by more than kCutTurnRad. A continuous path at any speed moves
// about as much each frame, so it never counts; a teleport or a snap turn
// (a step path) does.
inline constexpr double kCutTurnRad = 0.5235987755982988;  // 30 degrees: 1800 deg/s at 60 frames/s
bool isCut(const Camera& previous, const Camera& current, double previous_step_texels);

// The set-up every loop shares: plans the first frame for `camera`, creates
// the renderer with the plan's clip size and pyramid level, and loads the
// coarse pyramid from `source` on this thread before any frame, so every
// frame has something correct to draw (a tile that fails is filled from its
// ancestor and added to *failures, which may be null). The first frame's
// plan goes to *plan when given. The stack holds the source's content()
// (RGBA8 or BC1); `upload_tiles` sizes kStaged's staging regions;
// `memory` and `pool_bytes` are RendererConfig's (kPaged wants a planner
// with pyramid_tiles set: plannerFor(); pool_bytes 0 = defaultPoolBytes()
// for `viewport`). GL thread only.
Status createClipmapRenderer(TileSource& source, const Viewport& viewport, const Camera& camera,
                             const PlannerConfig& planner, Buffering buffering,
                             std::unique_ptr<ClipmapRenderer>* out, uint32_t* failures,
                             ClipmapPlan* plan = nullptr,
                             uint32_t upload_tiles = renderer_config::kDefaultUploadTilesPerFrame,
                             TextureMemory memory = TextureMemory::kStack, uint64_t pool_bytes = 0);

// Terrain under the colour layer: an elevation source (TileContent
// kHeightF32, e.g. openElevationSource()) and where it lies (alignElevation()).
struct TerrainLayerConfig {
  std::shared_ptr<TileSource> source;
  LayerAlignment alignment;
  uint32_t ring_cells = renderer_config::kTerrainRingCells;
  TerrainMethod method = TerrainMethod::kClipmap;       // --terrain
  double error_px = renderer_config::kTerrainErrorPx;   // quadtree: --terrain-error
  // Quadtree: --terrain-triangle-budget (TerrainConfig::triangle_budget; 0: none).
  uint64_t triangle_budget = renderer_config::kTerrainTriangleBudget;
  TerrainLighting lighting = TerrainLighting::kVertex;  // --terrain-lighting
  bool detail_textures = false;                         // --terrain-detail
  // Synthesized relief (synthesizeRelief()): the levels added below the
  // DEM's (0: none), and the DEM and its alignment as they were.
  uint32_t synthesized_levels = 0;
  std::shared_ptr<TileSource> data_source;
  LayerAlignment data_alignment;
};

// Synthesized relief below the DEM's resolution (--synthesize-relief,
// docs/terrain.md): replaces layer->source by makeSynthesizedHeightSource()
// of it with `levels` more levels and divides the alignment's spacing by
// 2^levels (sample 0 stays where it was), keeping the DEM in data_source.
// kInvalidArgument as makeSynthesizedHeightSource() says; `levels` 0 does
// nothing.
Status synthesizeRelief(uint32_t levels, TerrainLayerConfig* layer);

// The camera of --look-at (streamer/look_at.h): `look`'s map point in the
// colour layer's georeference (texels without one) and its height (given,
// else the terrain's ground there, else 0), seen from kLookAtDistanceFraction
// of the scene's larger side (`colour`'s), looking north, kLookAtPitchRad
// down. *camera_ground: the terrain's ground under the camera (0 without
// terrain), for a path whose heights are above the ground. Errors:
// mapToWorld()'s, groundHeightAt()'s.
Status aimAtMapPoint(const LookAt& look, const GeoReference& colour_geo, const PyramidGeometry& colour,
                     const TerrainLayerConfig* terrain, Camera* out, double* camera_ground);

// The terrain layer of a scene of two stores: opens `elevation_path` as a
// height source, reads both stores' headers and aligns the DEM under the
// colour layer (alignElevation(); `colour_path` empty: a colour layer of
// `colour_geometry` without georeference, e.g. a procedural texture).
// What the user should know (stretching, assumed units) goes to *warnings.
// Errors name the elevation store. Either path may be an http(s) URL, read
// with `remote`'s settings.
Status openTerrainLayer(const std::string& colour_path, const PyramidGeometry& colour_geometry,
                        const std::string& elevation_path, double vertical_scale, bool stretch,
                        uint32_t ring_cells, TerrainLayerConfig* out,
                        std::vector<std::string>* warnings, const RemoteOptions& remote = {});

struct FlightConfig {
  Viewport viewport{1280, 720};
  StreamerConfig streamer;
  uint32_t upload_tiles = renderer_config::kDefaultUploadTilesPerFrame;  // tiles handed to the GPU per frame
  Buffering buffering = kDefaultBuffering;
  // Where the colour tiles live on the GPU (renderer.h); kPaged sets the
  // planner's pyramid_tiles (when 0) to renderer_config::kPagedPyramidTiles
  // and does not draw terrain yet.
  TextureMemory texture_memory = TextureMemory::kStack;
  uint64_t pool_bytes = 0;  // kPaged: 0 = defaultPoolBytes() of the viewport
  Overlay overlay = Overlay::kOff;
  uint32_t warmup_frames = 0;          // the first steps are warm-up (see above)
  // true: draw into the flight's own OffscreenTarget (headless); false: into
  // the default framebuffer (a window) of size `framebuffer` (0x0: the
  // viewport), which the host presents.
  bool offscreen = true;
  Viewport framebuffer{0, 0};
  // With terrain the streamer serves two layers (colour, elevation) through
  // one cache, and the frame is drawn as a geometry clipmap (terrain.h).
  std::optional<TerrainLayerConfig> terrain;
};

// Counters of one level, or all levels, for one frame.
struct LevelFrame {
  uint64_t ram_hits = 0, ram_misses = 0, bytes_read = 0;
  uint32_t gpu_hits = 0, gpu_misses = 0;  // visible tiles of needed levels usable / not
};

// One frame. Counters are this frame's deltas, not running totals.
struct FrameSample {
  uint32_t frame = 0;         // recorded frame index (warm-up steps: 0-based warm-up index)
  bool warmup = false;
  bool cut = false;
  double clock_s = 0.0;       // the streamer's clock for this frame
  double frame_ms = 0.0;      // update .. draw finished on the GPU (glFinish)
  double cpu_ms = 0.0;        // the calling (render) thread's CPU time in the same span
  double streamer_ms = 0.0;   // update + takeReady
  double upload_ms = 0.0;     // the renderer's texture work
  double draw_ms = 0.0;       // draw until the GPU finished
  uint32_t tiles_uploaded = 0, second_copies = 0;
  // TextureMemory::kPaged: tiles the frame samples that got no page (the
  // pool was full of tiles this frame needs too): drawn coarser.
  uint32_t pages_short = 0;
  uint32_t pages_wanted = 0;  // kPaged: UploadStats::pages_wanted
  uint32_t max_texture_lod = 0, finest_needed = 0;
  uint64_t queue_depth = 0, in_flight = 0, ram_bytes = 0;
  uint64_t tiles_loaded = 0;  // tiles the loader read into RAM this frame
  std::vector<LevelFrame> levels;  // index = level (the colour layer's)
  LevelFrame total;
  // Terrain (zero without): what the geometry clipmap drew and uploaded.
  uint32_t terrain_rings = 0;
  uint32_t terrain_finest_level = 0;
  uint64_t terrain_triangles = 0;
  // Quadtree: the error bound the frame met (TerrainFrame::achieved_error_px)
  // and the node selection's time; 0 for the other methods.
  double terrain_error_px = 0.0;
  double terrain_select_ms = 0.0;
  uint32_t height_tiles_uploaded = 0;
  double ground_height = 0.0;  // world units under the camera (0 without terrain)
};

class Flight {
 public:
  // Creates the renderer for `first` (createClipmapRenderer()), the
  // offscreen target when asked, and the streamer. Errors: as from
  // ClipmapRenderer::create and OffscreenTarget::create.
  static Status create(std::shared_ptr<TileSource> source, const FlightConfig& config,
                       const Camera& first, std::unique_ptr<Flight>* out);
  ~Flight();
  Flight(const Flight&) = delete;
  Flight& operator=(const Flight&) = delete;

  // One frame on the simulated clock: streamer update and handoff, uploads,
  // draw, glFinish. With an offscreen target the frame is left there.
  FrameSample step(const Camera& camera);
  // The same on the host's clock (seconds, non-decreasing).
  FrameSample step(const Camera& camera, double clock_s);

  // A new viewport: a new renderer (the clip size follows the viewport) and
  // target, the pyramid loaded again, the streamer told that the GPU holds
  // nothing. `camera` is where the next frame looks from; `framebuffer` is
  // the window's new size when not offscreen (0x0: the viewport). On an
  // error the flight keeps its old viewport and target, with a renderer
  // for them made again; if even that fails, it must not be stepped again.
  Status resize(const Viewport& viewport, const Camera& camera, const Viewport& framebuffer = {0, 0});

  // Stops the streamer (joins its workers, publishes its trace) and returns
  // its final statistics. Steps after this are not allowed.
  StreamerStats finish();

  Streamer& streamer() { return *m_streamer; }
  const Streamer& streamer() const { return *m_streamer; }
  // Replaced by resize(): do not keep the reference across one.
  ClipmapRenderer& renderer() { return *m_renderer; }
  // Null without terrain.
  const TerrainRenderer* terrain() const { return m_terrain.get(); }
  TerrainRenderer* terrain() { return m_terrain.get(); }
  // The ground height (world units) at world (x, z) from the heights the
  // GPU holds (TerrainRenderer::groundHeight()); 0 and false without
  // terrain. The coarse height levels are loaded at create(), so over the
  // terrain's extent there is always an answer.
  bool groundHeight(const glm::dvec2& world_xz, double* height) const;
  const OffscreenTarget* target() const { return m_target.get(); }  // null unless offscreen
  const Viewport& viewport() const { return m_config.viewport; }
  const ClipmapPlan& firstPlan() const { return m_first_plan; }  // of create() or the last resize()
  double preloadMs() const { return m_preload_ms; }          // the first pyramid load
  uint32_t preloadFailures() const { return m_preload_failures; }  // every pyramid load
  uint32_t resizes() const { return m_resizes; }
  uint64_t warmupLoads() const { return m_warmup_loads; }    // tiles read during warm-up

 private:
  Flight() = default;
  // A renderer (and target) for `viewport`, into the members only when both
  // were made. Sets *preload_ms to the pyramid load's time.
  Status makeRenderer(const Viewport& viewport, const Camera& camera, double* preload_ms);
  Status makeTerrain();
  // The camera the streamer plans with for `camera` (step()'s rule), and
  // the ground height under it into *ground_height (0 without terrain).
  Camera planningCamera(const Camera& camera, double* ground_height);
  // Binds the frame's framebuffer (the offscreen target or the window's).
  void bindFrame();
  // Reads the ground the frame just drawn with `camera` showed into m_seen,
  // and the height samples its geometry read into m_reads (over terrain,
  // PlanScope::kSampled; docs/terrain.md "Over-fetch over terrain").
  void readGroundSeen(const Camera& camera);
  // Hands m_seen to the streamer for this frame's plans, moved into the
  // space of `planning`, the camera the streamer plans `camera` with, and
  // m_reads.
  void handGroundSeen(const Camera& camera, const Camera& planning);

  std::shared_ptr<TileSource> m_source;
  FlightConfig m_config;
  std::unique_ptr<ClipmapRenderer> m_renderer;
  std::unique_ptr<TerrainRenderer> m_terrain;
  std::unique_ptr<OffscreenTarget> m_target;
  std::unique_ptr<Streamer> m_streamer;
  // The elevation layer's per-tile bounds the quadtree refines by: the
  // streamer's (Streamer::terrainBounds()), or read here when the streamer
  // plans against the plane; null: none. Kept for resize().
  std::shared_ptr<const TerrainBounds> m_terrain_bounds;
  ClipmapPlan m_first_plan;
  StreamerStats m_before;
  Camera m_previous;
  double m_previous_step = 0.0;
  // Over terrain with PlanScope::kSampled: the ground the last frame showed,
  // in world space (null at first and after a resize).
  std::shared_ptr<const GroundSeen> m_seen;
  std::shared_ptr<const HeightReads> m_reads;  // read with m_seen
  double m_preload_ms = 0.0;
  uint32_t m_preload_failures = 0;
  uint32_t m_resizes = 0;
  uint32_t m_steps = 0;
  uint64_t m_warmup_loads = 0;
};

}  // namespace clipstream
