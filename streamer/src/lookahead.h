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

// The windows planned for the hinted camera at times k * step_s, for every k
// with now_s < k * step_s <= now_s + horizon_s, kept per level as runs.
struct LookaheadSnapshot {
  // A level's needed window over a stretch of samples: from t_s until the
  // next run's t_s. Consecutive samples with the same window share a run, so
  // scoring a tile scans only the moves of its own level's window.
  struct Run {
    double t_s = 0.0;
    TileRect rect;  // empty when the level is not needed
  };

  double now_s = 0.0;
  std::vector<double> times_s;        // ascending, one per sample
  std::vector<std::vector<Run>> runs; // per level, from index()

  // Builds `runs` from the samples' windows, one per entry of times_s.
  void index(const std::vector<PlanWindows>& windows);
};

class PathLookahead {
 public:
  // Plans the hinted poses on the grid up to time_s + hint.horizon_s.
  // Samples already planned for the same viewport are reused, so a frame
  // costs about frame time / step_s planner calls. A changed viewport or
  // hint (reset()) replans everything.
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
  uint64_t m_planner_calls = 0;
};

inline constexpr double kNoReturn = std::numeric_limits<double>::infinity();

// True when every field of the camera is finite: a hint may return anything.
bool finiteCamera(const Camera& camera);

// Seconds from the snapshot's time until `key` is next inside a needed
// window along the hinted path: for a tile inside a needed window of
// `current`, the first time after it has left; kNoReturn when that is
// beyond the horizon.
double predictedReturnS(const TileKey& key, const PlanWindows& current, const LookaheadSnapshot& ahead);

// evictionScore() with a lookahead (kGpuFirst only; other modes and a null
// or empty lookahead give evictionScore() unchanged): pyramid and unplanned
// tiles keep their score; tiles with no predicted return go next, in
// evictionScore() order; tiles with a predicted return go last, latest
// return first (Belady's rule on the predicted future).
double evictionScoreAhead(const TileKey& key, const PlanWindows& current, const PlanWindows& predicted,
                          EvictionMode mode, const LookaheadSnapshot* ahead);

}  // namespace clipstream
