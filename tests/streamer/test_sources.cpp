// Tile sources: procedural determinism and structure, store conversion to
// RGBA8 for every pixel format, corrupt tiles, injected faults.
#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/tile_source.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>
#include <clipstream/streamer/testing/faulty_source.h>
#include <clipstream/streamer/testing/procedural_texel.h>

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>

namespace clipstream {
namespace {

TEST(ProceduralSource, TilesMatchProceduralTexelEverywhereIncludingFarCorner) {
  ProceduralSpec spec;  // 2^26 x 2^26, tile 128
  auto source = makeProceduralSource(spec);
  ASSERT_TRUE(source);
  const PyramidGeometry& g = source->geometry();
  ASSERT_EQ(g.levels[0].tiles_x, 1u << 19);
  const TileKey keys[] = {{0, 0, 0},
                          {0, (1u << 19) - 1, (1u << 19) - 1},
                          {5, 1234, 777},
                          {g.levelCount() - 1, 0, 0}};
  std::vector<uint8_t> rgba;
  for (const TileKey& key : keys) {
    ASSERT_TRUE(source->fetch(key, &rgba).ok());
    ASSERT_EQ(rgba.size(), 128u * 128u * 4u);
    size_t mismatches = 0;
    for (uint32_t y = 0; y < 128; ++y)
      for (uint32_t x = 0; x < 128; ++x) {
        uint8_t want[4];
        proceduralTexel(spec, key.level, uint64_t(key.x) * 128 + x, uint64_t(key.y) * 128 + y, want);
        mismatches += std::memcmp(want, &rgba[(size_t(y) * 128 + x) * 4], 4) != 0;
      }
    EXPECT_EQ(mismatches, 0u) << "level " << key.level << " tile " << key.x << "," << key.y;
  }
  EXPECT_EQ(source->fetch({0, 1u << 19, 0}, &rgba).code, ErrorCode::kOutOfRange);
  EXPECT_EQ(makeProceduralSource(ProceduralSpec{(uint64_t(1) << 31) + 1, 16, 128, 1}), nullptr);
  EXPECT_NE(makeProceduralSource(ProceduralSpec{uint64_t(1) << 31, uint64_t(1) << 31, 128, 1}), nullptr);
}

// Levels agree on structure: the 2x2 box average of level l correlates
// strongly with level l+1 (Pearson r over a 512x512 patch, per channel),
// while an unrelated patch does not. A broken level mapping breaks this.
TEST(ProceduralSource, CoarserLevelLooksLikeADownsampleOfTheFinerOne) {
  ProceduralSpec spec;
  spec.width_px = spec.height_px = uint64_t(1) << 20;
  auto correlation = [&](uint32_t level, uint64_t ox, uint64_t oy, uint64_t cx, uint64_t cy) {
    double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
    const int n = 256;
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x)
        for (int c = 0; c < 3; ++c) {
          double avg = 0;
          for (int k = 0; k < 4; ++k) {
            uint8_t p[4];
            proceduralTexel(spec, level, 2 * (ox + x) + (k & 1), 2 * (oy + y) + (k >> 1), p);
            avg += p[c] * 0.25;
          }
          uint8_t q[4];
          proceduralTexel(spec, level + 1, cx + x, cy + y, q);
          sa += avg; sb += q[c]; saa += avg * avg; sbb += double(q[c]) * q[c]; sab += avg * q[c];
        }
    const double m = n * n * 3.0;
    const double cov = sab / m - (sa / m) * (sb / m);
    return cov / std::sqrt((saa / m - (sa / m) * (sa / m)) * (sbb / m - (sb / m) * (sb / m)));
  };
  for (uint32_t level : {0u, 3u, 7u}) {
    EXPECT_GT(correlation(level, 1000, 2000, 1000, 2000), 0.65) << "level " << level;
    EXPECT_LT(correlation(level, 1000, 2000, 5000, 300), 0.3) << "level " << level;
  }
}

TEST(ProceduralSource, NeighbouringBlocksAndTileEdgesAreDistinguishable) {
  ProceduralSpec spec;
  uint8_t a[4], b[4], edge[4], inner[4];
  size_t differing = 0;
  for (uint64_t i = 0; i < 64; ++i) {
    proceduralTexel(spec, 4, 8 * i + 3, 21, a);
    proceduralTexel(spec, 4, 8 * i + 11, 21, b);
    differing += std::memcmp(a, b, 3) != 0;
  }
  EXPECT_GT(differing, 60u);  // hashed block colours: collisions are rare
  proceduralTexel(spec, 2, 256, 5, edge);   // tile boundary column
  proceduralTexel(spec, 2, 257, 5, inner);  // same 8x8 block, inside
  for (int c = 0; c < 3; ++c) EXPECT_EQ(edge[c], inner[c] / 2);
  EXPECT_EQ(edge[3], 255);
}

class StoreSourceFormats : public ::testing::TestWithParam<PixelFormat> {};

TEST_P(StoreSourceFormats, ConvertsEveryTexelToRgba8) {
  const PixelFormat format = GetParam();
  const test::TempDir dir("formats");
  const std::string path = dir.file("store.cst");
  ASSERT_TRUE(test::writeSyntheticStore(path, {.width_px = 200, .height_px = 150, .tile_px = 64,
                                               .format = format})
                  .ok());
  Status status;
  auto source = openStoreSource(path, &status);
  ASSERT_TRUE(source) << status.toString();
  const PyramidGeometry& g = source->geometry();
  EXPECT_EQ(g.format, format);
  std::vector<uint8_t> rgba;
  size_t mismatches = 0;
  for (uint32_t level = 0; level < g.levelCount(); ++level)
    for (uint32_t ty = 0; ty < g.levels[level].tiles_y; ++ty)
      for (uint32_t tx = 0; tx < g.levels[level].tiles_x; ++tx) {
        const TileKey key{level, tx, ty};
        ASSERT_TRUE(source->fetch(key, &rgba).ok());
        ASSERT_EQ(rgba.size(), 64u * 64u * 4u);
        for (uint32_t y = 0; y < 64; ++y)
          for (uint32_t x = 0; x < 64; ++x) {
            uint8_t want[4];
            test::syntheticRgba(format, key, x, y, want);
            mismatches += std::memcmp(want, &rgba[(size_t(y) * 64 + x) * 4], 4) != 0;
          }
        // The stamp survives the conversion: the tile says which it is.
        TileKey stamped;
        if (test::syntheticTileKey(PixelFormat::kRGBA8, rgba, &stamped)) {
          EXPECT_EQ(stamped, key);
        } else {
          EXPECT_TRUE(test::isConstantTile(key)) << "level " << level << " tile " << tx << "," << ty;
        }
      }
  EXPECT_EQ(mismatches, 0u);
  // A tile with a payload reports the bytes it read.
  const TileKey stored{0, 2, 1};
  ASSERT_FALSE(test::isConstantTile(stored));
  FetchInfo info;
  ASSERT_TRUE(source->fetchWithInfo(stored, &rgba, &info).ok());
  EXPECT_GT(info.bytes_read, 0u);
  EXPECT_NE(source->describe().find(path), std::string::npos);
}

INSTANTIATE_TEST_SUITE_P(AllFormats, StoreSourceFormats,
                         ::testing::Values(PixelFormat::kR8, PixelFormat::kR16, PixelFormat::kRGB8,
                                           PixelFormat::kRGBA8));

TEST(StoreSource, CorruptTileIsAStatusNotACrash) {
  const test::TempDir dir("corrupt");
  const std::string path = dir.file("store.cst");
  ASSERT_TRUE(test::writeSyntheticStore(path, {.width_px = 256, .height_px = 256, .tile_px = 64,
                                               .format = PixelFormat::kRGB8})
                  .ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(path, &reader).ok());
  TileLocation loc;
  ASSERT_TRUE(reader->locate({0, 2, 1}, &loc).ok());
  ASSERT_FALSE(loc.constant);
  reader.reset();
  {
    std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(std::streamoff(loc.offset + loc.stored_bytes / 2));
    char c = 0;
    f.read(&c, 1);
    c = char(c ^ 0x5A);
    f.seekp(std::streamoff(loc.offset + loc.stored_bytes / 2));
    f.write(&c, 1);
  }
  Status status;
  auto source = openStoreSource(path, &status);
  ASSERT_TRUE(source) << status.toString();
  std::vector<uint8_t> rgba;
  const Status bad = source->fetch({0, 2, 1}, &rgba);
  EXPECT_FALSE(bad.ok());
  EXPECT_EQ(bad.code, ErrorCode::kCorruptTile) << bad.toString();
  EXPECT_TRUE(source->fetch({0, 1, 1}, &rgba).ok());
  EXPECT_EQ(source->fetch({0, 9, 9}, &rgba).code, ErrorCode::kOutOfRange);
}

TEST(StoreSource, MissingFileReturnsNullAndAStatus) {
  Status status;
  EXPECT_EQ(openStoreSource("/nonexistent/dir/none.cts", &status), nullptr);
  EXPECT_FALSE(status.ok());
}

TEST(FaultySource, FailsExactlyTheTilesFailsTileNames) {
  ProceduralSpec spec;
  spec.width_px = spec.height_px = 4096;
  FaultSpec fault;
  fault.fail_fraction = 0.25;
  fault.fail_code = ErrorCode::kUnavailable;
  auto source = makeFaultySource(makeProceduralSource(spec), fault);
  std::vector<uint8_t> rgba;
  size_t failed = 0;
  for (uint32_t y = 0; y < 32; ++y)
    for (uint32_t x = 0; x < 32; ++x) {
      const TileKey key{0, x, y};
      const Status s = source->fetch(key, &rgba);
      EXPECT_EQ(s.ok(), !failsTile(fault, key));
      if (!s.ok()) {
        EXPECT_EQ(s.code, ErrorCode::kUnavailable);
        ++failed;
      }
    }
  EXPECT_GT(failed, 1024u / 8);  // about a quarter
  EXPECT_LT(failed, 1024u * 3 / 8);
}

}  // namespace
}  // namespace clipstream
