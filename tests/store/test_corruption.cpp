// Bad bytes on disk: every truncated prefix and seeded single-byte flips
// must be reported as a Status, never as a crash or wrong pixels.
#include <clipstream/store/tile_store.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <span>

namespace clipstream {
namespace {

using test::writeBytes;

// Opens `path` and reads + decodes every tile. Returns ok only if all of
// that succeeded; any pixel mismatch against the synthetic pattern is
// reported through *wrong_pixels (the one outcome that must never happen).
Status openAndReadAll(const std::string& path, const PyramidGeometry& g, bool* wrong_pixels,
                      bool also_verify_all = true) {
  std::unique_ptr<TileStoreReader> reader;
  Status status = TileStoreReader::open(path, &reader);
  if (!status) return status;
  Status first_failure;
  std::vector<uint8_t> pixels;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        const TileKey key{l, x, y};
        status = reader->readTile(key, &pixels);
        if (!status) {
          if (first_failure.ok()) first_failure = status;
          continue;
        }
        if (pixels != test::syntheticTile(g, key)) *wrong_pixels = true;
      }
    }
  }
  if (!also_verify_all) return first_failure;
  // verifyAll must agree with the per-tile reads.
  std::vector<TileStoreReader::Problem> problems;
  const Status verify = reader->verifyAll(&problems, 1000, {}, 2);
  EXPECT_EQ(verify.ok(), first_failure.ok()) << verify.toString();
  return first_failure;
}

class StoreCorruption : public ::testing::Test {
 protected:
  void SetUp() override {
    m_path = m_dir.file("small.cst");
    // Several levels, partial edge pages, constant and non-constant tiles,
    // a georeference: every structure of the format is present.
    ASSERT_TRUE(makePyramidGeometry(150, 70, 16, PixelFormat::kRGB8, &m_geometry));
    WriterOptions options;
    options.fsync = false;
    options.geo.present = true;
    options.geo.crs = "EPSG:2992";
    options.geo.transform[0] = 100.0;
    ASSERT_TRUE(test::writeSyntheticStore(m_path, m_geometry, options).ok());
    m_bytes = test::readBytes(m_path);
    ASSERT_GT(m_bytes.size(), 1000u);
    m_damaged = m_dir.file("damaged.cst");
  }

  test::TempDir m_dir{"corruption"};
  std::string m_path;
  std::string m_damaged;
  PyramidGeometry m_geometry;
  std::vector<uint8_t> m_bytes;
};

TEST_F(StoreCorruption, EveryTruncatedPrefixFailsToOpenWithAMessage) {
  bool wrong_pixels = false;
  ASSERT_TRUE(openAndReadAll(m_path, m_geometry, &wrong_pixels).ok());
  for (size_t length = 0; length < m_bytes.size(); ++length) {
    writeBytes(m_damaged, std::span(m_bytes).first(length));
    std::unique_ptr<TileStoreReader> reader;
    const Status status = TileStoreReader::open(m_damaged, &reader);
    ASSERT_FALSE(status.ok()) << "prefix of " << length << " bytes opened";
    EXPECT_EQ(reader, nullptr);
    EXPECT_FALSE(status.message.empty());
    // Every prefix that still has the magic is reported as truncated.
    if (length >= 8) {
      EXPECT_EQ(status.code, ErrorCode::kTruncated) << length << ": " << status.toString();
    }
  }
}

TEST_F(StoreCorruption, EverySingleByteFlipIsDetected) {
  std::mt19937 rng(20240611);
  // Every byte of the header and of the tail (index pages, directories,
  // level table, metadata: from the index offset recorded at header byte 88
  // to the end) is flipped once; then random flips land anywhere, mostly in
  // payloads. ThreadSanitizer builds run fewer random flips: the loop is
  // single-threaded and ten times slower there.
  uint64_t index_offset = 0;
  std::memcpy(&index_offset, m_bytes.data() + 88, 8);
  const size_t header_bytes = 136, tail_bytes = m_bytes.size() - size_t(index_offset);
#if defined(__SANITIZE_THREAD__)
  const int kRandomFlips = 300;
#else
  const int kRandomFlips = 2000;
#endif
  const int kFlips = int(header_bytes + tail_bytes) + kRandomFlips;
  int detected_at_open = 0, detected_at_read = 0;
  std::vector<uint8_t> bytes;
  for (int i = 0; i < kFlips; ++i) {
    size_t position = rng() % m_bytes.size();
    if (size_t(i) < header_bytes) {
      position = size_t(i);
    } else if (size_t(i) < header_bytes + tail_bytes) {
      position = size_t(index_offset) + (size_t(i) - header_bytes);
    }
    const uint8_t mask = uint8_t(1u << (rng() % 8)) | uint8_t(rng() & 0xff);
    bytes = m_bytes;
    bytes[position] ^= mask;
    writeBytes(m_damaged, bytes);
    bool wrong_pixels = false;
    std::unique_ptr<TileStoreReader> reader;
    const Status open_status = TileStoreReader::open(m_damaged, &reader);
    if (!open_status) {
      ++detected_at_open;
      EXPECT_FALSE(open_status.message.empty());
      continue;
    }
    reader.reset();
    // verifyAll (which starts threads) is cross-checked on every 8th flip
    // to keep the test quick under ThreadSanitizer.
    const Status status = openAndReadAll(m_damaged, m_geometry, &wrong_pixels, i % 8 == 0);
    ASSERT_FALSE(wrong_pixels) << "flip at byte " << position << " gave wrong pixels";
    ASSERT_FALSE(status.ok()) << "flip at byte " << position << " (mask " << int(mask)
                                << ") went undetected";
    ++detected_at_read;
  }
  EXPECT_EQ(detected_at_open + detected_at_read, kFlips);
  // Both paths must have been exercised (payloads and structures).
  EXPECT_GT(detected_at_open, 0);
  EXPECT_GT(detected_at_read, 0);
}

