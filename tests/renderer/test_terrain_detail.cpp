// The detail beyond the data, drawn: the detail textures
// (TerrainConfig::detail_textures: the generated texture tiles and leaves the
// colour as it is on average; absent where a texel spans at most a pixel,
// present where the colour is magnified, faded in without a seam at either
// end of renderer_config::kDetailFadeLevels); every feature off draws a
// plain renderer's frames; synthesized relief draws the same frames twice.
#include <clipstream/renderer/config.h>
#include <clipstream/streamer/tile_source.h>

#include "../../renderer/src/terrain_detail.h"
#include "terrain_fixtures.h"
#include "test_helpers.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <vector>

using namespace clipstream;
using namespace terrain_test;

namespace {

HeightField flatField(uint32_t side, float height) {
  HeightField f;
  f.w = f.h = side;
  f.samples.assign(size_t(side) * side, height);
  EXPECT_TRUE(makePyramidGeometry(side, side, 128, PixelFormat::kF32, &f.geometry));
  return f;
}

}  // namespace

TEST(TerrainDetail, TheTextureTilesAndAveragesToNoChange) {
  const std::vector<uint8_t> a = detailTextureTexels(), b = detailTextureTexels();
  const uint32_t n = renderer_config::kDetailTexturePx;
  ASSERT_EQ(a.size(), size_t(n) * n * 4);
  EXPECT_EQ(a, b) << "the same bytes every time";
  for (uint32_t c = 0; c < 4; ++c) {
    double sum = 0.0;
    int steepest = 0, seam = 0, lo = 255, hi = 0;
    for (uint32_t y = 0; y < n; ++y)
      for (uint32_t x = 0; x < n; ++x) {
        const int v = a[(size_t(y) * n + x) * 4 + c];
        sum += v;
        lo = std::min(lo, v);
        hi = std::max(hi, v);
        const int right = a[(size_t(y) * n + (x + 1) % n) * 4 + c];
        const int below = a[(size_t((y + 1) % n) * n + x) * 4 + c];
        const int step = std::max(std::abs(v - right), std::abs(v - below));
        if (x + 1 < n && y + 1 < n) steepest = std::max(steepest, step);
        else seam = std::max(seam, step);
      }
    EXPECT_NEAR(sum / (double(n) * n), 127.5, 0.5) << "channel " << c;
    EXPECT_GT(hi - lo, 10) << "channel " << c << " has detail";
    // Across the wrap the texture steps no more than inside it.
    EXPECT_LE(seam, steepest) << "channel " << c;
  }
}

TEST(TerrainDetail, OnlyWhereTheColourIsMagnifiedAndFadedInWithoutASeam) {
  CLIPSTREAM_REQUIRE_GL();
  // Flat ground (one normal everywhere, so one light) under mid-grey, seen
  // low and at a grazing angle: from texels of many pixels at the bottom of
  // the frame to many texels a pixel towards the horizon.
  const Camera camera = overField(1024.0, 1024.0, 13.0, 0.3, -0.25);
  TerrainScene s = makeScene(camera, 64, TerrainMethod::kClipmap, flatField(1024, 10.0f), 128);
  uploadRings(*s.terrain, s.field, camera);
  const std::vector<uint8_t> off = drawTerrain(s, camera);
  ASSERT_TRUE(s.terrain->setDetailTextures(true).ok());
  const std::vector<uint8_t> on = drawTerrain(s, camera);
  EXPECT_EQ(drawTerrain(s, camera), on) << "the same frame twice";
  std::vector<float> xyzw;
  ASSERT_TRUE(s.terrain->readPositions(camera, kViewport, *s.colour, &xyzw).ok());

  // Each pixel's magnification from its ground positions (world units are
  // level-0 colour texels; the GPU's derivatives span the same pixel pairs
  // within its 2x2 quads): -log2 of the texels across it.
  const uint32_t w = kViewport.width_px, h = kViewport.height_px;
  const float fade = renderer_config::kDetailFadeLevels;
  constexpr int kBins = 16;  // magnification from -1 to 3 in quarter steps
  std::vector<double> diff(kBins, 0.0);
  std::vector<int> count(kBins, 0);
  size_t minified = 0, minified_changed = 0;
  for (uint32_t y = 0; y + 1 < h; ++y)
    for (uint32_t x = 0; x + 1 < w; ++x) {
      const size_t p = size_t(y) * w + x, r = p + 1, u = p + w;  // both top row first
      if (xyzw[p * 4 + 3] < 1.0f || xyzw[r * 4 + 3] < 1.0f || xyzw[u * 4 + 3] < 1.0f) continue;
      const double across = std::max(std::hypot(xyzw[p * 4] - xyzw[r * 4], xyzw[p * 4 + 2] - xyzw[r * 4 + 2]),
                                     std::hypot(xyzw[p * 4] - xyzw[u * 4], xyzw[p * 4 + 2] - xyzw[u * 4 + 2]));
      const double magnification = -std::log2(across);
      const size_t q = p * 4;
      const double d = std::abs(int(on[q]) - int(off[q]));
      if (magnification < -0.25) {
        ++minified;
        minified_changed += d != 0;
      }
      const int bin = int(std::floor((magnification + 1.0) * 4.0));
      if (bin >= 0 && bin < kBins) {
        diff[size_t(bin)] += d;
        ++count[size_t(bin)];
      }
    }
  for (int b = 0; b < kBins; ++b)
    if (count[size_t(b)] > 0) diff[size_t(b)] /= count[size_t(b)];
  auto at = [&](double m) { return diff[size_t(int(std::floor((m + 1.0) * 4.0)))]; };
  auto counted = [&](double m) { return count[size_t(int(std::floor((m + 1.0) * 4.0)))]; };
  ASSERT_GT(minified, 1000u) << "the view reaches minified ground";
  ASSERT_GT(counted(fade + 0.6), 100) << "and ground magnified past the fade";
  // Where a texel spans at most a pixel, no detail at all.
  EXPECT_EQ(minified_changed, 0u);
  // Past the fade, detail shows.
  EXPECT_GT(at(fade + 0.6), 1.5);
  // No seam where the fade begins: its first quarter level changes little.
  EXPECT_LT(at(0.1), 0.25 * at(fade + 0.6));
  // Nor where it ends: the quarter levels on either side of its end agree.
  EXPECT_NEAR(at(fade - 0.1), at(fade + 0.1), 0.35 * at(fade + 0.1));
  for (int b = 0; b < kBins; ++b)
    if (count[size_t(b)] > 0)
      std::printf("  magnification %+.2f: %5d px, mean change %.2f grey levels\n", b / 4.0 - 1.0, count[size_t(b)],
                  diff[size_t(b)]);
}

