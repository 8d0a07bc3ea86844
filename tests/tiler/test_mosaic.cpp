// Mosaics: sheets cut from the sample image, placed by their world files,
// tile to the store of the whole image; gaps take the fill value (and alpha
// 0), the later sheet wins where sheets overlap, and sheets that do not fit
// together are errors naming them.
#include "tiler_test_util.h"

#include <clipstream/testing/files.h>
#include <clipstream/testing/test_data.h>
#include <clipstream/tiler/mosaic.h>
#include <clipstream/tiler/shard.h>
#include <clipstream/tiler/tiler.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

namespace clipstream::test {
namespace {

// A 600 x 500 piece of autzen.jpg, decoded once, and a georeference with a
// pixel size that is not a power of two (so offsets are computed, not exact).
constexpr uint64_t kX = 1200, kY = 1700, kW = 600, kH = 500;
constexpr double kPixel = 0.3048;
constexpr double kOriginX = 635615.9278659122, kOriginY = 853362.1430851521;  // corner

struct Rect {
  uint64_t x, y, w, h;
};

class Mosaic : public ::testing::Test {
 protected:
  void SetUp() override {
    RefImage full;
    ASSERT_TRUE(readImage8(bundledDataPath("autzen.jpg"), &full)) << bundledDataPath("autzen.jpg");
    ASSERT_GE(full.width, kX + kW);
    ASSERT_GE(full.height, kY + kH);
    m_image.width = kW;
    m_image.height = kH;
    m_image.channels = 3;
    for (uint64_t y = 0; y < kH; ++y) {
      for (uint64_t x = 0; x < kW; ++x) {
        for (uint32_t c = 0; c < 3; ++c) m_image.samples.push_back(full.at(kX + x, kY + y, c));
      }
    }
  }

  // Writes `rect` of `image` (or of a function of it) as an image file with
  // a world file, the way a delivery comes.
  void writeSheet(const std::string& name, const Rect& r, const std::string& world_ext = ".wld",
                  double pixel = kPixel, double shift_px = 0.0,
                  const std::function<double(uint64_t, uint64_t, int)>& sample = {}, int channels = 3) {
    auto px = sample ? sample : [&](uint64_t x, uint64_t y, int c) {
      return double(m_image.at(x, y, uint32_t(c)));
    };
    ASSERT_TRUE(writeImage(m_dir.file(name), r.w, r.h, channels, OIIO::TypeDesc::UINT8,
                           [&](uint64_t x, uint64_t y, int c) {
                             return c < 3 ? px(r.x + x, r.y + y, c) : 255.0;
                           }));
    const std::string stem = name.substr(0, name.rfind('.'));
    std::FILE* f = std::fopen(m_dir.file(stem + world_ext).c_str(), "w");
    ASSERT_NE(f, nullptr);
    // Centre of the top-left pixel, as world files say.
    std::fprintf(f, "%.10f\n0\n0\n%.10f\n%.10f\n%.10f\n", pixel, -pixel,
                 kOriginX + (double(r.x) + shift_px + 0.5) * kPixel,
                 kOriginY - (double(r.y) + 0.5) * kPixel);
    std::fclose(f);
  }

  void writeList(const std::string& name, const std::vector<std::string>& lines) {
    std::ofstream out(m_dir.file(name));
    for (const std::string& l : lines) out << l << "\n";
  }

  // The whole piece through an image callback, as one georeferenced file.
  void writeWhole(const std::string& name,
                  const std::function<double(uint64_t, uint64_t, int)>& sample = {},
                  int channels = 3) {
    writeSheet(name, {0, 0, kW, kH}, ".wld", kPixel, 0.0, sample, channels);
  }

  // The six sheets of a 3 x 2 grid cut unevenly, listed out of order with a
  // comment, a blank line and one PNG sheet (its world file .pgw).
  std::vector<std::string> gridSheets() {
    const uint64_t xs[] = {0, 250, 410, kW}, ys[] = {0, 190, kH};
    std::vector<std::string> names;
    for (int r = 0; r < 2; ++r) {
      for (int c = 0; c < 3; ++c) {
        const bool png = r == 1 && c == 1;
        const std::string name =
            "sheet_" + std::to_string(r) + std::to_string(c) + (png ? ".png" : ".tif");
        writeSheet(name, {xs[c], ys[r], xs[c + 1] - xs[c], ys[r + 1] - ys[r]}, png ? ".pgw" : ".wld");
        names.push_back(name);
      }
    }
    std::swap(names[0], names[4]);
    names.insert(names.begin() + 2, "# a delivery, six sheets");
    names.insert(names.begin() + 3, "");
    return names;
  }

