// The terrain (terrain.h) on the GPU: no crack (no background pixel where
// the ground must be) at rest and while the rings move across level
// borders, vertex heights and normals against the CPU, missing fine tiles
// coarsening the geometry rather than opening holes, the height stack's
// toroidal slots, and the quadtree. The meshes on the CPU are
// test_terrain_mesh.cpp's. Headless llvmpipe; GL tests skip without EGL.
#include "test_helpers.h"

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

const Viewport kViewport{320, 200};

// A height field of w x h level-0 samples (heights in world units).
struct HeightField {
  uint32_t w = 0, h = 0;
  std::vector<float> samples;
  PyramidGeometry geometry;

  float at(uint32_t level, int64_t i, int64_t j) const {
    const int64_t step = int64_t(1) << level;
    const int64_t x = std::clamp<int64_t>(i * step, 0, w - 1);
    const int64_t y = std::clamp<int64_t>(j * step, 0, h - 1);
    return samples[size_t(y) * w + size_t(x)];
  }
  // Tile (level, tx, ty) as the tiler cuts it: decimated, edges repeated.
  std::vector<float> tile(const TileKey& k) const {
    const uint32_t t = geometry.tile_px;
    const LevelInfo& info = geometry.levels[k.level];
    std::vector<float> out(size_t(t) * t);
    for (uint32_t y = 0; y < t; ++y)
      for (uint32_t x = 0; x < t; ++x) {
        const int64_t i = std::min<int64_t>(int64_t(k.x) * t + x, int64_t(info.width_px) - 1);
        const int64_t j = std::min<int64_t>(int64_t(k.y) * t + y, int64_t(info.height_px) - 1);
        out[size_t(y) * t + x] = at(k.level, i, j);
      }
    return out;
  }
  float lowest() const { return *std::min_element(samples.begin(), samples.end()); }
  float highest() const { return *std::max_element(samples.begin(), samples.end()); }
};

// Rolling hills, a sharp ridge and a 40-unit cliff: what rings must stitch.
HeightField roughField(uint32_t side) {
  HeightField f;
  f.w = f.h = side;
  f.samples.resize(size_t(side) * side);
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      double v = 40.0 + 25.0 * std::sin(x * 0.05) * std::cos(y * 0.037) +
                 15.0 * std::abs(std::sin(x * 0.013 + y * 0.021)) + ((x * 7 + y * 3) % 11) * 0.7;
      if (x > side / 2 + 37) v += 40.0;
      f.samples[size_t(y) * side + x] = float(v);
    }
  EXPECT_TRUE(makePyramidGeometry(side, side, 128, PixelFormat::kF32, &f.geometry));
  return f;
}

// Uploads, for this camera, the tiles every ring reads at levels >= finest
// of `geometry`, each as `tile` gives it, into a TerrainRenderer or its
// TerrainRendererImpl.
template <class Terrain>
void uploadRingTiles(Terrain& terrain, const PyramidGeometry& geometry, const Camera& camera,
                     const std::function<std::vector<float>(const TileKey&)>& tile, uint32_t finest = 0) {
  const uint32_t n = terrain.config().ring_cells;
  const int64_t t = geometry.tile_px;
  for (uint32_t l = finest; l < geometry.levelCount(); ++l) {
    const glm::i64vec2 o = ringOrigin(terrain.config(), camera, l);
    const LevelInfo& info = geometry.levels[l];
    auto clampTile = [&](int64_t s, uint64_t size) {
      return std::clamp<int64_t>(s, 0, int64_t(size) - 1) / t;
    };
    for (int64_t ty = clampTile(o.y - 1, info.height_px); ty <= clampTile(o.y + n + 1, info.height_px); ++ty)
      for (int64_t tx = clampTile(o.x - 1, info.width_px); tx <= clampTile(o.x + n + 1, info.width_px); ++tx) {
        const TileKey key{l, uint32_t(tx), uint32_t(ty)};
        terrain.uploadTile(key, tile(key).data());
      }
  }
}

template <class Terrain>
void uploadRings(Terrain& terrain, const HeightField& f, const Camera& camera, uint32_t finest = 0) {
  uploadRingTiles(terrain, f.geometry, camera, [&f](const TileKey& key) { return f.tile(key); }, finest);
}

