// Level 0 reproduces the input exactly and every coarser level equals the
// reference pyramid computed in tiler_test_util.cpp from the definitions.
#include "tiler_test_util.h"

#include <clipstream/tiler/tiler.h>

#include <algorithm>
#include <cmath>

namespace clipstream::test {
namespace {

struct Case {
  uint64_t w, h;
  int channels;
  OIIO::TypeDesc type;
  const char* ext;
  uint32_t tile_px;
  int file_tile_px = 0;  // > 0: write a tiled TIFF with this tile size
};

void PrintTo(const Case& k, std::ostream* os) {
  *os << k.w << "x" << k.h << " " << k.channels << "ch " << k.type.c_str() << " " << k.ext;
}

// Pixels encode their own coordinates (and channel) so any misplaced
// block, swapped channel or off-by-one row shows as a mismatch.
double coordSample(uint64_t x, uint64_t y, int c, OIIO::TypeDesc type) {
  if (type == OIIO::TypeDesc::UINT16) {
    return double((x * 257 + y * 4099 + uint64_t(c) * 12345) & 0xffff);
  }
  switch (c) {
    case 0: return double(x & 255);
    case 1: return double(y & 255);
    case 2: return double(((x >> 8) * 16 + (y >> 8) * 3 + x * y) & 255);
    default: return double((x * 7 + y * 3) & 255);
  }
}

// The store's expected level 0 for an input written with coordSample.
RefImage expectedLevel0(const Case& k) {
  RefImage r;
  r.width = k.w, r.height = k.h;
  const bool is16 = k.type == OIIO::TypeDesc::UINT16;
  r.channels = k.channels == 2 ? 4 : uint32_t(k.channels);
  for (uint64_t y = 0; y < k.h; ++y) {
    for (uint64_t x = 0; x < k.w; ++x) {
      auto conv = [&](int c) {
        const uint32_t v = uint32_t(coordSample(x, y, c, k.type));
        // 16-bit colour becomes 8-bit, rounded; 16-bit grey stays R16.
        if (is16 && k.channels != 1) return (v * 255 + 32767) / 65535;
        return v;
      };
      if (k.channels == 2) {
        const uint32_t g = conv(0);
        r.samples.insert(r.samples.end(), {g, g, g, conv(1)});
      } else {
        for (int c = 0; c < k.channels; ++c) r.samples.push_back(conv(c));
      }
    }
  }
  return r;
}

class RoundTrip : public ::testing::TestWithParam<Case> {};

TEST_P(RoundTrip, EveryLevelMatchesReferenceBoxPyramid) {
  const Case k = GetParam();
  TempDir dir;
  const std::string input = dir.file(std::string("in.") + k.ext);
  ASSERT_TRUE(writeImage(input, k.w, k.h, k.channels, k.type,
                         [&](uint64_t x, uint64_t y, int c) { return coordSample(x, y, c, k.type); },
                         k.file_tile_px))
      << OIIO::geterror();
  TilerOptions opt;
  opt.input_path = input;
  opt.output_path = dir.file("out.cst");
  opt.tile_px = k.tile_px;
  opt.threads = 2;
  opt.fsync = false;
  TilerSummary summary;
  const Status s = tileImage(opt, &summary);
  ASSERT_TRUE(s.ok()) << s.toString();

  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(opt.output_path, &reader).ok());
  RefImage level = expectedLevel0(k);
  const uint32_t levels = reader->geometry().levelCount();
  ASSERT_EQ(levels, summary.levels);
  EXPECT_LE(reader->geometry().levels.back().width_px, k.tile_px);
  EXPECT_LE(reader->geometry().levels.back().height_px, k.tile_px);
  for (uint32_t l = 0; l < levels; ++l) {
    EXPECT_EQ(maxTileError(*reader, l, level), 0u) << "level " << l;
    level = referenceBoxDownsample(level);
  }
  EXPECT_EQ(dir.entries(), (std::vector<std::string>{std::string("in.") + k.ext, "out.cst"}));
}

INSTANTIATE_TEST_SUITE_P(
    OddSizesAndFormats, RoundTrip,
    ::testing::Values(Case{1000, 777, 3, OIIO::TypeDesc::UINT8, "tif", 128},
                      Case{1000, 777, 1, OIIO::TypeDesc::UINT16, "tif", 64},
                      Case{1000, 777, 4, OIIO::TypeDesc::UINT8, "png", 128},
                      Case{129, 1, 3, OIIO::TypeDesc::UINT8, "tif", 16},
                      Case{129, 1, 1, OIIO::TypeDesc::UINT8, "png", 16},
                      Case{1, 1, 4, OIIO::TypeDesc::UINT8, "tif", 16},
                      Case{1, 1, 1, OIIO::TypeDesc::UINT16, "png", 128},
                      Case{257, 130, 3, OIIO::TypeDesc::UINT16, "tif", 32},
                      Case{257, 130, 2, OIIO::TypeDesc::UINT8, "png", 32},
                      Case{257, 130, 1, OIIO::TypeDesc::UINT8, "tif", 16},
                      Case{257, 130, 4, OIIO::TypeDesc::UINT8, "tif", 64},
                      Case{1000, 777, 3, OIIO::TypeDesc::UINT8, "tif", 128, 64},
                      Case{257, 130, 1, OIIO::TypeDesc::UINT16, "tif", 32, 48}),
    [](const ::testing::TestParamInfo<Case>& param_info) {
      const Case& k = param_info.param;
      return std::to_string(k.w) + "x" + std::to_string(k.h) + "_" + std::to_string(k.channels) +
             "ch_" + (k.type == OIIO::TypeDesc::UINT16 ? "16bit_" : "8bit_") + k.ext +
             (k.file_tile_px > 0 ? "_tiled" + std::to_string(k.file_tile_px) : std::string()) +
             "_T" + std::to_string(k.tile_px);
    });

TEST(Tiler, FloatInputIsClampedToUnitRangeAndScaled) {
  TempDir dir;
  const std::string input = dir.file("f.tif");
  auto value = [](uint64_t x, uint64_t y, int c) { return (double(x + y * 3 + c) / 40.0) - 0.25; };
  ASSERT_TRUE(writeImage(input, 33, 17, 3, OIIO::TypeDesc::FLOAT, value));
  TilerOptions opt;
  opt.input_path = input;
  opt.output_path = dir.file("out.cst");
  opt.tile_px = 64;
  opt.fsync = false;
  TilerSummary summary;
  ASSERT_TRUE(tileImage(opt, &summary).ok());
  EXPECT_GT(summary.clamped_samples, 0u);
  RefImage ref;
  ref.width = 33, ref.height = 17, ref.channels = 3;
  for (uint64_t y = 0; y < 17; ++y) {
    for (uint64_t x = 0; x < 33; ++x) {
      for (int c = 0; c < 3; ++c) {
        const double v = std::clamp(float(value(x, y, c)), 0.0f, 1.0f);
        ref.samples.push_back(uint32_t(std::lround(v * 255.0)));
      }
    }
  }
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(opt.output_path, &reader).ok());
  EXPECT_LE(maxTileError(*reader, 0, ref), 1u);  // float rounding at .5 boundaries
}

