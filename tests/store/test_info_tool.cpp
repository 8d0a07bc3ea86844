// clipstream-info end to end: runs the built program on real files.
#include "store_test_util.h"

#include <sys/wait.h>

#include <cstdio>

namespace clipstream {
namespace {

struct RunResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

RunResult runInfo(const std::string& arguments) {
  const std::string command =
      std::string("CLIPSTREAM_PROGRESS=0 '") + CLIPSTREAM_INFO_EXE + "' " + arguments + " 2>&1";
  RunResult result;
  FILE* pipe = ::popen(command.c_str(), "r");
  if (pipe == nullptr) return result;
  char buffer[4096];
  size_t got;
  while ((got = std::fread(buffer, 1, sizeof(buffer), pipe)) > 0) result.output.append(buffer, got);
  const int status = ::pclose(pipe);
  if (WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
  return result;
}

class InfoTool : public ::testing::Test {
 protected:
  void SetUp() override {
    m_dir = testutil::tempDir("info");
    m_path = (m_dir / "store.cst").string();
    ASSERT_TRUE(makePyramidGeometry(300, 200, 32, PixelFormat::kRGB8, &m_geometry));
    WriterOptions options;
    options.fsync = false;
    options.geo.present = true;
    options.geo.crs = "EPSG:2992";
    options.geo.transform[0] = 635000.0;
    options.geo.transform[3] = 849000.0;
    ASSERT_TRUE(testutil::writeStore(m_path, m_geometry, options).isOk());
  }
  void TearDown() override { std::filesystem::remove_all(m_dir); }

  std::filesystem::path m_dir;
  std::string m_path;
  PyramidGeometry m_geometry;
};

TEST_F(InfoTool, VerifiesAGoodStoreAndPrintsItsHeader) {
  const RunResult result = runInfo("--verify --threads 2 '" + m_path + "'");
  EXPECT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("300 x 200 px, RGB8"), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("EPSG:2992"), std::string::npos);
  EXPECT_NE(result.output.find("verify: OK"), std::string::npos) << result.output;
}

TEST_F(InfoTool, JsonOutputCarriesLevelTable) {
  const RunResult result = runInfo("--json '" + m_path + "'");
  EXPECT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("\"level_stats\""), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("\"tile_px\": 32"), std::string::npos) << result.output;
}

TEST_F(InfoTool, VerifyNamesTheTileWithAFlippedPayloadByte) {
  TileLocation location;
  const TileKey key{0, 3, 2};
  ASSERT_FALSE(testutil::isConstantTile(key));
  {
    std::unique_ptr<TileStoreReader> reader;
    ASSERT_TRUE(TileStoreReader::open(m_path, &reader).isOk());
    ASSERT_TRUE(reader->locate(key, &location).isOk());
    ASSERT_FALSE(location.constant);
  }
  std::vector<uint8_t> bytes = testutil::readFile(m_path);
  bytes[location.offset + 1] ^= 0x10;
  testutil::writeFile(m_path, bytes, bytes.size());
  const RunResult result = runInfo("--verify '" + m_path + "'");
  EXPECT_EQ(result.exit_code, 3) << result.output;
  EXPECT_NE(result.output.find("level 0 tile (3, 2): corrupt tile: payload checksum mismatch"),
            std::string::npos)
      << result.output;
  // Without --verify the flip is not looked for: the header still reads.
  EXPECT_EQ(runInfo("'" + m_path + "'").exit_code, 0);
}

TEST_F(InfoTool, OpenErrorsExitNonZeroWithAMessage) {
  const RunResult missing = runInfo("'" + (m_dir / "absent.cst").string() + "'");
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.output.find("absent.cst"), std::string::npos) << missing.output;
  std::vector<uint8_t> bytes = testutil::readFile(m_path);
  testutil::writeFile(m_path, bytes, bytes.size() / 2);
  const RunResult truncated = runInfo("'" + m_path + "'");
  EXPECT_EQ(truncated.exit_code, 2);
  EXPECT_NE(truncated.output.find("truncated"), std::string::npos) << truncated.output;
  EXPECT_EQ(runInfo("--no-such-flag").exit_code, 1);
}

}  // namespace
}  // namespace clipstream
