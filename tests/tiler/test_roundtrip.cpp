// Level 0 reproduces the input exactly and every coarser level equals the
// reference pyramid computed in tiler_test_util.cpp from the definitions.
#include "tiler_test_util.h"

#include <clipstream/tiler/downsample.h>
#include <clipstream/tiler/georef.h>
#include <clipstream/tiler/image_source.h>
#include <clipstream/tiler/tiler.h>

#include <cstring>
#include <fstream>

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
  tiler::TilerOptions opt;
  opt.input_path = input;
  opt.output_path = dir.file("out.cst");
  opt.tile_px = k.tile_px;
  opt.threads = 2;
  opt.fsync = false;
  tiler::TilerSummary summary;
  const Status s = tiler::tileImage(opt, &summary);
  ASSERT_TRUE(s.isOk()) << s.toString();

  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(opt.output_path, &reader).isOk());
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
  tiler::TilerOptions opt;
  opt.input_path = input;
  opt.output_path = dir.file("out.cst");
  opt.tile_px = 64;
  opt.fsync = false;
  tiler::TilerSummary summary;
  ASSERT_TRUE(tiler::tileImage(opt, &summary).isOk());
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
  ASSERT_TRUE(TileStoreReader::open(opt.output_path, &reader).isOk());
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
    tiler::TilerOptions opt;
    opt.input_path = input;
    opt.output_path = dir.file("out.cst");
    opt.tile_px = 32;
    opt.filter = DownsampleFilter::kLanczos3;
    opt.linear_light = linear;
    opt.fsync = false;
    tiler::TilerSummary summary;
    const Status s = tiler::tileImage(opt, &summary);
    ASSERT_TRUE(s.isOk()) << s.toString();
    std::unique_ptr<TileStoreReader> reader;
    ASSERT_TRUE(TileStoreReader::open(opt.output_path, &reader).isOk());
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

TEST(Downsampler, BoxOddEdgeAveragesAvailablePixels) {
  tiler::Downsampler box(DownsampleFilter::kBox, false, PixelFormat::kR8);
  const uint8_t a[3] = {10, 20, 31};
  const uint8_t b[3] = {11, 21, 40};
  const uint8_t* rows[2] = {a, b};
  uint8_t out[2] = {};
  std::vector<float> scratch;
  box.downsampleRow(rows, 3, out, &scratch);
  EXPECT_EQ(out[0], (10 + 20 + 11 + 21 + 2) / 4);
  EXPECT_EQ(out[1], (31 + 40 + 1) / 2);
}

TEST(Downsampler, LanczosWeightsAreNormalisedAndSymmetric) {
  tiler::Downsampler l(DownsampleFilter::kLanczos3, false, PixelFormat::kRGB8);
  ASSERT_EQ(l.tapCount(), 12);
  EXPECT_EQ(l.firstTap(), -5);
  double sum = 0;
  for (float w : l.weights()) sum += w;
  EXPECT_NEAR(sum, 1.0, 1e-6);
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(l.weights()[size_t(k)], l.weights()[size_t(11 - k)], 1e-7);
}

TEST(GeoReference, WorldFileCentreIsMovedToPixelCorner) {
  TempDir dir;
  ASSERT_TRUE(writeImage(dir.file("g.png"), 20, 10, 3, OIIO::TypeDesc::UINT8,
                         [](uint64_t x, uint64_t, int) { return double(x); }));
  {
    std::ofstream w(dir.file("g.pgw"));
    w << "2.0\n0.0\n0.0\n-3.0\n1000.0\n5000.0\n";
  }
  {
    std::ofstream prj(dir.file("g.prj"));
    prj << "PROJCS[\"test\"]\n";
  }
  tiler::TilerOptions opt;
  opt.input_path = dir.file("g.png");
  opt.output_path = dir.file("out.cst");
  opt.fsync = false;
  tiler::TilerSummary summary;
  ASSERT_TRUE(tiler::tileImage(opt, &summary).isOk());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(opt.output_path, &reader).isOk());
  const GeoReference& geo = reader->info().geo;
  ASSERT_TRUE(geo.present);
  EXPECT_DOUBLE_EQ(geo.transform[0], 999.0);
  EXPECT_DOUBLE_EQ(geo.transform[1], 2.0);
  EXPECT_DOUBLE_EQ(geo.transform[3], 5001.5);
  EXPECT_DOUBLE_EQ(geo.transform[5], -3.0);
  EXPECT_EQ(geo.crs, "PROJCS[\"test\"]");
}

TEST(GeoReference, MalformedWorldFileIsAnError) {
  TempDir dir;
  {
    std::ofstream w(dir.file("g.wld"));
    w << "1.0\n0.0\nbanana\n";
  }
  GeoReference geo;
  const Status s = tiler::readWorldFile(dir.file("g.wld"), &geo);
  EXPECT_EQ(s.code, ErrorCode::kBadHeader);
  EXPECT_NE(s.message.find("g.wld"), std::string::npos) << s.message;
}

