// Single- vs double-buffered stack layers: upload stalls and frame-time
// jitter while the camera flies low and fast, so every frame uploads its
// budget of tiles into windows that keep moving.
//
// The loop keeps one frame in flight, as a swap chain would: frame N is
// submitted (glFlush), then the CPU waits for frame N-1's fence. Uploads of
// frame N+1 therefore meet a texture that frame N may still be reading
// (single-buffered), or one no queued frame reads (double-buffered).
// Tiles are fetched from the source outside the timed region; the timed
// part is the GL work of each frame. Wall-clock times, best run of R.
//
//   bench_renderer_buffering [--size 1280x720] [--frames 240] [--upload-tiles 16] [--runs 3] [--tsv FILE]
// Prints a tab-separated table; --tsv FILE also writes it into FILE
// (docs/data/renderer_buffering_run1.tsv).
#include <clipstream/cli/sizes.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/tile_source.h>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <map>
#include <set>

#include "tsv_out.h"
#include <tuple>

using namespace clipstream;

namespace {

using Clock = std::chrono::steady_clock;
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

struct KeyLess {
  bool operator()(const TileKey& a, const TileKey& b) const {
    return std::tie(a.level, a.y, a.x) < std::tie(b.level, b.y, b.x);
  }
};

struct Result {
  double frame_mean = 0, frame_p50 = 0, frame_p99 = 0, frame_max = 0, frame_sd = 0;
  double upload_mean = 0, upload_p99 = 0, upload_max = 0;
  double upload_cpu_mean = 0;  // render thread CPU time in the uploads: wall - this = waiting
  uint64_t tiles = 0, second = 0;
};

double pct(std::vector<double> v, double p) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[size_t(p * double(v.size() - 1) + 0.5)];
}

