// One trace line parsed (trace_line.h): every line appendTraceLine() writes
// reads back as its event, and a line that does not parse names the format
// it expected. Whole files (header, truncation, messages) are in
// test_trace.cpp.
#include "../../streamer/src/trace_line.h"  // private: the line parser under test

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace clipstream {
namespace {

// The line appendTraceLine() writes for `e`, without its newline.
std::string lineOf(const TraceEvent& e) {
  std::string line;
  appendTraceLine(e, &line);
  EXPECT_FALSE(line.empty());
  EXPECT_EQ(line.back(), '\n');
  line.pop_back();
  return line;
}

void expectSame(const TraceEvent& a, const TraceEvent& b) {
  EXPECT_EQ(a.frame, b.frame);
  EXPECT_EQ(a.key, b.key);
  EXPECT_EQ(a.leave, b.leave);
  EXPECT_EQ(a.window, b.window);
  EXPECT_EQ(a.rect, b.rect);
  EXPECT_EQ(a.kind, b.kind);
  EXPECT_EQ(a.time_s, b.time_s);
  EXPECT_EQ(a.viewport.width_px, b.viewport.width_px);
  EXPECT_EQ(a.viewport.height_px, b.viewport.height_px);
}

TEST(TraceLine, EveryKindOfLineReadsBackAsItsEvent) {
  std::vector<TraceEvent> events;
  events.push_back({7, {3, 4294967295u, 12}, false});  // an entry
  events.push_back({1ull << 40, {63, 0, 5}, true});    // a leave
  for (char tag : {kTraceWindowTag, kTracePredictedTag}) {
    TraceEvent w;
    w.frame = 9;
    w.window = tag;
    w.key.level = 2;
    w.rect = {-3, 4, 17, 40};
    w.kind = 2;
    events.push_back(w);
  }
  TraceEvent t;
  t.frame = 11;
  t.window = kTraceTimeTag;
  t.time_s = 0.1 + 1e-9;  // kept exactly (17 significant digits)
  t.kind = 1;
  t.viewport = {1920, 1080};
  events.push_back(t);
  for (const TraceEvent& e : events) {
    const std::string line = lineOf(e);
    TraceEvent parsed;
    EXPECT_EQ(parseTraceLine(line, &parsed), nullptr) << line;
    expectSame(parsed, e);
  }
}

TEST(TraceLine, ABadLineNamesTheFormatItExpectedAndLeavesTheEvent) {
  const std::string tile = "'frame level x y'";
  const std::string window = "'w|p frame level x0 y0 x1 y1 kind'";
  const std::string time = "'t frame seconds 0|1 width height'";
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"1 64 0 0", tile},                 // level above 63
      {"1 0 4294967296 0", tile},         // x past 32 bits
      {"- 1 0 0", tile},                  // a leave without its y
      {"1 0 0 -1", tile},
      {"x 1 0 0 0", tile},                // an unknown tag reads as a tile line
      {"w 1 0 0 0 1 1 3", window},        // kind above 2
      {"p 1 64 0 0 1 1 1", window},       // level above 63
      {"w 1 0 0 0 1 1", window},          // no kind
      {"t 1 nan 0 64 64", time},          // a time that is not finite
      {"t 1 0.5 2 64 64", time},          // hint flag above 1
      {"t 1 0.5 1 4294967296 64", time},  // width past 32 bits
      {"t 1 0.5 1 64", time},             // no height
  };
  for (const auto& [line, expected] : bad) {
    TraceEvent e;
    e.frame = 99;
    const char* got = parseTraceLine(line, &e);
    ASSERT_NE(got, nullptr) << line;
    EXPECT_EQ(std::string(got), expected) << line;
    EXPECT_EQ(e.frame, 99u) << line;  // untouched
  }
}

}  // namespace
}  // namespace clipstream
