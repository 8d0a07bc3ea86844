// Write -> read round trips over geometries, pixel formats and encodings.
#include "format.h"  // private: the page-grid rule shared by reader and writer

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <algorithm>

namespace clipstream {
namespace {

using test::isConstantTile;
using test::syntheticTile;
using test::syntheticTileKey;
using test::TempDir;
using test::writeSyntheticStore;

struct RoundTripCase {
  uint64_t width;
  uint64_t height;
  uint32_t tile_px;
  PixelFormat format;
  Compression compression;
  Predictor predictor;
};

class StoreRoundTrip : public ::testing::TestWithParam<RoundTripCase> {};

TEST_P(StoreRoundTrip, EveryTileReadsBackBitExact) {
  const RoundTripCase& c = GetParam();
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(c.width, c.height, c.tile_px, c.format, &g));
  const TempDir dir("roundtrip");
  const std::string path = dir.file("store.cst");
  WriterOptions options;
  options.encoding.compression = c.compression;
  options.encoding.predictor = c.predictor;
  options.encoding.zstd_level = 3;
  ASSERT_TRUE(writeSyntheticStore(path, g, options).ok());

  std::unique_ptr<TileStoreReader> reader;
  Status status = TileStoreReader::open(path, &reader);
  ASSERT_TRUE(status.ok()) << status.toString();
  EXPECT_EQ(reader->geometry().width_px, c.width);
  EXPECT_EQ(reader->geometry().height_px, c.height);
  EXPECT_EQ(reader->geometry().tile_px, c.tile_px);
  EXPECT_EQ(reader->geometry().format, c.format);
  EXPECT_EQ(reader->geometry().levelCount(), g.levelCount());
  EXPECT_EQ(reader->info().encoding.compression, c.compression);
  EXPECT_EQ(reader->info().encoding.predictor, c.predictor);

  uint64_t constant_tiles = 0, tiles = 0;
  std::vector<uint8_t> pixels;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        const TileKey key{l, x, y};
        status = reader->readTile(key, &pixels);
        ASSERT_TRUE(status.ok()) << status.toString();
        ASSERT_EQ(pixels, syntheticTile(g, key)) << "level " << l << " tile " << x << "," << y;
        TileLocation location;
        ASSERT_TRUE(reader->locate(key, &location).ok());
        EXPECT_EQ(location.constant, isConstantTile(key));
        TileKey stamped;
        EXPECT_EQ(syntheticTileKey(c.format, pixels, &stamped), !location.constant);
        if (!location.constant) {
          EXPECT_EQ(stamped, key);
        }
        constant_tiles += location.constant;
        ++tiles;
      }
    }
  }
  std::vector<LevelStats> stats;
  ASSERT_TRUE(reader->levelStats(&stats).ok());
  uint64_t stat_tiles = 0, stat_constant = 0;
  for (const LevelStats& s : stats) {
    stat_tiles += s.tiles;
    stat_constant += s.constant_tiles;
  }
  EXPECT_EQ(stat_tiles, tiles);
  EXPECT_EQ(stat_constant, constant_tiles);
  std::vector<TileStoreReader::Problem> problems;
  EXPECT_TRUE(reader->verifyAll(&problems, 10, {}, 2).ok());
  EXPECT_TRUE(problems.empty());
}

INSTANTIATE_TEST_SUITE_P(
    Geometries, StoreRoundTrip,
    ::testing::Values(
        RoundTripCase{1000, 777, 128, PixelFormat::kRGB8, Compression::kZstd, Predictor::kLeftDelta},
        RoundTripCase{1000, 777, 64, PixelFormat::kRGBA8, Compression::kZstd, Predictor::kNone},
        RoundTripCase{129, 1, 16, PixelFormat::kR8, Compression::kZstd, Predictor::kLeftDelta},
        RoundTripCase{1, 1, 128, PixelFormat::kR16, Compression::kZstd, Predictor::kLeftDelta},
        RoundTripCase{1, 1, 16, PixelFormat::kRGBA8, Compression::kNone, Predictor::kNone},
        RoundTripCase{300, 5000, 32, PixelFormat::kR16, Compression::kNone, Predictor::kLeftDelta},
        RoundTripCase{513, 257, 16, PixelFormat::kRGB8, Compression::kNone, Predictor::kNone},
        RoundTripCase{2048, 2048, 16, PixelFormat::kR8, Compression::kZstd, Predictor::kLeftDelta}));

