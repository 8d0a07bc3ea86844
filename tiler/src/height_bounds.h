// Per-tile height bounds and geometric error of an elevation store, worked
// out while the pyramid is built (docs/tile-store.md, "Tile entries of
// elevation stores"):
//   bounds(tile) = min/max of its own samples and of its children's bounds,
//                  so a tile bounds all level-0 ground under it;
//   error(tile)  = max over its children of (deviation of the child's
//                  samples from the surface this level's samples span +
//                  the child's own error); 0 at level 0.
// A level's samples are every other sample of the level below (the
// decimate filter), so the deviation of a child is measured at its odd
// samples against the bilinear surface of its even ones. The last odd row
// and column of a tile have no even sample beyond them in the tile and are
// measured against the nearest even one (a slight over-estimate at worst
// for smooth ground).
//
// Thread rule: owned by the tiler's build thread, which emits every tile
// after its children (the decimate filter's second tap guarantees it).
#pragma once

#include <clipstream/store/tile_store.h>

#include <span>
#include <unordered_map>

namespace clipstream {

struct TileHeights {
  float min_height = 0.0f;
  float max_height = 0.0f;
  float error = 0.0f;
};

class HeightBoundsTracker {
 public:
  HeightBoundsTracker(const PyramidGeometry& geometry, const ElevationInfo& elevation);

  // Called once per tile with its stored samples (tileBytes() bytes),
  // children before parents. Returns the tile's bounds and error.
  TileHeights add(const TileKey& key, std::span<const uint8_t> pixels);

  // Tiles whose children were seen but which were not yet added (0 at the end).
  size_t pending() const { return m_pending.size(); }

 private:
  struct Pending {
    float min_height = 0.0f;
    float max_height = 0.0f;
    float error = 0.0f;
    bool any = false;
  };

  const PyramidGeometry& m_geometry;
  ElevationInfo m_elevation;
  std::vector<float> m_heights;  // scratch: the tile's samples as heights
  std::unordered_map<TileKey, Pending, TileKeyHash> m_pending;
};

}  // namespace clipstream
