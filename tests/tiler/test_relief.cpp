// clipstream-tile --relief: a DEM drawn as a shaded colour relief.
#include "tiler_test_util.h"

#include <clipstream/store/tile_store.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

namespace clipstream::test {
namespace {

std::unique_ptr<TileStoreReader> openStore(const std::string& path) {
  std::unique_ptr<TileStoreReader> reader;
  if (!TileStoreReader::open(path, &reader)) return nullptr;
  return reader;
}

// A square pyramid on a 64x64 int16 DEM with 10 m samples: each face
// rises 10 m per sample (45 degrees) towards the summit (500 m) at (32, 32).
std::string writePyramidDem(const TempDir& dir) {
  const std::string dem = dir.file("d.tif");
  EXPECT_TRUE(writeImage(dem, 64, 64, 1, OIIO::TypeDesc::INT16, [](uint64_t x, uint64_t y, int) {
    const double dx = std::abs(double(x) - 32.0), dy = std::abs(double(y) - 32.0);
    return 500.0 - 10.0 * std::max(dx, dy);
  }));
  std::ofstream world(dir.file("d.tfw"));
  world << "10\n0\n0\n-10\n1005\n1995\n";  // upper-left pixel's centre at (1005, 1995)
  return dem;
}

// The RGB of pixel (x, y) of level 0 (one tile: the image is 128 px).
struct Rgb {
  int r, g, b;
  int sum() const { return r + g + b; }
};
Rgb pixel(const std::vector<uint8_t>& tile, uint32_t tile_px, uint32_t x, uint32_t y) {
  const uint8_t* p = &tile[(size_t(y) * tile_px + x) * 3];
  return {p[0], p[1], p[2]};
}

TEST(Relief, DrawsTheDemLitFromTheNorthWestAtTheAskedScale) {
  TempDir dir;
  const std::string dem = writePyramidDem(dir);
  const RunResult r = runTiler({dem, dir.file("r.cst"), "--relief", "--relief-scale", "2", "--no-fsync",
                                "--json-summary", dir.file("s.json")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("relief: shaded"), std::string::npos) << r.output;
  std::ifstream in(dir.file("s.json"));
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["relief_scale"], 2);
  EXPECT_EQ(j["layer"], "colour");

  auto reader = openStore(dir.file("r.cst"));
  ASSERT_TRUE(reader);
  const PyramidGeometry& g = reader->geometry();
  EXPECT_EQ(g.width_px, 128u);
  EXPECT_EQ(g.height_px, 128u);
  EXPECT_EQ(g.format, PixelFormat::kRGB8);
  EXPECT_FALSE(reader->info().elevation.present);
  // Georeferenced like the DEM, with pixels half its samples' size.
  const GeoReference& geo = reader->info().geo;
  ASSERT_TRUE(geo.present);
  EXPECT_DOUBLE_EQ(geo.transform[0], 1000.0);
  EXPECT_DOUBLE_EQ(geo.transform[3], 2000.0);
  EXPECT_DOUBLE_EQ(geo.transform[1], 5.0);
  EXPECT_DOUBLE_EQ(geo.transform[5], -5.0);

  std::vector<uint8_t> tile;
  ASSERT_TRUE(reader->readTile(TileKey{0, 0, 0}, &tile).ok());
  const uint32_t t = g.tile_px;
  // Sample (s) is drawn around pixel 2s + 0.5. Faces towards the light
  // (west, north) are brighter than those away from it (east, south), and
  // the two lit faces equally so (the light is between them).
  const Rgb west = pixel(tile, t, 32, 65), east = pixel(tile, t, 96, 65);
  const Rgb north = pixel(tile, t, 65, 32), south = pixel(tile, t, 65, 96);
  EXPECT_GT(west.sum(), east.sum() + 150) << west.sum() << " " << east.sum();
  EXPECT_GT(north.sum(), south.sum() + 150) << north.sum() << " " << south.sum();
  EXPECT_NEAR(west.sum(), north.sum(), 6);
  // The tint follows the height: the low corners are green, the ground
  // near the summit is lighter and less green.
  const Rgb low = pixel(tile, t, 2, 2), high = pixel(tile, t, 62, 58);
  EXPECT_GT(low.g, low.r) << low.r << " " << low.g;
  EXPECT_GT(low.g, low.b);
  EXPECT_LT(high.g - high.r, low.g - low.r);
}

TEST(Relief, RefusesWhatARelievedPictureCannotBe) {
  TempDir dir;
  const std::string dem = writePyramidDem(dir);
  RunResult r = runTiler({dem, dir.file("x.cst"), "--relief-scale", "2"});
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("--relief"), std::string::npos) << r.output;
  r = runTiler({dem, dir.file("x.cst"), "--relief", "--relief-scale", "65"});
  EXPECT_EQ(r.exit_code, 2) << r.output;
  for (const std::vector<std::string>& extra :
       {std::vector<std::string>{"--format", "RGB8"}, {"--layer", "colour"}, {"--shard", "1/2"}}) {
    std::vector<std::string> args = {dem, dir.file("x.cst"), "--relief"};
    args.insert(args.end(), extra.begin(), extra.end());
    r = runTiler(args);
    EXPECT_EQ(r.exit_code, 2) << extra[0] << ": " << r.output;
    EXPECT_NE(r.output.find(extra[0]), std::string::npos) << r.output;
  }
  const std::string rgb = dir.file("c.tif");
  ASSERT_TRUE(writeImage(rgb, 32, 32, 3, OIIO::TypeDesc::UINT8, [](uint64_t x, uint64_t, int) {
    return double(x);
  }));
  r = runTiler({rgb, dir.file("x.cst"), "--relief"});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("single-band"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.cst")));
}

}  // namespace
}  // namespace clipstream::test