TEST(Tiler, LanczosLevelOneMatchesReferenceWithinOneCode) {
  for (bool linear : {false, true}) {
    TempDir dir;
    const std::string input = dir.file("in.tif");
    // Smooth content plus hard edges, so ringing and gamma both matter.
    auto value = [](uint64_t x, uint64_t y, int c) {
      const double smooth = 128.0 + 100.0 * std::sin(double(x) * 0.21 + c) * std::cos(double(y) * 0.13);
      return ((x / 9 + y / 7) % 3 == 0) ? 250.0 : std::floor(smooth);
    };
    ASSERT_TRUE(writeImage(input, 257, 130, 3, OIIO::TypeDesc::UINT8, value));
    TilerOptions opt;
    opt.input_path = input;
    opt.output_path = dir.file("out.cst");
    opt.tile_px = 32;
    opt.filter = DownsampleFilter::kLanczos3;
    opt.linear_light = linear;
    opt.fsync = false;
    TilerSummary summary;
    const Status s = tileImage(opt, &summary);
    ASSERT_TRUE(s.ok()) << s.toString();
    std::unique_ptr<TileStoreReader> reader;
    ASSERT_TRUE(TileStoreReader::open(opt.output_path, &reader).ok());
    EXPECT_EQ(reader->info().encoding.filter, DownsampleFilter::kLanczos3);
    RefImage l0;
    l0.width = 257, l0.height = 130, l0.channels = 3;
    for (uint64_t y = 0; y < 130; ++y)
      for (uint64_t x = 0; x < 257; ++x)
        for (int c = 0; c < 3; ++c) l0.samples.push_back(uint32_t(value(x, y, c)));
    EXPECT_EQ(maxTileError(*reader, 0, l0), 0u);
    const RefImage l1 = referenceLanczosDownsample(l0, linear);
    EXPECT_LE(maxTileError(*reader, 1, l1), 1u) << (linear ? "linear light" : "sRGB");
    // The box reference differs: the test would notice a box fallback.
    EXPECT_GT(maxTileError(*reader, 1, referenceBoxDownsample(l0)), 8u);
  }
}

}  // namespace
}  // namespace clipstream::test