struct TerrainScene {
  HeightField field;
  std::shared_ptr<TileSource> colour_source;
  ClipmapPlan plan;
  std::unique_ptr<ClipmapRenderer> colour;
  std::unique_ptr<TerrainRenderer> terrain;
  std::unique_ptr<OffscreenTarget> target;
};

// A 1024^2-sample field under a 2048^2-texel white image (2 texels per
// sample): lit terrain is grey (r = g = b), which the background colour is
// not, so every background pixel is told apart from ground.
TerrainScene makeScene(const Camera& camera, uint32_t ring_cells = 64,
                       TerrainMethod method = TerrainMethod::kClipmap, HeightField field = roughField(1024)) {
  TerrainScene s;
  s.field = std::move(field);
  s.colour_source = makeImageSource(std::vector<uint8_t>(size_t(2048) * 2048 * 4, 255), 2048, 2048, 128);
  s.plan = planClipmap(s.colour_source->geometry(), kViewport, camera, {});
  RendererConfig rc{s.plan.clip_tiles, s.plan.pyramid_level, Buffering::kSingle};
  EXPECT_TRUE(ClipmapRenderer::create(s.colour_source->geometry(), rc, &s.colour).ok());
  test::loadPlan(*s.colour, *s.colour_source, s.plan);
  TerrainConfig tc;
  tc.ring_cells = ring_cells;
  tc.method = method;
  // The quadtree draws wherever heights are resident: a stack that holds
  // every tile of the 8 x 8-tile field (the tests upload them all).
  if (method != TerrainMethod::kClipmap) tc.clip_tiles = 8;
  tc.mapping.world_per_sample = {2.0, 2.0};
  tc.mapping.sample0_world = {1.0, 1.0};
  tc.mapping.world_per_height = 1.0;
  const Status st = TerrainRenderer::create(s.field.geometry, tc, &s.terrain);
  EXPECT_TRUE(st.ok()) << st.toString();
  EXPECT_TRUE(OffscreenTarget::create(kViewport, &s.target).ok());
  return s;
}

std::vector<uint8_t> drawTerrain(TerrainScene& s, const Camera& camera) {
  s.target->bind();
  ClipmapRenderer::clearSky();
  s.terrain->draw(camera, kViewport, *s.colour);
  std::vector<uint8_t> rgba;
  s.target->readRgba(&rgba);
  return rgba;
}

// Cracks of a frame over the 1024^2-sample field (2048 world units).
size_t crackPixels(const std::vector<uint8_t>& rgba, const Camera& camera, float lowest,
                   std::vector<uint8_t>* marked = nullptr) {
  return test::terrainCracks(rgba, camera, kViewport, lowest, 4.0, 2044.0, nullptr, marked);
}

// Pixels that show ground at all (to make sure a test looks at terrain).
size_t groundPixels(const std::vector<uint8_t>& rgba) {
  size_t n = 0;
  for (size_t i = 0; i < rgba.size(); i += 4)
    if (!std::equal(rgba.begin() + long(i), rgba.begin() + long(i) + 3, renderer_config::kSkyRgba)) ++n;
  return n;
}

Camera overField(double x, double z, double height, double heading, double pitch) {
  Camera c;
  c.position = {x, height, z};
  c.heading_rad = heading;
  c.pitch_rad = pitch;
  return c;
}

