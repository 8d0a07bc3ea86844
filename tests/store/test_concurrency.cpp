// Many threads on one reader, and the lazily loaded index of huge stores.
#include <clipstream/store/tile_store.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

namespace clipstream {
namespace {

TEST(TileStoreReader, ManyThreadsReadEveryTileCorrectly) {
  const test::TempDir dir("threads");
  const std::string path = dir.file("store.cst");
  PyramidGeometry g;
  // 1100 px / 16 px tiles = 69 x 69 tiles at level 0: 4 index pages
  // there, so racing threads load the same pages at the same time.
  ASSERT_TRUE(makePyramidGeometry(1100, 1100, 16, PixelFormat::kRGB8, &g));
  WriterOptions options;
  options.fsync = false;
  ASSERT_TRUE(test::writeSyntheticStore(path, g, options).ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());

  std::vector<TileKey> keys;
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y) {
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) keys.push_back({l, x, y});
    }
  }
  constexpr int kThreads = 8;
  std::atomic<bool> go{false};
  std::atomic<uint64_t> good{0}, bad{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      while (!go.load()) std::this_thread::yield();
      std::vector<uint8_t> pixels;
      // Each thread walks all keys from a different start.
      for (size_t i = 0; i < keys.size(); ++i) {
        const TileKey& key = keys[(i + size_t(t) * 997) % keys.size()];
        if (reader->readTile(key, &pixels).ok() && pixels == test::syntheticTile(g, key)) {
          good.fetch_add(1);
        } else {
          bad.fetch_add(1);
        }
      }
    });
  }
  go.store(true);
  for (auto& thread : threads) thread.join();
  EXPECT_EQ(bad.load(), 0u);
  EXPECT_EQ(good.load(), uint64_t(kThreads) * keys.size());
  // Each index page is published exactly once however many threads raced.
  uint64_t pages = 0;
  for (const LevelInfo& level : g.levels) {
    pages += uint64_t((level.tiles_x + 63) / 64) * ((level.tiles_y + 63) / 64);
  }
  EXPECT_EQ(reader->indexPagesLoaded(), pages);
}

// A 1,048,576^2 RGBA8 store (about 87 M tiles) written through the
// page-level constant path, with one real tile in it.
class HugeStore : public ::testing::Test {
 protected:
  void SetUp() override {
    m_path = m_dir.file("planet.cst");
    ASSERT_TRUE(makePyramidGeometry(uint64_t(1) << 20, uint64_t(1) << 20, 128, PixelFormat::kRGBA8,
                                    &m_geometry));
    WriterOptions options;
    options.fsync = false;
    std::unique_ptr<TileStoreWriter> writer;
    ASSERT_TRUE(TileStoreWriter::create(m_path, m_geometry, options, &writer).ok());
    const uint8_t ocean[4] = {10, 40, 90, 255};
    m_real = TileKey{0, 4000, 5000};
    EncodedTile encoded;
    ASSERT_TRUE(encodeTile(m_geometry, options.encoding, m_real,
                           test::syntheticTile(m_geometry, m_real, test::ConstantTiles::kNone), &encoded).ok());
    ASSERT_TRUE(writer->write(std::move(encoded)).ok());
    for (uint32_t l = 0; l < m_geometry.levelCount(); ++l) {
      const LevelInfo& level = m_geometry.levels[l];
      if (l == 0) {
        // Everything except the real tile: around it in four rectangles.
        const uint32_t x = m_real.x, y = m_real.y;
        ASSERT_TRUE(writer->writeConstantTiles(0, 0, 0, level.tiles_x, y, ocean).ok());
        ASSERT_TRUE(writer->writeConstantTiles(0, 0, y + 1, level.tiles_x, level.tiles_y, ocean).ok());
        ASSERT_TRUE(writer->writeConstantTiles(0, 0, y, x, y + 1, ocean).ok());
        ASSERT_TRUE(writer->writeConstantTiles(0, x + 1, y, level.tiles_x, y + 1, ocean).ok());
      } else {
        ASSERT_TRUE(writer->writeConstantTiles(l, 0, 0, level.tiles_x, level.tiles_y, ocean).ok());
      }
    }
    ASSERT_TRUE(writer->finish().ok());
  }

  test::TempDir m_dir{"huge"};
  std::string m_path;
  PyramidGeometry m_geometry;
  TileKey m_real;
};

TEST_F(HugeStore, OpenReadsOnlyHeaderTablesAndDirectories) {
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(m_path, &reader).ok());
  uint64_t tiles = 0;
  for (const LevelInfo& level : m_geometry.levels) tiles += uint64_t(level.tiles_x) * level.tiles_y;
  EXPECT_GT(tiles, 87'000'000u);
  // Directories are 32 bytes per 64x64-tile page: ~700 KB for 87 M tiles,
  // against ~1.4 GB for a flat 16-byte-per-tile index.
  EXPECT_LT(reader->bytesRead(), uint64_t(1) << 20);
  EXPECT_LT(reader->info().file_bytes, uint64_t(1) << 20);
  EXPECT_EQ(reader->indexPagesLoaded(), 0u);

  // A constant page answers without reading anything.
  const uint64_t after_open = reader->bytesRead();
  std::vector<uint8_t> pixels;
  ASSERT_TRUE(reader->readTile(TileKey{0, 100, 100}, &pixels).ok());
  EXPECT_EQ(pixels[0], 10);
  EXPECT_EQ(pixels[pixels.size() - 2], 90);
  EXPECT_EQ(reader->bytesRead(), after_open);
  ASSERT_TRUE(reader->readTile(TileKey{13, 0, 0}, &pixels).ok());
  EXPECT_EQ(reader->bytesRead(), after_open);

  // The real tile loads exactly its one index page (64 KiB) and payload.
  TileLocation location;
  ASSERT_TRUE(reader->locate(m_real, &location).ok());
  ASSERT_FALSE(location.constant);
  EXPECT_EQ(reader->indexPagesLoaded(), 1u);
  EXPECT_EQ(reader->bytesRead(), after_open + 64 * 64 * 16);
  ASSERT_TRUE(reader->readTile(m_real, &pixels).ok());
  EXPECT_EQ(pixels, test::syntheticTile(m_geometry, m_real, test::ConstantTiles::kNone));
  EXPECT_EQ(reader->bytesRead(), after_open + 64 * 64 * 16 + location.stored_bytes);
  // Its page neighbours are constant entries inside that page.
  ASSERT_TRUE(reader->readTile(TileKey{0, 4001, 5000}, &pixels).ok());
  EXPECT_EQ(pixels[1], 40);
  EXPECT_EQ(reader->indexPagesLoaded(), 1u);

  std::vector<LevelStats> stats;
  ASSERT_TRUE(reader->levelStats(&stats).ok());
  EXPECT_EQ(stats[0].tiles, uint64_t(8192) * 8192);
  EXPECT_EQ(stats[0].constant_tiles, uint64_t(8192) * 8192 - 1);
  EXPECT_EQ(stats[0].stored_bytes, location.stored_bytes);
}

}  // namespace
}  // namespace clipstream
