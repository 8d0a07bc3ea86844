// clipstream-info end to end: runs the built program on real files.
#include <clipstream/store/tile_store.h>
#include <clipstream/testing/files.h>
#include <clipstream/testing/synthetic_store.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <span>

namespace clipstream {
namespace {

struct RunResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};

// `arguments` may end in a redirection of standard output; stderr is
// captured either way.
RunResult runInfo(const std::string& arguments, const std::string& prefix = "") {
  const std::string command = "{ CLIPSTREAM_PROGRESS=0 " + prefix + "'" + CLIPSTREAM_INFO_EXE + "' " +
                              arguments + "; } 2>&1";
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
    m_path = m_dir.file("store.cst");
    ASSERT_TRUE(makePyramidGeometry(300, 200, 32, PixelFormat::kRGB8, &m_geometry));
    WriterOptions options;
    options.fsync = false;
    options.geo.present = true;
    options.geo.crs = "EPSG:2992";
    options.geo.transform[0] = 635000.0;
    options.geo.transform[3] = 849000.0;
    ASSERT_TRUE(test::writeSyntheticStore(m_path, m_geometry, options).ok());
  }

  test::TempDir m_dir{"info"};
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
  ASSERT_FALSE(test::isConstantTile(key));
  {
    std::unique_ptr<TileStoreReader> reader;
    ASSERT_TRUE(TileStoreReader::open(m_path, &reader).ok());
    ASSERT_TRUE(reader->locate(key, &location).ok());
    ASSERT_FALSE(location.constant);
  }
  std::vector<uint8_t> bytes = test::readBytes(m_path);
  bytes[location.offset + 1] ^= 0x10;
  test::writeBytes(m_path, bytes);
  const RunResult result = runInfo("--verify '" + m_path + "'");
  EXPECT_EQ(result.exit_code, 3) << result.output;
  EXPECT_NE(result.output.find("level 0 tile (3, 2): corrupt tile: payload checksum mismatch"),
            std::string::npos)
      << result.output;
  // Without --verify the flip is not looked for: the header still reads.
  EXPECT_EQ(runInfo("'" + m_path + "'").exit_code, 0);
}

TEST_F(InfoTool, OpenErrorsExitNonZeroWithAMessage) {
  const RunResult missing = runInfo("'" + m_dir.file("absent.cst") + "'");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("absent.cst"), std::string::npos) << missing.output;
  const std::vector<uint8_t> bytes = test::readBytes(m_path);
  test::writeBytes(m_path, std::span(bytes).first(bytes.size() / 2));
  const RunResult truncated = runInfo("'" + m_path + "'");
  EXPECT_EQ(truncated.exit_code, 1);
  EXPECT_NE(truncated.output.find("truncated"), std::string::npos) << truncated.output;
}

// The programs' one exit-code table (docs/cli.md): a command-line mistake is
// 2 in every program, with one plain line naming the option.
TEST_F(InfoTool, CommandLineMistakesExitTwo) {
  for (const std::string& args : {"--no-such-flag '" + m_path + "'", std::string(""),
                                 "--threads 100000 '" + m_path + "'", "--threads -1 '" + m_path + "'",
                                 "--threads 1e999 '" + m_path + "'"}) {
    const RunResult result = runInfo(args);
    EXPECT_EQ(result.exit_code, 2) << args << ": " << result.output;
    EXPECT_LT(result.output.size(), 300u) << result.output;
  }
  EXPECT_NE(runInfo("--threads 100000 '" + m_path + "'").output.find("--threads"), std::string::npos);
}

// A FIFO given as the store once made the program wait forever for a writer.
TEST_F(InfoTool, AFifoIsRefusedWithoutWaiting) {
  const std::string fifo = m_dir.file("fifo.cst");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  for (const char* flags : {"", "--verify ", "--json "}) {
    // timeout(1) turns a hang into exit 124 instead of a stuck suite.
    const RunResult result = runInfo(std::string(flags) + "'" + fifo + "'", "timeout 20 ");
    EXPECT_EQ(result.exit_code, 1) << flags << result.output;
    EXPECT_NE(result.output.find("is a FIFO"), std::string::npos) << result.output;
  }
}

// A report that cannot be written (a full disk, /dev/full) is a failure,
// not a success with nothing printed.
TEST_F(InfoTool, AFailedWriteOfTheReportExitsOne) {
  for (const char* flags : {"", "--json ", "--verify "}) {
    const RunResult result = runInfo(std::string(flags) + "'" + m_path + "' >/dev/full");
    EXPECT_EQ(result.exit_code, 1) << flags << result.output;
    EXPECT_NE(result.output.find("cannot write standard output"), std::string::npos) << result.output;
  }
}