// Runs terrain.vert over every vertex of ring `level`'s (n + 1)^2 grid for
// this camera, with the renderer's own uniforms, mesh and height stack,
// through transform feedback (nothing drawn), and returns for each vertex
// in row order the normal (xyz) and height (w) it outputs. The program is
// built here, for this test alone. A complete framebuffer must be bound
// (e.g. an OffscreenTarget).
std::vector<glm::vec4> ringVertices(const TerrainRendererImpl& terrain, const Camera& camera,
                                    const Viewport& viewport, uint32_t level) {
  const uint32_t n = terrain.config().ring_cells;
  const size_t count = size_t(n + 1) * (n + 1);
  if (level >= terrain.geometry().levelCount()) return {};
  GLuint p = 0;
  const std::string fragment = std::string(shaders::k_terrain_ground_glsl) + "\n" + shaders::k_ground_clipmap_frag;
  const Status built = gl_util::buildProgram(shaders::k_terrain_vert, fragment, &p, "#define TERRAIN 1\n",
                                             {"vNormal", "vHeight"});
  EXPECT_TRUE(built.ok()) << built.toString();
  if (!built) return {};
  terrain.setFrameUniforms(p, camera, viewport);
  terrain.setRingUniforms(p, camera, level, ringOrigin(terrain.config(), camera, level));
  GLuint buffer = 0;
  glCreateBuffers(1, &buffer);
  glNamedBufferStorage(buffer, GLsizeiptr(count * sizeof(glm::vec4)), nullptr, GL_MAP_READ_BIT);
  glUseProgram(p);
  glBindVertexArray(terrain.ringMesh().vao());
  glEnable(GL_RASTERIZER_DISCARD);
  glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, buffer);
  glBeginTransformFeedback(GL_POINTS);
  glDrawArrays(GL_POINTS, 0, GLsizei(count));  // the plain grid: the mesh's first (n + 1)^2 vertices
  glEndTransformFeedback();
  glDisable(GL_RASTERIZER_DISCARD);
  glBindVertexArray(0);
  glUseProgram(0);
  std::vector<glm::vec4> out(count);
  glGetNamedBufferSubData(buffer, 0, GLsizeiptr(count * sizeof(glm::vec4)), out.data());
  glDeleteBuffers(1, &buffer);
  glDeleteProgram(p);
  return out;
}

TEST(TerrainHeightStack, ATileTakesItsToroidalSlotFromTheTileThatHadIt) {
  CLIPSTREAM_REQUIRE_GL();
  const HeightField f = roughField(1024);  // level 0: 8 x 8 tiles of 128^2
  TerrainConfig config;
  config.ring_cells = 64;
  const uint32_t slots = TerrainHeightStack::slotsFor(f.geometry, config);
  ASSERT_LT(slots, 8u) << "the test needs two tiles of a level sharing a slot";
  std::unique_ptr<TerrainHeightStack> stack;
  ASSERT_TRUE(TerrainHeightStack::create(f.geometry, slots, f.geometry.levelCount(), &stack).ok());
  const int64_t t = f.geometry.tile_px;
  // Level 0's texels of slot (sx, sy), read back from the texture.
  auto slotTexels = [&](uint32_t sx, uint32_t sy) {
    std::vector<float> texels(size_t(t) * t);
    glGetTextureSubImage(stack->texture(), 0, GLint(sx * t), GLint(sy * t), 0, GLsizei(t), GLsizei(t), 1, GL_RED,
                         GL_FLOAT, GLsizei(texels.size() * sizeof(float)), texels.data());
    return texels;
  };
  auto bounds = [](const std::vector<float>& h) {
    const auto [lo, hi] = std::minmax_element(h.begin(), h.end());
    return glm::vec2(*lo, *hi);
  };
  EXPECT_FALSE(stack->holds(0, 1, 2));
  float h = 0.0f;
  EXPECT_FALSE(stack->sample(0, 1 * t + 5, 2 * t + 7, &h));
  const std::vector<float> a = f.tile({0, 1, 2});
  stack->upload({0, 1, 2}, a.data());
  EXPECT_TRUE(stack->holds(0, 1, 2));
  EXPECT_EQ(slotTexels(1 % slots, 2 % slots), a) << "the tile is not in slot (x mod slots, y mod slots)";
  ASSERT_TRUE(stack->sample(0, 1 * t + 5, 2 * t + 7, &h));
  EXPECT_EQ(h, f.at(0, 1 * t + 5, 2 * t + 7));
  EXPECT_EQ(stack->heightBounds(0, {1 * t, 2 * t}, {2 * t - 1, 3 * t - 1}), bounds(a));
  // The tile `slots` further along takes the same slot: the first one is
  // no longer resident anywhere, and its ground has no bound.
  const std::vector<float> b = f.tile({0, 1 + slots, 2});
  stack->upload({0, 1 + slots, 2}, b.data());
  EXPECT_FALSE(stack->holds(0, 1, 2));
  EXPECT_TRUE(stack->holds(0, 1 + slots, 2));
  EXPECT_EQ(slotTexels(1 % slots, 2 % slots), b);
  EXPECT_FALSE(stack->sample(0, 1 * t + 5, 2 * t + 7, &h));
  ASSERT_TRUE(stack->sample(0, (1 + slots) * t + 5, 2 * t + 7, &h));
  EXPECT_EQ(h, f.at(0, (1 + slots) * t + 5, 2 * t + 7));
  EXPECT_FALSE(std::isfinite(stack->heightBounds(0, {1 * t, 2 * t}, {2 * t - 1, 3 * t - 1}).x));
  // A ring is resident when every tile it reads (one sample around) is:
  // 64 cells from (266, 394) read samples 265..331 x 393..459.
  const glm::i64vec2 ring_origin(2 * t + 10, 3 * t + 10);
  EXPECT_FALSE(stack->ringResident(0, ring_origin, 64));
  stack->upload({0, 2, 3}, f.tile({0, 2, 3}).data());  // samples 256..383 x 384..511
  EXPECT_TRUE(stack->ringResident(0, ring_origin, 64));
  EXPECT_FALSE(stack->ringResident(0, ring_origin - glm::i64vec2(11, 0), 64)) << "reads one sample into tile 1";
}

