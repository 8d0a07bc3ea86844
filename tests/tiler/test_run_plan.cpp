// The plan of a tiler run (tiler/src/run_plan.h): the writer options made
// from the tiler's, the pyramid, and the panel layout: the largest panels
// the budget holds, a clear refusal when none fits, and the retry on top of
// memory that is resident before tiling starts.
#include "tiler_test_util.h"

#include "run_plan.h"

#include <thread>

namespace clipstream::test {
namespace {

TEST(WriterOptions, CarryTheTilersEncodingAndRecords) {
  TilerOptions o;
  o.zstd_level = 7;
  o.predictor = false;
  o.filter = DownsampleFilter::kLanczos3;
  o.linear_light = true;
  o.fsync = false;
  o.overwrite = true;
  o.payload_order = PayloadOrder::kWritten;
  GeoReference geo;
  geo.present = true;
  geo.crs = "EPSG:4326";
  ShardInfo shard;
  shard.present = true;
  shard.index = 2;
  shard.count = 3;
  const WriterOptions w = writerOptions(o, ElevationInfo{}, geo, shard);
  EXPECT_EQ(w.encoding.compression, Compression::kZstd);
  EXPECT_EQ(w.encoding.zstd_level, 7);
  EXPECT_EQ(w.encoding.predictor, Predictor::kNone);
  EXPECT_EQ(w.encoding.filter, DownsampleFilter::kLanczos3);
  EXPECT_TRUE(w.encoding.linear_light);
  EXPECT_FALSE(w.fsync);
  EXPECT_TRUE(w.replace);
  EXPECT_EQ(w.payload_order, PayloadOrder::kWritten);
  EXPECT_TRUE(w.geo.present);
  EXPECT_EQ(w.geo.crs, "EPSG:4326");
  EXPECT_TRUE(w.shard.present);
  EXPECT_EQ(w.shard.index, 2u);
  EXPECT_FALSE(w.elevation.present);

  o.predictor = true;
  o.filter = DownsampleFilter::kBox;
  o.linear_light = false;
  ElevationInfo elevation;
  elevation.present = true;
  elevation.scale = 0.25;
  const WriterOptions e = writerOptions(o, elevation, GeoReference{}, ShardInfo{});
  EXPECT_EQ(e.encoding.predictor, Predictor::kLeftDelta);
  EXPECT_EQ(e.encoding.filter, DownsampleFilter::kDecimate);  // heights are decimated
  EXPECT_TRUE(e.elevation.present);
  EXPECT_DOUBLE_EQ(e.elevation.scale, 0.25);
}

TEST(RunPlan, ThePyramidAndTheThreadCount) {
  SourceInfo src;
  src.width_px = 3000;
  src.height_px = 2000;
  src.format = PixelFormat::kRGBA8;
  PyramidGeometry g;
  ASSERT_TRUE(pyramidGeometryFor(src, 128, &g).ok());
  EXPECT_EQ(g.levelCount(), 6u);  // 3000 -> 1500 -> 750 -> 375 -> 188 -> 94
  EXPECT_EQ(g.format, PixelFormat::kRGBA8);
  src.width_px = 0;
  const Status s = pyramidGeometryFor(src, 128, &g);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(s.message, "cannot make a pyramid for 0x2000 with tile size 128");

  TilerOptions o;
  o.threads = 3;
  EXPECT_EQ(encoderThreads(o), 3u);
  o.threads = 0;
  EXPECT_EQ(encoderThreads(o), std::max(1u, std::thread::hardware_concurrency()));
}

PyramidGeometry geometry(uint64_t w, uint64_t h, PixelFormat format) {
  PyramidGeometry g;
  EXPECT_TRUE(makePyramidGeometry(w, h, 128, format, &g));
  return g;
}

const Downsampler kBox(DownsampleFilter::kBox, false, PixelFormat::kRGBA8);

// The least budget any layout of `g` fits in (with nothing resident).
uint64_t smallestNeed(const PyramidGeometry& g, const Downsampler& ds, unsigned threads) {
  uint64_t lo = 0, hi = uint64_t(1) << 40;
  PanelLayout l;
  while (lo + 1 < hi) {
    const uint64_t mid = lo + (hi - lo) / 2;
    if (planLayout(g, ds, threads, mid, 0, false, &l)) hi = mid;
    else lo = mid;
  }
  return hi;
}

TEST(PanelLayout, AGenerousBudgetBuildsEveryLevelInOnePanel) {
  const PyramidGeometry g = geometry(3000, 2000, PixelFormat::kRGBA8);
  PanelLayout l;
  ASSERT_TRUE(planLayout(g, kBox, 2, uint64_t(1) << 30, 0, false, &l).ok());
  EXPECT_EQ(l.local_levels, g.levelCount());
  EXPECT_EQ(l.panel_px, uint64_t(128) << (g.levelCount() - 1));
  EXPECT_GE(l.panel_px, 3000u);
  EXPECT_EQ(l.blocks_x, 1u);
  EXPECT_EQ(l.blocks_y, 1u);
  EXPECT_LE(l.estimate_bytes, uint64_t(1) << 30);
}

TEST(PanelLayout, ASmallBudgetTakesTheLargestPanelsThatFit) {
  const uint64_t side = uint64_t(1) << 20;
  const PyramidGeometry g = geometry(side, side, PixelFormat::kRGBA8);
  for (uint64_t mb : {80, 128, 256}) {
    const uint64_t budget = mb << 20;
    PanelLayout l;
    ASSERT_TRUE(planLayout(g, kBox, 4, budget, 0, false, &l).ok()) << mb;
    EXPECT_LT(l.local_levels, g.levelCount()) << mb;
    EXPECT_EQ(l.panel_px, uint64_t(128) << (l.local_levels - 1));
    EXPECT_EQ(l.blocks_x, (side + l.panel_px - 1) / l.panel_px);
    EXPECT_EQ(l.blocks_y, l.blocks_x);
    EXPECT_LE(l.estimate_bytes, budget);
    // Every larger panel was tried first: one byte less cannot keep these.
    PanelLayout smaller;
    if (planLayout(g, kBox, 4, l.estimate_bytes - 1, 0, false, &smaller)) {
      EXPECT_LT(smaller.local_levels, l.local_levels) << mb;
    }
    // What is resident counts against the budget.
    PanelLayout with_base;
    if (planLayout(g, kBox, 4, budget, budget - l.estimate_bytes + 1, false, &with_base)) {
      EXPECT_LT(with_base.local_levels, l.local_levels) << mb;
    }
  }
}

TEST(PanelLayout, ABudgetTooSmallForAnyLayoutSaysWhatItNeeds) {
  const uint64_t side = uint64_t(1) << 20;
  const PyramidGeometry g = geometry(side, side, PixelFormat::kRGBA8);
  const uint64_t need = smallestNeed(g, kBox, 4);
  const uint64_t mb = uint64_t(1) << 20;
  PanelLayout l;
  const Status s = planLayout(g, kBox, 4, uint64_t(16) << 20, 0, false, &l);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(s.message, "--memory-mb 16 is too small for a 1048576x1048576 RGBA8 image with 4 threads: "
                       "needs about " + std::to_string((need + mb - 1) / mb) + " MB");
  EXPECT_GT(need, uint64_t(16) << 20);
}

TEST(PanelLayout, LanczosTakesTheFullWidthOrNothing) {
  const Downsampler lanczos(DownsampleFilter::kLanczos3, false, PixelFormat::kRGBA8);
  const PyramidGeometry g = geometry(65536, 4096, PixelFormat::kRGBA8);
  PanelLayout l;
  ASSERT_TRUE(planLayout(g, lanczos, 2, uint64_t(4) << 30, 0, true, &l).ok());
  EXPECT_EQ(l.local_levels, g.levelCount());
  EXPECT_EQ(l.blocks_x, 1u);
  const Status s = planLayout(g, lanczos, 2, uint64_t(64) << 20, 0, true, &l);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(s.message.find("--memory-mb 64 is too small: the Lanczos filter needs full-width strips "
                           "of 65536 px, about "),
            std::string::npos)
      << s.message;
  // The box filter fits the same budget in panels.
  EXPECT_TRUE(planLayout(g, kBox, 2, uint64_t(64) << 20, 0, false, &l).ok());
}

TEST(PanelLayout, MemoryResidentBeforeTilingIsPlannedAroundWithAWarning) {
  const PyramidGeometry g = geometry(20000, 20000, PixelFormat::kRGBA8);
  const uint64_t need = smallestNeed(g, kBox, 2);
  // More than half the budget resident: no layout fits on top of it, but
  // one fits in half the budget on top of it.
  const uint64_t budget = 3 * need, base = 5 * need / 2;
  PanelLayout l;
  ASSERT_FALSE(planLayout(g, kBox, 2, budget, base, false, &l).ok());
  std::vector<std::string> warnings;
  Status s = planLayoutInBudget(g, kBox, 2, budget, base, false, &l, &warnings);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_LE(l.estimate_bytes, base + budget / 2);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_EQ(warnings[0], std::to_string(base >> 20) +
                             " MB are resident before tiling starts (image libraries and decoder "
                             "state; a progressive JPEG keeps all its coefficients); peak memory "
                             "will exceed --memory-mb " + std::to_string(budget >> 20));

  // Half the budget on top is not enough either: the first plan's error.
  warnings.clear();
  const uint64_t tight = 3 * need / 2;
  s = planLayoutInBudget(g, kBox, 2, tight, need, false, &l, &warnings);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(s.message.find("--memory-mb " + std::to_string(tight >> 20) + " is too small"),
            std::string::npos)
      << s.message;
  EXPECT_TRUE(warnings.empty());

  // A plan that fits needs no retry and no warning.
  PanelLayout direct, planned;
  ASSERT_TRUE(planLayout(g, kBox, 2, 2 * need, need / 4, false, &direct).ok());
  ASSERT_TRUE(planLayoutInBudget(g, kBox, 2, 2 * need, need / 4, false, &planned, &warnings).ok());
  EXPECT_EQ(planned.local_levels, direct.local_levels);
  EXPECT_EQ(planned.estimate_bytes, direct.estimate_bytes);
  EXPECT_TRUE(warnings.empty());
}

}  // namespace
}  // namespace clipstream::test
