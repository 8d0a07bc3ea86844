// Measuring the terrain, not drawing it: a switch of the quadtree that the
// evaluation harness uses to find the fewest triangles that reach an error
// (eval/terrain_accuracy.h). Part of the renderer library but not
// installed: a host has no use for it. GL thread only, as TerrainRenderer.
#pragma once

#include <clipstream/renderer/terrain.h>

#include <cstdint>
#include <functional>

namespace clipstream {

// Quadtree: each node's error from `error` (height units; level, node x,
// node y) instead of the store's bounds, and no restriction between
// neighbours (no stitching: cracks may open). Null: back to the bounds,
// for display.
void setExactNodeError(TerrainRenderer& terrain, std::function<double(uint32_t, int64_t, int64_t)> error);

}  // namespace clipstream
