// Speed against accuracy: per-frame image error of a streamed frame against
// an ideal reference, run summaries (PSNR, time to sharp, frame-time
// percentiles, hit rates, over-fetch), process RSS, the set of tiles a frame
// actually samples, and the ideal reference renderer itself.
//
// Thread rule: the free functions are pure (or read /proc) and thread-safe.
// IdealReference is owned by the GL thread, like ClipmapRenderer: create it
// and call render() on the thread whose context is current. It fetches
// tiles synchronously, so it is for measurement only, never for display.
#pragma once

#include <clipstream/renderer/flight_path.h>
#include <clipstream/renderer/reference.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace clipstream {

// PSNR reported for identical frames. The true value is +infinity, which
// neither CSV consumers nor JSON can carry; 99 dB is above anything two
// different 8-bit frames can score (one channel off by 1 in a 16-megapixel
// frame scores about 120 dB, but a single differing pixel at our viewports
// scores below 99), and frames are compared for bit-identity with
// max_abs_error == 0, never with this number.
inline constexpr double kIdenticalPsnrDb = 99.0;
// PSNR below this is a visibly degraded frame ("frames below 30 dB").
inline constexpr double kDegradedPsnrDb = 30.0;
// PSNR at or above this counts as sharp again after a cut (time to sharp).
inline constexpr double kSharpPsnrDb = 40.0;

struct FrameError {
  double psnr_db = kIdenticalPsnrDb;  // RGB, peak 255, capped at kIdenticalPsnrDb
  int max_abs_error = 0;              // largest |a - b| of any RGB channel
};

// Compares two RGBA8 frames of equal size (alpha ignored). Frames of
// different sizes or empty frames give psnr 0 and max_abs_error 255, the
// worst score, so a mismatch can never pass for a match.
FrameError compareFrames(const std::vector<uint8_t>& streamed, const std::vector<uint8_t>& reference);

// One frame of a run, as summarizeRun() needs it. Counters are this
// frame's deltas, not running totals.
struct FrameRecord {
  uint32_t frame = 0;
  bool cut = false;            // first recorded frame (unless warmed up), teleport, jump
  bool has_error = false;      // psnr_db / max_abs_error were measured
  double psnr_db = kIdenticalPsnrDb;
  int max_abs_error = 0;
  double frame_ms = 0.0;
  uint64_t bytes_read = 0;
  uint64_t tiles_uploaded = 0;
  uint64_t tiles_loaded = 0;   // tiles the loader read into RAM this frame
  uint64_t ram_hits = 0, ram_misses = 0;
  uint64_t gpu_hits = 0, gpu_misses = 0;
};

struct RunSummary {
  uint32_t frames = 0;
  uint32_t measured_frames = 0;   // frames with has_error
  double psnr_mean_db = kIdenticalPsnrDb;  // mean of the capped per-frame PSNR
  double psnr_min_db = kIdenticalPsnrDb;
  uint32_t frames_below_30db = 0;
  uint32_t identical_frames = 0;  // max_abs_error == 0
  // Per cut: frames from the cut until the first frame with PSNR >=
  // kSharpPsnrDb (0 = sharp at the cut), or -1 when the next cut or the end
  // of the run came first.
  std::vector<int32_t> time_to_sharp_frames;
  double time_to_sharp_mean = 0.0;  // over the cuts that became sharp
  int32_t time_to_sharp_max = 0;    // -1 if any cut never became sharp
  double frame_ms_p50 = 0.0, frame_ms_p99 = 0.0, frame_ms_max = 0.0, frame_ms_mean = 0.0;
  uint64_t bytes_read = 0;
  uint64_t tiles_uploaded = 0;
  uint64_t tiles_loaded = 0;
  double ram_hit_rate = 1.0;  // ram_hits / (ram_hits + ram_misses); 1 when nothing was asked
  double gpu_hit_rate = 1.0;  // gpu_hits / (gpu_hits + gpu_misses)
  uint64_t peak_rss_bytes = 0;
  uint64_t tiles_sampled = 0;  // distinct (level, tile) the visible pixels sample, whole run
  double over_fetch_ratio = 0.0;  // tiles_loaded / tiles_sampled; 0 when not measured

  // One JSON object with the fields above (time_to_sharp_frames as an
  // array). Always valid JSON.
  std::string toJson() const;
};

// Summarises a run. `tiles_sampled` is the size of the union of
// sampledTiles() over the run's frames (0 = not measured: no over-fetch
// ratio). Percentiles use nearest rank on the sorted frame times.
RunSummary summarizeRun(const std::vector<FrameRecord>& frames, uint64_t tiles_sampled,
                        uint64_t peak_rss_bytes);

