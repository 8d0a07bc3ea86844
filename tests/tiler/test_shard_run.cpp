// The tiler's side of a sharded run (tiler/src/shard_run.h): the run
// fingerprint is the same for the same input and options whatever the
// shard, path or machine-side options, and differs for any option or input
// byte that changes the tiles; the band is the whole image's rows.
#include "tiler_test_util.h"

#include "shard_run.h"

#include <clipstream/tiler/shard.h>

#include <filesystem>
#include <fstream>
#include <set>

namespace clipstream::test {
namespace {

// A file of `size` bytes whose byte i is i * 7 + salt.
void writeBytes(const std::string& path, size_t size, uint8_t salt = 0) {
  std::ofstream out(path, std::ios::binary);
  for (size_t i = 0; i < size; ++i) out.put(char(uint8_t(i * 7 + salt)));
}

// Flips one byte of a file in place.
void flipByte(const std::string& path, size_t at) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(std::streamoff(at));
  const char c = char(f.get());
  f.seekp(std::streamoff(at));
  f.put(char(~c));
}

class RunFingerprint : public ::testing::Test {
 protected:
  void SetUp() override {
    m_input = m_dir.file("in.tif");
    writeBytes(m_input, 300000);
    m_options.input_path = m_input;
    m_options.output_path = m_dir.file("part1.cst");
    m_options.shard_index = 1;
    m_options.shard_count = 4;
    m_src.width_px = 5000;
    m_src.height_px = 3000;
    m_src.input_type = "uint8";
    m_src.input_channels = 3;
    m_src.format = PixelFormat::kRGB8;
    m_geo.present = true;
    const double transform[6] = {1000.0, 0.5, 0.0, 2000.0, 0.0, -0.5};
    std::copy(transform, transform + 6, m_geo.transform);
    m_geo.crs = "EPSG:32610";
  }

  uint64_t fingerprint(const TilerOptions& o, const SourceInfo& src, const GeoReference& geo,
                       const std::vector<std::string>& sheets = {}) {
    uint64_t h = 0;
    const Status s = runFingerprint(o, src, geo, sheets, &h);
    EXPECT_TRUE(s.ok()) << s.toString();
    return h;
  }
  uint64_t base() { return fingerprint(m_options, m_src, m_geo); }

