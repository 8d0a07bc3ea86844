// PlanScope::kSampled: which tiles of each needed clip window the screen
// samples (planner.h). planClipmap() places the windows, then markSampled()
// (the flat plane) or markSeen() (terrain, from the ground a frame showed)
// fills each needed level's `sampled` mask. The steps are declared here so
// the tests can check each alone.
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
// Over terrain (groundSeenGrid()) the grid is twice as fine: points at
// least 2 px apart, at most 192 along the longer side. Its boxes and levels
// follow the relief closer: on the valley flight of
// scripts/bench_terrain_planning.sh (1280x720) the clip levels loaded 2.16x
// the tiles sampled on the plane's grid, 1.62x on this one and 1.67x on one
// twice finer again, for 2.5 / 5.2 / 17.5 ms of streamer time a frame; on
// the St Helens orbits of tests/eval/test_terrain_planning.cpp (320x180) 11
// / 3 tiles of 1,162 sampled went unwanted on the plane's grid / this one.
inline constexpr double kSeenStepMinPx = 2.0;
inline constexpr double kSeenCellsMax = 192.0;
// Over terrain (markSeen()) the lead is half a tile: the flights of
// scripts/bench_terrain_planning.sh (1280x720, every 5th frame judged, on
// the plane's grid) loaded 1.76 / 1.93 / 2.11 times the clip-level tiles
// the St Helens valley flight samples with a lead of 0 / 0.5 / 1 tile, and
// 1.04 / 1.18 / 1.31 on the orbit, at the same PSNR to 0.01 dB; half a
// tile keeps some of the flat plane's margin for a start from rest within
// the over-fetch target of 2 (docs/decisions.md D295).
inline constexpr double kSeenLeadTiles = 0.5;
// Over terrain the levels of detail are compared with this much slack:
// a grid point's level comes from the ground steps to its neighbours, 2 to
// 7 pixels away, and a DEM's facets make the level vary within a cell. On
// the St Helens orbits of tests/eval/test_terrain_planning.cpp (320x180,
// at rest, on the plane's grid) the tiles sampled that the plan did not
// want were 25 of 1,162 at the clip levels with the plane's 0.05, 17 with
// 0.15, 14 with 0.2 and 8 with 0.35, for 1,475 / 1,552 / 1,605 / 1,786
// tiles wanted (3 with 0.2 on the finer grid, kSeenCellsMax). A tile
// missed this way is one the pixels sample with little weight (their level
// lies near the next coarser one, which is loaded).
inline constexpr double kSeenLodSlack = 0.2;
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
// of the level and stretched lead_tiles tiles of the level along
// `ahead` (the unit horizontal view direction, or zero). Searched from the top block down,
// so the cost follows the tiles marked, not the cells; the result is that
// of marking cell by cell. Tiles already marked stay marked.
void markSampledLevel(const std::vector<SampleGrid>& pyramid, uint32_t tile_px, glm::dvec2 ahead,
                      ClipLevelPlan* lp, double lead_tiles = kSampleLeadTiles);

// Over terrain, the steps to a grid point's two neighbours on one screen
// axis differ by the ground's recession across a cell; more than this
// ratio means the larger crosses an edge of the relief (a ridge in front of
// farther ground), and the smaller is the surface's.
inline constexpr double kSeenEdgeRatio = 3.0;

// A point of a GroundSeen grid as the planned camera would sample it: its
// ground (x, z) when the frame showed ground there; the box of the ground
// halfway to its grid neighbours on the screen (`lo`, `hi`); which of the
// four neighbours (per axis, before and after) lie on its surface
// (`continuous`: a step over kSeenEdgeRatio times the other side's is a
// jump across an edge of the relief); and the level of detail there
// (INFINITY when no neighbour showed ground): log2 of the larger axis' step
// per pixel (the mean of its two sides'), scaled by the distance from the
// planned camera over the distance from the camera that saw it (and by the
// two pixels' angles); a change of the view's obliquity to the surface is
// left out (exact for the small moves between frames, a fraction of a level
// off for a camera moved far: SeenScope tests).
struct SeenCorner {
  bool shown = false;
  glm::dvec2 ground{0.0};
  glm::dvec2 lo{0.0}, hi{0.0};
  bool continuous[2][2] = {{false, false}, {false, false}};
  double lod = INFINITY;
};
std::vector<SeenCorner> seenCorners(const GroundSeen& seen, const Viewport& viewport, const Camera& camera);

// Marks, for every needed stack level m of *plan, the window tiles under
// the ground `seen` showed whose level of detail (seenCorners(), for
// `camera` in `viewport`) is below m + 1: a cell per grid point, its box
// halfway to its neighbours at the least level over it (its own, and
// halfway to each neighbour on its surface), then markSampledLevel() as on
// the plane with a lead of `lead_tiles`. Not the plane's quads between
// four corners: over relief a quad may span a ridge and the plain behind
// it, and its box then covers the ground between, which no pixel shows
// (on the St Helens orbit at 1280x720 the quads wanted twice the level-0
// tiles the frame sampled). A grid that does not match its points, or that
// showed no ground with a level of its own (a frame drawn before any height
// was resident, or of the sky), leaves the windows whole.
void markSeen(uint32_t tile_px, const Viewport& viewport, const Camera& camera, const GroundSeen& seen,
              ClipmapPlan* plan, double lead_tiles = kSeenLeadTiles);

// Marks, for every needed stack level of *plan, the window tiles under the
// samples `reads` gives at that level (an elevation layer, its texels the
// samples; `camera` and reads.camera in them): each rect swept from where
// the camera that read it stood to `camera` (the geometry moves with the
// camera: the clipmap's rings are centred on it, and the predicted
// camera's plan sweeps them along its motion, the prefetch's half second
// ahead). No lead beyond that: the reads say what is next (the clipmap's
// give each ring's square one snap wider): on the flight of
// TerrainPlanning.HeightLoadsAreTheTilesTheRingsRead a lead of four more
// moves loaded 40 tiles instead of 24 and drew no ring finer, and on the
// Rainier mountainside (x10) no frame's finest ring is coarser without one
// than with whole windows. A needed level without rects wants nothing.
// `reads` without rects leaves the windows whole.
void markHeightReads(uint32_t tile_px, const Camera& camera, const HeightReads& reads, ClipmapPlan* plan);

}  // namespace clipstream