  TilerOptions run(const std::string& input, const std::string& output, bool mosaic) {
    TilerOptions o;
    o.input_path = m_dir.file(input);
    o.output_path = m_dir.file(output);
    o.mosaic = mosaic;
    o.tile_px = 64;
    o.threads = 2;
    o.fsync = false;
    return o;
  }

  void tile(const TilerOptions& o, TilerSummary* summary = nullptr) {
    TilerSummary local;
    const Status s = tileImage(o, summary ? summary : &local);
    ASSERT_TRUE(s.ok()) << s.toString();
  }

  // Runs the tiler expecting exit 1 with `needle` in its output and nothing
  // left behind; returns the output.
  std::string expectFailure(const std::vector<std::string>& args, const std::string& needle) {
    const std::vector<std::string> before = m_dir.entries();
    const RunResult r = runTiler(args);
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find(needle), std::string::npos) << r.output;
    EXPECT_EQ(m_dir.entries(), before) << "left behind in " << m_dir.path();
    return r.output;
  }

  TempDir m_dir{"mosaic"};
  RefImage m_image;
};

TEST_F(Mosaic, SheetsGiveTheStoreOfTheWholeImage) {
  writeWhole("whole.tif");
  writeList("sheets.txt", gridSheets());
  tile(run("whole.tif", "whole.cst", false));
  TilerSummary summary;
  tile(run("sheets.txt", "mosaic.cst", true), &summary);
  EXPECT_EQ(summary.mosaic_sheets, 6u);
  EXPECT_EQ(summary.gap_px, 0u);
  expectSameTiles(m_dir.file("whole.cst"), m_dir.file("mosaic.cst"));
  std::unique_ptr<TileStoreReader> whole, mosaic;
  ASSERT_TRUE(TileStoreReader::open(m_dir.file("whole.cst"), &whole).ok());
  ASSERT_TRUE(TileStoreReader::open(m_dir.file("mosaic.cst"), &mosaic).ok());
  ASSERT_TRUE(mosaic->info().geo.present);
  for (int i = 0; i < 6; ++i) {
    EXPECT_NEAR(mosaic->info().geo.transform[i], whole->info().geo.transform[i], 1e-6) << i;
  }
}

TEST_F(Mosaic, GapsTakeTheFillValueAndAlphaZero) {
  std::vector<std::string> sheets = gridSheets();
  sheets.erase(std::find(sheets.begin(), sheets.end(), "sheet_01.tif"));  // x 250..410, y 0..190
  writeList("sheets.txt", sheets);
  auto in_hole = [](uint64_t x, uint64_t y) { return x >= 250 && x < 410 && y < 190; };
  writeWhole("rgb.tif", [&](uint64_t x, uint64_t y, int c) {
    return in_hole(x, y) ? 7.0 : double(m_image.at(x, y, uint32_t(c)));
  });
  for (bool alpha : {false, true}) {
    TilerOptions m = run("sheets.txt", alpha ? "m4.cst" : "m3.cst", true);
    m.fill = 7;
    if (alpha) m.format = PixelFormat::kRGBA8;
    TilerSummary summary;
    tile(m, &summary);
    EXPECT_EQ(summary.gap_px, 160u * 190u);
    if (!alpha) {
      tile(run("rgb.tif", "ref3.cst", false));
      expectSameTiles(m_dir.file("ref3.cst"), m.output_path);
    } else {
      // The reference: RGBA with alpha 0 over the hole, written directly.
      ASSERT_TRUE(writeImage(m_dir.file("ref4.tif"), kW, kH, 4, OIIO::TypeDesc::UINT8,
                             [&](uint64_t x, uint64_t y, int c) {
                               if (c == 3) return in_hole(x, y) ? 0.0 : 255.0;
                               return in_hole(x, y) ? 7.0 : double(m_image.at(x, y, uint32_t(c)));
                             }));
      TilerOptions r = run("ref4.tif", "ref4.cst", false);
      tile(r);
      expectSameTiles(r.output_path, m.output_path);
    }
  }
  // A fill the format cannot hold.
  TilerOptions big = run("sheets.txt", "big.cst", true);
  big.fill = 300;
  TilerSummary summary;
  const Status s = tileImage(big, &summary);
  EXPECT_NE(s.message.find("--fill 300"), std::string::npos) << s.toString();
}

TEST_F(Mosaic, LaterSheetWinsWhereSheetsOverlap) {
  const Rect patch{200, 150, 150, 120};  // over four sheets
  auto inverted = [&](uint64_t x, uint64_t y, int c) {
    return 255.0 - double(m_image.at(x, y, uint32_t(c)));
  };
  writeSheet("patch.tif", patch, ".wld", kPixel, 0.0, inverted);
  std::vector<std::string> sheets = gridSheets();
  sheets.push_back("patch.tif");
  writeList("last.txt", sheets);
  sheets.insert(sheets.begin(), "patch.tif");
  sheets.pop_back();
  writeList("first.txt", sheets);
  auto in_patch = [&](uint64_t x, uint64_t y) {
    return x >= patch.x && x < patch.x + patch.w && y >= patch.y && y < patch.y + patch.h;
  };
  writeWhole("patched.tif", [&](uint64_t x, uint64_t y, int c) {
    return in_patch(x, y) ? inverted(x, y, c) : double(m_image.at(x, y, uint32_t(c)));
  });
  writeWhole("whole.tif");
  tile(run("patched.tif", "patched.cst", false));
  tile(run("whole.tif", "whole.cst", false));
  tile(run("last.txt", "last.cst", true));
  tile(run("first.txt", "first.cst", true));
  expectSameTiles(m_dir.file("patched.cst"), m_dir.file("last.cst"));
  expectSameTiles(m_dir.file("whole.cst"), m_dir.file("first.cst"));
}

// A VRT of simple sources, as gdalbuildvrt writes one (three bands, each
// naming every sheet), written here by hand: the same mosaic as the list.
std::string vrtText(const std::vector<std::pair<std::string, Rect>>& sheets,
                    const std::string& source = "SimpleSource", uint64_t src_x = 0) {
  std::string t = "<VRTDataset rasterXSize=\"600\" rasterYSize=\"500\">\n";
  for (int band = 1; band <= 3; ++band) {
    t += "  <VRTRasterBand dataType=\"Byte\" band=\"" + std::to_string(band) + "\">\n";
    for (const auto& [name, r] : sheets) {
      const std::string size = "xSize=\"" + std::to_string(r.w) + "\" ySize=\"" + std::to_string(r.h) + "\"";
      t += "    <" + source + ">\n      <SourceFilename relativeToVRT=\"1\">" + name +
           "</SourceFilename>\n      <SourceBand>" + std::to_string(band) +
           "</SourceBand>\n      <SrcRect xOff=\"" + std::to_string(src_x) + "\" yOff=\"0\" " + size +
           " />\n      <DstRect xOff=\"" + std::to_string(r.x) + "\" yOff=\"" + std::to_string(r.y) +
           "\" " + size + " />\n    </" + source + ">\n";
    }
    t += "  </VRTRasterBand>\n";
  }
  return t + "</VRTDataset>\n";
}

TEST_F(Mosaic, VrtOfSimpleSourcesIsTheSameMosaic) {
  writeWhole("whole.tif");
  const uint64_t xs[] = {0, 250, 410, kW}, ys[] = {0, 190, kH};
  std::vector<std::pair<std::string, Rect>> sheets;
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) {
      const Rect rect{xs[c], ys[r], xs[c + 1] - xs[c], ys[r + 1] - ys[r]};
      const std::string name = "v" + std::to_string(r) + std::to_string(c) + ".tif";
      writeSheet(name, rect);
      sheets.emplace_back(name, rect);
    }
  }
  { std::ofstream(m_dir.file("sheets.vrt")) << vrtText(sheets); }
  tile(run("whole.tif", "whole.cst", false));
  TilerSummary summary;
  tile(run("sheets.vrt", "vrt.cst", true), &summary);
  EXPECT_EQ(summary.mosaic_sheets, 6u);
  expectSameTiles(m_dir.file("whole.cst"), m_dir.file("vrt.cst"));
  // What a VRT can do beyond placing whole sheets is refused, naming it.
  { std::ofstream(m_dir.file("complex.vrt")) << vrtText(sheets, "ComplexSource"); }
  expectFailure({"--mosaic", m_dir.file("complex.vrt"), m_dir.file("o.cst")},
                "complex.vrt line 3: ComplexSource is not a simple source");
  { std::ofstream(m_dir.file("part.vrt")) << vrtText(sheets, "SimpleSource", 5); }
  expectFailure({"--mosaic", m_dir.file("part.vrt"), m_dir.file("o.cst")}, "draws part of");

  // Valid XML however it starts: a declaration, a comment, a byte order mark.
  const std::string vrt = vrtText(sheets);
  { std::ofstream(m_dir.file("prolog.vrt")) << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<!-- by hand -->\n" << vrt; }
  { std::ofstream(m_dir.file("bom.vrt")) << "\xEF\xBB\xBF" << vrt; }
  for (const char* name : {"prolog.vrt", "bom.vrt"}) {
    tile(run(name, std::string(name) + ".cst", true));
    expectSameTiles(m_dir.file("whole.cst"), m_dir.file(std::string(name) + ".cst"));
  }
  // Malformed XML is named as such, with libxml2's complaint and line.
  auto lineAt = [&](size_t at) { return std::to_string(std::count(vrt.begin(), vrt.begin() + long(at), '\n') + 1); };
  std::string mismatched = vrt;
  const size_t wrong = mismatched.find("</VRTRasterBand>");
  mismatched.replace(wrong, 16, "</VRTRasterBnad>");
  { std::ofstream(m_dir.file("mismatched.vrt")) << mismatched; }
  expectFailure({"--mosaic", m_dir.file("mismatched.vrt"), m_dir.file("o.cst")},
                "mismatched.vrt line " + lineAt(wrong) + ": not a well-formed VRT: Opening and ending tag mismatch");
  { std::ofstream(m_dir.file("unclosed.vrt")) << vrt.substr(0, vrt.rfind("</VRTDataset>")); }
  expectFailure({"--mosaic", m_dir.file("unclosed.vrt"), m_dir.file("o.cst")},
                ": not a well-formed VRT: Premature end of data in tag VRTDataset");
  { std::ofstream(m_dir.file("truncated.vrt")) << vrt.substr(0, vrt.size() / 2); }
  const std::string truncated =
      expectFailure({"--mosaic", m_dir.file("truncated.vrt"), m_dir.file("o.cst")}, "not a well-formed VRT");
  EXPECT_EQ(truncated.find("other sources"), std::string::npos) << truncated;
  { std::ofstream(m_dir.file("other.vrt")) << "<?xml version=\"1.0\"?>\n<svg/>\n"; }
  expectFailure({"--mosaic", m_dir.file("other.vrt"), m_dir.file("o.cst")},
                "other.vrt line 2: not a well-formed VRT: the root element is <svg>, not <VRTDataset>");
  EXPECT_FALSE(std::filesystem::exists(m_dir.file("o.cst")));
}

