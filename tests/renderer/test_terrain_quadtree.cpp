// The quadtree terrain method (TerrainMethod::kQuadtree) on the GPU: no
// crack and a restricted cover while the camera moves over rough ground,
// missing fine tiles drawing the finest resident ancestor without holes,
// flat ground kept coarse and rough ground refined, and the flat method.
// Fixtures: terrain_fixtures.h. Headless llvmpipe; GL tests skip without EGL.
#include "terrain_fixtures.h"

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/terrain.h>

#include "../../renderer/src/gl.h"
#include "../../renderer/src/gl_util.h"
#include "../../renderer/src/shaders.h"
#include "../../renderer/src/terrain_impl.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <map>
#include <utility>

namespace clipstream {
namespace {

using namespace terrain_test;

// Uploads every tile of every level of the field (the quadtree scenes'
// stack holds them all), from level `finest` up.
void uploadAll(TerrainRenderer& terrain, const HeightField& f, uint32_t finest = 0) {
  for (uint32_t l = finest; l < f.geometry.levelCount(); ++l)
    for (uint32_t y = 0; y < f.geometry.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < f.geometry.levels[l].tiles_x; ++x) {
        const TileKey key{l, x, y};
        terrain.uploadTile(key, f.tile(key).data());
      }
}

// The exact per-tile bounds and errors of a field (the tiler's rule, by
// brute force): the error of a level-L tile is the largest distance of the
// level-0 samples under it from the bilinear surface of level L.
std::shared_ptr<TerrainBounds> exactBounds(const HeightField& f) {
  auto b = std::make_shared<TerrainBounds>();
  const PyramidGeometry& g = f.geometry;
  b->tile_px = g.tile_px;
  b->width_samples = f.w;
  b->height_samples = f.h;
  b->levels.resize(g.levelCount());
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    TerrainBounds::Level& lv = b->levels[l];
    lv.tiles_x = g.levels[l].tiles_x;
    lv.tiles_y = g.levels[l].tiles_y;
    lv.range.assign(size_t(lv.tiles_x) * lv.tiles_y, glm::vec2(INFINITY, -INFINITY));
    lv.error.assign(size_t(lv.tiles_x) * lv.tiles_y, 0.0f);
    const uint64_t span = uint64_t(g.tile_px) << l;
    const double step = std::ldexp(1.0, int(l));
    for (uint32_t j = 0; j < f.h; ++j)
      for (uint32_t i = 0; i < f.w; ++i) {
        const size_t t = size_t(j / span) * lv.tiles_x + i / span;
        const float h0 = f.samples[size_t(j) * f.w + i];
        lv.range[t] = {std::min(lv.range[t].x, h0), std::max(lv.range[t].y, h0)};
        const double u = i / step, v = j / step;
        const int64_t i0 = int64_t(u), j0 = int64_t(v);
        const double fu = u - double(i0), fv = v - double(j0);
        const double bil = (1 - fu) * (1 - fv) * f.at(l, i0, j0) + fu * (1 - fv) * f.at(l, i0 + 1, j0) +
                           (1 - fu) * fv * f.at(l, i0, j0 + 1) + fu * fv * f.at(l, i0 + 1, j0 + 1);
        lv.error[t] = std::max(lv.error[t], float(std::abs(h0 - bil)));
      }
  }
  b->range = b->levels.back().range[0];
  return b;
}

// The leaves of the last draw cover the field once, and every drawn leaf's
// neighbours are at most one level coarser, with exactly those sides
// marked coarse. Returns the drawn leaves.
size_t checkRestrictedCover(const TerrainRenderer& terrain, uint32_t patch) {
  const std::vector<TerrainNode>& nodes = terrain.lastNodes();
  // Which leaf covers each level-0 sample cell (i + 0.5, j + 0.5) of the
  // field's 1024^2 samples, on a grid of every 8th.
  auto covering = [&](double i, double j) -> const TerrainNode* {
    const TerrainNode* found = nullptr;
    for (const TerrainNode& n : nodes) {
      const double span = std::ldexp(double(patch), int(n.level));
      if (i >= n.x * span && i < (n.x + 1) * span && j >= n.y * span && j < (n.y + 1) * span) {
        EXPECT_EQ(found, nullptr) << "two leaves over (" << i << ", " << j << ")";
        found = &n;
      }
    }
    return found;
  };
  for (double j = 0.5; j < 1024.0; j += 8.0)
    for (double i = 0.5; i < 1024.0; i += 8.0) EXPECT_NE(covering(i, j), nullptr) << i << ", " << j;
  size_t drawn = 0;
  for (const TerrainNode& n : nodes) {
    if (!n.drawn) continue;
    ++drawn;
    const double span = std::ldexp(double(patch), int(n.level));
    const double mid_x = (n.x + 0.5) * span, mid_y = (n.y + 0.5) * span;
    const double dx[4] = {0, 1, 0, -1}, dy[4] = {-1, 0, 1, 0};
    for (int side = 0; side < 4; ++side) {
      const double px = mid_x + dx[side] * (0.5 * span + 0.25), py = mid_y + dy[side] * (0.5 * span + 0.25);
      if (px < 0 || py < 0 || px >= 1024.0 || py >= 1024.0) continue;
      const TerrainNode* nb = covering(px, py);
      if (nb == nullptr) continue;
      if (nb->drawn) {
        EXPECT_LE(nb->level, n.level + 1) << "neighbours two levels apart";
      }
      EXPECT_EQ(((n.coarse_sides >> side) & 1) != 0, nb->level > n.level)
          << "level " << n.level << " (" << n.x << ", " << n.y << ") side " << side;
    }
  }
  return drawn;
}

TEST(TerrainQuadtree, NoCrackAndRestrictedWhileTheCameraMovesOverRoughGround) {
  CLIPSTREAM_REQUIRE_GL();
  Camera camera = overField(1000.0, 1000.0, 160.0, 0.6, -0.45);
  TerrainScene s = makeScene(camera, 64, TerrainMethod::kQuadtree);
  ASSERT_TRUE(s.terrain && s.colour && s.target);
  s.terrain->setBounds(exactBounds(s.field));
  uploadAll(*s.terrain, s.field);
  const float lowest = s.field.lowest();
  std::map<uint32_t, size_t> levels_seen;
  uint32_t stitched = 0;
  for (int step = 0; step < 24; ++step) {
    camera.position.x = 1000.0 + step * 3.7;
    camera.position.z = 1000.0 - step * 2.3;
    camera.heading_rad = 0.6 + step * (6.2831853 / 24.0);
    camera.position.y = (step % 3 == 0) ? 110.0 : 160.0 + step;
    const std::vector<uint8_t> rgba = drawTerrain(s, camera);
    EXPECT_GT(groundPixels(rgba), rgba.size() / 8) << "step " << step;
    std::vector<uint8_t> marked;
    const size_t cracks = crackPixels(rgba, camera, lowest, &marked);
    if (cracks > 0) test::dumpPpm("quadtree_crack_" + std::to_string(step), marked, kViewport);
    EXPECT_EQ(cracks, 0u) << "step " << step;
    EXPECT_EQ(checkRestrictedCover(*s.terrain, s.terrain->config().patch_cells), s.terrain->lastFrame().nodes);
    for (const TerrainNode& n : s.terrain->lastNodes())
      if (n.drawn) {
        ++levels_seen[n.level];
        if (n.coarse_sides) ++stitched;
      }
    EXPECT_EQ(s.terrain->lastFrame().finest_level, 0u) << "step " << step;
    EXPECT_EQ(s.terrain->lastFrame().fallback_nodes, 0u);
  }
  // Several levels in every frame, and sides stitched to coarser nodes.
  EXPECT_GE(levels_seen.size(), 3u);
  EXPECT_GT(stitched, 24u);
}

TEST(TerrainQuadtree, MissingFineTilesDrawTheFinestResidentAncestorWithoutHoles) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera camera = overField(900.0, 1100.0, 140.0, 2.0, -0.5);
  TerrainScene s = makeScene(camera, 64, TerrainMethod::kQuadtree);
  ASSERT_TRUE(s.terrain);
  s.terrain->setBounds(exactBounds(s.field));
  // Nothing resident: nothing drawn (no garbage heights).
  std::vector<uint8_t> rgba = drawTerrain(s, camera);
  EXPECT_EQ(s.terrain->lastFrame().nodes, 0u);
  EXPECT_EQ(groundPixels(rgba), 0u);
  // Levels 2 and coarser: nodes that want to split are drawn at level 2.
  uploadAll(*s.terrain, s.field, 2);
  rgba = drawTerrain(s, camera);
  EXPECT_EQ(s.terrain->lastFrame().finest_level, 2u);
  EXPECT_GT(s.terrain->lastFrame().fallback_nodes, 0u);
  EXPECT_EQ(crackPixels(rgba, camera, s.field.lowest()), 0u);
  checkRestrictedCover(*s.terrain, s.terrain->config().patch_cells);
  // Level 0 only under part of the field: restricted, no crack, finer there.
  for (uint32_t y = 3; y < 6; ++y)
    for (uint32_t x = 2; x < 5; ++x) s.terrain->uploadTile({1, x / 2, y / 2}, s.field.tile({1, x / 2, y / 2}).data());
  for (uint32_t y = 3; y < 6; ++y)
    for (uint32_t x = 2; x < 5; ++x) s.terrain->uploadTile({0, x, y}, s.field.tile({0, x, y}).data());
  rgba = drawTerrain(s, camera);
  EXPECT_EQ(s.terrain->lastFrame().finest_level, 0u);
  EXPECT_EQ(crackPixels(rgba, camera, s.field.lowest()), 0u);
  checkRestrictedCover(*s.terrain, s.terrain->config().patch_cells);
}

