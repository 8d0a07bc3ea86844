// Every program: --version prints "NAME VERSION" and exits 0; --help shows
// the options' defaults (the first hour: "--size TEXT Viewport" said nothing
// of 1280x720); its manual page (help2man, at build time) lists its
// options; bash completes its long options (cmake/bash_completion). The
// programs are the built ones (CLIPSTREAM_PROGRAMS).
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

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

// Runs SCRIPT with bash, bash-completion and our completion loaded.
Output runBash(const std::string& script) {
  char path[] = "/tmp/clipstream-completion-XXXXXX";
  const int fd = ::mkstemp(path);
  if (fd < 0) return {};
  const std::string text = "source /usr/share/bash-completion/bash_completion\nsource '" +
                           std::string(CLIPSTREAM_COMPLETION) + "'\n" + script + "\n";
  const bool written = ::write(fd, text.data(), text.size()) == static_cast<ssize_t>(text.size());
  ::close(fd);
  Output out = written ? run(std::string("bash ") + path) : Output{};
  ::unlink(path);
  return out;
}

// What bash-completion offers for LINE (the word being completed is its
// last), with the program's folder on PATH as an installed program is.
std::vector<std::string> complete(const std::string& program, const std::string& line) {
  const std::string folder = program.substr(0, program.rfind('/'));
  const Output out = runBash(
      "PATH='" + folder + "':$PATH\nCOMP_LINE='" + line + "'\nCOMP_POINT=${#COMP_LINE}\n"
      "read -ra COMP_WORDS <<<\"$COMP_LINE\"\nCOMP_CWORD=$((${#COMP_WORDS[@]} - 1))\n"
      "_clipstream_complete \"${COMP_WORDS[0]}\" \"${COMP_WORDS[COMP_CWORD]}\" x\n"
      "printf '%s\\n' \"${COMPREPLY[@]}\"");
  std::vector<std::string> words;
  std::stringstream lines(out.text);
  for (std::string w; std::getline(lines, w);)
    if (!w.empty()) words.push_back(w);
  return words;
}

bool contains(const std::vector<std::string>& words, const std::string& word) {
  for (const std::string& w : words)
    if (w == word) return true;
  return false;
}

TEST(Programs, BashCompletesTheLongOptionsFromHelp) {
  if (::access("/usr/share/bash-completion/bash_completion", R_OK) != 0)
    GTEST_SKIP() << "bash-completion is not installed (scripts/deps.sh installs it)";
  for (const std::string& program : programs()) {
    const std::string name = baseName(program);
    // Registered under the program's name, as bash-completion loads it.
    const Output registered = runBash("complete -p " + name);
    EXPECT_NE(registered.text.find("_clipstream_complete " + name), std::string::npos) << registered.text;
    const std::vector<std::string> all = complete(program, name + " --");
    EXPECT_TRUE(contains(all, "--help")) << name;
    EXPECT_TRUE(contains(all, "--version")) << name;
    EXPECT_GE(all.size(), 3u) << name;
    for (const std::string& w : all) EXPECT_EQ(w.rfind("--", 0), 0u) << name << ": " << w;
  }
  for (const std::string& program : programs()) {
    if (baseName(program) != "clipstream-tile") continue;
    EXPECT_EQ(complete(program, "clipstream-tile --memo"), std::vector<std::string>{"--memory-mb"});
  }
}

TEST(Programs, ManualPagesListTheirOptions) {
  const std::string folder = CLIPSTREAM_MAN_DIR;
  if (folder.empty()) GTEST_SKIP() << "help2man was not found at configure time: no manual pages";
  for (const std::string& program : programs()) {
    const std::string name = baseName(program);
    const Output page = run("zcat '" + folder + "/" + name + ".1.gz'");
    ASSERT_EQ(page.exit_code, 0) << name << ": " << page.text;
    EXPECT_NE(page.text.find(".SH NAME"), std::string::npos) << name;
    EXPECT_NE(page.text.find(name + " \\- "), std::string::npos) << name << ":\n" << page.text.substr(0, 600);
    EXPECT_NE(page.text.find("version"), std::string::npos) << name;
    EXPECT_NE(page.text.find(CLIPSTREAM_VERSION), std::string::npos) << name;
  }
}

}  // namespace
