// Writer contract: atomic output, temporaries cleaned, clear failures.
#include "store_test_util.h"

#include "file_io.h"  // private: exercised directly for the disk-full path
#include "format.h"   // private: tile checksum for hand-made payloads

#include <fcntl.h>

#include <thread>

namespace clipstream {
namespace {

TEST(TileStoreWriter, MissingTileFailsFinishAndLeavesNoFile) {
  const auto dir = testutil::tempDir("missing");
  const std::string path = (dir / "out.cst").string();
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(100, 100, 16, PixelFormat::kR8, &g));
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(path, g, {}, &writer).isOk());
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        if (l == 1 && x == 2 && y == 3) continue;
        EncodedTile encoded;
        ASSERT_TRUE(encodeTile(g, {}, {l, x, y}, testutil::makeTile(g, {l, x, y}), &encoded).isOk());
        ASSERT_TRUE(writer->write(std::move(encoded)).isOk());
      }
    }
  }
  const Status status = writer->finish();
  EXPECT_EQ(status.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(status.message.find("level 1 tile (2, 3)"), std::string::npos) << status.message;
  EXPECT_TRUE(testutil::listDir(dir).empty());
  writer.reset();
  EXPECT_TRUE(testutil::listDir(dir).empty());
  std::filesystem::remove_all(dir);
}

TEST(TileStoreWriter, DestroyingUnfinishedWriterRemovesEveryTemporary) {
  const auto dir = testutil::tempDir("unfinished");
  const std::string path = (dir / "out.cst").string();
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(200, 200, 16, PixelFormat::kRGBA8, &g));
  {
    std::unique_ptr<TileStoreWriter> writer;
    ASSERT_TRUE(TileStoreWriter::create(path, g, {}, &writer).isOk());
    // Tiles on several levels so that spill files exist.
    for (uint32_t l = 0; l < g.levelCount(); ++l) {
      EncodedTile encoded;
      ASSERT_TRUE(encodeTile(g, {}, {l, 0, 0}, testutil::makeTile(g, {l, 0, 0}, false), &encoded).isOk());
      ASSERT_TRUE(writer->write(std::move(encoded)).isOk());
    }
    EXPECT_FALSE(testutil::listDir(dir).empty());
    for (const std::string& name : testutil::listDir(dir)) {
      EXPECT_EQ(name.rfind(".out.cst.tmp-", 0), 0u) << name;
    }
    EXPECT_FALSE(std::filesystem::exists(path));
  }
  EXPECT_TRUE(testutil::listDir(dir).empty());
  std::filesystem::remove_all(dir);
}

TEST(TileStoreWriter, MissingDirectoryIsNamed) {
  const auto dir = testutil::tempDir("nodir");
  const std::string missing = (dir / "no" / "such").string();
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 16, PixelFormat::kR8, &g));
  std::unique_ptr<TileStoreWriter> writer;
  const Status status = TileStoreWriter::create(missing + "/out.cst", g, {}, &writer);
  EXPECT_TRUE(status.code == ErrorCode::kNotFound || status.code == ErrorCode::kIo);
  EXPECT_NE(status.message.find(missing), std::string::npos) << status.message;
  EXPECT_EQ(writer, nullptr);
  std::filesystem::remove_all(dir);
}

TEST(TileStoreWriter, RejectsDuplicateTilesAndBadGeometry) {
  const auto dir = testutil::tempDir("dup");
  const std::string path = (dir / "out.cst").string();
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 16, PixelFormat::kR8, &g));
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(path, g, {}, &writer).isOk());
  EncodedTile a, b;
  ASSERT_TRUE(encodeTile(g, {}, {0, 1, 1}, testutil::makeTile(g, {0, 1, 1}), &a).isOk());
  b = a;
  EXPECT_TRUE(writer->write(std::move(a)).isOk());
  const Status status = writer->write(std::move(b));
  EXPECT_EQ(status.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(status.message.find("written twice"), std::string::npos);
  EncodedTile outside;
  outside.key = {0, 9, 0};
  EXPECT_EQ(writer->write(std::move(outside)).code, ErrorCode::kOutOfRange);
  writer.reset();

  PyramidGeometry bad = g;
  bad.tile_px = 8;
  EXPECT_EQ(TileStoreWriter::create(path, bad, {}, &writer).code, ErrorCode::kInvalidArgument);
  bad = g;
  bad.levels.pop_back();
  EXPECT_EQ(TileStoreWriter::create(path, bad, {}, &writer).code, ErrorCode::kInvalidArgument);
  EXPECT_TRUE(testutil::listDir(dir).empty());
  std::filesystem::remove_all(dir);
}

