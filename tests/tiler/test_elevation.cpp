// Elevation stores from DEMs: the conversion, the no-data fill, decimated
// levels, per-tile height bounds and geometric error, quantisation, and the
// command line's rules for them (docs/terrain.md, "Elevation stores").
#include "tiler_test_util.h"

#include <clipstream/testing/test_data.h>
#include <clipstream/tiler/tiler.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>

namespace clipstream::test {
namespace {

// Every sample of one level, as heights, row-major (level size, no padding).
std::vector<float> levelHeights(const TileStoreReader& reader, uint32_t level) {
  const PyramidGeometry& g = reader.geometry();
  const LevelInfo& info = g.levels[level];
  std::vector<float> out(size_t(info.width_px) * info.height_px);
  std::vector<float> tile(size_t(g.tile_px) * g.tile_px);
  for (uint32_t ty = 0; ty < info.tiles_y; ++ty) {
    for (uint32_t tx = 0; tx < info.tiles_x; ++tx) {
      RawTile raw;
      EXPECT_TRUE(reader.readRaw(TileKey{level, tx, ty}, &raw).ok());
      EXPECT_TRUE(decodeTileHeights(g, reader.info().encoding, reader.info().elevation, raw, tile).ok());
      for (uint32_t y = 0; y < g.tile_px; ++y) {
        const uint64_t gy = uint64_t(ty) * g.tile_px + y;
        if (gy >= info.height_px) break;
        for (uint32_t x = 0; x < g.tile_px; ++x) {
          const uint64_t gx = uint64_t(tx) * g.tile_px + x;
          if (gx >= info.width_px) break;
          out[gy * info.width_px + gx] = tile[size_t(y) * g.tile_px + x];
        }
      }
    }
  }
  return out;
}

// The input's first channel as doubles, read by OpenImageIO.
std::vector<double> readInput(const std::string& path, uint64_t* w, uint64_t* h) {
  auto in = OIIO::ImageInput::open(path);
  EXPECT_TRUE(in) << path;
  if (!in) return {};
  const OIIO::ImageSpec& spec = in->spec();
  *w = uint64_t(spec.width), *h = uint64_t(spec.height);
  std::vector<double> v(*w * *h);
  // Read in the file's own type: OpenImageIO rescales integers to [0, 1]
  // (or [-1, 1]) when asked for floating point.
  if (spec.format == OIIO::TypeDesc::INT16) {
    std::vector<int16_t> raw(v.size());
    EXPECT_TRUE(in->read_image(0, 0, 0, 1, OIIO::TypeDesc::INT16, raw.data()));
    std::copy(raw.begin(), raw.end(), v.begin());
  } else if (spec.format == OIIO::TypeDesc::UINT16) {
    std::vector<uint16_t> raw(v.size());
    EXPECT_TRUE(in->read_image(0, 0, 0, 1, OIIO::TypeDesc::UINT16, raw.data()));
    std::copy(raw.begin(), raw.end(), v.begin());
  } else {
    EXPECT_TRUE(in->read_image(0, 0, 0, 1, OIIO::TypeDesc::DOUBLE, v.data()));
  }
  return v;
}

std::unique_ptr<TileStoreReader> openStore(const std::string& path) {
  std::unique_ptr<TileStoreReader> reader;
  const Status s = TileStoreReader::open(path, &reader);
  EXPECT_TRUE(s.ok()) << s.toString();
  return reader;
}

// The checks every elevation store must pass against its level 0:
// decimated levels, bounds that hold every level-0 sample under a tile, and
// an error that bounds the distance of level-0 samples to the surface the
// level's samples span (interior of each tile's footprint).
void checkPyramid(const TileStoreReader& reader) {
  const PyramidGeometry& g = reader.geometry();
  const std::vector<float> h0 = levelHeights(reader, 0);
  const uint64_t w0 = g.levels[0].width_px, hh0 = g.levels[0].height_px;
  for (uint32_t l = 1; l < g.levelCount(); ++l) {
    const std::vector<float> hl = levelHeights(reader, l);
    const LevelInfo& info = g.levels[l];
    const uint64_t step = uint64_t(1) << l;
    for (uint64_t y = 0; y < info.height_px; ++y)
      for (uint64_t x = 0; x < info.width_px; ++x)
        ASSERT_EQ(hl[y * info.width_px + x], h0[(y * step) * w0 + x * step])
            << "level " << l << " sample (" << x << ", " << y << ") is not level 0's (" << x * step
            << ", " << y * step << ")";
  }
  for (uint32_t l = 0; l < g.levelCount(); ++l) {
    const LevelInfo& info = g.levels[l];
    const std::vector<float> hl = levelHeights(reader, l);
    const uint64_t step = uint64_t(1) << l;
    const uint64_t foot = uint64_t(g.tile_px) << l;
    for (uint32_t ty = 0; ty < info.tiles_y; ++ty) {
      for (uint32_t tx = 0; tx < info.tiles_x; ++tx) {
        TileLocation loc;
        ASSERT_TRUE(reader.locate(TileKey{l, tx, ty}, &loc).ok());
        if (l == 0) {
          EXPECT_EQ(loc.error, 0.0f);
        }
        float lo = INFINITY, hi = -INFINITY, dev = 0.0f;
        const uint64_t x0 = tx * foot, y0 = ty * foot;
        const uint64_t x1 = std::min(x0 + foot, w0), y1 = std::min(y0 + foot, hh0);
        for (uint64_t y = y0; y < y1; ++y) {
          for (uint64_t x = x0; x < x1; ++x) {
            const float v = h0[y * w0 + x];
            lo = std::min(lo, v), hi = std::max(hi, v);
            // The level's bilinear surface at (x, y), inside the footprint
            // away from its last cell (measured approximately there).
            const uint64_t cx = x / step, cy = y / step;
            if (l == 0 || x + step >= x1 || y + step >= y1 || cx + 1 >= info.width_px ||
                cy + 1 >= info.height_px)
              continue;
            const double fx = double(x - cx * step) / double(step);
            const double fy = double(y - cy * step) / double(step);
            auto at = [&](uint64_t i, uint64_t j) { return double(hl[j * info.width_px + i]); };
            const double s = (1 - fx) * (1 - fy) * at(cx, cy) + fx * (1 - fy) * at(cx + 1, cy) +
                             (1 - fx) * fy * at(cx, cy + 1) + fx * fy * at(cx + 1, cy + 1);
            dev = std::max(dev, float(std::abs(v - s)));
          }
        }
        EXPECT_LE(loc.min_height, lo) << "level " << l << " tile " << tx << "," << ty;
        EXPECT_GE(loc.max_height, hi) << "level " << l << " tile " << tx << "," << ty;
        EXPECT_GE(loc.error + 1e-3f, dev) << "level " << l << " tile " << tx << "," << ty;
      }
    }
  }
}

TEST(Elevation, RealDemWithNoDataTilesExactlyAndFillsTheHoles) {
  CLIPSTREAM_REQUIRE_SHARED_DATA("mount_st_helens_30m.tif");
  const std::string dem = sharedDataPath("mount_st_helens_30m.tif");
  TempDir dir;
  const RunResult r = runTiler({dem, dir.file("h.cst"), "--no-fsync", "--json-summary", dir.file("s.json")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(dir.file("s.json"));
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["layer"], "elevation");
  EXPECT_EQ(j["pixel_format"], "I16");

  // One vocabulary (docs/cli.md, "JSON outputs"): clipstream-info describes
  // the store it wrote under the same keys with the same values.
  const RunResult info = runInfo({"--json", dir.file("h.cst")}, ">" + dir.file("info.json"));
  ASSERT_EQ(info.exit_code, 0) << info.output;
  std::ifstream info_in(dir.file("info.json"));
  const nlohmann::json info_json = nlohmann::json::parse(info_in);
  for (const char* key : {"pixel_format", "layer", "levels", "width_px", "height_px", "georeference",
                          "elevation"}) {
    EXPECT_EQ(j[key], info_json[key]) << key;
  }
  ASSERT_TRUE(j["georeference"].is_object());
  EXPECT_FALSE(j["georeference"]["crs"].get<std::string>().empty());
  EXPECT_EQ(j["georeference"]["pixel_size"].size(), 2u);
  EXPECT_TRUE(j["elevation"]["nodata"].is_number());

  auto reader = openStore(dir.file("h.cst"));
  ASSERT_TRUE(reader);
  const ElevationInfo& e = reader->info().elevation;
  ASSERT_TRUE(e.present);
  EXPECT_EQ(reader->geometry().format, PixelFormat::kI16);
  EXPECT_EQ(reader->info().encoding.filter, DownsampleFilter::kDecimate);
  EXPECT_TRUE(e.has_nodata);
  EXPECT_EQ(e.nodata, -32767.0);
  EXPECT_FALSE(e.quantised);
  EXPECT_EQ(e.units, HeightUnits::kMetre);
  EXPECT_FALSE(e.units_assumed);  // GDAL's UNITTYPE says m

  uint64_t w = 0, h = 0;
  const std::vector<double> input = readInput(dem, &w, &h);
  const std::vector<float> stored = levelHeights(*reader, 0);
  ASSERT_EQ(stored.size(), input.size());
  uint64_t holes = 0;
  double lo = INFINITY, hi = -INFINITY;
  for (double v : input) {
    if (v == -32767.0) continue;
    lo = std::min(lo, v), hi = std::max(hi, v);
  }
  for (size_t i = 0; i < input.size(); ++i) {
    if (input[i] == -32767.0) {
      ++holes;
      // Filled from neighbours: inside the valid range, never a spike.
      EXPECT_GE(stored[i], lo) << i;
      EXPECT_LE(stored[i], hi) << i;
    } else {
      ASSERT_EQ(stored[i], input[i]) << "valid sample " << i << " changed";
    }
  }
  EXPECT_EQ(holes, 4151u);
  EXPECT_EQ(e.filled_samples, holes);
  EXPECT_EQ(e.min_height, lo);
  EXPECT_EQ(e.max_height, hi);
  checkPyramid(*reader);
}

TEST(Elevation, SrtmVoidsAreFilledAndBoundsHoldAtEveryLevel) {
  CLIPSTREAM_REQUIRE_SHARED_DATA("mt_rainier_90m.tif");
  TempDir dir;
  const RunResult r = runTiler({sharedDataPath("mt_rainier_90m.tif"), dir.file("r.cst"), "--no-fsync"});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto reader = openStore(dir.file("r.cst"));
  ASSERT_TRUE(reader);
  const ElevationInfo& e = reader->info().elevation;
  EXPECT_TRUE(e.units_assumed);  // SRTM files do not say
  EXPECT_GT(e.filled_samples, 0u);
  EXPECT_GE(e.min_height, 263.0);  // no -32768 spike survives
  EXPECT_LE(e.max_height, 4371.0);
  checkPyramid(*reader);
}

TEST(Elevation, FloatHeightsStoreExactlyOrQuantisedWithinTheStatedBound) {
  TempDir dir;
  const std::string tif = dir.file("f.tif");
  // A sloped surface with fractional heights and a NaN hole.
  ASSERT_TRUE(writeImage(tif, 300, 200, 1, OIIO::TypeDesc::FLOAT, [](uint64_t x, uint64_t y, int) {
    if (x >= 100 && x < 110 && y >= 50 && y < 53) return std::numeric_limits<double>::quiet_NaN();
    return 100.0 + 0.37 * double(x) - 0.21 * double(y) + 3.0 * std::sin(double(x * y) * 0.01);
  }));
  uint64_t w = 0, h = 0;
  const std::vector<double> input = readInput(tif, &w, &h);

  // No georeference: auto would tile colour, so the layer is asked for.
  RunResult r = runTiler({tif, dir.file("exact.cst"), "--layer", "elevation", "--no-fsync"});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("no georeference"), std::string::npos) << r.output;
  auto exact = openStore(dir.file("exact.cst"));
  ASSERT_TRUE(exact);
  EXPECT_EQ(exact->geometry().format, PixelFormat::kF32);
  EXPECT_EQ(exact->info().elevation.filled_samples, 30u);
  std::vector<float> stored = levelHeights(*exact, 0);
  for (size_t i = 0; i < input.size(); ++i) {
    if (std::isnan(input[i])) {
      EXPECT_TRUE(std::isfinite(stored[i]));
    } else {
      ASSERT_EQ(stored[i], float(input[i])) << i;
    }
  }
  checkPyramid(*exact);

  r = runTiler({tif, dir.file("q.cst"), "--layer", "elevation", "--height-step", "0.25", "--no-fsync"});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto quantised = openStore(dir.file("q.cst"));
  ASSERT_TRUE(quantised);
  const ElevationInfo& e = quantised->info().elevation;
  EXPECT_EQ(quantised->geometry().format, PixelFormat::kR16);
  EXPECT_TRUE(e.quantised);
  EXPECT_EQ(e.scale, 0.25);
  EXPECT_GT(e.max_error, 0.0);
  EXPECT_LE(e.max_error, 0.125 + 1e-9);
  stored = levelHeights(*quantised, 0);
  double worst = 0.0;
  for (size_t i = 0; i < input.size(); ++i) {
    if (!std::isnan(input[i])) worst = std::max(worst, std::abs(double(stored[i]) - input[i]));
  }
  EXPECT_LE(worst, 0.125 + 1e-4);
  EXPECT_NEAR(worst, e.max_error, 1e-4);
  checkPyramid(*quantised);
}

TEST(Elevation, NoDataGivenOnTheCommandLineIsFilledNotKept) {
  TempDir dir;
  const std::string tif = dir.file("u.tif");
  // UInt16 heights with a 20x20 block of 0 declared as no-data below: a
  // pit to 0 m if kept.
  ASSERT_TRUE(writeImage(tif, 160, 140, 1, OIIO::TypeDesc::UINT16, [](uint64_t x, uint64_t y, int) {
    if (x >= 60 && x < 80 && y >= 60 && y < 80) return 0.0;
    return 1000.0 + double(x) + double(y);
  }));
  const RunResult r = runTiler({tif, dir.file("u.cst"), "--layer", "elevation", "--nodata", "0",
                                "--vertical-units", "foot", "--no-fsync"});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto reader = openStore(dir.file("u.cst"));
  ASSERT_TRUE(reader);
  EXPECT_EQ(reader->geometry().format, PixelFormat::kR16);
  EXPECT_EQ(reader->info().elevation.units, HeightUnits::kFoot);
  EXPECT_EQ(reader->info().elevation.filled_samples, 400u);
  EXPECT_GE(reader->info().elevation.min_height, 1000.0);
  const std::vector<float> stored = levelHeights(*reader, 0);
  // A plane is filled close to itself (inverse-distance weighting of the
  // nearest rim samples along eight directions).
  for (uint64_t y = 60; y < 80; ++y)
    for (uint64_t x = 60; x < 80; ++x) EXPECT_NEAR(stored[y * 160 + x], 1000.0 + x + y, 12.0);
}

TEST(Elevation, CommandLineRefusesWhatHeightsCannotMean) {
  TempDir dir;
  const std::string grey16 = dir.file("g.tif"), rgb = dir.file("c.tif"), i16 = dir.file("i.tif");
  ASSERT_TRUE(writeImage(grey16, 64, 64, 1, OIIO::TypeDesc::INT16, [](uint64_t x, uint64_t, int) {
    return double(x) - 10.0;
  }));
  ASSERT_TRUE(writeImage(rgb, 64, 64, 3, OIIO::TypeDesc::UINT8, [](uint64_t x, uint64_t, int) {
    return double(x);
  }));
  // int16 is elevation by default, and colour when asked (negatives clamp as before).
  RunResult r = runTiler({grey16, dir.file("a.cst"), "--no-fsync"});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(openStore(dir.file("a.cst"))->info().elevation.present);
  EXPECT_EQ(openStore(dir.file("a.cst"))->info().elevation.min_height, -10.0);
  r = runTiler({grey16, dir.file("b.cst"), "--layer", "colour", "--no-fsync"});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(openStore(dir.file("b.cst"))->info().elevation.present);
  EXPECT_EQ(openStore(dir.file("b.cst"))->geometry().format, PixelFormat::kR16);

  r = runTiler({rgb, dir.file("x.cst"), "--layer", "elevation", "--no-fsync"});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("single-band"), std::string::npos) << r.output;
  r = runTiler({grey16, dir.file("x.cst"), "--height-step", "0.5", "--no-fsync"});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("stored exactly"), std::string::npos) << r.output;
  r = runTiler({grey16, dir.file("x.cst"), "--layer", "elevation", "--filter", "lanczos3"});
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = runTiler({grey16, dir.file("x.cst"), "--format", "RGB8", "--layer", "elevation"});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  r = runTiler({grey16, dir.file("x.cst"), "--height-step", "-1"});
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = runTiler({grey16, dir.file("x.cst"), "--nodata", "inf"});
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = runTiler({grey16, dir.file("x.cst"), "--vertical-units", "furlong"});
  EXPECT_EQ(r.exit_code, 2) << r.output;
  r = runTiler({"--synthetic", "64x64", "--format", "F32", dir.file("x.cst")});
  EXPECT_EQ(r.exit_code, 2) << r.output;
  // A no-data value no int16 sample can hold would turn no-data off unsaid.
  for (const char* nodata : {"1e30", "40000", "-32769", "2.5", "nan"}) {
    r = runTiler({grey16, dir.file("x.cst"), "--nodata", nodata, "--no-fsync"});
    EXPECT_EQ(r.exit_code, 1) << nodata << ": " << r.output;
    EXPECT_NE(r.output.find("no int16 sample can hold it"), std::string::npos) << r.output;
  }
  r = runTiler({grey16, dir.file("n.cst"), "--nodata", "-32768", "--no-fsync"});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("x.cst")));
  // Float heights cannot go into I16: the one format that holds them is named once.
  const std::string f32 = dir.file("f.tif");
  ASSERT_TRUE(writeImage(f32, 64, 64, 1, OIIO::TypeDesc::FLOAT, [](uint64_t x, uint64_t, int) {
    return double(x) * 0.5;
  }));
  r = runTiler({f32, dir.file("x.cst"), "--layer", "elevation", "--format", "I16", "--no-fsync"});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("exactly (use F32)"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("F32 or F32"), std::string::npos) << r.output;
  // R16 is a height format too: quantised float heights (with --height-step),
  // and refused, naming what holds them, for int16 heights it cannot hold.
  r = runTiler({f32, dir.file("q.cst"), "--layer", "elevation", "--format", "R16", "--height-step", "0.25",
                "--no-fsync"});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  r = runTiler({grey16, dir.file("x.cst"), "--layer", "elevation", "--format", "R16", "--no-fsync"});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_EQ(r.output.find("is a colour format"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("exactly (use I16 or F32)"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace clipstream::test
