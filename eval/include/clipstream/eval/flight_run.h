// A measured flight along a scripted path: the one frame loop behind
// clipstream-fly, the stability scenarios and the sweep. It flies a Flight
// (renderer/flight.h) through the path's cameras, with warm-up, rest frames
// and an optional resize, and judges frames against the IdealReference.
//
// Frame rules (docs/renderer.md, "The frame loop"): recorded frame i shows
// path time min(i, frames - 1) * kSimulatedFrameSeconds * speed (wrapped
// with `loop`), whatever the real render time, so runs ask for the same
// cameras (which tiles have landed by then is timing-free only with
// StreamerConfig::deterministic_io);
// warm-up frames hold the first camera, rest frames the last; the clock and
// cut rules are Flight's.
//
// Thread rule: runFlight() runs on the calling thread, which must have a
// current GL context; the streamer's workers read tiles. `on_frame` runs on
// the calling thread.
#pragma once

#include <clipstream/eval/accuracy.h>
#include <clipstream/streamer/flight_path.h>
#include <clipstream/eval/metrics.h>
#include <clipstream/eval/reference.h>
#include <clipstream/eval/terrain_accuracy.h>
#include <clipstream/renderer/config.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/stats.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace clipstream {

struct FlightRunOptions {
  std::shared_ptr<TileSource> source;
  // The ideal reference's and the ground truth's tiles; null: `source`.
  // Same geometry as `source` (e.g. its RGBA8 tiles under a BC1 flight).
  std::shared_ptr<TileSource> reference_source;
  FlightPath path;
  uint32_t frames = 60;         // moving frames (at least 1)
  uint32_t warmup_frames = 0;   // first: the first camera held, not recorded
  uint32_t rest_frames = 0;     // then: the last camera held this many frames
  // Rest frames take at least this wall time (a display's refresh), so a
  // slow source gets real time to catch up; moving frames never wait.
  double rest_frame_ms = 0.0;
  double speed = 1.0;           // path seconds per simulated second
  bool loop = false;            // wrap path time instead of clamping at the end
  Viewport viewport{320, 180};
  uint32_t resize_at_frame = 0;  // > 0: switch to resize_to before this recorded frame
  Viewport resize_to{0, 0};
  StreamerConfig streamer;
  uint32_t upload_tiles = renderer_config::kDefaultUploadTilesPerFrame;
  Buffering buffering = kDefaultBuffering;
  TextureMemory texture_memory = TextureMemory::kStack;  // FlightConfig's; the reference's too
  uint64_t pool_bytes = 0;                                // kPaged: 0 = the default pool
  Overlay overlay = Overlay::kOff;
  bool path_hint = false;       // give the streamer the scripted path (Streamer::setPathHint)
  // Terrain under the colour layer (FlightConfig::terrain). Path heights
  // then mean heights above the ground under the camera, never less than
  // kTerrainClearance; judged frames (reference_every) are compared with
  // the TerrainReference (PSNR) and measure the geometric error.
  std::optional<TerrainLayerConfig> terrain;
  // The TerrainReference's lighting; unset: terrain->lighting.
  std::optional<TerrainLighting> reference_lighting;

  // Measurement.
  uint32_t reference_every = 1;     // compare every Nth frame (and every rest frame); 0 = never
  uint32_t ground_truth_every = 0;  // also the reference against the CPU ground truth; 0 = never
  bool sample_tiles = true;         // collect sampledTiles() (warm-up too) for the over-fetch ratio;
                                    // over terrain sampledTilesOfPositions(), a position pass a frame
  // Over terrain, judged frames also count the fewest triangles that model
  // them as well as they are drawn (FewestTriangles at the frame's own p95
  // geometric error: a dozen position passes a frame).
  bool fewest_triangles = false;
  // Frames checked with countGarbagePixels(): the lowest-PSNR measured
  // frames below kSharpPsnrDb, at most this many (CPU-heavy).
  uint32_t garbage_checks = 0;
  int garbage_tolerance = 6;
  // The ground those frames are checked against; empty: texelsFromSource()
  // of the source (a tile that fails has no texels there).
  TexelFunction garbage_texels;

