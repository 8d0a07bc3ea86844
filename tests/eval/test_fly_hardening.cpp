// clipstream-fly against the hostile-input findings: a FIFO as the store, a
// full disk while frames and statistics are written, an unwritable trace,
// absurd numbers, signals and an earlier run's files in --out. Each test
// failed on the code before the fix (docs/cli.md has the rules they pin).
#include "test_helpers.h"

#include <clipstream/eval/frame_writer.h>
#include <clipstream/renderer/renderer.h>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

namespace clipstream {
namespace {

namespace fs = std::filesystem;

struct FlyRun {
  int exit_code = -1;    // -1 when killed by a signal
  int signal = 0;
  std::string output;    // stdout + stderr
};

// Runs clipstream-fly in a child: `limit_bytes` > 0 sets a file-size limit
// with SIGXFSZ ignored, so writes fail as on a full disk (ENOSPC and EFBIG
// take the same path). `on_start` runs in the parent while the child runs.
FlyRun runFly(const std::vector<std::string>& args, const std::string& log, rlim_t limit_bytes = 0,
           const std::function<void(pid_t)>& on_start = {}) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    if (limit_bytes > 0) {
      ::signal(SIGXFSZ, SIG_IGN);
      rlimit limit{limit_bytes, limit_bytes};
      ::setrlimit(RLIMIT_FSIZE, &limit);
    }
    std::vector<char*> argv = {const_cast<char*>(CLIPSTREAM_FLY_EXE)};
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    // A hang fails the test instead of stopping the suite.
    ::alarm(120);
    ::execv(CLIPSTREAM_FLY_EXE, argv.data());
    ::_exit(127);
  }
  if (on_start) on_start(pid);
  int status = 0;
  ::waitpid(pid, &status, 0);
  FlyRun run;
  if (WIFEXITED(status)) run.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) run.signal = WTERMSIG(status);
  std::ifstream in(log);
  run.output.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  return run;
}

