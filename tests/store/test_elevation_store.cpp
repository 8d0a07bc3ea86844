// Elevation stores at the format level (docs/tile-store.md, version 2):
// the elevation record and 32-byte tile entries sit where the document
// says, heights and bounds survive the round trip, constant pages keep the
// bounds they stand for, the writer refuses what a reader would reject, and
// version 1 stores still open.
#include "format.h"  // private: the record codec shared by reader and writer

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>

namespace clipstream {
namespace {

using test::TempDir;

std::vector<uint8_t> readAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)), {});
}

void writeAll(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}

uint32_t le32(const std::vector<uint8_t>& b, uint64_t offset) {
  uint32_t v;
  std::memcpy(&v, b.data() + offset, 4);
  return v;
}
uint64_t le64(const std::vector<uint8_t>& b, uint64_t offset) {
  uint64_t v;
  std::memcpy(&v, b.data() + offset, 8);
  return v;
}
double f64(const std::vector<uint8_t>& b, uint64_t offset) {
  double v;
  std::memcpy(&v, b.data() + offset, 8);
  return v;
}
float f32(const std::vector<uint8_t>& b, uint64_t offset) {
  float v;
  std::memcpy(&v, b.data() + offset, 4);
  return v;
}

// Heights of tile (l, x, y) at sample (i, j): distinct per tile and sample.
int16_t sampleOf(const TileKey& k, uint32_t i, uint32_t j) {
  return int16_t(int(k.level) * 1000 + int(k.x) * 100 + int(k.y) * 10 - 500 + int((i * 7 + j * 3) % 50));
}

struct Written {
  std::string path;
  PyramidGeometry geometry;
  WriterOptions options;
};

// A 200x150 I16 elevation store with tile 32: every tile varies, except
// level 1 tile (0, 0), which is constant with bounds wider than its value
// (the ground under a flat-looking coarse tile need not be flat).
Written writeElevationStore(const TempDir& dir) {
  Written w;
  w.path = dir.file("e.cst");
  EXPECT_TRUE(makePyramidGeometry(200, 150, 32, PixelFormat::kI16, &w.geometry));
  w.options.encoding.filter = DownsampleFilter::kDecimate;
  w.options.elevation.present = true;
  w.options.elevation.scale = 0.5;
  w.options.elevation.offset = 100.0;
  w.options.elevation.units = HeightUnits::kFoot;
  w.options.elevation.units_assumed = false;
  w.options.elevation.has_nodata = true;
  w.options.elevation.nodata = -32768;
  w.options.fsync = false;
  std::unique_ptr<TileStoreWriter> writer;
  EXPECT_TRUE(TileStoreWriter::create(w.path, w.geometry, w.options, &writer).ok());
  const PyramidGeometry& g = w.geometry;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        const TileKey key{l, x, y};
        std::vector<uint8_t> pixels(g.tileBytes());
        const bool flat = l == 1 && x == 0 && y == 0;
        for (uint32_t j = 0; j < g.tile_px; ++j)
          for (uint32_t i = 0; i < g.tile_px; ++i) {
            const int16_t v = flat ? int16_t(40) : sampleOf(key, i, j);
            std::memcpy(pixels.data() + (size_t(j) * g.tile_px + i) * 2, &v, 2);
          }
        EncodedTile encoded;
        EXPECT_TRUE(encodeTile(g, w.options.encoding, key, pixels, &encoded).ok());
        encoded.location.min_height = float(l) - 10.0f;
        encoded.location.max_height = float(l) + float(x) + float(y) + 10.0f;
        encoded.location.error = float(l) * 0.5f;
        EXPECT_TRUE(writer->write(std::move(encoded)).ok());
      }
    }
  }
  EXPECT_TRUE(writer->setElevationFigures(12, 0.0, -150.0, 600.0).ok());
  EXPECT_TRUE(writer->finish().ok());
  return w;
}

