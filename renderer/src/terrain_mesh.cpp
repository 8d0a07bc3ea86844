#include "terrain_mesh.h"

#include <cstddef>

namespace clipstream::terrain_mesh {
namespace {

// The two triangles of cell (i, j), cut along the diagonal (i, j)-(i+1, j+1).
void appendCell(uint32_t n, uint32_t i, uint32_t j, std::vector<uint32_t>* out) {
  const uint32_t a = vertexIndex(n, i, j), b = vertexIndex(n, i + 1, j);
  const uint32_t d = vertexIndex(n, i, j + 1), e = vertexIndex(n, i + 1, j + 1);
  out->insert(out->end(), {a, b, e, a, e, d});
}

// The 2 x 2 cells at (i0, j0) as a fan around their centre; the perimeter
// runs (i0, j0) -> (i0+2, j0) -> (i0+2, j0+2) -> (i0, j0+2) -> back, with
// the midpoint of each side in `skip` (PatchSide bits) left out, so that
// side has only the coarser grid's vertices.
void appendFan(uint32_t n, uint32_t i0, uint32_t j0, uint32_t skip, std::vector<uint32_t>* out) {
  const uint32_t c = vertexIndex(n, i0 + 1, j0 + 1);
  std::vector<uint32_t> rim;
  auto side = [&](uint32_t ia, uint32_t ja, uint32_t im, uint32_t jm, uint32_t bit) {
    rim.push_back(vertexIndex(n, ia, ja));
    if (!(skip & bit)) rim.push_back(vertexIndex(n, im, jm));
  };
  side(i0, j0, i0 + 1, j0, kSideTop);
  side(i0 + 2, j0, i0 + 2, j0 + 1, kSideRight);
  side(i0 + 2, j0 + 2, i0 + 1, j0 + 2, kSideBottom);
  side(i0, j0 + 2, i0, j0 + 1, kSideLeft);
  for (size_t k = 0; k < rim.size(); ++k) out->insert(out->end(), {c, rim[k], rim[(k + 1) % rim.size()]});
}

// Which sides of the grid of n cells the 2 x 2 block (bx, by) lies on.
uint32_t blockSides(uint32_t n, uint32_t bx, uint32_t by) {
  const uint32_t blocks = n / 2;
  return (by == 0 ? kSideTop : 0u) | (bx + 1 == blocks ? kSideRight : 0u) |
         (by + 1 == blocks ? kSideBottom : 0u) | (bx == 0 ? kSideLeft : 0u);
}

}  // namespace

std::vector<uint32_t> ringTriangles(uint32_t n, int hole_x, int hole_y) {
  std::vector<uint32_t> out;
  const int hole = int(n / 2);
  auto inHole = [&](uint32_t i, uint32_t j) {
    return hole_x >= 0 && int(i) >= hole_x && int(i) < hole_x + hole && int(j) >= hole_y &&
           int(j) < hole_y + hole;
  };
  for (uint32_t by = 0; by < n / 2; ++by)
    for (uint32_t bx = 0; bx < n / 2; ++bx) {
      // Every block on the ring's outer edge is a fan whose outer sides
      // skip their midpoints.
      if (const uint32_t outer = blockSides(n, bx, by)) {
        appendFan(n, 2 * bx, 2 * by, outer, &out);
        continue;
      }
      for (uint32_t j = 2 * by; j < 2 * by + 2; ++j)
        for (uint32_t i = 2 * bx; i < 2 * bx + 2; ++i)
          if (!inHole(i, j)) appendCell(n, i, j, &out);
    }
  return out;
}

std::vector<uint32_t> gridTriangles(uint32_t n) {
  std::vector<uint32_t> out;
  out.reserve(size_t(n) * n * 6);
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i) appendCell(n, i, j, &out);
  return out;
}

std::vector<uint32_t> patchTriangles(uint32_t n, uint32_t coarse_sides) {
  std::vector<uint32_t> out;
  out.reserve(size_t(n) * n * 6);
  for (uint32_t by = 0; by < n / 2; ++by)
    for (uint32_t bx = 0; bx < n / 2; ++bx) {
      // A block on a side towards a coarser node: the ring's fan, with
      // the midpoint left out on the coarse sides only.
      if (const uint32_t coarse = blockSides(n, bx, by) & coarse_sides) {
        appendFan(n, 2 * bx, 2 * by, coarse, &out);
        continue;
      }
      for (uint32_t j = 2 * by; j < 2 * by + 2; ++j)
        for (uint32_t i = 2 * bx; i < 2 * bx + 2; ++i) appendCell(n, i, j, &out);
    }
  return out;
}

}  // namespace clipstream::terrain_mesh