  // Called once the flight, its renderer and the reference exist, before the
  // first frame: everything that can fail at set-up has been tried. An
  // error stops the run.
  std::function<Status()> on_start;
  // Called after each recorded frame is drawn and timed, before it is
  // judged, with the flight's target (e.g. to save the frame); a hook that
  // reads the frame back sets *readback_ms (left 0 otherwise). An error
  // stops the run.
  std::function<Status(const FrameSample& frame, const OffscreenTarget& target, double* readback_ms)>
      on_frame;
  // Called after the last frame, before the streamer stops and publishes its
  // trace (e.g. to finish writing frames). An error fails the run, and a
  // failed run publishes no trace.
  std::function<Status()> before_finish;
};

struct FlightRunFrame {
  FrameSample sample;
  double t_s = 0.0;            // path time shown
  double readback_ms = 0.0;    // reading a saved frame back (FlightRunOptions::on_frame); 0 if not saved
  // When judged: against the IdealReference, or over terrain against the
  // TerrainReference (then hole_pixels is not counted: a silhouette of
  // coarser geometry is no hole; the crack tests cover holes).
  AccuracyFrame accuracy;
  GeometryError geometry;      // over terrain, when judged (reference_every)
  // Over terrain, when judged: pixels showing the reference's world
  // position to the bit, and of them those whose colour differs.
  uint32_t terrain_agree_pixels = 0, terrain_agree_mismatched = 0;
  uint64_t fewest_triangles = 0;  // over terrain, when judged (FlightRun::fewest_triangles_mean)
  // Over terrain with sample_tiles: the finest level the planner's rule
  // gives for the nearest ground this frame shows (finestLevelAt() of the
  // nearest of its positions), to set against sample.finest_needed; -1:
  // not measured (no terrain in view, or not sampled).
  int32_t seen_level = -1;
};

