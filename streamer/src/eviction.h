// The RAM cache's eviction score, shared by the streamer and the trace
// replay so both run the same policy. Pure functions; thread-safe.
//
// Policy (plan distance): the cost of evicting a tile is a read when it is
// next wanted. A tile is wanted again only after it has left every window,
// so a RAM copy of a tile the GPU already holds pays only once that tile
// has left. With the default EvictionMode::kGpuFirst:
//  1. pyramid tiles already on the GPU go first: their window is the whole
//     level, they never leave it, so their RAM copy can only serve a
//     renderer reset (and the renderer reloads the pyramid itself then);
//  2. then stack tiles inside a needed window that are on the GPU, deepest
//     first (deeper takes longer to leave and come back; until it has left,
//     the GPU draws such a tile whenever it is wanted again);
//  3. then tiles outside every window, by score: Chebyshev distance to the
//     window (tiles) times 4^level; levels the plan does not need add a
//     clip's width per level away from the finest needed level. The
//     predicted plan counts too: outside both, the distance is extrapolated
//     along the motion to twice the prediction's horizon (tiles left
//     behind go sooner); inside either, the smaller score wins;
//  4. last, tiles inside a needed window that are not on the GPU: with
//     PlanScope::kSampled a window can come back over a tile no frame
//     samples yet, and the next frame that does reads its RAM copy.
// With kProtectGpu, every inside tile goes after every outside tile and
// pyramid tiles are never scored (only a better-ranked newcomer may take
// their room). Larger score = evicted sooner; ties go MOST recently wanted first:
// tiles the score cannot tell apart (a whole level the plan no longer
// needs, tiles equally far beside the path) then stay a stable subset
// instead of cycling through RAM, which is what pays on loops, zoom cycles
// and returns (LRU is the worst case on a loop larger than the cache).
// Without any plan (kNoPlanScore) recency is the only locality signal left,
// so those ties go least recently wanted first.
// The 4^level weight (coarse outside tiles first) was chosen by replaying
// the benchmark flight paths: 2^level (pure travel distance) and 4^level
// agree on passes and orbits, 4^level keeps far more of revisited places
// (docs/decisions.md D55; the alternatives measured: D73-D76, D81).
#pragma once

#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/streamer.h>

#include <cstdint>
#include <vector>

namespace clipstream {

// The plan as the eviction sees it: one rect per level.
struct PlanWindows {
  enum Kind : uint8_t { kNotNeeded = 0, kNeeded = 1, kPyramid = 2 };
  std::vector<TileRect> rects;  // index = level
  std::vector<uint8_t> kinds;   // Kind per level
  uint32_t clip_tiles = 0;
  uint32_t finest_level = 0;

  bool empty() const { return rects.empty(); }
  // Fills clip_tiles and finest_level from rects and kinds.
  void finish();
};

PlanWindows planWindows(const ClipmapPlan& plan);

// True for tiles of pyramid levels: always wanted.
bool isPyramidTile(const TileKey& key, const PlanWindows& windows);

// True when a wanted tile already handed to the GPU is an eviction
// candidate by score: every such tile with kGpuFirst; with kProtectGpu
// pyramid tiles stay out of the scored list.
inline bool scoredOnGpu(const TileKey& key, const PlanWindows& windows, EvictionMode mode) {
  return mode == EvictionMode::kGpuFirst || !isPyramidTile(key, windows);
}

// Score of tiles no plan covers (no window line for their level yet).
inline constexpr double kNoPlanScore = 1e30;
// Score of pyramid tiles already on the GPU with kGpuFirst: above every
// stack tile, below kNoPlanScore.
inline constexpr double kPyramidFirstScore = 1e25;

// Eviction score (see above). `predicted` may be empty; `on_gpu`: the
// renderer holds the tile now.
double evictionScore(const TileKey& key, const PlanWindows& current, const PlanWindows& predicted,
                     EvictionMode mode, bool on_gpu);

// Victim order shared by the streamer and the replay: true when a tile with
// (score_a, wanted_a) is evicted before one with (score_b, wanted_b), where
// wanted_* is when the tile was last wanted (frames or trace positions).
inline bool evictsBefore(double score_a, uint64_t wanted_a, double score_b, uint64_t wanted_b) {
  if (score_a != score_b) return score_a > score_b;
  return score_a >= kNoPlanScore ? wanted_a < wanted_b : wanted_a > wanted_b;
}

}  // namespace clipstream