TEST(StoreGeometry, LevelsHalveWithCeilingDownToOneTile) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(1000, 777, 128, PixelFormat::kRGB8, &g));
  ASSERT_EQ(g.levelCount(), 4u);  // 1000 -> 500 -> 250 -> 125 (one tile)
  EXPECT_EQ(g.levels[0].tiles_x, 8u);
  EXPECT_EQ(g.levels[0].tiles_y, 7u);
  EXPECT_EQ(g.levels[1].width_px, 500u);
  EXPECT_EQ(g.levels[1].height_px, 389u);
  EXPECT_EQ(g.levels[3].width_px, 125u);
  EXPECT_EQ(g.levels[3].height_px, 98u);
  EXPECT_EQ(g.levels[3].tiles_x, 1u);
  ASSERT_TRUE(makePyramidGeometry(1, 1, 128, PixelFormat::kR8, &g));
  EXPECT_EQ(g.levelCount(), 1u);
  EXPECT_FALSE(makePyramidGeometry(0, 5, 128, PixelFormat::kR8, &g));
  ASSERT_TRUE(makePyramidGeometry(uint64_t(1) << 20, uint64_t(1) << 20, 128, PixelFormat::kRGBA8, &g));
  EXPECT_EQ(g.levelCount(), 14u);
}

TEST(StoreGeometry, PageCountDoesNotWrapAtTheLargestTileGrid) {
  // tiles_x may be up to 2^32 - 1; ceil(tiles / 64) must not wrap to 0 (it
  // did in 32 bits, leaving an empty page directory that lookups indexed).
  EXPECT_EQ(format::pagesAlong(0xFFFFFFFFu), 0x4000000u);
  EXPECT_EQ(format::pagesAlong(0xFFFFFFC1u), 0x3FFFFFFu + 1);
  EXPECT_EQ(format::pagesAlong(64), 1u);
  EXPECT_EQ(format::pagesAlong(65), 2u);
  EXPECT_EQ(format::pageSpan(0xFFFFFFFFu, 0x3FFFFFF), 63u);
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(uint64_t(0xFFFFFFFFu) * 16, 16, 16, PixelFormat::kR8, &g));
  EXPECT_EQ(g.levels[0].tiles_x, 0xFFFFFFFFu);
  EXPECT_EQ(uint64_t(format::pagesAlong(g.levels[0].tiles_x)) * format::kPageTiles,
            uint64_t(0xFFFFFFFFu) + 1);
}

TEST(StoreEncode, ConstantTilesCostNoPayloadBytesInTheFile) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(512, 512, 16, PixelFormat::kRGBA8, &g));
  const TempDir dir("constant");
  const std::string path = dir.file("flat.cst");
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(path, g, {}, &writer).ok());
  const std::vector<uint8_t> flat = [&] {
    std::vector<uint8_t> p(g.tileBytes());
    for (size_t i = 0; i < p.size(); ++i) p[i] = uint8_t(i % 4 == 3 ? 255 : 7);
    return p;
  }();
  uint64_t tiles = 0;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        EncodedTile encoded;
        ASSERT_TRUE(encodeTile(g, {}, TileKey{l, x, y}, flat, &encoded).ok());
        ASSERT_TRUE(writer->write(std::move(encoded)).ok());
        ++tiles;
      }
    }
  }
  EXPECT_EQ(writer->constantTiles(), tiles);
  EXPECT_EQ(writer->bytesWritten(), 0u);
  ASSERT_TRUE(writer->finish().ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());
  // Whole constant pages need no index page either: the file is header,
  // directories, level table and metadata only.
  EXPECT_LT(reader->info().file_bytes, 1024u);
  std::vector<uint8_t> pixels;
  ASSERT_TRUE(reader->readTile(TileKey{1, 3, 5}, &pixels).ok());
  EXPECT_EQ(pixels, flat);
}

TEST(StoreGeoReference, TransformAndCrsRoundTrip) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(100, 60, 16, PixelFormat::kRGB8, &g));
  const TempDir dir("geo");
  const std::string path = dir.file("geo.cst");
  WriterOptions options;
  options.geo.present = true;
  const double transform[6] = {635747.5, 0.25, 0.0, 848898.75, 0.0, -0.25};
  std::copy(transform, transform + 6, options.geo.transform);
  options.geo.crs = "PROJCS[\"NAD83 / Oregon GIC Lambert (ft)\",UNIT[\"foot\",0.3048]]";
  options.encoding.linear_light = true;
  options.encoding.filter = DownsampleFilter::kLanczos3;
  ASSERT_TRUE(writeSyntheticStore(path, g, options).ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());
  const GeoReference& geo = reader->info().geo;
  EXPECT_TRUE(geo.present);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(geo.transform[i], transform[i]) << i;
  EXPECT_EQ(geo.crs, options.geo.crs);
  EXPECT_TRUE(reader->info().encoding.linear_light);
  EXPECT_EQ(reader->info().encoding.filter, DownsampleFilter::kLanczos3);

  const std::string plain = dir.file("plain.cst");
  WriterOptions no_geo;
  no_geo.geo.crs = "EPSG:4326";  // ignored: present is false
  no_geo.geo.transform[0] = 5.0;
  ASSERT_TRUE(writeSyntheticStore(plain, g, no_geo).ok());
  ASSERT_TRUE(TileStoreReader::open(plain, &reader).ok());
  EXPECT_FALSE(reader->info().geo.present);
  EXPECT_TRUE(reader->info().geo.crs.empty());
  EXPECT_EQ(reader->info().geo.transform[0], 0.0);
  EXPECT_EQ(reader->info().geo.transform[1], 1.0);
}

}  // namespace
}  // namespace clipstream
