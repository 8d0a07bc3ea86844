// Synthesized relief (makeSynthesizedHeightSource()): the DEM's samples kept
// exactly, every coarser level the decimation of the finer, the same bytes
// every time, no seam between tiles, detail only where the DEM is rough,
// bounds that hold every sample, and clear refusals.
#include <clipstream/streamer/tile_source.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

using namespace clipstream;

namespace {

// A DEM in memory: heights of f(x, y) at its level-0 samples, decimated.
class FunctionDem final : public TileSource {
 public:
  FunctionDem(uint64_t w, uint64_t h, double (*f)(int64_t, int64_t)) : m_f(f) {
    EXPECT_TRUE(makePyramidGeometry(w, h, 128, PixelFormat::kF32, &m_geometry));
  }
  const PyramidGeometry& geometry() const override { return m_geometry; }
  TileContent content() const override { return TileContent::kHeightF32; }
  std::string describe() const override { return "function DEM"; }
  Status tileHeightBounds(const TileKey& key, TileHeightBounds* out) const override {
    std::vector<uint8_t> bytes;
    const Status s = const_cast<FunctionDem*>(this)->fetch(key, &bytes);  // small: every sample
    if (!s) return s;
    const float* v = reinterpret_cast<const float*>(bytes.data());
    const auto [lo, hi] = std::minmax_element(v, v + 128 * 128);
    *out = {*lo, *hi, 0.0f};
    return okStatus();
  }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    if (!m_geometry.contains(key)) return Status::error(ErrorCode::kOutOfRange, "outside");
    const LevelInfo& info = m_geometry.levels[key.level];
    rgba->resize(128 * 128 * 4);
    float* out = reinterpret_cast<float*>(rgba->data());
    for (int64_t y = 0; y < 128; ++y)
      for (int64_t x = 0; x < 128; ++x) {
        const int64_t i = std::min<int64_t>(int64_t(key.x) * 128 + x, int64_t(info.width_px) - 1);
        const int64_t j = std::min<int64_t>(int64_t(key.y) * 128 + y, int64_t(info.height_px) - 1);
        out[y * 128 + x] = float(m_f(i << key.level, j << key.level));
      }
    return okStatus();
  }

 private:
  double (*m_f)(int64_t, int64_t);
  PyramidGeometry m_geometry;
};

double roughGround(int64_t x, int64_t y) {
  const uint32_t h = uint32_t(x * 73856093) ^ uint32_t(y * 19349663);
  return 100.0 + 30.0 * std::sin(x * 0.07) * std::cos(y * 0.05) + double(h % 1000) * 0.01;
}
double tiltedPlane(int64_t x, int64_t y) { return 50.0 + 0.5 * double(x) - 0.25 * double(y); }

std::vector<float> tileOf(TileSource& s, const TileKey& k) {
  std::vector<uint8_t> bytes;
  const Status st = s.fetch(k, &bytes);
  EXPECT_TRUE(st.ok()) << st.toString();
  std::vector<float> v(bytes.size() / 4);
  std::memcpy(v.data(), bytes.data(), bytes.size());
  return v;
}

// Level `level`'s sample (i, j) of `s`, clamped to the level.
float sampleOf(TileSource& s, uint32_t level, int64_t i, int64_t j) {
  const LevelInfo& info = s.geometry().levels[level];
  i = std::clamp<int64_t>(i, 0, int64_t(info.width_px) - 1);
  j = std::clamp<int64_t>(j, 0, int64_t(info.height_px) - 1);
  const std::vector<float> t = tileOf(s, {level, uint32_t(i / 128), uint32_t(j / 128)});
  return t[size_t((j % 128) * 128 + i % 128)];
}

}  // namespace

TEST(SynthesizedHeights, KeepsTheDemAndEachLevelDecimatesTheFiner) {
  auto dem = std::make_shared<FunctionDem>(300, 200, roughGround);
  Status s;
  auto synth = makeSynthesizedHeightSource(dem, 2, &s);
  ASSERT_TRUE(synth) << s.toString();
  const PyramidGeometry& g = synth->geometry();
  EXPECT_EQ(g.levels[0].width_px, 299u * 4 + 1);
  EXPECT_EQ(g.levelCount(), dem->geometry().levelCount() + 2);
  // Level 2 and up are the DEM's own tiles.
  for (uint32_t l = 0; l < dem->geometry().levelCount(); ++l)
    EXPECT_EQ(tileOf(*synth, {l + 2, 0, 0}), tileOf(*dem, {l, 0, 0})) << "level " << l;
  // Level 1's sample k is level 0's 2k; the DEM's samples are kept exactly.
  for (int64_t j : {0, 7, 130, 397})
    for (int64_t i : {0, 5, 129, 255, 597}) {
      EXPECT_EQ(sampleOf(*synth, 1, i, j), sampleOf(*synth, 0, 2 * i, 2 * j)) << i << "," << j;
      if (i % 2 == 0 && j % 2 == 0)
        EXPECT_EQ(sampleOf(*synth, 0, 2 * i, 2 * j), float(roughGround(i / 2, j / 2))) << i << "," << j;
    }
}

