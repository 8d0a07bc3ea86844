// Sharded runs: the partial stores of `--shard K/N`, joined by mergeShards()
// / clipstream-merge, give the single run's tiles; a missing, duplicate,
// foreign or corrupt shard is an error naming it and leaves nothing behind.
#include "tiler_test_util.h"

#include <clipstream/testing/files.h>
#include <clipstream/tiler/shard.h>
#include <clipstream/tiler/tiler.h>

#include <span>

namespace clipstream::test {
namespace {

TilerOptions syntheticRun(uint64_t w, uint64_t h, const std::string& out, uint32_t tile_px = 64) {
  TilerOptions o;
  o.synthetic_width_px = w;
  o.synthetic_height_px = h;
  o.output_path = out;
  o.tile_px = tile_px;
  o.threads = 2;
  o.fsync = false;
  return o;
}

// Tiles every shard of `base` into dir/part<K>.cst; returns their paths.
std::vector<std::string> tileShards(const TilerOptions& base, uint32_t count, const TempDir& dir,
                                    const std::string& prefix = "part") {
  std::vector<std::string> parts;
  for (uint32_t k = 1; k <= count; ++k) {
    TilerOptions o = base;
    o.output_path = dir.file(prefix + std::to_string(k) + ".cst");
    o.shard_index = k;
    o.shard_count = count;
    TilerSummary summary;
    const Status s = tileImage(o, &summary);
    EXPECT_TRUE(s.ok()) << s.toString();
    EXPECT_TRUE(summary.shard.present);
    parts.push_back(o.output_path);
  }
  return parts;
}

Status merge(const std::vector<std::string>& parts, const std::string& out) {
  MergeOptions m;
  m.input_paths = parts;
  m.output_path = out;
  m.fsync = false;
  MergeSummary summary;
  return mergeShards(m, &summary);
}

TEST(ShardPlan, BandsCoverTheImageInOrderAndDifferByAtMostOneBlockRow) {
  for (uint32_t n = 1; n <= 7; ++n) {
    uint64_t next_y = 0;
    uint64_t smallest = UINT64_MAX, largest = 0;
    for (uint32_t k = 1; k <= n; ++k) {
      ShardPlan p;
      ASSERT_TRUE(planShard(900, 1000, 64, k, n, &p).ok()) << k << "/" << n;
      EXPECT_EQ(p.y0_px, next_y) << k << "/" << n;
      EXPECT_EQ(p.y0_px % (uint64_t(64) << (p.owned_levels - 1)), 0u);
      next_y = p.y0_px + p.height_px;
      if (k < n) {
        smallest = std::min(smallest, p.height_px);
        largest = std::max(largest, p.height_px);
      }
    }
    EXPECT_EQ(next_y, 1000u) << n;
    if (n > 2) {
      ShardPlan p;
      ASSERT_TRUE(planShard(900, 1000, 64, 1, n, &p).ok());
      EXPECT_LE(largest - smallest, uint64_t(64) << (p.owned_levels - 1)) << n;
    }
  }
  ShardPlan p;
  const Status s = planShard(900, 100, 64, 1, 3, &p);  // two tile rows
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(s.message.find("only 2 tile rows"), std::string::npos) << s.message;
  EXPECT_FALSE(planShard(900, 1000, 64, 0, 3, &p).ok());
  EXPECT_FALSE(planShard(900, 1000, 64, 4, 3, &p).ok());
}

// N = 1..4 over 900x1000 in 64-px tiles (16 tile rows): N = 3 deals 4 block
// rows as 1, 1, 2, so the grid is not cut evenly.
TEST(ShardMerge, MergedShardsEqualTheSingleRunTileForTile) {
  TempDir dir("shard");
  const TilerOptions base = syntheticRun(900, 1000, dir.file("whole.cst"));
  TilerSummary whole;
  ASSERT_TRUE(tileImage(base, &whole).ok());
  for (uint32_t n = 1; n <= 4; ++n) {
    const std::vector<std::string> parts = tileShards(base, n, dir, "n" + std::to_string(n) + "_");
    const std::string merged = dir.file("merged" + std::to_string(n) + ".cst");
    const Status s = merge(parts, merged);
    ASSERT_TRUE(s.ok()) << n << ": " << s.toString();
    expectSameTiles(base.output_path, merged);
  }
}

// A file input (RGBA, 32-px tiles, a last band shorter than the others):
// the same tiles.
TEST(ShardMerge, FileInputEqualsTheSingleRun) {
  TempDir dir("shard");
  ASSERT_TRUE(writeImage(dir.file("in.tif"), 2100, 700, 4, OIIO::TypeDesc::UINT8,
                         [](uint64_t x, uint64_t y, int c) {
                           return double((x * 7 + y * 13 + uint64_t(c) * 50 + (x ^ y)) & 255);
                         }));
  TilerOptions base;
  base.input_path = dir.file("in.tif");
  base.output_path = dir.file("whole.cst");
  base.tile_px = 32;
  base.threads = 1;
  base.fsync = false;
  TilerSummary whole;
  const Status s = tileImage(base, &whole);
  ASSERT_TRUE(s.ok()) << s.toString();
  const std::vector<std::string> parts = tileShards(base, 3, dir);
  ASSERT_TRUE(merge(parts, dir.file("merged.cst")).ok());
  expectSameTiles(base.output_path, dir.file("merged.cst"));
}

TEST(ShardMerge, ProgramJoinsPartsInAnyOrder) {
  TempDir dir("shard");
  const TilerOptions base = syntheticRun(300, 700, dir.file("whole.cst"), 32);
  TilerSummary whole;
  ASSERT_TRUE(tileImage(base, &whole).ok());
  for (int k = 1; k <= 3; ++k) {
    const RunResult r = runTiler({"--synthetic", "300x700", "--tile-size", "32", "--no-fsync", "-q",
                                  "--shard", std::to_string(k) + "/3",
                                  dir.file("p" + std::to_string(k) + ".cst")});
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  const RunResult r = runMerge({dir.file("m.cst"), dir.file("p3.cst"), dir.file("p1.cst"),
                                dir.file("p2.cst"), "--no-fsync"});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("3 shards"), std::string::npos) << r.output;
  expectSameTiles(base.output_path, dir.file("m.cst"));
}

void expectMergeFails(const std::vector<std::string>& parts, const TempDir& dir,
                      const std::string& needle) {
  const std::vector<std::string> before = dir.entries();
  const Status s = merge(parts, dir.file("out.cst"));
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.toString().find(needle), std::string::npos) << s.toString();
  EXPECT_EQ(dir.entries(), before) << "left behind in " << dir.path();
}

TEST(ShardMerge, MissingDuplicateAndForeignShardsAreNamed) {
  TempDir dir("shard");
  const TilerOptions base = syntheticRun(400, 600, dir.file("unused.cst"));
  const std::vector<std::string> parts = tileShards(base, 3, dir);
  expectMergeFails({}, dir, "no partial stores");
  expectMergeFails({parts[0], parts[2]}, dir, "shard 2 of 3 missing");
  expectMergeFails({parts[0], parts[1], parts[2], parts[1]}, dir, "are both shard 2/3");

  // Another run: other options (zstd level), another image size, another
  // shard count, and another input of the same size and options.
  TilerOptions other = base;
  other.zstd_level = 3;
  const std::vector<std::string> zstd = tileShards(other, 3, dir, "zstd");
  expectMergeFails({parts[0], zstd[1], parts[2]}, dir, "zstd2.cst");
  expectMergeFails({parts[0], zstd[1], parts[2]}, dir, "encoding");
  other = syntheticRun(400, 660, dir.file("unused.cst"));
  const std::vector<std::string> taller = tileShards(other, 3, dir, "tall");
  expectMergeFails({parts[0], taller[1], parts[2]}, dir, "400x660");
  const std::vector<std::string> four = tileShards(base, 4, dir, "four");
  expectMergeFails({parts[0], four[1], parts[2]}, dir, "one of 4 shards");

  auto image = [&](const std::string& name, int seed) {
    EXPECT_TRUE(writeImage(dir.file(name), 400, 600, 3, OIIO::TypeDesc::UINT8,
                           [seed](uint64_t x, uint64_t y, int c) {
                             return double((x * 3 + y * 5 + uint64_t(c + seed) * 40) & 255);
                           }));
    TilerOptions o = base;
    o.input_path = dir.file(name);
    return o;
  };
  const std::vector<std::string> a = tileShards(image("a.tif", 0), 3, dir, "a");
  const std::vector<std::string> b = tileShards(image("b.tif", 1), 3, dir, "b");
  expectMergeFails({a[0], b[1], a[2]}, dir, "different input");
  ASSERT_TRUE(merge(a, dir.file("a_merged.cst")).ok());

  // A whole store is not a part.
  TilerSummary summary;
  ASSERT_TRUE(tileImage(base, &summary).ok());
  expectMergeFails({parts[0], base.output_path, parts[2]}, dir, "not a partial store");
  // The output may not be one of the parts, even with overwrite.
  MergeOptions m;
  m.input_paths = parts;
  m.output_path = parts[1];
  m.overwrite = true;
  MergeSummary ms;
  const Status s = mergeShards(m, &ms);
  EXPECT_NE(s.message.find("is the input"), std::string::npos) << s.toString();
}

TEST(ShardMerge, CorruptOrTruncatedShardFailsNamingIt) {
  TempDir dir("shard");
  const TilerOptions base = syntheticRun(400, 600, dir.file("unused.cst"));
  std::vector<std::string> parts = tileShards(base, 2, dir);
  const std::vector<uint8_t> good = readBytes(parts[1]);
  ASSERT_GT(good.size(), 4096u);

  std::vector<uint8_t> bytes = good;
  bytes[1000] ^= 0x55;  // inside level 0's payloads
  writeBytes(parts[1], bytes);
  expectMergeFails(parts, dir, "part2.cst");
  expectMergeFails(parts, dir, "checksum");

  writeBytes(parts[1], std::span(good).first(good.size() / 2));
  expectMergeFails(parts, dir, "part2.cst");

  writeBytes(parts[1], good);
  ASSERT_TRUE(merge(parts, dir.file("out.cst")).ok());
}

TEST(ShardMerge, CancelledMergeLeavesNothingAndProgressCountsEveryTile) {
  TempDir dir("shard");
  const std::vector<std::string> parts = tileShards(syntheticRun(400, 600, dir.file("u.cst")), 2, dir);
  const std::vector<std::string> before = dir.entries();
  MergeOptions m;
  m.input_paths = parts;
  m.output_path = dir.file("out.cst");
  m.fsync = false;
  std::atomic<int> cancel{15};
  m.cancel = &cancel;
  MergeSummary summary;
  EXPECT_EQ(mergeShards(m, &summary).code, ErrorCode::kCancelled);
  EXPECT_EQ(dir.entries(), before);
  m.cancel = nullptr;
  uint64_t last = 0, total = 0;
  m.progress = [&](uint64_t done, uint64_t all) {
    EXPECT_GE(done, last);
    last = done;
    total = all;
  };
  ASSERT_TRUE(mergeShards(m, &summary).ok());
  EXPECT_EQ(last, total);
  EXPECT_EQ(summary.copied_tiles + summary.built_tiles, total);
  EXPECT_GT(summary.built_tiles, 0u);
}

TEST(ShardCli, BadShardArgumentsAreCommandLineMistakes) {
  TempDir dir("shard");
  for (const char* bad : {"0/4", "5/4", "2", "a/b", "1/0", "-1/4", "1/99999999999"}) {
    const RunResult r = runTiler({"--synthetic", "256x256", dir.file("o.cst"), "--shard", bad});
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find("--shard"), std::string::npos) << r.output;
  }
  const RunResult lanczos = runTiler(
      {"--synthetic", "256x256", dir.file("o.cst"), "--shard", "1/2", "--filter", "lanczos3"});
  EXPECT_EQ(lanczos.exit_code, 2) << lanczos.output;
  EXPECT_NE(lanczos.output.find("box filter"), std::string::npos) << lanczos.output;
  // More shards than tile rows: a failed run (the image decides), exit 1.
  const RunResult many = runTiler({"--synthetic", "256x256", dir.file("o.cst"), "--shard", "1/3"});
  EXPECT_EQ(many.exit_code, 1) << many.output;
  EXPECT_NE(many.output.find("only 2 tile rows"), std::string::npos) << many.output;
  const RunResult merge_one = runMerge({dir.file("o.cst")});
  EXPECT_EQ(merge_one.exit_code, 2) << merge_one.output;
  const RunResult merge_missing = runMerge({dir.file("o.cst"), dir.file("nope.cst")});
  EXPECT_EQ(merge_missing.exit_code, 1) << merge_missing.output;
  EXPECT_NE(merge_missing.output.find("nope.cst"), std::string::npos) << merge_missing.output;
  EXPECT_TRUE(dir.entries().empty());
}