size_t openFiles() {
  size_t n = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator("/proc/self/fd")) ++n;
  return n;
}

// 3 x 20 sheets of 40 x 20 px: reading the mosaic top to bottom in strips
// keeps only the sheets under the strip open (each open sheet holds its
// file), never the whole list.
TEST_F(Mosaic, OnlyTheSheetsUnderAStripAreOpen) {
  std::vector<std::string> names;
  for (uint64_t r = 0; r < 20; ++r) {
    for (uint64_t c = 0; c < 3; ++c) {
      const std::string name = "t" + std::to_string(r) + "_" + std::to_string(c) + ".tif";
      writeSheet(name, {c * 40, r * 20, 40, 20});
      names.push_back(name);
    }
  }
  writeList("many.txt", names);
  std::unique_ptr<ImageSource> source;
  MosaicInfo info;
  const size_t base = openFiles();
  ASSERT_TRUE(openMosaic(m_dir.file("many.txt"), std::nullopt, 0, &source, &info).ok());
  EXPECT_EQ(openFiles(), base) << "sheets stay open after the mosaic is opened";
  ASSERT_EQ(source->info().width_px, 120u);
  ASSERT_EQ(source->info().height_px, 400u);
  std::vector<uint8_t> strip(120 * 32 * 3);
  size_t most = 0;
  for (uint64_t y = 0; y < 400; y += 32) {
    const uint32_t rows = uint32_t(std::min<uint64_t>(32, 400 - y));
    ASSERT_TRUE(source->readRows(y, rows, 0, 120, strip.data(), 120 * 3).ok());
    most = std::max(most, openFiles() - base);
    // The strip holds the sheets' pixels (row y + 5 of the image).
    EXPECT_EQ(strip[(5 * 120 + 50) * 3], m_image.at(50, y + 5, 0)) << y;
  }
  // A 32-row strip meets at most three rows of 20-row sheets: 9 sheets.
  EXPECT_LE(most, 9u) << "of 60 sheets";
  EXPECT_GE(most, 3u);
  // Vertical panels read the image block column by block column, each top
  // to bottom: sheets closed by one column are opened again by the next,
  // and every pixel is still the sheet's.
  std::vector<uint8_t> block(64 * 32 * 3);
  for (uint64_t bx = 0; bx < 120; bx += 64) {
    const uint64_t bw = std::min<uint64_t>(64, 120 - bx);
    for (uint64_t y = 0; y < 400; y += 32) {
      const uint32_t rows = uint32_t(std::min<uint64_t>(32, 400 - y));
      ASSERT_TRUE(source->readRows(y, rows, bx, bw, block.data(), 64 * 3).ok());
      EXPECT_LE(openFiles() - base, 9u);
      for (uint64_t r = 0; r < rows; r += 7) {
        for (uint64_t x = 0; x < bw; x += 13) {
          ASSERT_EQ(block[(r * 64 + x) * 3 + 1], m_image.at(bx + x, y + r, 1)) << bx + x << ", " << y + r;
        }
      }
    }
  }
  source.reset();
  EXPECT_EQ(openFiles(), base);
}

