// TempDir: the one temporary directory of the tests. Unique per instance
// (mkdtemp), so tests running in parallel (ctest -j), forked children and
// repeated runs never share or inherit files; removed with everything in it
// when the instance goes out of scope.
//
// Thread rule: an instance belongs to the thread that made it; path(),
// file() and entries() are const and may be called from any thread while
// the instance lives.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace clipstream::test {

class TempDir {
 public:
  // Creates <temp>/clipstream-<label>-XXXXXX. `label` only helps a person
  // find a directory left by a crashed run; any short name will do. Throws
  // std::runtime_error naming the path and errno's text if it cannot be
  // made (gtest reports that as a failure of the test).
  explicit TempDir(std::string_view label = "test");
  // Removes the directory and its contents; errors are ignored (a test that
  // must leave nothing behind checks entries() itself).
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return m_path; }
  // The path of `name` inside the directory, as a string (whatever open()
  // and the programs under test take). `name` may contain '/'.
  std::string file(std::string_view name) const;
  // Names of everything directly inside, sorted: what a test compares to
  // prove nothing was left behind.
  std::vector<std::string> entries() const;

 private:
  std::filesystem::path m_path;
};

}  // namespace clipstream::test