TEST(ElevationStore, HeightsBoundsAndTheRecordRoundTrip) {
  TempDir dir;
  const Written w = writeElevationStore(dir);
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(w.path, &reader).ok());
  const StoreInfo& info = reader->info();
  EXPECT_EQ(info.format_version, 2u);
  EXPECT_EQ(info.encoding.filter, DownsampleFilter::kDecimate);
  const ElevationInfo& e = info.elevation;
  ASSERT_TRUE(e.present);
  EXPECT_EQ(e.scale, 0.5);
  EXPECT_EQ(e.offset, 100.0);
  EXPECT_EQ(e.units, HeightUnits::kFoot);
  EXPECT_FALSE(e.units_assumed);
  EXPECT_TRUE(e.has_nodata);
  EXPECT_EQ(e.nodata, -32768.0);
  EXPECT_EQ(e.filled_samples, 12u);
  EXPECT_EQ(e.min_height, -150.0);
  EXPECT_EQ(e.max_height, 600.0);
  const PyramidGeometry& g = w.geometry;
  std::vector<float> heights(size_t(g.tile_px) * g.tile_px);
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        const TileKey key{l, x, y};
        RawTile raw;
        ASSERT_TRUE(reader->readRaw(key, &raw).ok());
        EXPECT_EQ(raw.location.min_height, float(l) - 10.0f);
        EXPECT_EQ(raw.location.max_height, float(l + x + y) + 10.0f);
        EXPECT_EQ(raw.location.error, float(l) * 0.5f);
        ASSERT_TRUE(decodeTileHeights(g, info.encoding, e, raw, heights).ok());
        const bool flat = l == 1 && x == 0 && y == 0;
        EXPECT_EQ(raw.location.constant, flat);
        for (uint32_t j = 0; j < g.tile_px; j += 7)
          for (uint32_t i = 0; i < g.tile_px; i += 5)
            ASSERT_EQ(heights[size_t(j) * g.tile_px + i],
                      100.0f + 0.5f * float(flat ? 40 : sampleOf(key, i, j)));
      }
    }
  }
  // A colour decode of heights is refused, not garbage.
  RawTile raw;
  ASSERT_TRUE(reader->readRaw(TileKey{0, 0, 0}, &raw).ok());
  std::vector<uint8_t> rgba(size_t(g.tile_px) * g.tile_px * 4);
  EXPECT_EQ(decodeTileRgba8(g, info.encoding, raw, rgba).code, ErrorCode::kUnsupported);
}

TEST(ElevationStore, RecordAndEntriesSitWhereTheDocumentSays) {
  TempDir dir;
  const Written w = writeElevationStore(dir);
  const std::vector<uint8_t> b = readAll(w.path);
  // docs/tile-store.md sections 5, 8 and 10, as literals.
  EXPECT_EQ(le32(b, 8), 2u);    // format_version
  EXPECT_EQ(le32(b, 36), 5u);   // pixel_format I16
  EXPECT_EQ(le32(b, 56), 2u);   // filter decimate
  EXPECT_EQ(le32(b, 60), 4u);   // flags: elevation (no georeference)
  EXPECT_EQ(le32(b, 68), 32u);  // tile_entry_bytes
  const uint64_t metadata_offset = le64(b, 104), metadata_bytes = le64(b, 112);
  EXPECT_EQ(metadata_bytes, 52u + 0 + 64 + 8);  // fixed part, no CRS, record, checksum
  const uint64_t r = metadata_offset + 52;      // the record follows the (empty) CRS
  EXPECT_EQ(f64(b, r + 0), 0.5);                // scale
  EXPECT_EQ(f64(b, r + 8), 100.0);              // offset
  EXPECT_EQ(f64(b, r + 16), -32768.0);          // nodata
  EXPECT_EQ(le32(b, r + 24), 1u);               // flags: has no-data (units given)
  EXPECT_EQ(le32(b, r + 28), 2u);               // units: foot
  EXPECT_EQ(le64(b, r + 32), 12u);              // filled samples
  EXPECT_EQ(f64(b, r + 40), 0.0);               // max error
  EXPECT_EQ(f64(b, r + 48), -150.0);            // min height
  EXPECT_EQ(f64(b, r + 56), 600.0);             // max height
  // Level 0's one index page: entry (1, 0) holds its bounds at 16, 20, 24.
  const uint64_t table = le64(b, 72);
  const uint64_t dir0 = le64(b, table + 48);
  const uint64_t page = le64(b, dir0 + 0);
  EXPECT_EQ(le32(b, dir0 + 8), 7u * 5u * 32u);  // 7x5 tiles of 32 bytes
  const uint64_t entry = page + 1 * 32;
  EXPECT_EQ(f32(b, entry + 16), -10.0f);
  EXPECT_EQ(f32(b, entry + 20), 11.0f);
  EXPECT_EQ(f32(b, entry + 24), 0.0f);
  EXPECT_EQ(le32(b, entry + 28), 0u);  // reserved
}

