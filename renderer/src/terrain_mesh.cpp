#include "terrain_mesh.h"

#include <algorithm>
#include <cmath>
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

glm::i64vec2 ringOrigin(const glm::dvec2& camera_samples, uint32_t n, uint32_t level) {
  const glm::dvec2 cam = camera_samples / std::ldexp(1.0, int(level));
  const double half = double(n) / 2.0;
  return {2 * int64_t(std::floor((cam.x - half) / 2.0)), 2 * int64_t(std::floor((cam.y - half) / 2.0))};
}

void patternHole(uint32_t n, int pattern, int* hole_x, int* hole_y) {
  *hole_x = pattern == kNoHole ? -1 : int(n / 4) + (pattern - 1) % 2;
  *hole_y = pattern == kNoHole ? -1 : int(n / 4) + (pattern - 1) / 2;
}

int holePattern(const glm::i64vec2& fine_origin, const glm::i64vec2& origin, uint32_t n) {
  // The finer ring's origin in this level's samples (both are even at their own level).
  const int64_t kx = fine_origin.x / 2 - origin.x, ky = fine_origin.y / 2 - origin.y;
  const int64_t base = int64_t(n / 4);
  return 1 + int(kx - base) + 2 * int(ky - base);
}

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


namespace {

// The plain (n + 1)^2 grid's (i, j) pairs in row order.
std::vector<int32_t> gridVertices(uint32_t n) {
  std::vector<int32_t> out;
  out.reserve(size_t(n + 1) * (n + 1) * 2);
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) out.insert(out.end(), {int32_t(i), int32_t(j)});
  return out;
}

// Appends one pattern's triangles `tris` to `mesh`, filed in blocks by the
// cell of their centroid, each block with its own copy of its vertices.
void appendBlocks(uint32_t n, const std::vector<uint32_t>& tris, RingMesh* mesh,
                  std::array<IndexRange, RingMesh::kBlocks * RingMesh::kBlocks>* ranges) {
  constexpr uint32_t kBlocks = RingMesh::kBlocks;
  const uint32_t block_cells = n / kBlocks;
  std::vector<std::vector<uint32_t>> blocks(kBlocks * kBlocks);
  for (size_t t = 0; t < tris.size(); t += 3) {
    uint32_t sx = 0, sy = 0;
    for (int k = 0; k < 3; ++k) {
      sx += tris[t + k] % (n + 1);
      sy += tris[t + k] / (n + 1);
    }
    const uint32_t bx = std::min(sx / 3 / block_cells, kBlocks - 1);
    const uint32_t by = std::min(sy / 3 / block_cells, kBlocks - 1);
    blocks[by * kBlocks + bx].insert(blocks[by * kBlocks + bx].end(), tris.begin() + long(t),
                                     tris.begin() + long(t) + 3);
  }
  for (uint32_t b = 0; b < kBlocks * kBlocks; ++b) {
    std::vector<uint32_t> used(blocks[b]);
    std::sort(used.begin(), used.end());
    used.erase(std::unique(used.begin(), used.end()), used.end());
    const uint32_t base = uint32_t(mesh->vertices.size() / 2);
    for (uint32_t v : used) {
      mesh->vertices.push_back(int32_t(v % (n + 1)));
      mesh->vertices.push_back(int32_t(v / (n + 1)));
    }
    (*ranges)[b] = {uint32_t(mesh->indices.size()), uint32_t(blocks[b].size())};
    for (uint32_t v : blocks[b])
      mesh->indices.push_back(base + uint32_t(std::lower_bound(used.begin(), used.end(), v) - used.begin()));
  }
}

}  // namespace

RingMesh buildRingMesh(uint32_t n, bool plain_grid) {
  RingMesh mesh;
  mesh.vertices = gridVertices(n);
  mesh.patterns = plain_grid ? 1 : kRingPatterns;
  for (int pattern = 0; pattern < mesh.patterns; ++pattern) {
    int hx = 0, hy = 0;
    patternHole(n, pattern, &hx, &hy);
    const std::vector<uint32_t> tris = plain_grid ? gridTriangles(n) : ringTriangles(n, hx, hy);
    appendBlocks(n, tris, &mesh, &mesh.blocks[size_t(pattern)]);
  }
  return mesh;
}

PatchMesh buildPatchMesh(uint32_t n) {
  PatchMesh mesh;
  mesh.vertices = gridVertices(n);
  for (uint32_t mask = 0; mask < 16; ++mask) {
    const std::vector<uint32_t> tris = patchTriangles(n, mask);
    mesh.masks[mask] = {uint32_t(mesh.indices.size()), uint32_t(tris.size())};
    mesh.indices.insert(mesh.indices.end(), tris.begin(), tris.end());
  }
  return mesh;
}

}  // namespace clipstream::terrain_mesh
