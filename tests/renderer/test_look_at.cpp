// Cameras in map coordinates (--look-at, aimAtMapPoint()): a map point of a
// georeferenced scene is drawn at the centre of the frame, on the ground.
#include <clipstream/cli/renderer_options.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/streamer/look_at.h>

#include "terrain_fixtures.h"
#include "test_helpers.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

using namespace clipstream;
using namespace terrain_test;

TEST(LookAt, MapCoordinatesBecomeTexels) {
  GeoReference geo;
  glm::dvec2 world;
  ASSERT_TRUE(mapToWorld(geo, {12.5, 7.0}, &world).ok());
  EXPECT_EQ(world, glm::dvec2(12.5, 7.0)) << "without a georeference: texels";
  geo.present = true;
  const double t[6] = {500000.0, 0.5, 0.0, 4000000.0, 0.0, -0.5};
  std::copy(t, t + 6, geo.transform);
  ASSERT_TRUE(mapToWorld(geo, {500350.0, 3999550.0}, &world).ok());
  EXPECT_DOUBLE_EQ(world.x, 700.0);
  EXPECT_DOUBLE_EQ(world.y, 900.0);
  geo.transform[2] = 0.1;  // rotated
  EXPECT_EQ(mapToWorld(geo, {0.0, 0.0}, &world).code, ErrorCode::kInvalidArgument);
}

