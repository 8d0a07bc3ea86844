// clipstream-view: runs in a virtual X server, refuses to record over its
// store.
#include "test_helpers.h"

#include <clipstream/testing/test_data.h>

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

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

// A Cloud-Optimized GeoTIFF where the store goes: opened directly (no
// tiling), its georeference taken for --look-at in map coordinates.
TEST(ClipstreamView, OpensACogAndLooksAtAPointOfItsMap) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0) GTEST_SKIP() << "no xvfb-run";
  test::TempDir dir;
  const std::string cog = dir.file("autzen.tif");
  ASSERT_EQ(std::system(("gdal_translate -q -of COG -outsize 25% 25% '" + test::bundledDataPath("autzen.jpg") + "' '" +
                         cog + "' > /dev/null 2>&1")
                            .c_str()),
            0);
  // autzen.wld places it from (635615, 853363), 4 m a pixel at this size.
  const std::string cmd = "xvfb-run -a -s '-screen 0 640x480x24' " + std::string(CLIPSTREAM_VIEW_EXE) + " '" + cog +
                          "' --look-at 637000,851000 --size 320x240 --frames 20 > " + dir.file("log.txt") + " 2>&1";
  const int rc = std::system(cmd.c_str());
  std::ifstream log(dir.file("log.txt"));
  std::stringstream ss;
  ss << log.rdbuf();
  EXPECT_EQ(rc, 0) << ss.str();
  // A file that is neither a store nor a TIFF says both, exit 1.
  std::ofstream(dir.file("notes.tif")) << "not an image\n";
  const std::string bad = std::string(CLIPSTREAM_VIEW_EXE) + " '" + dir.file("notes.tif") + "' > " + dir.file("bad.txt") + " 2>&1";
  const int bad_rc = std::system(bad.c_str());
  std::ifstream bad_log(dir.file("bad.txt"));
  std::stringstream bad_text;
  bad_text << bad_log.rdbuf();
  EXPECT_TRUE(WIFEXITED(bad_rc) && WEXITSTATUS(bad_rc) == 1) << bad_text.str();
  EXPECT_NE(bad_text.str().find("not a clipstream tile store nor a TIFF"), std::string::npos) << bad_text.str();
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
                            // The quadtree flies with the detail beyond the data, starting
                            // at a point named in the store's coordinates (texels here).
                            (std::string(method) == "quadtree"
                                 ? " --terrain-lighting pixel --terrain-detail --synthesize-relief 1 --look-at 2000,1500"
                                 : "") +
                            " --size 320x240 --frames 20 > " + dir.file("log.txt") + " 2>&1";
    const int rc = std::system(cmd.c_str());
    std::ifstream log(dir.file("log.txt"));
    std::stringstream ss;
    ss << log.rdbuf();
    EXPECT_EQ(rc, 0) << method << ": " << ss.str();
    EXPECT_NE(ss.str().find("stretched"), std::string::npos) << "the DEM without georeference is stretched, and said so";
  }
  // A method that does not exist, or a point that is not one, is a
  // command-line mistake.
  for (const char* wrong : {" --terrain mesh", " --look-at 1,x", " --terrain-detail --elevation-less"}) {
    const std::string bad = std::string(CLIPSTREAM_VIEW_EXE) + " --procedural 4096 --elevation " + dir.file("dem.cst") +
                            wrong + " > " + dir.file("bad.txt") + " 2>&1";
    const int rc = std::system(bad.c_str());
    EXPECT_TRUE(WIFEXITED(rc) && WEXITSTATUS(rc) == 2) << wrong << ": " << rc;
  }
}

// The keys, pressed as a person would: real X events (xdotool, through
// XTEST) in a virtual X server. P writes a screenshot of the window's size
// and says where the camera was; W moves; H returns to the starting view,
// where the third screenshot's camera equals the first's.
TEST(ClipstreamView, KeysTakeScreenshotsAndGoHome) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1 && command -v xdotool > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "no xvfb-run or xdotool (scripts/deps.sh installs them)";
  test::TempDir dir("view_keys");
  const std::string script = dir.file("keys.sh");
  std::ofstream(script) << R"(set -u
view=$1 out=$2
"$view" --procedural 65536 --size 320x240 --screenshot-dir "$out" > "$out/log.txt" 2>&1 &
pid=$!
win=$(timeout 60 xdotool search --sync --onlyvisible --name clipstream-view | head -n 1)
if [ -z "$win" ]; then kill $pid; echo "no window"; exit 1; fi
xdotool mousemove --window "$win" 160 120
sleep 1
xdotool key p; sleep 0.5
xdotool keydown w; sleep 1; xdotool keyup w; sleep 0.3
xdotool key p; sleep 0.5
xdotool key h; sleep 0.3
xdotool key p; sleep 0.5
xdotool key F1 o; sleep 0.5
xdotool key Escape
wait $pid
)";
  const std::string cmd = "xvfb-run -a -s '-screen 0 640x480x24' bash '" + script + "' '" +
                          std::string(CLIPSTREAM_VIEW_EXE) + "' '" + dir.path().string() + "' > '" + dir.file("run.txt") +
                          "' 2>&1";
  const int rc = std::system(cmd.c_str());
  std::stringstream log;
  log << std::ifstream(dir.file("log.txt")).rdbuf() << std::ifstream(dir.file("run.txt")).rdbuf();
  ASSERT_TRUE(WIFEXITED(rc) && WEXITSTATUS(rc) == 0) << log.str();
  // "screenshot written to PATH (camera X Y Z, heading H, pitch P degrees)"
  std::vector<std::string> cameras;
  std::istringstream lines(log.str());
  for (std::string line; std::getline(lines, line);) {
    const size_t at = line.find("screenshot written to ");
    if (at == std::string::npos) continue;
    cameras.push_back(line.substr(line.find(" (camera ")));
  }
  ASSERT_EQ(cameras.size(), 3u) << log.str();
  EXPECT_NE(cameras[1], cameras[0]) << "W did not move the camera\n" << log.str();
  EXPECT_EQ(cameras[2], cameras[0]) << "H did not return to the starting view\n" << log.str();
  for (int n = 1; n <= 3; ++n) {
    const std::string png = dir.file("clipstream-view-00" + std::to_string(n) + ".png");
    std::ifstream in(png, std::ios::binary);
    std::string head(24, '\0');
    ASSERT_TRUE(in.read(head.data(), 24)) << png;
    EXPECT_EQ(head.substr(1, 3), "PNG") << png;
    const auto be32 = [&](size_t at) {
      return uint32_t(uint8_t(head[at])) << 24 | uint32_t(uint8_t(head[at + 1])) << 16 |
             uint32_t(uint8_t(head[at + 2])) << 8 | uint32_t(uint8_t(head[at + 3]));
    };
    EXPECT_EQ(be32(16), 320u) << png;  // IHDR: the window's size
    EXPECT_EQ(be32(20), 240u) << png;
  }
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
