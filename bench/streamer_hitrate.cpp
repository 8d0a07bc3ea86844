// RAM hit rate of the streamer's plan-aware eviction against LRU and
// Belady's OPT. Drives a Streamer over a procedural 2^22-texel texture along
// scripted camera paths (pass, dive, orbit, teleport, zoom), records each
// request trace, then replays it at several budgets. Each path is flown
// twice: as an interactive camera (the streamer knows only the poses so
// far: "ours") and as a scripted one whose path the streamer is given
// (Streamer::setPathHint: "hinted"). Both flights request the same tiles at
// the same frames; OPT and LRU are the same for both.
//
// Usage: bench_streamer_hitrate [frames_per_path=600] [trace_dir=/tmp] [--tsv FILE] [--cost-tsv FILE]
// Prints two tab-separated tables, the hit rates and the render thread's
// cost per frame; --tsv FILE and --cost-tsv FILE also write them into those
// files (docs/data/streamer_hitrate.tsv, streamer_hitrate_cost.tsv).
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/trace.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include "tsv_out.h"

using namespace clipstream;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kSide = 4194304.0;  // 2^22 texels
constexpr double kFps = 60.0;
// The plans want only the tiles the frames sample (PlanScope::kSampled):
// every path's distinct tiles fit 256 MiB (2,377 tiles at most), so the
// budgets where eviction decides anything are the small ones.
constexpr double kBudgetsMb[] = {32, 48, 64, 96, 128, 256};

struct Path {
  const char* name;
  std::function<Camera(double t)> at;  // camera at time t (s)
};

Camera make(double x, double height, double z, double heading, double pitch) {
  Camera c;
  c.position = {x, height, z};
  c.heading_rad = heading;
  c.pitch_rad = pitch;
  return c;
}

// Ten-second paths (at 60 fps) that come back over ground they saw, as
// real flights do; a path that never returns has no hits for any policy.
std::vector<Path> paths() {
  const double cx = kSide * 0.5, cz = kSide * 0.5;
  return {
      {"pass",  // east for 2.5 s, back west, twice
       [=](double t) {
         const double u = std::fmod(t, 5.0);
         const double x = u < 2.5 ? 3000.0 * u : 3000.0 * (5.0 - u);
         return make(cx + x, 300.0, cz, u < 2.5 ? kPi / 2 : -kPi / 2, -0.4);
       }},
      {"dive",  // 20000 -> 50 texels high in 5 s and back up, drifting east
       [=](double t) {
         const double u = t < 5.0 ? t / 5.0 : (10.0 - t) / 5.0;
         const double h = 20000.0 * std::pow(50.0 / 20000.0, std::clamp(u, 0.0, 1.0));
         return make(cx + 100.0 * t, h, cz, 0.3, -0.8);
       }},
      {"orbit",  // two laps of radius 3000 at height 800, looking at the centre
       [=](double t) {
         const double a = 2.0 * kPi * t / 5.0;
         return make(cx + 3000.0 * std::sin(a), 800.0, cz + 3000.0 * std::cos(a), a + kPi,
                     -std::atan2(800.0, 3000.0));
       }},
      {"teleport",  // four places, one second each, round and round
       [=](double t) {
         const int hop = int(t) % 4;
         const double ox[4] = {0.2, 0.7, 0.3, 0.8}, oz[4] = {0.3, 0.2, 0.8, 0.6};
         return make(kSide * ox[hop] + 50.0 * std::fmod(t, 1.0), 400.0, kSide * oz[hop], 0.5 * hop, -0.6);
       }},
      {"zoom",  // 100 <-> 10000 texels high, period 5 s, looking down ahead
       [=](double t) {
         const double h = 100.0 * std::pow(100.0, 0.5 - 0.5 * std::cos(2.0 * kPi * t / 5.0));
         return make(cx, h, cz, 0.0, -1.2);
       }},
  };
}

// Trace recording needs plans, not pixels: this source returns a flat tile
// at memory speed so the benchmark spends its time in the streamer.
class FlatSource final : public TileSource {
 public:
  explicit FlatSource(const PyramidGeometry& g) : m_geometry(g) {}
  const PyramidGeometry& geometry() const override { return m_geometry; }
  Status fetch(const TileKey&, std::vector<uint8_t>* rgba) override {
    rgba->assign(size_t(m_geometry.tile_px) * m_geometry.tile_px * 4, 128);
    return okStatus();
  }
  std::string describe() const override { return "flat"; }

 private:
  PyramidGeometry m_geometry;
};

struct FrameCost {
  std::string path;
  double mean_ms, p99_ms, max_ms;
  uint64_t hint_frames, hint_ignored_frames;
};