// Nearest-rank percentile (p in [0, 1]) of the values; 0 for none.
double percentileOf(std::vector<double> values, double p);

// Whether the camera jumped between two consecutive frames: it moved more
// than half its height above the ground AND more than 8 times the previous
// frame's movement (with at least one texel of that). A continuous path at
// any speed moves about as much each frame, so it never counts; a teleport
// (a step path) does.
bool isCut(const Camera& previous, const Camera& current, double previous_step_texels);

// Resident set size of this process, bytes: current (VmRSS) and peak
// (VmHWM) from /proc/self/status; 0 where it cannot be read.
uint64_t currentRssBytes();
uint64_t peakRssBytes();

// Packs a tile key into 64 bits (level: 6 bits, x and y: 29 bits each),
// enough for 2^31-texel levels at 16-texel tiles or larger.
inline uint64_t packTileKey(const TileKey& key) {
  return (uint64_t(key.level) << 58) | (uint64_t(key.y & 0x1FFFFFFFu) << 29) | (key.x & 0x1FFFFFFFu);
}

// Adds to *out every (level, tile) whose texels the CPU reference
// (renderReference(), min_level 0) reads for this view: the tiles the
// visible pixels really sample under ideal residency. No tile is fetched.
// The denominator of the over-fetch ratio.
void sampledTiles(const PyramidGeometry& geometry, const Camera& camera, const Viewport& viewport,
                  std::unordered_set<uint64_t>* out);

// The ideal reference for a streamed frame: the same camera drawn by a
// second ClipmapRenderer (single-buffered) whose every tile of the frame's
// plan (pyramid and every needed stack level's whole window) is fetched
// synchronously from the source, with MaxTextureLOD at 0 (never
// throttled). Fetched tiles stay in an unbounded RAM cache for the
// renderer's lifetime, so a moving camera costs only the tiles entering
// the windows. A tile that fails to fetch is left non-resident (the shader
// falls back to a coarser level), as the streamer does.
class IdealReference {
 public:
  // kUnavailable if GL objects cannot be made (needs a current context).
  static Status create(std::shared_ptr<TileSource> source, const Viewport& viewport,
                       const PlannerConfig& planner, std::unique_ptr<IdealReference>* out);
  ~IdealReference();
  IdealReference(const IdealReference&) = delete;
  IdealReference& operator=(const IdealReference&) = delete;

  // Plans, loads what is missing, draws into its own target and reads the
  // frame back (RGBA8, top row first). Leaves its own framebuffer bound:
  // callers rebind theirs.
  Status render(const Camera& camera, std::vector<uint8_t>* rgba);

  // Recreates the renderer and target for a new viewport (clip size
  // follows the viewport); the tile cache is kept.
  Status resize(const Viewport& viewport);

  uint64_t tilesFetched() const { return m_fetched; }
  uint64_t fetchFailures() const { return m_failures; }
  uint64_t cachedBytes() const { return m_cached_bytes; }
  const ClipmapPlan& lastPlan() const { return m_plan; }

 private:
  IdealReference() = default;
  std::shared_ptr<const std::vector<uint8_t>> tile(const TileKey& key);

  std::shared_ptr<TileSource> m_source;
  PyramidGeometry m_geometry;
  PlannerConfig m_planner;
  Viewport m_viewport;
  std::unique_ptr<ClipmapRenderer> m_renderer;
  std::unique_ptr<OffscreenTarget> m_target;
  // Per stack level: the window whose tiles are on the GPU now (empty = none).
  std::vector<TileRect> m_loaded;
  // Packed key -> pixels; null = the fetch failed (not retried).
  std::unordered_map<uint64_t, std::shared_ptr<const std::vector<uint8_t>>> m_cache;
  ClipmapPlan m_plan;
  uint64_t m_fetched = 0, m_failures = 0, m_cached_bytes = 0;
};


// Per-frame measurement for clipstream-fly --reference: compares the
// streamed frame in `target` against the IdealReference and, every Nth
// frame, the reference against the CPU ground truth (renderReference() over
// the full pyramid), which separates the clipmap's own approximation error
// from streaming error. Owned by the GL thread.
struct AccuracyOptions {
  bool ground_truth = false;  // measure() may be asked for the CPU ground truth
  bool sample_tiles = true;   // collect sampledTiles() for the over-fetch ratio
};

struct AccuracyFrame {
  bool measured = false;
  FrameError error;                 // streamed vs reference
  uint32_t hole_pixels = 0;         // reference ground drawn as sky or black
  bool ground_truth_measured = false;
  FrameError ground_truth;          // reference vs CPU ground truth
};