TEST(ShardStore, ShardRecordRoundTripsThroughTheStore) {
  TempDir dir("shard");
  TilerOptions o = syntheticRun(300, 500, dir.file("p.cst"));
  o.shard_index = 2;
  o.shard_count = 3;
  TilerSummary summary;
  ASSERT_TRUE(tileImage(o, &summary).ok());
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(o.output_path, &reader).ok());
  const ShardInfo& sh = reader->info().shard;
  ShardPlan plan;
  ASSERT_TRUE(planShard(300, 500, 64, 2, 3, &plan).ok());
  EXPECT_TRUE(sh.present);
  EXPECT_EQ(sh.index, 2u);
  EXPECT_EQ(sh.count, 3u);
  EXPECT_EQ(sh.full_width_px, 300u);
  EXPECT_EQ(sh.full_height_px, 500u);
  EXPECT_EQ(sh.y0_px, plan.y0_px);
  EXPECT_EQ(reader->geometry().height_px, plan.height_px);
  EXPECT_EQ(sh.owned_levels, plan.owned_levels);
  EXPECT_EQ(sh.fingerprint, summary.shard.fingerprint);
  // Every prefix of a partial store fails to open (never crashes).
  const std::vector<uint8_t> bytes = readBytes(o.output_path);
  for (size_t n = 0; n < bytes.size(); n += std::max<size_t>(1, bytes.size() / 97)) {
    writeBytes(dir.file("cut.cst"), std::span(bytes).first(n));
    std::unique_ptr<TileStoreReader> cut;
    EXPECT_FALSE(TileStoreReader::open(dir.file("cut.cst"), &cut).ok()) << n;
  }
}

}  // namespace
}  // namespace clipstream::test