  TempDir m_dir{"fingerprint"};
  std::string m_input;
  TilerOptions m_options;
  SourceInfo m_src;
  GeoReference m_geo;
};

TEST_F(RunFingerprint, IsTheSameForEveryShardAndWhatOnlyChangesHowTheRunGoes) {
  const uint64_t h = base();
  EXPECT_EQ(base(), h);
  TilerOptions o = m_options;
  o.shard_index = 3;
  o.output_path = m_dir.file("part3.cst");
  o.threads = 7;
  o.memory_budget_bytes = uint64_t(64) << 20;
  o.payload_order = PayloadOrder::kWritten;
  o.fsync = false;
  o.overwrite = true;
  o.reader = ImageReader::kOpenImageIO;
  EXPECT_EQ(fingerprint(o, m_src, m_geo), h);
  // The same bytes under another path (another mount on another machine).
  const std::string copy = m_dir.file("elsewhere.tif");
  std::filesystem::copy_file(m_input, copy);
  o.input_path = copy;
  EXPECT_EQ(fingerprint(o, m_src, m_geo), h);
}

TEST_F(RunFingerprint, EveryOptionThatChangesTheTilesChangesIt) {
  std::vector<std::pair<std::string, uint64_t>> variants;
  auto option = [&](const std::string& name, const std::function<void(TilerOptions&)>& change) {
    TilerOptions o = m_options;
    change(o);
    variants.emplace_back(name, fingerprint(o, m_src, m_geo));
  };
  option("tile_px", [](TilerOptions& o) { o.tile_px = 256; });
  option("zstd_level", [](TilerOptions& o) { o.zstd_level = 3; });
  option("predictor", [](TilerOptions& o) { o.predictor = false; });
  option("filter", [](TilerOptions& o) { o.filter = DownsampleFilter::kLanczos3; });
  option("linear_light", [](TilerOptions& o) { o.linear_light = true; });
  option("mosaic", [](TilerOptions& o) { o.mosaic = true; });
  option("fill", [](TilerOptions& o) { o.fill = 255; });
  option("shard_count", [](TilerOptions& o) { o.shard_count = 5; });
  option("synthetic", [](TilerOptions& o) { o.input_path.clear(); });
  auto source = [&](const std::string& name, const std::function<void(SourceInfo&)>& change) {
    SourceInfo src = m_src;
    change(src);
    variants.emplace_back(name, fingerprint(m_options, src, m_geo));
  };
  source("width", [](SourceInfo& s) { s.width_px += 1; });
  source("height", [](SourceInfo& s) { s.height_px += 1; });
  source("input_type", [](SourceInfo& s) { s.input_type = "uint16"; });
  source("channels", [](SourceInfo& s) { s.input_channels = 4; });
  source("format", [](SourceInfo& s) { s.format = PixelFormat::kRGBA8; });
  auto geo = [&](const std::string& name, const std::function<void(GeoReference&)>& change) {
    GeoReference g = m_geo;
    change(g);
    variants.emplace_back(name, fingerprint(m_options, m_src, g));
  };
  geo("geo.present", [](GeoReference& g) { g.present = false; });
  geo("geo.transform", [](GeoReference& g) { g.transform[0] += 0.25; });
  geo("geo.crs", [](GeoReference& g) { g.crs = "EPSG:32611"; });
  const std::string sheet = m_dir.file("sheet.tif");
  writeBytes(sheet, 1000, 1);
  variants.emplace_back("a sheet", fingerprint(m_options, m_src, m_geo, {sheet}));

  std::set<uint64_t> seen{base()};
  for (const auto& [name, h] : variants) {
    EXPECT_TRUE(seen.insert(h).second) << name << " does not change the fingerprint";
  }
}

TEST_F(RunFingerprint, TheInputsFirstAndLastBytesAndSizeChangeIt) {
  const uint64_t h = base();
  flipByte(m_input, 10);
  const uint64_t first = base();
  EXPECT_NE(first, h);
  flipByte(m_input, 10);
  EXPECT_EQ(base(), h);
  flipByte(m_input, 300000 - 10);
  EXPECT_NE(base(), h);
  flipByte(m_input, 300000 - 10);
  std::filesystem::resize_file(m_input, 300001);
  EXPECT_NE(base(), h);
  // What it cannot see: a byte in the middle, beyond both samples.
  std::filesystem::resize_file(m_input, 300000);
  flipByte(m_input, 150000);
  EXPECT_EQ(base(), h);
}

TEST_F(RunFingerprint, AnInputThatCannotBeReadIsAnErrorNamingIt) {
  TilerOptions o = m_options;
  o.input_path = m_dir.file("gone.tif");
  uint64_t h = 0;
  Status s = runFingerprint(o, m_src, m_geo, {}, &h);
  EXPECT_EQ(s.code, ErrorCode::kIo);
  EXPECT_EQ(s.message, o.input_path + ": cannot open to fingerprint it");
  s = runFingerprint(m_options, m_src, m_geo, {m_dir.file("no-sheet.tif")}, &h);
  EXPECT_EQ(s.code, ErrorCode::kIo);
}

TEST(BandSource, ReadsTheWholeImagesRowsFromItsOrigin) {
  std::unique_ptr<ImageSource> whole, same;
  ASSERT_TRUE(makeSyntheticSource(100, 300, PixelFormat::kRGB8, &whole).ok());
  ASSERT_TRUE(makeSyntheticSource(100, 300, PixelFormat::kRGB8, &same).ok());
  BandSource band(std::move(whole), 128, 64);
  EXPECT_EQ(band.info().width_px, 100u);
  EXPECT_EQ(band.info().height_px, 64u);
  std::vector<uint8_t> got(size_t(40) * 5 * 3), want(got.size());
  ASSERT_TRUE(band.readRows(10, 5, 30, 40, got.data(), 40 * 3).ok());
  ASSERT_TRUE(same->readRows(138, 5, 30, 40, want.data(), 40 * 3).ok());
  EXPECT_EQ(got, want);
}

TEST(CutShard, FillsTheShardRecordAndLeavesTheBand) {
  TilerOptions o;
  o.synthetic_width_px = 500;
  o.synthetic_height_px = 1000;
  o.tile_px = 64;
  o.shard_index = 2;
  o.shard_count = 3;
  std::unique_ptr<ImageSource> source;
  ASSERT_TRUE(makeSyntheticSource(500, 1000, PixelFormat::kRGB8, &source).ok());
  ShardInfo shard;
  const Status s = cutShard(o, GeoReference{}, {}, false, &source, &shard);
  ASSERT_TRUE(s.ok()) << s.toString();
  ShardPlan plan;
  ASSERT_TRUE(planShard(500, 1000, 64, 2, 3, &plan).ok());
  EXPECT_TRUE(shard.present);
  EXPECT_EQ(shard.index, 2u);
  EXPECT_EQ(shard.count, 3u);
  EXPECT_EQ(shard.full_width_px, 500u);
  EXPECT_EQ(shard.full_height_px, 1000u);
  EXPECT_EQ(shard.y0_px, plan.y0_px);
  EXPECT_EQ(shard.owned_levels, plan.owned_levels);
  EXPECT_GT(shard.y0_px, 0u);
  EXPECT_EQ(source->info().height_px, plan.height_px);
  EXPECT_EQ(source->info().width_px, 500u);
  uint64_t h = 0;
  std::unique_ptr<ImageSource> again;
  ASSERT_TRUE(makeSyntheticSource(500, 1000, PixelFormat::kRGB8, &again).ok());
  ASSERT_TRUE(runFingerprint(o, again->info(), GeoReference{}, {}, &h).ok());
  EXPECT_EQ(shard.fingerprint, h);
}

TEST(CutShard, RefusesAnElevationStoreAndAnImageWithTooFewTileRows) {
  TilerOptions o;
  o.input_path = "dem.tif";
  o.tile_px = 64;
  o.shard_index = 1;
  o.shard_count = 2;
  std::unique_ptr<ImageSource> source;
  ASSERT_TRUE(makeSyntheticSource(500, 1000, PixelFormat::kRGB8, &source).ok());
  ShardInfo shard;
  Status s = cutShard(o, GeoReference{}, {}, true, &source, &shard);
  EXPECT_EQ(s.code, ErrorCode::kUnsupported);
  EXPECT_EQ(s.message, "dem.tif becomes an elevation store, and elevation stores are not sharded "
                       "(use --layer colour for a picture of it)");
  EXPECT_FALSE(shard.present);

  o.shard_count = 20;  // 1000 rows are 16 tile rows
  s = cutShard(o, GeoReference{}, {}, false, &source, &shard);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(source->info().height_px, 1000u);  // left whole
}

}  // namespace
}  // namespace clipstream::test
