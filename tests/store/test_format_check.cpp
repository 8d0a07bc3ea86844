// The checks between a store's records (store/src/format_check.h), on bytes
// alone: the writer's real output passes every check in the order the
// reader makes them, and each kind of corruption made on those bytes gives
// its own code and message. Most corruptions are resealed (their checksum
// recomputed, or the record re-encoded) so that the check behind the
// checksum is the one that must catch them. Messages are compared whole:
// the reader reports them word for word after the store's path.
#include "format.h"        // private: the record codec, to re-encode damaged records
#include "format_check.h"  // private: the checks under test

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <span>
#include <string>
#include <vector>

namespace clipstream {
namespace {

using format::CheckedHeader;
using format::IndexLayout;

// The first min(size, kHeaderBytes) bytes: what the reader hands checkHeader().
std::span<const uint8_t> headerPrefix(const std::vector<uint8_t>& bytes) {
  return std::span(bytes).first(std::min<size_t>(bytes.size(), format::kHeaderBytes));
}

std::span<const uint8_t> region(const std::vector<uint8_t>& bytes, uint64_t offset, uint64_t size) {
  EXPECT_LE(offset + size, bytes.size());
  return std::span(bytes).subspan(size_t(offset), size_t(size));
}

// A checksummed block (level table, directory, metadata) with its checksum
// recomputed after a change.
void resealBlock(std::vector<uint8_t>* block) {
  const size_t body = block->size() - format::kChecksumBytes;
  format::put64(block->data() + body, format::checksum64(block->data(), body));
}

void expectError(const Status& status, ErrorCode code, const std::string& message,
                 const std::string& what = "") {
  EXPECT_EQ(status.code, code) << what << ": " << status.toString() << ", expected "
                               << errorCodeName(code);
  EXPECT_EQ(status.message, message) << what;
}

// Everything the reader checks at open, run over a whole store in memory in
// the reader's order; the first failure, or the layout and directories.
struct Opened {
  CheckedHeader header;
  IndexLayout layout;
  std::vector<std::vector<format::PageDirEntry>> directories;
  StoreInfo info;
};
Status checkAll(const std::vector<uint8_t>& bytes, Opened* out) {
  Status status = format::checkHeader(headerPrefix(bytes), bytes.size(), &out->header);
  if (!status) return status;
  const format::Header& h = out->header.fields;
  status = format::checkLevelTable(region(bytes, h.level_table_offset, h.level_table_bytes),
                                   out->header, &out->layout);
  if (!status) return status;
  out->directories.resize(h.level_count);
  for (uint32_t l = 0; l < h.level_count; ++l) {
    uint64_t offset = 0;
    status = format::checkDirectoryPlace(out->layout, l, &offset);
    if (!status) return status;
    status = format::checkPageDirectory(
        region(bytes, offset, out->layout.levels[l].directory_bytes), out->header, out->layout, l,
        &out->directories[l]);
    if (!status) return status;
  }
  return format::checkMetadata(region(bytes, h.metadata_offset, h.metadata_bytes), out->header,
                               &out->info);
}

// A real store: 150 x 70 RGB8 in 16-px tiles (levels of 10 x 5 down to
// 1 x 1 tiles), some tiles constant, a georeference.
class FormatCheck : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(makePyramidGeometry(150, 70, 16, PixelFormat::kRGB8, &m_geometry));
    WriterOptions options;
    options.fsync = false;
    options.geo.present = true;
    options.geo.crs = "EPSG:2992";
    options.geo.transform[0] = 100.0;
    const std::string path = m_dir.file("store.cst");
    ASSERT_TRUE(test::writeSyntheticStore(path, m_geometry, options).ok());
    m_bytes = test::readBytes(path);
    ASSERT_TRUE(checkAll(m_bytes, &m_good).ok());
    format::decodeHeader(m_bytes.data(), &m_fields);
  }

  // checkHeader() on the store's header after `change`, resealed; the file
  // is taken to be as long as the changed header says.
  Status changedHeader(const std::function<void(format::Header&)>& change,
                       CheckedHeader* out = nullptr) const {
    format::Header fields = m_fields;
    change(fields);
    std::vector<uint8_t> bytes(format::kHeaderBytes);
    format::encodeHeader(fields, bytes.data());
    CheckedHeader ignored;
    return format::checkHeader(bytes, fields.file_bytes, out != nullptr ? out : &ignored);
  }

  std::span<const uint8_t> tableBytes() const {
    return region(m_bytes, m_fields.level_table_offset, m_fields.level_table_bytes);
  }