std::vector<std::string> namesIn(const fs::path& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

// Every file in `dir` is whole: no temporary, no empty file, every PNG
// decodes to the full frame.
void expectOnlyWholeFiles(const fs::path& dir, uint32_t width_px, uint32_t height_px) {
  for (const std::string& name : namesIn(dir)) {
    const fs::path path = dir / name;
    EXPECT_EQ(name.find(".tmp"), std::string::npos) << "temporary left: " << name;
    EXPECT_GT(fs::file_size(path), 0u) << name;
    if (path.extension() == ".png") {
      std::vector<uint8_t> rgba;
      uint32_t w = 0, h = 0;
      EXPECT_TRUE(readImageRgba(path.string(), &rgba, &w, &h).ok()) << name << " does not decode";
      EXPECT_EQ(w, width_px);
      EXPECT_EQ(h, height_px);
    }
  }
}

// Bug 5: a FIFO given as the store hung the program forever.
TEST(FlyHardening, AFifoStoreIsRefusedWithoutWaiting) {
  test::TempDir dir("fly_fifo");
  const std::string fifo = dir.file("store.cstore");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  const FlyRun run = runFly({fifo, "--frames", "2", "--out", dir.file("out")}, dir.file("log"));
  EXPECT_EQ(run.exit_code, 1) << run.output;
  EXPECT_NE(run.output.find("is a FIFO"), std::string::npos) << run.output;
}

// Bug 6 and 9 and the minor items: --io-threads 100000 aborted (SIGABRT);
// parser errors exited with CLI11's raw codes; nan, 0 and absurd delays ran
// silently (or hung).
TEST(FlyHardening, AbsurdNumbersAreCommandLineMistakes) {
  test::TempDir dir("fly_args");
  const std::vector<std::vector<std::string>> cases = {
      {"--io-threads", "100000"}, {"--speed", "nan"},          {"--speed", "-1"},
      {"--speed", "1e999"},       {"--cache-mb", "0"},         {"--upload-tiles", "0"},
      {"--frames", "0"},          {"--fault-latency-ms", "1e308"}, {"--rest-frame-ms", "1e308"},
      {"--fault-corrupt", "nan"}, {"--size", "99999x2"},      {"--size", "0x0"},
      {"--no-such-flag"},         {"--teleport-frames", "0"}, {"--reference-every", "0"},
      // Terrain choices without terrain would be ignored; a method that
      // does not exist, or a bound of no pixels, cannot be flown.
      {"--terrain", "quadtree"},  {"--terrain-error", "0"},   {"--terrain-error", "nan"},
      {"--terrain", "mesh", "--elevation", "dem.cst"},
      {"--terrain-lighting", "pixel"},  {"--terrain-lighting", "phong", "--elevation", "dem.cst"},
      {"--reference-lighting", "pixel", "--elevation", "dem.cst"}, {"--terrain-detail"},
      {"--synthesize-relief", "2"}, {"--synthesize-relief", "9", "--elevation", "dem.cst"},
      {"--look-at", "1,2,3,4"}, {"--look-at", "nan,2"}, {"--look-at", "1,2", "--path", "orbit"}};
  for (std::vector<std::string> args : cases) {
    const std::string what = args[0] + (args.size() > 1 ? " " + args[1] : "");
    args.insert(args.begin(), {"--procedural", "4096", "--out", dir.file("out")});
    const FlyRun run = runFly(args, dir.file("log"));
    EXPECT_EQ(run.exit_code, 2) << what << ": " << run.output;
    EXPECT_LT(run.output.size(), 300u) << what << ": " << run.output;
    if (what.rfind("--size", 0) != 0 && what != "--no-such-flag") {
      EXPECT_NE(run.output.find(args[4]), std::string::npos) << what << ": " << run.output;
    }
  }
  EXPECT_FALSE(fs::exists(dir.file("out"))) << "a mistake writes nothing";
}

// Bug 10: --trace to an unwritable path only warned and exited 0.
TEST(FlyHardening, AnUnwritableTraceFailsBeforeAnyWork) {
  test::TempDir dir("fly_trace");
  const std::string fifo = dir.file("trace.fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  for (const std::string& trace : {std::string("/nonexistent-dir/t.trace"), fifo, dir.path().string()}) {
    const FlyRun run = runFly({"--procedural", "4096", "--frames", "2", "--trace", trace, "--out",
                            dir.file("out")},
                           dir.file("log"));
    EXPECT_EQ(run.exit_code, 1) << trace << ": " << run.output;
    EXPECT_NE(run.output.find(trace), std::string::npos) << run.output;
  }
  struct stat st {};
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
}

// Bug 4: on a full disk the run exited 1 but left a truncated PNG under its
// final name (the PNG writer did not report the failed write), 0-byte PNGs
// and frames.csv.tmp.
TEST(FlyHardening, AFullDiskLeavesOnlyWholeFiles) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("fly_full");
  // 640x360 frames are larger than the 8 KiB limit: every PNG fails.
  const fs::path out = dir.file("big");
  FlyRun run = runFly({"--procedural", "65536", "--path", "pass", "--frames", "3", "--size", "640x360",
                    "--save-frames", "1", "--io-threads", "2", "--trace", dir.file("t.trace"), "--out",
                    out.string()},
                   dir.file("log"), 8192);
  EXPECT_EQ(run.exit_code, 1) << run.output;
  EXPECT_FALSE(fs::exists(dir.file("t.trace"))) << "a failed run published its trace";
  EXPECT_NE(run.output.find("frame_0000"), std::string::npos) << run.output;
  expectOnlyWholeFiles(out, 640, 360);
  EXPECT_FALSE(fs::exists(out / "frames.csv"));
  // 160x90 frames fit, frames.json does not: no statistics file at all.
  const fs::path small = dir.file("small");
  run = runFly({"--procedural", "65536", "--path", "pass", "--frames", "3", "--size", "160x90",
                "--save-frames", "1", "--io-threads", "2", "--out", small.string()},
               dir.file("log"), 8192);
  EXPECT_EQ(run.exit_code, 1) << run.output;
  expectOnlyWholeFiles(small, 160, 90);
  EXPECT_FALSE(fs::exists(small / "frames.csv"));
  EXPECT_FALSE(fs::exists(small / "summary.tsv"));
  EXPECT_TRUE(fs::exists(small / "frame_00002.png"));
}

