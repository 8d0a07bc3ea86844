// The terrain's meshes and ring layout on the CPU (renderer/src/
// terrain_mesh.h), and the height stack's slot rule: the ring and patch
// index patterns cover their cells once without a crack, the buffers
// built from them hold every triangle once in its block, rings nest and
// meet vertex for vertex, and a stack has a slot for every tile a ring or
// the streamer's window needs. No GL.
#include <clipstream/renderer/terrain.h>

#include "../../renderer/src/terrain_height_stack.h"
#include "../../renderer/src/terrain_mesh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <map>
#include <set>
#include <utility>
#include <vector>

namespace clipstream {
namespace {

using Point = std::pair<int, int>;
using Edge = std::pair<Point, Point>;        // lower point first
using Triangle = std::array<Point, 3>;       // sorted: the same triangle whatever its winding

Point gridPoint(uint32_t n, uint32_t v) { return {int(v % (n + 1)), int(v / (n + 1))}; }

Edge edgeOf(Point a, Point b) { return a < b ? Edge{a, b} : Edge{b, a}; }

// Twice the signed area of triangle abc.
int twiceArea(Point a, Point b, Point c) {
  return (b.first - a.first) * (c.second - a.second) - (c.first - a.first) * (b.second - a.second);
}

// The area and the edge uses of a mesh of index triples over an
// (n + 1)^2 vertex grid; a degenerate triangle fails the test.
struct MeshTopology {
  double area = 0.0;
  std::map<std::pair<uint32_t, uint32_t>, int> edges;  // (lower, higher vertex) -> triangles
};
MeshTopology topologyOf(const std::vector<uint32_t>& tris, uint32_t n) {
  MeshTopology m;
  EXPECT_EQ(tris.size() % 3, 0u);
  for (size_t t = 0; t + 2 < tris.size(); t += 3) {
    const int a = twiceArea(gridPoint(n, tris[t]), gridPoint(n, tris[t + 1]), gridPoint(n, tris[t + 2]));
    EXPECT_NE(a, 0) << "degenerate triangle";
    m.area += 0.5 * std::abs(a);
    for (int e = 0; e < 3; ++e) {
      uint32_t u = tris[t + e], v = tris[t + (e + 1) % 3];
      if (u > v) std::swap(u, v);
      ++m.edges[{u, v}];
    }
  }
  return m;
}

// Edges used by one triangle only, as grid points.
std::set<Edge> borderEdges(const std::vector<uint32_t>& tris, uint32_t n) {
  std::set<Edge> border;
  for (const auto& [edge, uses] : topologyOf(tris, n).edges)
    if (uses == 1) border.insert(edgeOf(gridPoint(n, edge.first), gridPoint(n, edge.second)));
  return border;
}

// The triangles of `tris` as sorted point triples (a multiset).
std::multiset<Triangle> trianglesOf(const std::vector<uint32_t>& tris, uint32_t n) {
  std::multiset<Triangle> out;
  for (size_t t = 0; t + 2 < tris.size(); t += 3) {
    Triangle tri{gridPoint(n, tris[t]), gridPoint(n, tris[t + 1]), gridPoint(n, tris[t + 2])};
    std::sort(tri.begin(), tri.end());
    out.insert(tri);
  }
  return out;
}

// The ring of n cells with no hole, counted by hand: (n/2 - 2)^2 inner
// 2 x 2 blocks of 8 triangles, 4 (n/2 - 2) side fans of 7 (one midpoint
// skipped) and 4 corner fans of 6 (two skipped).
size_t ringTriangleCount(uint32_t n) {
  const size_t inner = size_t(n / 2 - 2);
  return inner * inner * 8 + 4 * inner * 7 + 4 * 6;
}

TEST(TerrainMesh, RingsCoverTheirCellsOnceAndMeetWithoutTJunctions) {
  for (uint32_t n : {16u, 64u, 128u}) {
    for (int config = 0; config < 5; ++config) {
      const int hx = config == 0 ? -1 : int(n / 4) + (config - 1) % 2;
      const int hy = config == 0 ? -1 : int(n / 4) + (config - 1) / 2;
      int pattern_hx = 0, pattern_hy = 0;
      terrain_mesh::patternHole(n, config, &pattern_hx, &pattern_hy);
      EXPECT_EQ(pattern_hx, hx);
      EXPECT_EQ(pattern_hy, hy);
      const std::vector<uint32_t> tris = terrain_mesh::ringTriangles(n, hx, hy);
      const MeshTopology topology = topologyOf(tris, n);
      const double hole = config == 0 ? 0.0 : double(n / 2) * (n / 2);
      EXPECT_DOUBLE_EQ(topology.area, double(n) * n - hole) << "n " << n << " config " << config;
      EXPECT_EQ(tris.size() / 3, ringTriangleCount(n) - (config == 0 ? 0 : size_t(n / 2) * (n / 2) * 2));
      for (const auto& [edge, uses] : topology.edges) {
        ASSERT_LE(uses, 2) << "an edge shared by three triangles";
        if (uses == 2) continue;
        // A border edge: on the outer edge it joins two even vertices two
        // cells apart (the coarser ring's vertices); on the hole's edge it
        // is one cell long (the finer ring's outer edge has the same).
        const auto [ux, uy] = gridPoint(n, edge.first);
        const auto [vx, vy] = gridPoint(n, edge.second);
        const bool outer = (ux == vx && (ux == 0 || ux == int(n))) || (uy == vy && (uy == 0 || uy == int(n)));
        if (outer) {
          EXPECT_EQ(std::abs(ux - vx) + std::abs(uy - vy), 2) << "T-junction on the outer edge";
          EXPECT_EQ(ux % 2 + uy % 2 + vx % 2 + vy % 2, 0);
        } else {
          ASSERT_NE(config, 0) << "a border edge inside a ring without hole";
          EXPECT_EQ(std::abs(ux - vx) + std::abs(uy - vy), 1);
          const bool on_hole = (ux == hx || ux == hx + int(n / 2) || uy == hy || uy == hy + int(n / 2));
          EXPECT_TRUE(on_hole) << "a crack inside the ring at (" << ux << ", " << uy << ")";
        }
      }
    }
  }
}

TEST(TerrainMesh, PatchEdgePatternsCoverTheirCellsAndSkipOddVerticesTowardsCoarserNodes) {
  for (uint32_t n : {4u, 8u, 32u}) {
    for (uint32_t mask = 0; mask < 16; ++mask) {
      const std::vector<uint32_t> tris = terrain_mesh::patchTriangles(n, mask);
      const MeshTopology topology = topologyOf(tris, n);
      EXPECT_DOUBLE_EQ(topology.area, double(n) * n) << "n " << n << " mask " << mask;
      // Each coarse side turns its n/2 blocks' 8 triangles into 7.
      const size_t coarse_sides = size_t(__builtin_popcount(mask));
      EXPECT_EQ(tris.size() / 3, size_t(n) * n * 2 - coarse_sides * n / 2) << "n " << n << " mask " << mask;
      // Every border edge lies on a side: two cells long between even
      // vertices on a side towards a coarser node, one cell elsewhere.
      size_t border = 0;
      for (const auto& [edge, uses] : topology.edges) {
        ASSERT_LE(uses, 2) << "an edge shared by three triangles";
        if (uses == 2) continue;
        ++border;
        const auto [ux, uy] = gridPoint(n, edge.first);
        const auto [vx, vy] = gridPoint(n, edge.second);
        int side = -1;
        if (uy == 0 && vy == 0) side = 0;
        if (ux == int(n) && vx == int(n)) side = 1;
        if (uy == int(n) && vy == int(n)) side = 2;
        if (ux == 0 && vx == 0) side = 3;
        ASSERT_GE(side, 0) << "a border edge inside the patch: a crack";
        const bool coarse = (mask >> side) & 1;
        EXPECT_EQ(std::abs(ux - vx) + std::abs(uy - vy), coarse ? 2 : 1) << "mask " << mask << " side " << side;
        if (coarse) {
          EXPECT_EQ(ux % 2 + uy % 2 + vx % 2 + vy % 2, 0) << "an odd vertex on a coarse side";
        }
      }
      size_t want = 0;
      for (int side = 0; side < 4; ++side) want += ((mask >> side) & 1) ? n / 2 : n;
      EXPECT_EQ(border, want) << "n " << n << " mask " << mask;
    }
  }
}

// The buffers of the ring mesh: the plain grid first, every pattern's
// triangles once, each in the block of its centroid, drawn from the
// block's own vertex copies, which it all uses.
void checkRingMesh(uint32_t n, bool plain_grid) {
  SCOPED_TRACE("n " + std::to_string(n) + (plain_grid ? " plain grid" : " rings"));
  constexpr uint32_t kBlocks = terrain_mesh::RingMesh::kBlocks;
  const terrain_mesh::RingMesh mesh = terrain_mesh::buildRingMesh(n, plain_grid);
  ASSERT_EQ(mesh.patterns, plain_grid ? 1 : terrain_mesh::kRingPatterns);
  const size_t grid = size_t(n + 1) * (n + 1);
  ASSERT_EQ(mesh.vertices.size() % 2, 0u);
  ASSERT_GE(mesh.vertices.size() / 2, grid);
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) {
      const size_t v = terrain_mesh::vertexIndex(n, i, j);
      ASSERT_EQ(mesh.vertices[2 * v], int32_t(i));
      ASSERT_EQ(mesh.vertices[2 * v + 1], int32_t(j));
    }
  auto point = [&](uint32_t v) { return Point{mesh.vertices[2 * v], mesh.vertices[2 * v + 1]}; };
  // Ranges follow each other through the whole index buffer, and each
  // block's vertex copies follow each other after the grid.
  uint32_t next_index = 0;
  size_t next_vertex = grid;
  for (int pattern = 0; pattern < terrain_mesh::kRingPatterns; ++pattern) {
    int hx = 0, hy = 0;
    terrain_mesh::patternHole(n, pattern, &hx, &hy);
    std::multiset<Triangle> want;
    if (pattern < mesh.patterns)
      want = trianglesOf(plain_grid ? terrain_mesh::gridTriangles(n) : terrain_mesh::ringTriangles(n, hx, hy), n);
    std::multiset<Triangle> got;
    for (uint32_t b = 0; b < kBlocks * kBlocks; ++b) {
      const terrain_mesh::IndexRange range = mesh.blocks[size_t(pattern)][b];
      if (pattern >= mesh.patterns) {
        EXPECT_EQ(range.count, 0u) << "a pattern the mesh does not have";
        continue;
      }
      ASSERT_EQ(range.first, next_index) << "pattern " << pattern << " block " << b;
      ASSERT_EQ(range.count % 3, 0u);
      next_index += range.count;
      std::set<uint32_t> used;
      for (uint32_t k = range.first; k < range.first + range.count; k += 3) {
        Triangle tri;
        int cx = 0, cy = 0;
        for (int c = 0; c < 3; ++c) {
          const uint32_t v = mesh.indices[k + uint32_t(c)];
          used.insert(v);
          tri[size_t(c)] = point(v);
          cx += tri[size_t(c)].first;
          cy += tri[size_t(c)].second;
        }
        EXPECT_NE(twiceArea(tri[0], tri[1], tri[2]), 0) << "degenerate triangle";
        // Filed by the cell of its centroid.
        const uint32_t block_cells = n / kBlocks;
        EXPECT_EQ(std::min(uint32_t(cx) / 3 / block_cells, kBlocks - 1), b % kBlocks);
        EXPECT_EQ(std::min(uint32_t(cy) / 3 / block_cells, kBlocks - 1), b / kBlocks);
        std::sort(tri.begin(), tri.end());
        got.insert(tri);
      }
      if (used.empty()) continue;
      // The block's own copies, every one of them used.
      EXPECT_EQ(*used.begin(), next_vertex) << "pattern " << pattern << " block " << b;
      EXPECT_EQ(*used.rbegin() + 1 - *used.begin(), used.size()) << "an unused vertex copy";
      next_vertex += used.size();
    }
    EXPECT_EQ(got, want) << "pattern " << pattern << ": a triangle lost, added or duplicated";
    EXPECT_EQ(std::set<Triangle>(got.begin(), got.end()).size(), got.size()) << "a duplicated triangle";
  }
  EXPECT_EQ(next_index, mesh.indices.size());
  EXPECT_EQ(next_vertex, mesh.vertices.size() / 2);
  // Index counts by hand.
  const size_t want_indices =
      plain_grid ? size_t(n) * n * 6 : 3 * (5 * ringTriangleCount(n) - 4 * size_t(n / 2) * (n / 2) * 2);
  EXPECT_EQ(mesh.indices.size(), want_indices);
}

TEST(TerrainMesh, RingBuffersHoldEveryTriangleOnceInTheBlockOfItsCentroid) {
  for (uint32_t n : {16u, 64u, 128u}) checkRingMesh(n, false);
}

TEST(TerrainMesh, FullResolutionBuffersAreOnePlainGridThatMeetsItsNeighbours) {
  for (uint32_t n : {16u, 128u}) checkRingMesh(n, true);
  // Patches side by side share their border vertex for vertex: the right
  // side's edges moved n cells left are the left side's.
  const uint32_t n = 32;
  std::set<Edge> right, left, top, bottom;
  for (const Edge& e : borderEdges(terrain_mesh::gridTriangles(n), n)) {
    if (e.first.first == int(n) && e.second.first == int(n)) right.insert({{0, e.first.second}, {0, e.second.second}});
    if (e.first.first == 0 && e.second.first == 0) left.insert(e);
    if (e.first.second == int(n) && e.second.second == int(n)) bottom.insert({{e.first.first, 0}, {e.second.first, 0}});
    if (e.first.second == 0 && e.second.second == 0) top.insert(e);
  }
  EXPECT_EQ(right.size(), n);
  EXPECT_EQ(right, left);
  EXPECT_EQ(bottom.size(), n);
  EXPECT_EQ(bottom, top);
}

TEST(TerrainMesh, PatchBuffersHoldTheSixteenEdgePatternsInMaskOrder) {
  const uint32_t n = 16;
  const terrain_mesh::PatchMesh mesh = terrain_mesh::buildPatchMesh(n);
  ASSERT_EQ(mesh.vertices.size(), size_t(n + 1) * (n + 1) * 2);
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) {
      EXPECT_EQ(mesh.vertices[2 * terrain_mesh::vertexIndex(n, i, j)], int32_t(i));
      EXPECT_EQ(mesh.vertices[2 * terrain_mesh::vertexIndex(n, i, j) + 1], int32_t(j));
    }
  uint32_t next = 0;
  for (uint32_t mask = 0; mask < 16; ++mask) {
    const std::vector<uint32_t> want = terrain_mesh::patchTriangles(n, mask);
    const terrain_mesh::IndexRange range = mesh.masks[mask];
    EXPECT_EQ(range.first, next) << "mask " << mask;
    ASSERT_EQ(range.count, want.size()) << "mask " << mask;
    EXPECT_TRUE(std::equal(want.begin(), want.end(), mesh.indices.begin() + range.first)) << "mask " << mask;
    next += range.count;
  }
  EXPECT_EQ(next, mesh.indices.size());
}

