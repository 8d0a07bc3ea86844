// The path hint (Streamer::setPathHint): eviction by the hinted path's
// predicted returns, prefetch from the hinted camera, a hint that does not
// match the camera being ignored, and the trace replay of the hinted policy
// (the trace's time lines are parsed in test_trace.cpp).
#include "streamer_test_util.h"
#include "../../streamer/src/lookahead.h"  // private: the return prediction under test

#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>
#include <clipstream/testing/cameras.h>
#include <clipstream/testing/sources.h>
#include <clipstream/testing/temp_dir.h>

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <fstream>
#include <sstream>

namespace clipstream {
namespace {

using test::kPi;
using test::procedural;
using test::TempDir;
using test::waitIdle;

constexpr double kSide = 1 << 20;
constexpr double kFps = 30.0;

// Two laps of radius 3000 texels in 5 s each, looking at the centre.
Camera orbitAt(double t) {
  const double a = 2.0 * kPi * t / 5.0;
  Camera c;
  c.position = {kSide / 2 + 3000.0 * std::sin(a), 800.0, kSide / 2 + 3000.0 * std::cos(a)};
  c.heading_rad = a + kPi;
  c.pitch_rad = -std::atan2(800.0, 3000.0);
  return c;
}

StreamerConfig orbitConfig(uint64_t budget_tiles, const std::string& trace_path) {
  StreamerConfig cfg;
  cfg.io_threads = 1;
  cfg.prefetch = false;  // hits then come from eviction alone, as in the replay
  cfg.planner.clip_tiles = 8;
  cfg.planner.scope = PlanScope::kWindow;  // the replay re-plans whole windows
  cfg.ram_budget_bytes = budget_tiles * (128 * 128 * 4 + kCacheEntryOverheadBytes);
  cfg.trace_path = trace_path;
  return cfg;
}

// Flies `frames` frames of `path`, each loaded completely and handed off
// before the next, so hits depend only on the policy. Returns the stats.
StreamerStats flySettled(Streamer& s, const std::function<Camera(double)>& path, int frames,
                         const Viewport& vp) {
  for (int f = 0; f < frames; ++f) {
    s.update(path(f / kFps), vp, f / kFps);
    EXPECT_TRUE(waitIdle(s));
    (void)s.takeReady(100000);
  }
  return s.stats();
}

TEST(PathHint, OrbitKeepsTheTilesTheNextLapNeeds) {
  const Viewport vp{800, 600};
  auto source = procedural(uint64_t(kSide));
  // A lap wants about 1,700 distinct tiles; 600 hold a third of them and
  // still fit every frame's wanted set (at 300 the budget, not the policy,
  // decides: the streamer drops requests it has no room for).
  const uint64_t budget_tiles = 600;
  const TempDir dir("path_hint");
  const std::string plain_trace = dir.file("plain.trace"), hinted_trace = dir.file("hinted.trace");
  StreamerStats plain, hinted;
  {
    Streamer s(source, orbitConfig(budget_tiles, plain_trace));
    plain = flySettled(s, orbitAt, 300, vp);
  }
  PathHint hint;
  hint.camera_at = orbitAt;
  {
    Streamer s(source, orbitConfig(budget_tiles, hinted_trace));
    s.setPathHint(hint);
    hinted = flySettled(s, orbitAt, 300, vp);
  }
  EXPECT_EQ(hinted.path_hint_frames, 300u);
  EXPECT_EQ(hinted.path_hint_ignored_frames, 0u);
  EXPECT_EQ(plain.path_hint_frames, 0u);
  EXPECT_LE(hinted.ram_peak_bytes, hinted.ram_budget_bytes);
  // Both flights want the same tiles at the same frames.
  const uint64_t accesses = plain.total.ram_hits + plain.total.ram_misses;
  EXPECT_EQ(hinted.total.ram_hits + hinted.total.ram_misses, accesses);

  std::vector<TraceEvent> plain_events, hinted_events;
  ASSERT_TRUE(readTrace(plain_trace, &plain_events).ok());
  ASSERT_TRUE(readTrace(hinted_trace, &hinted_events).ok());
  ReplayHint replay_hint;
  replay_hint.path = hint;
  replay_hint.geometry = source->geometry();
  replay_hint.planner = orbitConfig(budget_tiles, "").planner;
  const ReplayResult r = replayTrace(hinted_events, budget_tiles, &replay_hint);
  const ReplayResult r_plain = replayTrace(plain_events, budget_tiles);
  std::printf(
      "orbit, %llu tiles of RAM: %llu accesses, %llu distinct, OPT %llu, "
      "streamer hits plain %llu / hinted %llu, replay plain %llu / hinted %llu; skips %llu %llu\n",
      (unsigned long long)budget_tiles, (unsigned long long)r.accesses, (unsigned long long)r.distinct_tiles,
      (unsigned long long)r.hits_opt, (unsigned long long)plain.total.ram_hits,
      (unsigned long long)hinted.total.ram_hits, (unsigned long long)r_plain.hits_gpu_first,
      (unsigned long long)r.hits_hinted, (unsigned long long)plain.total.budget_skips,
      (unsigned long long)hinted.total.budget_skips);
  EXPECT_EQ(r.accesses, accesses);
  // The replay reproduces what the streamer did with and without the hint:
  // within 4 % of OPT (the streamer breaks score ties by frame, the replay
  // by trace position) and a hit for every request the streamer dropped
  // for want of room (budget_skips: it makes room per plan change, the
  // replay per access, so the replay rarely has to drop one).
  EXPECT_NEAR(double(r.hits_hinted), double(hinted.total.ram_hits),
              0.04 * double(r.hits_opt) + double(hinted.total.budget_skips));
  EXPECT_NEAR(double(r_plain.hits_gpu_first), double(plain.total.ram_hits),
              0.04 * double(r.hits_opt) + double(plain.total.budget_skips));
  // The hinted policy is close to OPT; without the hint it is not.
  EXPECT_GE(double(hinted.total.ram_hits), 0.95 * double(r.hits_opt));
  EXPECT_LT(double(plain.total.ram_hits), 0.9 * double(r.hits_opt));
}

// A hint that is somewhere else than the camera is not used: the flight
// behaves exactly as without one, and the trace says so.
TEST(PathHint, AHintThatDisagreesWithTheCameraIsIgnored) {
  const Viewport vp{800, 600};
  auto source = procedural(uint64_t(kSide));
  const TempDir dir("path_hint");
  const std::string plain_trace = dir.file("plain.trace"), wrong_trace = dir.file("wrong.trace");
  StreamerStats plain, wrong;
  {
    Streamer s(source, orbitConfig(600, plain_trace));
    plain = flySettled(s, orbitAt, 150, vp);
  }
  PathHint hint;
  hint.camera_at = [](double t) {
    Camera c = orbitAt(t);
    c.position.x += 20000.0;  // the same orbit, far to the east
    return c;
  };
  {
    Streamer s(source, orbitConfig(600, wrong_trace));
    s.setPathHint(hint);
    wrong = flySettled(s, orbitAt, 150, vp);
  }
  EXPECT_EQ(wrong.path_hint_frames, 0u);
  EXPECT_EQ(wrong.path_hint_ignored_frames, 150u);
  EXPECT_EQ(wrong.total.ram_hits, plain.total.ram_hits);
  EXPECT_EQ(wrong.total.ram_misses, plain.total.ram_misses);
  std::vector<TraceEvent> events;
  ASSERT_TRUE(readTrace(wrong_trace, &events).ok());
  size_t time_lines = 0;
  for (const TraceEvent& e : events) {
    if (e.window != 't') continue;
    ++time_lines;
    EXPECT_EQ(e.kind, 0u) << "frame " << e.frame << " claims the hint was used";
  }
  EXPECT_GT(time_lines, 100u);
  // The streamer's JSON carries the counters.
  EXPECT_NE(wrong.toJson().find("\"path_hint_ignored_frames\":150"), std::string::npos);
}

// A scripted jump: the hinted streamer prefetches the destination before
// the camera gets there; without the hint nothing of it is in RAM.
TEST(PathHint, PrefetchLoadsTheDestinationOfAScriptedJumpBeforeIt) {
  const Viewport vp{800, 600};
  auto jump = [](double t) {
    return test::lookingDown(t < 1.0 ? 100000.0 : 700000.0, t < 1.0 ? 100000.0 : 600000.0, 300.0);
  };
  auto hitsAtTheJump = [&](bool with_hint) {
    StreamerConfig cfg = orbitConfig(4000, "");
    cfg.prefetch = true;
    Streamer s(procedural(uint64_t(kSide)), cfg);
    if (with_hint) {
      PathHint hint;
      hint.camera_at = jump;
      s.setPathHint(hint);
    }
    for (int f = 0; f < 30; ++f) {  // 0 .. 0.97 s: at the start
      s.update(jump(f / kFps), vp, f / kFps);
      EXPECT_TRUE(waitIdle(s));
      (void)s.takeReady(100000);
    }
    const StreamerStats before = s.stats();
    s.update(jump(1.0), vp, 1.0);  // the jump
    const StreamerStats after = s.stats();
    EXPECT_GT(after.total.ram_hits + after.total.ram_misses, before.total.ram_hits + before.total.ram_misses);
    return std::pair{after.total.ram_hits - before.total.ram_hits,
                     after.total.ram_misses - before.total.ram_misses};
  };
  const auto [hinted_hits, hinted_misses] = hitsAtTheJump(true);
  const auto [plain_hits, plain_misses] = hitsAtTheJump(false);
  EXPECT_EQ(plain_hits, 0u);
  EXPECT_GT(plain_misses, 0u);
  // Every tile the destination wants was prefetched (the pyramid is shared
  // and stays wanted, so it is not among them).
  EXPECT_EQ(hinted_misses, 0u);
  EXPECT_EQ(hinted_hits, plain_misses);
}

// A hint may return anything and carry any settings: a non-finite camera
// is a disagreement, absurd steps and horizons fall back to the defaults,
// and none of it hangs or crashes.
TEST(PathHint, AbsurdHintsAreSurvived) {
  const Viewport vp{800, 600};
  auto source = procedural(uint64_t(kSide));
  auto fly = [&](PathHint hint) {
    StreamerConfig cfg = orbitConfig(600, "");
    cfg.prefetch = true;
    Streamer s(source, cfg);
    s.setPathHint(std::move(hint));
    for (int f = 0; f < 20; ++f) {
      s.update(orbitAt(f / kFps), vp, f / kFps);
      (void)s.takeReady(64);
    }
    return s.stats();
  };
  PathHint nan_camera;
  nan_camera.camera_at = [](double) {
    Camera c;
    c.position.x = std::nan("");
    return c;
  };
  StreamerStats st = fly(nan_camera);
  EXPECT_EQ(st.path_hint_frames, 0u);
  EXPECT_EQ(st.path_hint_ignored_frames, 20u);
  // Right now, NaN from a second ahead: used, with a shorter lookahead.
  PathHint nan_later;
  nan_later.camera_at = [](double t) {
    Camera c = orbitAt(t);
    if (t > 1.0) c.heading_rad = std::nan("");
    return c;
  };
  st = fly(nan_later);
  EXPECT_EQ(st.path_hint_frames, 20u);
  for (double step : {0.0, -1.0, std::nan(""), 1e-9, std::numeric_limits<double>::infinity()}) {
    for (double horizon : {-5.0, std::nan(""), std::numeric_limits<double>::infinity(), 1e300}) {
      PathHint odd;
      odd.camera_at = orbitAt;
      odd.step_s = step;
      odd.horizon_s = horizon;
      st = fly(odd);
      EXPECT_EQ(st.path_hint_frames, 20u) << "step " << step << ", horizon " << horizon;
    }
  }
  // What the lookahead makes of them: the default step for a bad one, the
  // default horizon for a non-finite one, nothing for a negative one, and
  // never more than 1024 samples.
  const PyramidGeometry& g = source->geometry();
  auto samples = [&](double step, double horizon) {
    PathHint h;
    h.camera_at = orbitAt;
    h.step_s = step;
    h.horizon_s = horizon;
    PathLookahead ahead;
    // A call plans at most 16 new samples; frames at the same time fill
    // the rest of the horizon.
    ahead.advance(g, vp, PlannerConfig{}, h, 2.0);
    EXPECT_LE(ahead.snapshot()->times_s.size(), 16u);
    for (int call = 0; call < 70; ++call) ahead.advance(g, vp, PlannerConfig{}, h, 2.0);
    return *ahead.snapshot();
  };
  LookaheadSnapshot snap = samples(0.0, std::numeric_limits<double>::infinity());
  ASSERT_EQ(snap.times_s.size(), 75u);  // 5 s at 1/15 s
  EXPECT_NEAR(snap.times_s[1] - snap.times_s[0], 1.0 / 15.0, 1e-12);
  EXPECT_NEAR(snap.times_s.back(), 7.0, 1e-9);
  EXPECT_EQ(samples(0.5, -5.0).times_s.size(), 0u);
  EXPECT_EQ(samples(std::nan(""), 1e300).times_s.size(), 1024u);
  snap = samples(0.5, 2.0);  // 2.5, 3.0, 3.5, 4.0
  ASSERT_EQ(snap.times_s.size(), 4u);
  EXPECT_DOUBLE_EQ(snap.times_s.front(), 2.5);
  EXPECT_DOUBLE_EQ(snap.now_s, 2.0);
}

// A hint can be set, replaced and cleared between frames; only frames with
// a hint count, and the cache keeps its budget throughout.
TEST(PathHint, SetReplacedAndClearedMidFlight) {
  const Viewport vp{800, 600};
  StreamerConfig cfg = orbitConfig(300, "");
  cfg.prefetch = true;
  Streamer s(procedural(uint64_t(kSide)), cfg);
  int f = 0;
  auto fly = [&](int frames) {
    for (int i = 0; i < frames; ++i, ++f) {
      s.update(orbitAt(f / kFps), vp, f / kFps);
      ASSERT_TRUE(waitIdle(s));
      (void)s.takeReady(100000);
    }
  };
  fly(10);
  EXPECT_EQ(s.stats().path_hint_frames + s.stats().path_hint_ignored_frames, 0u);
  PathHint hint;
  hint.camera_at = orbitAt;
  s.setPathHint(hint);
  fly(10);
  EXPECT_EQ(s.stats().path_hint_frames, 10u);
  hint.camera_at = [](double t) { return orbitAt(t + 2.5); };  // half a lap off
  s.setPathHint(hint);
  fly(10);
  EXPECT_EQ(s.stats().path_hint_frames, 10u);
  EXPECT_EQ(s.stats().path_hint_ignored_frames, 10u);
  s.setPathHint({});
  fly(10);
  const StreamerStats st = s.stats();
  EXPECT_EQ(st.path_hint_frames, 10u);
  EXPECT_EQ(st.path_hint_ignored_frames, 10u);
  EXPECT_LE(st.ram_peak_bytes, st.ram_budget_bytes);
  EXPECT_TRUE(s.settled());
}

// The prediction behind the hinted eviction, on hand-made windows.
TEST(PathHint, PredictedReturnIsTheFirstEntryAfterLeaving) {
  auto windows = [](TileRect level0) {
    PlanWindows w;
    w.rects = {level0, TileRect{0, 0, 1, 1}};
    w.kinds = {PlanWindows::kNeeded, PlanWindows::kPyramid};
    w.finish();
    return w;
  };
  const PlanWindows current = windows({0, 0, 2, 1});  // tiles (0,0) and (1,0)
  LookaheadSnapshot ahead;
  ahead.now_s = 10.0;
  ahead.times_s = {10.5, 11.0, 11.5, 12.0};
  ahead.index({windows({1, 0, 3, 1}), windows({2, 0, 4, 1}), windows({0, 0, 2, 1}), windows({5, 0, 6, 1})});
  ASSERT_EQ(ahead.runs.size(), 2u);
  EXPECT_EQ(ahead.runs[0].size(), 4u);  // level 0 moves at every sample
  EXPECT_EQ(ahead.runs[1].size(), 1u);  // level 1 is the pyramid: never a needed window
  const TileKey inside_left{0, 0, 0}, inside_right{0, 1, 0}, ahead_tile{0, 3, 0}, never{0, 9, 0};
  // (0,0) leaves at once and is back at 11.5; (1,0) stays until 11.0 and is
  // back at 11.5; (3,0) is entered at 11.0; (9,0) never within the horizon.
  EXPECT_DOUBLE_EQ(predictedReturnS(inside_left, current, true, ahead), 1.5);
  EXPECT_DOUBLE_EQ(predictedReturnS(inside_right, current, true, ahead), 1.5);
  EXPECT_DOUBLE_EQ(predictedReturnS(ahead_tile, current, true, ahead), 1.0);
  EXPECT_EQ(predictedReturnS(never, current, true, ahead), kNoReturn);
  // Scores: the pyramid tile first, then no return, then the latest return.
  const PlanWindows none;
  const double pyramid = evictionScoreAhead({1, 0, 0}, current, none, EvictionMode::kGpuFirst, true, &ahead);
  const double no_return = evictionScoreAhead(never, current, none, EvictionMode::kGpuFirst, true, &ahead);
  const double late = evictionScoreAhead(inside_left, current, none, EvictionMode::kGpuFirst, true, &ahead);
  const double soon = evictionScoreAhead(ahead_tile, current, none, EvictionMode::kGpuFirst, true, &ahead);
  EXPECT_TRUE(evictsBefore(pyramid, 0, no_return, 0));
  EXPECT_TRUE(evictsBefore(no_return, 0, late, 0));
  EXPECT_TRUE(evictsBefore(late, 0, soon, 0));
  // kProtectGpu and an empty lookahead keep the plan-distance score.
  EXPECT_EQ(evictionScoreAhead(never, current, none, EvictionMode::kProtectGpu, true, &ahead),
            evictionScore(never, current, none, EvictionMode::kProtectGpu, true));
  EXPECT_EQ(evictionScoreAhead(never, current, none, EvictionMode::kGpuFirst, true, nullptr),
            evictionScore(never, current, none, EvictionMode::kGpuFirst, true));
  // A tile inside the window that is not on the GPU (back in its window
  // without being wanted since) is read the next time it is wanted.
  EXPECT_DOUBLE_EQ(predictedReturnS(inside_right, current, false, ahead), 0.5);
}

// With the sampled scope a return is the next time the plan wants the tile,
// not when its window comes back over it.
TEST(PathHint, PredictedReturnFollowsTheSampledTiles) {
  PlanWindows w;
  w.rects = {TileRect{0, 0, 4, 1}};
  w.kinds = {PlanWindows::kNeeded};
  w.finish();
  auto mask = [](std::vector<uint8_t> bits) { return std::make_shared<const std::vector<uint8_t>>(bits); };
  PlanWindows away;
  away.rects = {TileRect{8, 0, 12, 1}};
  away.kinds = {PlanWindows::kNeeded};
  away.finish();
  LookaheadSnapshot ahead;
  ahead.now_s = 0.0;
  ahead.times_s = {1.0, 2.0, 3.0, 4.0};
  // Window over tiles 0-3 sampling only 0 and 1, the same, then away, then
  // back sampling 2 and 3.
  ahead.index({w, w, away, w}, {{mask({1, 1, 0, 0})}, {mask({1, 1, 0, 0})}, {nullptr}, {mask({0, 0, 1, 1})}});
  ASSERT_EQ(ahead.runs.size(), 1u);
  EXPECT_EQ(ahead.runs[0].size(), 3u);  // equal masks share a run
  const TileKey t0{0, 0, 0}, t2{0, 2, 0};
  // Not on the GPU: the first time wanted.
  EXPECT_DOUBLE_EQ(predictedReturnS(t0, w, false, ahead), 1.0);
  EXPECT_DOUBLE_EQ(predictedReturnS(t2, w, false, ahead), 4.0);
  // On the GPU inside the window: only after leaving; tile 0 is never
  // wanted again after that, tile 2 is at 4 s.
  EXPECT_EQ(predictedReturnS(t0, w, true, ahead), kNoReturn);
  EXPECT_DOUBLE_EQ(predictedReturnS(t2, w, true, ahead), 4.0);
}

}  // namespace
}  // namespace clipstream