  // checkLevelTable() on the store's level table after `change`, re-encoded.
  Status changedTable(const std::function<void(std::vector<format::LevelEntry>&)>& change,
                      IndexLayout* out, const CheckedHeader* header = nullptr) const {
    std::vector<format::LevelEntry> entries = m_good.layout.levels;
    change(entries);
    return format::checkLevelTable(format::encodeLevelTable(entries),
                                   header != nullptr ? *header : m_good.header, out);
  }

  // checkPageDirectory() on level 0's directory after `change`, re-encoded.
  Status changedDirectory(const std::function<void(format::PageDirEntry&)>& change) const {
    std::vector<format::PageDirEntry> entries = m_good.directories[0];
    change(entries[0]);
    std::vector<format::PageDirEntry> out;
    return format::checkPageDirectory(format::encodePageDirectory(entries), m_good.header,
                                      m_good.layout, 0, &out);
  }

  // Level 0's only index page, as stored.
  std::span<const uint8_t> pageBytes() const {
    const format::PageDirEntry& dir = m_good.directories[0][0];
    return region(m_bytes, dir.offset, dir.bytes);
  }

  // checkIndexPage() on level 0's page after `change` to its entries,
  // re-encoded with the checksum the directory would then hold.
  Status changedPage(const std::function<void(std::vector<format::TileEntry>&)>& change) const {
    std::vector<format::TileEntry> entries;
    const format::PageDirEntry& dir = m_good.directories[0][0];
    EXPECT_EQ(format::decodeIndexPage(pageBytes(), dir.checksum, format::kTileEntryBytes, &entries),
              format::Decoded::kOk);
    change(entries);
    std::vector<uint8_t> page;
    const uint64_t checksum = format::encodeIndexPage(entries, format::kTileEntryBytes, &page);
    std::vector<format::TileEntry> out;
    return format::checkIndexPage(page, m_good.header, 0, 0, 0, checksum,
                                  m_good.layout.levels[0].payload_bytes, &out);
  }

  test::TempDir m_dir{"format-check"};
  PyramidGeometry m_geometry;
  std::vector<uint8_t> m_bytes;
  format::Header m_fields;
  Opened m_good;
};

TEST_F(FormatCheck, TheWritersStorePassesEveryCheckAndReadsBackAsWritten) {
  const CheckedHeader& h = m_good.header;
  EXPECT_EQ(h.fields.file_bytes, m_bytes.size());
  EXPECT_EQ(h.geometry.width_px, 150u);
  EXPECT_EQ(h.geometry.height_px, 70u);
  EXPECT_EQ(h.geometry.tile_px, 16u);
  EXPECT_EQ(h.geometry.format, PixelFormat::kRGB8);
  ASSERT_EQ(h.geometry.levelCount(), m_geometry.levelCount());
  EXPECT_EQ(h.encoding.compression, Compression::kZstd);
  EXPECT_EQ(h.encoding.predictor, Predictor::kLeftDelta);
  EXPECT_FALSE(h.elevation);
  EXPECT_FALSE(h.shard);
  EXPECT_TRUE(h.geo_present);
  EXPECT_EQ(h.entry_bytes, format::kTileEntryBytes);
  EXPECT_EQ(h.max_stored_bytes, format::maxStoredBytes(m_geometry.tileBytes(), Compression::kZstd));

  // The level table lays the payloads from the header's end to the index,
  // and the directories after the index pages.
  const IndexLayout& layout = m_good.layout;
  ASSERT_EQ(layout.levels.size(), m_geometry.levelCount());
  EXPECT_EQ(layout.levels[0].payload_offset, format::kHeaderBytes);
  EXPECT_EQ(layout.pages_begin, m_fields.index_offset);
  uint64_t directories = 0;
  for (uint32_t l = 0; l < layout.levels.size(); ++l) {
    EXPECT_EQ(layout.levels[l].tiles_x, m_geometry.levels[l].tiles_x) << l;
    EXPECT_EQ(layout.levels[l].tiles_y, m_geometry.levels[l].tiles_y) << l;
    uint64_t offset = 0;
    ASSERT_TRUE(format::checkDirectoryPlace(layout, l, &offset).ok());
    EXPECT_EQ(offset, layout.levels[l].directory_offset) << l;
    directories += layout.levels[l].directory_bytes;
  }
  EXPECT_EQ(layout.pages_end, m_fields.level_table_offset - directories);

  EXPECT_TRUE(m_good.info.geo.present);
  EXPECT_EQ(m_good.info.geo.crs, "EPSG:2992");
  EXPECT_EQ(m_good.info.geo.transform[0], 100.0);

  // Every index page passes and holds one entry per tile it covers.
  size_t pages = 0;
  for (uint32_t l = 0; l < layout.levels.size(); ++l) {
    for (const format::PageDirEntry& dir : m_good.directories[l]) {
      if (dir.flags & format::kPageFlagConstant) continue;
      std::vector<format::TileEntry> entries;
      const Status status =
          format::checkIndexPage(region(m_bytes, dir.offset, dir.bytes), h, l, 0, 0, dir.checksum,
                                 layout.levels[l].payload_bytes, &entries);
      ASSERT_TRUE(status.ok()) << status.toString();
      EXPECT_EQ(entries.size(),
                size_t(m_geometry.levels[l].tiles_x) * m_geometry.levels[l].tiles_y);
      ++pages;
    }
  }
  EXPECT_GT(pages, 0u);
}