TEST(ElevationStore, ConstantPagesStandForFlatGroundOnly) {
  TempDir dir;
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 32, PixelFormat::kF32, &g));
  WriterOptions options;
  options.encoding.filter = DownsampleFilter::kDecimate;
  options.elevation.present = true;
  options.fsync = false;
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(dir.file("c.cst"), g, options, &writer).ok());
  // Level 0: all four tiles constant 7 m and flat: one constant page.
  const float seven = 7.0f;
  ASSERT_TRUE(writer->writeConstantTiles(0, 0, 0, 2, 2, std::span<const uint8_t>(
      reinterpret_cast<const uint8_t*>(&seven), 4)).ok());
  // Level 1: constant 7 m samples over ground from 3 to 9 m.
  std::vector<uint8_t> pixels(g.tileBytes());
  for (size_t i = 0; i < pixels.size(); i += 4) std::memcpy(pixels.data() + i, &seven, 4);
  EncodedTile encoded;
  ASSERT_TRUE(encodeTile(g, options.encoding, {1, 0, 0}, pixels, &encoded).ok());
  ASSERT_TRUE(encoded.location.constant);
  encoded.location.min_height = 3.0f;
  encoded.location.max_height = 9.0f;
  encoded.location.error = 2.0f;
  ASSERT_TRUE(writer->write(std::move(encoded)).ok());
  ASSERT_TRUE(writer->setElevationFigures(0, 0.0, 3.0, 9.0).ok());
  ASSERT_TRUE(writer->finish().ok());

  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(dir.file("c.cst"), &reader).ok());
  TileLocation loc;
  ASSERT_TRUE(reader->locate({0, 1, 1}, &loc).ok());
  EXPECT_TRUE(loc.constant);
  EXPECT_EQ(loc.min_height, 7.0f);
  EXPECT_EQ(loc.max_height, 7.0f);
  ASSERT_TRUE(reader->locate({1, 0, 0}, &loc).ok());
  EXPECT_TRUE(loc.constant);
  EXPECT_EQ(loc.min_height, 3.0f);
  EXPECT_EQ(loc.max_height, 9.0f);
  EXPECT_EQ(loc.error, 2.0f);
}