struct FlightRun {
  std::vector<FlightRunFrame> frames;  // recorded frames only
  RunSummary summary;                  // over the recorded frames (warm-up loads in over-fetch)
  StreamerStats streamer;              // the streamer's statistics after the last frame
  std::string gl;                      // GL_RENDERER / GL_VERSION
  std::string source;                  // TileSource::describe()
  uint32_t clip_tiles = 0, pyramid_level = 0;  // the renderer's at the end (after a resize, the new one)
  TextureBytes texture_bytes;          // the colour clip stack's video memory (the renderer at the end)
  TileContent tile_content = TileContent::kRgba8;  // what the stack holds
  TextureMemory texture_memory = TextureMemory::kStack;
  uint32_t pool_pages = 0;             // kPaged: the pool's pages (0 for the stack)
  double preload_ms = 0.0;             // the first synchronous pyramid load
  uint32_t preload_failures = 0;       // pyramid tiles that could not be read, every load
  uint32_t resizes = 0;
  uint64_t warmup_loads = 0;
  double run_ms = 0.0;                 // the frame loop, warm-up included
  // Fetches that ran on the render thread inside the frame loop (a frame
  // waiting on I/O). Pyramid loads before frame 0 and at a resize, and the
  // reference's own fetches, are not counted.
  uint64_t render_thread_fetches = 0;
  uint64_t rss_after_warmup_bytes = 0;  // after a quarter of the recorded frames
  uint64_t rss_end_bytes = 0;
  uint32_t garbage_checked_frames = 0;
  uint32_t garbage_pixels_max = 0;       // worst checked frame
  int final_max_abs_error = -1;          // last frame against the reference (-1: not compared)
  uint64_t tile_failures = 0;            // streamer failures + preload failures
  // The stores read over HTTP (colour and elevation; the reference's reads
  // of the same store included): requests, bytes, retries, disk cache.
  // All zero for local stores.
  RemoteStats remote;
  Status trace_status;                   // Streamer::traceStatus() after the streamer stopped
  uint32_t frames_with_holes = 0;        // judged frames with hole pixels
  uint32_t ground_truth_frames = 0;
  double ground_truth_psnr_mean_db = 0.0, ground_truth_psnr_min_db = 0.0;  // 0 when none
  // Terrain (0 without): the height stack's video memory and the mean
  // triangles drawn per recorded frame.
  uint64_t height_texture_bytes = 0;
  double terrain_triangles_mean = 0.0;
  // Quadtree: the error bound the recorded frames met (FrameSample::
  // terrain_error_px), mean and largest; 0 for the other methods.
  double terrain_error_px_mean = 0.0, terrain_error_px_max = 0.0;
  std::string terrain_method;     // terrainMethodName(), empty without terrain
  std::string terrain_lighting;   // terrainLightingName(), empty without terrain
  std::string reference_lighting; // the TerrainReference's, empty without terrain
  double render_cpu_ms_mean = 0.0;  // FrameSample::cpu_ms over the recorded frames
  bool plans_on_terrain = false;  // the streamer planned against the height bounds (Streamer::plansOnTerrain())
  // Recorded frames with a seen_level, and those whose plan needed a level
  // coarser than it (pixels nearer than planned for: blurrier than the
  // view asks, a hole in the plan) or finer (a level loaded that no pixel
  // needs).
  uint32_t seen_frames = 0, needed_coarser_frames = 0, needed_finer_frames = 0;
  // Geometric error over the judged frames (terrain with reference_every):
  // means of the per-frame mean and p95, and the largest; the same over
  // the rest frames alone (the camera still). 0 when not measured.
  uint32_t geometry_frames = 0, geometry_rest_frames = 0;
  double geometry_mean_px = 0.0, geometry_p95_px = 0.0, geometry_max_px = 0.0;
  double geometry_rest_mean_px = 0.0, geometry_rest_p95_px = 0.0, geometry_rest_max_px = 0.0;
  // Coverage and the silhouette figure (GeometryError; means over the judged
  // frames, and the largest).
  double coverage_pixels_mean = 0.0;
  // The on-screen texel density (texelDensity(), with the detail textures'
  // kDetailTexelsPerTexel): means over the judged frames of each frame's
  // median and 5th percentile, without and with the detail textures.
  double texel_density_median = 0.0, texel_density_p5 = 0.0;
  // Synthesized relief: the geometric error against the DEM's own surface
  // (means of each judged frame's mean and p95; projection only); 0 without.
  double geometry_data_mean_px = 0.0, geometry_data_p95_px = 0.0;
  double detail_texel_density_median = 0.0, detail_texel_density_p5 = 0.0;
  double silhouette_mean_px = 0.0, silhouette_p95_px = 0.0, silhouette_max_px = 0.0;
  // Over the judged rest frames: pixels where the geometry agrees with the
  // reference to the bit, and of them those whose colour differs (0 when
  // the texture is bit-identical wherever the geometry agrees).
  uint64_t terrain_rest_agree_pixels = 0, terrain_rest_agree_mismatched = 0;
  uint32_t terrain_rest_agree_max_diff = 0;  // the largest channel difference of those
  // Over the judged frames with terrain in view: the triangles drawn and
  // the fewest that model the frame within its own p95 geometric error
  // (FewestTriangles; not below kFewestFloorPx), means. 0 when not measured.
  double judged_triangles_mean = 0.0, fewest_triangles_mean = 0.0;
  // Temporal stability, over pairs of consecutive judged frames (every
  // frame with reference_every 1): the mean absolute change of a pixel's
  // grey level from one frame to the next, streamed and reference. Popping
  // shows as the streamed change above the reference's. 0 pairs: not measured.
  uint32_t change_pairs = 0;
  double change_mean = 0.0, reference_change_mean = 0.0;
  // Over terrain, the geometry alone: the mean change of each pixel's
  // displacement from the full-resolution surface (displacementChange()),
  // and its largest over a pair of frames (a pop).
  double geometry_change_mean = 0.0, geometry_change_max = 0.0;
};

// The least p95 error the fewest triangles are counted at (pixels): below
// half a pixel a tree cut by one bound everywhere is no longer the fewest
// (a quadtree frame at rest with p95 0.055 px drew 23.1k triangles where
// the 4-cell tree needed 26.7k; docs/decisions.md D281).
inline constexpr double kFewestFloorPx = 0.5;

// The camera of a terrain flight: `path_camera` with its height taken as
// height above `ground` (world units), at least
// renderer_config::kTerrainClearance.
Camera cameraAboveGround(Camera path_camera, double ground);

// Flies the run. kInvalidArgument for a missing source or zero frames;
// GL failures as from Flight::create; the first error of `on_frame` or of
// the reference.
Status runFlight(const FlightRunOptions& options, FlightRun* run);

}  // namespace clipstream
