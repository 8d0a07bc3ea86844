// Measuring a streamed run: image error of a frame against a reference,
// run summaries (PSNR, time to sharp, frame-time percentiles, hit rates,
// over-fetch), the set of tiles a frame actually samples, and the hole and
// garbage counters of the stability scenarios. docs/accuracy.md.
//
// Thread rule: pure functions, thread-safe (sampledTiles() and
// countGarbagePixels() call the CPU reference on the calling thread).
#pragma once

#include <clipstream/eval/reference.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <cstdint>
#include <string>
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
  // The same without the coarse pyramid (levels that fit one clip, loaded
  // whole once and kept): the clip levels' loads over their sampled tiles.
  uint64_t tiles_loaded_stack = 0;
  uint64_t tiles_sampled_stack = 0;
  double over_fetch_stack_ratio = 0.0;  // 0 when not measured
  // Over terrain, the height layer's clip levels (those not held whole):
  // tiles the streamer loaded, over the distinct tiles the drawn geometry
  // read in every frame, warm-up included (TerrainRenderer::lastHeightTiles()).
  uint64_t height_tiles_loaded_stack = 0;
  uint64_t height_tiles_sampled_stack = 0;
  double height_over_fetch_stack_ratio = 0.0;  // 0 when not measured

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

// Over terrain: adds to *out every (level, tile) of the colour pyramid
// `geometry` whose texels a frame samples with every tile resident, from
// the ground point each pixel shows: `xyzw` as TerrainRenderer::
// readPositions() gives it (camera-relative world x, y, z and w = 1 on
// terrain, top row first; world x and z are the colour layer's level-0
// texels). The level is the terrain shader's: log2 of the longer screen
// derivative of (x, z), formed from the pixel's 2x2 quad as the CPU
// reference forms it; trilinear, so the next coarser level's taps count
// too. A quad partner off the terrain is replaced by the pixel's other
// neighbour on that axis (the GPU would extrapolate the triangle's plane);
// a pixel with neither on both axes is left out. The denominator of the
// over-fetch ratio over terrain.
void sampledTilesOfPositions(const PyramidGeometry& geometry, const std::vector<float>& xyzw,
                             const Camera& camera, const Viewport& viewport,
                             std::unordered_set<uint64_t>* out);

// The distance from the camera to the nearest ground point of positions
// `xyzw` (as for sampledTilesOfPositions(): camera-relative, w = 1 on
// terrain); infinity when no pixel shows terrain.
double nearestPositionDistance(const std::vector<float>& xyzw);

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

// PSNR over RGB (alpha ignored) of two equally sized RGBA8 images, in dB;
// +infinity when identical. `mask` (optional, one byte per pixel) limits
// the comparison to pixels where it is non-zero.
double psnrRgb(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b,
               const std::vector<uint8_t>* mask = nullptr);

}  // namespace clipstream
