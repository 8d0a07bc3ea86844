// Writer contract: atomic output, temporaries cleaned, clear failures.
#include <clipstream/util/file_io.h>  // private: exercised directly for the disk-full path
#include "format.h"   // private: tile checksum for hand-made payloads

#include <clipstream/store/tile_store.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <random>
#include <thread>

namespace clipstream {
namespace {

using test::ConstantTiles;
using test::syntheticTile;
using test::TempDir;

TEST(TileStoreWriter, MissingTileFailsFinishAndLeavesNoFile) {
  const TempDir dir("missing");
  const std::string path = dir.file("out.cst");
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(100, 100, 16, PixelFormat::kR8, &g));
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(path, g, {}, &writer).ok());
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) {
        if (l == 1 && x == 2 && y == 3) continue;
        EncodedTile encoded;
        ASSERT_TRUE(encodeTile(g, {}, {l, x, y}, syntheticTile(g, {l, x, y}), &encoded).ok());
        ASSERT_TRUE(writer->write(std::move(encoded)).ok());
      }
    }
  }
  const Status status = writer->finish();
  EXPECT_EQ(status.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(status.message.find("level 1 tile (2, 3)"), std::string::npos) << status.message;
  EXPECT_TRUE(dir.entries().empty());
  writer.reset();
  EXPECT_TRUE(dir.entries().empty());
}

TEST(TileStoreWriter, DestroyingUnfinishedWriterRemovesEveryTemporary) {
  const TempDir dir("unfinished");
  const std::string path = dir.file("out.cst");
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(200, 200, 16, PixelFormat::kRGBA8, &g));
  {
    std::unique_ptr<TileStoreWriter> writer;
    ASSERT_TRUE(TileStoreWriter::create(path, g, {}, &writer).ok());
    // Tiles on several levels so that spill files exist.
    for (uint32_t l = 0; l < g.levelCount(); ++l) {
      EncodedTile encoded;
      ASSERT_TRUE(encodeTile(g, {}, {l, 0, 0}, syntheticTile(g, {l, 0, 0}, ConstantTiles::kNone), &encoded).ok());
      ASSERT_TRUE(writer->write(std::move(encoded)).ok());
    }
    EXPECT_FALSE(dir.entries().empty());
    for (const std::string& name : dir.entries()) {
      EXPECT_EQ(name.rfind(".out.cst.tmp-", 0), 0u) << name;
    }
    EXPECT_FALSE(std::filesystem::exists(path));
  }
  EXPECT_TRUE(dir.entries().empty());
}

TEST(TileStoreWriter, MissingDirectoryIsNamed) {
  const TempDir dir("nodir");
  const std::string missing = dir.file("no/such");
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 16, PixelFormat::kR8, &g));
  std::unique_ptr<TileStoreWriter> writer;
  const Status status = TileStoreWriter::create(missing + "/out.cst", g, {}, &writer);
  EXPECT_TRUE(status.code == ErrorCode::kNotFound || status.code == ErrorCode::kIo);
  EXPECT_NE(status.message.find(missing), std::string::npos) << status.message;
  EXPECT_EQ(writer, nullptr);
}

TEST(TileStoreWriter, RejectsDuplicateTilesAndBadGeometry) {
  const TempDir dir("dup");
  const std::string path = dir.file("out.cst");
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 16, PixelFormat::kR8, &g));
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(path, g, {}, &writer).ok());
  EncodedTile a, b;
  ASSERT_TRUE(encodeTile(g, {}, {0, 1, 1}, syntheticTile(g, {0, 1, 1}), &a).ok());
  b = a;
  EXPECT_TRUE(writer->write(std::move(a)).ok());
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
  EXPECT_TRUE(dir.entries().empty());
}