TEST(TerrainQuadtree, FlatGroundStaysCoarseAndRoughGroundIsRefined) {
  CLIPSTREAM_REQUIRE_GL();
  // Flat up to x = 640, the rough field beyond; the camera high above the
  // middle looking straight down sees both halves at the same distances.
  // (The flat level-2 tile, x < 512, reaches to its neighbour's first
  // sample: that is flat too, so its error is 0.)
  HeightField f = roughField(1024);
  for (uint32_t y = 0; y < 1024; ++y)
    for (uint32_t x = 0; x < 640; ++x) f.samples[size_t(y) * 1024 + x] = 30.0f;
  const Camera camera = overField(1024.0, 1024.0, 1400.0, 0.0, -1.5707);
  TerrainScene s = makeScene(camera, 64, TerrainMethod::kQuadtree, f);
  ASSERT_TRUE(s.terrain);
  const std::shared_ptr<TerrainBounds> bounds = exactBounds(s.field);
  auto drawWith = [&](double error_px) {
    TerrainConfig tc = s.terrain->config();
    tc.error_px = error_px;
    tc.triangle_budget = 0;  // the bound alone decides
    std::unique_ptr<TerrainRenderer> t;
    EXPECT_TRUE(TerrainRenderer::create(s.field.geometry, tc, &t).ok());
    t->setBounds(bounds);
    uploadAll(*t, s.field);
    s.target->bind();
    t->draw(camera, kViewport, *s.colour);
    return t;
  };
  const std::unique_ptr<TerrainRenderer> t = drawWith(1.0);
  const uint32_t patch = t->config().patch_cells;
  // Drawn nodes over each half (by their centre), and the ground they cover.
  double flat_area = 0, rough_area = 0, flat_nodes = 0, rough_nodes = 0;
  for (const TerrainNode& n : t->lastNodes()) {
    if (!n.drawn) continue;
    const double span = std::ldexp(double(patch), int(n.level));
    const bool flat = (n.x + 0.5) * span < 512.0;
    (flat ? flat_nodes : rough_nodes) += 1;
    (flat ? flat_area : rough_area) += span * span;
  }
  ASSERT_GT(flat_nodes, 0);
  ASSERT_GT(rough_nodes, 0);
  // Nodes (triangles) per unit of ground: rough ground several times the flat's.
  const double flat_density = flat_nodes / flat_area, rough_density = rough_nodes / rough_area;
  std::printf("  nodes per 1000 samples^2: flat %.3f, rough %.3f\n", 1e3 * flat_density, 1e3 * rough_density);
  EXPECT_GT(rough_density, 4.0 * flat_density);
  // A tighter bound draws more triangles; a looser one fewer.
  const uint64_t at_one = t->lastFrame().triangles;
  EXPECT_GT(drawWith(0.25)->lastFrame().triangles, at_one);
  EXPECT_LT(drawWith(6.0)->lastFrame().triangles, at_one);
}