// Minor: stale PNGs of an earlier run stayed in --out. A new run removes
// what an earlier run wrote there, and nothing else.
TEST(FlyHardening, AnEarlierRunsFilesAreRemovedAndOthersKept) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("fly_stale");
  const fs::path out = dir.file("out");
  fs::create_directories(out);
  for (const char* name : {"frame_99999.png", "frames.csv", "summary.tsv"}) std::ofstream(out / name) << "old";
  std::ofstream(out / "notes.txt") << "mine";
  fs::create_directories(out / "frame_00001.png");  // not a regular file: kept, and the frame fails
  FlyRun run = runFly({"--procedural", "65536", "--frames", "2", "--size", "160x90", "--save-frames", "1",
                    "--out", out.string()},
                   dir.file("log"));
  EXPECT_EQ(run.exit_code, 1) << run.output;
  fs::remove(out / "frame_00001.png");
  run = runFly({"--procedural", "65536", "--frames", "2", "--size", "160x90", "--save-frames", "1",
                "--out", out.string()},
               dir.file("log"));
  EXPECT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(namesIn(out), (std::vector<std::string>{"frame_00000.png", "frame_00001.png", "frames.csv",
                                                    "frames.json", "notes.txt", "summary.tsv"}));
  std::ifstream notes(out / "notes.txt");
  std::string text;
  notes >> text;
  EXPECT_EQ(text, "mine");
  expectOnlyWholeFiles(out, 160, 90);
}

// The value of `key` in the summary a run prints ("key\tvalue" lines), or
// "(none)".
std::string summaryValue(const std::string& output, const std::string& key) {
  const size_t at = output.find("\n" + key + "\t");
  if (at == std::string::npos) return "(none)";
  const size_t from = at + key.size() + 2;
  return output.substr(from, output.find('\n', from) - from);
}

// --texture-memory auto (the default) pages the flat plane, so a screen the
// stack cannot be allocated for still flies; it keeps the stack with double
// buffering, which the pool does not do (and with terrain:
// automaticTextureMemory()). A choice given is taken as given.
TEST(FlyHardening, TheDefaultTextureMemoryIsPagedWhereThePoolDrawsIt) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("fly_auto");
  auto mode = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = {"--procedural", "65536", "--frames", "2", "--size", "160x90",
                                     "--save-frames", "0", "--out", dir.file("out")};
    args.insert(args.end(), extra.begin(), extra.end());
    const FlyRun run = runFly(args, dir.file("log"));
    EXPECT_EQ(run.exit_code, 0) << run.output;
    return summaryValue(run.output, "texture_memory");
  };
  EXPECT_EQ(mode({}), "paged");
  EXPECT_EQ(mode({"--pool-mb", "8"}), "paged");
  EXPECT_EQ(mode({"--buffering", "double-upload"}), "stack");
  EXPECT_EQ(mode({"--texture-memory", "stack"}), "stack");
  EXPECT_EQ(mode({"--texture-memory", "auto", "--buffering", "single"}), "paged");
  EXPECT_TRUE(automaticTextureMemory(true, Buffering::kStaged) == TextureMemory::kStack);
  EXPECT_TRUE(automaticTextureMemory(false, Buffering::kDoubleCopy) == TextureMemory::kStack);
  EXPECT_TRUE(automaticTextureMemory(false, Buffering::kStaged) == TextureMemory::kPaged);
}