// Longitude and latitude (--look-at lonlat:...) through PROJ: a UTM
// zone's central meridian is its false easting (500 km), the equator its
// false northing (0 north, 10000 km south); a geographic CRS keeps the
// degrees in longitude, latitude order whatever its axis order; what
// cannot be converted is an error naming why.
TEST(LookAt, LongitudeAndLatitudeBecomeMapCoordinates) {
  glm::dvec2 map;
  ASSERT_TRUE(lonLatToMap("EPSG:32610", {-123.0, 0.0}, &map).ok());
  EXPECT_NEAR(map.x, 500000.0, 1e-6);
  EXPECT_NEAR(map.y, 0.0, 1e-6);
  ASSERT_TRUE(lonLatToMap("EPSG:32710", {-123.0, 0.0}, &map).ok());
  EXPECT_NEAR(map.y, 10000000.0, 1e-6);
  ASSERT_TRUE(lonLatToMap("EPSG:32610", {-123.0, 46.2}, &map).ok());
  EXPECT_NEAR(map.x, 500000.0, 1e-6);
  EXPECT_NEAR(map.y, 5116000.0, 2000.0);  // about 111 km a degree of latitude
  ASSERT_TRUE(lonLatToMap("EPSG:4326", {-122.19, 46.2}, &map).ok());
  EXPECT_NEAR(map.x, -122.19, 1e-9);
  EXPECT_NEAR(map.y, 46.2, 1e-9);
  EXPECT_EQ(lonLatToMap("", {0.0, 0.0}, &map).code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(lonLatToMap("EPSG:99999999", {0.0, 0.0}, &map).code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(lonLatToMap("EPSG:32610", {200.0, 0.0}, &map).code, ErrorCode::kInvalidArgument);

  LookAt look;
  ASSERT_TRUE(cli::parseLookAt("lonlat:-122.19,46.2,2500", &look).ok());
  EXPECT_TRUE(look.lon_lat);
  EXPECT_EQ(look.map, glm::dvec2(-122.19, 46.2));
  EXPECT_EQ(look.height, 2500.0);
  ASSERT_TRUE(cli::parseLookAt("562710,5114985", &look).ok());
  EXPECT_FALSE(look.lon_lat);
  EXPECT_FALSE(cli::parseLookAt("lonlat:-190,46", &look).ok());
  EXPECT_FALSE(cli::parseLookAt("lonlat:46", &look).ok());
  // A store without a georeference has no place for degrees.
  look.lon_lat = true;
  Camera camera;
  double ground = 0.0;
  PyramidGeometry g;
  g.width_px = g.height_px = 1024;
  EXPECT_EQ(aimAtMapPoint(look, GeoReference{}, g, nullptr, &camera, &ground).code, ErrorCode::kInvalidArgument);
}

// A path in map units (--path-in-map-units): x and z through the
// georeference, heights through the elevation's scale (or, without one, the
// georeference's pixel size).
TEST(LookAt, APathInMapUnitsBecomesTexels) {
  GeoReference geo;
  geo.present = true;
  const double t[6] = {500000.0, 0.5, 0.0, 4000000.0, 0.0, -0.5};
  std::copy(t, t + 6, geo.transform);
  FlightPath path;
  Keyframe a, b;
  a.position = {500350.0, 30.0, 3999550.0};
  b.t_s = 2.0;
  b.position = {500000.0, 10.0, 4000000.0};
  path.keyframes = {a, b};
  LayerAlignment elevation;
  elevation.world_per_height = 2.0;
  FlightPath over_terrain = path;
  ASSERT_TRUE(pathFromMapUnits(geo, &elevation, &over_terrain).ok());
  EXPECT_EQ(over_terrain.keyframes[0].position, glm::dvec3(700.0, 60.0, 900.0));
  EXPECT_EQ(over_terrain.keyframes[1].position, glm::dvec3(0.0, 20.0, 0.0));
  EXPECT_EQ(over_terrain.keyframes[1].t_s, 2.0) << "times and angles as they were";
  FlightPath flat = path;
  ASSERT_TRUE(pathFromMapUnits(geo, nullptr, &flat).ok());
  EXPECT_EQ(flat.keyframes[0].position, glm::dvec3(700.0, 60.0, 900.0));
  geo.transform[4] = 0.2;  // rotated
  EXPECT_EQ(pathFromMapUnits(geo, nullptr, &flat).code, ErrorCode::kInvalidArgument);
}

namespace {

// Rolling hills, smooth enough that every ring's surface is within a small
// fraction of a unit of the samples' (the methods' own error is measured
// elsewhere).
HeightField smoothField(uint32_t side) {
  HeightField f;
  f.w = f.h = side;
  f.samples.resize(size_t(side) * side);
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x)
      f.samples[size_t(y) * side + x] = float(60.0 + 30.0 * std::sin(x * 0.01) * std::cos(y * 0.013));
  EXPECT_TRUE(makePyramidGeometry(side, side, 128, PixelFormat::kF32, &f.geometry));
  return f;
}

}  // namespace

// The middle of the roughest area (--path rough): smooth rolling hills, a
// tall smooth bump (the summit, not rough: its curvature is small) and a
// patch of sample-scale noise far from it: the orbit goes to the noise.
TEST(LookAt, TheRoughestAreaIsTheNoiseNotTheSummit) {
  HeightField f = smoothField(1024);
  for (uint32_t y = 0; y < 1024; ++y)
    for (uint32_t x = 0; x < 1024; ++x) {
      const double d2 = (double(x) - 300.0) * (double(x) - 300.0) + (double(y) - 700.0) * (double(y) - 700.0);
      f.samples[size_t(y) * 1024 + x] += float(200.0 * std::exp(-d2 / 20000.0));
      if (x >= 700 && x < 828 && y >= 100 && y < 228) {
        f.samples[size_t(y) * 1024 + x] += float(((x * 7919u + y * 104729u) % 17u) * 1.5);
      }
    }
  FieldSource source(f);
  LayerAlignment alignment;
  alignment.world_per_sample = {2.0, 2.0};
  alignment.sample0_world = {1.0, 1.0};
  alignment.world_per_height = 0.5;
  glm::dvec3 rough, peak;
  ASSERT_TRUE(roughestPoint(source, alignment, &rough).ok());
  ASSERT_TRUE(highestPoint(source, alignment, &peak).ok());
  // The patch's middle, sample (764, 164), is world (1529, 329); within
  // the square's half side (64 samples, 128 world units).
  EXPECT_NEAR(rough.x, 1.0 + 2.0 * 764.0, 128.0);
  EXPECT_NEAR(rough.z, 1.0 + 2.0 * 164.0, 128.0);
  EXPECT_GT(glm::length(glm::dvec2(rough.x - peak.x, rough.z - peak.z)), 500.0) << "the summit is not rough";
  // On the ground there, as the decimated level sees it.
  EXPECT_GT(rough.y, 0.5 * f.lowest());
  EXPECT_LT(rough.y, 0.5 * f.highest());
}

// The summit the built-in path circles (--path summit): the DEM's highest
// sample, found by a climb from its coarse levels, in world units.
TEST(LookAt, TheHighestPointIsTheSummit) {
  HeightField f = smoothField(1024);
  // A bump on the rolling hills, its top at sample (301, 702).
  for (uint32_t y = 0; y < 1024; ++y)
    for (uint32_t x = 0; x < 1024; ++x) {
      const double d2 = (double(x) - 301.0) * (double(x) - 301.0) + (double(y) - 702.0) * (double(y) - 702.0);
      f.samples[size_t(y) * 1024 + x] += float(80.0 * std::exp(-d2 / 2000.0));
    }
  FieldSource source(f);
  LayerAlignment alignment;
  alignment.world_per_sample = {2.0, 2.0};
  alignment.sample0_world = {1.0, 1.0};
  alignment.world_per_height = 0.5;
  glm::dvec3 peak;
  ASSERT_TRUE(highestPoint(source, alignment, &peak).ok());
  // The highest sample, by looking at every one (the hills' slope moves it
  // a few samples off the bump's centre).
  const size_t top = size_t(std::max_element(f.samples.begin(), f.samples.end()) - f.samples.begin());
  EXPECT_NEAR(double(top % 1024), 301.0, 8.0);
  EXPECT_DOUBLE_EQ(peak.x, 1.0 + 2.0 * double(top % 1024));
  EXPECT_DOUBLE_EQ(peak.z, 1.0 + 2.0 * double(top / 1024));
  EXPECT_DOUBLE_EQ(peak.y, 0.5 * double(f.samples[top]));
}

TEST(LookAt, TheNamedPointIsAtTheCentreOfTheFrameOnTheGround) {
  CLIPSTREAM_REQUIRE_GL();
  // A 1024^2 field (2 world units a sample) under a 2048^2 image whose
  // georeference puts texel (x, y) at map (500000 + x / 2, 4000000 - y / 2).
  GeoReference geo;
  geo.present = true;
  const double t[6] = {500000.0, 0.5, 0.0, 4000000.0, 0.0, -0.5};
  std::copy(t, t + 6, geo.transform);
  for (const glm::dvec2 target : {glm::dvec2(700.0, 900.0), glm::dvec2(1500.5, 1200.25)}) {
    TerrainScene s = makeScene(overField(1024.0, 1024.0, 500.0, 0.0, -0.5), 64, TerrainMethod::kClipmap,
                               smoothField(1024));
    TerrainLayerConfig layer;
    layer.source = std::make_shared<FieldSource>(s.field);
    layer.alignment = s.terrain->config().mapping;
    LookAt look;
    look.map = {t[0] + target.x * t[1], t[3] + target.y * t[5]};
    Camera camera;
    double camera_ground = 0.0;
    ASSERT_TRUE(aimAtMapPoint(look, geo, s.colour_source->geometry(), &layer, &camera, &camera_ground).ok());
    EXPECT_GT(camera.position.y, camera_ground) << "the camera above the ground";
    uploadRings(*s.terrain, s.field, camera);
    drawTerrain(s, camera);
    std::vector<float> xyzw;
    ASSERT_TRUE(s.terrain->readPositions(camera, kViewport, *s.colour, &xyzw).ok());
    // The pixels around the frame's centre (it falls between four).
    glm::dvec3 centre(0.0);
    for (uint32_t y : {kViewport.height_px / 2 - 1, kViewport.height_px / 2})
      for (uint32_t x : {kViewport.width_px / 2 - 1, kViewport.width_px / 2}) {
        const float* p = &xyzw[(size_t(y) * kViewport.width_px + x) * 4];
        ASSERT_GE(p[3], 1.0f) << "ground at the centre";
        centre += 0.25 * (glm::dvec3(p[0], p[1], p[2]) + camera.position);
      }
    // Within a texel of the point, on the ground there.
    EXPECT_NEAR(centre.x, target.x, 1.0);
    EXPECT_NEAR(centre.z, target.y, 1.0);
    double ground = 0.0;
    ASSERT_TRUE(groundHeightAt(*layer.source, layer.alignment, target, &ground).ok());
    EXPECT_NEAR(centre.y, ground, 0.5);
  }
}