TEST(TerrainMesh, RingsNestAroundTheCameraAndMeetVertexForVertex) {
  // Cameras anywhere (negative, fractional, far out), every level pair:
  // the finer ring lies in one of the coarser ring's four holes, exactly on
  // its vertices, and the finer ring's outer border is the hole's border,
  // edge for edge (no crack, no T-junction).
  uint64_t seed = 12345;
  auto next = [&seed]() {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    return double(seed >> 11) / double(1ull << 53);
  };
  for (uint32_t n : {16u, 64u}) {
    std::map<int, std::set<Edge>> hole_borders;  // by pattern, in coarse grid points
    for (int pattern = 1; pattern < terrain_mesh::kRingPatterns; ++pattern) {
      int hx = 0, hy = 0;
      terrain_mesh::patternHole(n, pattern, &hx, &hy);
      for (const Edge& e : borderEdges(terrain_mesh::ringTriangles(n, hx, hy), n)) {
        const bool outer = e.first.first == 0 || e.first.second == 0 || e.second.first == int(n) ||
                           e.second.second == int(n);
        if (!outer) hole_borders[pattern].insert(e);
      }
      EXPECT_EQ(hole_borders[pattern].size(), size_t(4 * n / 2)) << "pattern " << pattern;
    }
    // The finer ring's outer border (the same whatever its own hole).
    const std::set<Edge> fine_outer = borderEdges(terrain_mesh::ringTriangles(n, -1, -1), n);
    ASSERT_EQ(fine_outer.size(), size_t(4 * n / 2));
    std::set<int> patterns_seen;
    for (int k = 0; k < 200; ++k) {
      const glm::dvec2 cam((next() - 0.5) * 1e7, (next() - 0.5) * 1e5);
      for (uint32_t l = 0; l < 12; ++l) {
        const glm::i64vec2 fine = terrain_mesh::ringOrigin(cam, n, l);
        const glm::i64vec2 coarse = terrain_mesh::ringOrigin(cam, n, l + 1);
        ASSERT_EQ(fine.x % 2, 0);
        ASSERT_EQ(fine.y % 2, 0);
        // Centred: the camera within two samples of the ring's middle.
        const glm::dvec2 at = cam / std::ldexp(1.0, int(l));
        EXPECT_LE(std::abs(at.x - double(fine.x + n / 2)), 2.0);
        EXPECT_LE(std::abs(at.y - double(fine.y + n / 2)), 2.0);
        const int pattern = terrain_mesh::holePattern(fine, coarse, n);
        ASSERT_GE(pattern, 1);
        ASSERT_LE(pattern, 4);
        patterns_seen.insert(pattern);
        int hx = 0, hy = 0;
        terrain_mesh::patternHole(n, pattern, &hx, &hy);
        // The finer ring's vertex (0, 0) is the coarser ring's (hx, hy).
        ASSERT_EQ(fine.x, 2 * (coarse.x + hx));
        ASSERT_EQ(fine.y, 2 * (coarse.y + hy));
        // Its outer border (even vertices only), in the coarser ring's grid
        // points, is the hole's border.
        std::set<Edge> mapped;
        for (const Edge& e : fine_outer)
          mapped.insert(edgeOf({hx + e.first.first / 2, hy + e.first.second / 2},
                               {hx + e.second.first / 2, hy + e.second.second / 2}));
        ASSERT_EQ(mapped, hole_borders[pattern]) << "rings do not meet at level " << l;
      }
    }
    EXPECT_EQ(patterns_seen.size(), 4u) << "every hole position occurs";
  }
}