// --no-over-fetch skips the per-pixel trace of the sampled tiles (most of
// a judged run's time at 3840x2160), and only that: frames are still judged.
TEST(FlyHardening, NoOverFetchSkipsTheSampledTilesButStillJudges) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("fly_no_over_fetch");
  for (const bool skip : {false, true}) {
    std::vector<std::string> args = {"--procedural", "65536", "--frames", "3", "--size", "160x90", "--reference",
                                     "--deterministic", "--save-frames", "0", "--out", dir.file("out")};
    if (skip) args.push_back("--no-over-fetch");
    const FlyRun run = runFly(args, dir.file("log"));
    ASSERT_EQ(run.exit_code, 0) << run.output;
    const std::string ratio = summaryValue(run.output, "over_fetch_ratio");
    ASSERT_NE(ratio, "(none)") << run.output;
    if (skip) EXPECT_EQ(std::stod(ratio), 0.0) << run.output;
    else EXPECT_GT(std::stod(ratio), 0.0) << run.output;
    const std::string psnr = summaryValue(run.output, "psnr_mean_db");
    ASSERT_NE(psnr, "(none)") << run.output;
    EXPECT_GT(std::stod(psnr), 30.0) << run.output;
  }
}

// Bug 8: SIGHUP was not handled. Every signal that ends a run removes the
// temporaries and leaves only whole files.
TEST(FlyHardening, SignalsLeaveOnlyWholeFiles) {
  CLIPSTREAM_REQUIRE_GL();
  for (int signo : {SIGHUP, SIGTERM, SIGINT}) {
    test::TempDir dir("fly_signal");
    const fs::path out = dir.file("out");
    const FlyRun run = runFly({"--procedural", "65536", "--frames", "100000", "--size", "320x180",
                            "--save-frames", "1", "--out", out.string()},
                           dir.file("log"), 0, [&](pid_t pid) {
                             for (int i = 0; i < 2400 && !fs::exists(out / "frame_00003.png"); ++i)
                               std::this_thread::sleep_for(std::chrono::milliseconds(25));
                             ::kill(pid, signo);
                           });
    EXPECT_EQ(run.signal, signo) << run.output;
    EXPECT_TRUE(fs::exists(out / "frame_00003.png"));
    expectOnlyWholeFiles(out, 320, 180);
    EXPECT_FALSE(fs::exists(out / "frames.csv"));
  }
}

// A path file: two keyframes `duration_s` apart over a procedural texture.
std::string writePathJson(const std::string& path, double duration_s) {
  std::ofstream(path) << R"({"interpolation": "smooth", "keyframes": [)"
                      << R"({"t": 0, "x": 1000, "y": 300, "z": 1000, "heading_deg": 0, "pitch_deg": -30},)"
                      << R"({"t": )" << duration_s
                      << R"(, "x": 3000, "y": 300, "z": 1000, "heading_deg": 0, "pitch_deg": -30}]})";
  return path;
}