TEST_F(FormatCheck, EveryPrefixOfTheHeaderIsTruncated) {
  for (size_t length = 0; length <= format::kHeaderBytes; ++length) {
    const std::vector<uint8_t> prefix(m_bytes.begin(), m_bytes.begin() + length);
    CheckedHeader out;
    const Status status = format::checkHeader(prefix, length, &out);
    EXPECT_EQ(status.code, ErrorCode::kTruncated) << length << ": " << status.toString();
  }
  CheckedHeader out;
  expectError(format::checkHeader({}, 5, &out), ErrorCode::kTruncated,
              "file is 5 bytes, too short to be a tile store");
  expectError(format::checkHeader(headerPrefix(m_bytes).first(10), 10, &out),
              ErrorCode::kTruncated, "file ends inside the header");
  expectError(format::checkHeader(headerPrefix(m_bytes).first(100), 100, &out),
              ErrorCode::kTruncated, "file is 100 bytes, shorter than the 136-byte header");
  // A whole header of a file shorter than it says.
  expectError(format::checkHeader(headerPrefix(m_bytes), m_bytes.size() - 1, &out),
              ErrorCode::kTruncated,
              "file is " + std::to_string(m_bytes.size() - 1) + " bytes, the header says " +
                  std::to_string(m_bytes.size()));
}

TEST_F(FormatCheck, BadMagicAndUnknownVersionsAreNamedBeforeTheChecksum) {
  std::vector<uint8_t> bytes(headerPrefix(m_bytes).begin(), headerPrefix(m_bytes).end());
  CheckedHeader out;
  bytes[3] = 'X';
  expectError(format::checkHeader(bytes, m_bytes.size(), &out), ErrorCode::kBadMagic,
              "not a clipstream tile store (bad magic)");
  // Even a file too short for the version is judged by its magic first.
  expectError(format::checkHeader(std::span(bytes).first(10), 10, &out), ErrorCode::kBadMagic,
              "not a clipstream tile store (bad magic)");
  bytes[3] = m_bytes[3];
  for (const uint32_t version : {0u, 3u, 0xFFFFFFFFu}) {
    format::put32(bytes.data() + format::kOffVersion, version);  // not resealed
    expectError(format::checkHeader(bytes, m_bytes.size(), &out), ErrorCode::kBadVersion,
                "format version " + std::to_string(version) +
                    " (this reader knows versions 1 to 2)");
  }
}

TEST_F(FormatCheck, EveryFlippedHeaderByteIsRefused) {
  for (size_t i = 0; i < format::kHeaderBytes; ++i) {
    std::vector<uint8_t> bytes(headerPrefix(m_bytes).begin(), headerPrefix(m_bytes).end());
    bytes[i] ^= 0x20;
    CheckedHeader out;
    const Status status = format::checkHeader(bytes, m_bytes.size(), &out);
    ASSERT_FALSE(status.ok()) << "byte " << i;
    const ErrorCode expected = i < format::kMagicEndBytes     ? ErrorCode::kBadMagic
                               : i < format::kVersionEndBytes ? ErrorCode::kBadVersion
                                                              : ErrorCode::kBadHeader;
    EXPECT_EQ(status.code, expected) << "byte " << i << ": " << status.toString();
    if (expected == ErrorCode::kBadHeader) {
      EXPECT_EQ(status.message, "header checksum mismatch") << "byte " << i;
    }
  }
}

TEST_F(FormatCheck, TheFileMustEndExactlyWhereTheHeaderSays) {
  CheckedHeader out;
  expectError(format::checkHeader(headerPrefix(m_bytes), m_bytes.size() + 3, &out),
              ErrorCode::kBadHeader, "file has 3 bytes after the end the header records");
}