TEST(Terrain, NoCrackAtRestOrWhileRingsMoveAcrossLevelBorders) {
  CLIPSTREAM_REQUIRE_GL();
  Camera camera = overField(1000.0, 1000.0, 160.0, 0.6, -0.45);
  TerrainScene s = makeScene(camera);
  ASSERT_TRUE(s.terrain && s.colour && s.target);
  const float lowest = s.field.lowest();
  size_t frames = 0, culled = 0, drawn = 0;
  // Sub-sample steps across several ring snaps of every level, looking in
  // four directions, low and high.
  for (int step = 0; step < 24; ++step) {
    camera.position.x = 1000.0 + step * 3.7;
    camera.position.z = 1000.0 - step * 2.3;
    camera.heading_rad = 0.6 + step * (6.2831853 / 24.0);
    camera.position.y = (step % 3 == 0) ? 110.0 : 160.0 + step;
    uploadRings(*s.terrain, s.field, camera);
    const std::vector<uint8_t> rgba = drawTerrain(s, camera);
    ASSERT_GT(s.terrain->lastFrame().rings, 1u);
    EXPECT_EQ(s.terrain->lastFrame().finest_level, 0u);
    EXPECT_GT(groundPixels(rgba), rgba.size() / 8) << "step " << step;
    std::vector<uint8_t> marked;
    const size_t cracks = crackPixels(rgba, camera, lowest, &marked);
    if (cracks > 0) test::dumpPpm("terrain_crack_" + std::to_string(step), marked, kViewport);
    EXPECT_EQ(cracks, 0u) << "step " << step;
    culled += s.terrain->lastFrame().culled_blocks;
    drawn += s.terrain->lastFrame().blocks;
    ++frames;
  }
  EXPECT_EQ(frames, 24u);
  // Blocks behind the camera were culled (with no crack above, none that
  // could be seen was).
  EXPECT_GT(culled, drawn / 4) << "drawn " << drawn;
}

TEST(Terrain, SeenFromOutsideItsCornerTheWholeFieldIsDrawn) {
  CLIPSTREAM_REQUIRE_GL();
  // 200 samples beyond a corner of the field, high, looking across it to
  // the opposite corner 1224 samples away: the outermost ring must reach
  // that far from the camera, not only as far as the field is wide.
  const Camera camera = overField(-400.0, 2448.0, 900.0, 0.785, -0.42);
  TerrainScene s = makeScene(camera);
  ASSERT_TRUE(s.terrain);
  uploadRings(*s.terrain, s.field, camera);
  const std::vector<uint8_t> rgba = drawTerrain(s, camera);
  EXPECT_GT(groundPixels(rgba), rgba.size() / 4 / 8);
  std::vector<uint8_t> marked;
  const size_t cracks = test::terrainCracks(rgba, camera, kViewport, s.field.lowest(), 4.0, 2044.0, nullptr,
                                            &marked, s.field.highest());
  if (cracks > 0) test::dumpPpm("terrain_far_corner", marked, kViewport);
  EXPECT_EQ(cracks, 0u) << "ground of the field left undrawn";
}