Result runOnce(Buffering buffering, TileSource& source, const Viewport& vp, uint32_t frames,
               uint32_t upload_tiles, OffscreenTarget& target) {
  const PyramidGeometry& g = source.geometry();
  auto cameraAt = [&](uint32_t i) {
    Camera c;
    c.position = {double(g.width_px) * 0.3 + 40.0 * i, 120.0, double(g.height_px) * 0.5 + 0.37};
    c.heading_rad = 1.2;
    c.pitch_rad = -0.45;
    return c;
  };
  std::unique_ptr<ClipmapRenderer> r;
  if (!createClipmapRenderer(source, vp, cameraAt(0), {}, buffering, &r, nullptr).ok()) return {};
  glFinish();

  std::set<TileKey, KeyLess> resident;
  std::vector<double> frame_ms, upload_ms;
  double upload_cpu_total = 0.0;
  Result res;
  GLsync previous = nullptr;
  auto last_done = Clock::now();
  for (uint32_t i = 0; i < frames; ++i) {
    const Camera cam = cameraAt(i);
    const ClipmapPlan plan = planClipmap(g, vp, cam, {});
    // Forget tiles that left their window; pick this frame's uploads.
    for (auto it = resident.begin(); it != resident.end();) {
      const bool keep = it->level < plan.stack.size() && plan.stack[it->level].needed &&
                        plan.stack[it->level].window.contains(it->x, it->y);
      it = keep ? std::next(it) : resident.erase(it);
    }
    std::vector<std::pair<TileKey, std::shared_ptr<std::vector<uint8_t>>>> batch;
    for (const TileKey& k : rankPlanTiles(g, plan)) {
      if (batch.size() >= upload_tiles) break;
      if (k.level >= plan.pyramid_level || resident.count(k)) continue;
      auto px = std::make_shared<std::vector<uint8_t>>();
      if (!source.fetch(k, px.get()).ok()) continue;
      batch.push_back({k, std::move(px)});
    }
    std::vector<LevelResidency> residency;
    for (const ClipLevelPlan& lp : plan.stack) {
      LevelResidency lr{lp.level, lp.window, {}};
      lr.resident.assign(size_t(lp.window.width() * lp.window.height()), 0);
      for (const auto& [k, px] : batch)
        if (k.level == lp.level) resident.insert(k);
      size_t j = 0;
      for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
        for (int64_t x = lp.window.x0; x < lp.window.x1; ++x, ++j)
          lr.resident[j] = resident.count({lp.level, uint32_t(x), uint32_t(y)}) ? 1 : 0;
      residency.push_back(std::move(lr));
    }

    const auto t0 = Clock::now();
    const double cpu0 = threadCpuMs();
    r->beginFrame();
    for (auto& [k, px] : batch) r->uploadTile(k, px);
    r->setResidency(residency);
    r->endUploads();
    upload_ms.push_back(msSince(t0));
    upload_cpu_total += threadCpuMs() - cpu0;
    res.tiles += r->lastUploads().tiles;
    res.second += r->lastUploads().second_copies;
    target.bind();
    ClipmapRenderer::clearSky();
    r->draw(cam, vp);
    GLsync fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    glFlush();
    if (previous != nullptr) {
      glClientWaitSync(previous, GL_SYNC_FLUSH_COMMANDS_BIT, uint64_t(10) * 1000000000);
      glDeleteSync(previous);
    }
    previous = fence;
    const auto now = Clock::now();
    if (i > 0) frame_ms.push_back(std::chrono::duration<double, std::milli>(now - last_done).count());
    last_done = now;
  }
  if (previous != nullptr) {
    glClientWaitSync(previous, GL_SYNC_FLUSH_COMMANDS_BIT, uint64_t(10) * 1000000000);
    glDeleteSync(previous);
  }
  double sum = 0, sq = 0;
  for (double v : frame_ms) sum += v;
  res.frame_mean = sum / double(std::max<size_t>(frame_ms.size(), 1));
  for (double v : frame_ms) sq += (v - res.frame_mean) * (v - res.frame_mean);
  res.frame_sd = std::sqrt(sq / double(std::max<size_t>(frame_ms.size(), 1)));
  res.frame_p50 = pct(frame_ms, 0.5);
  res.frame_p99 = pct(frame_ms, 0.99);
  res.frame_max = pct(frame_ms, 1.0);
  double usum = 0;
  for (double v : upload_ms) usum += v;
  res.upload_mean = usum / double(std::max<size_t>(upload_ms.size(), 1));
  res.upload_p99 = pct(upload_ms, 0.99);
  res.upload_cpu_mean = upload_cpu_total / double(std::max<size_t>(upload_ms.size(), 1));
  res.upload_max = pct(upload_ms, 1.0);
  return res;
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  Viewport vp{1280, 720};
  uint32_t frames = 240, upload_tiles = 16, runs = 3;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--size") && !cli::parseSize(argv[i + 1], &vp.width_px, &vp.height_px).ok()) return 2;
    if (!std::strcmp(argv[i], "--frames")) frames = uint32_t(std::max(2, std::atoi(argv[i + 1])));
    if (!std::strcmp(argv[i], "--upload-tiles")) upload_tiles = uint32_t(std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--runs")) runs = uint32_t(std::max(1, std::atoi(argv[i + 1])));
  }
  std::unique_ptr<HeadlessContext> ctx;
  if (Status s = HeadlessContext::create(&ctx); !s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  ProceduralSpec spec;
  spec.width_px = spec.height_px = uint64_t(1) << 20;
  auto source = makeProceduralSource(spec);
  std::unique_ptr<OffscreenTarget> target;
  if (!OffscreenTarget::create(vp, &target).ok()) return 1;
  std::printf("# %s, %ux%u, procedural 2^20, %u frames, %u uploads/frame, best of %u runs (by p99)\n",
              ctx->describe().c_str(), vp.width_px, vp.height_px, frames, upload_tiles, runs);
  table.row("buffering\tframe_mean_ms\tframe_p50_ms\tframe_p99_ms\tframe_max_ms\tframe_sd_ms\t"
              "upload_mean_ms\tupload_cpu_mean_ms\tupload_p99_ms\tupload_max_ms\ttiles\tsecond_copies\n");
  for (Buffering b : {Buffering::kSingle, Buffering::kDoubleUploadTwice, Buffering::kDoubleCopy,
                      Buffering::kStaged}) {
    Result best;
    best.frame_p99 = 1e30;
    for (uint32_t run = 0; run < runs; ++run) {
      Result r = runOnce(b, *source, vp, frames, upload_tiles, *target);
      if (r.frame_p99 < best.frame_p99) best = r;
    }
    table.row("%s\t%.2f\t%.2f\t%.2f\t%.2f\t%.2f\t%.3f\t%.3f\t%.3f\t%.3f\t%llu\t%llu\n",
                bufferingName(b), best.frame_mean, best.frame_p50, best.frame_p99, best.frame_max,
                best.frame_sd, best.upload_mean, best.upload_cpu_mean, best.upload_p99, best.upload_max, (unsigned long long)best.tiles,
                (unsigned long long)best.second);
  }
  return table.commit() ? 0 : 1;
}