TEST_F(FormatCheck, EachBadHeaderFieldIsNamed) {
  const uint32_t i16 = static_cast<uint32_t>(PixelFormat::kI16);
  const uint64_t index_end = m_fields.index_offset + m_fields.index_bytes;
  const uint64_t metadata_max = format::metadataBytes(format::kMaxCrsBytes);
  struct Case {
    const char* what;
    std::function<void(format::Header&)> change;
    ErrorCode code;
    std::string message;
  };
  const Case cases[] = {
      {"header size", [](format::Header& h) { h.header_bytes = 128; }, ErrorCode::kBadHeader,
       "header size field is not 136"},
      {"tile too small", [](format::Header& h) { h.tile_px = 8; }, ErrorCode::kBadHeader,
       "tile size 8 outside 16..4096"},
      {"tile too large", [](format::Header& h) { h.tile_px = 8192; }, ErrorCode::kBadHeader,
       "tile size 8192 outside 16..4096"},
      {"pixel format", [](format::Header& h) { h.pixel_format = 99; }, ErrorCode::kUnsupported,
       "unknown pixel format 99"},
      {"heights in version 1",
       [&](format::Header& h) {
         h.format_version = 1;
         h.pixel_format = i16;
       },
       ErrorCode::kUnsupported, "unknown pixel format " + std::to_string(i16)},
      {"compression", [](format::Header& h) { h.compression = 2; }, ErrorCode::kUnsupported,
       "unknown compression 2"},
      {"predictor", [](format::Header& h) { h.predictor = 2; }, ErrorCode::kUnsupported,
       "unknown predictor 2"},
      {"filter", [](format::Header& h) { h.filter = 3; }, ErrorCode::kBadHeader,
       "unknown filter 3"},
      {"decimate in version 1",
       [](format::Header& h) {
         h.format_version = 1;
         h.filter = 2;
       },
       ErrorCode::kBadHeader, "unknown filter 2"},
      {"unknown flag", [](format::Header& h) { h.flags |= 1u << 4; }, ErrorCode::kBadHeader,
       "unknown header flags"},
      {"elevation in version 1",
       [](format::Header& h) {
         h.format_version = 1;
         h.flags |= format::kFlagElevation;
       },
       ErrorCode::kBadHeader, "unknown header flags"},
      {"heights in colour", [](format::Header& h) { h.flags |= format::kFlagElevation; },
       ErrorCode::kBadHeader, "pixel format RGB8 cannot hold heights"},
      {"colour format for heights", [&](format::Header& h) { h.pixel_format = i16; },
       ErrorCode::kBadHeader, "pixel format I16 is for elevation stores only"},
      {"page tiles", [](format::Header& h) { h.page_tiles = 32; }, ErrorCode::kBadHeader,
       "index page shape is not 64 tiles of 16 bytes"},
      {"entry bytes", [](format::Header& h) { h.tile_entry_bytes = 32; }, ErrorCode::kBadHeader,
       "index page shape is not 64 tiles of 16 bytes"},
      {"zero width", [](format::Header& h) { h.width_px = 0; }, ErrorCode::kBadHeader,
       "image size 0x70 is not representable"},
      {"level count", [](format::Header& h) { h.level_count = 4; }, ErrorCode::kBadHeader,
       "level count 4 does not match the image size (expected 5)"},
      {"level table size", [](format::Header& h) { h.level_table_bytes += 64; },
       ErrorCode::kBadHeader, "level table size does not match the level count"},
      {"gap before the level table", [](format::Header& h) { h.index_bytes -= 1; },
       ErrorCode::kBadHeader, "region offsets in the header are inconsistent"},
      {"index over the header",
       [&](format::Header& h) {
         h.index_offset = 8;
         h.index_bytes = index_end - 8;
       },
       ErrorCode::kBadHeader, "region offsets in the header are inconsistent"},
      {"index wrapping past 2^64",
       [&](format::Header& h) {
         h.index_offset = std::numeric_limits<uint64_t>::max() - 7;
         h.index_bytes = index_end + 8;
       },
       ErrorCode::kBadHeader, "region offsets in the header are inconsistent"},
      {"metadata past the end", [](format::Header& h) { h.metadata_bytes += 1; },
       ErrorCode::kBadHeader, "region offsets in the header are inconsistent"},
      {"metadata before the level table's end", [](format::Header& h) { h.metadata_offset -= 1; },
       ErrorCode::kBadHeader, "region offsets in the header are inconsistent"},
      {"metadata too small",
       [](format::Header& h) {
         h.metadata_bytes = format::kMetadataFixedBytes - 1;
         h.file_bytes = h.metadata_offset + h.metadata_bytes;
       },
       ErrorCode::kBadHeader, "metadata block size out of range"},
      {"metadata too large",
       [&](format::Header& h) {
         h.metadata_bytes = metadata_max + 1;
         h.file_bytes = h.metadata_offset + h.metadata_bytes;
       },
       ErrorCode::kBadHeader, "metadata block size out of range"},
  };
  for (const Case& c : cases) expectError(changedHeader(c.change), c.code, c.message, c.what);
  // The same store, called version 1, is a valid version 1 store.
  EXPECT_TRUE(changedHeader([](format::Header& h) { h.format_version = 1; }).ok());
}