TEST(Terrain, MissingFineHeightTilesCoarsenTheGeometryWithoutHoles) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera camera = overField(900.0, 1100.0, 140.0, 2.0, -0.5);
  TerrainScene s = makeScene(camera);
  ASSERT_TRUE(s.terrain);
  // Nothing resident: nothing drawn (no garbage heights).
  std::vector<uint8_t> rgba = drawTerrain(s, camera);
  EXPECT_EQ(s.terrain->lastFrame().rings, 0u);
  EXPECT_EQ(groundPixels(rgba), 0u);
  uploadRings(*s.terrain, s.field, camera, 2);
  rgba = drawTerrain(s, camera);
  EXPECT_EQ(s.terrain->lastFrame().finest_level, 2u);
  EXPECT_EQ(crackPixels(rgba, camera, s.field.lowest()), 0u);
  uploadRings(*s.terrain, s.field, camera, 0);
  rgba = drawTerrain(s, camera);
  EXPECT_EQ(s.terrain->lastFrame().finest_level, 0u);
  EXPECT_EQ(crackPixels(rgba, camera, s.field.lowest()), 0u);
}

TEST(Terrain, VertexHeightsAndNormalsMatchTheCpu) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera camera = overField(1234.5, 987.25, 150.0, 0.3, -0.5);
  TerrainScene s = makeScene(camera);
  ASSERT_TRUE(s.terrain);
  // The same terrain as the scene's, reached through its implementation.
  std::unique_ptr<TerrainRendererImpl> terrain;
  ASSERT_TRUE(TerrainRendererImpl::create(s.field.geometry, s.terrain->config(), &terrain).ok());
  uploadRings(*terrain, s.field, camera);
  s.target->bind();  // draws need a complete framebuffer, even with nothing rasterised
  const uint32_t n = terrain->config().ring_cells;
  const uint32_t w = std::max(1u, n / renderer_config::kTerrainTransitionDivisor);
  for (uint32_t level : {0u, 1u, 2u}) {
    const std::vector<glm::vec4> v = ringVertices(*terrain, camera, kViewport, level);
    ASSERT_EQ(v.size(), size_t(n + 1) * (n + 1));
    const glm::i64vec2 o = ringOrigin(terrain->config(), camera, level);
    const double spacing = 2.0 * double(1 << level);  // world units between samples
    size_t inner = 0, edge = 0;
    for (uint32_t j = 0; j <= n; ++j)
      for (uint32_t i = 0; i <= n; ++i) {
        const glm::vec4 got = v[size_t(j) * (n + 1) + i];
        const int64_t si = o.x + i, sj = o.y + j;
        const uint32_t d = std::max(uint32_t(std::abs(int(2 * i) - int(n))), uint32_t(std::abs(int(2 * j) - int(n)))) / 2;
        if (d + w + 1 <= n / 2) {
          // Inside the transition band: the level's own sample, and the
          // normal by central differences of the level (seed 000).
          ASSERT_EQ(got.w, s.field.at(level, si, sj)) << level << ": " << i << "," << j;
          const double dx = s.field.at(level, si + 1, sj) - s.field.at(level, si - 1, sj);
          const double dz = s.field.at(level, si, sj + 1) - s.field.at(level, si, sj - 1);
          const glm::dvec3 want = glm::normalize(glm::dvec3(-dx / (2 * spacing), 1.0, -dz / (2 * spacing)));
          EXPECT_NEAR(got.x, want.x, 1e-4);
          EXPECT_NEAR(got.y, want.y, 1e-4);
          EXPECT_NEAR(got.z, want.z, 1e-4);
          ++inner;
        } else if (d == n / 2 && level + 1 < s.field.geometry.levelCount()) {
          // On the outer edge: exactly the coarser ring's surface.
          const int64_t ci0 = si >> 1, cj0 = sj >> 1, ci1 = (si + 1) >> 1, cj1 = (sj + 1) >> 1;
          const float coarse = 0.5f * (s.field.at(level + 1, ci0, cj0) + s.field.at(level + 1, ci1, cj1));
          EXPECT_FLOAT_EQ(got.w, coarse) << level << ": " << i << "," << j;
          ++edge;
        }
      }
    EXPECT_GT(inner, size_t(n) * n / 2);
    EXPECT_EQ(edge, size_t(4) * n);
  }
}

