// The ideal reference a streamed frame is judged against, and the
// per-frame accuracy of a flight (docs/accuracy.md).
//
// Thread rule: IdealReference and FlyAccuracy are owned by the GL thread,
// like ClipmapRenderer: create them and call every method on the thread
// whose context is current. IdealReference fetches tiles synchronously, so
// it is for measurement only, never for display.
#pragma once

#include <clipstream/eval/metrics.h>
#include <clipstream/eval/reference.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/tile_source.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <unordered_map>
#include <unordered_set>
#include <vector>

namespace clipstream {

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
  // `memory`: the streamed frames' TextureMemory, so that a frame at rest
  // is compared with the same sampling (kPaged: four times the default
  // pool, the planner's pyramid as plannerFor() gives it; a view that
  // needs more pages fails prepare() with kOutOfMemory).
  static Status create(std::shared_ptr<TileSource> source, const Viewport& viewport,
                       const PlannerConfig& planner, std::unique_ptr<IdealReference>* out,
                       TextureMemory memory = TextureMemory::kStack);
  ~IdealReference();
  IdealReference(const IdealReference&) = delete;
  IdealReference& operator=(const IdealReference&) = delete;

  // Plans, loads what is missing, draws into its own target and reads the
  // frame back (RGBA8, top row first). Leaves its own framebuffer bound:
  // callers rebind theirs.
  Status render(const Camera& camera, std::vector<uint8_t>* rgba);

  // The first half of render(): plans for `camera` and loads what is
  // missing, drawing nothing. With `every_level`, every stack level's
  // window counts as needed, not only those the flat plane's footprint
  // asks for (over terrain, ground may come near wherever the frame looks).
  // renderer() then textures any geometry with the ideal stack.
  Status prepare(const Camera& camera, bool every_level);
  const ClipmapRenderer& renderer() const { return *m_renderer; }

  // Recreates the renderer and target for a new viewport (clip size
  // follows the viewport); the tile cache is kept.
  Status resize(const Viewport& viewport);


 private:
  IdealReference() = default;
  std::shared_ptr<const std::vector<uint8_t>> tile(const TileKey& key);

  std::shared_ptr<TileSource> m_source;
  PyramidGeometry m_geometry;
  PlannerConfig m_planner;
  TextureMemory m_memory = TextureMemory::kStack;
  Viewport m_viewport;
  std::unique_ptr<ClipmapRenderer> m_renderer;
  std::unique_ptr<OffscreenTarget> m_target;
  // Per stack level: the window whose tiles are on the GPU now (empty = none).
  std::vector<TileRect> m_loaded;
  // Packed key -> pixels; null = the fetch failed (not retried).
  std::unordered_map<uint64_t, std::shared_ptr<const std::vector<uint8_t>>> m_cache;
  ClipmapPlan m_plan;
};

// Per-frame measurement of a measured flight (runFlight): compares the
// streamed frame in `target` against the IdealReference and, every Nth
// frame, the reference against the CPU ground truth (renderReference() over
// the full pyramid), which separates the clipmap's own approximation error
// from streaming error. Owned by the GL thread.
struct AccuracyOptions {
  bool reference = true;      // false: no IdealReference, measure() only samples tiles
  bool ground_truth = false;  // measure() may be asked for the CPU ground truth
  bool sample_tiles = true;   // collect sampledTiles() for the over-fetch ratio
  TextureMemory texture_memory = TextureMemory::kStack;  // the reference's (IdealReference::create())
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
  const std::unordered_set<uint64_t>& sampledSet() const { return m_sampled; }
  // The streamed frame the last comparing measure() read back.
  const std::vector<uint8_t>& lastStreamed() const { return m_streamed; }

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

}  // namespace clipstream
