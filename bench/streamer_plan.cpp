// The planner's cost on the render thread: planClipmap() for one camera,
// with the sampled plan scope (PlanScope::kSampled, the default on the flat
// plane: the window tiles the frame samples) and the whole window
// (kWindow), at three viewports and three views over a 2^26-texel pyramid
// (the sweep's procedural texture). The streamer plans twice a frame (the
// camera and the predicted camera), so a frame pays about twice the figure.
//
// Usage: bench_streamer_plan [repeats=400] [--tsv FILE]
// Prints a tab-separated table: view, viewport, scope, mean / p50 / p99 us
// per plan, and the tiles the plan wants; --tsv FILE also writes it into
// FILE (docs/data/streamer_plan.tsv).
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/planner.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "tsv_out.h"

using namespace clipstream;

namespace {

struct View {
  const char* name;
  double height, pitch_deg;
};

uint64_t wantedTiles(const ClipmapPlan& plan) {
  uint64_t n = 0;
  for (const ClipLevelPlan& lp : plan.stack)
    if (lp.needed) n += lp.wantedCount();
  return n;
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  const int repeats = argc > 1 ? std::max(1, std::atoi(argv[1])) : 400;
  PyramidGeometry g;
  if (!makePyramidGeometry(uint64_t(1) << 26, uint64_t(1) << 26, 128, PixelFormat::kRGBA8, &g)) return 1;
  const View views[] = {{"line (200 up, 30 deg down)", 200.0, -30.0},
                        {"low, near the horizon (20 up, 5 deg down)", 20.0, -5.0},
                        {"high nadir (5000 up, 90 deg down)", 5000.0, -89.9}};
  const Viewport viewports[] = {{320, 180}, {1280, 720}, {1920, 1080}};
  table.row("view\tviewport\tscope\tmean_us\tp50_us\tp99_us\twanted_tiles\n");
  for (const View& v : views) {
    for (const Viewport& vp : viewports) {
      for (const PlanScope scope : {PlanScope::kSampled, PlanScope::kWindow}) {
        PlannerConfig config;
        config.scope = scope;
        std::vector<double> us;
        us.reserve(size_t(repeats));
        uint64_t wanted = 0;
        const double centre = double(uint64_t(1) << 25);
        for (int r = 0; r < repeats; ++r) {
          Camera camera;
          // A camera moving along the line, one texel a plan: every plan
          // starts from a new position, as in a flight.
          camera.position = {centre + double(r), v.height, centre};
          camera.heading_rad = M_PI / 2.0;
          camera.pitch_rad = v.pitch_deg * M_PI / 180.0;
          const auto t0 = std::chrono::steady_clock::now();
          const ClipmapPlan plan = planClipmap(g, vp, camera, config);
          const auto t1 = std::chrono::steady_clock::now();
          us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
          wanted = wantedTiles(plan);
        }
        std::sort(us.begin(), us.end());
        double mean = 0.0;
        for (double x : us) mean += x / double(us.size());
        table.row("%s\t%ux%u\t%s\t%.1f\t%.1f\t%.1f\t%llu\n", v.name, vp.width_px, vp.height_px,
                    scope == PlanScope::kSampled ? "sampled" : "window", mean, us[us.size() / 2],
                    us[std::min(us.size() - 1, size_t(double(us.size()) * 0.99))],
                    static_cast<unsigned long long>(wanted));
      }
    }
  }
  return table.commit() ? 0 : 1;
}