TEST(ElevationStore, WriterRefusesFormatsAndBoundsThatDoNotFit) {
  TempDir dir;
  PyramidGeometry rgb, f32;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 32, PixelFormat::kRGB8, &rgb));
  ASSERT_TRUE(makePyramidGeometry(64, 64, 32, PixelFormat::kF32, &f32));
  WriterOptions elevation;
  elevation.elevation.present = true;
  elevation.fsync = false;
  std::unique_ptr<TileStoreWriter> writer;
  EXPECT_EQ(TileStoreWriter::create(dir.file("a.cst"), rgb, elevation, &writer).code,
            ErrorCode::kInvalidArgument);
  EXPECT_EQ(TileStoreWriter::create(dir.file("a.cst"), f32, WriterOptions{}, &writer).code,
            ErrorCode::kInvalidArgument);
  WriterOptions bad_scale = elevation;
  bad_scale.elevation.scale = 0.0;
  EXPECT_EQ(TileStoreWriter::create(dir.file("a.cst"), f32, bad_scale, &writer).code,
            ErrorCode::kInvalidArgument);
  ASSERT_TRUE(TileStoreWriter::create(dir.file("a.cst"), f32, elevation, &writer).ok());
  std::vector<uint8_t> pixels(f32.tileBytes());
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = uint8_t(i % 251);
  EncodedTile encoded;
  ASSERT_TRUE(encodeTile(f32, elevation.encoding, {0, 0, 0}, pixels, &encoded).ok());
  encoded.location.min_height = NAN;
  EXPECT_EQ(writer->write(EncodedTile(encoded)).code, ErrorCode::kInvalidArgument);
  encoded.location.min_height = 5.0f;
  encoded.location.max_height = 1.0f;
  EXPECT_EQ(writer->write(EncodedTile(encoded)).code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(writer->setElevationFigures(0, 0.0, 2.0, 1.0).code, ErrorCode::kInvalidArgument);
}

TEST(ElevationStore, VersionOneStoresStillOpenAndCannotClaimHeights) {
  TempDir dir;
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(100, 80, 32, PixelFormat::kRGB8, &g));
  WriterOptions options;
  options.fsync = false;
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(dir.file("v.cst"), g, options, &writer).ok());
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        std::vector<uint8_t> pixels(g.tileBytes());
        for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = uint8_t(i * 3 + l + x + y);
        EncodedTile encoded;
        ASSERT_TRUE(encodeTile(g, options.encoding, {l, x, y}, pixels, &encoded).ok());
        ASSERT_TRUE(writer->write(std::move(encoded)).ok());
      }
  ASSERT_TRUE(writer->finish().ok());
  // A colour store of version 2 has version 1's layout: only the number differs.
  std::vector<uint8_t> bytes = readAll(dir.file("v.cst"));
  auto reseal = [](std::vector<uint8_t>* b) {
    const uint64_t sum = format::checksum64(b->data(), format::kHeaderChecksumOffset);
    std::memcpy(b->data() + format::kHeaderChecksumOffset, &sum, 8);
  };
  bytes[8] = 1;
  reseal(&bytes);
  writeAll(dir.file("v1.cst"), bytes);
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(dir.file("v1.cst"), &reader).ok());
  EXPECT_EQ(reader->info().format_version, 1u);
  std::vector<uint8_t> pixels;
  EXPECT_TRUE(reader->readTile({0, 2, 1}, &pixels).ok());
  std::vector<LevelStats> stats;
  EXPECT_TRUE(reader->levelStats(&stats).ok());

  // Version 1 knows no elevation flag, height format or decimate filter.
  std::vector<uint8_t> flagged = bytes;
  flagged[60] |= 4;
  reseal(&flagged);
  writeAll(dir.file("v1e.cst"), flagged);
  EXPECT_EQ(TileStoreReader::open(dir.file("v1e.cst"), &reader).code, ErrorCode::kBadHeader);
  std::vector<uint8_t> f32 = bytes;
  f32[36] = 6;
  reseal(&f32);
  writeAll(dir.file("v1f.cst"), f32);
  EXPECT_EQ(TileStoreReader::open(dir.file("v1f.cst"), &reader).code, ErrorCode::kUnsupported);
  // Version 2: a colour format under the elevation flag is refused.
  std::vector<uint8_t> v2 = readAll(dir.file("v.cst"));
  v2[60] |= 4;
  reseal(&v2);
  writeAll(dir.file("v2e.cst"), v2);
  const Status s = TileStoreReader::open(dir.file("v2e.cst"), &reader);
  EXPECT_EQ(s.code, ErrorCode::kBadHeader);
  EXPECT_NE(s.message.find("cannot hold heights"), std::string::npos) << s.message;
}

}  // namespace
}  // namespace clipstream