TEST_F(StoreCorruption, FlippedPayloadNamesTheTile) {
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(m_path, &reader).ok());
  TileLocation location;
  TileKey key{0, 2, 1};
  ASSERT_FALSE(test::isConstantTile(key));
  ASSERT_TRUE(reader->locate(key, &location).ok());
  ASSERT_FALSE(location.constant);
  reader.reset();
  std::vector<uint8_t> bytes = m_bytes;
  bytes[location.offset + location.stored_bytes / 2] ^= 0x40;
  writeBytes(m_damaged, bytes);
  ASSERT_TRUE(TileStoreReader::open(m_damaged, &reader).ok());
  std::vector<uint8_t> pixels;
  const Status status = reader->readTile(key, &pixels);
  EXPECT_EQ(status.code, ErrorCode::kCorruptTile);
  EXPECT_NE(status.message.find("level 0 tile (2, 1)"), std::string::npos) << status.message;
  std::vector<TileStoreReader::Problem> problems;
  EXPECT_EQ(reader->verifyAll(&problems, 100, {}, 3).code, ErrorCode::kCorruptTile);
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_EQ(problems[0].key, key);
  // Neighbours still read.
  EXPECT_TRUE(reader->readTile(TileKey{0, 3, 1}, &pixels).ok());
}

TEST_F(StoreCorruption, CorruptIndexPageFailsEveryTileOfThatPageOnly) {
  uint64_t index_offset = 0;
  std::memcpy(&index_offset, m_bytes.data() + 88, 8);
  std::vector<uint8_t> bytes = m_bytes;
  bytes[index_offset + 3] ^= 0x01;  // inside the first index page written
  writeBytes(m_damaged, bytes);
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(m_damaged, &reader).ok());  // pages load lazily
  std::vector<TileStoreReader::Problem> problems;
  const Status status = reader->verifyAll(&problems, 1000, {}, 2);
  EXPECT_EQ(status.code, ErrorCode::kCorruptIndex) << status.toString();
  ASSERT_FALSE(problems.empty());
  // Every tile of the level's single page (levels here are < 64 tiles a
  // side) fails, and nothing else does.
  const uint32_t level = problems[0].key.level;
  EXPECT_EQ(problems.size(),
            size_t(m_geometry.levels[level].tiles_x) * m_geometry.levels[level].tiles_y);
  for (const auto& problem : problems) {
    EXPECT_EQ(problem.key.level, level);
    EXPECT_EQ(problem.status.code, ErrorCode::kCorruptIndex);
    EXPECT_NE(problem.status.message.find("checksum mismatch"), std::string::npos);
  }
  std::vector<LevelStats> stats;
  EXPECT_EQ(reader->levelStats(&stats).code, ErrorCode::kCorruptIndex);
}

TEST_F(StoreCorruption, WrongMagicVersionAndTrailingBytesAreNamed) {
  std::vector<uint8_t> bytes = m_bytes;
  bytes[0] = 'X';
  writeBytes(m_damaged, bytes);
  std::unique_ptr<TileStoreReader> reader;
  EXPECT_EQ(TileStoreReader::open(m_damaged, &reader).code, ErrorCode::kBadMagic);
  bytes = m_bytes;
  bytes[8] = 3;  // version field: one this reader does not know
  writeBytes(m_damaged, bytes);
  EXPECT_EQ(TileStoreReader::open(m_damaged, &reader).code, ErrorCode::kBadVersion);
  bytes = m_bytes;
  bytes.push_back(0);
  writeBytes(m_damaged, bytes);
  const Status status = TileStoreReader::open(m_damaged, &reader);
  EXPECT_EQ(status.code, ErrorCode::kBadHeader);
  EXPECT_NE(status.message.find("after the end"), std::string::npos) << status.message;
  EXPECT_EQ(TileStoreReader::open(m_dir.file("absent.cst"), &reader).code,
            ErrorCode::kNotFound);
}

TEST_F(StoreCorruption, VersionIsReportedFromTheFirstTwelveBytes) {
  // Magic and version are all a reader needs to say "a newer format": a
  // 12-byte prefix of a version-3 file is kBadVersion, not kTruncated.
  std::vector<uint8_t> bytes(m_bytes.begin(), m_bytes.begin() + 12);
  bytes[8] = 3;
  writeBytes(m_damaged, bytes);
  std::unique_ptr<TileStoreReader> reader;
  Status status = TileStoreReader::open(m_damaged, &reader);
  EXPECT_EQ(status.code, ErrorCode::kBadVersion) << status.toString();
  writeBytes(m_damaged, std::span(bytes).first(11));
  status = TileStoreReader::open(m_damaged, &reader);
  EXPECT_EQ(status.code, ErrorCode::kTruncated) << status.toString();
}

TEST_F(StoreCorruption, DirectoryIsNamedAsADirectory) {
  std::unique_ptr<TileStoreReader> reader;
  const Status status = TileStoreReader::open(m_dir.path().string(), &reader);
  EXPECT_EQ(status.code, ErrorCode::kIo);
  EXPECT_NE(status.message.find("is a directory"), std::string::npos) << status.message;
  EXPECT_EQ(reader, nullptr);
}

}  // namespace
}  // namespace clipstream
