#include <clipstream/testing/test_data.h>

#include <cstdlib>
#include <filesystem>
#include <system_error>

namespace clipstream::test {
namespace {

std::string configuredSharedDir() {
  const char* env = std::getenv("CLIPSTREAM_SHARED_DATA_DIR");
  return (env != nullptr && *env != '\0') ? std::string(env) : std::string(CLIPSTREAM_SHARED_DATA_DIR);
}

}  // namespace

std::string bundledDataPath(std::string_view name) {
  return (std::filesystem::path(CLIPSTREAM_BUNDLED_DATA_DIR) / name).string();
}

std::string sharedDataDir() {
  const std::string dir = configuredSharedDir();
  std::error_code ec;
  return std::filesystem::is_directory(dir, ec) ? dir : std::string();
}

std::string sharedDataPath(std::string_view name) {
  const std::string dir = sharedDataDir();
  if (dir.empty()) return "";
  const std::string path = (std::filesystem::path(dir) / name).string();
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec) ? path : std::string();
}

std::string sharedDataAbsent(std::string_view name) {
  return "shared test data absent: " + (std::filesystem::path(configuredSharedDir()) / name).string() +
         " (set CLIPSTREAM_SHARED_DATA_DIR, in CMake or the environment, to the folder that has it)";
}

}  // namespace clipstream::test
