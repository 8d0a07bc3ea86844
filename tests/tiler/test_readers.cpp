// The tiler's own TIFF, JPEG and PNG readers (tiler/src/native_source.h)
// against OpenImageIO: for each kind of file, tiling it with --reader auto
// gives the tiles tiling it with --reader openimageio gives, and the summary
// names the reader that decoded it (a silent fall-back to OpenImageIO would
// fail). Files the readers leave alone are still tiled, by OpenImageIO.
#include "tiler_test_util.h"

#include <clipstream/testing/files.h>
#include <clipstream/testing/sanitizers.h>
#include <clipstream/testing/test_data.h>
#include <clipstream/tiler/image_source.h>
#include <clipstream/tiler/tiler.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>

namespace clipstream::test {
namespace {

double pattern(uint64_t x, uint64_t y, int c) {
  return double((x * 131 + y * 71 + uint64_t(c) * 29 + ((x * y) >> 3)) & 255);
}

struct Case {
  const char* name;
  const char* file;  // its extension picks OIIO's writer
  uint64_t w, h;
  int channels;
  OIIO::TypeDesc type;
  int tile_px;
  std::function<void(OIIO::ImageSpec&)> configure;
  const char* decoder;  // the summary's decoder with --reader auto
  double scale = 1.0;   // sample = pattern * scale (+ offset)
  double offset = 0.0;
};

std::ostream& operator<<(std::ostream& os, const Case& c) { return os << c.name; }

TilerSummary tileWith(const std::string& in, const std::string& out, ImageReader reader,
                      uint64_t budget_mb = 256, unsigned threads = 2) {
  TilerOptions o;
  o.input_path = in;
  o.output_path = out;
  o.tile_px = 64;
  o.threads = threads;
  o.fsync = false;
  o.reader = reader;
  o.memory_budget_bytes = budget_mb << 20;
  TilerSummary summary;
  const Status s = tileImage(o, &summary);
  EXPECT_TRUE(s.ok()) << in << ": " << s.toString();
  return summary;
}

class Readers : public ::testing::TestWithParam<Case> {};

TEST_P(Readers, GiveOpenImageIosTiles) {
  const Case& c = GetParam();
  TempDir dir;
  const std::string in = dir.file(c.file);
  ASSERT_TRUE(writeImage(in, c.w, c.h, c.channels, c.type,
                         [&](uint64_t x, uint64_t y, int ch) { return pattern(x, y, ch) * c.scale + c.offset; },
                         c.tile_px, c.configure));
  const TilerSummary ours = tileWith(in, dir.file("ours.cst"), ImageReader::kAuto);
  const TilerSummary oiio = tileWith(in, dir.file("oiio.cst"), ImageReader::kOpenImageIO);
  EXPECT_EQ(ours.decoder, c.decoder);
  EXPECT_EQ(oiio.decoder, "openimageio");
  EXPECT_EQ(ours.input_type, oiio.input_type);
  EXPECT_EQ(ours.format, oiio.format);
  EXPECT_EQ(ours.clamped_samples, oiio.clamped_samples);
  expectSameTiles(dir.file("oiio.cst"), dir.file("ours.cst"));
}

auto set(const char* key, const char* value) {
  return [=](OIIO::ImageSpec& s) { s.attribute(key, value); };
}
auto setInt(const char* key, int value) {
  return [=](OIIO::ImageSpec& s) { s.attribute(key, value); };
}

const OIIO::TypeDesc kU8 = OIIO::TypeDesc::UINT8, kU16 = OIIO::TypeDesc::UINT16,
                     kI16 = OIIO::TypeDesc::INT16, kF32 = OIIO::TypeDesc::FLOAT,
                     kF64 = OIIO::TypeDesc::DOUBLE;

INSTANTIATE_TEST_SUITE_P(
    Kinds, Readers,
    ::testing::Values(
        Case{"TiffRgbStrips", "a.tif", 301, 257, 3, kU8, 0, set("compression", "none"), "libtiff"},
        Case{"TiffRgbTiledDeflate", "a.tif", 300, 200, 3, kU8, 64, set("compression", "zip"), "libtiff"},
        Case{"TiffRgbaLzw", "a.tif", 257, 131, 4, kU8, 0, set("compression", "lzw"), "libtiff"},
        Case{"TiffGreyAlpha", "a.tif", 130, 70, 2, kU8, 32, set("compression", "zip"), "libtiff"},
        Case{"TiffGrey16Tiled", "a.tif", 200, 190, 1, kU16, 48, set("compression", "zip"), "libtiff", 250.0},
        Case{"TiffRgb16Strips", "a.tif", 150, 140, 3, kU16, 0, set("compression", "lzw"), "libtiff", 251.0},
        Case{"TiffInt16Elevation", "a.tif", 190, 170, 1, kI16, 0, set("compression", "zip"), "libtiff", 40.0, -3000.0},
        Case{"TiffFloatClamped", "a.tif", 140, 120, 1, kF32, 16, set("compression", "zip"), "libtiff", 1.0 / 200.0, -0.1},
        Case{"TiffDoubleRgb", "a.tif", 90, 80, 3, kF64, 0, set("compression", "none"), "libtiff", 1.0 / 255.0},
        Case{"TiffJpegStrips", "a.tif", 200, 150, 3, kU8, 0, set("compression", "jpeg"), "libtiff"},
        Case{"BigTiff", "a.tif", 170, 90, 3, kU8, 32,
             [](OIIO::ImageSpec& s) { s.attribute("tiff:bigtiff", 1); s.attribute("compression", "zip"); },
             "libtiff"},
        Case{"TiffSeparatePlanesGoToOpenImageIo", "a.tif", 120, 100, 3, kU8, 0,
             set("planarconfig", "separate"), "openimageio"},
        Case{"JpegBaseline", "a.jpg", 333, 222, 3, kU8, 0, setInt("Compression", 90), "libjpeg"},
        Case{"JpegGrey", "a.jpg", 201, 199, 1, kU8, 0, {}, "libjpeg"},
        Case{"JpegProgressive", "a.jpg", 400, 300, 3, kU8, 0, setInt("jpeg:progressive", 1), "libjpeg"},
        Case{"PngRgb", "a.png", 211, 173, 3, kU8, 0, {}, "libpng"},
        Case{"PngRgba", "a.png", 99, 77, 4, kU8, 0, {}, "libpng"},
        Case{"PngGrey16", "a.png", 120, 110, 1, kU16, 0, {}, "libpng", 257.0},
        Case{"PngGreyAlpha16", "a.png", 64, 100, 2, kU16, 0, {}, "libpng", 200.0}),
    [](const ::testing::TestParamInfo<Case>& c) { return std::string(c.param.name); });

// The real GeoTIFFs (colour, int16 and float DEMs with no-data): the same
// tiles through libtiff as through OpenImageIO.
TEST(Readers, RealGeoTiffsGiveOpenImageIosTiles) {
  std::vector<std::string> inputs = {bundledDataPath("mount_st_helens_30m.tif")};
  for (const char* name : {"RGB.byte.tif", "mt_rainier_90m.tif"}) {
    if (!sharedDataPath(name).empty()) inputs.push_back(sharedDataPath(name));
  }
  for (const std::string& in : inputs) {
    SCOPED_TRACE(in);
    TempDir dir;
    const TilerSummary ours = tileWith(in, dir.file("ours.cst"), ImageReader::kAuto);
    tileWith(in, dir.file("oiio.cst"), ImageReader::kOpenImageIO);
    EXPECT_EQ(ours.decoder, "libtiff");
    expectSameTiles(dir.file("oiio.cst"), dir.file("ours.cst"));
  }
  if (inputs.size() < 3) GTEST_SKIP() << "St Helens passed; " << sharedDataAbsent("RGB.byte.tif");
}

// clipstream-tile's JSON summary of tiling `in` with extra `args`: a child
// process, so that the memory plan sees the program's own memory (this test
// binary links OpenImageIO).
nlohmann::json tileCli(const TempDir& dir, const std::string& in, const std::string& out,
                       std::vector<std::string> args) {
  const std::string json = dir.file("summary.json");
  std::vector<std::string> all = {in, out, "-f", "-q", "--no-fsync", "--tile-size", "64",
                                  "--json-summary", json};
  all.insert(all.end(), args.begin(), args.end());
  const RunResult r = runTiler(all);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  if (r.exit_code != 0) return nlohmann::json::object();
  std::ifstream f(json);
  return nlohmann::json::parse(f);
}

// A progressive JPEG whose coefficients would take more than a quarter of
// the budget is decoded through a temporary file, within the budget, with
// OpenImageIO's tiles.
TEST(Readers, ProgressiveJpegOverTheBudgetSpillsItsCoefficients) {
  if (kSanitized) GTEST_SKIP() << "memory budgets do not hold under sanitizers";
  TempDir dir;
  const std::string in = dir.file("big.jpg");
  // 4096 x 3072 at 4:2:0: 36 MiB of coefficients, over a quarter of the
  // 64 MiB budget; OpenImageIO alone would hold them all.
  ASSERT_TRUE(writeImage(in, 4096, 3072, 3, kU8, pattern, 0, setInt("jpeg:progressive", 1)));
  const nlohmann::json small = tileCli(dir, in, dir.file("small.cst"), {"--memory-mb", "64"});
  EXPECT_EQ(small.value("decoder", ""), "libjpeg, coefficients in a temporary file");
  EXPECT_LT(small.value("peak_rss_bytes", uint64_t(0)), uint64_t(64) << 20);
  const nlohmann::json roomy = tileCli(dir, in, dir.file("roomy.cst"), {"--memory-mb", "512"});
  EXPECT_EQ(roomy.value("decoder", ""), "libjpeg");
  tileCli(dir, in, dir.file("oiio.cst"), {"--reader", "openimageio"});
  expectSameTiles(dir.file("oiio.cst"), dir.file("small.cst"));
  expectSameTiles(dir.file("oiio.cst"), dir.file("roomy.cst"));
}

// The reader alone, so that sanitizer builds run it too: a progressive
// JPEG decoded with its coefficients in a temporary file gives the rows of
// one decoded with them in memory, read in strips and again from the top.
TEST(Readers, SpilledCoefficientsDecodeLikeHeldOnes) {
  TempDir dir;
  const std::string in = dir.file("p.jpg");
  // Luma alone is 9 MiB of coefficients: more than one window of the file.
  ASSERT_TRUE(writeImage(in, 1600, 2800, 3, kU8, pattern, 0, setInt("jpeg:progressive", 1)));
  auto decodeAll = [&](uint64_t budget_bytes, std::string* decoder) {
    ImageReadOptions read;
    read.memory_budget_bytes = budget_bytes;
    std::unique_ptr<ImageSource> src;
    const Status s = openImageFile(in, std::nullopt, &src, read);
    EXPECT_TRUE(s.ok()) << s.toString();
    std::vector<uint8_t> px(1600 * 2800 * 3);
    if (!s) return px;
    *decoder = src->info().decoder;
    for (uint64_t y = 0; y < 2800; y += 100) {
      EXPECT_TRUE(src->readRows(y, 100, 0, 1600, px.data() + y * 4800, 4800).ok());
    }
    // Back to the top: decoded again from the start, same rows.
    std::vector<uint8_t> again(4800 * 10);
    EXPECT_TRUE(src->readRows(5, 10, 0, 1600, again.data(), 4800).ok());
    EXPECT_TRUE(std::equal(again.begin(), again.end(), px.begin() + 5 * 4800));
    return px;
  };
  std::string spilled_by, held_by;
  const std::vector<uint8_t> spilled = decodeAll(uint64_t(4) << 20, &spilled_by);  // 12.8 MiB > 1 MiB
  const std::vector<uint8_t> held = decodeAll(0, &held_by);
  EXPECT_EQ(spilled_by, "libjpeg, coefficients in a temporary file");
  EXPECT_EQ(held_by, "libjpeg");
  EXPECT_TRUE(spilled == held);
}

// Bytes this process has handed to write() and pwrite() so far.
uint64_t bytesWritten() {
  std::ifstream io("/proc/self/io");
  std::string key;
  uint64_t value = 0;
  while (io >> key >> value) {
    if (key == "wchar:") return value;
  }
  return 0;
}

// A progressive JPEG cut short whose header claims a huge image: libjpeg
// would pad every block of every scan after the data runs out, writing
// gigabytes of zeros to the coefficient file before anyone saw the damage.
// The first sign of damage ends the read, naming the file, having written
// next to nothing.
TEST(Readers, AProgressiveJpegCutShortFailsAtItsFirstDamage) {
  TempDir dir;
  const std::string small = dir.file("small.jpg");
  ASSERT_TRUE(writeImage(small, 256, 256, 3, kU8, pattern, 0, setInt("jpeg:progressive", 1)));
  std::vector<uint8_t> bytes = readBytes(small);
  size_t sof = 0;
  for (size_t i = 0; i + 9 < bytes.size(); ++i) {
    if (bytes[i] == 0xFF && bytes[i + 1] == 0xC2) {
      sof = i;
      break;
    }
  }
  ASSERT_GT(sof, 0u) << "no progressive frame header";
  // Height and width: 20000 x 20000, 1.1 GiB of coefficients at 4:2:0.
  bytes[sof + 5] = bytes[sof + 7] = 20000 >> 8;
  bytes[sof + 6] = bytes[sof + 8] = 20000 & 255;
  bytes.resize(bytes.size() / 2);
  const std::string cut = dir.file("cut.jpg");
  writeBytes(cut, bytes);

  ImageReadOptions read;
  read.memory_budget_bytes = uint64_t(64) << 20;
  const uint64_t written_before = bytesWritten();
  std::unique_ptr<ImageSource> src;
  const Status s = openImageFile(cut, std::nullopt, &src, read);
  const uint64_t written = bytesWritten() - written_before;
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code, ErrorCode::kTruncated) << s.toString();
  EXPECT_NE(s.toString().find(cut), std::string::npos) << s.toString();
  EXPECT_NE(s.toString().find("damaged image data"), std::string::npos) << s.toString();
  EXPECT_LT(written, uint64_t(1) << 20) << "bytes written before the failure";
}

// Panels (a budget too small for the image's width) read each file in
// blocks of columns, going back up the image for every block: the tiles
// are those of one pass down, for every reader.
TEST(Readers, PanelReadsGiveTheTilesOfOnePass) {
  if (kSanitized) GTEST_SKIP() << "memory budgets do not hold under sanitizers";
  TempDir dir;
  struct File {
    const char* name;
    int channels, tile_px;
    const char* decoder;
  } files[] = {{"strips.tif", 4, 0, "libtiff"}, {"tiled.tif", 4, 128, "libtiff"},
               {"wide.png", 4, 0, "libpng"}, {"wide.jpg", 3, 0, "libjpeg"}};
  for (const File& f : files) {
    SCOPED_TRACE(f.name);
    const std::string in = dir.file(f.name);
    ASSERT_TRUE(writeImage(in, 40000, 300, f.channels, kU8, pattern, f.tile_px));
    const nlohmann::json whole = tileCli(dir, in, dir.file("whole.cst"), {});
    const nlohmann::json panels = tileCli(dir, in, dir.file("panels.cst"), {"--memory-mb", "36"});
    EXPECT_EQ(whole.value("panels", 0), 1);
    EXPECT_GT(panels.value("panels", 0), 1);
    EXPECT_EQ(panels.value("decoder", ""), f.decoder);
    expectSameTiles(dir.file("whole.cst"), dir.file("panels.cst"));
  }
}

// One decode thread and eight give the same tiles (the band logic does not
// depend on which thread decoded what).
TEST(Readers, TiffDecodeThreadsDoNotChangeTiles) {
  TempDir dir;
  const std::string in = dir.file("t.tif");
  ASSERT_TRUE(writeImage(in, 1000, 700, 3, kU8, pattern, 0, [](OIIO::ImageSpec& s) {
    s.attribute("compression", "zip");
    s.attribute("tiff:RowsPerStrip", 7);  // many strips per band, not aligned to the tiler's
  }));
  tileWith(in, dir.file("one.cst"), ImageReader::kAuto, 256, 1);
  tileWith(in, dir.file("eight.cst"), ImageReader::kAuto, 256, 8);
  expectSameTiles(dir.file("one.cst"), dir.file("eight.cst"));
}

// Tiles `in` into `out` with the defaults (no fsync): the run's status.
Status tileToFile(const std::string& in, const std::string& out, ImageReader reader = ImageReader::kAuto) {
  TilerOptions o;
  o.input_path = in;
  o.output_path = out;
  o.fsync = false;
  o.reader = reader;
  TilerSummary summary;
  return tileImage(o, &summary);
}

// Damage found by a decode worker is the run's error, naming the file.
TEST(Readers, DamagedTiffStripFailsTheRunNamingTheFile) {
  TempDir dir;
  const std::string in = dir.file("d.tif");
  ASSERT_TRUE(writeImage(in, 600, 400, 3, kU8, pattern, 0, set("compression", "zip")));
  // Overwrite the middle of the file (compressed strips) with garbage.
  std::vector<uint8_t> bytes = readBytes(in);
  for (size_t i = bytes.size() / 3; i < bytes.size() / 2; ++i) bytes[i] = uint8_t(i * 37);
  writeBytes(in, bytes);
  const Status s = tileToFile(in, dir.file("d.cst"));
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message.find("d.tif"), std::string::npos) << s.message;
  EXPECT_FALSE(std::filesystem::exists(dir.file("d.cst")));
}

