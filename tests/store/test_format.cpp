// The record codec (store/src/format.h): every record survives encode ->
// decode, a flipped byte is caught, and the bytes of a real store sit where
// docs/tile-store.md says. The layout checks below use the documented offsets
// as literals on purpose: a wrong named constant in format.h must fail them.
#include "format.h"  // private: the record codec shared by reader and writer

#include <clipstream/store/tile_store.h>

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

namespace clipstream {
namespace {

uint32_t le32(const std::vector<uint8_t>& b, uint64_t offset) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | b.at(offset + i);
  return v;
}

uint64_t le64(const std::vector<uint8_t>& b, uint64_t offset) {
  uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | b.at(offset + i);
  return v;
}

std::vector<uint8_t> slice(const std::vector<uint8_t>& b, uint64_t offset, uint64_t bytes) {
  EXPECT_LE(offset + bytes, b.size());
  return std::vector<uint8_t>(b.begin() + offset, b.begin() + offset + bytes);
}

format::Header sampleHeader() {
  format::Header h;
  h.format_version = 0x01020304;
  h.header_bytes = 0x05060708;
  h.width_px = 0x1112131415161718ull;
  h.height_px = 0x2122232425262728ull;
  h.tile_px = 0x31323334;
  h.pixel_format = 0x41424344;
  h.level_count = 0x51525354;
  h.compression = 0x61626364;
  h.zstd_level = -7;
  h.predictor = 0x71727374;
  h.filter = 0x81828384;
  h.flags = 0x91929394;
  h.page_tiles = 0xA1A2A3A4;
  h.tile_entry_bytes = 0xB1B2B3B4;
  h.level_table_offset = 0xC1C2C3C4C5C6C7C8ull;
  h.level_table_bytes = 0xD1D2D3D4D5D6D7D8ull;
  h.index_offset = 0xE1E2E3E4E5E6E7E8ull;
  h.index_bytes = 0xF1F2F3F4F5F6F7F8ull;
  h.metadata_offset = 0x0A0B0C0D0E0F1011ull;
  h.metadata_bytes = 0x1A1B1C1D1E1F2021ull;
  h.file_bytes = 0x2A2B2C2D2E2F3031ull;
  return h;
}

TEST(StoreFormat, HeaderRoundTripsAndItsChecksumCatchesAFlippedByte) {
  const format::Header header = sampleHeader();
  uint8_t bytes[format::kHeaderBytes];
  std::memset(bytes, 0xEE, sizeof bytes);
  format::encodeHeader(header, bytes);
  EXPECT_TRUE(format::hasMagic(bytes));
  EXPECT_EQ(format::decodeVersion(bytes), header.format_version);
  EXPECT_TRUE(format::headerChecksumOk(bytes));
  format::Header decoded;
  format::decodeHeader(bytes, &decoded);
  EXPECT_EQ(decoded, header);
  for (size_t i = 0; i < format::kHeaderChecksumOffset; ++i) {
    bytes[i] ^= 0x10;
    EXPECT_FALSE(format::headerChecksumOk(bytes)) << "byte " << i;
    bytes[i] ^= 0x10;
  }
  bytes[0] = 'X';
  EXPECT_FALSE(format::hasMagic(bytes));
}

TEST(StoreFormat, LevelTableRoundTripsAndRejectsBadChecksumOrSize) {
  std::vector<format::LevelEntry> levels(3);
  for (size_t l = 0; l < levels.size(); ++l) {
    const uint64_t b = 0x0101010101010101ull * (l + 1);
    levels[l] = {b * 1, b * 2, uint32_t(b * 3), uint32_t(b * 4), uint32_t(b * 5),
                 uint32_t(b * 6), b * 7, b * 8, b * 9, b * 10};
  }
  std::vector<uint8_t> table = format::encodeLevelTable(levels);
  ASSERT_EQ(table.size(), format::levelTableBytes(3));
  ASSERT_EQ(table.size(), 3u * 64 + 8);
  std::vector<format::LevelEntry> decoded;
  ASSERT_EQ(format::decodeLevelTable(table, &decoded), format::Decoded::kOk);
  EXPECT_EQ(decoded, levels);
  table[70] ^= 1;
  EXPECT_EQ(format::decodeLevelTable(table, &decoded), format::Decoded::kBadChecksum);
  table.pop_back();
  EXPECT_EQ(format::decodeLevelTable(table, &decoded), format::Decoded::kBadSize);
}

TEST(StoreFormat, PageDirectoryRoundTripsAndRejectsBadChecksumOrSize) {
  std::vector<format::PageDirEntry> pages = {
      {0x1122334455667788ull, 0x99AABBCC, 0, 0, 0xDDEEFF0011223344ull},
      {0, 0, format::kPageFlagConstant, 0x00000000A1B2C3D4ull, 0},
  };
  std::vector<uint8_t> directory = format::encodePageDirectory(pages);
  ASSERT_EQ(directory.size(), format::pageDirectoryBytes(2));
  ASSERT_EQ(directory.size(), 2u * 32 + 8);
  std::vector<format::PageDirEntry> decoded;
  ASSERT_EQ(format::decodePageDirectory(directory, &decoded), format::Decoded::kOk);
  EXPECT_EQ(decoded, pages);
  directory[40] ^= 0x80;
  EXPECT_EQ(format::decodePageDirectory(directory, &decoded), format::Decoded::kBadChecksum);
  directory.resize(7);
  EXPECT_EQ(format::decodePageDirectory(directory, &decoded), format::Decoded::kBadSize);
}

TEST(StoreFormat, IndexPageRoundTripsAgainstItsDirectoryChecksum) {
  const std::vector<format::TileEntry> entries = {
      {0x0102030405060708ull, 0x11121314, 0x21222324},
      {0x0000000000A0B0C0ull, 0, 0},
      {0x3132333435363738ull, 0x41424344, 0x51525354},
  };
  std::vector<uint8_t> page;
  const uint64_t checksum = format::encodeIndexPage(entries, format::kTileEntryBytes, &page);
  ASSERT_EQ(page.size(), 3u * 16);
  EXPECT_EQ(checksum, format::checksum64(page.data(), page.size()));
  std::vector<format::TileEntry> decoded;
  ASSERT_EQ(format::decodeIndexPage(page, checksum, format::kTileEntryBytes, &decoded), format::Decoded::kOk);
  EXPECT_EQ(decoded, entries);
  page[17] ^= 4;
  EXPECT_EQ(format::decodeIndexPage(page, checksum, format::kTileEntryBytes, &decoded), format::Decoded::kBadChecksum);
  page.pop_back();
  EXPECT_EQ(format::decodeIndexPage(page, checksum, format::kTileEntryBytes, &decoded), format::Decoded::kBadSize);
}

TEST(StoreFormat, MetadataRoundTripsAndRejectsAWrongCrsLength) {
  const double transform[6] = {-180.5, 0.25, 1e-9, 90.125, -3e-7, -0.25};
  const std::string crs = "EPSG:4326";
  std::vector<uint8_t> block = format::encodeMetadata(transform, crs);
  ASSERT_EQ(block.size(), 60u + crs.size());
  GeoReference geo;
  ASSERT_EQ(format::decodeMetadata(block, &geo), format::Decoded::kOk);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(geo.transform[i], transform[i]) << i;
  EXPECT_EQ(geo.crs, crs);
  EXPECT_FALSE(geo.present);  // a header flag, not the block's business

  block[3] ^= 1;
  EXPECT_EQ(format::decodeMetadata(block, &geo), format::Decoded::kBadChecksum);
  block[3] ^= 1;
  // A CRS length one too long, checksum re-sealed: the size is what is wrong.
  format::put32(block.data() + 48, uint32_t(crs.size() + 1));
  const size_t body = block.size() - 8;
  format::put64(block.data() + body, format::checksum64(block.data(), body));
  EXPECT_EQ(format::decodeMetadata(block, &geo), format::Decoded::kBadSize);
  EXPECT_EQ(format::decodeMetadata(std::span<const uint8_t>(block.data(), 59), &geo),
            format::Decoded::kBadSize);

  const std::vector<uint8_t> empty = format::encodeMetadata(transform, "");
  ASSERT_EQ(format::decodeMetadata(empty, &geo), format::Decoded::kOk);
  EXPECT_TRUE(geo.crs.empty());
}

// A store written by the real writer, read back as bytes.
std::vector<uint8_t> writeKnownStore(const PyramidGeometry& g, const WriterOptions& options) {
  const auto dir = std::filesystem::temp_directory_path() /
                   ("clipstream_store_test_format_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "known.cst").string();
  std::unique_ptr<TileStoreWriter> writer;
  EXPECT_TRUE(TileStoreWriter::create(path, g, options, &writer).ok());
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        // Tile (0, 0) of level 0 is constant; the others vary per pixel.
        std::vector<uint8_t> pixels(g.tileBytes(), uint8_t(l * 16 + y * 4 + x));
        if (l > 0 || x > 0 || y > 0) {
          for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = uint8_t(pixels[i] + i * 7 + (i >> 9));
        }
        EncodedTile encoded;
        EXPECT_TRUE(encodeTile(g, options.encoding, {l, x, y}, pixels, &encoded).ok());
        EXPECT_TRUE(writer->write(std::move(encoded)).ok());
      }
    }
  }
  EXPECT_TRUE(writer->finish().ok());
  std::ifstream in(path, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), {});
  std::filesystem::remove_all(dir);
  return bytes;
}