TEST(TileStoreWriter, RejectsAnUncompressedPayloadThatIsNotOneRawTile) {
  // The reader refuses any other size, so the writer must not store one.
  const auto dir = testutil::tempDir("short_raw");
  const std::string path = (dir / "out.cst").string();
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 16, PixelFormat::kRGB8, &g));
  WriterOptions options;
  options.encoding.compression = Compression::kNone;
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(path, g, options, &writer).isOk());
  EncodedTile encoded;
  ASSERT_TRUE(encodeTile(g, options.encoding, {0, 1, 1}, testutil::makeTile(g, {0, 1, 1}, false),
                         &encoded).isOk());
  ASSERT_EQ(encoded.payload.size(), g.tileBytes());
  EncodedTile shorter = encoded;
  shorter.payload.resize(g.tileBytes() - 3);
  shorter.location.stored_bytes = static_cast<uint32_t>(shorter.payload.size());
  shorter.location.checksum = format::tileChecksum(shorter.payload.data(), shorter.payload.size());
  EXPECT_EQ(writer->write(std::move(shorter)).code, ErrorCode::kInvalidArgument);
  // The slot was not taken: the real tile still goes in.
  EXPECT_TRUE(writer->write(std::move(encoded)).isOk());
  writer.reset();
  EXPECT_TRUE(testutil::listDir(dir).empty());
  std::filesystem::remove_all(dir);
}

TEST(TileStoreWriter, ConcurrentWritersInAnyOrderProduceAReadableStore) {
  const auto dir = testutil::tempDir("concurrent_write");
  const std::string path = (dir / "out.cst").string();
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(700, 500, 16, PixelFormat::kRGB8, &g));
  std::vector<TileKey> keys;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) keys.push_back({l, x, y});
    }
  }
  std::shuffle(keys.begin(), keys.end(), std::mt19937(3));
  std::unique_ptr<TileStoreWriter> writer;
  WriterOptions options;
  options.fsync = false;
  ASSERT_TRUE(TileStoreWriter::create(path, g, options, &writer).isOk());
  std::atomic<size_t> next{0};
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (size_t i; (i = next.fetch_add(1)) < keys.size();) {
        EncodedTile encoded;
        if (!encodeTile(g, options.encoding, keys[i], testutil::makeTile(g, keys[i]), &encoded) ||
            !writer->write(std::move(encoded))) {
          failures.fetch_add(1);
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(failures.load(), 0);
  ASSERT_TRUE(writer->finish().isOk());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(path, &reader).isOk());
  std::vector<uint8_t> pixels;
  for (const TileKey& key : keys) {
    ASSERT_TRUE(reader->readTile(key, &pixels).isOk());
    ASSERT_EQ(pixels, testutil::makeTile(g, key));
  }
  std::filesystem::remove_all(dir);
}

TEST(TileStoreWriter, FinishReplacesAnExistingFileAtomically) {
  const auto dir = testutil::tempDir("replace");
  const std::string path = (dir / "out.cst").string();
  testutil::writeFile(path, std::vector<uint8_t>(10, 'x'), 10);
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(40, 40, 16, PixelFormat::kR8, &g));
  // Without `replace` an existing file is never touched.
  EXPECT_EQ(testutil::writeStore(path, g).code, ErrorCode::kAlreadyExists);
  EXPECT_EQ(testutil::readFile(path), std::vector<uint8_t>(10, 'x'));
  WriterOptions options;
  options.replace = true;
  ASSERT_TRUE(testutil::writeStore(path, g, options).isOk());
  std::unique_ptr<TileStoreReader> reader;
  EXPECT_TRUE(TileStoreReader::open(path, &reader).isOk());
  EXPECT_EQ(testutil::listDir(dir).size(), 1u);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace clipstream

namespace clipstream {
namespace {

TEST(TileStoreWriter, DiskFullBecomesNoSpaceNamingTheFile) {
  // /dev/full fails every write with ENOSPC: the same path the writer's
  // payload, spill and index writes all go through.
  const int fd = ::open("/dev/full", O_WRONLY | O_CLOEXEC);
  if (fd < 0) GTEST_SKIP() << "/dev/full not available";
  const std::vector<uint8_t> bytes(4096, 1);
  const Status status = fileio::pwriteAll(fd, bytes.data(), bytes.size(), 0, "/dev/full");
  ::close(fd);
  EXPECT_EQ(status.code, ErrorCode::kNoSpace);
  EXPECT_NE(status.message.find("no space left on device writing /dev/full"), std::string::npos)
      << status.message;
}

}  // namespace
}  // namespace clipstream
