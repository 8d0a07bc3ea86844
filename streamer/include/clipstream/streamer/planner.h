// Clipmap planning: which tiles of which levels a view needs. Pure functions
// over plain data; no threads, no I/O, no GL.
//
// The clipmap (Tanner et al. 1998) is a stack of clip levels, each a
// clip_tiles x clip_tiles window of its pyramid level centred under the
// camera, plus the "pyramid": every level small enough to fit whole in one
// clip-sized texture, which is loaded completely and first.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/camera.h>

#include <cstdint>
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

struct PlannerConfig {
  uint32_t clip_tiles = 0;       // clip size in tiles; 0 = choose from the viewport
  double max_oversample = 2.0;   // finest level: texel footprint >= 1/this screen pixel
  uint32_t max_stack_levels = 0; // 0 = no limit beyond the pyramid
};

// One level of the clip stack.
struct ClipLevelPlan {
  uint32_t level = 0;
  bool needed = false;       // false: finer than any visible pixel needs; not loaded
  int64_t origin_tx = 0;     // window's top-left tile (snapped to the tile grid)
  int64_t origin_ty = 0;
  TileRect window;           // the clip window clamped to the level's tiles
  TileRect visible;          // tiles under the frustum's ground footprint (within window)
};

struct ClipmapPlan {
  uint32_t clip_tiles = 0;
  uint32_t pyramid_level = 0;  // levels >= this fit whole in a clip and are always resident
  uint32_t finest_level = 0;   // finest level any visible pixel needs
  std::vector<ClipLevelPlan> stack;  // one entry per level in [0, pyramid_level)
};

// Chooses the clip size (tiles) for a viewport: the window must cover about
// twice the screen's resolution plus a tile of margin for toroidal updates.
uint32_t chooseClipTiles(const Viewport& viewport, uint32_t tile_px);

// Plans the clipmap for one frame.
ClipmapPlan planClipmap(const PyramidGeometry& geometry, const Viewport& viewport,
                        const Camera& camera, const PlannerConfig& config);

// Tiles that entered and left the needed windows between two plans.
struct PlanDelta {
  std::vector<TileKey> entered;
  std::vector<TileKey> left;
};
PlanDelta diffPlans(const ClipmapPlan& before, const ClipmapPlan& after);

// Tiles of the plan in load order: pyramid first (coarse to fine), then the
// stack coarse to fine, visible before hidden, near the window centre first.
std::vector<TileKey> rankPlanTiles(const PyramidGeometry& geometry, const ClipmapPlan& plan,
                                   bool frustum_first = true);

}  // namespace clipstream