TEST(Terrain, GroundHeightFollowsTheFinestResidentLevel) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera camera = overField(1001.0, 777.0, 150.0, 0.0, -0.5);
  TerrainScene s = makeScene(camera);
  ASSERT_TRUE(s.terrain);
  double h = 0.0;
  uint32_t level = 99;
  EXPECT_FALSE(s.terrain->groundHeight({1001.0, 777.0}, &h));
  uploadRings(*s.terrain, s.field, camera, 1);
  ASSERT_TRUE(s.terrain->groundHeight({1001.0, 777.0}, &h, &level));
  EXPECT_EQ(level, 1u);
  uploadRings(*s.terrain, s.field, camera, 0);
  // World (1001, 777) is sample (500, 388) exactly: the level-0 sample.
  ASSERT_TRUE(s.terrain->groundHeight({1001.0, 777.0}, &h, &level));
  EXPECT_EQ(level, 0u);
  EXPECT_FLOAT_EQ(float(h), s.field.at(0, 500, 388));
  // Half-way along x between two samples: their mean (on the cell's edge).
  ASSERT_TRUE(s.terrain->groundHeight({1002.0, 777.0}, &h));
  EXPECT_NEAR(h, 0.5 * (s.field.at(0, 500, 388) + s.field.at(0, 501, 388)), 1e-4);
}

TEST(Terrain, GroundHeightIsAboveEverySurfaceTheNextFrameMayDraw) {
  CLIPSTREAM_REQUIRE_GL();
  // Only the rings from level 2 out are resident and drawn; then level 0's
  // tiles arrive. Until a frame draws the level-0 ring, the ground under a
  // point is the highest of the level-0 to level-2 surfaces there (the
  // drawn ring may lie above the finer one, where it bridges a hollow);
  // once it is drawn, the level-0 surface alone.
  const Camera camera = overField(1001.0, 777.0, 150.0, 0.0, -0.5);
  TerrainScene s = makeScene(camera);
  ASSERT_TRUE(s.terrain);
  uploadRings(*s.terrain, s.field, camera, 2);
  s.target->bind();
  s.terrain->draw(camera, kViewport, *s.colour);
  ASSERT_EQ(s.terrain->lastFrame().finest_level, 2u);
  // Level-0 samples (496 + k, 388): world (2 i + 1, 777).
  std::vector<double> coarse(16);
  for (int k = 0; k < 16; ++k) {
    uint32_t level = 99;
    ASSERT_TRUE(s.terrain->groundHeight({2.0 * (496 + k) + 1.0, 777.0}, &coarse[size_t(k)], &level));
    EXPECT_EQ(level, 2u);
  }
  uploadRings(*s.terrain, s.field, camera, 0);
  int above = 0;  // points where the drawn level-2 surface lies above level 0's
  for (int k = 0; k < 16; ++k) {
    double h = 0.0;
    uint32_t level = 99;
    ASSERT_TRUE(s.terrain->groundHeight({2.0 * (496 + k) + 1.0, 777.0}, &h, &level));
    EXPECT_EQ(level, 0u);
    const double fine = s.field.at(0, uint64_t(496 + k), 388);
    EXPECT_GE(h, coarse[size_t(k)]) << k;
    EXPECT_GE(h, fine) << k;
    if (coarse[size_t(k)] > fine) ++above;
  }
  EXPECT_GT(above, 0) << "no point where the coarser surface is higher: the test cannot tell";
  s.terrain->draw(camera, kViewport, *s.colour);
  ASSERT_EQ(s.terrain->lastFrame().finest_level, 0u);
  for (int k = 0; k < 16; ++k) {
    double h = 0.0;
    ASSERT_TRUE(s.terrain->groundHeight({2.0 * (496 + k) + 1.0, 777.0}, &h));
    EXPECT_FLOAT_EQ(float(h), s.field.at(0, uint64_t(496 + k), 388)) << k;
  }
}