TEST_F(FormatCheck, EachBadLevelTableEntryIsNamed) {
  IndexLayout out;
  std::vector<uint8_t> flipped(tableBytes().begin(), tableBytes().end());
  flipped[70] ^= 0x01;
  expectError(format::checkLevelTable(flipped, m_good.header, &out), ErrorCode::kCorruptIndex,
              "level table checksum mismatch");
  const uint32_t last = m_geometry.levelCount() - 1;
  struct Case {
    const char* what;
    std::function<void(std::vector<format::LevelEntry>&)> change;
    std::string message;
  };
  const Case cases[] = {
      {"width", [](auto& e) { e[1].width_px += 1; },
       "level table entry 1: size does not match the pyramid rule"},
      {"tiles", [](auto& e) { e[3].tiles_y += 1; },
       "level table entry 3: size does not match the pyramid rule"},
      {"pages", [](auto& e) { e[2].pages_x += 1; },
       "level table entry 2: page grid does not match the tile grid"},
      {"payload gap", [](auto& e) { e[1].payload_offset += 1; },
       "level table entry 1: payload region out of place"},
      {"payload over the index",
       [](auto& e) { e[0].payload_bytes = std::numeric_limits<uint64_t>::max() - 100; },
       "level table entry 0: payload region out of place"},
      {"payloads short of the index", [&](auto& e) { e[last].payload_bytes -= 1; },
       "payload regions do not end where the index begins"},
      {"directory size", [](auto& e) { e[3].directory_bytes += format::kPageEntryBytes; },
       "level table entry 3: page directory size does not match"},
  };
  for (const Case& c : cases) {
    expectError(changedTable(c.change, &out), ErrorCode::kCorruptIndex, c.message, c.what);
  }

  // Directories larger than the index region: the header moves the index
  // start up (the level table stays put) and the last level's payloads grow
  // to meet it, so only the directories no longer fit.
  uint64_t directories = 0;
  for (const format::LevelEntry& e : m_good.layout.levels) directories += e.directory_bytes;
  const uint64_t shift = m_fields.index_bytes - (directories - 1);
  CheckedHeader moved;
  ASSERT_TRUE(changedHeader(
                  [&](format::Header& h) {
                    h.index_offset += shift;
                    h.index_bytes -= shift;
                  },
                  &moved)
                  .ok());
  expectError(changedTable([&](auto& e) { e[last].payload_bytes += shift; }, &out, &moved),
              ErrorCode::kCorruptIndex, "page directories larger than the index region");
}

TEST_F(FormatCheck, ADirectoryOutOfPlaceIsNamedBeforeItIsRead) {
  IndexLayout layout;
  ASSERT_TRUE(changedTable([](auto& e) { e[2].directory_offset += format::kPageEntryBytes; },
                           &layout)
                  .ok());  // the level table itself is well formed
  uint64_t offset = 0;
  EXPECT_TRUE(format::checkDirectoryPlace(layout, 1, &offset).ok());
  EXPECT_EQ(offset, m_good.layout.levels[1].directory_offset);
  expectError(format::checkDirectoryPlace(layout, 2, &offset), ErrorCode::kCorruptIndex,
              "level table entry 2: page directory out of place");
}