// Flies one path for `frames` frames, recording its trace; returns the
// render-thread cost of update() + takeReady(64) per frame (plan, hint
// lookahead, ranking, queue rebuild on plan changes, hand-off, residency
// bitmaps).
FrameCost fly(const std::shared_ptr<TileSource>& source, const Viewport& vp, int frames, const Path& p,
              const StreamerConfig& cfg, const PathHint* hint, const std::string& label) {
  std::vector<double> frame_ms;
  StreamerStats stats;
  {
    Streamer s(source, cfg);
    if (hint) s.setPathHint(*hint);
    for (int f = 0; f < frames; ++f) {
      const auto t0 = std::chrono::steady_clock::now();
      s.update(p.at(f / kFps), vp, f / kFps);
      (void)s.takeReady(64);
      frame_ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
    stats = s.stats();
  }
  std::sort(frame_ms.begin(), frame_ms.end());
  double sum = 0.0;
  for (double v : frame_ms) sum += v;
  return {label, sum / double(frame_ms.size()), frame_ms[size_t(double(frame_ms.size() - 1) * 0.99)],
          frame_ms.back(), stats.path_hint_frames, stats.path_hint_ignored_frames};
}

// One row per budget: the path's two traces replayed under each policy.
void replayRows(const Path& p, const std::vector<TraceEvent>& events, const std::vector<TraceEvent>& hinted_events,
                const ReplayHint& hint, uint64_t entry_bytes, bench::TsvOut* hits_table) {
  for (double mb : kBudgetsMb) {
    const uint64_t capacity = uint64_t(mb * 1048576.0) / entry_bytes;
    const ReplayResult r = replayTrace(events, capacity);
    const ReplayResult h = replayTrace(hinted_events, capacity, &hint);
    auto pct = [&](uint64_t hits) { return r.accesses ? 100.0 * double(hits) / double(r.accesses) : 0.0; };
    auto ofOpt = [&](uint64_t hits) {
      return r.hits_opt ? 100.0 * double(hits) / double(r.hits_opt) : 100.0;
    };
    hits_table->row("%s\t%.0f\t%llu\t%llu\t%llu\t%.2f\t%.2f\t%.2f\t%.1f\t%.2f\t%.1f\t%.2f\t%.1f\n", p.name, mb,
                    (unsigned long long)r.accesses, (unsigned long long)r.gpu_reentries,
                    (unsigned long long)r.distinct_tiles, pct(r.hits_opt), pct(r.hits_lru),
                    pct(r.hits_gpu_first), ofOpt(r.hits_gpu_first),
                    pct(r.hits_plan), ofOpt(r.hits_plan), pct(h.hits_hinted), ofOpt(h.hits_hinted));
  }
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut hits_table(bench::takeOption(&argc, argv, "--tsv"));
  bench::TsvOut cost_table(bench::takeOption(&argc, argv, "--cost-tsv"));
  if (!hits_table.ok() || !cost_table.ok()) return 1;
  const int frames = argc > 1 ? std::atoi(argv[1]) : 600;
  const std::string dir = argc > 2 ? argv[2] : "/tmp";
  const uint64_t entry_bytes = 128 * 128 * 4 + kCacheEntryOverheadBytes;
  PyramidGeometry geometry;
  makePyramidGeometry(uint64_t(kSide), uint64_t(kSide), 128, PixelFormat::kRGBA8, &geometry);
  auto source = std::make_shared<FlatSource>(geometry);
  const Viewport vp{1280, 720};

  std::printf("# %.0fx%.0f texels, tile 128, viewport 1280x720, %d frames at 60 fps per path\n",
              kSide, kSide, frames);
  hits_table.row(
      "path\tbudget_mib\taccesses\tgpu_reentries\tdistinct\topt_hit_%%\tlru_hit_%%\tours_hit_%%"
      "\tours_of_opt_%%"
      "\tprotect_gpu_hit_%%\tprotect_gpu_of_opt_%%\thinted_hit_%%\thinted_of_opt_%%\n");
  std::vector<FrameCost> costs;
  for (const Path& p : paths()) {
    StreamerConfig cfg;
    cfg.io_threads = 1;
    cfg.ram_budget_bytes = uint64_t(64) << 20;
    cfg.trace_path = dir + "/clipstream_" + p.name + ".trace";
    costs.push_back(fly(source, vp, frames, p, cfg, nullptr, p.name));
    // The same flight with its path given to the streamer.
    ReplayHint hint;
    hint.path.camera_at = p.at;
    hint.geometry = geometry;
    hint.planner = cfg.planner;
    StreamerConfig hinted_cfg = cfg;
    hinted_cfg.trace_path = dir + "/clipstream_" + p.name + "_hinted.trace";
    costs.push_back(fly(source, vp, frames, p, hinted_cfg, &hint.path, std::string(p.name) + " hinted"));
    std::vector<TraceEvent> events, hinted_events;
    for (auto [path, out] :
         {std::pair{&cfg.trace_path, &events}, std::pair{&hinted_cfg.trace_path, &hinted_events}}) {
      if (Status st = readTrace(*path, out); !st) {
        std::fprintf(stderr, "%s\n", st.toString().c_str());
        return 1;
      }
    }
    // Both flights must want the same tiles at the same frames.
    auto accessesOf = [](const std::vector<TraceEvent>& ev) {
      std::vector<std::pair<uint64_t, TileKey>> out;
      for (const TraceEvent& e : ev)
        if (e.isAccess()) out.emplace_back(e.frame, e.key);
      return out;
    };
    if (accessesOf(events) != accessesOf(hinted_events)) {
      std::fprintf(stderr, "%s: the hinted flight requested other tiles or at other frames\n", p.name);
      return 1;
    }
    replayRows(p, events, hinted_events, hint, entry_bytes, &hits_table);
  }
  std::printf("\n");
  cost_table.row("flight\tupdate_takeready_mean_ms\tp99_ms\tmax_ms\thint_frames\thint_ignored_frames\n");
  for (const FrameCost& c : costs)
    cost_table.row("%s\t%.3f\t%.3f\t%.3f\t%llu\t%llu\n", c.path.c_str(), c.mean_ms, c.p99_ms, c.max_ms,
                (unsigned long long)c.hint_frames, (unsigned long long)c.hint_ignored_frames);
  return hits_table.commit() && cost_table.commit() ? 0 : 1;
}
