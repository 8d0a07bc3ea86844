// clipstream-tile as users run it: bad inputs fail with a message naming the
// problem and leave nothing behind; memory stays under the budget; the real
// sample files tile and verify.
#include "tiler_test_util.h"

#include <clipstream/testing/files.h>
#include <clipstream/testing/sanitizers.h>
#include <clipstream/testing/test_data.h>
#include <clipstream/tiler/image_source.h>

#include <nlohmann/json.hpp>

#include <chrono>
#include <csignal>
#include <fstream>
#include <span>
#include <thread>
#include <sys/resource.h>
#include <sys/wait.h>
#include <fcntl.h>
#include <unistd.h>

namespace clipstream::test {
namespace {

void expectFailure(const RunResult& r, const std::string& needle, const TempDir& dir,
                   const std::vector<std::string>& allowed = {}) {
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(needle), std::string::npos) << "output: " << r.output;
  EXPECT_EQ(dir.entries(), allowed) << "left behind in " << dir.path();
}

// A missing or empty `from` fails the test: a truncated nothing would pass
// the checks on `to` without testing anything.
void copyPrefix(const std::string& from, const std::string& to, double fraction) {
  const std::vector<uint8_t> bytes = readBytes(from);
  ASSERT_FALSE(bytes.empty()) << from;
  writeBytes(to, std::span(bytes).first(size_t(double(bytes.size()) * fraction)));
}

double noisy(uint64_t x, uint64_t y, int c) {
  return double((x * 131 + y * 71 + uint64_t(c) * 29 + ((x * y) >> 3)) & 255);
}

TEST(TileCli, MissingInputFileIsNamed) {
  TempDir dir;
  expectFailure(runTiler({dir.file("nope.tif"), dir.file("out.cst")}), "nope.tif: no such file", dir);
}

TEST(TileCli, UnreadableImageIsNamed) {
  TempDir dir;
  { std::ofstream(dir.file("text.tif")) << "this is not a TIFF file at all\n"; }
  expectFailure(runTiler({dir.file("text.tif"), dir.file("out.cst")}), "text.tif", dir, {"text.tif"});
}

TEST(TileCli, TruncatedTiffFailsNamingFile) {
  TempDir dir;
  ASSERT_TRUE(writeImage(dir.file("full.tif"), 300, 400, 3, OIIO::TypeDesc::UINT8, noisy));
  copyPrefix(dir.file("full.tif"), dir.file("half.tif"), 0.5);
  std::filesystem::remove(dir.file("full.tif"));
  expectFailure(runTiler({dir.file("half.tif"), dir.file("out.cst")}), "half.tif", dir, {"half.tif"});
}

TEST(TileCli, TruncatedJpegFailsNamingFile) {
  TempDir dir;
  ASSERT_TRUE(writeImage(dir.file("full.jpg"), 300, 400, 3, OIIO::TypeDesc::UINT8, noisy));
  copyPrefix(dir.file("full.jpg"), dir.file("half.jpg"), 0.5);
  std::filesystem::remove(dir.file("full.jpg"));
  expectFailure(runTiler({dir.file("half.jpg"), dir.file("out.cst")}), "half.jpg", dir, {"half.jpg"});
}

TEST(TileCli, TruncatedRealJpegFails) {
  TempDir dir;
  copyPrefix(bundledDataPath("autzen.jpg"), dir.file("cut.jpg"), 0.5);
  expectFailure(runTiler({dir.file("cut.jpg"), dir.file("out.cst")}), "cut.jpg", dir, {"cut.jpg"});
}

TEST(TileCli, ZeroSizeImageIsRejected) {
  TempDir dir;
  // A minimal little-endian TIFF whose ImageWidth is 0.
  const uint8_t tiff[] = {'I', 'I', 42, 0, 8, 0, 0, 0,  // header, IFD at 8
                          3, 0,                         // 3 entries
                          0x00, 0x01, 3, 0, 1, 0, 0, 0, 0, 0, 0, 0,   // ImageWidth = 0
                          0x01, 0x01, 3, 0, 1, 0, 0, 0, 5, 0, 0, 0,   // ImageLength = 5
                          0x02, 0x01, 3, 0, 1, 0, 0, 0, 8, 0, 0, 0,   // BitsPerSample = 8
                          0, 0, 0, 0};
  {
    std::ofstream out(dir.file("zero.tif"), std::ios::binary);
    out.write(reinterpret_cast<const char*>(tiff), sizeof(tiff));
  }
  expectFailure(runTiler({dir.file("zero.tif"), dir.file("out.cst")}), "zero.tif", dir, {"zero.tif"});
}

TEST(TileCli, UnsupportedPixelTypeIsNamed) {
  TempDir dir;
  ASSERT_TRUE(writeImage(dir.file("u32.tif"), 16, 16, 1, OIIO::TypeDesc::UINT32,
                         [](uint64_t x, uint64_t, int) { return double(x); }));
  expectFailure(runTiler({dir.file("u32.tif"), dir.file("out.cst")}), "pixel type", dir, {"u32.tif"});
}

TEST(TileCli, MissingOutputDirectoryIsNamed) {
  TempDir dir;
  expectFailure(runTiler({"--synthetic", "64x64", dir.file("missing/out.cst")}), "does not exist", dir);
}

TEST(TileCli, AbsurdArgumentsAreRejected) {
  TempDir dir;
  const std::string out = dir.file("out.cst");
  expectFailure(runTiler({"--synthetic", "64x64", "--tile-size", "0", out}), "--tile-size", dir);
  expectFailure(runTiler({"--synthetic", "64x64", "--tile-size", "100", out}), "power of two", dir);
  expectFailure(runTiler({"--synthetic", "0x5", out}), "0x5 is empty", dir);
  expectFailure(runTiler({"--synthetic", "64x64", "--threads", "100000", out}), "--threads", dir);
  expectFailure(runTiler({"--synthetic", "banana", out}), "not WIDTHxHEIGHT", dir);
  expectFailure(runTiler({"--synthetic", "64x64", "--format", "CMYK", out}), "CMYK", dir);
  expectFailure(runTiler({"--synthetic", "64x64", "--filter", "bicubic", out}), "bicubic", dir);
  expectFailure(runTiler({"--synthetic", "64x64", "--zstd-level", "99", out}), "--zstd-level", dir);
  expectFailure(runTiler({"--synthetic", "64x64", "--memory-mb", "1", out}), "--memory-mb", dir);
  expectFailure(runTiler({"--synthetic", "64x64", "--payload-order", "zigzag", out}),
                "--payload-order", dir);
  // Both orders, in any case, make a store.
  for (const char* order : {"WRITTEN", "curve"}) {
    const RunResult r = runTiler({"--synthetic", "300x200", "--payload-order", order, "--quiet",
                                  "--no-fsync", "--force", out});
    EXPECT_EQ(r.exit_code, 0) << order << ": " << r.output;
    std::unique_ptr<TileStoreReader> reader;
    EXPECT_TRUE(TileStoreReader::open(out, &reader).ok()) << order;
  }
}

TEST(TileCli, RefusesToOverwriteWithoutForce) {
  TempDir dir;
  const std::string out = dir.file("out.cst");
  { std::ofstream(out) << "precious"; }
  expectFailure(runTiler({"--synthetic", "64x64", out}), "already exists", dir, {"out.cst"});
  std::ifstream in(out);
  std::string text;
  in >> text;
  EXPECT_EQ(text, "precious");
  const RunResult r = runTiler({"--synthetic", "64x64", "--force", "--quiet", out});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  std::unique_ptr<TileStoreReader> reader;
  EXPECT_TRUE(TileStoreReader::open(out, &reader).ok());
}

TEST(TileCli, InterruptRemovesTemporaryFiles) {
  TempDir dir;
  const std::string out = dir.file("out.cst");
  const pid_t pid = spawnTiler({"--synthetic", "60000x60000", "--threads", "1", "--no-fsync", out});
  ASSERT_GE(pid, 0);
  // Wait until the writer's temporary file exists, so the signal arrives mid-run.
  bool started = false;
  for (int i = 0; i < 400 && !started; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
    started = !dir.entries().empty();
  }
  EXPECT_TRUE(started);
  kill(pid, SIGINT);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
  EXPECT_TRUE(dir.entries().empty()) << dir.entries().front();
}

TEST(TileCli, WriteFailureMidRunLeavesNothingBehind) {
  // A 1 MiB file-size limit makes the store's writes fail part way through,
  // as a full disk would (EFBIG instead of ENOSPC).
  TempDir dir;
  const std::string out = dir.file("out.cst");
  const std::string log = dir.file("../" + dir.path().filename().string() + ".log");
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(fd, 1);
    dup2(fd, 2);
    rlimit limit{1 << 20, 1 << 20};
    setrlimit(RLIMIT_FSIZE, &limit);
    execl(CLIPSTREAM_TILE_EXE, CLIPSTREAM_TILE_EXE, "--synthetic", "4096x4096", "--no-fsync",
          out.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 1);
  std::ifstream in(log);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::filesystem::remove(log);
  EXPECT_NE(text.find("out.cst"), std::string::npos) << text;
  EXPECT_TRUE(dir.entries().empty()) << dir.entries().front();
}

TEST(TileCli, PeakMemoryStaysUnderBudgetForLargeSyntheticImage) {
  if (kSanitized) GTEST_SKIP() << "memory budgets do not hold under sanitizers";
  TempDir dir;
  // 16384 x 16384 RGBA8 is 1 GiB of pixels; the budget is 64 MiB.
  const RunResult r = runTiler({"--synthetic", "16384x16384", "--format", "RGBA8", "--memory-mb", "64",
                                "--no-fsync", "--json-summary", dir.file("s.json"), dir.file("big.cst")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(dir.file("s.json"));
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["width_px"].get<uint64_t>(), 16384u);
  EXPECT_EQ(j["pixel_format"].get<std::string>(), "RGBA8");
  const uint64_t peak = j["peak_rss_bytes"].get<uint64_t>();
  EXPECT_GT(peak, 0u);
  EXPECT_LT(peak, uint64_t(64) << 20) << "peak RSS " << peak / (1 << 20) << " MiB";
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(dir.file("big.cst"), &reader).ok());
  EXPECT_EQ(reader->geometry().levelCount(), 8u);
}

TEST(TileCli, NarrowBudgetSplitsIntoPanelsAndStillMatchesReference) {
  if (kSanitized) GTEST_SKIP() << "memory budgets do not hold under sanitizers";
  TempDir dir;
  // 40000 px wide RGBA: one strip of 128 rows is 20 MB, three strips in
  // flight and the pyramid far more than the 36 MiB budget allows, so the
  // tiler must cut vertical panels. (36, not 32: the smallest panel layout
  // needs about 32 MB with the program's own few MB, too close to call.)
  const uint64_t w = 40000, h = 300;
  const RunResult r = runTiler({"--synthetic", "40000x300", "--format", "RGBA8", "--memory-mb", "36",
                                "--no-fsync", "--json-summary", dir.file("s.json"), dir.file("p.cst")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::ifstream in(dir.file("s.json"));
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_GT(j["panels"].get<uint32_t>(), 1u);
  EXPECT_LT(j["peak_rss_bytes"].get<uint64_t>(), uint64_t(36) << 20);
  RefImage level;
  level.width = w, level.height = h, level.channels = 4;
  level.samples.resize(w * h * 4);
  uint8_t px[4];
  for (uint64_t y = 0; y < h; ++y) {
    for (uint64_t x = 0; x < w; ++x) {
      syntheticPixel(x, y, PixelFormat::kRGBA8, px);
      for (int c = 0; c < 4; ++c) level.samples[(y * w + x) * 4 + c] = px[c];
    }
  }
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(dir.file("p.cst"), &reader).ok());
  for (uint32_t l = 0; l < reader->geometry().levelCount(); ++l) {
    EXPECT_EQ(maxTileError(*reader, l, level), 0u) << "level " << l;
    level = referenceBoxDownsample(level);
  }
}

// The bundled autzen.jpg always; the shared globe (8192 x 4096) when present.
TEST(TileCli, RealFilesTileAndVerify) {
  const char* kGlobe = "fg_globe_colors_8192x4096.jpg";
  std::vector<std::string> inputs = {bundledDataPath("autzen.jpg")};
  if (!sharedDataPath(kGlobe).empty()) inputs.push_back(sharedDataPath(kGlobe));
  for (const std::string& input : inputs) {
    const std::string name = std::filesystem::path(input).filename().string();
    TempDir dir;
    const std::string out = dir.file("real.cst");
    const RunResult r = runTiler({input, out, "--no-fsync", "--quiet"});
    ASSERT_EQ(r.exit_code, 0) << r.output;
    std::unique_ptr<TileStoreReader> reader;
    ASSERT_TRUE(TileStoreReader::open(out, &reader).ok());
    std::vector<TileStoreReader::Problem> problems;
    const Status s = reader->verifyAll(&problems);
    EXPECT_TRUE(s.ok()) << name << ": " << s.toString();
    EXPECT_TRUE(problems.empty());
    RefImage level;
    ASSERT_TRUE(readImage8(input, &level)) << input;
    EXPECT_EQ(maxTileError(*reader, 0, level), 0u) << name;
    level = referenceBoxDownsample(level);
    EXPECT_EQ(maxTileError(*reader, 1, level), 0u) << name;
    if (name == "autzen.jpg") {
      EXPECT_TRUE(reader->info().geo.present);
    }
  }
  if (inputs.size() == 1) GTEST_SKIP() << "autzen.jpg passed; " << sharedDataAbsent(kGlobe);
}

}  // namespace
}  // namespace clipstream::test