TEST_F(FormatCheck, EachBadPageDirectoryEntryIsNamed) {
  const format::LevelEntry& level0 = m_good.layout.levels[0];
  const std::span<const uint8_t> directory =
      region(m_bytes, level0.directory_offset, level0.directory_bytes);
  std::vector<uint8_t> flipped(directory.begin(), directory.end());
  flipped[5] ^= 0x01;
  std::vector<format::PageDirEntry> out;
  expectError(format::checkPageDirectory(flipped, m_good.header, m_good.layout, 0, &out),
              ErrorCode::kCorruptIndex, "page directory of level 0: checksum mismatch");

  const uint64_t pages_begin = m_good.layout.pages_begin, pages_end = m_good.layout.pages_end;
  const auto constant = [](format::PageDirEntry& e, uint64_t value) {
    e = format::PageDirEntry{};
    e.flags = format::kPageFlagConstant;
    e.constant_value = value;
  };
  // A constant page of an RGB8 store: three bytes of value at most.
  EXPECT_TRUE(changedDirectory([&](auto& e) { constant(e, 0xFFFFFF); }).ok());
  const std::string where = "index page (0, 0) of level 0: ";
  struct Case {
    const char* what;
    std::function<void(format::PageDirEntry&)> change;
    std::string message;
  };
  const Case cases[] = {
      {"unknown flag", [](auto& e) { e.flags = 2; }, where + "unknown flags"},
      {"constant page with a location", [](auto& e) { e.flags = format::kPageFlagConstant; },
       where + "malformed constant page entry"},
      {"constant value wider than a pixel", [&](auto& e) { constant(e, 0x1000000); },
       where + "malformed constant page entry"},
      {"constant page with a checksum",
       [&](auto& e) {
         constant(e, 1);
         e.checksum = 1;
       },
       where + "malformed constant page entry"},
      {"size not the page's tiles", [](auto& e) { e.bytes -= format::kTileEntryBytes; },
       where + "page location out of bounds"},
      {"value on a stored page", [](auto& e) { e.constant_value = 1; },
       where + "page location out of bounds"},
      {"before the index", [&](auto& e) { e.offset = pages_begin - 1; },
       where + "page location out of bounds"},
      {"over the directories", [&](auto& e) { e.offset = pages_end - e.bytes + 1; },
       where + "page location out of bounds"},
  };
  for (const Case& c : cases) {
    expectError(changedDirectory(c.change), ErrorCode::kCorruptIndex, c.message, c.what);
  }
}

TEST_F(FormatCheck, EachBadIndexPageEntryIsNamed) {
  const format::PageDirEntry& dir = m_good.directories[0][0];
  std::vector<format::TileEntry> out;
  std::vector<uint8_t> flipped(pageBytes().begin(), pageBytes().end());
  flipped[9] ^= 0x01;
  const uint64_t payload_bytes = m_good.layout.levels[0].payload_bytes;
  expectError(format::checkIndexPage(flipped, m_good.header, 0, 0, 0, dir.checksum, payload_bytes,
                                     &out),
              ErrorCode::kCorruptIndex, "index page (0, 0) of level 0: checksum mismatch");
  const std::vector<uint8_t> short_page(pageBytes().begin(), pageBytes().end() - 1);
  expectError(format::checkIndexPage(short_page, m_good.header, 0, 0, 0,
                                     format::checksum64(short_page.data(), short_page.size()),
                                     payload_bytes, &out),
              ErrorCode::kCorruptIndex, "index page (0, 0) of level 0: malformed entries");

  // Entry 13 is tile (3, 1) of the 10-tile-wide level 0; made a payload or
  // a constant as each case needs.
  const std::string bad =
      "index page (0, 0) of level 0: entry for level 0 tile (3, 1) is out of bounds";
  const auto stored = [](format::TileEntry& e, uint64_t offset, uint32_t bytes) {
    e = format::TileEntry{};
    e.offset_or_value = offset;
    e.stored_bytes = bytes;
    e.checksum = 7;
  };
  const size_t max_stored = m_good.header.max_stored_bytes;
  EXPECT_TRUE(changedPage([&](auto& e) { stored(e[13], payload_bytes - 10, 10); }).ok());
  struct Case {
    const char* what;
    std::function<void(std::vector<format::TileEntry>&)> change;
  };
  const Case cases[] = {
      {"larger than any tile", [&](auto& e) { stored(e[13], 0, uint32_t(max_stored + 1)); }},
      {"past the level's payloads", [&](auto& e) { stored(e[13], payload_bytes - 9, 10); }},
      {"offset wrapping past 2^64",
       [&](auto& e) { stored(e[13], std::numeric_limits<uint64_t>::max() - 3, 10); }},
      {"constant with a checksum",
       [](auto& e) {
         e[13] = format::TileEntry{};
         e[13].checksum = 1;
       }},
      {"constant wider than a pixel",
       [](auto& e) {
         e[13] = format::TileEntry{};
         e[13].offset_or_value = 0x1000000;
       }},
  };
  for (const Case& c : cases) {
    expectError(changedPage(c.change), ErrorCode::kCorruptIndex, bad, c.what);
  }
}

