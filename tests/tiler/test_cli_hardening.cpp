// clipstream-tile against the hostile-input findings: outputs that are not
// regular files, outputs that appear or change during the run, the input
// named as the output, failed summary writes, signals, temporaries of killed
// runs, command-line mistakes and noisy decoders. Each test failed on the
// code before the fix (docs/cli.md has the rules they pin).
#include "tiler_test_util.h"

#include <clipstream/testing/files.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <fstream>
#include <thread>

namespace clipstream::test {
namespace {

bool hasTemporary(const TempDir& dir) {
  for (const std::string& name : dir.entries())
    if (name.find(".tmp-") != std::string::npos) return true;
  return false;
}

// An uncompressed RGB8 TIFF written byte by byte: `orientation` tag, one
// strip per row; with `bad_offsets` every strip points past the end (a
// damaged file the decoder complains about once per strip).
void writeRawTiff(const std::string& path, uint32_t w, uint32_t h, uint16_t orientation,
                  bool bad_offsets) {
  std::string out = "II*";
  out += '\0';
  auto put16 = [&](uint32_t v) { out += char(v & 255), out += char(v >> 8 & 255); };
  auto put32 = [&](uint32_t v) { put16(v & 0xffff), put16(v >> 16); };
  const uint32_t row = w * 3, pixels_at = 8, offsets_at = pixels_at + row * h,
                 counts_at = offsets_at + 4 * h, bps_at = counts_at + 4 * h, ifd_at = bps_at + 6;
  put32(ifd_at);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < row; ++x) out += char((x * 7 + y * 3) & 255);
  for (uint32_t y = 0; y < h; ++y) put32(pixels_at + y * row + (bad_offsets ? 1000000000u : 0u));
  for (uint32_t y = 0; y < h; ++y) put32(row);
  put16(8), put16(8), put16(8);
  const struct {
    uint16_t tag, type;
    uint32_t count, value;
  } entries[] = {{256, 3, 1, w},          {257, 3, 1, h},          {258, 3, 3, bps_at},
                 {259, 3, 1, 1},          {262, 3, 1, 2},          {273, 4, h, offsets_at},
                 {274, 3, 1, orientation}, {277, 3, 1, 3},         {278, 3, 1, 1},
                 {279, 4, h, counts_at},  {284, 3, 1, 1}};
  put16(uint32_t(std::size(entries)));
  for (const auto& e : entries) {
    put16(e.tag), put16(e.type), put32(e.count);
    if (e.type == 3 && e.count == 1) put16(e.value), put16(0);
    else put32(e.value);
  }
  put32(0);
  std::ofstream(path, std::ios::binary) << out;
}

// Starts clipstream-tile on a large synthetic image, returns its pid once
// its temporary file exists (the run is under way).
pid_t startLongRun(const TempDir& dir, const std::string& out, const char* size = "30000x30000") {
  const pid_t pid = spawnTiler({"--synthetic", size, "--threads", "1", "--no-fsync", out});
  for (int i = 0; i < 400 && !hasTemporary(dir); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(25));
  return pid;
}

// Bug 1: `clipstream-tile small.jpg /dev/null -f` turned /dev/null into a
// regular file.
TEST(TileCliHardening, ForceNeverReplacesAFifoOrADevice) {
  TempDir dir;
  const std::string fifo = dir.file("fifo");
  ASSERT_EQ(mkfifo(fifo.c_str(), 0644), 0);
  std::vector<std::string> outputs = {fifo};
  const std::string device = dir.file("null");
  if (mknod(device.c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0) outputs.push_back(device);
  for (const std::string& out : outputs) {
    const RunResult r = runTiler({"--synthetic", "64x64", "-f", "-q", out});
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find("not a regular file"), std::string::npos) << r.output;
  }
  struct stat st {};
  ASSERT_EQ(lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  if (outputs.size() == 2) {
    ASSERT_EQ(lstat(device.c_str(), &st), 0);
    EXPECT_TRUE(S_ISCHR(st.st_mode));
  }
  EXPECT_FALSE(hasTemporary(dir));
}

// Bug 2: a file created at OUTPUT during the run was overwritten without
// --force.
TEST(TileCliHardening, AFileCreatedAtOutputDuringTheRunIsKept) {
  TempDir dir;
  const std::string out = dir.file("o.cst");
  const pid_t pid = startLongRun(dir, out, "4096x4096");
  ASSERT_TRUE(hasTemporary(dir));
  { std::ofstream(out) << "precious"; }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  EXPECT_EQ(readText(out), "precious");
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"o.cst"});
}

