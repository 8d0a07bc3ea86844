// Georeferencing (georef.h): world files and their pixel-centre origin,
// GeoTIFF tags parsed from a hand-made header (every truncation and byte
// flip survived), the georeference of the real sample files, and its way
// through the tiler into the store.
#include "tiler_test_util.h"

#include <clipstream/testing/test_data.h>
#include <clipstream/tiler/georef.h>
#include <clipstream/tiler/tiler.h>

#include <cstring>
#include <fstream>

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
  const Status s = readGeoTiffTags(dir.file("g.tif"), &geo);
  ASSERT_TRUE(s.ok()) << s.toString();
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
    const Status s = readGeoTiffTags(path, &geo);
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
      (void)readGeoTiffTags(path, &geo);  // must return, not crash or hang
    }
  }
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
  TilerOptions opt;
  opt.input_path = dir.file("g.png");
  opt.output_path = dir.file("out.cst");
  opt.fsync = false;
  TilerSummary summary;
  ASSERT_TRUE(tileImage(opt, &summary).ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(opt.output_path, &reader).ok());
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
  const Status s = readWorldFile(dir.file("g.wld"), &geo);
  EXPECT_EQ(s.code, ErrorCode::kBadHeader);
  EXPECT_NE(s.message.find("g.wld"), std::string::npos) << s.message;
}

TEST(GeoReference, RealFilesKeepTransformAndCrs) {
  GeoReference geo;
  ASSERT_TRUE(findGeoReference(bundledDataPath("autzen.jpg"), &geo).ok());
  ASSERT_TRUE(geo.present);
  // autzen.wld: 1 ft pixels, centre of pixel (0, 0) at (635615.9278659122, 853362.1430851521).
  EXPECT_DOUBLE_EQ(geo.transform[0], 635615.9278659122 - 0.5);
  EXPECT_DOUBLE_EQ(geo.transform[3], 853362.1430851521 + 0.5);
  EXPECT_DOUBLE_EQ(geo.transform[1], 1.0);
  EXPECT_DOUBLE_EQ(geo.transform[5], -1.0);

  // RGB.byte.tif, values as gdalinfo prints them.
  CLIPSTREAM_REQUIRE_SHARED_DATA("RGB.byte.tif");
  ASSERT_TRUE(findGeoReference(sharedDataPath("RGB.byte.tif"), &geo).ok());
  ASSERT_TRUE(geo.present);
  EXPECT_NEAR(geo.transform[0], 101985.0, 1e-6);
  EXPECT_NEAR(geo.transform[1], 300.0379266750948, 1e-9);
  EXPECT_NEAR(geo.transform[3], 2826915.0, 1e-6);
  EXPECT_NEAR(geo.transform[5], -300.041782729805, 1e-9);
  EXPECT_EQ(geo.crs, "EPSG:32618");

  CLIPSTREAM_REQUIRE_SHARED_DATA("mt_rainier_90m.tif");
  ASSERT_TRUE(findGeoReference(sharedDataPath("mt_rainier_90m.tif"), &geo).ok());
  ASSERT_TRUE(geo.present);
  EXPECT_EQ(geo.crs, "EPSG:4326");
}

}  // namespace
}  // namespace clipstream::test
