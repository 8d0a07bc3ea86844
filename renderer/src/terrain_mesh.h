// Private: the index pattern of one geometry clipmap ring (terrain.h).
// Pure functions; any thread.
#pragma once

#include <cstdint>
#include <vector>

namespace clipstream::terrain_mesh {

// Vertex (i, j), 0 <= i, j <= n, of a ring's (n + 1)^2 grid.
inline uint32_t vertexIndex(uint32_t n, uint32_t i, uint32_t j) { return j * (n + 1) + i; }

// Triangles (index triples) of a ring of n x n cells (n a power of two,
// >= 16), leaving out the finer ring's square of n/2 x n/2 cells whose first
// cell is (hole_x, hole_y) (hole_x < 0: no hole, the finest ring). Cells are
// cut along the diagonal (i, j)-(i+1, j+1), which is also how the coarser
// ring cuts the cell this ring's 2x2 cells make up. The outermost 2x2 blocks
// are fans around their centre whose outer sides skip the midpoint, so the
// ring's outer edge has exactly the coarser ring's vertices: no T-junction
// where two rings meet (the edge-stitching of crack-free chunk LOD).
std::vector<uint32_t> ringTriangles(uint32_t n, int hole_x, int hole_y);

// Triangles of a plain grid of n x n cells, every cell cut along the same
// diagonal as a ring's: the full-resolution mesh's patches
// (TerrainConfig::full_resolution), which meet each other vertex for vertex.
std::vector<uint32_t> gridTriangles(uint32_t n);

// Sides of a quadtree node's patch, for patchTriangles()'s mask: the side
// at j = 0, at i = n, at j = n and at i = 0.
enum PatchSide : uint32_t { kSideTop = 1, kSideRight = 2, kSideBottom = 4, kSideLeft = 8 };

// Triangles of a quadtree node's patch of n x n cells (n even, >= 4) whose
// sides in `coarse_sides` (PatchSide bits) border a node one level coarser:
// along such a side the 2 x 2 blocks are fans around their centre that skip
// the side's midpoint, so the side has only every other vertex, which are
// the coarser node's (seed 003's edge patterns: 16 masks, no T-junction,
// no crack). Elsewhere cells are cut along the diagonal (i, j)-(i+1, j+1),
// as a ring's and the full-resolution mesh's are.
std::vector<uint32_t> patchTriangles(uint32_t n, uint32_t coarse_sides);

}  // namespace clipstream::terrain_mesh