TEST(TileStoreWriter, RejectsAnUncompressedPayloadThatIsNotOneRawTile) {
  // The reader refuses any other size, so the writer must not store one.
  const TempDir dir("short_raw");
  const std::string path = dir.file("out.cst");
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(64, 64, 16, PixelFormat::kRGB8, &g));
  WriterOptions options;
  options.encoding.compression = Compression::kNone;
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(path, g, options, &writer).ok());
  EncodedTile encoded;
  ASSERT_TRUE(encodeTile(g, options.encoding, {0, 1, 1}, syntheticTile(g, {0, 1, 1}, ConstantTiles::kNone),
                         &encoded).ok());
  ASSERT_EQ(encoded.payload.size(), g.tileBytes());
  EncodedTile shorter = encoded;
  shorter.payload.resize(g.tileBytes() - 3);
  shorter.location.stored_bytes = static_cast<uint32_t>(shorter.payload.size());
  shorter.location.checksum = format::tileChecksum(shorter.payload.data(), shorter.payload.size());
  EXPECT_EQ(writer->write(std::move(shorter)).code, ErrorCode::kInvalidArgument);
  // The slot was not taken: the real tile still goes in.
  EXPECT_TRUE(writer->write(std::move(encoded)).ok());
  writer.reset();
  EXPECT_TRUE(dir.entries().empty());
}

TEST(TileStoreWriter, ConcurrentWritersInAnyOrderProduceAReadableStore) {
  const TempDir dir("concurrent_write");
  const std::string path = dir.file("out.cst");
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
  ASSERT_TRUE(TileStoreWriter::create(path, g, options, &writer).ok());
  std::atomic<size_t> next{0};
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (size_t i; (i = next.fetch_add(1)) < keys.size();) {
        EncodedTile encoded;
        if (!encodeTile(g, options.encoding, keys[i], syntheticTile(g, keys[i]), &encoded) ||
            !writer->write(std::move(encoded))) {
          failures.fetch_add(1);
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(failures.load(), 0);
  ASSERT_TRUE(writer->finish().ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());
  std::vector<uint8_t> pixels;
  for (const TileKey& key : keys) {
    ASSERT_TRUE(reader->readTile(key, &pixels).ok());
    ASSERT_EQ(pixels, syntheticTile(g, key));
  }
}

// Counts the aligned squares of side x side tiles (over every level) whose
// stored payloads lie back to back in the file (*together) and those that do
// not (*apart); squares of constant tiles only are not counted.
void countAlignedSquares(const TileStoreReader& reader, uint32_t side, size_t* together, size_t* apart) {
  const PyramidGeometry& g = reader.geometry();
  *together = *apart = 0;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t by = 0; by + side <= g.levels[l].tiles_y; by += side) {
      for (uint32_t bx = 0; bx + side <= g.levels[l].tiles_x; bx += side) {
        uint64_t first = UINT64_MAX, end = 0, bytes = 0;
        for (uint32_t y = by; y < by + side; ++y) {
          for (uint32_t x = bx; x < bx + side; ++x) {
            TileLocation location;
            ASSERT_TRUE(reader.locate({l, x, y}, &location).ok());
            if (location.constant) continue;
            first = std::min(first, location.offset);
            end = std::max(end, location.offset + location.stored_bytes);
            bytes += location.stored_bytes;
          }
        }
        if (bytes == 0) continue;
        (end - first == bytes ? *together : *apart) += 1;
      }
    }
  }
}