// The (count, value) of tag `tag` in the first directory of a classic
// little-endian TIFF: where the entry lies, for a test to damage it.
size_t tiffEntry(const std::vector<uint8_t>& b, uint16_t tag) {
  auto u16 = [&](size_t at) { return uint16_t(b[at] | (b[at + 1] << 8)); };
  auto u32 = [&](size_t at) { return uint32_t(u16(at) | (uint32_t(u16(at + 2)) << 16)); };
  if (b.size() < 8 || b[0] != 'I' || u16(2) != 42) return 0;
  const size_t ifd = u32(4);
  for (size_t i = 0, n = u16(ifd); i < n; ++i) {
    const size_t at = ifd + 2 + 12 * i;
    if (u16(at) == tag) return at;
  }
  return 0;
}

// Damage libtiff only warns about: a StripOffsets tag with one value where
// the image needs one a row. libtiff ignores the tag and reads zeros; the
// run tiled 1,999 rows of zeros with exit 0. Now it is refused at open.
TEST(Readers, ATiffWhoseStripOffsetsTagIsIgnoredIsRefused) {
  TempDir dir;
  const std::string in = dir.file("s.tif");
  ASSERT_TRUE(writeImage(in, 300, 200, 1, kI16, pattern, 0, [](OIIO::ImageSpec& spec) {
    spec.attribute("compression", "none");
    spec.attribute("tiff:RowsPerStrip", 1);
  }));
  std::vector<uint8_t> bytes = readBytes(in);
  const size_t entry = tiffEntry(bytes, 273);  // StripOffsets
  ASSERT_NE(entry, 0u);
  const uint32_t count = 1;
  uint32_t array = 0;
  std::memcpy(&array, bytes.data() + entry + 8, 4);
  std::memcpy(bytes.data() + entry + 4, &count, 4);
  std::memcpy(bytes.data() + entry + 8, bytes.data() + array, 4);  // the one value inline
  writeBytes(in, bytes);
  // Whichever reader decodes it: OpenImageIO's drops libtiff's warning.
  for (ImageReader reader : {ImageReader::kAuto, ImageReader::kOpenImageIO}) {
    const Status s = tileToFile(in, dir.file("s.cst"), reader);
    ASSERT_FALSE(s.ok()) << (reader == ImageReader::kAuto ? "auto" : "openimageio");
    EXPECT_NE(s.message.find("s.tif: damaged TIFF"), std::string::npos) << s.message;
    EXPECT_NE(s.message.find("StripOffsets"), std::string::npos) << s.message;
    EXPECT_FALSE(std::filesystem::exists(dir.file("s.cst")));
  }
}