TEST_F(FormatCheck, MetadataChecksumAndCrsLengthAreNamed) {
  const std::span<const uint8_t> good =
      region(m_bytes, m_fields.metadata_offset, m_fields.metadata_bytes);
  std::vector<uint8_t> block(good.begin(), good.end());
  StoreInfo info;
  block[format::kMetaOffCrs] ^= 0x01;
  expectError(format::checkMetadata(block, m_good.header, &info), ErrorCode::kBadHeader,
              "metadata block checksum mismatch");
  block.assign(good.begin(), good.end());
  format::put32(block.data() + format::kMetaOffCrsBytes, 8);
  resealBlock(&block);
  expectError(format::checkMetadata(block, m_good.header, &info), ErrorCode::kBadHeader,
              "metadata CRS length does not match the block size");
  // Without the georeference flag the block still decodes; present says no.
  CheckedHeader no_geo = m_good.header;
  no_geo.geo_present = false;
  ASSERT_TRUE(format::checkMetadata(good, no_geo, &info).ok());
  EXPECT_FALSE(info.geo.present);
  EXPECT_EQ(info.geo.crs, "EPSG:2992");
}

TEST_F(FormatCheck, CallerMistakesAreInvalidArgumentsNotCorruption) {
  const CheckedHeader& h = m_good.header;
  CheckedHeader header_out;
  EXPECT_EQ(format::checkHeader(headerPrefix(m_bytes).first(100), m_bytes.size(), &header_out).code,
            ErrorCode::kInvalidArgument);
  IndexLayout layout;
  EXPECT_EQ(format::checkLevelTable(tableBytes().first(64), h, &layout).code,
            ErrorCode::kInvalidArgument);
  uint64_t offset = 0;
  EXPECT_EQ(format::checkDirectoryPlace(m_good.layout, 99, &offset).code,
            ErrorCode::kInvalidArgument);
  std::vector<format::PageDirEntry> directory;
  EXPECT_EQ(format::checkPageDirectory(tableBytes(), h, m_good.layout, 0, &directory).code,
            ErrorCode::kInvalidArgument);
  StoreInfo info;
  EXPECT_EQ(format::checkMetadata(tableBytes(), h, &info).code, ErrorCode::kInvalidArgument);
  std::vector<format::TileEntry> entries;
  EXPECT_EQ(format::checkIndexPage(pageBytes(), h, 0, 1, 0, 0, 0, &entries).code,
            ErrorCode::kInvalidArgument);
  EXPECT_EQ(format::checkIndexPage(pageBytes(), h, 99, 0, 0, 0, 0, &entries).code,
            ErrorCode::kInvalidArgument);
}

// Elevation and partial stores carry records the header announces; their
// values are checked against it.
class FormatCheckRecords : public ::testing::Test {
 protected:
  // The store at `path`, checked up to its metadata block, which is returned.
  std::vector<uint8_t> metadataOf(const std::string& path, Opened* opened) {
    m_bytes = test::readBytes(path);
    const Status status = checkAll(m_bytes, opened);
    EXPECT_TRUE(status.ok()) << status.toString();
    const format::Header& h = opened->header.fields;
    const std::span<const uint8_t> block = region(m_bytes, h.metadata_offset, h.metadata_bytes);
    return std::vector<uint8_t>(block.begin(), block.end());
  }

  test::TempDir m_dir{"format-check-records"};
  std::vector<uint8_t> m_bytes;
};

