// Where tests find real data: the one rule (docs/decisions.md D154).
//
// * Bundled data, the repository's data/ (data/autzen.jpg + .wld): shipped
//   with the product, so present in every checkout and in CI. A test that
//   needs it never skips: a missing bundled file fails the test.
// * Shared data, ../shared/data beside the checkout (real DEMs, the globe,
//   the Landsat scene): for tests and benchmarks only; the product must not
//   read it at run time. Configured by the CMake cache variable
//   CLIPSTREAM_SHARED_DATA_DIR; the environment variable of the same name
//   overrides it at run time. A test that needs a shared file skips, naming
//   the path it looked for, when the file is absent.
//
// A file that is in both places is read from data/: a test then runs
// wherever the product's own sample runs.
//
// Thread rule: plain functions reading the file system and the environment;
// any thread.
#pragma once

#include <gtest/gtest.h>

#include <string>
#include <string_view>

namespace clipstream::test {

// <source>/data/<name>, whether or not it exists (the test's own open then
// fails naming it).
std::string bundledDataPath(std::string_view name);

// The shared data folder in force (environment, else CMake), or "" when it
// is not a directory.
std::string sharedDataDir();

// <shared>/<name>, or "" when that file is absent.
std::string sharedDataPath(std::string_view name);

// The skip message for an absent shared file: the path looked for and how
// to point the tests elsewhere.
std::string sharedDataAbsent(std::string_view name);

}  // namespace clipstream::test

// Skips the calling test (GTEST_SKIP, so only in the test body or a fixture's
// SetUp) when the shared file `name` is absent; then
// sharedDataPath(name) is its path.
#define CLIPSTREAM_REQUIRE_SHARED_DATA(name)                                    \
  do {                                                                          \
    if (::clipstream::test::sharedDataPath(name).empty())                       \
      GTEST_SKIP() << ::clipstream::test::sharedDataAbsent(name);               \
  } while (0)