namespace {

// Every tile of `source` into `terrain` (a stack that holds them all).
void uploadAllTiles(TerrainRenderer& terrain, TileSource& source) {
  const PyramidGeometry& g = source.geometry();
  std::vector<uint8_t> bytes;
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        ASSERT_TRUE(source.fetch({l, x, y}, &bytes).ok());
        terrain.uploadTile({l, x, y}, reinterpret_cast<const float*>(bytes.data()));
      }
}

}  // namespace

// Each feature off draws what a renderer that never had it draws: lit per
// pixel with the detail textures, then both switched off, the frame is the
// plain renderer's to the bit (and differs while they are on).
TEST(TerrainDetail, EveryFeatureOffDrawsTheFramesOfARendererWithoutIt) {
  CLIPSTREAM_REQUIRE_GL();
  const Camera camera = overField(700.0, 900.0, 90.0, 0.8, -0.35);
  TerrainScene plain = makeScene(camera, 64, TerrainMethod::kClipmap, roughField(1024), 128);
  uploadRings(*plain.terrain, plain.field, camera);
  TerrainScene featured = makeScene(camera, 64, TerrainMethod::kClipmap, roughField(1024), 128);
  ASSERT_TRUE(featured.terrain->setLighting(TerrainLighting::kPixel).ok());
  ASSERT_TRUE(featured.terrain->setDetailTextures(true).ok());
  uploadRings(*featured.terrain, featured.field, camera);
  const std::vector<uint8_t> expected = drawTerrain(plain, camera);
  ASSERT_GT(groundPixels(expected), size_t(kViewport.width_px) * kViewport.height_px / 2);
  EXPECT_NE(drawTerrain(featured, camera), expected);
  ASSERT_TRUE(featured.terrain->setLighting(TerrainLighting::kVertex).ok());
  EXPECT_NE(drawTerrain(featured, camera), expected) << "the detail textures still on";
  ASSERT_TRUE(featured.terrain->setDetailTextures(false).ok());
  EXPECT_EQ(drawTerrain(featured, camera), expected);
}

// Synthesized relief is the same frames twice: two renderers over two
// synthesized sources of one DEM draw the same pixels, and they differ from
// the DEM's own.
TEST(TerrainDetail, SynthesizedReliefDrawsTheSameFramesTwice) {
  CLIPSTREAM_REQUIRE_GL();
  // Low and steep, so that the synthesis's own rings (within 32 and 64
  // world units) fill the frame.
  const Camera camera = overField(300.0, 300.0, 100.0, 2.4, -1.1);
  const HeightField field = roughField(256);
  std::vector<uint8_t> frames[3];
  for (int i = 0; i < 3; ++i) {
    TerrainScene s = makeScene(camera, 64, TerrainMethod::kClipmap, field, 128);
    std::shared_ptr<TileSource> heights = std::make_shared<FieldSource>(s.field);
    TerrainConfig tc = s.terrain->config();
    if (i > 0) {
      Status st;
      heights = makeSynthesizedHeightSource(heights, 2, &st);
      ASSERT_TRUE(heights) << st.toString();
      tc.mapping.world_per_sample /= 4.0;
    }
    const PyramidGeometry& g = heights->geometry();
    tc.clip_tiles = std::max(g.levels[0].tiles_x, g.levels[0].tiles_y);
    ASSERT_TRUE(TerrainRenderer::create(g, tc, &s.terrain).ok());
    ASSERT_NO_FATAL_FAILURE(uploadAllTiles(*s.terrain, *heights));
    frames[i] = drawTerrain(s, camera);
    if (i > 0) {
      EXPECT_EQ(s.terrain->lastFrame().finest_level, 0u) << "drawn down to the synthesis's level 0";
    }
  }
  ASSERT_GT(groundPixels(frames[1]), size_t(kViewport.width_px) * kViewport.height_px / 4);
  EXPECT_EQ(frames[1], frames[2]);
  EXPECT_NE(frames[0], frames[1]);
}