TEST_F(FormatCheckRecords, ElevationRecordAndHeightBoundsAreChecked) {
  const std::string path = m_dir.file("dem.cst");
  ASSERT_TRUE(test::writeElevationStore(path, 300, 200, [](uint64_t x, uint64_t y) {
                return float(x) - float(y);
              }).ok());
  Opened opened;
  const std::vector<uint8_t> good = metadataOf(path, &opened);
  ASSERT_TRUE(opened.header.elevation);
  EXPECT_EQ(opened.header.entry_bytes, format::kElevationTileEntryBytes);
  EXPECT_TRUE(opened.info.elevation.present);
  const size_t record = good.size() - format::kChecksumBytes - format::kElevationRecordBytes;
  StoreInfo info;

  std::vector<uint8_t> block = good;
  format::putF64(block.data() + record + format::kElevOffScale, 0.0);
  resealBlock(&block);
  expectError(format::checkMetadata(block, opened.header, &info), ErrorCode::kBadHeader,
              "elevation record: scale, offset or bounds out of range");
  block = good;
  format::putF64(block.data() + record + format::kElevOffMinHeight, std::nan(""));
  resealBlock(&block);
  expectError(format::checkMetadata(block, opened.header, &info), ErrorCode::kBadHeader,
              "elevation record: scale, offset or bounds out of range");
  block = good;
  format::put32(block.data() + record + format::kElevOffUnits, 9);
  resealBlock(&block);
  expectError(format::checkMetadata(block, opened.header, &info), ErrorCode::kBadHeader,
              "metadata block: CRS length does not match the block size, or the elevation record "
              "has unknown flags or units");

  // A tile whose height bounds are reversed, and an entry's reserved word.
  const format::PageDirEntry& dir = opened.directories[0][0];
  const uint64_t payload_bytes = opened.layout.levels[0].payload_bytes;
  std::vector<format::TileEntry> entries;
  const std::span<const uint8_t> page = region(m_bytes, dir.offset, dir.bytes);
  ASSERT_TRUE(format::checkIndexPage(page, opened.header, 0, 0, 0, dir.checksum, payload_bytes,
                                     &entries)
                  .ok());
  ASSERT_GE(entries.size(), 2u);
  entries[1].min_height = entries[1].max_height + 1.0f;
  std::vector<uint8_t> bytes;
  uint64_t checksum = format::encodeIndexPage(entries, format::kElevationTileEntryBytes, &bytes);
  std::vector<format::TileEntry> out;
  expectError(format::checkIndexPage(bytes, opened.header, 0, 0, 0, checksum, payload_bytes, &out),
              ErrorCode::kCorruptIndex,
              "index page (0, 0) of level 0: entry for level 0 tile (1, 0) is out of bounds");
  bytes.assign(page.begin(), page.end());
  format::put32(bytes.data() + format::kTileOffReserved, 1);
  checksum = format::checksum64(bytes.data(), bytes.size());
  expectError(format::checkIndexPage(bytes, opened.header, 0, 0, 0, checksum, payload_bytes, &out),
              ErrorCode::kCorruptIndex, "index page (0, 0) of level 0: malformed entries");
}

TEST_F(FormatCheckRecords, AShardRecordMustDescribeABandOfTheWholeImage) {
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(100, 60, 16, PixelFormat::kRGB8, &g));
  WriterOptions options;
  options.fsync = false;
  options.shard.present = true;
  options.shard.index = 1;
  options.shard.count = 2;
  options.shard.full_width_px = 100;
  options.shard.full_height_px = 120;
  options.shard.owned_levels = 1;
  const std::string path = m_dir.file("part.cst");
  ASSERT_TRUE(test::writeSyntheticStore(path, g, options).ok());
  Opened opened;
  const std::vector<uint8_t> good = metadataOf(path, &opened);
  ASSERT_TRUE(opened.header.shard);
  EXPECT_EQ(opened.info.shard.count, 2u);
  const size_t record = good.size() - format::kChecksumBytes - format::kShardRecordBytes;
  StoreInfo info;
  struct Case {
    const char* what;
    size_t offset;
    uint64_t value;
    int bytes;
    std::string message;
  };
  const std::string not_a_band = " does not describe a band of the whole image";
  const Case cases[] = {
      {"index 0", format::kShardOffIndex, 0, 4, "shard record: shard 0/2" + not_a_band},
      {"index above count", format::kShardOffIndex, 3, 4, "shard record: shard 3/2" + not_a_band},
      {"band past the bottom", format::kShardOffY0, 64, 8, "shard record: shard 1/2" + not_a_band},
      {"origin off the tile grid", format::kShardOffY0, 8, 8,
       "shard record: shard 1/2" + not_a_band},
      {"more levels than the store", format::kShardOffOwnedLevels, 9, 4,
       "shard record: shard 1/2" + not_a_band},
      {"reserved word", format::kShardOffReserved1, 1, 8,
       "metadata block: CRS length does not match the block size, or the shard record's reserved "
       "words are not 0"},
  };
  for (const Case& c : cases) {
    std::vector<uint8_t> block = good;
    if (c.bytes == 4) {
      format::put32(block.data() + record + c.offset, uint32_t(c.value));
    } else {
      format::put64(block.data() + record + c.offset, c.value);
    }
    resealBlock(&block);
    expectError(format::checkMetadata(block, opened.header, &info), ErrorCode::kBadHeader,
                c.message, c.what);
  }
}

}  // namespace
}  // namespace clipstream
