// Aligning an elevation store under a colour store (alignment.h): by
// georeference (finer, coarser, larger and smaller than the image), by
// stretching, and the refusals.
#include <clipstream/streamer/alignment.h>

#include <gtest/gtest.h>

#include <cmath>

namespace clipstream {
namespace {

StoreInfo store(uint64_t w, uint64_t h, const double t[6], const std::string& crs, bool elevation) {
  StoreInfo info;
  EXPECT_TRUE(makePyramidGeometry(w, h, 128, elevation ? PixelFormat::kI16 : PixelFormat::kRGB8,
                                  &info.geometry));
  if (t != nullptr) {
    info.geo.present = true;
    std::copy(t, t + 6, info.geo.transform);
    info.geo.crs = crs;
  }
  info.elevation.present = elevation;
  return info;
}

TEST(Alignment, ByGeoreferenceACoarserLargerDemUnderA1mImage) {
  // A 1 m image 2000 x 1000 px at (500000, 4000000); a 30 m DEM starting
  // 300 m west and 600 m north of it, 100 x 60 samples (3 km x 1.8 km).
  const double image[6] = {500000.0, 1.0, 0.0, 4000000.0, 0.0, -1.0};
  const double dem[6] = {499700.0, 30.0, 0.0, 4000600.0, 0.0, -30.0};
  const StoreInfo c = store(2000, 1000, image, "EPSG:32633", false);
  const StoreInfo e = store(100, 60, dem, "EPSG:32633", true);
  LayerAlignment a;
  ASSERT_TRUE(alignElevation(c, e, 1.0, false, &a).ok());
  EXPECT_FALSE(a.stretched);
  EXPECT_DOUBLE_EQ(a.world_per_sample.x, 30.0);
  EXPECT_DOUBLE_EQ(a.world_per_sample.y, 30.0);
  // Sample (0, 0)'s centre: 15 m in from the DEM's corner.
  EXPECT_DOUBLE_EQ(a.sample0_world.x, -300.0 + 15.0);
  EXPECT_DOUBLE_EQ(a.sample0_world.y, -600.0 + 15.0);
  EXPECT_DOUBLE_EQ(a.world_per_height, 1.0);  // metres over 1 m texels (UTM: metres)
  EXPECT_TRUE(a.warnings.empty());  // UTM's unit is known: nothing assumed
  ASSERT_TRUE(alignElevation(c, e, 3.0, false, &a).ok());
  EXPECT_DOUBLE_EQ(a.world_per_height, 3.0);
}

TEST(Alignment, KnownEpsgCodesAreMetresAndOthersAssumed) {
  for (const char* crs : {"EPSG:32633", "EPSG:32755", "EPSG:26710", "EPSG:26910", "EPSG:25832", "EPSG:3857"}) {
    const CrsUnitMetres u = metresPerCrsUnit(crs, 45.0);
    EXPECT_FALSE(u.assumed) << crs;
    EXPECT_EQ(u.x, 1.0) << crs;
  }
  EXPECT_TRUE(metresPerCrsUnit("EPSG:2992", 45.0).assumed);  // Oregon Lambert, in feet
  EXPECT_TRUE(metresPerCrsUnit("", 45.0).assumed);
  const CrsUnitMetres degrees = metresPerCrsUnit("EPSG:4326", 60.0);
  EXPECT_FALSE(degrees.assumed);
  EXPECT_NEAR(degrees.x, 111320.0 * 0.5, 1.0);
}

TEST(Alignment, FeetAndDegreesReachTheVerticalScale) {
  const char* feet = "PROJCS[\"NAD83(HARN) / Oregon GIC Lambert (ft)\",UNIT[\"foot\",0.3048]]";
  const double image[6] = {635615.0, 1.0, 0.0, 853362.0, 0.0, -1.0};
  const double dem[6] = {635000.0, 10.0, 0.0, 854000.0, 0.0, -10.0};
  LayerAlignment a;
  ASSERT_TRUE(alignElevation(store(3248, 4385, image, feet, false), store(400, 600, dem, feet, true),
                             1.0, false, &a).ok());
  EXPECT_NEAR(a.metres_per_world.x, 0.3048, 1e-12);
  EXPECT_NEAR(a.world_per_height, 1.0 / 0.3048, 1e-9);  // metres of height in 1-ft texels

  // Geographic: 1/1200 degree texels at 47 N are about 63 x 92 m.
  const double geo[6] = {-122.0, 1.0 / 1200, 0.0, 47.0, 0.0, -1.0 / 1200};
  ASSERT_TRUE(alignElevation(store(1201, 1201, geo, "EPSG:4326", false),
                             store(1201, 1201, geo, "EPSG:4326", true), 1.0, false, &a).ok());
  EXPECT_NEAR(a.metres_per_world.x, 111320.0 * std::cos(46.5 * M_PI / 180.0) / 1200.0, 0.5);
  EXPECT_NEAR(a.metres_per_world.y, 110574.0 / 1200.0, 0.01);
  EXPECT_FALSE(a.warnings.empty());  // non-square texels are said
}

TEST(Alignment, WithoutGeoreferenceTheDemIsStretchedAndSaidSo) {
  const double dem[6] = {557805.0, 30.0, 0.0, 5122005.0, 0.0, -30.0};
  LayerAlignment a;
  ASSERT_TRUE(alignElevation(store(3248, 4385, nullptr, "", false),
                             store(327, 468, dem, "EPSG:26710", true), 1.0, false, &a).ok());
  EXPECT_TRUE(a.stretched);
  EXPECT_DOUBLE_EQ(a.world_per_sample.x, 3248.0 / 327.0);
  EXPECT_DOUBLE_EQ(a.sample0_world.x, 0.5 * 3248.0 / 327.0);
  // A 30 m sample spans ~9.9 x 9.4 texels: a texel is ~3.02 x 3.20 m, and
  // heights are scaled by the mean.
  const double texel_m = 0.5 * (30.0 / (3248.0 / 327.0) + 30.0 / (4385.0 / 468.0));
  EXPECT_NEAR(a.world_per_height, 1.0 / texel_m, 1e-9);
  ASSERT_FALSE(a.warnings.empty());
  EXPECT_NE(a.warnings[0].find("stretched"), std::string::npos);
}

TEST(Alignment, RefusesWhatItCannotPlace) {
  const double image[6] = {500000.0, 1.0, 0.0, 4000000.0, 0.0, -1.0};
  const double far_dem[6] = {900000.0, 30.0, 0.0, 4000000.0, 0.0, -30.0};
  const double rot[6] = {500000.0, 1.0, 0.1, 4000000.0, 0.0, -1.0};
  const StoreInfo c = store(2000, 1000, image, "EPSG:32633", false);
  LayerAlignment a;
  EXPECT_EQ(alignElevation(c, store(100, 60, far_dem, "EPSG:32633", true), 1.0, false, &a).code,
            ErrorCode::kInvalidArgument);
  const Status crs = alignElevation(c, store(100, 60, image, "EPSG:4326", true), 1.0, false, &a);
  EXPECT_EQ(crs.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(crs.message.find("clipstream-tile DEM OUTPUT --t-srs 'EPSG:32633'"), std::string::npos) << crs.message;
  EXPECT_EQ(alignElevation(c, store(100, 60, rot, "EPSG:32633", true), 1.0, false, &a).code,
            ErrorCode::kInvalidArgument);
  EXPECT_EQ(alignElevation(c, store(100, 60, image, "EPSG:32633", true), 0.0, false, &a).code,
            ErrorCode::kInvalidArgument);
  EXPECT_EQ(alignElevation(c, store(100, 60, image, "EPSG:32633", false), 1.0, false, &a).code,
            ErrorCode::kInvalidArgument);
}

}  // namespace
}  // namespace clipstream