// PayloadOrder::kCurve: the same tiles, the same reader, another layout:
// every aligned square of 2, 4 and 8 tiles lies in one stretch of the file
// (its payloads back to back), which the written order (row by row) does
// not give; every tile reads back as written, from shuffled concurrent
// writes too; the file is no larger.
TEST(TileStoreWriter, CurveOrderLaysAlignedSquaresTogetherAndReadsTheSameTiles) {
  const TempDir dir("curve_order");
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(1500, 1100, 16, PixelFormat::kRGB8, &g));  // 94 x 69 tiles
  std::vector<TileKey> keys;
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) keys.push_back({l, x, y});
  uint64_t written_bytes = 0;
  for (const PayloadOrder order : {PayloadOrder::kWritten, PayloadOrder::kCurve}) {
    SCOPED_TRACE(payloadOrderName(order));
    const std::string path = dir.file(std::string(payloadOrderName(order)) + ".cst");
    WriterOptions options;
    options.fsync = false;
    options.payload_order = order;
    ASSERT_TRUE(test::writeSyntheticStore(path, g, options).ok());
    std::unique_ptr<TileStoreReader> reader;
    ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());
    // The reader tells the order from the first index page it loads.
    EXPECT_EQ(reader->suggestedBatchShape(), BatchShape::kRow) << "nothing loaded yet";
    std::vector<uint8_t> pixels;
    for (const TileKey& key : keys) {
      ASSERT_TRUE(reader->readTile(key, &pixels).ok());
      ASSERT_EQ(pixels, syntheticTile(g, key));
    }
    EXPECT_EQ(reader->suggestedBatchShape(),
              order == PayloadOrder::kCurve ? BatchShape::kSquare : BatchShape::kRow);
    for (const uint32_t side : {2u, 4u, 8u}) {
      size_t together = 0, apart = 0;
      countAlignedSquares(*reader, side, &together, &apart);
      if (order == PayloadOrder::kCurve) {
        EXPECT_EQ(apart, 0u) << side << " x " << side;
        EXPECT_GT(together, 0u);
      } else {
        EXPECT_GT(apart, together) << side << " x " << side << ": rows lie apart";
      }
    }
    if (order == PayloadOrder::kWritten) {
      written_bytes = reader->info().file_bytes;
    } else {
      EXPECT_EQ(reader->info().file_bytes, written_bytes);
    }
  }
  // Shuffled writes from several threads give the same curve layout.
  std::shuffle(keys.begin(), keys.end(), std::mt19937(5));
  const std::string path = dir.file("shuffled.cst");
  WriterOptions options;
  options.fsync = false;
  options.payload_order = PayloadOrder::kCurve;
  std::unique_ptr<TileStoreWriter> writer;
  ASSERT_TRUE(TileStoreWriter::create(path, g, options, &writer).ok());
  std::atomic<size_t> next{0};
  std::atomic<int> failures{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 3; ++t) {
    threads.emplace_back([&] {
      for (size_t i; (i = next.fetch_add(1)) < keys.size();) {
        EncodedTile encoded;
        if (!encodeTile(g, options.encoding, keys[i], syntheticTile(g, keys[i]), &encoded) ||
            !writer->write(std::move(encoded))) {
          failures.fetch_add(1);
        }
      }
    });
  }
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(failures.load(), 0);
  ASSERT_TRUE(writer->finish().ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());
  std::vector<uint8_t> pixels;
  for (const TileKey& key : keys) {
    ASSERT_TRUE(reader->readTile(key, &pixels).ok());
    ASSERT_EQ(pixels, syntheticTile(g, key));
  }
  size_t together = 0, apart = 0;
  countAlignedSquares(*reader, 8, &together, &apart);
  EXPECT_EQ(apart, 0u);
  EXPECT_EQ(dir.entries().size(), 3u) << "no temporary left";
}

TEST(TileStoreWriter, FinishReplacesAnExistingFileAtomically) {
  const TempDir dir("replace");
  const std::string path = dir.file("out.cst");
  test::writeBytes(path, std::vector<uint8_t>(10, 'x'));
  PyramidGeometry g;
  ASSERT_TRUE(makePyramidGeometry(40, 40, 16, PixelFormat::kR8, &g));
  // Without `replace` an existing file is never touched.
  EXPECT_EQ(test::writeSyntheticStore(path, g, {}).code, ErrorCode::kAlreadyExists);
  EXPECT_EQ(test::readBytes(path), std::vector<uint8_t>(10, 'x'));
  WriterOptions options;
  options.replace = true;
  ASSERT_TRUE(test::writeSyntheticStore(path, g, options).ok());
  std::unique_ptr<TileStoreReader> reader;
  EXPECT_TRUE(TileStoreReader::open(path, &reader).ok());
  EXPECT_EQ(dir.entries().size(), 1u);
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