TEST(TerrainMesh, APatchSideTowardsACoarserNodeHasExactlyThatNodesVertices) {
  // A level-L patch whose side s borders a level-(L + 1) patch: along that
  // side, the finer patch's border edges (in level-L samples) are the
  // coarser patch's own side edges (1 cell of level L + 1 = 2 of level L)
  // over the half they share.
  const uint32_t n = 16;
  for (uint32_t mask = 1; mask < 16; ++mask)
    for (int side = 0; side < 4; ++side) {
      if (!((mask >> side) & 1)) continue;
      // Along-side positions of the border edges on `side`, in level-L samples.
      auto sideSpans = [&](const std::vector<uint32_t>& tris, int scale) {
        std::set<std::pair<int, int>> spans;
        for (const Edge& e : borderEdges(tris, n)) {
          const bool vertical = side == 1 || side == 3;
          const int at = side == 0 || side == 3 ? 0 : int(n);
          const Point a = e.first, b = e.second;
          if (vertical ? (a.first == at && b.first == at) : (a.second == at && b.second == at)) {
            const int u = vertical ? a.second : a.first, v = vertical ? b.second : b.first;
            spans.insert({std::min(u, v) * scale, std::max(u, v) * scale});
          }
        }
        return spans;
      };
      const std::set<std::pair<int, int>> fine = sideSpans(terrain_mesh::patchTriangles(n, mask), 1);
      // The coarser neighbour's side facing it (not coarse: the finer node
      // is no coarser than it; every plain side has the same edges), in
      // level-L samples, over the half beside the finer node.
      const std::set<std::pair<int, int>> coarse_all = sideSpans(terrain_mesh::patchTriangles(n, 0), 2);
      std::set<std::pair<int, int>> coarse_half;
      for (const auto& span : coarse_all)
        if (span.second <= int(n)) coarse_half.insert(span);
      EXPECT_EQ(fine, coarse_half) << "mask " << mask << " side " << side;
    }
}