// A file cut short declares more data than it holds: refused before any
// work, naming the first strip or tile that is missing, compressed or not.
TEST(Readers, ATiffCutShortIsRefusedBeforeTheWorkStarts) {
  TempDir dir;
  for (const char* compression : {"none", "zip"}) {
    for (int tile : {0, 64}) {
      SCOPED_TRACE(std::string(compression) + (tile ? " tiled" : " strips"));
      const std::string in = dir.file("c.tif");
      ASSERT_TRUE(writeImage(in, 400, 300, 3, kU8, pattern, tile, set("compression", compression)));
      std::vector<uint8_t> bytes = readBytes(in);
      // The directory and its arrays come first (OpenImageIO writes them so):
      // keep them, and two thirds of the data.
      auto u16 = [&](size_t at) { return uint16_t(bytes[at] | (bytes[at + 1] << 8)); };
      auto u32 = [&](size_t at) { return uint32_t(u16(at) | (uint32_t(u16(at + 2)) << 16)); };
      const size_t ifd = u32(4);
      size_t header_end = ifd + 2 + 12 * size_t(u16(ifd)) + 4;
      for (size_t i = 0, n = u16(ifd); i < n; ++i) {
        const size_t at = ifd + 2 + 12 * i;
        const uint16_t type = u16(at + 2);
        const size_t size = (type == 3 ? 2 : type == 4 ? 4 : type == 5 || type == 12 ? 8 : 1) * size_t(u32(at + 4));
        if (size > 4) header_end = std::max(header_end, size_t(u32(at + 8)) + size);
      }
      const size_t keep = bytes.size() * 2 / 3;
      ASSERT_LT(header_end, keep);
      std::vector<uint8_t> cut(bytes.begin(), bytes.begin() + long(keep));
      writeBytes(in, cut);
      const Status s = tileToFile(in, dir.file("c.cst"));
      ASSERT_FALSE(s.ok());
      EXPECT_NE(s.message.find("c.tif: damaged TIFF: "), std::string::npos) << s.message;
      EXPECT_NE(s.message.find("beyond the end of the file"), std::string::npos) << s.message;
      EXPECT_FALSE(std::filesystem::exists(dir.file("c.cst")));
    }
  }
}

}  // namespace
}  // namespace clipstream::test
