// The clip windows along an application-supplied future camera path
// (PathHint), for eviction by predicted return. Shared by the streamer and
// the trace replay so both score tiles the same way. Not thread-safe: the
// streamer advances it on the render thread and hands immutable snapshots
// to the workers.
#pragma once

#include "eviction.h"

#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/streamer.h>

#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

namespace clipstream {

// A level's wanted tiles of one planned sample, row-major over its window
// (ClipLevelPlan::sampled); null: the whole window.
using SampledMask = std::shared_ptr<const std::vector<uint8_t>>;

// The plans of the hinted camera at times k * step_s, for every k with
// now_s < k * step_s <= now_s + horizon_s, kept per level as runs.
struct LookaheadSnapshot {
  // A level's needed window and its wanted tiles over a stretch of samples:
  // from t_s until the next run's t_s. Consecutive samples with the same
  // window and mask share a run, so scoring a tile scans only the changes
  // of its own level.
  struct Run {
    double t_s = 0.0;
    TileRect rect;        // empty when the level is not needed
    SampledMask sampled;  // null: every tile of rect is wanted
    bool wants(int64_t x, int64_t y) const {
      if (!rect.contains(x, y)) return false;
      return !sampled || (*sampled)[size_t(y - rect.y0) * size_t(rect.width()) + size_t(x - rect.x0)] != 0;
    }
  };

  double now_s = 0.0;
  std::vector<double> times_s;        // ascending, one per sample
  std::vector<std::vector<Run>> runs; // per level, from index()

  // Builds `runs` from the samples' windows, one per entry of times_s, and
  // their masks (per sample, per level; null or absent: the whole window).
  void index(const std::vector<PlanWindows>& windows,
             const std::vector<std::vector<SampledMask>>& sampled = {});
};

class PathLookahead {
 public:
  // Plans the hinted poses on the grid up to time_s + hint.horizon_s.
  // Samples already planned for the same viewport are reused, so a frame
  // costs about frame time / step_s planner calls; a call plans at most 16
  // new ones, so a fresh horizon fills over a few frames. A changed
  // viewport or hint (reset()) replans everything.
  void advance(const PyramidGeometry& geometry, const Viewport& viewport, const PlannerConfig& planner,
               const PathHint& hint, double time_s);
  void reset();
  std::shared_ptr<const LookaheadSnapshot> snapshot() const;
  uint64_t plannerCalls() const { return m_planner_calls; }

 private:
  Viewport m_viewport{0, 0};
  double m_now_s = 0.0;
  double m_step_s = 1.0 / 15.0;
  std::vector<int64_t> m_steps;        // grid index k of each sample, ascending
  std::vector<PlanWindows> m_windows;  // same order
  std::vector<std::vector<SampledMask>> m_sampled;  // same order, per stack level
  uint64_t m_planner_calls = 0;
};

inline constexpr double kNoReturn = std::numeric_limits<double>::infinity();

// True when every field of the camera is finite: a hint may return anything.
bool finiteCamera(const Camera& camera);

// Seconds from the snapshot's time until the RAM copy of `key` is next
// read along the hinted path: the first time the plan wants the tile, but
// for a tile on the GPU inside a needed window of `current` only after it
// has left that window (until then the GPU draws it whenever it is wanted
// again); kNoReturn when that is beyond the horizon.
double predictedReturnS(const TileKey& key, const PlanWindows& current, bool on_gpu,
                        const LookaheadSnapshot& ahead);

// evictionScore() with a lookahead (kGpuFirst only; other modes and a null
// or empty lookahead give evictionScore() unchanged): pyramid and unplanned
// tiles keep their score; tiles with no predicted return go next, in
// evictionScore() order; tiles with a predicted return go last, latest
// return first (Belady's rule on the predicted future).
double evictionScoreAhead(const TileKey& key, const PlanWindows& current, const PlanWindows& predicted,
                          EvictionMode mode, bool on_gpu, const LookaheadSnapshot* ahead);

}  // namespace clipstream
