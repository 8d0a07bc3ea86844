// The shard record of a partial store (docs/tile-store.md, section 10): where
// the writer puts each field, that the reader gives them back, and that a
// record not describing a band of the whole image is refused.
#include "format.h"  // private: checksum64 to reseal a tampered block

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

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
template <typename T>
T get(const std::vector<uint8_t>& b, uint64_t offset) {
  T v;
  std::memcpy(&v, b.data() + offset, sizeof(T));
  return v;
}
template <typename T>
void put(std::vector<uint8_t>* b, uint64_t offset, T v) {
  std::memcpy(b->data() + offset, &v, sizeof(T));
}

// A 200 x 96 RGB8 band (32-px tiles) at row 64 of a 200 x 300 image, shard
// 2 of 3, owning levels 0 and 1; every tile constant (the record is the point).
ShardInfo band() {
  ShardInfo s;
  s.present = true;
  s.index = 2;
  s.count = 3;
  s.full_width_px = 200;
  s.full_height_px = 300;
  s.x0_px = 0;
  s.y0_px = 64;
  s.owned_levels = 2;
  s.fingerprint = 0x0123456789abcdefull;
  return s;
}

std::string writePart(const TempDir& dir, const ShardInfo& shard, bool geo = true) {
  PyramidGeometry g;
  EXPECT_TRUE(makePyramidGeometry(200, 96, 32, PixelFormat::kRGB8, &g));
  WriterOptions options;
  options.fsync = false;
  options.shard = shard;
  options.geo.present = geo;
  options.geo.crs = "EPSG:2992";
  const std::string path = dir.file("part.cst");
  std::unique_ptr<TileStoreWriter> writer;
  EXPECT_TRUE(TileStoreWriter::create(path, g, options, &writer).ok());
  const uint8_t pixel[3] = {1, 2, 3};
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    EXPECT_TRUE(writer->writeConstantTiles(l, 0, 0, g.levels[l].tiles_x, g.levels[l].tiles_y, pixel)
                    .ok());
  }
  const Status s = writer->finish();
  EXPECT_TRUE(s.ok()) << s.toString();
  return path;
}

TEST(ShardRecord, SitsWhereTheDocumentSaysAndReadsBack) {
  TempDir dir;
  const std::vector<uint8_t> b = readAll(writePart(dir, band()));
  EXPECT_EQ(get<uint32_t>(b, 60), 2u | 8u);  // flags: georeference, partial store
  const uint64_t meta = get<uint64_t>(b, 104);
  EXPECT_EQ(get<uint64_t>(b, 112), 52u + 9 + 64 + 8);  // fixed, "EPSG:2992", record, checksum
  const uint64_t r = meta + 52 + 9;
  EXPECT_EQ(get<uint32_t>(b, r + 0), 2u);
  EXPECT_EQ(get<uint32_t>(b, r + 4), 3u);
  EXPECT_EQ(get<uint64_t>(b, r + 8), 200u);
  EXPECT_EQ(get<uint64_t>(b, r + 16), 300u);
  EXPECT_EQ(get<uint64_t>(b, r + 24), 0u);
  EXPECT_EQ(get<uint64_t>(b, r + 32), 64u);
  EXPECT_EQ(get<uint32_t>(b, r + 40), 2u);
  EXPECT_EQ(get<uint32_t>(b, r + 44), 0u);
  EXPECT_EQ(get<uint64_t>(b, r + 48), 0x0123456789abcdefull);
  EXPECT_EQ(get<uint64_t>(b, r + 56), 0u);

  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(dir.file("part.cst"), &reader).ok());
  const ShardInfo& s = reader->info().shard;
  EXPECT_TRUE(s.present);
  EXPECT_EQ(s.index, 2u);
  EXPECT_EQ(s.count, 3u);
  EXPECT_EQ(s.full_width_px, 200u);
  EXPECT_EQ(s.full_height_px, 300u);
  EXPECT_EQ(s.y0_px, 64u);
  EXPECT_EQ(s.owned_levels, 2u);
  EXPECT_EQ(s.fingerprint, 0x0123456789abcdefull);
  EXPECT_EQ(reader->info().geo.crs, "EPSG:2992");
}

TEST(ShardRecord, ARecordThatIsNoBandOfTheImageIsRefused) {
  TempDir dir;
  const std::vector<uint8_t> good = readAll(writePart(dir, band(), false));
  const uint64_t meta = get<uint64_t>(good, 104), meta_bytes = get<uint64_t>(good, 112);
  const uint64_t r = meta + 52;  // no CRS without a georeference
  struct Case {
    const char* what;
    uint64_t offset;
    uint64_t value;
    int bytes;
  };
  const Case cases[] = {
      {"index 0", 0, 0, 4},          {"index above count", 0, 4, 4},
      {"count 0", 4, 0, 4},          {"band past the right edge", 8, 199, 8},
      {"band past the bottom", 16, 159, 8}, {"origin off the block grid", 32, 32, 8},
      {"no owned level", 40, 0, 4},  {"more levels than the store", 40, 9, 4},
      {"reserved word", 44, 1, 4},   {"reserved word", 56, 1, 8},
  };
  for (const Case& c : cases) {
    std::vector<uint8_t> b = good;
    if (c.bytes == 4) put<uint32_t>(&b, r + c.offset, uint32_t(c.value));
    else put<uint64_t>(&b, r + c.offset, c.value);
    put<uint64_t>(&b, meta + meta_bytes - 8, format::checksum64(b.data() + meta, meta_bytes - 8));
    writeAll(dir.file("bad.cst"), b);
    std::unique_ptr<TileStoreReader> reader;
    const Status s = TileStoreReader::open(dir.file("bad.cst"), &reader);
    EXPECT_EQ(s.code, ErrorCode::kBadHeader) << c.what << ": " << s.toString();
  }
  // Without the flag the same bytes are a metadata block of the wrong size.
  std::vector<uint8_t> unflagged = good;
  put<uint32_t>(&unflagged, 60, 0);
  put<uint64_t>(&unflagged, format::kHeaderChecksumOffset,
                format::checksum64(unflagged.data(), format::kHeaderChecksumOffset));
  writeAll(dir.file("unflagged.cst"), unflagged);
  std::unique_ptr<TileStoreReader> reader;
  EXPECT_EQ(TileStoreReader::open(dir.file("unflagged.cst"), &reader).code, ErrorCode::kBadHeader);
}

}  // namespace
}  // namespace clipstream