// DEM sheets (int16 with world files) make an elevation store equal to the
// whole DEM's; gaps are no-data, filled as the whole DEM's voids are.
TEST_F(Mosaic, DemSheetsGiveTheWholeDemsElevationStore) {
  constexpr uint64_t w = 200, h = 150;
  auto height = [](uint64_t x, uint64_t y) {
    return std::round(300.0 + 80.0 * std::sin(double(x) * 0.05) * std::cos(double(y) * 0.07) +
                      double((x * 7 + y * 3) % 11));
  };
  auto in_hole = [](uint64_t x, uint64_t y) { return x >= 100 && y < 60; };
  auto dem = [&](const std::string& name, const Rect& r, bool hole) {
    ASSERT_TRUE(writeImage(m_dir.file(name), r.w, r.h, 1, OIIO::TypeDesc::INT16,
                           [&](uint64_t x, uint64_t y, int) {
                             const uint64_t gx = r.x + x, gy = r.y + y;
                             return hole && in_hole(gx, gy) ? -32768.0 : height(gx, gy);
                           }));
    std::FILE* f = std::fopen(m_dir.file(name.substr(0, name.rfind('.')) + ".wld").c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fprintf(f, "30\n0\n0\n-30\n%.6f\n%.6f\n", 500000.0 + (double(r.x) + 0.5) * 30.0,
                 4000000.0 - (double(r.y) + 0.5) * 30.0);
    std::fclose(f);
  };
  dem("whole.tif", {0, 0, w, h}, false);
  dem("holed.tif", {0, 0, w, h}, true);
  const Rect parts[] = {{0, 0, 100, 60}, {100, 0, 100, 60}, {0, 60, 100, 90}, {100, 60, 100, 90}};
  std::vector<std::string> names;
  for (int i = 0; i < 4; ++i) {
    names.push_back("d" + std::to_string(i) + ".tif");
    dem(names.back(), parts[i], false);
  }
  writeList("dem.txt", names);
  names.erase(names.begin() + 1);  // the top right quarter: the hole
  writeList("gap.txt", names);

  tile(run("whole.tif", "whole.cst", false));
  tile(run("dem.txt", "mosaic.cst", true));
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(m_dir.file("mosaic.cst"), &reader).ok());
  EXPECT_TRUE(reader->info().elevation.present);
  EXPECT_EQ(reader->geometry().format, PixelFormat::kI16);
  expectSameTiles(m_dir.file("whole.cst"), m_dir.file("mosaic.cst"));

  TilerOptions holed = run("holed.tif", "holed.cst", false);
  holed.nodata = -32768;
  tile(holed);
  TilerOptions gap = run("gap.txt", "gap.cst", true);
  gap.nodata = -32768;
  TilerSummary summary;
  tile(gap, &summary);
  EXPECT_EQ(summary.gap_px, 100u * 60u);
  EXPECT_EQ(summary.elevation.filled_samples, 100u * 60u);
  expectSameTiles(holed.output_path, gap.output_path);
  // Integer sheets that declare no no-data value leave nothing to fill gaps with.
  expectFailure({"--mosaic", m_dir.file("gap.txt"), m_dir.file("o.cst")}, "give --nodata");
}