// Long: one known store checked against docs/tile-store.md section by section, field by field,
// in the order the document lists them; it reads best as one walk through the file.
TEST(StoreFormat, KnownStoreHeaderMatchesTheDocumentedLayout) {
  PyramidGeometry g;
  // Values chosen so that no two neighbouring header fields hold the same
  // number: a swapped pair of offsets cannot pass unnoticed.
  ASSERT_TRUE(makePyramidGeometry(300, 200, 32, PixelFormat::kRGBA8, &g));
  ASSERT_EQ(g.levelCount(), 5u);  // 10x7, 5x4, 3x2, 2x1, 1x1 tiles
  WriterOptions options;
  options.encoding.compression = Compression::kZstd;
  options.encoding.zstd_level = 7;
  options.encoding.predictor = Predictor::kNone;
  options.encoding.filter = DownsampleFilter::kLanczos3;
  options.encoding.linear_light = true;
  options.geo.present = true;
  const double transform[6] = {500000.0, 10.0, 0.0, 4649776.0, 0.0, -10.0};
  std::copy(transform, transform + 6, options.geo.transform);
  options.geo.crs = "EPSG:32633";
  options.fsync = false;
  const std::vector<uint8_t> b = writeKnownStore(g, options);
  ASSERT_GE(b.size(), 136u);

  // docs/tile-store.md section 5, offset by offset.
  EXPECT_EQ(std::string(b.begin(), b.begin() + 8), "CLIPTILE");
  EXPECT_EQ(le32(b, 8), 2u);     // format_version
  EXPECT_EQ(le32(b, 12), 136u);  // header_bytes
  EXPECT_EQ(le64(b, 16), 300u);  // width_px
  EXPECT_EQ(le64(b, 24), 200u);  // height_px
  EXPECT_EQ(le32(b, 32), 32u);   // tile_px
  EXPECT_EQ(le32(b, 36), 4u);    // pixel_format RGBA8
  EXPECT_EQ(le32(b, 40), 5u);    // level_count
  EXPECT_EQ(le32(b, 44), 1u);    // compression zstd
  EXPECT_EQ(le32(b, 48), 7u);    // zstd_level
  EXPECT_EQ(le32(b, 52), 0u);    // predictor none
  EXPECT_EQ(le32(b, 56), 1u);    // filter lanczos3
  EXPECT_EQ(le32(b, 60), 3u);    // flags: linear_light | georeference
  EXPECT_EQ(le32(b, 64), 64u);   // page_tiles
  EXPECT_EQ(le32(b, 68), 16u);   // tile_entry_bytes
  const uint64_t table_offset = le64(b, 72), table_bytes = le64(b, 80);
  const uint64_t index_offset = le64(b, 88), index_bytes = le64(b, 96);
  const uint64_t metadata_offset = le64(b, 104), metadata_bytes = le64(b, 112);
  EXPECT_EQ(table_offset, index_offset + index_bytes);
  EXPECT_EQ(table_bytes, 5u * 64 + 8);
  EXPECT_EQ(metadata_offset, table_offset + table_bytes);
  EXPECT_EQ(metadata_bytes, 60u + options.geo.crs.size());
  EXPECT_EQ(le64(b, 120), b.size());  // file_bytes
  EXPECT_EQ(metadata_offset + metadata_bytes, b.size());
  EXPECT_EQ(le64(b, 128), format::checksum64(b.data(), 128));

  // The codec reads the same values...
  format::Header header;
  format::decodeHeader(b.data(), &header);
  EXPECT_EQ(header.width_px, 300u);
  EXPECT_EQ(header.level_count, 5u);
  EXPECT_EQ(header.zstd_level, 7);
  EXPECT_EQ(header.level_table_offset, table_offset);
  EXPECT_EQ(header.metadata_bytes, metadata_bytes);
  EXPECT_EQ(header.file_bytes, b.size());
  // ...and writes exactly the same bytes back.
  uint8_t again[format::kHeaderBytes];
  format::encodeHeader(header, again);
  EXPECT_EQ(std::memcmp(again, b.data(), sizeof again), 0);

  // Level table, section 6: level 0's payloads start right after the header,
  // the last directory ends where the level table starts.
  EXPECT_EQ(le64(b, table_offset + 32), 136u);  // level 0 payload_offset
  EXPECT_EQ(le64(b, table_offset + 0), 300u);   // level 0 width_px
  EXPECT_EQ(le64(b, table_offset + 8), 200u);   // level 0 height_px
  EXPECT_EQ(le32(b, table_offset + 16), 10u);   // level 0 tiles_x
  EXPECT_EQ(le32(b, table_offset + 20), 7u);    // level 0 tiles_y
  EXPECT_EQ(le32(b, table_offset + 24), 1u);    // level 0 pages_x
  EXPECT_EQ(le64(b, table_offset + 64 + 0), 150u);  // level 1 width_px
  const uint64_t last = table_offset + 4 * 64;
  EXPECT_EQ(le64(b, last + 32) + le64(b, last + 40), index_offset);  // payloads end at the index
  EXPECT_EQ(le64(b, last + 48) + le64(b, last + 56), table_offset);  // directories end at the table
  const std::vector<uint8_t> table_block = slice(b, table_offset, table_bytes);
  std::vector<format::LevelEntry> levels;
  ASSERT_EQ(format::decodeLevelTable(table_block, &levels), format::Decoded::kOk);
  ASSERT_EQ(levels.size(), 5u);
  EXPECT_EQ(format::encodeLevelTable(levels), table_block);

  // Page directories (section 7) and index pages (section 8) re-encode to
  // the same bytes; level 0's page holds the constant tile (0, 0).
  for (size_t l = 0; l < levels.size(); ++l) {
    const std::vector<uint8_t> dir_block =
        slice(b, levels[l].directory_offset, levels[l].directory_bytes);
    std::vector<format::PageDirEntry> pages;
    ASSERT_EQ(format::decodePageDirectory(dir_block, &pages), format::Decoded::kOk) << l;
    EXPECT_EQ(format::encodePageDirectory(pages), dir_block) << l;
    ASSERT_EQ(pages.size(), 1u);
    ASSERT_EQ(pages[0].flags, 0u);
    EXPECT_EQ(le32(b, levels[l].directory_offset + 8), pages[0].bytes);
    const std::vector<uint8_t> page_block = slice(b, pages[0].offset, pages[0].bytes);
    std::vector<format::TileEntry> entries;
    ASSERT_EQ(format::decodeIndexPage(page_block, pages[0].checksum, format::kTileEntryBytes, &entries),
              format::Decoded::kOk);
    std::vector<uint8_t> page_again;
    EXPECT_EQ(format::encodeIndexPage(entries, format::kTileEntryBytes, &page_again), pages[0].checksum);
    EXPECT_EQ(page_again, page_block);
    ASSERT_EQ(entries.size(), size_t(g.levels[l].tiles_x) * g.levels[l].tiles_y);
    if (l == 0) {
      EXPECT_EQ(le32(b, pages[0].offset + 8), 0u);  // stored_bytes 0: constant
      EXPECT_EQ(entries[0].stored_bytes, 0u);
      EXPECT_EQ(entries[0].offset_or_value, 0u);  // value 0 in all four channels
      EXPECT_EQ(entries[1].offset_or_value, 0u);  // the first payload, relative offset 0
      EXPECT_GT(entries[1].stored_bytes, 0u);
    }
  }

  // Metadata block, section 10.
  EXPECT_EQ(le32(b, metadata_offset + 48), options.geo.crs.size());
  EXPECT_EQ(std::string(b.begin() + metadata_offset + 52,
                        b.begin() + metadata_offset + 52 + options.geo.crs.size()),
            options.geo.crs);
  double origin_x = 0;
  std::memcpy(&origin_x, b.data() + metadata_offset, 8);
  EXPECT_EQ(origin_x, 500000.0);
  const std::vector<uint8_t> meta_block = slice(b, metadata_offset, metadata_bytes);
  GeoReference geo;
  ASSERT_EQ(format::decodeMetadata(meta_block, &geo), format::Decoded::kOk);
  EXPECT_EQ(format::encodeMetadata(geo.transform, geo.crs), meta_block);
}

}  // namespace
}  // namespace clipstream
