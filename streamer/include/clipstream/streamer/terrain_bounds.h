// Per-tile height bounds of an elevation layer, for planning against the
// terrain instead of the plane y = 0 (planClipmap with
// PlannerConfig::terrain; docs/terrain.md, "Planning against the terrain").
// Two sources, combined: the index's bounds of the pyramid's coarse levels
// (TerrainBounds, read once when the layer is opened), and the detail of
// the height tiles the streamer has read (TileDetail: the bounds of a
// tile's cells, from its samples), which refines them where the camera is.
//
// Thread rule: TerrainBounds, TileDetail and TerrainDetail are plain
// values, immutable once made and shared between threads read-only.
// loadTerrainBounds() may do I/O (index pages of an elevation store, over
// HTTP a request each): call it when the layer is opened, never per frame.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/tile_source.h>

#include <glm/glm.hpp>

#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

namespace clipstream {

// Largest tile grid of one level whose bounds are loaded: 128 x 128 tiles.
// An elevation store keeps 32 bytes of index per tile, so the finest level
// loaded costs at most 512 KiB of index pages (a few range requests over
// HTTP) and 128 KiB of bounds; finer levels are planned with their
// ancestors' (looser) bounds and the detail of the tiles read.
inline constexpr uint64_t kTerrainBoundsMaxLevelTiles = uint64_t(1) << 14;

// The height bounds of an elevation pyramid's coarse levels, in its own
// samples and height units. Level L tile (x, y) spans level-0 samples
// [x T 2^L, (x + 1) T 2^L) (T = tile_px); its range holds every level-0
// height there (the store's rule; a parent's range holds its children's).
struct TerrainBounds {
  struct Level {
    uint32_t tiles_x = 0, tiles_y = 0;
    std::vector<glm::vec2> range;  // (min, max) per tile, row-major; empty: no bounds
    // Geometric error per tile (TileHeightBounds::error), row-major, as
    // `range`: what the quadtree terrain refines by.
    std::vector<float> error;
  };
  uint32_t tile_px = 0;
  uint64_t width_samples = 0, height_samples = 0;  // level 0
  uint32_t finest_level = 0;  // finest level with bounds; every coarser level has them
  std::vector<Level> levels;  // index = level of the elevation pyramid
  glm::vec2 range{0.0f, 0.0f};  // the whole terrain: the coarsest level's
};

// Reads the bounds of every level of `source` from the coarsest down to the
// finest whose grid has at most max_level_tiles tiles
// (TileSource::tileHeightBounds()). kUnsupported when the source has no
// bounds (a colour source, a height source without an index); a failure
// below the coarsest level stops there and keeps the coarser levels.
Status loadTerrainBounds(const TileSource& source, uint64_t max_level_tiles,
                         std::shared_ptr<const TerrainBounds>* out);

// Cells a side of a tile's detail, log2: 16 x 16 cells, so a tile's detail
// refines its index bounds by four levels.
inline constexpr uint32_t kTileDetailLog2 = 4;
// Tiles whose detail a streamer keeps (the most recently read): about
// 2.8 MiB; detail outlives its tile in the cache (it stays true), so a
// camera that stays put keeps it when the tiles that gave it are evicted.
inline constexpr size_t kTerrainDetailTiles = 1024;

// The height range of every cell of one height tile at 2^k x 2^k cells
// for k = 0 .. log2 (cells[k], row-major): the min and max of the tile's
// own samples in the cell, widened by the tile's error, so each range holds
// the level-0 ground under its cell (as the index's ranges hold it under
// their tiles).
struct TileDetail {
  uint32_t log2 = 0;  // finest cells: 2^log2 a side
  std::vector<glm::vec2> cells[kTileDetailLog2 + 1];
};

// The detail of a tile of tile_px^2 heights (`heights`, row-major) whose
// error is `error` (TileHeightBounds::error; 0 at level 0). Cells:
// min(2^kTileDetailLog2, tile_px) a side.
std::shared_ptr<const TileDetail> makeTileDetail(uint32_t tile_px, const float* heights, float error);

// The detail a streamer holds, by tile of the elevation pyramid.
struct TerrainDetail {
  std::unordered_map<TileKey, std::shared_ptr<const TileDetail>, TileKeyHash> tiles;
};

// The terrain as one layer's planner sees it: where the bounds lie in the
// planning space (the layer's level-0 texels, y up). Level-0 sample (i, j)
// has its centre at sample_origin + (i, j) * units_per_sample, and height h
// lies at y = h * units_per_height. bounds null: no terrain (flat).
struct TerrainView {
  std::shared_ptr<const TerrainBounds> bounds;
  std::shared_ptr<const TerrainDetail> detail;  // may be null
  glm::dvec2 sample_origin{0.5, 0.5};
  glm::dvec2 units_per_sample{1.0, 1.0};
  double units_per_height = 1.0;
};

}  // namespace clipstream