TEST(SynthesizedHeights, DeterministicAndWithoutASeamBetweenTiles) {
  Status s;
  auto a = makeSynthesizedHeightSource(std::make_shared<FunctionDem>(300, 200, roughGround), 3, &s);
  auto b = makeSynthesizedHeightSource(std::make_shared<FunctionDem>(300, 200, roughGround), 3, &s);
  ASSERT_TRUE(a && b);
  const std::vector<float> t00 = tileOf(*a, {0, 0, 0}), t10 = tileOf(*a, {0, 1, 0}), t01 = tileOf(*a, {0, 0, 1});
  EXPECT_EQ(t00, tileOf(*a, {0, 0, 0}));
  EXPECT_EQ(t00, tileOf(*b, {0, 0, 0}));
  // Across a tile's border the ground steps no more than within the tiles.
  float inside = 0.0f, across = 0.0f;
  for (int y = 0; y < 128; ++y) {
    for (int x = 0; x + 1 < 128; ++x) inside = std::max(inside, std::abs(t00[y * 128 + x + 1] - t00[y * 128 + x]));
    across = std::max(across, std::abs(t10[y * 128] - t00[y * 128 + 127]));
  }
  for (int x = 0; x < 128; ++x) across = std::max(across, std::abs(t01[x] - t00[127 * 128 + x]));
  EXPECT_GT(inside, 0.0f);
  EXPECT_LE(across, inside);
}

TEST(SynthesizedHeights, DetailOnlyWhereTheDemIsRoughAndWithinItsBounds) {
  Status s;
  // A tilted plane has no roughness: the synthesis is the plane.
  auto plane = makeSynthesizedHeightSource(std::make_shared<FunctionDem>(300, 200, tiltedPlane), 2, &s);
  ASSERT_TRUE(plane);
  for (int64_t j : {1, 6, 131})
    for (int64_t i : {1, 3, 257, 1001})
      EXPECT_NEAR(sampleOf(*plane, 0, i, j), tiltedPlane(0, 0) + 0.5 * i / 4.0 - 0.25 * j / 4.0, 1e-3) << i << "," << j;
  // Rough ground: between the DEM's samples the synthesis strays from the
  // bilinear surface; every sample lies within the tile's bounds.
  auto rough = makeSynthesizedHeightSource(std::make_shared<FunctionDem>(300, 200, roughGround), 2, &s);
  ASSERT_TRUE(rough);
  double strayed = 0.0;
  for (uint32_t ty = 0; ty < 2; ++ty)
    for (uint32_t tx = 0; tx < 3; ++tx) {
      const TileKey k{0, tx, ty};
      const std::vector<float> t = tileOf(*rough, k);
      TileHeightBounds b;
      ASSERT_TRUE(rough->tileHeightBounds(k, &b).ok());
      for (float v : t) {
        EXPECT_GE(v, b.min_height);
        EXPECT_LE(v, b.max_height);
      }
      for (int y = 0; y < 128; y += 4)
        for (int x = 0; x + 4 < 128; x += 4) {
          const float mid = t[size_t(y * 128 + x + 2)];
          strayed = std::max(strayed, double(std::abs(mid - 0.5f * (t[size_t(y * 128 + x)] + t[size_t(y * 128 + x + 4)]))));
        }
    }
  EXPECT_GT(strayed, 0.5);
}

TEST(SynthesizedHeights, RefusesWhatItCannotSynthesize) {
  Status s;
  auto dem = std::make_shared<FunctionDem>(300, 200, roughGround);
  EXPECT_FALSE(makeSynthesizedHeightSource(dem, 0, &s));
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_FALSE(makeSynthesizedHeightSource(dem, kMaxSynthesizedLevels + 1, &s));
  EXPECT_NE(s.message.find("levels"), std::string::npos);
  EXPECT_FALSE(makeSynthesizedHeightSource(makeProceduralSource(ProceduralSpec{1024, 1024, 128, 1}), 2, &s)) << "a colour source";
  EXPECT_NE(s.message.find("not a height source"), std::string::npos);
  std::vector<uint8_t> bytes;
  auto synth = makeSynthesizedHeightSource(dem, 2, &s);
  EXPECT_EQ(synth->fetch({0, 100, 0}, &bytes).code, ErrorCode::kOutOfRange);
}
