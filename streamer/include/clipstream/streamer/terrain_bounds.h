// Per-tile height bounds of an elevation layer, for planning against the
// terrain instead of the plane y = 0 (planClipmap with
// PlannerConfig::terrain; docs/terrain.md, "Planning against the terrain").
//
// Thread rule: TerrainBounds is a plain value, immutable once loaded and
// shared between threads read-only. loadTerrainBounds() may do I/O (index
// pages of an elevation store, over HTTP a request each): call it when the
// layer is opened, never per frame.
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/tile_source.h>

#include <glm/glm.hpp>

#include <cstdint>
#include <memory>
#include <vector>

namespace clipstream {

// Largest tile grid of one level whose bounds are loaded: 128 x 128 tiles.
// An elevation store keeps 32 bytes of index per tile, so the finest level
// loaded costs at most 512 KiB of index pages (a few range requests over
// HTTP) and 128 KiB of bounds; finer levels are planned with their
// ancestors' (looser) bounds.
inline constexpr uint64_t kTerrainBoundsMaxLevelTiles = uint64_t(1) << 14;

// The height bounds of an elevation pyramid's coarse levels, in its own
// samples and height units. Level L tile (x, y) spans level-0 samples
// [x T 2^L, (x + 1) T 2^L) (T = tile_px); its `range` is the lowest and
// highest height of the tile and of its +x, +z and +x+z neighbours, so
// the box from the centre of its first sample to the centre of its +x+z
// neighbour's first sample holds the whole surface drawn between those
// samples (the surface between two tiles is made of both tiles' samples).
struct TerrainBounds {
  struct Level {
    uint32_t tiles_x = 0, tiles_y = 0;
    std::vector<glm::vec2> range;  // (min, max) per tile, row-major; empty: no bounds
  };
  uint32_t tile_px = 0;
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

// The terrain as one layer's planner sees it: where the bounds lie in the
// planning space (the layer's level-0 texels, y up). Level-0 sample (i, j)
// has its centre at sample_origin + (i, j) * units_per_sample, and height h
// lies at y = h * units_per_height. bounds null: no terrain (flat).
struct TerrainView {
  std::shared_ptr<const TerrainBounds> bounds;
  glm::dvec2 sample_origin{0.5, 0.5};
  glm::dvec2 units_per_sample{1.0, 1.0};
  double units_per_height = 1.0;
};

}  // namespace clipstream
