// PlanScope::kSampled on the flat plane: which tiles of each needed clip
// window the screen samples (planner.h). planClipmap() places the windows,
// then markSampled() fills each needed level's `sampled` mask. The steps
// are declared here so the tests can check each alone.
//
// Thread rule: pure functions, safe from any thread.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>

#include <glm/glm.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace clipstream {

// Screen cells of at least kSampleStepMinPx pixels, at most kSampleCellsMax
// along the longer side: the cell bounds are exact, so the grid only trades
// tightness for time (320x180: 80 x 45 cells, 1920x1080: 96 x 54; a plan
// costs 0.17 / 0.40 ms on this machine against 3-6 us for the whole window:
// bench_streamer_plan).
inline constexpr double kSampleStepMinPx = 4.0;
inline constexpr double kSampleCellsMax = 96.0;
// Levels of detail are compared with this much slack: the GPU forms its
// derivatives per 2x2 quad, from pixel pairs a little apart from the ones
// sampled here.
inline constexpr double kSampleLodSlack = 0.05;
// Each cell's ground also reaches this many tiles of the level ahead along
// the horizontal view direction: a camera that starts to move forward
// finds the next tiles loaded (the prefetch needs a few frames of motion
// to see it). Measured on the sweep's line, deterministic (docs/decisions.md
// D67): none lost 1-3 frames below 30 dB at
// each start from rest (x10: 98.7 dB mean, x50: 97.1), half a tile one
// (x50: 97.8), one tile none (99.0, 98.4) for an over-fetch of 1.85 at x1
// instead of 1.27.
inline constexpr double kSampleLeadTiles = 1.0;
// A block of cells over at most this many window tiles that are all marked
// already is not searched further (a larger one costs more to check than
// its search saves).
inline constexpr int64_t kSampleMarkedCheckTiles = 64;

// Marks, for every needed stack level m of *plan, the window tiles under
// ground whose level of detail is below m + 1 (PlanScope::kSampled): per
// screen cell, the level of detail at its corners (log2 of the longer
// ground step to the next pixel across and up, as the renderer's shader and
// renderReference() form it), its least value over the corners, and the
// bounding box of the corners' ground points. On a plane the ground a cell
// sees is the convex quad of its corners, so the box holds it; a corner
// above the horizon stands for the ground out to far_h along its azimuth.
// Each box is widened by half a texel of the level (the bilinear taps) and
// stretched kSampleLeadTiles ahead along the horizontal view direction.
// Levels that are not needed, or have an empty window, are left as they
// are (planClipmap() leaves their masks empty).
void markSampled(const PyramidGeometry& geometry, const Viewport& viewport, const Camera& camera,
                 double far_h, ClipmapPlan* plan);

// The screen positions (pixels) of the cell corners along an axis of
// size_px pixels: pixel centres step_px apart from the first, 0.5, while
// below the last, size_px - 0.5, which ends the list. step_px > 0.
std::vector<double> sampleCornerPositions(double size_px, double step_px);

// A screen cell, or a block of cells: the least level of detail of its
// corners (INFINITY: none sees the ground with a finite one) and the
// bounding box of its ground (level-0 texels, x and z; empty, lo > hi,
// when its level of detail is not finite).
struct SampleCell {
  double lod = INFINITY;
  glm::dvec2 lo{INFINITY}, hi{-INFINITY};
};

// A w x h grid of cells or blocks, row-major.
struct SampleGrid {
  size_t w = 0, h = 0;
  std::vector<SampleCell> cells;
};

// The pyramid of blocks over `cells` (at least one cell): [0] is `cells`,
// each next grid holds blocks of 2 x 2 of the one before (the last row and
// column of blocks hold what is left), up to a single block. A block's
// level of detail is the least of its cells', its box the union of theirs.
std::vector<SampleGrid> buildCellPyramid(SampleGrid cells);

// Marks in lp->sampled (sized to lp->window, row-major) the window tiles
// of level lp->level that the cells of `pyramid` (buildCellPyramid())
// sample: every cell whose level of detail less kSampleLodSlack is below
// lp->level + 1 marks the tiles its box touches, widened by half a texel
// of the level and stretched kSampleLeadTiles tiles of the level along
// `ahead` (the unit horizontal view direction, or zero). Searched from the top block down,
// so the cost follows the tiles marked, not the cells; the result is that
// of marking cell by cell. Tiles already marked stay marked.
void markSampledLevel(const std::vector<SampleGrid>& pyramid, uint32_t tile_px, glm::dvec2 ahead,
                      ClipLevelPlan* lp);

}  // namespace clipstream
