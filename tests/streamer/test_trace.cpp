// The request trace (trace.h): what the streamer records, the reader's
// refusals of damaged or foreign traces, the replay's hit counts, and the
// clipstream-trace program's command line. Eviction policies compared on
// traces are in test_eviction.cpp.
#include "streamer_test_util.h"

#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace clipstream {
namespace {

using test::lookingDown;
using test::procedural;
using test::waitIdle;

TEST(Streamer, TraceRecordsEveryAccessAndReplays) {
  const test::TempDir dir("trace");
  const std::string path = dir.file("trace.txt");
  StreamerConfig cfg;
  cfg.io_threads = 2;
  cfg.prefetch = false;
  cfg.planner.clip_tiles = 8;
  cfg.trace_path = path;
  uint64_t accesses = 0, gpu_reentries = 0;
  {
    Streamer s(procedural(1 << 16), cfg);
    const Viewport vp{800, 600};
    // Forward, then back over the same ground: tiles the frames stop
    // sampling while still in their window come back on the way back. Each
    // frame is loaded and handed over before the next, as the replay
    // assumes.
    for (int i = 0; i < 40; ++i) {
      const int step = i < 20 ? i : 39 - i;
      s.update(lookingDown(20000.0 + 150.0 * step, 20000.0, 40.0), vp, i / 30.0);
      ASSERT_TRUE(waitIdle(s));
      (void)s.takeReady(100000);
    }
    const StreamerStats st = s.stats();
    accesses = st.total.ram_hits + st.total.ram_misses;
    gpu_reentries = st.total.gpu_reentries;
  }
  std::vector<TraceEvent> events;
  ASSERT_TRUE(readTrace(path, &events).ok());
  uint64_t enters = 0, leaves = 0, windows = 0;
  for (const TraceEvent& e : events) {
    if (e.window) windows++;
    else (e.leave ? leaves : enters)++;
  }
  EXPECT_GT(windows, 0u);
  EXPECT_EQ(enters, accesses + gpu_reentries);
  EXPECT_GT(leaves, 0u);
  EXPECT_GT(gpu_reentries, 0u);
  const ReplayResult r = replayTrace(events, 300);
  // The replay tells the entries the GPU serves from the trace alone, as
  // the streamer did from its GPU set.
  EXPECT_EQ(r.accesses, accesses);
  EXPECT_EQ(r.gpu_reentries, gpu_reentries);
  EXPECT_GE(r.hits_opt, r.hits_lru);
  EXPECT_GE(r.hits_opt, r.hits_plan);
  EXPECT_GE(r.hits_opt, r.hits_gpu_first);
}

TEST(Trace, ReplayMatchesHandComputedHitCounts) {
  // Accesses A B C A B with room for two tiles.
  const TileKey a{0, 0, 0}, b{0, 1, 0}, c{0, 2, 0};
  std::vector<TraceEvent> ev = {{1, a, false}, {1, b, false}, {2, c, false},
                                {3, a, false}, {3, b, false}};
  ReplayResult r = replayTrace(ev, 2);
  EXPECT_EQ(r.accesses, 5u);
  EXPECT_EQ(r.distinct_tiles, 3u);
  EXPECT_EQ(r.hits_lru, 0u);  // C evicts A, A evicts B, B evicts C
  EXPECT_EQ(r.hits_opt, 2u);  // C bypasses: A and B hit
  // No window lines: the plan-aware policy falls back to least recently
  // wanted, where leaving counts as wanted. A leaves (refreshed) before C
  // arrives, so B is the victim and A hits when it re-enters; LRU evicts A.
  std::vector<TraceEvent> ev2 = {{1, a, false}, {2, b, false}, {3, a, true},
                                 {4, c, false}, {5, a, false}};
  r = replayTrace(ev2, 2);
  EXPECT_EQ(r.hits_plan, 1u);
  EXPECT_EQ(r.hits_gpu_first, 1u);
  EXPECT_EQ(r.hits_lru, 0u);
  EXPECT_EQ(r.hits_opt, 1u);
  // A tile that leaves the wanted set but not its needed window is still on
  // the GPU when it comes back: not an access. Once a plan change has taken
  // its window away (even one with no tile line) it is an access again.
  auto window = [](uint64_t frame, int64_t x0, int64_t x1) {
    TraceEvent w;
    w.window = kTraceWindowTag;
    w.frame = frame;
    w.rect = {x0, 0, x1, 1};
    w.kind = 1;  // needed
    return w;
  };
  std::vector<TraceEvent> ev3 = {window(1, 0, 2), {1, a, false}, {1, b, false},
                                 window(2, 0, 2), {2, a, true},                 // a leaves, stays on the GPU
                                 window(3, 0, 2), {3, a, false},                // back: the GPU serves it
                                 window(4, 1, 3), {4, a, true}, {4, c, false},  // a leaves its window
                                 window(5, 0, 3), {5, a, false},                // back: read again
                                 window(6, 0, 3), {6, b, true},
                                 window(7, 2, 3),                               // b's window moves away
                                 window(8, 0, 3), {8, b, false}};               // b is read again
  r = replayTrace(ev3, 3);
  EXPECT_EQ(r.gpu_reentries, 1u);
  EXPECT_EQ(r.accesses, 5u);  // a, b, c, a, b
  EXPECT_EQ(r.hits_opt, 2u);  // room for all three: the second a and b hit
  EXPECT_EQ(r.hits_lru, 2u);
  const test::TempDir dir("trace");
  const std::string path = dir.file("bad_trace.txt");
  {
    std::ofstream f(path);
    f << kTraceHeader << "\n1 0 2 3\nnot a line\n";
  }
  std::vector<TraceEvent> parsed;
  const Status st = readTrace(path, &parsed);
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(st.message.find(":3:"), std::string::npos) << st.message;
  EXPECT_EQ(readTrace("/nonexistent/trace", &parsed).code, ErrorCode::kNotFound);
}

// The time lines ('t') that let a replay follow a path hint.
TEST(PathHint, TraceTimeLinesParseAndBadOnesAreNamed) {
  const test::TempDir dir("trace");
  const std::string path = dir.file("times.trace");
  auto readText = [&](const std::string& text, std::vector<TraceEvent>* events) {
    std::ofstream(path) << kTraceHeader << '\n' << text;
    return readTrace(path, events);
  };
  std::vector<TraceEvent> events;
  ASSERT_TRUE(readText("t 3 0.10000000000000001 1 800 600\nw 3 0 0 0 2 2 1\n3 0 1 1\n", &events).ok());
  ASSERT_EQ(events.size(), 3u);
  EXPECT_EQ(events[0].window, 't');
  EXPECT_EQ(events[0].frame, 3u);
  EXPECT_DOUBLE_EQ(events[0].time_s, 0.1);
  EXPECT_EQ(events[0].kind, 1u);
  EXPECT_EQ(events[0].viewport.width_px, 800u);
  EXPECT_EQ(events[0].viewport.height_px, 600u);
  EXPECT_FALSE(events[0].isAccess());
  for (const char* bad : {"t 3 0.1 2 800 600\n", "t 3 nan 1 800 600\n", "t 3 0.1 1\n", "t 3\n",
                          "t x 0.1 0 800 600\n", "t 3 0.1 0 -1 600\n"}) {
    const Status st = readText(bad, &events);
    EXPECT_EQ(st.code, ErrorCode::kInvalidArgument) << bad;
    EXPECT_NE(st.message.find(":2: expected 't frame seconds 0|1 width height'"), std::string::npos)
        << st.message;
  }
}

// clipstream-trace accepted an empty or truncated trace and echoed raw bytes
// (terminal escapes included) in its error.
TEST(Trace, EmptyTruncatedForeignOrNonRegularTracesAreRefused) {
  const test::TempDir dir("trace");
  const std::string path = dir.file("hostile.trace");
  auto readText = [&](const std::string& text) {
    std::ofstream(path, std::ios::binary) << text;
    std::vector<TraceEvent> events;
    return readTrace(path, &events);
  };
  const std::string header = std::string(kTraceHeader) + "\n";
  EXPECT_TRUE(readText(header).ok()) << "a header alone is a trace of no frames";
  EXPECT_TRUE(readText(header + "1 0 2 3\n").ok());
  Status st = readText("");
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument);
  EXPECT_NE(st.message.find("empty"), std::string::npos) << st.message;
  st = readText(header + "1 0 2 3\n2 0 2");
  EXPECT_EQ(st.code, ErrorCode::kTruncated) << st.toString();
  EXPECT_NE(st.message.find(":3:"), std::string::npos) << st.message;
  st = readText("1 0 2 3\n");
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument) << "no header";
  st = readText(std::string(1 << 20, '\0'));  // no newline anywhere: refused from its first bytes
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument) << st.toString();
  st = readText("# clipstream trace v9: from the future\n");
  EXPECT_EQ(st.code, ErrorCode::kUnsupported) << st.toString();
  st = readText(header + "1 0 \x1b[31mred\x07\n");
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument);
  for (char c : st.message) EXPECT_GE(static_cast<unsigned char>(c), 0x20) << st.message;
  EXPECT_NE(st.message.find("?[31mred?"), std::string::npos) << st.message;
  const std::string fifo = path + ".fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  std::vector<TraceEvent> events;
  EXPECT_EQ(readTrace(fifo, &events).code, ErrorCode::kIo);
  // Past the stated size (a sparse file: no disk used), refused before a line is read.
  std::ofstream(path, std::ios::binary) << header;
  std::filesystem::resize_file(path, kMaxTraceFileBytes + 1);
  st = readTrace(path, &events);
  EXPECT_EQ(st.code, ErrorCode::kInvalidArgument) << st.toString();
  EXPECT_NE(st.message.find("larger than any trace read here (2048 MiB at most)"), std::string::npos) << st.message;
}