TEST(TerrainHeightStack, SlotsHoldEveryTileARingOrTheStreamersWindowReads) {
  for (uint32_t tile : {64u, 128u, 256u})
    for (uint32_t n = 16; n <= 1024; n *= 2) {
      PyramidGeometry g;
      ASSERT_TRUE(makePyramidGeometry(8192, 8192, tile, PixelFormat::kF32, &g));
      TerrainConfig config;
      config.ring_cells = n;
      const uint32_t alone = TerrainHeightStack::slotsFor(g, config);
      // The most tiles a ring's n + 3 samples touch, at any offset in a
      // tile, plus one slot for a tile that just left.
      uint32_t most = 0;
      for (uint32_t offset = 0; offset < tile; ++offset)
        most = std::max(most, (offset + n + 2) / tile + 1);
      EXPECT_GE(alone, most + 1) << "tile " << tile << " n " << n;
      // With the streamer's window (TerrainRenderer::windowTiles()): more
      // slots than the window's tiles.
      config.clip_tiles = TerrainRenderer::windowTiles(n, tile);
      EXPECT_GT(TerrainHeightStack::slotsFor(g, config), config.clip_tiles) << "tile " << tile << " n " << n;
      // The full-resolution mesh: level 0 whole.
      config.full_resolution = true;
      EXPECT_EQ(TerrainHeightStack::slotsFor(g, config), g.levels[0].tiles_x);
    }
}

}  // namespace
}  // namespace clipstream
