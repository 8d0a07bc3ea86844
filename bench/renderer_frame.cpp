// Frame cost of the clipmap ground against a plain mipmapped 2D texture
// drawing the same view (same ray setup, hardware trilinear), of BC1
// tiles against RGBA8 ones (the same shader sampling a compressed stack),
// and of paged texture memory (TextureMemory::kPaged: the tiles the view
// samples in a pool of pages) against the full stack.
// Everything the clipmap needs is resident; the time is the render thread's CPU time for
// draw + glFinish, best of N. Run with LP_NUM_THREADS=0 so llvmpipe shades on
// that thread (then the CPU time is the whole frame's work).
//
//   bench_renderer_frame [--size 1280x720] [--repeats 15] [--clip-tiles C] [--tsv FILE]
// Prints a tab-separated table; --tsv FILE also writes it into FILE
// (docs/data/renderer_frame.tsv).
#include "plain_texture_renderer.h"
#include "tsv_out.h"

#include <clipstream/cli/sizes.h>
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
#include <string>
#include <ctime>

using namespace clipstream;

namespace {

std::vector<uint8_t> pattern(uint32_t n) {
  std::vector<uint8_t> rgba(size_t(n) * n * 4);
  for (uint32_t y = 0; y < n; ++y)
    for (uint32_t x = 0; x < n; ++x) {
      uint8_t* p = rgba.data() + (size_t(y) * n + x) * 4;
      p[0] = uint8_t(128 + 100 * std::sin(x * 0.071) * std::cos(y * 0.053));
      p[1] = uint8_t(128 + 90 * std::sin((x + 2.0 * y) * 0.019));
      p[2] = ((x / 8 + y / 8) & 1) ? 200 : 60;
      p[3] = 255;
    }
  return rgba;
}

double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}

template <class Draw>
double bestMs(int repeats, OffscreenTarget& target, Draw draw) {
  double best = 1e30;
  for (int i = 0; i < repeats + 1; ++i) {  // one warm-up frame
    target.bind();
    ClipmapRenderer::clearSky();
    glFinish();
    // With LP_NUM_THREADS=0 llvmpipe rasterises on this thread, and its CPU
    // time is a measure that load from other processes barely disturbs.
    const double t0 = threadCpuMs();
    draw();
    glFinish();
    const double ms = threadCpuMs() - t0;
    if (i >= 1) best = std::min(best, ms);
  }
  return best;
}