// Uploads, for this camera, the tiles every ring reads, fetched from a
// height source.
template <class Terrain>
void uploadRingsFrom(Terrain& terrain, TileSource& heights, const Camera& camera) {
  uploadRingTiles(terrain, heights.geometry(), camera, [&heights](const TileKey& key) {
    std::vector<uint8_t> bytes;
    EXPECT_TRUE(heights.fetch(key, &bytes).ok());
    std::vector<float> out(bytes.size() / sizeof(float));
    std::memcpy(out.data(), bytes.data(), out.size() * sizeof(float));
    return out;
  });
}

// Uploads the 3 x 3 tiles around the camera's at every level (what the
// quadtree's stack slots hold), as a streamer's windows would hold them.
void uploadWindowsFrom(TerrainRenderer& terrain, TileSource& heights, const Camera& camera) {
  for (uint32_t l = 0; l < heights.geometry().levelCount(); ++l) {
    const LevelInfo& info = heights.geometry().levels[l];
    const double span = std::ldexp(double(heights.geometry().tile_px), int(l));
    const int64_t cx = int64_t(camera.position.x / span), cz = int64_t(camera.position.z / span);
    for (int64_t ty = std::max<int64_t>(cz - 1, 0); ty <= std::min<int64_t>(cz + 1, info.tiles_y - 1); ++ty)
      for (int64_t tx = std::max<int64_t>(cx - 1, 0); tx <= std::min<int64_t>(cx + 1, info.tiles_x - 1); ++tx) {
        std::vector<uint8_t> bytes;
        const TileKey key{l, uint32_t(tx), uint32_t(ty)};
        ASSERT_TRUE(heights.fetch(key, &bytes).ok());
        terrain.uploadTile(key, reinterpret_cast<const float*>(bytes.data()));
      }
  }
}

// Heights of the finest ring, as terrain.vert outputs them after a draw of
// the terrain `config` makes over `heights` (through its implementation),
// are the procedural samples exactly. A complete framebuffer must be bound.
void expectFinestRingOnTheSamples(TileSource& heights, const ProceduralSpec& spec, const TerrainConfig& config,
                                  std::shared_ptr<const TerrainBounds> bounds, const Camera& camera,
                                  const ClipmapRenderer& colour) {
  std::unique_ptr<TerrainRendererImpl> terrain;
  ASSERT_TRUE(TerrainRendererImpl::create(heights.geometry(), config, &terrain).ok());
  terrain->setBounds(std::move(bounds));
  uploadRingsFrom(*terrain, heights, camera);
  terrain->draw(camera, kViewport, colour);
  ASSERT_EQ(terrain->lastFrame().finest_level, 0u);
  const std::vector<glm::vec4> v = ringVertices(*terrain, camera, kViewport, 0);
  ASSERT_EQ(v.size(), size_t(65) * 65);
  const glm::i64vec2 o = ringOrigin(config, camera, 0);
  for (uint32_t j = 20; j <= 44; j += 6)
    for (uint32_t i = 20; i <= 44; i += 6)
      EXPECT_EQ(v[size_t(j) * 65 + i].w, float(proceduralHeight(spec, uint64_t(o.x + i), uint64_t(o.y + j))));
}

