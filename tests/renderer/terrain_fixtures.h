// Shared by the terrain GPU tests (test_terrain.cpp: the clipmap rings and
// the height stack; test_terrain_quadtree.cpp: the quadtree): a rough
// height field cut into tiles as the tiler cuts them, uploads of the tiles
// a camera needs, and a scene of a white colour clipmap under the terrain,
// drawn offscreen, with its cracks and ground pixels counted.
#pragma once

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
namespace terrain_test {


inline const Viewport kViewport{320, 200};

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
inline HeightField roughField(uint32_t side) {
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

// A HeightField as a height source (its tiles as the tiler cuts them).
class FieldSource final : public TileSource {
 public:
  explicit FieldSource(const HeightField& f) : m_field(f) {}
  const PyramidGeometry& geometry() const override { return m_field.geometry; }
  TileContent content() const override { return TileContent::kHeightF32; }
  std::string describe() const override { return "height field"; }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    if (!m_field.geometry.contains(key)) return Status::error(ErrorCode::kOutOfRange, "outside");
    const std::vector<float> t = m_field.tile(key);
    rgba->resize(t.size() * 4);
    std::memcpy(rgba->data(), t.data(), rgba->size());
    return okStatus();
  }

 private:
  const HeightField& m_field;
};

struct TerrainScene {
  HeightField field;
  std::shared_ptr<TileSource> colour_source;
  ClipmapPlan plan;
  std::unique_ptr<ClipmapRenderer> colour;
  std::unique_ptr<TerrainRenderer> terrain;
  std::unique_ptr<OffscreenTarget> target;
};

// A 1024^2-sample field under a 2048^2-texel white image (2 texels per
// sample; `grey` instead of white): lit terrain is grey (r = g = b), which
// the background colour is not, so every background pixel is told apart
// from ground.
inline TerrainScene makeScene(const Camera& camera, uint32_t ring_cells = 64,
                       TerrainMethod method = TerrainMethod::kClipmap, HeightField field = roughField(1024),
                       uint8_t grey = 255) {
  TerrainScene s;
  s.field = std::move(field);
  std::vector<uint8_t> image(size_t(2048) * 2048 * 4, grey);
  for (size_t i = 3; i < image.size(); i += 4) image[i] = 255;
  s.colour_source = makeImageSource(std::move(image), 2048, 2048, 128);
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

inline std::vector<uint8_t> drawTerrain(TerrainScene& s, const Camera& camera) {
  s.target->bind();
  ClipmapRenderer::clearSky();
  s.terrain->draw(camera, kViewport, *s.colour);
  std::vector<uint8_t> rgba;
  s.target->readRgba(&rgba);
  return rgba;
}

// Cracks of a frame over the 1024^2-sample field (2048 world units).
inline size_t crackPixels(const std::vector<uint8_t>& rgba, const Camera& camera, float lowest,
                   std::vector<uint8_t>* marked = nullptr) {
  return test::terrainCracks(rgba, camera, kViewport, lowest, 4.0, 2044.0, nullptr, marked);
}

// Pixels that show ground at all (to make sure a test looks at terrain).
inline size_t groundPixels(const std::vector<uint8_t>& rgba) {
  size_t n = 0;
  for (size_t i = 0; i < rgba.size(); i += 4)
    if (!std::equal(rgba.begin() + long(i), rgba.begin() + long(i) + 3, renderer_config::kSkyRgba)) ++n;
  return n;
}

inline Camera overField(double x, double z, double height, double heading, double pitch) {
  Camera c;
  c.position = {x, height, z};
  c.heading_rad = heading;
  c.pitch_rad = pitch;
  return c;
}

}  // namespace terrain_test
}  // namespace clipstream
