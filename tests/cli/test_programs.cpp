// Every program: --version prints "NAME VERSION" and exits 0; --help shows
// the options' defaults (the first hour: "--size TEXT Viewport" said nothing
// of 1280x720). The programs are the built ones (CLIPSTREAM_PROGRAMS).
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <cstdio>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace {

struct Output {
  int exit_code = -1;
  std::string text;  // stdout + stderr
};

Output run(const std::string& command) {
  Output out;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (pipe == nullptr) return out;
  char buffer[4096];
  size_t got;
  while ((got = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) out.text.append(buffer, got);
  const int status = ::pclose(pipe);
  if (WIFEXITED(status)) out.exit_code = WEXITSTATUS(status);
  return out;
}

// CLIPSTREAM_PROGRAMS: "path|path|..." of every built program.
std::vector<std::string> programs() {
  std::vector<std::string> paths;
  std::stringstream list(CLIPSTREAM_PROGRAMS);
  for (std::string path; std::getline(list, path, '|');)
    if (!path.empty()) paths.push_back(path);
  return paths;
}

std::string baseName(const std::string& path) { return path.substr(path.rfind('/') + 1); }

TEST(Programs, EveryOneHasVersion) {
  ASSERT_GE(programs().size(), 4u);
  for (const std::string& program : programs()) {
    const Output out = run("'" + program + "' --version");
    EXPECT_EQ(out.exit_code, 0) << program << ": " << out.text;
    EXPECT_EQ(out.text, baseName(program) + " " + CLIPSTREAM_VERSION + "\n") << program;
  }
}

TEST(Programs, HelpShowsDefaults) {
  for (const std::string& program : programs()) {
    const Output out = run("'" + program + "' --help");
    EXPECT_EQ(out.exit_code, 0) << program << ": " << out.text;
    EXPECT_NE(out.text.find("--version"), std::string::npos) << program << ": " << out.text;
  }
  // One option of each program that has a default, as --help shows it.
  const std::vector<std::pair<std::string, std::string>> shown = {
      {"clipstream-tile", "--memory-mb UINT"}, {"clipstream-fly", "--size TEXT=1280x720"},
      {"clipstream-view", "--size TEXT=1280x720"}, {"clipstream-info", "--disk-cache-mb"}};
  for (const std::string& program : programs()) {
    for (const auto& [name, text] : shown) {
      if (baseName(program) != name) continue;
      const Output out = run("'" + program + "' --help");
      EXPECT_NE(out.text.find(text), std::string::npos) << program << " --help:\n" << out.text;
    }
  }
}

}  // namespace