// Bug 3: OUTPUT equal to INPUT with -f destroyed the input, also through a
// symbolic or hard link.
TEST(TileCliHardening, TheInputIsNeverTheOutputEvenWithForce) {
  TempDir dir;
  const std::string input = dir.file("s.tif");
  writeRawTiff(input, 40, 30, 1, false);
  const std::string before = readText(input);
  std::filesystem::create_symlink(input, dir.file("sym.cst"));
  std::filesystem::create_hard_link(input, dir.file("hard.cst"));
  for (const std::string& out : {input, dir.file("sym.cst"), dir.file("hard.cst"), dir.file("./s.tif")}) {
    const RunResult r = runTiler({input, out, "-f", "-q"});
    EXPECT_NE(r.exit_code, 0) << out;
    EXPECT_NE(r.output.find("is the input file"), std::string::npos) << r.output;
  }
  EXPECT_EQ(readText(input), before);
  EXPECT_FALSE(hasTemporary(dir));
}

// Bug 7: a failed --json-summary write (to /dev/full, or a full disk) exited
// 0 with a 0-byte file.
TEST(TileCliHardening, AJsonSummaryThatCannotBeWrittenFailsTheRun) {
  TempDir dir;
  RunResult r = runTiler({"--synthetic", "64x64", "-q", "--json-summary", "/dev/full", dir.file("a.cst")});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("/dev/full"), std::string::npos) << r.output;
  // To standard output that is full.
  r = runTiler({"--synthetic", "64x64", "-q", "--json-summary", "-", dir.file("b.cst")}, ">/dev/full");
  EXPECT_NE(r.exit_code, 0) << r.output;
  // A real full filesystem: a tiny tmpfs (needs root; skipped otherwise).
  const std::string full = dir.file("full");
  std::filesystem::create_directories(full);
  if (mount("tmpfs", full.c_str(), "tmpfs", 0, "size=64k") != 0) {
    GTEST_SKIP() << "cannot mount a tmpfs here: " << std::strerror(errno);
  }
  {
    std::ofstream filler(full + "/filler", std::ios::binary);
    const std::string block(4096, 'x');
    for (int i = 0; i < 64 && filler; ++i) filler << block;
  }
  r = runTiler({"--synthetic", "64x64", "-q", "--json-summary", full + "/s.json", dir.file("c.cst")});
  const std::vector<std::string> left = [&] {
    std::vector<std::string> names;
    for (const auto& e : std::filesystem::directory_iterator(full)) names.push_back(e.path().filename());
    return names;
  }();
  umount(full.c_str());
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("s.json"), std::string::npos) << r.output;
  EXPECT_EQ(left, std::vector<std::string>{"filler"});
}

// The summary named as the store (or the input) would replace it at the end.
TEST(TileCliHardening, TheSummaryIsNeitherTheStoreNorTheInput) {
  TempDir dir;
  const std::string input = dir.file("s.tif");
  writeRawTiff(input, 40, 30, 1, false);
  const std::string before = readText(input);
  for (const std::string& json : {dir.file("o.cst"), dir.file("./o.cst"), input}) {
    const RunResult r = runTiler({input, dir.file("o.cst"), "-q", "--json-summary", json});
    EXPECT_EQ(r.exit_code, 2) << json << ": " << r.output;
  }
  EXPECT_EQ(readText(input), before);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"s.tif"});
}

// Bug 8: SIGHUP was not handled (rc 129 by the signal, every temporary left).
TEST(TileCliHardening, HangupRemovesTheTemporaries) {
  TempDir dir;
  const pid_t pid = startLongRun(dir, dir.file("o.cst"));
  ASSERT_TRUE(hasTemporary(dir));
  kill(pid, SIGHUP);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 128 + SIGHUP);
  EXPECT_TRUE(dir.entries().empty()) << dir.entries().front();
}

// Whether process `pid` holds `path` open, polled (up to 30 s) through
// /proc/<pid>/fd; false if it never did or has exited.
bool waitUntilOpened(pid_t pid, const std::string& path) {
  const std::filesystem::path fds = "/proc/" + std::to_string(pid) + "/fd";
  const std::filesystem::path target = std::filesystem::canonical(path);
  for (int i = 0; i < 6000; ++i) {
    std::error_code ec;
    for (const auto& fd : std::filesystem::directory_iterator(fds, ec)) {
      std::error_code link_ec;
      if (std::filesystem::read_symlink(fd.path(), link_ec) == target) return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return false;
}

// Third pass: a huge all-zero input kept the image library busy guessing its
// format for minutes, where the tiler never polls its stop flag: one SIGTERM
// did nothing. The grace alarm ends the run within seconds.
TEST(TileCliHardening, OneSignalStopsTheRunEvenInsideTheImageLibrary) {
  TempDir dir;
  const std::string input = dir.file("zeros.jpg");
  { std::ofstream create(input); }
  std::filesystem::resize_file(input, uint64_t(4) << 30);  // sparse: no disk used
  const pid_t pid = spawnTiler({"-q", input, dir.file("z.cst")});
  ASSERT_GE(pid, 0);
  // The signal is sent once the run holds the input open: from then on the
  // image library is reading it (and, this input, guessing its format).
  ASSERT_TRUE(waitUntilOpened(pid, input)) << "the tiler never opened " << input;
  const auto start = std::chrono::steady_clock::now();
  kill(pid, SIGTERM);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  const double waited_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 128 + SIGTERM);
  EXPECT_LT(waited_s, 30.0);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"zeros.jpg"});
}

