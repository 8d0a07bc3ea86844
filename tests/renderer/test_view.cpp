// clipstream-view: runs in a virtual X server, refuses to record over its
// store.
#include "test_helpers.h"

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace clipstream {
namespace {

namespace fs = std::filesystem;

// clipstream-view in a virtual X server: opens its window, flies 20 frames
// and exits 0. Skipped where xvfb-run is not installed.
TEST(ClipstreamView, RunsUnderXvfb) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0) GTEST_SKIP() << "no xvfb-run";
  const fs::path dir = fs::temp_directory_path() / ("clipstream_view_smoke_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string cmd = "xvfb-run -a -s '-screen 0 640x480x24' " + std::string(CLIPSTREAM_VIEW_EXE) +
                          " --procedural 1048576 --size 320x240 --frames 20 > " +
                          (dir / "log.txt").string() + " 2>&1";
  const int rc = std::system(cmd.c_str());
  std::ifstream log(dir / "log.txt");
  std::stringstream ss;
  ss << log.rdbuf();
  EXPECT_EQ(rc, 0) << ss.str();
  fs::remove_all(dir);
}

// Over terrain: a procedural texture over an elevation store, 20 frames,
// exit 0 (the camera kept above the ground on the way).
TEST(ClipstreamView, FliesOverTerrainUnderXvfb) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0) GTEST_SKIP() << "no xvfb-run";
  test::TempDir dir;
  ASSERT_TRUE(test::writeElevationStore(dir.file("dem.cst"), 300, 200, [](uint64_t x, uint64_t y) {
                return float(100.0 + 50.0 * std::sin(x * 0.05) * std::cos(y * 0.04));
              }).ok());
  for (const char* method : {"clipmap", "quadtree"}) {
    const std::string cmd = "xvfb-run -a -s '-screen 0 640x480x24' " + std::string(CLIPSTREAM_VIEW_EXE) +
                            " --procedural 4096 --elevation " + dir.file("dem.cst") + " --terrain " + method +
                            " --size 320x240 --frames 20 > " + dir.file("log.txt") + " 2>&1";
    const int rc = std::system(cmd.c_str());
    std::ifstream log(dir.file("log.txt"));
    std::stringstream ss;
    ss << log.rdbuf();
    EXPECT_EQ(rc, 0) << method << ": " << ss.str();
    EXPECT_NE(ss.str().find("stretched"), std::string::npos) << "the DEM without georeference is stretched, and said so";
  }
  // A method that does not exist is a command-line mistake.
  const std::string bad = std::string(CLIPSTREAM_VIEW_EXE) + " --procedural 4096 --elevation " + dir.file("dem.cst") +
                          " --terrain mesh > " + dir.file("bad.txt") + " 2>&1";
  const int rc = std::system(bad.c_str());
  EXPECT_TRUE(WIFEXITED(rc) && WEXITSTATUS(rc) == 2) << rc;
}

// Third pass: clipstream-view --record-out naming the store being viewed
// would have replaced it with the recorded path.
TEST(ClipstreamView, NeverRecordsOverItsStore) {
  test::TempDir dir("view_record");
  const std::string store = dir.file("a.cst");
  std::ofstream(store) << "a store";
  for (const std::string& record : {store, dir.file("./a.cst")}) {
    const std::string cmd = std::string("'") + CLIPSTREAM_VIEW_EXE + "' '" + store + "' --record-out '" + record +
                            "' > /dev/null 2>&1";
    const int status = std::system(cmd.c_str());
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 2) << record;
  }
  std::ifstream in(store);
  std::string text;
  std::getline(in, text);
  EXPECT_EQ(text, "a store");
}

}  // namespace
}  // namespace clipstream
