// Private: the meshes of the terrain renderer (terrain.h), built on the
// CPU: the index patterns of a geometry clipmap ring, where each ring lies,
// the full-resolution mesh's plain grid and the quadtree's patch with its
// edge patterns, and the buffers' contents made of them (buildRingMesh(),
// buildPatchMesh()). Vertices are grid points (i, j) of an (n + 1)^2 grid;
// the vertex shader places them. Pure functions; any thread.
#pragma once

#include <glm/glm.hpp>

#include <array>
#include <cstdint>
#include <vector>

namespace clipstream::terrain_mesh {

// Vertex (i, j), 0 <= i, j <= n, of a ring's (n + 1)^2 grid.
inline uint32_t vertexIndex(uint32_t n, uint32_t i, uint32_t j) { return j * (n + 1) + i; }

// ---- Ring layout ----

// Ring origin of `level` with the camera at `camera_samples` (level-0
// samples): the level's sample index of the n-cell ring's vertex (0, 0),
// even, so every other vertex is a vertex of the next coarser ring, and the
// ring is centred on the camera to within two samples.
glm::i64vec2 ringOrigin(const glm::dvec2& camera_samples, uint32_t n, uint32_t level);

// The index patterns of a ring: kNoHole (the innermost ring), or one of four
// holes for the finer ring, n/2 x n/2 cells from cell (n/4 + hx, n/4 + hy),
// hx, hy in {0, 1}, in pattern 1 + hx + 2 hy.
inline constexpr int kNoHole = 0;
inline constexpr int kRingPatterns = 5;
// The first cell (hole_x, hole_y) of pattern `pattern`'s hole; (-1, -1)
// for kNoHole.
void patternHole(uint32_t n, int pattern, int* hole_x, int* hole_y);
// The pattern of the ring at `origin` around the finer ring at
// `fine_origin` (both from ringOrigin(), one level apart): 1..4 when the
// origins nest, as ringOrigin()'s always do; anything else when they do not.
int holePattern(const glm::i64vec2& fine_origin, const glm::i64vec2& origin, uint32_t n);

// ---- Triangles ----

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

// ---- Buffer contents ----

// Where one draw's indices lie in an index buffer (in indices).
struct IndexRange {
  uint32_t first = 0;
  uint32_t count = 0;
};

// The ring mesh's buffers: each pattern's triangles filed in kBlocks x
// kBlocks blocks by the cell of their centroid (culled one by one against
// the frustum), each block drawing from its own copy of the vertices it
// uses, stored together after the plain grid: a driver that shades the
// whole index range of a draw (llvmpipe does) then shades each vertex of
// the block once instead of every grid row the block spans, and its
// per-draw vertex buffers stay small.
struct RingMesh {
  static constexpr uint32_t kBlocks = 4;  // blocks a side
  using Blocks = std::array<std::array<IndexRange, kBlocks * kBlocks>, kRingPatterns>;
  // (i, j) pairs: the plain (n + 1)^2 grid in row order (vertex
  // vertexIndex(n, i, j) is (i, j)), then each pattern's blocks' copies.
  std::vector<int32_t> vertices;
  std::vector<uint32_t> indices;
  Blocks blocks{};   // [pattern][by * kBlocks + bx]
  int patterns = 0;  // kRingPatterns, or 1 for the plain grid
};
// The ring mesh of n cells (a power of two, >= 16): the five ring patterns,
// or with `plain_grid` the full-resolution mesh's patch, one pattern of
// gridTriangles() (kNoHole).
RingMesh buildRingMesh(uint32_t n, bool plain_grid);

// The quadtree's patch buffers: one (n + 1)^2 grid in row order, and the
// triangles of its 16 edge patterns (patchTriangles(), by mask) one after
// another.
struct PatchMesh {
  using Masks = std::array<IndexRange, 16>;
  std::vector<int32_t> vertices;
  std::vector<uint32_t> indices;
  Masks masks{};
};
PatchMesh buildPatchMesh(uint32_t n);

}  // namespace clipstream::terrain_mesh