// A 2^26-sample terrain 3000 samples from its far corner, drawn by `method`.
void planetNearItsFarCorner(TerrainMethod method) {
  const uint64_t side = uint64_t(1) << 26;
  ProceduralSpec spec;
  spec.width_px = spec.height_px = side;
  auto heights = makeProceduralHeightSource(spec);
  ASSERT_TRUE(heights);
  // World = the planet's samples, one colour texel each (the procedural
  // texture): camera coordinates near 6.7e7, where float positions would
  // be off by whole texels.
  ProceduralSpec colour_spec = spec;
  auto colour = makeProceduralSource(colour_spec);
  const double x = double(side) - 3000.25, z = double(side) - 2000.75;
  Camera world;
  world.position = {x, proceduralHeight(spec, uint64_t(x), uint64_t(z)) + 150.0, z};
  world.heading_rad = 0.8;
  world.pitch_rad = -0.35;
  TerrainConfig tc;
  tc.ring_cells = 64;
  tc.method = method;
  tc.mapping.world_per_sample = {1.0, 1.0};
  tc.mapping.sample0_world = {0.5, 0.5};
  tc.mapping.world_per_height = 1.0;
  std::unique_ptr<TerrainRenderer> terrain;
  ASSERT_TRUE(TerrainRenderer::create(heights->geometry(), tc, &terrain).ok());
  std::shared_ptr<const TerrainBounds> bounds;
  ASSERT_TRUE(loadTerrainBounds(*heights, kTerrainBoundsMaxLevelTiles, &bounds).ok());
  terrain->setBounds(bounds);
  const ClipmapPlan plan = planClipmap(colour->geometry(), kViewport, world, {});
  std::unique_ptr<ClipmapRenderer> colour_renderer;
  ASSERT_TRUE(ClipmapRenderer::create(colour->geometry(), {plan.clip_tiles, plan.pyramid_level, Buffering::kSingle},
                                      &colour_renderer).ok());
  test::loadPlan(*colour_renderer, *colour, plan);
  std::unique_ptr<OffscreenTarget> target;
  ASSERT_TRUE(OffscreenTarget::create(kViewport, &target).ok());
  if (method == TerrainMethod::kClipmap)
    uploadRingsFrom(*terrain, *heights, world);
  else
    uploadWindowsFrom(*terrain, *heights, world);

  auto draw = [&](const Camera& c) {
    target->bind();
    ClipmapRenderer::clearSky();
    terrain->draw(c, kViewport, *colour_renderer);
    std::vector<uint8_t> rgba;
    target->readRgba(&rgba);
    return rgba;
  };
  const std::vector<uint8_t> a = draw(world);
  // Several levels; the clipmap's innermost ring is level 0, the quadtree
  // refines by error (150 units above this ground, level 1 is enough).
  ASSERT_GT(terrain->lastFrame().rings, 3u);
  EXPECT_LE(terrain->lastFrame().finest_level, method == TerrainMethod::kClipmap ? 0u : 1u);
  if (method == TerrainMethod::kClipmap) {
    target->bind();
    expectFinestRingOnTheSamples(*heights, spec, tc, bounds, world, *colour_renderer);
  }
  // No crack: every pixel whose ray meets the plane of the lowest ground
  // (proceduralHeight >= 345) inside the planet shows terrain.
  size_t ground = 0;
  const size_t cracks = test::terrainCracks(a, world, kViewport, 340.0, 0.0, double(side) - 1.0, &ground);
  EXPECT_GT(ground, size_t(kViewport.width_px) * kViewport.height_px / 3);
  EXPECT_EQ(cracks, 0u);
  // No jitter: a hundredth of a sample sideways moves the picture by far
  // less than a pixel, so the frames barely differ (float positions near
  // 2^26 would snap vertices by whole samples and scramble them).
  Camera nudged = world;
  nudged.position.x += 0.01;
  const std::vector<uint8_t> b = draw(nudged);
  double diff = 0.0;
  for (size_t i = 0; i < a.size(); i += 4) diff += std::abs(int(a[i]) - int(b[i]));
  diff /= double(a.size() / 4);
  std::printf("  %s: mean grey change for a 0.01-sample move: %.4f\n", terrainMethodName(method), diff);
  EXPECT_LT(diff, 0.5);
}

TEST(Terrain, PlanetSizedTerrainNearItsFarCornerHasNoCrackOrJitter) {
  CLIPSTREAM_REQUIRE_GL();
  planetNearItsFarCorner(TerrainMethod::kClipmap);
}

TEST(TerrainQuadtree, PlanetSizedTerrainNearItsFarCornerHasNoCrackOrJitter) {
  CLIPSTREAM_REQUIRE_GL();
  planetNearItsFarCorner(TerrainMethod::kQuadtree);
}

// ---- The quadtree method (TerrainMethod::kQuadtree) ----

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