TEST_F(Mosaic, ShardedMosaicMergesToTheSingleRun) {
  writeList("sheets.txt", gridSheets());
  const TilerOptions single = run("sheets.txt", "single.cst", true);
  tile(single);
  MergeOptions m;
  for (uint32_t k = 1; k <= 3; ++k) {
    TilerOptions o = single;
    o.output_path = m_dir.file("part" + std::to_string(k) + ".cst");
    o.shard_index = k;
    o.shard_count = 3;
    tile(o);
    m.input_paths.push_back(o.output_path);
  }
  m.output_path = m_dir.file("merged.cst");
  m.fsync = false;
  MergeSummary ms;
  const Status s = mergeShards(m, &ms);
  ASSERT_TRUE(s.ok()) << s.toString();
  expectSameTiles(single.output_path, m.output_path);
}

TEST_F(Mosaic, SheetsThatDoNotFitTogetherAreNamed) {
  std::vector<std::string> sheets = gridSheets();
  writeList("ok.txt", sheets);
  const std::string out = m_dir.file("out.cst");
  auto with = [&](const std::string& list, const std::string& extra) {
    std::vector<std::string> s = sheets;
    s.push_back(extra);
    writeList(list, s);
    return m_dir.file(list);
  };
  writeSheet("coarse.tif", {0, 0, 100, 100}, ".wld", kPixel * 2);
  expectFailure({"--mosaic", with("res.txt", "coarse.tif"), out}, "coarse.tif: pixel size");
  writeSheet("offgrid.tif", {0, 0, 100, 100}, ".wld", kPixel, 0.5);
  expectFailure({"--mosaic", with("grid.txt", "offgrid.tif"), out},
                "offgrid.tif is not on the pixel grid");
  writeSheet("other_crs.tif", {0, 0, 100, 100});
  { std::ofstream(m_dir.file("other_crs.prj")) << "LOCAL_CS[\"elsewhere\"]"; }
  expectFailure({"--mosaic", with("crs.txt", "other_crs.tif"), out}, "other_crs.tif: CRS");
  writeSheet("four.tif", {0, 0, 100, 100}, ".wld", kPixel, 0.0, {}, 4);
  expectFailure({"--mosaic", with("chan.txt", "four.tif"), out}, "four.tif has 4 uint8 channels");
  ASSERT_TRUE(writeImage(m_dir.file("bare.tif"), 50, 50, 3, OIIO::TypeDesc::UINT8,
                         [](uint64_t, uint64_t, int) { return 9.0; }));
  expectFailure({"--mosaic", with("bare.txt", "bare.tif"), out}, "bare.tif has no georeference");
  expectFailure({"--mosaic", with("missing.txt", "nope.tif"), out}, "missing.txt line 9: ");
  expectFailure({"--mosaic", m_dir.file("missing.txt"), out}, "nope.tif");
  expectFailure({"--mosaic", with("self.txt", "self.txt"), out}, "self.txt is the mosaic list itself");
  writeList("empty.txt", {"# nothing yet", ""});
  expectFailure({"--mosaic", m_dir.file("empty.txt"), out}, "names no sheets");
  expectFailure({"--mosaic", m_dir.file("absent.txt"), out}, "absent.txt");
  // Command-line mistakes: exit 2, nothing read.
  EXPECT_EQ(runTiler({"--mosaic", m_dir.file("ok.txt"), "in.tif", out}).exit_code, 2);
  EXPECT_EQ(runTiler({"--fill", "3", m_dir.file("sheet_00.tif"), out}).exit_code, 2);
  // The output may not be a sheet, even with --force.
  expectFailure({"--mosaic", m_dir.file("ok.txt"), m_dir.file("sheet_00.tif"), "--force"},
                "is the mosaic's sheet");
  // And the program runs it.
  const RunResult ok = runTiler({"--mosaic", m_dir.file("ok.txt"), out, "--no-fsync"});
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_NE(ok.output.find("mosaic: 6 sheets, 0 px covered by none"), std::string::npos) << ok.output;
}

}  // namespace
}  // namespace clipstream::test