// Second pass: a FIFO as the path file hung; a long path at a low speed
// (no --frames) aborted with std::bad_alloc and left the trace temporary.
TEST(FlyHardening, APathThatIsAFifoOrTooLongIsRefused) {
  test::TempDir dir("fly_path");
  const std::string fifo = dir.file("path.fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  FlyRun run = runFly({"--procedural", "65536", "--path", fifo, "--out", dir.file("out")}, dir.file("log"));
  EXPECT_EQ(run.exit_code, 1) << run.output;
  EXPECT_NE(run.output.find("not a regular file"), std::string::npos) << run.output;
  const std::string long_path = writePathJson(dir.file("long.json"), 10000.0);
  run = runFly({"--procedural", "65536", "--path", long_path, "--speed", "0.001", "--trace", dir.file("t.trace"),
                "--out", dir.file("out")},
               dir.file("log"));
  EXPECT_EQ(run.exit_code, 1) << run.output;
  EXPECT_NE(run.output.find("--frames"), std::string::npos) << run.output;
  // An absurd duration is written as a number a person reads, not 300 digits.
  const std::string absurd = writePathJson(dir.file("absurd.json"), 1e300);
  run = runFly({"--procedural", "65536", "--path", absurd, "--out", dir.file("out")}, dir.file("log"));
  EXPECT_EQ(run.exit_code, 1) << run.output;
  EXPECT_NE(run.output.find("the path lasts 1e+300 s"), std::string::npos) << run.output;
  EXPECT_LT(run.output.size(), 400u) << run.output;
  EXPECT_EQ(namesIn(dir.path().string()),
            (std::vector<std::string>{"absurd.json", "log", "long.json", "path.fifo"}));
}

// Second pass: --trace naming an input (the path file) replaced it, and
// --trace or an input inside --out under a run file's name collided.
TEST(FlyHardening, TheTraceIsNeverAnInputNorARunFile) {
  test::TempDir dir("fly_inputs");
  const std::string path_file = writePathJson(dir.file("p.json"), 2.0);
  const fs::path out = dir.file("out");
  fs::create_directories(out);
  const std::string moved = writePathJson((out / "frames.csv").string(), 2.0);
  const std::vector<std::vector<std::string>> cases = {
      {"--path", path_file, "--trace", path_file},
      {"--path", path_file, "--trace", dir.file("./p.json")},
      {"--path", path_file, "--trace", (out / "frames.json").string()},
      {"--path", path_file, "--trace", (out / "frame_00001.png").string()},
      {"--path", moved}};
  for (std::vector<std::string> args : cases) {
    args.insert(args.begin(), {"--procedural", "65536", "--frames", "3", "--out", out.string()});
    const FlyRun run = runFly(args, dir.file("log"));
    EXPECT_EQ(run.exit_code, 1) << args[7] << ": " << run.output;
  }
  std::ifstream in(path_file);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("keyframes"), std::string::npos) << "the path file was overwritten";
  EXPECT_EQ(namesIn(out), std::vector<std::string>{"frames.csv"});
}

// Second pass: a bad --trace (or any failure before the first frame)
// removed the earlier run's results before failing; the sweep removed
// "frame_1.png" and other names the run never writes; "--frames 010" ran 8
// frames; --resize-at took negative and huge frame numbers.
TEST(FlyHardening, NothingIsRemovedBeforeTheRunCanStartAndOnlyItsOwnNames) {
  test::TempDir dir("fly_sweep");
  const fs::path out = dir.file("out");
  fs::create_directories(out);
  const std::vector<std::string> others = {"frame_1.png", "frame_000000.png", "frame_00000000000000000001.png",
                                           "frame_0000a.png", "FRAMES.CSV", "notes.txt"};
  for (const std::string& name : others) std::ofstream(out / name) << "mine";
  std::ofstream(out / "frame_00007.png") << "earlier run";
  std::ofstream(out / "summary.tsv") << "earlier run";
  FlyRun run = runFly({"--procedural", "65536", "--frames", "3", "--trace", dir.file("missing/t.trace"), "--out",
                       out.string()},
                      dir.file("log"));
  EXPECT_EQ(run.exit_code, 1) << run.output;
  EXPECT_TRUE(fs::exists(out / "frame_00007.png"));
  EXPECT_TRUE(fs::exists(out / "summary.tsv"));
  for (const char* resize : {"-1:160x90", "0:160x90", "99999999999999999999:160x90", "-18446744073709551615:160x90",
                             "10000001:160x90"}) {
    run = runFly({"--procedural", "65536", "--frames", "3", "--resize-at", resize, "--out", out.string()},
                 dir.file("log"));
    EXPECT_EQ(run.exit_code, 2) << resize << ": " << run.output;
  }
  CLIPSTREAM_REQUIRE_GL();
  run = runFly({"--procedural", "65536", "--frames", "010", "--size", "160x90", "--save-frames", "0", "--out",
                out.string()},
               dir.file("log"));
  ASSERT_EQ(run.exit_code, 0) << run.output;
  std::ifstream csv(out / "frames.csv");
  size_t lines = 0;
  for (std::string line; std::getline(csv, line);) ++lines;
  EXPECT_EQ(lines, 11u) << "header + ten frames (not octal 8)";
  std::vector<std::string> expected = others;
  for (const char* name : {"frames.csv", "frames.json", "summary.tsv"}) expected.push_back(name);
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(namesIn(out), expected);
}

