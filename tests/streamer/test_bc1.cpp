// BC1 tiles: the decoder against the S3TC rules on hand-made blocks, the
// block layout of a tile, stb_dxt's encoding error, the transcoding source
// and a streamer that hands out and caches BC1 tiles.
#include "streamer_test_util.h"

#include <clipstream/streamer/bc1.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/streamer/testing/faulty_source.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>

namespace clipstream {
namespace {

// A block from end points and one 2-bit index per texel (row-major).
std::vector<uint8_t> makeBlock(uint16_t c0, uint16_t c1, const int (&codes)[16]) {
  uint32_t bits = 0;
  for (int t = 0; t < 16; ++t) bits |= uint32_t(codes[t]) << (2 * t);
  return {uint8_t(c0), uint8_t(c0 >> 8), uint8_t(c1), uint8_t(c1 >> 8),
          uint8_t(bits), uint8_t(bits >> 8), uint8_t(bits >> 16), uint8_t(bits >> 24)};
}

uint16_t rgb565(uint32_t r5, uint32_t g6, uint32_t b5) { return uint16_t((r5 << 11) | (g6 << 5) | b5); }

double psnr(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  double se = 0.0;
  size_t n = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (i % 4 == 3) continue;
    const double d = double(a[i]) - double(b[i]);
    se += d * d;
    ++n;
  }
  return se == 0.0 ? 99.0 : 10.0 * std::log10(255.0 * 255.0 * double(n) / se);
}

TEST(Bc1, DecodesFourColourBlocksAsTheS3tcExtensionSays) {
  // c0 > c1: colours 2 and 3 are (2 c0 + c1) / 3 and (c0 + 2 c1) / 3.
  const uint16_t c0 = rgb565(31, 63, 0), c1 = rgb565(0, 0, 31);  // yellow, blue
  const int codes[16] = {0, 1, 2, 3, 3, 2, 1, 0, 0, 0, 1, 1, 2, 2, 3, 3};
  uint8_t rgba[64];
  decodeBc1Block(makeBlock(c0, c1, codes).data(), rgba);
  const uint8_t want[4][3] = {{255, 255, 0}, {0, 0, 255}, {170, 170, 85}, {85, 85, 170}};
  for (int t = 0; t < 16; ++t) {
    EXPECT_EQ(rgba[t * 4 + 0], want[codes[t]][0]) << "texel " << t;
    EXPECT_EQ(rgba[t * 4 + 1], want[codes[t]][1]) << "texel " << t;
    EXPECT_EQ(rgba[t * 4 + 2], want[codes[t]][2]) << "texel " << t;
    EXPECT_EQ(rgba[t * 4 + 3], 255);
  }
  // 565 expands by bit replication: 16 -> 132 (5 bits), 33 -> 134 (6 bits).
  const int zeros[16] = {};
  decodeBc1Block(makeBlock(rgb565(16, 33, 1), 0, zeros).data(), rgba);
  EXPECT_EQ(rgba[0], 132);
  EXPECT_EQ(rgba[1], 134);
  EXPECT_EQ(rgba[2], 8);
}

TEST(Bc1, DecodesThreeColourBlocksWithOpaqueBlack) {
  // c0 <= c1: colour 2 is the mean, colour 3 black (opaque in the RGB format).
  const uint16_t c0 = rgb565(0, 0, 31), c1 = rgb565(31, 0, 0);
  const int codes[16] = {2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3, 0, 1};
  uint8_t rgba[64];
  decodeBc1Block(makeBlock(c0, c1, codes).data(), rgba);
  EXPECT_EQ(rgba[0], 127);
  EXPECT_EQ(rgba[1], 0);
  EXPECT_EQ(rgba[2], 127);
  EXPECT_EQ(rgba[4 + 0], 0);
  EXPECT_EQ(rgba[4 + 1], 0);
  EXPECT_EQ(rgba[4 + 2], 0);
  EXPECT_EQ(rgba[4 + 3], 255);
}

TEST(Bc1, EachBlockOfATileHoldsItsOwnTexels) {
  // Every 4x4 block a flat colour of its own (bx, by): after encoding, the
  // block at byte 8 (by * n + bx) decodes to that colour, and the tile
  // decodes to the image.
  const uint32_t tp = 32, n = tp / 4;
  std::vector<uint8_t> rgba(size_t(tp) * tp * 4);
  auto colour = [](uint32_t bx, uint32_t by, uint8_t out[3]) {
    out[0] = uint8_t(bx * 32 + 8), out[1] = uint8_t(by * 32 + 8), out[2] = uint8_t((bx ^ by) * 24 + 16);
  };
  for (uint32_t y = 0; y < tp; ++y)
    for (uint32_t x = 0; x < tp; ++x) {
      colour(x / 4, y / 4, &rgba[(size_t(y) * tp + x) * 4]);
      rgba[(size_t(y) * tp + x) * 4 + 3] = 255;
    }
  std::vector<uint8_t> blocks;
  ASSERT_TRUE(encodeBc1Tile(rgba, tp, &blocks).ok());
  ASSERT_EQ(blocks.size(), bc1TileBytes(tp));
  ASSERT_EQ(blocks.size(), size_t(n) * n * 8);
  for (uint32_t by = 0; by < n; ++by)
    for (uint32_t bx = 0; bx < n; ++bx) {
      uint8_t texels[64], want[3];
      decodeBc1Block(blocks.data() + (size_t(by) * n + bx) * 8, texels);
      colour(bx, by, want);
      for (int t = 0; t < 16; ++t)
        for (int c = 0; c < 3; ++c)
          EXPECT_NEAR(texels[t * 4 + c], want[c], 4) << "block " << bx << "," << by;
    }
  std::vector<uint8_t> decoded;
  ASSERT_TRUE(decodeBc1Tile(blocks, tp, &decoded).ok());
  EXPECT_GE(psnr(rgba, decoded), 40.0);
}

TEST(Bc1, EncodingASmoothAndBlockyImageCostsAFewDecibels) {
  const uint32_t tp = 128;
  const std::vector<uint8_t> rgba = test::patternImage(tp, tp);
  std::vector<uint8_t> blocks, decoded;
  ASSERT_TRUE(encodeBc1Tile(rgba, tp, &blocks).ok());
  ASSERT_TRUE(decodeBc1Tile(blocks, tp, &decoded).ok());
  const double db = psnr(rgba, decoded);
  std::printf("  BC1 PSNR of the pattern tile: %.2f dB\n", db);
  EXPECT_GE(db, 32.0);
  EXPECT_LT(db, 99.0);
}

TEST(Bc1, RefusesSizesThatAreNotWholeBlocks) {
  std::vector<uint8_t> out;
  EXPECT_EQ(encodeBc1Tile(std::vector<uint8_t>(6 * 6 * 4), 6, &out).code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(encodeBc1Tile(std::vector<uint8_t>(8 * 8 * 4 - 1), 8, &out).code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(decodeBc1Tile(std::vector<uint8_t>(7), 4, &out).code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(decodeBc1Tile(std::vector<uint8_t>(8), 0, &out).code, ErrorCode::kInvalidArgument);
}

TEST(Bc1Source, HandsOutTheInnerTilesEncoded) {
  auto inner = test::procedural(8192);
  Status s;
  auto bc1 = makeBc1Source(inner, &s);
  ASSERT_TRUE(bc1) << s.toString();
  EXPECT_EQ(bc1->content(), TileContent::kBc1);
  EXPECT_EQ(tileContentBytes(TileContent::kBc1, 128), 128u * 128u / 2u);
  const TileKey key{2, 3, 5};
  std::vector<uint8_t> rgba, blocks, want;
  ASSERT_TRUE(inner->fetch(key, &rgba).ok());
  ASSERT_TRUE(bc1->fetch(key, &blocks).ok());
  ASSERT_TRUE(encodeBc1Tile(rgba, 128, &want).ok());
  EXPECT_EQ(blocks, want);
  // Failures pass through, named by the inner source.
  auto failing = makeBc1Source(makeFaultySource(inner, FaultSpec{0.0, 1.0, ErrorCode::kCorruptTile, 7}), &s);
  ASSERT_TRUE(failing);
  EXPECT_EQ(failing->fetch(key, &blocks).code, ErrorCode::kCorruptTile);
}

TEST(Bc1Source, BatchesEncodeEachTileWhereItLanded) {
  Status s;
  auto bc1 = makeBc1Source(makeFaultySource(test::procedural(8192), FaultSpec{0.0, 0.3, ErrorCode::kCorruptTile, 7}), &s);
  ASSERT_TRUE(bc1) << s.toString();
  const std::vector<TileKey> keys = {{1, 0, 0}, {1, 1, 0}, {1, 2, 0}, {1, 3, 0}, {1, 4, 0}, {1, 5, 0}};
  std::vector<std::vector<uint8_t>> out(keys.size());
  std::vector<std::vector<uint8_t>*> outs;
  for (auto& o : out) outs.push_back(&o);
  std::vector<Status> statuses(keys.size());
  std::vector<FetchInfo> infos(keys.size());
  bc1->fetchBatch(keys, outs, statuses, infos);
  size_t failed = 0;
  for (size_t i = 0; i < keys.size(); ++i) {
    std::vector<uint8_t> one;
    const Status alone = bc1->fetch(keys[i], &one);
    EXPECT_EQ(statuses[i].code, alone.code) << i;
    if (alone.ok()) {
      EXPECT_EQ(out[i], one) << i;
    }
    failed += !alone.ok();
  }
  EXPECT_GT(failed, 0u) << "the batch must mix failures and tiles";
  EXPECT_LT(failed, keys.size());
}

TEST(Bc1Source, RefusesHeightsAndTilesThatAreNotWholeBlocks) {
  Status s;
  ProceduralSpec heights;
  heights.width_px = heights.height_px = 4096;
  EXPECT_FALSE(makeBc1Source(makeProceduralHeightSource(heights), &s));
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_FALSE(makeBc1Source(makeImageSource(std::vector<uint8_t>(30 * 30 * 4, 9), 30, 30, 10), &s));
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(s.message.find("multiple of 4"), std::string::npos) << s.message;
  EXPECT_FALSE(makeBc1Source(nullptr, &s));
}

TEST(Bc1Source, TheStreamerHandsOutAndCachesCompressedTiles) {
  Status st;
  StreamerConfig cfg;
  cfg.io_threads = 2;
  cfg.prefetch = false;
  cfg.planner.clip_tiles = 8;
  Streamer s(makeBc1Source(test::procedural(8192), &st), cfg);
  s.update(test::lookingDown(4000.0, 4000.0, 60.0), Viewport{800, 600}, 0.0);
  ASSERT_TRUE(test::waitIdle(s));
  const FrameHandoff h = s.takeReady(100000);
  ASSERT_FALSE(h.tiles.empty());
  for (const ReadyTile& t : h.tiles) {
    ASSERT_TRUE(t.rgba);
    EXPECT_EQ(t.rgba->size(), bc1TileBytes(128));
  }
  const StreamerStats stats = s.stats();
  EXPECT_EQ(stats.ram_bytes, stats.total.loads * (bc1TileBytes(128) + kCacheEntryOverheadBytes));
  test::expectCountersAddUp(stats);
}

}  // namespace
}  // namespace clipstream