// Bug 8: temporaries left by SIGKILL (80-130 MB each) were never swept or
// reported.
TEST(TileCliHardening, TemporariesOfAKilledRunAreSweptAndReported) {
  TempDir dir;
  const std::string out = dir.file("o.cst");
  const pid_t pid = startLongRun(dir, out);
  ASSERT_TRUE(hasTemporary(dir));
  kill(pid, SIGKILL);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(hasTemporary(dir));
  const RunResult r = runTiler({"--synthetic", "256x256", "--no-fsync", out});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("left by an interrupted earlier run"), std::string::npos) << r.output;
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"o.cst"});
}

// Bug 9: command-line mistakes exited with CLI11's raw codes (104, 106, 109,
// 114) and range errors printed 300-digit numbers.
TEST(TileCliHardening, CommandLineMistakesExitTwoWithAShortMessage) {
  TempDir dir;
  const std::string out = dir.file("o.cst");
  const std::vector<std::vector<std::string>> cases = {
      {"--synthetic", "64x64", "--no-such-flag", out},
      {"--synthetic", "64x64", "--threads", "1e999", out},
      {"--synthetic", "64x64", "--threads", "-1", out},
      {"--synthetic", "64x64", "--zstd-level", "banana", out},
      {"--synthetic", "64x64", "--memory-mb", "1e308", out},
      {"--synthetic", "64x64", "--tile-size", "100", out},
      {"--synthetic", "64x64", "--tile-size", "99999999999999999999999", out},
      {"--synthetic", "99999999999999999999x2", out},
      {"--synthetic", "64x64", "--format", "CMYK", out},
      {"--synthetic", "64x64"},
      {}};
  for (const auto& args : cases) {
    const RunResult r = runTiler(args);
    std::string joined;
    for (const std::string& a : args) joined += a + " ";
    EXPECT_EQ(r.exit_code, 2) << joined << "\n" << r.output;
    EXPECT_LT(r.output.size(), 300u) << joined << "\n" << r.output;
  }
  EXPECT_NE(runTiler({"--synthetic", "99999999999999999999x2", out}).output.find("too large"),
            std::string::npos);
  EXPECT_TRUE(dir.entries().empty());
}

// Second pass: CLI11 read "010" as octal 8 after our range check had read
// ten; file names, values and file contents reached the terminal raw.
TEST(TileCliHardening, NumbersAreDecimalAndMessagesArePrintable) {
  TempDir dir;
  RunResult r = runTiler({"--synthetic", "64x64", "-q", "--zstd-level", "010", dir.file("a.cst")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::unique_ptr<TileStoreReader> reader;
  ASSERT_TRUE(TileStoreReader::open(dir.file("a.cst"), &reader).ok());
  EXPECT_EQ(reader->info().encoding.zstd_level, 10);
  r = runTiler({"--synthetic", "64x64", "-q", "--tile-size", "0100", dir.file("b.cst")});
  EXPECT_EQ(r.exit_code, 2) << "100 is not a power of two (octal 0100 would be 64): " << r.output;
  const std::string hostile = "x\x1b[2J\ny\a";
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"--synthetic", "1" + hostile, dir.file("c.cst")},
        std::vector<std::string>{"--synthetic", "64x64", "-q", dir.file("missing" + hostile + "/c.cst")},
        std::vector<std::string>{dir.file("absent" + hostile + ".tif"), dir.file("c.cst")},
        std::vector<std::string>{"--bogus" + hostile, dir.file("c.cst")}}) {
    r = runTiler(args);
    EXPECT_NE(r.exit_code, 0);
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
    for (char c : r.output) {
      if (c != '\n') {
        EXPECT_GE(static_cast<unsigned char>(c), 0x20) << r.output;
      }
    }
  }
  r = runTiler({"", dir.file("d.cst")});
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_NE(r.output.find("must not be empty"), std::string::npos) << r.output;
}

// Minor: a TIFF Orientation tag was ignored without a word.
TEST(TileCliHardening, ATiffOrientationTagIsWarnedAbout) {
  TempDir dir;
  writeRawTiff(dir.file("turned.tif"), 40, 30, 6, false);
  RunResult r = runTiler({dir.file("turned.tif"), dir.file("t.cst"), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("orientation tag 6"), std::string::npos) << r.output;
  writeRawTiff(dir.file("plain.tif"), 40, 30, 1, false);
  r = runTiler({dir.file("plain.tif"), dir.file("p.cst"), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(r.output.find("orientation"), std::string::npos) << r.output;
}

// Minor: a damaged TIFF flooded the terminal with one decoder line per strip
// (127 lines) under the one clear error.
TEST(TileCliHardening, ADamagedTiffGivesOneErrorLine) {
  TempDir dir;
  writeRawTiff(dir.file("bad.tif"), 40, 128, 1, true);
  const RunResult r = runTiler({dir.file("bad.tif"), dir.file("b.cst"), "-q"});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("bad.tif"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"bad.tif"});
}

}  // namespace
}  // namespace clipstream::test