// clipstream-trace: NaN and other absurd numbers, and a bad trace, exit
// with the documented codes and one plain line.
TEST(Trace, ClipstreamTraceRejectsAbsurdArgumentsAndBadTraces) {
  const test::TempDir dir("trace");
  const std::string path = dir.file("cli.trace");
  std::ofstream(path) << kTraceHeader << "\n1 0 2 3\n2 0 2 3\n1 0 2 3\n";
  auto run = [&](const std::string& args, std::string* output) {
    const std::string cmd = std::string("{ '") + CLIPSTREAM_TRACE_EXE + "' " + args + "; } 2>&1";
    FILE* pipe = ::popen(cmd.c_str(), "r");
    char buffer[4096];
    size_t got;
    output->clear();
    while ((got = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) output->append(buffer, got);
    const int status = ::pclose(pipe);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  };
  std::string out;
  EXPECT_EQ(run("--budget-mb 1 '" + path + "'", &out), 0) << out;
  EXPECT_NE(out.find("opt\t"), std::string::npos) << out;
  for (const char* bad : {"--budget-mb nan", "--budget-mb 0", "--budget-mb -5", "--budget-mb 1e999",
                          "--budget-mb 1 --tile-bytes 0", "--budget-mb 1 --no-such-flag"}) {
    EXPECT_EQ(run(std::string(bad) + " '" + path + "'", &out), 2) << bad << ": " << out;
    EXPECT_LT(out.size(), 300u) << out;
  }
  EXPECT_EQ(run("--budget-mb 1 '" + path + "' >/dev/full", &out), 1) << out;
  EXPECT_NE(out.find("cannot write standard output"), std::string::npos) << out;
  std::ofstream(path, std::ios::trunc);  // empty
  EXPECT_EQ(run("--budget-mb 1 '" + path + "'", &out), 1) << out;
  EXPECT_NE(out.find("empty"), std::string::npos) << out;
}

// The trace is written under OutputFile's rule: nothing under its name until
// shutdown(), then the whole trace; an unwritable path is reported, not
// printed and ignored.
TEST(Trace, TheTraceAppearsWholeAtShutdownAndFailuresAreReported) {
  const test::TempDir dir("trace");
  const std::string path = dir.file("streamer.trace");
  {
    StreamerConfig cfg;
    cfg.io_threads = 1;
    cfg.trace_path = path;
    Streamer streamer(procedural(4096), cfg);
    const Viewport vp{320, 240};
    for (int f = 0; f < 5; ++f) streamer.update(lookingDown(2048, 2048, 300.0 + f), vp, f / 60.0);
    EXPECT_FALSE(std::filesystem::exists(path)) << "visible before shutdown";
    streamer.shutdown();
    EXPECT_TRUE(streamer.traceStatus().ok()) << streamer.traceStatus().toString();
  }
  std::vector<TraceEvent> events;
  ASSERT_TRUE(readTrace(path, &events).ok());
  EXPECT_GT(events.size(), 5u);
  StreamerConfig cfg;
  cfg.trace_path = "/nonexistent-dir/streamer.trace";
  Streamer streamer(procedural(4096), cfg);
  streamer.shutdown();
  EXPECT_EQ(streamer.traceStatus().code, ErrorCode::kNotFound) << streamer.traceStatus().toString();
}

}  // namespace
}  // namespace clipstream