// Second pass: a signal ignored at start (nohup, a background job) was
// caught anyway and ended the run.
TEST(FlyHardening, ASignalIgnoredAtStartStaysIgnored) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("fly_nohup");
  const fs::path out = dir.file("out");
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const int fd = ::open((dir.file("log")).c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    ::signal(SIGHUP, SIG_IGN);  // as nohup does
    ::alarm(120);
    const std::string out_arg = out.string();
    ::execl(CLIPSTREAM_FLY_EXE, CLIPSTREAM_FLY_EXE, "--procedural", "65536", "--frames", "40", "--size", "160x90",
            "--save-frames", "1", "--out", out_arg.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  for (int i = 0; i < 2400 && !fs::exists(out / "frame_00002.png"); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(25));
  ::kill(pid, SIGHUP);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "killed by signal " << WTERMSIG(status);
  EXPECT_EQ(WEXITSTATUS(status), 0);
  EXPECT_TRUE(fs::exists(out / "summary.tsv"));
}

// A run whose tile reads failed exited 0 with nothing on stderr (a store
// replaced on the server gave "tile_failures 97, tiles_loaded 0", rc 0). Now
// any failure is a warning, more than --max-failed-reads per cent an error
// (exit 1, the statistics written), and a run that loaded nothing fails
// whatever the threshold.
TEST(FlyHardening, FailedTileReadsAreReportedAndFailTheRunPastTheThreshold) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("fly_failures");
  const std::vector<std::string> base = {"--procedural", "65536", "--path", "pass", "--frames", "20",
                                         "--size", "160x96", "--out", dir.file("out")};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = base;
    args.insert(args.end(), extra.begin(), extra.end());
    return runFly(args, dir.file("log"));
  };
  const FlyRun clean = with({});
  EXPECT_EQ(clean.exit_code, 0) << clean.output;
  EXPECT_EQ(clean.output.find("tile reads failed"), std::string::npos) << clean.output;

  const FlyRun failing = with({"--fault-corrupt", "0.3"});
  EXPECT_EQ(failing.exit_code, 1) << failing.output;
  EXPECT_NE(failing.output.find("tile reads failed"), std::string::npos) << failing.output;
  EXPECT_NE(failing.output.find("--max-failed-reads"), std::string::npos) << failing.output;
  EXPECT_TRUE(fs::exists(dir.file("out") + "/summary.tsv")) << "the statistics say where it failed";

  const FlyRun allowed = with({"--fault-corrupt", "0.3", "--max-failed-reads", "100"});
  EXPECT_EQ(allowed.exit_code, 0) << allowed.output;
  EXPECT_NE(allowed.output.find("warning: "), std::string::npos) << allowed.output;
  EXPECT_NE(allowed.output.find("tile reads failed"), std::string::npos) << allowed.output;

  const FlyRun none = with({"--fault-corrupt", "1", "--max-failed-reads", "100"});
  EXPECT_EQ(none.exit_code, 1) << none.output;
  EXPECT_NE(none.output.find("none loaded"), std::string::npos) << none.output;

  const FlyRun absurd = with({"--max-failed-reads", "101"});
  EXPECT_EQ(absurd.exit_code, 2) << absurd.output;
}