TEST_F(InfoTool, BadInputsGiveOneLineAndExitOne) {
  const std::string empty = m_dir.file("empty.cst");
  test::writeBytes(empty, {});
  // The first bytes of a JFIF file.
  const std::vector<uint8_t> jpeg = {0xff, 0xd8, 0xff, 0xe0, 0x00, 0x10, 'J', 'F', 'I', 'F', 0x00,
                                     0x01, 0x01, 0x00, 0x00, 0x01, 0x00, 0x01, 0x00, 0x00};
  const std::string jpeg_path = m_dir.file("photo.jpg");
  test::writeBytes(jpeg_path, jpeg);
  const std::string sub = m_dir.file("sub");
  std::filesystem::create_directories(sub);
  const struct {
    std::string path;
    const char* expect;
  } cases[] = {{empty, "truncated"}, {jpeg_path, "bad magic"}, {sub, "is a directory"},
               {m_dir.file("absent.cst"), "not found"}};
  for (const auto& c : cases) {
    for (const char* flags : {"", "--verify ", "--json "}) {
      const RunResult result = runInfo(std::string(flags) + "'" + c.path + "'");
      EXPECT_EQ(result.exit_code, 1) << flags << c.path << ": " << result.output;
      EXPECT_NE(result.output.find(c.expect), std::string::npos) << result.output;
      EXPECT_NE(result.output.find(c.path), std::string::npos) << result.output;
      // One line: the message, then the newline that ends it.
      EXPECT_EQ(result.output.find('\n'), result.output.size() - 1) << result.output;
    }
  }
}

TEST_F(InfoTool, CrsTextThatIsNotUtf8OrHasControlBytesIsPrintedSafely) {
  // The CRS comes from the file: invalid UTF-8 once made --json throw
  // (and abort); a newline or escape must not break the one-line field.
  WriterOptions options;
  options.fsync = false;
  options.geo.present = true;
  options.geo.crs = "EPSG:\xff\xfe\n\x1b[2Jx";
  const std::string path = m_dir.file("odd_crs.cst");
  ASSERT_TRUE(test::writeSyntheticStore(path, m_geometry, options).ok());
  const RunResult json = runInfo("--json '" + path + "'");
  EXPECT_EQ(json.exit_code, 0) << json.output;
  EXPECT_NE(json.output.find("\"crs\": \"EPSG:"), std::string::npos) << json.output;
  const RunResult text = runInfo("'" + path + "'");
  EXPECT_EQ(text.exit_code, 0) << text.output;
  EXPECT_EQ(text.output.find('\x1b'), std::string::npos) << text.output;
  const size_t crs = text.output.find("CRS ");
  ASSERT_NE(crs, std::string::npos) << text.output;
  const std::string line = text.output.substr(crs, text.output.find('\n', crs) - crs);
  EXPECT_NE(line.find("[2Jx"), std::string::npos) << line;
}

// --tiles lists what the index records of each tile: two files holding the
// same tiles in another payload order list the same, and a store with
// other tiles (no constant tiles) does not.
TEST_F(InfoTool, TilesListTheSameTilesWhateverTheirPlaceInTheFile) {
  const std::string curve = m_dir.file("curve.cst"), other = m_dir.file("other.cst");
  WriterOptions options;
  options.fsync = false;
  options.geo.present = true;
  options.geo.crs = "EPSG:2992";
  options.geo.transform[0] = 635000.0;
  options.geo.transform[3] = 849000.0;
  options.payload_order = PayloadOrder::kCurve;
  ASSERT_TRUE(test::writeSyntheticStore(curve, m_geometry, options).ok());
  ASSERT_NE(test::readBytes(curve), test::readBytes(m_path));  // laid out differently
  ASSERT_TRUE(test::writeSyntheticStore(other, m_geometry, options, test::ConstantTiles::kNone).ok());

  const RunResult written = runInfo("--tiles '" + m_path + "'");
  const RunResult curved = runInfo("--tiles '" + curve + "'");
  const RunResult changed = runInfo("--tiles '" + other + "'");
  ASSERT_EQ(written.exit_code, 0) << written.output;
  auto tileLines = [](const std::string& text) { return text.substr(text.find("\ntile 0 0 0 ") + 1); };
  size_t tiles = 0;
  for (const LevelInfo& level : m_geometry.levels) tiles += size_t(level.tiles_x) * level.tiles_y;
  const std::string list = tileLines(written.output);
  EXPECT_EQ(size_t(std::count(list.begin(), list.end(), '\n')), tiles);
  EXPECT_NE(list.find("tile 0 0 0 "), std::string::npos);
  EXPECT_NE(list.find(" constant "), std::string::npos);  // one key in five is constant
  EXPECT_EQ(tileLines(curved.output), list);
  EXPECT_NE(tileLines(changed.output), list);

  const RunResult json = runInfo("--json --tiles '" + m_path + "'");
  ASSERT_EQ(json.exit_code, 0) << json.output;
  EXPECT_NE(json.output.find("\"tiles\": ["), std::string::npos);
  EXPECT_NE(json.output.find("\"checksum\""), std::string::npos);
}

}  // namespace
}  // namespace clipstream
