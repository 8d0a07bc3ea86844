// The headless flythrough behind clipstream-fly: a measured flight
// (flight_run.h) over a store or a procedural texture, with its reports
// (report.h) published into one output directory and chosen frames as PNG.
//
// Thread rule: runFly() owns its GL context and runs the frame loop on the
// calling thread; the streamer's workers read tiles and a FrameWriter
// thread encodes PNGs. Nothing in a frame waits on I/O.
#pragma once

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/terrain.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/look_at.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <functional>
#include <iosfwd>
#include <optional>
#include <string>

namespace clipstream {

// Bounds of FlyOptions that runFly() and clipstream-fly check: beyond them a
// run would hang (a delay of hours per read) or mean nothing.
inline constexpr double kMaxFlySpeed = 10000.0;     // path seconds per simulated second
inline constexpr double kMaxFlyDelayMs = 10000.0;   // fault latency per read, rest-frame time
inline constexpr uint32_t kMaxFlyFrames = 10000000; // frames, rest and warm-up frames
// Deterministic I/O (DeterministicIo): more reads a frame than any flight
// wants, and a latency past any flight's length, mean nothing.
inline constexpr uint32_t kMaxFlyIoReadsPerFrame = 100000;
inline constexpr uint32_t kMaxFlyIoLatencyFrames = 100000;
// Tile reads that may fail before a run counts as failed, in per cent of
// the reads: a few failures show as blur (coarser levels) and are worth a
// warning; past 1 % the frames no longer show the store (a server that
// lost it, a store replaced under the run, a damaged file).
inline constexpr double kDefaultMaxFailedReadsPercent = 1.0;

struct FlyOptions {
  std::string store_path;          // tile store file or http(s) URL; empty when procedural_px > 0
  uint64_t procedural_px = 0;      // > 0: procedural texture of this side instead
  std::string path = "orbit";      // built-in name (or kSummitPath) or JSON file
  uint32_t frames = 0;             // 0 = the whole path at `speed`
  Viewport viewport{1280, 720};
  double speed = 1.0;              // path seconds per simulated second
  // The streamer's settings (RAM budget, loader threads, throttling,
  // prefetch, plan scope, request trace, deterministic I/O, ...), handed to
  // it as they are. runFly() refuses a budget under 1 MiB, more than
  // kMaxIoThreads loaders, and deterministic reads per frame or latency
  // outside 1..kMaxFlyIoReadsPerFrame or 1..kMaxFlyIoLatencyFrames (with
  // deterministic I/O off too); the trace may be neither an input nor one
  // of the run's files.
  StreamerConfig streamer;
  uint32_t upload_tiles = renderer_config::kDefaultUploadTilesPerFrame;  // GPU uploads per frame
  RemoteOptions remote;            // a URL store: requests in flight, disk cache
  std::string out_dir = "fly-out";
  // PNGs: every Nth frame and the last; 0 = none; unset = five frames
  // spread over the run (the first, one each quarter, the last).
  std::optional<uint32_t> save_every;
  Buffering buffering = kDefaultBuffering;
  // Where the colour tiles live on the GPU (renderer.h), and the pool's
  // size for kPaged (0 = defaultPoolBytes() of the viewport).
  TextureMemory texture_memory = TextureMemory::kStack;
  uint64_t pool_mb = 0;
  // Colour tiles on the GPU: kRgba8 as the source gives them, or kBc1
  // transcoded by the loader threads (makeBc1Source()).
  TileContent tile_format = TileContent::kRgba8;
  bool overlay = false;
  bool quiet = false;              // no summary table
  // Called on the render thread after each frame (warm-up excluded) with
  // the frames done and the run's total: a progress display.
  std::function<void(uint32_t done, uint32_t total)> on_progress;
  // Speed against accuracy (docs/accuracy.md).
  bool reference = false;            // compare frames with the ideal reference
  bool fewest_triangles = false;     // over terrain, judged frames count the fewest triangles too
  uint32_t reference_every = 1;      // ... every Nth frame (and every rest frame)
  uint32_t ground_truth_every = 0;   // reference vs CPU ground truth every Nth frame; 0 = never
  // With reference: also trace which tiles every frame samples (on the CPU,
  // every pixel of every frame, judged or not) for the over-fetch ratio.
  // The largest part of a judged run at 3840x2160; false leaves it 0.
  bool over_fetch = true;
  // The ideal reference's tiles; unset: tile_format (frames at rest are then
  // bit-identical to it). kRgba8 under a BC1 flight measures the
  // compression error too.
  std::optional<TileContent> reference_tile_format;
  bool path_hint = false;            // give the streamer the scripted path (Streamer::setPathHint)
  double fault_latency_ms = 0.0;     // > 0: every read waits this long (FaultSpec)
  double fault_corrupt_fraction = 0.0;  // this fraction of tiles fail as corrupt
  // Failed tile reads (per cent of the reads) past which the run fails;
  // a run in which reads failed and none loaded fails whatever this is.
  double max_failed_reads_percent = kDefaultMaxFailedReadsPercent;
  uint32_t resize_at_frame = 0;      // > 0: switch to resize_to before this frame
  Viewport resize_to{0, 0};
  uint32_t warmup_frames = 0;        // first hold the first camera this many frames, unrecorded
  uint32_t rest_frames = 0;          // then hold the last camera this many frames
  double rest_frame_ms = 0.0;        // rest frames last at least this wall time
  bool loop = false;                 // wrap path time instead of clamping at the end
  uint32_t teleport_frames = 30;     // the built-in teleport path jumps this often
  // Terrain (docs/terrain.md): an elevation store under the colour layer.
  std::string elevation_path;        // empty: the flat plane
  double vertical_scale = 1.0;       // height exaggeration
  bool stretch_elevation = false;    // place by extent, not by georeference
  uint32_t terrain_ring = renderer_config::kTerrainRingCells;  // cells per ring side
  TerrainMethod terrain_method = TerrainMethod::kClipmap;     // --terrain
  double terrain_error_px = renderer_config::kTerrainErrorPx; // quadtree: --terrain-error
  // Quadtree: --terrain-triangle-budget (0: none; TerrainConfig::triangle_budget).
  uint64_t terrain_triangle_budget = renderer_config::kTerrainTriangleBudget;
  TerrainLighting terrain_lighting = TerrainLighting::kVertex;  // --terrain-lighting
  bool terrain_detail = false;                                  // --terrain-detail
  uint32_t synthesized_levels = 0;                              // --synthesize-relief
  // --path-in-map-units: a JSON path's x and z are map coordinates of the
  // colour store's georeference and its heights are in the elevation's
  // unit (without terrain: map units), turned into texels by
  // pathFromMapUnits().
  bool path_in_map_units = false;
  // --look-at X,Y[,HEIGHT]: instead of `path`, the camera that looks at this
  // map point (aimAtMapPoint()), held for every frame.
  std::optional<LookAt> look_at;
  // The terrain reference's lighting (--reference-lighting); unset: the
  // flight's. Both lightings judged against one per-pixel reference
  // compare them.
  std::optional<TerrainLighting> reference_lighting;
};

// --path summit: over terrain, the built-in orbit around the DEM's highest
// point (highestPoint()) instead of the texture's centre.
inline constexpr const char* kSummitPath = "summit";
// --path rough: over terrain, the built-in orbit around the middle of the
// DEM's roughest area (roughestPoint(), streamer/look_at.h).
inline constexpr const char* kRoughPath = "rough";

// Largest --vertical-scale: beyond it every slope is a wall.
inline constexpr double kMaxVerticalScale = 1000.0;

// Runs the flythrough. Frame i shows path time i * speed / 60 s whatever
// the real render time (simulated pacing: the same cameras every run; the
// same frames too with `deterministic`).
// Writes OUT/frames.csv, OUT/frames.json, OUT/summary.tsv and
// OUT/frame_NNNNN.png, each under OutputFile's rule, after removing what an
// earlier run wrote in OUT (once the GL context and the first frame's
// resources exist; the statistics files are published only when the run
// succeeded), and prints a summary table to `log`. Returns the first error
// (options out of bounds, bad store, no GL context, unwritable output or
// trace). Failed tile reads are counted and, when there are any, a warning
// says how many; past `max_failed_reads_percent` of the reads, or when
// reads failed and none loaded, the run returns an error after writing its
// statistics (kUnavailable).
// Warnings (temporaries of killed runs removed) go to `warnings`, or to
// `log` when it is null.
Status runFly(const FlyOptions& options, std::ostream& log, std::ostream* warnings = nullptr);

}  // namespace clipstream