class FlyAccuracy {
 public:
  static Status create(std::shared_ptr<TileSource> source, const Viewport& viewport,
                       const PlannerConfig& planner, const AccuracyOptions& options,
                       std::unique_ptr<FlyAccuracy>* out);
  // Call after the streamed frame is drawn and timed, every frame (the
  // sampled-tile set needs them all). With `compare`, reads `target` back,
  // renders the reference (binding its own framebuffer) and compares; with
  // `ground_truth` too (needs AccuracyOptions::ground_truth), also compares
  // the reference with the CPU ground truth.
  Status measure(const Camera& camera, const OffscreenTarget& target, bool compare,
                 bool ground_truth, AccuracyFrame* out);
  Status resize(const Viewport& viewport);
  uint64_t tilesSampled() const { return m_sampled.size(); }
  const IdealReference& reference() const { return *m_reference; }

 private:
  FlyAccuracy() = default;
  std::shared_ptr<TileSource> m_source;
  AccuracyOptions m_options;
  Viewport m_viewport;
  std::unique_ptr<IdealReference> m_reference;
  std::unordered_set<uint64_t> m_sampled;
  std::vector<uint8_t> m_streamed, m_ideal, m_truth;
  std::function<void(uint32_t, uint64_t, uint64_t, uint8_t*)> m_texels;  // ground truth texels
};

// Counts pixels where `reference` shows ground (not kSkyRgba) but `streamed`
// shows sky, or black where the reference is not black: holes.
uint32_t countHolePixels(const std::vector<uint8_t>& streamed, const std::vector<uint8_t>& reference);

// Garbage check: a streamed pixel that fell back to coarser levels must
// still equal the CPU reference rendered with some min_level (the level it
// fell back to). Renders the CPU reference for every min_level and counts
// pixels whose RGB differs from all of them by more than tolerance in some
// channel. A wrong tile, texel or colour shows; a correct fallback does not.
uint32_t countGarbagePixels(const std::vector<uint8_t>& streamed, const PyramidGeometry& geometry,
                            const TexelFunction& texel, const Camera& camera,
                            const Viewport& viewport, int tolerance);

// A measured flythrough: the streamed frame loop of clipstream-fly (update,
// takeReady, upload, draw, glFinish) with each frame compared against the
// IdealReference. Used by the stability tests and the sweep.
struct ScenarioOptions {
  std::shared_ptr<TileSource> source;
  FlightPath path;
  uint32_t frames = 60;        // moving frames: frame i shows path time i * speed / 60 s
  uint32_t rest_frames = 0;    // then this many frames holding the last camera
  Viewport viewport{320, 180};
  double speed = 1.0;
  StreamerConfig streamer;
  uint32_t upload_tiles = 16;
  Buffering buffering = Buffering::kDoubleUploadTwice;
  uint32_t resize_at_frame = 0;  // > 0: switch to resize_to before this frame
  Viewport resize_to{0, 0};
  uint32_t reference_every = 1;  // compare every Nth frame (and every rest frame); 0 = never
  bool sample_tiles = true;      // collect sampledTiles() for the over-fetch ratio
  // Frames checked with countGarbagePixels(): the lowest-PSNR measured
  // frames below kSharpPsnrDb, at most this many (CPU-heavy).
  uint32_t garbage_checks = 6;
  int garbage_tolerance = 6;
  // The ground those frames are checked against; empty: texelsFromSource()
  // of the source (a tile that fails has no texels there).
  TexelFunction garbage_texels;
  // Rest frames take at least this wall time (a display's refresh), so a
  // slow source gets real time to catch up; moving frames never wait.
  double rest_frame_ms = 0.0;
};

struct ScenarioResult {
  std::vector<FrameRecord> frames;
  std::vector<uint32_t> hole_pixels;  // per frame: reference ground drawn as sky or black
  std::vector<uint32_t> max_texture_lod;
  RunSummary summary;
  // Fetches that ran on the render thread inside the frame loop (a frame
  // waiting on I/O). The synchronous pyramid preload before frame 0 and the
  // reference's own fetches are not counted.
  uint64_t render_thread_fetches = 0;
  uint64_t ram_peak_bytes = 0, ram_budget_bytes = 0;
  uint64_t rss_after_warmup_bytes = 0;  // after 1/4 of the frames
  uint64_t rss_end_bytes = 0;
  uint32_t garbage_checked_frames = 0;
  uint32_t garbage_pixels_max = 0;      // worst checked frame
  int final_max_abs_error = -1;          // last frame against the reference (-1: not compared)
  uint64_t tile_failures = 0;
  std::string gl;
};

// Runs the scenario on the calling thread, which must have a current GL
// context. kInvalidArgument for a missing source; GL failures as from
// ClipmapRenderer::create.
Status runScenario(const ScenarioOptions& options, ScenarioResult* result);

}  // namespace clipstream
