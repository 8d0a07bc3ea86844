// The request trace's writer on its own (trace_recorder.h): what it writes
// reads back as the same events, and nothing appears unless finished.
#include "../../streamer/src/trace_recorder.h"  // private: the writer under test

#include <clipstream/streamer/trace.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace clipstream {
namespace {

PlanWindows oneLevel(uint8_t kind) {
  PlanWindows w;
  w.rects = {TileRect{1, 2, 5, 6}};
  w.kinds = {kind};
  w.finish();
  return w;
}

TEST(TraceRecorder, WritesPlansAndTilesThatReadBackAsTheSameEvents) {
  test::TempDir dir("trace-recorder");
  const std::string path = dir.file("t.trace");
  TraceRecorder rec;
  rec.open(path);
  ASSERT_TRUE(rec.active()) << rec.status().toString();
  rec.beginPlan(7, 0.25, true, Viewport{640, 360}, oneLevel(PlanWindows::kNeeded), PlanWindows{});
  rec.tile({0, 3, 4}, false);
  rec.tile({0, 1, 2}, true);
  rec.endPlan();
  EXPECT_TRUE(dir.entries().size() <= 1u);  // at most the temporary so far
  rec.finish();
  EXPECT_FALSE(rec.active());
  ASSERT_TRUE(rec.status().ok());

  std::vector<TraceEvent> events;
  ASSERT_TRUE(readTrace(path, &events).ok());
  ASSERT_EQ(events.size(), 4u);  // time, window, enter, leave (no predicted windows)
  EXPECT_EQ(events[0].window, kTraceTimeTag);
  EXPECT_EQ(events[0].frame, 7u);
  EXPECT_EQ(events[0].time_s, 0.25);
  EXPECT_EQ(events[0].kind, 1);  // the hint was used
  EXPECT_EQ(events[0].viewport.width_px, 640u);
  EXPECT_EQ(events[1].window, kTraceWindowTag);
  EXPECT_EQ(events[1].rect, (TileRect{1, 2, 5, 6}));
  EXPECT_TRUE(events[2].isAccess());
  EXPECT_EQ(events[2].key, (TileKey{0, 3, 4}));
  EXPECT_EQ(events[2].frame, 7u);
  EXPECT_TRUE(events[3].leave);
  EXPECT_EQ(dir.entries(), std::vector<std::string>{"t.trace"});
}

TEST(TraceRecorder, ADiscardedTraceLeavesNothing) {
  test::TempDir dir("trace-recorder");
  TraceRecorder rec;
  rec.open(dir.file("t.trace"));
  ASSERT_TRUE(rec.active());
  rec.beginPlan(1, 0.0, false, Viewport{64, 64}, oneLevel(PlanWindows::kPyramid), PlanWindows{});
  rec.discard();
  EXPECT_FALSE(rec.active());
  rec.finish();  // after a discard: nothing to publish
  EXPECT_TRUE(dir.entries().empty());
}

TEST(TraceRecorder, AnUnwritablePathIsReportedAndNothingIsRecorded) {
  test::TempDir dir("trace-recorder");
  TraceRecorder rec;
  rec.open(dir.file("no/such/folder/t.trace"));
  EXPECT_FALSE(rec.active());
  EXPECT_FALSE(rec.status().ok());
  EXPECT_NE(rec.status().toString().find("no/such/folder"), std::string::npos) << rec.status().toString();
  rec.tile({0, 0, 0}, false);  // ignored
  rec.finish();
  EXPECT_TRUE(dir.entries().empty());
}

}  // namespace
}  // namespace clipstream