TEST(GeoReference, RealFilesKeepTransformAndCrs) {
  const std::string data = sharedDataDir();
  if (data.empty()) GTEST_SKIP() << "shared data directory absent";
  GeoReference geo;
  ASSERT_TRUE(tiler::findGeoReference(data + "/autzen.jpg", &geo).isOk());
  ASSERT_TRUE(geo.present);
  // autzen.wld: 1 ft pixels, centre of pixel (0, 0) at (635615.9278659122, 853362.1430851521).
  EXPECT_DOUBLE_EQ(geo.transform[0], 635615.9278659122 - 0.5);
  EXPECT_DOUBLE_EQ(geo.transform[3], 853362.1430851521 + 0.5);
  EXPECT_DOUBLE_EQ(geo.transform[1], 1.0);
  EXPECT_DOUBLE_EQ(geo.transform[5], -1.0);

  // RGB.byte.tif, values as gdalinfo prints them.
  ASSERT_TRUE(tiler::findGeoReference(data + "/RGB.byte.tif", &geo).isOk());
  ASSERT_TRUE(geo.present);
  EXPECT_NEAR(geo.transform[0], 101985.0, 1e-6);
  EXPECT_NEAR(geo.transform[1], 300.0379266750948, 1e-9);
  EXPECT_NEAR(geo.transform[3], 2826915.0, 1e-6);
  EXPECT_NEAR(geo.transform[5], -300.041782729805, 1e-9);
  EXPECT_EQ(geo.crs, "EPSG:32618");

  ASSERT_TRUE(tiler::findGeoReference(data + "/mt_rainier_90m.tif", &geo).isOk());
  ASSERT_TRUE(geo.present);
  EXPECT_EQ(geo.crs, "EPSG:4326");
}

}  // namespace
}  // namespace clipstream::test

namespace clipstream::test {
namespace {

// A minimal little-endian GeoTIFF header + IFD holding only the GeoTIFF
// tags (no image data: readGeoTiffTags needs none).
std::vector<uint8_t> makeGeoTiffBytes() {
  std::vector<uint8_t> b;
  auto u16 = [&](uint16_t v) { b.push_back(uint8_t(v)); b.push_back(uint8_t(v >> 8)); };
  auto u32 = [&](uint32_t v) { for (int i = 0; i < 4; ++i) b.push_back(uint8_t(v >> (8 * i))); };
  auto f64 = [&](double d) { uint64_t v; std::memcpy(&v, &d, 8); for (int i = 0; i < 8; ++i) b.push_back(uint8_t(v >> (8 * i))); };
  b = {'I', 'I', 42, 0};
  u32(8);  // IFD offset
  const uint32_t entries = 3;
  const uint32_t data = 8 + 2 + entries * 12 + 4;
  u16(uint16_t(entries));
  u16(33550); u16(12); u32(3); u32(data);            // ModelPixelScale: 3 doubles
  u16(33922); u16(12); u32(6); u32(data + 24);       // ModelTiepoint: 6 doubles
  u16(34735); u16(3); u32(12); u32(data + 72);       // GeoKeyDirectory: 12 shorts
  u32(0);  // next IFD
  f64(30.0); f64(30.0); f64(0.0);
  f64(0.0); f64(0.0); f64(0.0); f64(500000.0); f64(4000000.0); f64(0.0);
  for (uint16_t v : {1, 1, 0, 2, 1024, 0, 1, 1, 3072, 0, 1, 32633}) u16(v);
  return b;
}

TEST(GeoReference, GeoTiffTagsGiveTransformAndEpsg) {
  TempDir dir;
  const std::vector<uint8_t> bytes = makeGeoTiffBytes();
  {
    std::ofstream out(dir.file("g.tif"), std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
  }
  GeoReference geo;
  const Status s = tiler::readGeoTiffTags(dir.file("g.tif"), &geo);
  ASSERT_TRUE(s.isOk()) << s.toString();
  ASSERT_TRUE(geo.present);
  EXPECT_DOUBLE_EQ(geo.transform[0], 500000.0);
  EXPECT_DOUBLE_EQ(geo.transform[1], 30.0);
  EXPECT_DOUBLE_EQ(geo.transform[3], 4000000.0);
  EXPECT_DOUBLE_EQ(geo.transform[5], -30.0);
  EXPECT_EQ(geo.crs, "EPSG:32633");
}

TEST(GeoReference, EveryTruncationAndByteFlipIsHandled) {
  TempDir dir;
  const std::vector<uint8_t> good = makeGeoTiffBytes();
  const std::string path = dir.file("g.tif");
  auto write = [&](const std::vector<uint8_t>& b) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(b.data()), std::streamsize(b.size()));
  };
  size_t errors = 0;
  for (size_t n = 0; n < good.size(); ++n) {
    write(std::vector<uint8_t>(good.begin(), good.begin() + std::ptrdiff_t(n)));
    GeoReference geo;
    const Status s = tiler::readGeoTiffTags(path, &geo);
    // A prefix either lacks the tags (no georeference) or is reported.
    if (!s) {
      ++errors;
      EXPECT_NE(s.message.find("g.tif"), std::string::npos);
    } else {
      EXPECT_FALSE(geo.present && n < good.size() - 24) << "prefix " << n;
    }
  }
  EXPECT_GT(errors, 0u);
  for (size_t i = 0; i < good.size(); ++i) {
    for (uint8_t flip : {uint8_t(0x01), uint8_t(0x80), uint8_t(0xff)}) {
      std::vector<uint8_t> bad = good;
      bad[i] ^= flip;
      write(bad);
      GeoReference geo;
      (void)tiler::readGeoTiffTags(path, &geo);  // must return, not crash or hang
    }
  }
}

}  // namespace
}  // namespace clipstream::test
