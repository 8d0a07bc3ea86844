// Smoke test of clipstream-fly: a tiny store written here, ~30 frames, and
// the program must exit 0 having written CSV, JSON and PNG frames.
#include "test_helpers.h"

#include <clipstream/store/tile_store.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace clipstream {
namespace {

namespace fs = std::filesystem;

// 768 x 640 RGB8, 128-px tiles: levels of 6x5, 3x3, 2x2, 1x1 tiles.
Status writeTinyStore(const std::string& path) {
  PyramidGeometry g;
  if (!makePyramidGeometry(768, 640, 128, PixelFormat::kRGB8, &g))
    return Status::error(ErrorCode::kInvalidArgument, "geometry");
  WriterOptions options;
  options.fsync = false;
  std::unique_ptr<TileStoreWriter> writer;
  if (Status s = TileStoreWriter::create(path, g, options, &writer); !s) return s;
  std::vector<uint8_t> pixels(g.tileBytes());
  for (uint32_t l = 0; l < g.levelCount(); ++l)
    for (uint32_t ty = 0; ty < g.levels[l].tiles_y; ++ty)
      for (uint32_t tx = 0; tx < g.levels[l].tiles_x; ++tx) {
        for (uint32_t y = 0; y < 128; ++y)
          for (uint32_t x = 0; x < 128; ++x) {
            uint8_t* p = pixels.data() + (size_t(y) * 128 + x) * 3;
            p[0] = uint8_t(tx * 40 + x);
            p[1] = uint8_t(ty * 40 + y);
            p[2] = uint8_t(l * 60 + ((x / 8 + y / 8) & 1) * 50);
          }
        EncodedTile t;
        if (Status s = encodeTile(g, options.encoding, {l, tx, ty}, pixels, &t); !s) return s;
        if (Status s = writer->write(std::move(t)); !s) return s;
      }
  return writer->finish();
}

TEST(ClipstreamFly, WritesCsvJsonAndPngForATinyStore) {
  CLIPSTREAM_REQUIRE_GL();
  const fs::path dir = fs::temp_directory_path() / ("clipstream_fly_smoke_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string store = (dir / "tiny.cstore").string();
  const Status s = writeTinyStore(store);
  ASSERT_TRUE(s.ok()) << s.toString();
  const fs::path out = dir / "out";
  const std::string cmd = std::string(CLIPSTREAM_FLY_EXE) + " " + store +
                          " --path orbit --frames 30 --size 256x192 --io-threads 2 --save-frames 10 --out " +
                          out.string() + " > " + (dir / "log.txt").string() + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  EXPECT_TRUE(fs::exists(out / "frames.csv"));
  EXPECT_TRUE(fs::exists(out / "frame_00000.png"));
  EXPECT_TRUE(fs::exists(out / "frame_00029.png"));
  std::ifstream csv(out / "frames.csv");
  size_t lines = 0;
  for (std::string line; std::getline(csv, line);) ++lines;
  EXPECT_EQ(lines, 31u) << "header + one row per frame";
  std::ifstream json_in(out / "frames.json");
  std::stringstream ss;
  ss << json_in.rdbuf();
  const nlohmann::json doc = nlohmann::json::parse(ss.str(), nullptr, false);
  ASSERT_FALSE(doc.is_discarded());
  EXPECT_EQ(doc["frames"].size(), 30u);
  EXPECT_EQ(doc["summary"]["pngs_written"].get<int>(), 4);
  // Readback time belongs to saved frames only; the summary's keys are the
  // report's (gpu_hit_rate, not a ratio).
  for (const nlohmann::json& f : doc["frames"]) {
    const int i = f["frame"].get<int>();
    const bool saved = i % 10 == 0 || i == 29;
    if (saved) EXPECT_GT(f["readback_ms"].get<double>(), 0.0) << "frame " << i;
    else EXPECT_EQ(f["readback_ms"].get<double>(), 0.0) << "frame " << i;
  }
  EXPECT_TRUE(doc["summary"].contains("gpu_hit_rate"));
  EXPECT_FALSE(doc["summary"].contains("gpu_hit_ratio"));
  EXPECT_EQ(doc["summary"]["render_thread_fetches"].get<int>(), 0);
  fs::remove_all(dir);
}

// --path-hint: the hinted camera must be the flown one in every frame
// (warm-up, speed, looping and rest frames included), or the streamer
// ignores the hint.
TEST(ClipstreamFly, PathHintMatchesTheFlownCameraInEveryFrame) {
  CLIPSTREAM_REQUIRE_GL();
  const fs::path dir = fs::temp_directory_path() / ("clipstream_fly_hint_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  auto fly = [&](const std::string& args) {
    const fs::path out = dir / "out";
    fs::remove_all(out);
    // A texture large enough for clip windows that move every frame.
    const std::string cmd = std::string(CLIPSTREAM_FLY_EXE) + " --procedural 1048576" +
                            " --size 256x192 --io-threads 2 --out " + out.string() + " " + args + " > " +
                            (dir / "log.txt").string() + " 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    std::ifstream json_in(out / "frames.json");
    std::stringstream ss;
    ss << json_in.rdbuf();
    return nlohmann::json::parse(ss.str(), nullptr, false);
  };
  const nlohmann::json hinted =
      fly("--path pass --path-hint --warmup-frames 5 --frames 40 --rest-frames 3 --speed 7 --loop");
  ASSERT_FALSE(hinted.is_discarded());
  const nlohmann::json& acc = hinted["summary"]["accuracy"];
  EXPECT_TRUE(acc["path_hint"].get<bool>());
  EXPECT_EQ(acc["path_hint_frames"].get<int>(), 5 + 40 + 3);
  EXPECT_EQ(acc["path_hint_ignored_frames"].get<int>(), 0);
  const nlohmann::json plain = fly("--path pass --warmup-frames 5 --frames 40 --speed 7 --loop");
  ASSERT_FALSE(plain.is_discarded());
  EXPECT_FALSE(plain["summary"]["accuracy"]["path_hint"].get<bool>());
  EXPECT_EQ(plain["summary"]["accuracy"]["path_hint_frames"].get<int>(), 0);
  fs::remove_all(dir);
}

TEST(ClipstreamFly, FailsWithAMessageForACorruptStore) {
  const fs::path dir = fs::temp_directory_path() / ("clipstream_fly_bad_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path bad = dir / "bad.cstore";
  std::ofstream(bad) << "this is not a tile store";
  const std::string cmd = std::string(CLIPSTREAM_FLY_EXE) + " " + bad.string() + " --frames 2 --out " +
                          (dir / "out").string() + " > " + (dir / "log.txt").string() + " 2>&1";
  const int rc = std::system(cmd.c_str());
  EXPECT_NE(rc, 0);
  std::ifstream log(dir / "log.txt");
  std::stringstream ss;
  ss << log.rdbuf();
  EXPECT_NE(ss.str().find("clipstream-fly:"), std::string::npos) << ss.str();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace clipstream