// Makes the renderer of one mode for the camera and uploads every tile it
// needs: the pyramid from its plan's level up and the stack windows, with
// the residency the streamer would report. Modes: 0 RGBA8 single-buffered,
// 1 RGBA8 double-buffered, 2 BC1 single-buffered (from bc1_tiles), 3 RGBA8
// paged. False after printing why it cannot.
bool makeFilledRenderer(int mode, TileSource& rgba_tiles, TileSource& bc1_tiles, const Viewport& vp,
                        const Camera& cam, const PlannerConfig& planner, std::unique_ptr<ClipmapRenderer>* out) {
  std::unique_ptr<ClipmapRenderer>& r = *out;
  TileSource& tiles = mode == 2 ? bc1_tiles : rgba_tiles;
  const TextureMemory memory = mode == 3 ? TextureMemory::kPaged : TextureMemory::kStack;
  const ClipmapPlan plan = planClipmap(rgba_tiles.geometry(), vp, cam, plannerFor(memory, planner));
  RendererConfig rc{plan.clip_tiles, plan.pyramid_level,
                    mode == 1 ? Buffering::kDoubleUploadTwice : Buffering::kSingle, tiles.content()};
  rc.texture_memory = memory;
  if (memory == TextureMemory::kPaged) rc.pool_bytes = uint64_t(1) << 40;
  if (Status s = ClipmapRenderer::create(rgba_tiles.geometry(), rc, &r); !s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return false;
  }
  r->beginFrame();
  const PyramidGeometry& g = rgba_tiles.geometry();
  auto upload = [&](uint32_t l, int64_t x, int64_t y) {
    auto px = std::make_shared<std::vector<uint8_t>>();
    if (tiles.fetch({l, uint32_t(x), uint32_t(y)}, px.get()).ok())
      r->uploadTile({l, uint32_t(x), uint32_t(y)}, px);
  };
  for (uint32_t l = plan.pyramid_level; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) upload(l, x, y);
  std::vector<LevelResidency> res;
  for (const ClipLevelPlan& lp : plan.stack) {
    for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
      for (int64_t x = lp.window.x0; x < lp.window.x1; ++x) upload(lp.level, x, y);
    LevelResidency level{lp.level, lp.window,
                         std::vector<uint8_t>(size_t(lp.window.width() * lp.window.height()), 1)};
    // The tiles no tap reads, as the streamer says them: the stack
    // ignores this, the pool gives pages to the others only.
    if (!lp.sampled.empty()) {
      level.unread.assign(level.resident.size(), 0);
      size_t j = 0;
      for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
        for (int64_t x = lp.window.x0; x < lp.window.x1; ++x, ++j) level.unread[j] = lp.wants(x, y) ? 0 : 1;
    }
    res.push_back(std::move(level));
  }
  r->setResidency(res);
  r->endUploads();
  r->beginFrame();
  r->endUploads();
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  Viewport vp{1280, 720};
  int repeats = 15;
  PlannerConfig planner;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--size") && !cli::parseSize(argv[i + 1], &vp.width_px, &vp.height_px).ok()) return 2;
    if (!std::strcmp(argv[i], "--repeats")) repeats = std::max(1, std::atoi(argv[i + 1]));
    if (!std::strcmp(argv[i], "--clip-tiles")) planner.clip_tiles = uint32_t(std::atoi(argv[i + 1]));
  }
  std::unique_ptr<HeadlessContext> ctx;
  if (Status s = HeadlessContext::create(&ctx); !s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  const uint32_t side = 4096, tile = 128;
  std::vector<uint8_t> image = pattern(side);
  std::unique_ptr<PlainTextureRenderer> plain;
  if (Status s = PlainTextureRenderer::create(image.data(), side, side, &plain); !s) return 1;
  auto source = makeImageSource(std::move(image), side, side, tile);
  Status bc1_status;
  auto bc1_source = makeBc1Source(source, &bc1_status);
  if (!bc1_source) {
    std::fprintf(stderr, "%s\n", bc1_status.toString().c_str());
    return 1;
  }
  std::unique_ptr<OffscreenTarget> target;
  if (Status s = OffscreenTarget::create(vp, &target); !s) return 1;

  struct View {
    const char* name;
    double height, pitch;
  };
  const View views[] = {{"low-oblique", 40.0, -0.35}, {"mid-oblique", 300.0, -0.6},
                        {"high-down", 900.0, -1.45}, {"horizon", 15.0, -0.05}};
  std::printf("# %s, %ux%u, texture %ux%u, tile %u, best of %d\n", ctx->describe().c_str(),
              vp.width_px, vp.height_px, side, side, tile, repeats);
  table.row("view\tplain_ms\tclipmap_single_ms\tclipmap_double_ms\tratio_double\tclipmap_bc1_ms\t"
              "bc1_vs_rgba8\tstack_levels\tclipmap_paged_ms\tpaged_vs_stack\tpaged_pages\n");
  for (const View& v : views) {
    Camera cam;
    cam.position = {side * 0.5 + 0.3, v.height, side * 0.6 + 0.7};
    cam.heading_rad = 0.35;
    cam.pitch_rad = v.pitch;
    // RGBA8 single-buffered, RGBA8 double-buffered, BC1 single-buffered,
    // RGBA8 paged (its own plan: a small pyramid; the pool as large as the
    // GL allows, so no sampled tile goes without a page).
    constexpr int kModes = 4;
    std::unique_ptr<ClipmapRenderer> renderers[kModes];
    for (int mode = 0; mode < kModes; ++mode) {
      if (!makeFilledRenderer(mode, *source, *bc1_source, vp, cam, planner, &renderers[mode])) return 1;
    }
    // Interleaved rounds, so load from other processes hits all three alike.
    double ms[kModes] = {1e30, 1e30, 1e30, 1e30}, plain_ms = 1e30;
    for (int round = 0; round < repeats; ++round) {
      plain_ms = std::min(plain_ms, bestMs(1, *target, [&] { plain->draw(cam, vp); }));
      for (int mode = 0; mode < kModes; ++mode)
        ms[mode] = std::min(ms[mode], bestMs(1, *target, [&] { renderers[mode]->draw(cam, vp); }));
    }
    const ClipmapPlan plan = planClipmap(source->geometry(), vp, cam, planner);
    table.row("%s\t%.2f\t%.2f\t%.2f\t%.2f\t%.2f\t%.2f\t%u\t%.2f\t%.2f\t%u\n", v.name, plain_ms, ms[0],
                ms[1], ms[1] / plain_ms, ms[2], ms[2] / ms[0], plan.pyramid_level, ms[3], ms[3] / ms[0],
                renderers[3]->poolPagesUsed());
  }
  return table.commit() ? 0 : 1;
}
