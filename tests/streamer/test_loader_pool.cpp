// The loader threads and batches on their own (loader_pool.h): how many
// loaders start, which queued tiles share a read, and a batch's read.
#include "../../streamer/src/loader_pool.h"  // private: the pool under test

#include <clipstream/streamer/streamer.h>
#include <clipstream/testing/sources.h>

#include <gtest/gtest.h>

#include <atomic>
#include <vector>

namespace clipstream {
namespace {

TEST(LoaderPool, ThreadCountIsToldThenSuggestedThenOnePerCore) {
  EXPECT_EQ(loaderThreadCount(5, 3, 8), 5u);
  EXPECT_EQ(loaderThreadCount(0, 3, 8), 3u);
  EXPECT_EQ(loaderThreadCount(0, 0, 8), 8u);
  EXPECT_EQ(loaderThreadCount(0, 0, 0), 1u);  // a system that cannot tell its cores
  EXPECT_EQ(loaderThreadCount(100000, 0, 8), kMaxIoThreads);
}

TEST(LoaderPool, RunsTheBodyOnEachLoaderAndJoinsThem) {
  std::atomic<int> ran{0};
  LoaderPool pool;
  EXPECT_EQ(pool.start(4, [&] { ran++; }), 4u);
  EXPECT_EQ(pool.size(), 4u);
  pool.join();
  EXPECT_EQ(ran.load(), 4);
  EXPECT_EQ(pool.size(), 0u);
}

TEST(LoaderPool, BatchSquaresAreTheLargestPowerOfTwoThatFits) {
  EXPECT_EQ(batchSide(1), 1u);
  EXPECT_EQ(batchSide(15), 2u);
  EXPECT_EQ(batchSide(16), 4u);
  EXPECT_EQ(batchSide(63), 4u);
  EXPECT_EQ(batchSide(64), 8u);
  EXPECT_EQ(batchLimit(0), 1u);
  EXPECT_EQ(batchLimit(1000), kMaxBatchTiles);
}

TEST(LoaderPool, RowBatchesTakeTheRowWithinTheBatchSizeSquaresTheAlignedSquare) {
  const TileKey first{3, 9, 5};
  EXPECT_TRUE(inBatch(first, {3, 1, 5}, 16, BatchShape::kRow));    // 8 columns left
  EXPECT_FALSE(inBatch(first, {3, 25, 5}, 16, BatchShape::kRow));  // 16 columns right
  EXPECT_FALSE(inBatch(first, {3, 9, 6}, 16, BatchShape::kRow));   // the next row
  // Squares of 4 x 4 for 16: (9, 5) lies in the square x 8..11, y 4..7.
  EXPECT_TRUE(inBatch(first, {3, 8, 4}, 16, BatchShape::kSquare));
  EXPECT_TRUE(inBatch(first, {3, 11, 7}, 16, BatchShape::kSquare));
  EXPECT_FALSE(inBatch(first, {3, 12, 5}, 16, BatchShape::kSquare));
  EXPECT_FALSE(inBatch(first, {3, 9, 3}, 16, BatchShape::kSquare));
}

TEST(LoaderPool, ABatchReadsWhatFetchingEachTileReads) {
  const std::shared_ptr<TileSource> source = test::procedural(1024);
  ReadBatch batch;
  for (size_t n : {size_t(1), size_t(3)}) {
    batch.keys.clear();
    for (uint32_t i = 0; i < n; ++i) batch.keys.push_back({1, i, 1});
    batch.read(*source);
    ASSERT_EQ(batch.pixels.size(), n);
    for (size_t i = 0; i < n; ++i) {
      std::vector<uint8_t> expected;
      ASSERT_TRUE(source->fetch(batch.keys[i], &expected));
      EXPECT_TRUE(batch.statuses[i].ok());
      EXPECT_EQ(*batch.pixels[i], expected);
    }
  }
  // Each read hands out fresh buffers: those of the last batch stay as they were.
  const std::shared_ptr<std::vector<uint8_t>> kept = batch.pixels[0];
  const std::vector<uint8_t> copy = *kept;
  batch.keys = {{1, 5, 5}};
  batch.read(*source);
  EXPECT_NE(batch.pixels[0], kept);
  EXPECT_EQ(*kept, copy);
}

}  // namespace
}  // namespace clipstream
