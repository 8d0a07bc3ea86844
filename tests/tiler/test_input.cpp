// The tiler's input (tiler/src/input.h, elevation_input.h): which reader a
// file gets (by its first bytes, not its name), the errors of a file that
// is missing or no image, a mosaic sheet that is the output, when an input
// becomes an elevation store, and a relief drawn from a DEM.
#include "tiler_test_util.h"

#include "elevation_input.h"
#include "input.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

namespace clipstream::test {
namespace {

TilerOptions fileRun(const std::string& input, const std::string& output) {
  TilerOptions o;
  o.input_path = input;
  o.output_path = output;
  o.threads = 1;
  return o;
}

double pattern(uint64_t x, uint64_t y, int c) { return double((x * 3 + y * 5 + uint64_t(c) * 7) & 255); }

// World file of 2 m pixels whose top-left pixel centre is at (1001, 1999).
void writeWorldFile(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  ASSERT_NE(f, nullptr);
  std::fprintf(f, "2\n0\n0\n-2\n1001\n1999\n");
  std::fclose(f);
}

struct Opened {
  Status status;
  std::string decoder;
};

Opened openFirst(const std::string& path, ImageReader reader = ImageReader::kAuto) {
  TilerOptions o = fileRun(path, path + ".cst");
  o.reader = reader;
  TilerInput in;
  Opened r;
  r.status = openInputImage(o, &in);
  if (r.status) r.decoder = in.source->info().decoder;
  return r;
}

TEST(TilerInput, EachFormatGetsItsOwnReaderAndTheRestOpenImageIO) {
  TempDir dir("input");
  for (const char* name : {"a.tif", "a.png", "a.jpg", "a.bmp"}) {
    ASSERT_TRUE(writeImage(dir.file(name), 40, 30, 3, OIIO::TypeDesc::UINT8, pattern)) << name;
  }
  EXPECT_EQ(openFirst(dir.file("a.tif")).decoder, "libtiff");
  EXPECT_EQ(openFirst(dir.file("a.png")).decoder, "libpng");
  EXPECT_EQ(openFirst(dir.file("a.jpg")).decoder, "libjpeg");
  EXPECT_EQ(openFirst(dir.file("a.bmp")).decoder, "openimageio");
  // --reader openimageio takes every file.
  EXPECT_EQ(openFirst(dir.file("a.tif"), ImageReader::kOpenImageIO).decoder, "openimageio");
  EXPECT_EQ(openFirst(dir.file("a.png"), ImageReader::kOpenImageIO).decoder, "openimageio");
}

TEST(TilerInput, TheReaderFollowsTheFirstBytesNotTheName) {
  TempDir dir("input");
  ASSERT_TRUE(writeImage(dir.file("a.png"), 40, 30, 3, OIIO::TypeDesc::UINT8, pattern));
  std::filesystem::copy_file(dir.file("a.png"), dir.file("png-named.tif"));
  const Opened r = openFirst(dir.file("png-named.tif"));
  ASSERT_TRUE(r.status.ok()) << r.status.toString();
  EXPECT_EQ(r.decoder, "libpng");
}

TEST(TilerInput, AMissingFileAndAnUnknownFormatAreErrorsNamingTheFile) {
  TempDir dir("input");
  const Opened missing = openFirst(dir.file("missing.tif"));
  EXPECT_EQ(missing.status.code, ErrorCode::kNotFound);
  EXPECT_NE(missing.status.message.find("missing.tif"), std::string::npos) << missing.status.message;

  const std::string text = dir.file("notes.dat");
  std::ofstream(text) << "this is not an image at all, just some text\n";
  const Opened unknown = openFirst(text);
  EXPECT_EQ(unknown.status.code, ErrorCode::kIo);
  EXPECT_NE(unknown.status.message.find(text + ": cannot open image"), std::string::npos)
      << unknown.status.message;
}

TEST(TilerInput, NoInputPathIsTheSyntheticImageInTheFormatAskedFor) {
  TilerOptions o;
  o.synthetic_width_px = 300;
  o.synthetic_height_px = 200;
  o.format = PixelFormat::kRGBA8;
  o.output_path = "unused.cst";
  TilerInput in;
  std::vector<std::string> warnings;
  ASSERT_TRUE(openInput(o, &in, &warnings).ok());
  const SourceInfo& info = in.source->info();
  EXPECT_EQ(info.decoder, "synthetic");
  EXPECT_EQ(info.width_px, 300u);
  EXPECT_EQ(info.height_px, 200u);
  EXPECT_EQ(info.format, PixelFormat::kRGBA8);
  EXPECT_FALSE(in.elevation.present);
  EXPECT_EQ(in.heights, nullptr);
  EXPECT_FALSE(in.geo.present);
  EXPECT_TRUE(warnings.empty());
}

TEST(TilerInput, AFileComesWithTheGeoreferenceBesideIt) {
  TempDir dir("input");
  ASSERT_TRUE(writeImage(dir.file("a.png"), 40, 30, 3, OIIO::TypeDesc::UINT8, pattern));
  writeWorldFile(dir.file("a.pgw"));
  TilerInput in;
  ASSERT_TRUE(openInputImage(fileRun(dir.file("a.png"), dir.file("a.cst")), &in).ok());
  ASSERT_TRUE(in.geo.present);
  EXPECT_DOUBLE_EQ(in.geo.transform[0], 1000.0);  // the corner, a half pixel from the centre
  EXPECT_DOUBLE_EQ(in.geo.transform[1], 2.0);
  EXPECT_DOUBLE_EQ(in.geo.transform[3], 2000.0);
  EXPECT_DOUBLE_EQ(in.geo.transform[5], -2.0);
}

TEST(TilerInput, AMosaicWhoseSheetIsTheOutputIsRefused) {
  TempDir dir("input");
  const std::string sheet = dir.file("s.tif"), list = dir.file("sheets.txt");
  ASSERT_TRUE(writeImage(sheet, 40, 30, 3, OIIO::TypeDesc::UINT8, pattern));
  writeWorldFile(dir.file("s.tfw"));
  std::ofstream(list) << sheet << "\n";

  TilerOptions o = fileRun(list, dir.file("m.cst"));
  o.mosaic = true;
  TilerInput in;
  Status s = openInputImage(o, &in);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_EQ(in.source->info().decoder, "mosaic of libtiff");
  EXPECT_EQ(in.mosaic.sheets.size(), 1u);
  EXPECT_TRUE(in.geo.present);

  o.output_path = sheet;
  TilerInput again;
  s = openInputImage(o, &again);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(s.message.find("is the mosaic's sheet"), std::string::npos) << s.message;
}

SourceInfo samples(const std::string& type, uint32_t channels) {
  SourceInfo info;
  info.input_type = type;
  info.input_channels = channels;
  return info;
}

TEST(ElevationChoice, AutoTakesInt16AndGeoreferencedUint16OrFloatSingleBands) {
  TilerOptions o;
  GeoReference none, geo;
  geo.present = true;
  EXPECT_TRUE(wantsElevation(o, samples("int16", 1), none));
  EXPECT_FALSE(wantsElevation(o, samples("uint16", 1), none));
  EXPECT_TRUE(wantsElevation(o, samples("uint16", 1), geo));
  EXPECT_FALSE(wantsElevation(o, samples("float", 1), none));
  EXPECT_TRUE(wantsElevation(o, samples("float", 1), geo));
  EXPECT_TRUE(wantsElevation(o, samples("double", 1), geo));
  EXPECT_FALSE(wantsElevation(o, samples("uint8", 1), geo));
  EXPECT_FALSE(wantsElevation(o, samples("int16", 3), none));
  EXPECT_FALSE(wantsElevation(o, samples("float", 2), geo));
}

TEST(ElevationChoice, LayerAndFormatOverrideTheGuess) {
  GeoReference none;
  TilerOptions colour;
  colour.layer = LayerKind::kColour;
  EXPECT_FALSE(wantsElevation(colour, samples("int16", 1), none));
  TilerOptions elevation;
  elevation.layer = LayerKind::kElevation;
  EXPECT_TRUE(wantsElevation(elevation, samples("uint8", 3), none));
  TilerOptions height_format;
  height_format.format = PixelFormat::kF32;
  EXPECT_TRUE(wantsElevation(height_format, samples("uint8", 1), none));
  TilerOptions colour_format;
  colour_format.format = PixelFormat::kR16;  // grey colour unless the layer says otherwise
  EXPECT_FALSE(wantsElevation(colour_format, samples("int16", 1), none));
}

TEST(TilerInput, AnInt16DemIsReopenedAsHeights) {
  TempDir dir("input");
  const std::string tif = dir.file("dem.tif");
  ASSERT_TRUE(writeImage(tif, 50, 40, 1, OIIO::TypeDesc::INT16,
                         [](uint64_t x, uint64_t y, int) { return double(x) - double(y) - 100.0; }));
  TilerInput in;
  std::vector<std::string> warnings;
  const Status s = openInput(fileRun(tif, dir.file("dem.cst")), &in, &warnings);
  ASSERT_TRUE(s.ok()) << s.toString();
  ASSERT_TRUE(in.elevation.present);
  EXPECT_NE(in.heights, nullptr);
  EXPECT_EQ(static_cast<ImageSource*>(in.heights), in.source.get());
  EXPECT_EQ(in.source->info().format, PixelFormat::kI16);
  EXPECT_FALSE(in.elevation.quantised);
  EXPECT_EQ(in.elevation.units, HeightUnits::kMetre);
  EXPECT_TRUE(in.elevation.units_assumed);
  // The heights are the file's samples.
  std::vector<int16_t> row(50);
  ASSERT_TRUE(in.source->readRows(7, 1, 0, 50, reinterpret_cast<uint8_t*>(row.data()), 100).ok());
  EXPECT_EQ(row[0], -107);
  EXPECT_EQ(row[49], -58);
  // No georeference: said once.
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("the DEM has no georeference"), std::string::npos) << warnings[0];
}

TEST(TilerInput, HeightOptionsThatDoNotFitTheInputAreErrorsNamingIt) {
  TempDir dir("input");
  const std::string rgb = dir.file("c.tif"), dem = dir.file("i.tif");
  ASSERT_TRUE(writeImage(rgb, 32, 32, 3, OIIO::TypeDesc::UINT8, pattern));
  ASSERT_TRUE(writeImage(dem, 32, 32, 1, OIIO::TypeDesc::INT16,
                         [](uint64_t x, uint64_t, int) { return double(x); }));
  std::vector<std::string> warnings;
  TilerOptions step = fileRun(rgb, dir.file("c.cst"));
  step.height_step = 0.5;
  TilerInput in;
  Status s = openInput(step, &in, &warnings);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(s.message, rgb + ": --height-step applies to elevation stores, and this input is tiled "
                             "as colour (use --layer elevation)");

  TilerOptions bands = fileRun(rgb, dir.file("c.cst"));
  bands.layer = LayerKind::kElevation;
  TilerInput in2;
  s = openInput(bands, &in2, &warnings);
  EXPECT_EQ(s.code, ErrorCode::kUnsupported);
  EXPECT_EQ(s.message, rgb + ": 3 channels; an elevation store needs a single-band DEM");

  TilerOptions integer_step = fileRun(dem, dir.file("i.cst"));
  integer_step.height_step = 0.5;
  TilerInput in3;
  s = openInput(integer_step, &in3, &warnings);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(s.message.find("integer heights (int16) are stored exactly"), std::string::npos) << s.message;

  TilerOptions nodata = fileRun(dem, dir.file("i.cst"));
  nodata.nodata = 40000.0;
  TilerInput in4;
  s = openInput(nodata, &in4, &warnings);
  EXPECT_EQ(s.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(s.message.find("--nodata 40000: no int16 sample can hold it"), std::string::npos) << s.message;
}

TEST(TilerInput, AFloatDemWithAStepIsQuantisedFromItsLowestHeight) {
  TempDir dir("input");
  const std::string tif = dir.file("f.tif");
  ASSERT_TRUE(writeImage(tif, 40, 20, 1, OIIO::TypeDesc::FLOAT,
                         [](uint64_t x, uint64_t y, int) { return 10.25 + double(x) + double(y); }));
  TilerOptions o = fileRun(tif, dir.file("f.cst"));
  o.layer = LayerKind::kElevation;
  o.height_step = 0.5;
  TilerInput in;
  std::vector<std::string> warnings;
  const Status s = openInput(o, &in, &warnings);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_TRUE(in.elevation.quantised);
  EXPECT_DOUBLE_EQ(in.elevation.scale, 0.5);
  EXPECT_DOUBLE_EQ(in.elevation.offset, 10.0);  // floor(10.25 / 0.5) * 0.5
  EXPECT_EQ(in.source->info().format, PixelFormat::kR16);
}

TEST(TilerInput, AReliefIsAColourPictureOfTheDemAtItsScale) {
  TempDir dir("input");
  const std::string tif = dir.file("dem.tif");
  ASSERT_TRUE(writeImage(tif, 30, 20, 1, OIIO::TypeDesc::INT16,
                         [](uint64_t x, uint64_t y, int) { return double(x * 10 + y * 3); }));
  writeWorldFile(dir.file("dem.tfw"));
  TilerOptions o = fileRun(tif, dir.file("relief.cst"));
  o.relief_scale = 4;
  TilerInput in;
  std::vector<std::string> warnings;
  const Status s = openInput(o, &in, &warnings);
  ASSERT_TRUE(s.ok()) << s.toString();
  EXPECT_EQ(in.source->info().format, PixelFormat::kRGB8);
  EXPECT_EQ(in.source->info().width_px, 120u);
  EXPECT_EQ(in.source->info().height_px, 80u);
  EXPECT_FALSE(in.elevation.present);
  EXPECT_EQ(in.heights, nullptr);
  ASSERT_TRUE(in.geo.present);
  EXPECT_DOUBLE_EQ(in.geo.transform[1], 0.5);  // 2 m samples, 4 pixels each
  EXPECT_DOUBLE_EQ(in.geo.transform[5], -0.5);
  EXPECT_DOUBLE_EQ(in.geo.transform[0], 1000.0);
}

}  // namespace
}  // namespace clipstream::test
