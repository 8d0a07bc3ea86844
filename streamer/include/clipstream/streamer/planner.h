// Clipmap planning: which tiles of which levels a view needs. Pure functions
// over plain data; no threads, no I/O, no GL.
//
// Thread rule: pure, safe from any thread.
//
// The clipmap (Tanner et al. 1998) is a stack of clip levels, each a
// clip_tiles x clip_tiles window of its pyramid level centred under the
// camera, plus the "pyramid": every level small enough to fit whole in one
// clip-sized texture, which is loaded completely and first.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/terrain_bounds.h>

#include <cstdint>
#include <memory>
#include <vector>

namespace clipstream {

// Half-open rectangle of tiles [x0, x1) x [y0, y1) in one level's tile grid.
struct TileRect {
  int64_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  int64_t width() const { return x1 > x0 ? x1 - x0 : 0; }
  int64_t height() const { return y1 > y0 ? y1 - y0 : 0; }
  bool empty() const { return width() == 0 || height() == 0; }
  bool contains(int64_t x, int64_t y) const { return x >= x0 && x < x1 && y >= y0 && y < y1; }
  friend bool operator==(const TileRect&, const TileRect&) = default;
};

// Which tiles of a needed stack level a plan asks to load.
enum class PlanScope {
  // The window tiles over ground that the screen samples at this level or
  // through it: where the pixel's level of detail (the renderer's, from
  // screen derivatives) is below level + 1. Trilinear filtering reads
  // level l where the LOD lies in (l - 1, l + 1); the nearer ground, whose
  // LOD is below l - 1, is kept too, so that every sampled tile has its
  // ancestors for the per-tile fallback while it loads, and one tile of
  // each level ahead along the view (a start from rest finds it loaded).
  // Computed on a grid of screen cells, each cell's ground and LOD range
  // bounded by its corners (exact bounds on the plane). Over terrain (height
  // bounds or relief planes) the cells are those of the ground a frame
  // showed (PlannerConfig::seen); without it the plan wants the whole window.
  // The default: a scene loads what its frames sample (docs/decisions.md
  // D62).
  kSampled,
  kWindow,  // the whole clip window of every needed level (the classic clipmap)
};

// The ground a drawn frame showed, for planning the next frames over
// terrain, where no ray cast on the planner's side knows what a pixel shows
// (a slope hides what lies behind it): for a grid of screen points
// (groundSeenGrid()), the point each showed, read back from the frame's
// depth (TerrainRenderer::readGroundSeen()). With PlanScope::kSampled the
// planner marks the window tiles under this ground, at the levels its pixels
// sample seen from the camera being planned (docs/terrain.md, "Over-fetch
// over terrain"). Ground the frame did not show (a turn brings it in at the
// screen's border) is missed until a frame shows it; it is drawn from the
// coarser levels meanwhile.
struct GroundSeen {
  Camera camera;                   // the camera that drew it
  Viewport viewport;               // the frame's size (xs and ys are in its pixels)
  std::vector<double> xs, ys;      // the grid: groundSeenGrid(viewport)
  // xs.size() * ys.size() points, row-major (x fastest), in the planner's
  // space (the streamer maps them into each layer's texels); NaN where the
  // pixel shows no ground (sky, beyond the texture).
  std::vector<glm::dvec3> points;
};

// The samples of an elevation layer the terrain's geometry read to draw a
// frame, and those it would have read had their tiles been resident
// (TerrainRenderer::heightReads(): the clipmap's ring squares, the
// quadtree's leaves and the children of the nodes that wanted to split).
// Over terrain with PlanScope::kSampled the elevation layer's plans want
// only the window tiles under them (markHeightReads()), as the colour
// layers' want the ground seen.
struct HeightReads {
  Camera camera;  // the camera that drew the frame, in the planner's space
  struct Rect {
    uint32_t level = 0;
    glm::i64vec2 s0{0}, s1{0};  // the level's samples s0..s1, both included
  };
  std::vector<Rect> rects;
};

// The screen positions (pixels, y down; pixel centres) of the grid a
// GroundSeen is read on: 192 cells along the longer side at most, 2 px
// apart at least (twice the flat planner's grid).
void groundSeenGrid(const Viewport& viewport, std::vector<double>* xs, std::vector<double>* ys);

struct PlannerConfig {
  uint32_t clip_tiles = 0;       // clip size in tiles; 0 = choose from the viewport
  double max_oversample = 2.0;   // finest level: texel footprint >= 1/this screen pixel
  uint32_t max_stack_levels = 0; // 0 = no limit beyond the pyramid
  // The pyramid is every level at most this many tiles a side (at most
  // clip_tiles; 0 = clip_tiles, the classic clipmap). The paged texture
  // memory pins the pyramid's tiles in its pool and pages the rest, so it
  // asks for a small pyramid (renderer_config::kPagedPyramidTiles).
  uint32_t pyramid_tiles = 0;
  // Terrain without per-tile bounds: how far the ground within view rises
  // above (and falls below) the plane y = 0 under the camera, in level-0
  // texels. The footprint is then the union of the footprints on the
  // planes y = -ground_below, 0 and ground_above (a slope in front, seen
  // from below its top, hits the upper plane), and the finest level follows
  // the nearest of them. 0 and 0: the flat plane, exactly as without
  // terrain. Ignored when `terrain` has bounds.
  double ground_above = 0.0;
  double ground_below = 0.0;
  // Terrain with per-tile height bounds, placed in this plan's texels
  // (bounds null: the flat plane). The camera's y is then its real height
  // in the same units, and the footprint, the nearest visible ground and
  // the visible tiles come from the terrain (terrainFootprint(),
  // docs/terrain.md "Planning against the terrain"); windows are placed
  // by the same rule as on the plane.
  TerrainView terrain;
  PlanScope scope = PlanScope::kSampled;
  // Over terrain with PlanScope::kSampled: the ground the last frame
  // showed, in this plan's space (the streamer's Streamer::setGroundSeen(),
  // mapped into the layer's texels). Null: every needed window whole.
  std::shared_ptr<const GroundSeen> seen;
  // An elevation layer over terrain with PlanScope::kSampled: what the
  // geometry read last (Streamer::setHeightReads(), its camera mapped into
  // the layer's texels). Null or no rects: every needed window whole.
  std::shared_ptr<const HeightReads> reads;
};

// One level of the clip stack.
struct ClipLevelPlan {
  uint32_t level = 0;
  bool needed = false;       // false: finer than any visible pixel needs; not loaded
  int64_t origin_tx = 0;     // window's top-left tile (snapped to the tile grid)
  int64_t origin_ty = 0;
  TileRect window;           // the clip window clamped to the level's tiles
  TileRect visible;          // tiles under the frustum's ground footprint (within window)
  // Window tiles the plan wants loaded, row-major over `window` (1 = wanted);
  // empty: the whole window (PlanScope::kWindow, or no sampled scope here).
  std::vector<uint8_t> sampled;
  // True when the plan wants tile (x, y) of this level loaded: a needed
  // level, inside the window, and sampled (or the whole window).
  bool wants(int64_t x, int64_t y) const {
    if (!needed || !window.contains(x, y)) return false;
    return sampled.empty() ||
           sampled[size_t(y - window.y0) * size_t(window.width()) + size_t(x - window.x0)] != 0;
  }
  // Tiles wants() is true for.
  uint64_t wantedCount() const;
};

struct ClipmapPlan {
  uint32_t clip_tiles = 0;
  uint32_t pyramid_level = 0;  // levels >= this fit whole in a clip (PlannerConfig::pyramid_tiles) and are always resident
  uint32_t finest_level = 0;   // finest level any visible pixel needs
  std::vector<ClipLevelPlan> stack;  // one entry per level in [0, pyramid_level)
  // Whole tile grid of each pyramid level: pyramid[i] is level pyramid_level + i.
  // Lets diffPlans() and the loader see every wanted tile without the geometry.
  std::vector<TileRect> pyramid;
  // Camera's ground point (level-0 texels, x and z). Ranking measures "near"
  // from here; windows are centred a little ahead of it (see planClipmap()).
  glm::dvec2 focus_texel{0.0, 0.0};
  bool ground_visible = false;  // false: the frustum misses the ground (no stack level needed)
};

// Chooses the clip size (tiles) for a viewport: the window must cover about
// twice the screen's resolution plus a tile of margin for toroidal updates.
uint32_t chooseClipTiles(const Viewport& viewport, uint32_t tile_px);

// Plans the clipmap for one frame. Pure; double precision throughout.
// Window centre for level l: the camera's ground point moved a quarter of
// the window's extent along the horizontal view direction (scaled by
// cos(pitch)), so a camera looking ahead keeps 3/4 of each window in front;
// the window is then snapped to the tile grid and shifted to lie inside the
// level. `needed` comes from the nearest visible ground distance.
ClipmapPlan planClipmap(const PyramidGeometry& geometry, const Viewport& viewport,
                        const Camera& camera, const PlannerConfig& config);

// The finest level planClipmap() needs for ground `distance` away (3D,
// level-0 texels) in this view: the level whose texel covers at least
// 1/max_oversample of a pixel there, at most level_count - 1. The rule
// planClipmap() applies to the nearest visible ground; exposed so that an
// evaluation can apply it to the nearest ground a frame shows.
uint32_t finestLevelAt(double distance, const Viewport& viewport, const Camera& camera,
                       const PlannerConfig& config, uint32_t level_count);

// Tiles that entered and left the wanted tiles (ClipLevelPlan::wants() of
// the stack levels, plus every pyramid tile) between two plans. Order: level by
// level, row-major; no duplicates.
struct PlanDelta {
  std::vector<TileKey> entered;
  std::vector<TileKey> left;
};
PlanDelta diffPlans(const ClipmapPlan& before, const ClipmapPlan& after);

// Tiles of the plan in load order: pyramid first (coarse to fine), then the
// wanted tiles of the needed stack levels coarse to fine; inside a level
// visible before hidden (when frustum_first) and near the camera's ground
// point first. Tiles the plan does not want are not listed.
std::vector<TileKey> rankPlanTiles(const PyramidGeometry& geometry, const ClipmapPlan& plan,
                                   bool frustum_first = true);

}  // namespace clipstream
