#include "terrain_mesh.h"

#include <cstddef>

namespace clipstream::terrain_mesh {

std::vector<uint32_t> ringTriangles(uint32_t n, int hole_x, int hole_y) {
  std::vector<uint32_t> out;
  const uint32_t blocks = n / 2;
  const int hole = int(n / 2);
  auto inHole = [&](uint32_t i, uint32_t j) {
    return hole_x >= 0 && int(i) >= hole_x && int(i) < hole_x + hole && int(j) >= hole_y &&
           int(j) < hole_y + hole;
  };
  auto tri = [&](uint32_t a, uint32_t b, uint32_t c) {
    out.push_back(a);
    out.push_back(b);
    out.push_back(c);
  };
  for (uint32_t by = 0; by < blocks; ++by) {
    for (uint32_t bx = 0; bx < blocks; ++bx) {
      const uint32_t i0 = 2 * bx, j0 = 2 * by;
      const bool top = by == 0, bottom = by + 1 == blocks, left = bx == 0, right = bx + 1 == blocks;
      if (top || bottom || left || right) {
        // Fan around the centre; the perimeter runs (i0, j0) -> (i0+2, j0)
        // -> (i0+2, j0+2) -> (i0, j0+2) -> back, with each side's midpoint
        // left out when that side is the ring's outer edge.
        const uint32_t c = vertexIndex(n, i0 + 1, j0 + 1);
        std::vector<uint32_t> rim;
        auto side = [&](uint32_t ia, uint32_t ja, uint32_t im, uint32_t jm, bool outer) {
          rim.push_back(vertexIndex(n, ia, ja));
          if (!outer) rim.push_back(vertexIndex(n, im, jm));
        };
        side(i0, j0, i0 + 1, j0, top);
        side(i0 + 2, j0, i0 + 2, j0 + 1, right);
        side(i0 + 2, j0 + 2, i0 + 1, j0 + 2, bottom);
        side(i0, j0 + 2, i0, j0 + 1, left);
        for (size_t k = 0; k < rim.size(); ++k) tri(c, rim[k], rim[(k + 1) % rim.size()]);
        continue;
      }
      for (uint32_t j = j0; j < j0 + 2; ++j) {
        for (uint32_t i = i0; i < i0 + 2; ++i) {
          if (inHole(i, j)) continue;
          const uint32_t a = vertexIndex(n, i, j), b = vertexIndex(n, i + 1, j);
          const uint32_t d = vertexIndex(n, i, j + 1), e = vertexIndex(n, i + 1, j + 1);
          tri(a, b, e);
          tri(a, e, d);
        }
      }
    }
  }
  return out;
}

std::vector<uint32_t> gridTriangles(uint32_t n) {
  std::vector<uint32_t> out;
  out.reserve(size_t(n) * n * 6);
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i) {
      const uint32_t a = vertexIndex(n, i, j), b = vertexIndex(n, i + 1, j);
      const uint32_t d = vertexIndex(n, i, j + 1), e = vertexIndex(n, i + 1, j + 1);
      out.insert(out.end(), {a, b, e, a, e, d});
    }
  return out;
}

std::vector<uint32_t> patchTriangles(uint32_t n, uint32_t coarse_sides) {
  std::vector<uint32_t> out;
  out.reserve(size_t(n) * n * 6);
  auto tri = [&](uint32_t a, uint32_t b, uint32_t c) { out.insert(out.end(), {a, b, c}); };
  const uint32_t blocks = n / 2;
  for (uint32_t by = 0; by < blocks; ++by)
    for (uint32_t bx = 0; bx < blocks; ++bx) {
      const uint32_t i0 = 2 * bx, j0 = 2 * by;
      const bool top = by == 0 && (coarse_sides & kSideTop);
      const bool right = bx + 1 == blocks && (coarse_sides & kSideRight);
      const bool bottom = by + 1 == blocks && (coarse_sides & kSideBottom);
      const bool left = bx == 0 && (coarse_sides & kSideLeft);
      if (top || right || bottom || left) {
        // The ring's outer fans (ringTriangles), with the midpoint left out
        // on the coarse sides only.
        const uint32_t c = vertexIndex(n, i0 + 1, j0 + 1);
        std::vector<uint32_t> rim;
        auto side = [&](uint32_t ia, uint32_t ja, uint32_t im, uint32_t jm, bool coarse) {
          rim.push_back(vertexIndex(n, ia, ja));
          if (!coarse) rim.push_back(vertexIndex(n, im, jm));
        };
        side(i0, j0, i0 + 1, j0, top);
        side(i0 + 2, j0, i0 + 2, j0 + 1, right);
        side(i0 + 2, j0 + 2, i0 + 1, j0 + 2, bottom);
        side(i0, j0 + 2, i0, j0 + 1, left);
        for (size_t k = 0; k < rim.size(); ++k) tri(c, rim[k], rim[(k + 1) % rim.size()]);
        continue;
      }
      for (uint32_t j = j0; j < j0 + 2; ++j)
        for (uint32_t i = i0; i < i0 + 2; ++i) {
          const uint32_t a = vertexIndex(n, i, j), b = vertexIndex(n, i + 1, j);
          const uint32_t d = vertexIndex(n, i, j + 1), e = vertexIndex(n, i + 1, j + 1);
          tri(a, b, e);
          tri(a, e, d);
        }
    }
  return out;
}

}  // namespace clipstream::terrain_mesh
