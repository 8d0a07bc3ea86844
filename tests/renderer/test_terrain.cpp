// The terrain (terrain.h) on the GPU: no crack (no background pixel where
// the ground must be) at rest and while the rings move across level
// borders, vertex heights and normals against the CPU, missing fine tiles
// coarsening the geometry rather than opening holes, the height stack's
// toroidal slots, and both methods near a planet-sized field's far corner.
// The quadtree's own tests are test_terrain_quadtree.cpp's, the meshes on
// the CPU test_terrain_mesh.cpp's. Headless llvmpipe; GL tests skip without EGL.
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
  const std::string vertex = std::string(shaders::k_terrain_heights_glsl) + "\n" + shaders::k_terrain_vert;
  const Status built = gl_util::buildProgram(vertex, fragment, &p, "#define TERRAIN 1\n",
                                             {"vNormal", "vHeight"});
  EXPECT_TRUE(built.ok()) << built.toString();
  if (!built) return {};
  terrain.setFrameUniforms(p, camera, viewport);
  TerrainMeshBuffers::setOrigin(terrain.gridOrigin(camera, level, ringOrigin(terrain.config(), camera, level)));
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
  ASSERT_TRUE(TerrainHeightStack::create(f.geometry, slots, f.geometry.levelCount(), false, &stack).ok());
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

}  // namespace
}  // namespace clipstream