// summary.tsv as key -> value (its two lines: the keys, the values).
std::map<std::string, std::string> readSummary(const std::string& path) {
  std::ifstream in(path);
  std::string keys, values;
  std::getline(in, keys);
  std::getline(in, values);
  std::map<std::string, std::string> summary;
  std::stringstream k(keys), v(values);
  for (std::string key, value; std::getline(k, key, '\t');) {
    value.clear();
    std::getline(v, value, '\t');
    summary[key] = value;
  }
  return summary;
}

// Without --reference, summary.tsv said psnr_mean_db 99.0000 (the cap of
// an identical frame) for a run that compared nothing; the accuracy fields
// are empty now, and numbers with --reference.
TEST(FlyHardening, AccuracyFieldsAreEmptyWithoutTheReference) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("fly_blank");
  const std::vector<std::string> accuracy = {"psnr_mean_db", "psnr_min_db", "frames_below_30db",
                                             "identical_frames", "time_to_sharp_mean",
                                             "time_to_sharp_max", "frames_with_holes"};
  for (const bool reference : {false, true}) {
    std::vector<std::string> args = {"--procedural", "65536", "--path", "pass", "--frames", "8",
                                     "--size", "160x96", "--out", dir.file("out")};
    if (reference) args.push_back("--reference");
    const FlyRun run = runFly(args, dir.file("log"));
    ASSERT_EQ(run.exit_code, 0) << run.output;
    const auto summary = readSummary(dir.file("out") + "/summary.tsv");
    for (const std::string& key : accuracy) {
      ASSERT_EQ(summary.count(key), 1u) << key;
      if (reference) {
        EXPECT_FALSE(summary.at(key).empty()) << key;
      } else {
        EXPECT_EQ(summary.at(key), "") << key;
      }
    }
    EXPECT_FALSE(summary.at("frame_ms_mean").empty());
  }
}

// The first hour: a run saved no frame unless asked and showed no progress
// on a 1,200-frame flight. By default five frames are saved (the first, one
// each quarter, the last), --save-frames 0 saves none, and a progress line
// is drawn when stderr is a terminal (CLIPSTREAM_PROGRESS=1 here).
TEST(FlyHardening, FramesAreSavedAndProgressShownByDefault) {
  CLIPSTREAM_REQUIRE_GL();
  test::TempDir dir("fly_defaults");
  const std::vector<std::string> base = {"--procedural", "65536", "--path", "pass", "--frames", "12",
                                         "--size", "160x96", "--out", dir.file("out")};
  auto pngs = [&] {
    std::vector<std::string> found;
    for (const std::string& name : namesIn(dir.file("out")))
      if (name.size() > 4 && name.compare(name.size() - 4, 4, ".png") == 0) found.push_back(name);
    return found;
  };
  ::setenv("CLIPSTREAM_PROGRESS", "1", 1);
  const FlyRun run = runFly(base, dir.file("log"));
  ::unsetenv("CLIPSTREAM_PROGRESS");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  EXPECT_EQ(pngs(), (std::vector<std::string>{"frame_00000.png", "frame_00003.png", "frame_00006.png",
                                              "frame_00009.png", "frame_00011.png"}));
  EXPECT_NE(run.output.find("flying 100% [##############################] 12/12"), std::string::npos)
      << run.output;
  expectOnlyWholeFiles(dir.file("out"), 160, 96);

  std::vector<std::string> none = base;
  none.insert(none.end(), {"--save-frames", "0"});
  const FlyRun quiet = runFly(none, dir.file("log"));
  ASSERT_EQ(quiet.exit_code, 0) << quiet.output;
  EXPECT_TRUE(pngs().empty());
  EXPECT_EQ(quiet.output.find("flying"), std::string::npos) << "no progress when stderr is a file";
}

}  // namespace
}  // namespace clipstream