TEST(TerrainQuadtree, FlatMethodDrawsThePlaneAndRejectsBadSettings) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera camera = overField(1000.0, 1000.0, 160.0, 0.6, -0.45);
  TerrainScene s = makeScene(camera, 64, TerrainMethod::kFlat);
  ASSERT_TRUE(s.terrain);
  uploadAll(*s.terrain, s.field);
  const std::vector<uint8_t> rgba = drawTerrain(s, camera);
  // The plane at the lowest height of the pyramid's last level: no crack
  // against the field's lowest ground, every ground pixel at that height
  // (the position pass), and the ground under a camera is still the
  // terrain's (cameras fly the same paths as over the other methods).
  EXPECT_GT(groundPixels(rgba), rgba.size() / 8);
  EXPECT_EQ(crackPixels(rgba, camera, s.field.lowest()), 0u);
  std::vector<float> xyzw;
  ASSERT_TRUE(s.terrain->readPositions(camera, kViewport, *s.colour, &xyzw).ok());
  float plane = INFINITY;
  for (uint32_t j = 0; j < s.field.geometry.levels.back().height_px; ++j)
    for (uint32_t i = 0; i < s.field.geometry.levels.back().width_px; ++i)
      plane = std::min(plane, s.field.at(s.field.geometry.levelCount() - 1, i, j));
  size_t on_plane = 0, ground = 0;
  for (size_t k = 0; k < xyzw.size(); k += 4) {
    if (xyzw[k + 3] < 1.0f) continue;
    ++ground;
    on_plane += std::abs(double(xyzw[k + 1]) + camera.position.y - plane) < 1e-3;
  }
  EXPECT_GT(ground, 0u);
  EXPECT_EQ(on_plane, ground);
  double h = 0.0;
  ASSERT_TRUE(s.terrain->groundHeight({1001.0, 777.0}, &h));
  EXPECT_FLOAT_EQ(float(h), s.field.at(0, 500, 388));
  TerrainConfig tc = s.terrain->config();
  std::unique_ptr<TerrainRenderer> t;
  for (uint32_t bad : {7u, 12u, 2u, 512u}) {  // not a power of two from 4 to 256
    tc.patch_cells = bad;
    EXPECT_EQ(TerrainRenderer::create(s.field.geometry, tc, &t).code, ErrorCode::kInvalidArgument) << bad;
  }
  tc.patch_cells = 32;
  tc.error_px = 0.0;
  EXPECT_EQ(TerrainRenderer::create(s.field.geometry, tc, &t).code, ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace clipstream
