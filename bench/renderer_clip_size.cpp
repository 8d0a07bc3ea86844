// Does a smaller clip change the picture? The ideal reference (every tile
// of every needed window resident, eval/accuracy.h) drawn with the
// planner's clip size for the viewport and with clips a few tiles smaller
// and larger, over a 2^26-texel procedural texture, from views that stress
// the windows (straight down just before a level switch, with the screen's
// diagonal along a window axis or not; oblique; grazing). Prints, per view
// and clip, the pixels that differ from the planner's clip, the PSNR
// against the CPU ground truth (every level at full size, reference.h) and
// the stack's bytes for one RGBA8 set (what the clip costs).
//
//   bench_renderer_clip_size [--size 1280x720] [--deltas -8,-6,-4,-2,2,4] [--view NAME] [--tsv FILE]
// Prints a tab-separated table; --tsv FILE also writes it into FILE
// (docs/data/renderer_clip_size_1280x720.tsv).
// CLIPSTREAM_BENCH_DUMP=DIR also writes each frame there as a PPM.
#include <clipstream/cli/sizes.h>
#include <clipstream/eval/accuracy.h>
#include <clipstream/eval/metrics.h>
#include <clipstream/eval/reference.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/streamer/planner.h>
#include <clipstream/streamer/tile_source.h>
#include <clipstream/streamer/testing/procedural_texel.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <vector>

#include "tsv_out.h"

using namespace clipstream;

namespace {

// Bytes of one RGBA8 stack set for a clip (renderer.cpp's layout: slots =
// clip rounded down to even + 2, pyramid_level + 1 layers, the mip chain).
uint64_t stackBytes(const PyramidGeometry& g, const ClipmapPlan& plan) {
  RendererConfig rc{plan.clip_tiles, plan.pyramid_level, Buffering::kSingle};
  std::unique_ptr<ClipmapRenderer> r;
  if (!ClipmapRenderer::create(g, rc, &r).ok()) return 0;
  return r->textureBytes().stack;
}

}  // namespace

int main(int argc, char** argv) {
  bench::TsvOut table(bench::takeOption(&argc, argv, "--tsv"));
  if (!table.ok()) return 1;
  Viewport vp{1280, 720};
  std::vector<int> deltas = {-8, -6, -4, -2, 2, 4};
  std::string only;  // --view NAME: that view only
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--size") && !cli::parseSize(argv[i + 1], &vp.width_px, &vp.height_px).ok()) return 2;
    if (!std::strcmp(argv[i], "--view")) only = argv[i + 1];
    if (!std::strcmp(argv[i], "--deltas")) {
      deltas.clear();
      std::stringstream list(argv[i + 1]);
      std::string item;
      while (std::getline(list, item, ',')) deltas.push_back(std::atoi(item.c_str()));
    }
  }
  std::unique_ptr<HeadlessContext> ctx;
  if (Status s = HeadlessContext::create(&ctx); !s) {
    std::fprintf(stderr, "%s\n", s.toString().c_str());
    return 1;
  }
  ProceduralSpec spec;  // 2^26
  auto source = makeProceduralSource(spec);
  const PyramidGeometry& g = source->geometry();
  const double mid = double(g.width_px) * 0.5;
  const double deg = 3.14159265358979323846 / 180.0;
  // Straight down, a pixel at the nadir spans height * 2 tan(vfov / 2) / height_px
  // texels: heights where that is 2^3.1 and 2^3.9 (just before level 4).
  Camera probe;
  const double texels_per_height = 2.0 * std::tan(probe.vfov_rad * 0.5) / double(vp.height_px);
  struct View {
    const char* name;
    double height, pitch_deg, heading_deg;
  };
  const View views[] = {
      {"down_lambda3.9_heading0", std::exp2(3.9) / texels_per_height, -90.0, 0.0},
      {"down_lambda3.9_heading45", std::exp2(3.9) / texels_per_height, -90.0, 45.0},
      {"down_lambda3.1_heading30", std::exp2(3.1) / texels_per_height, -90.0, 30.0},
      {"sweep_line", 200.0, -30.0, 90.0},
      {"oblique", 2000.0, -45.0, 30.0},
      {"grazing", 20.0, -5.0, 60.0},
  };
  const uint32_t planned = planClipmap(g, vp, Camera{}, {}).clip_tiles;
  std::printf("# %s, %ux%u, procedural 2^26, planner clip %u tiles; differing pixels against the planner's clip\n",
              ctx->describe().c_str(), vp.width_px, vp.height_px, planned);
  table.row("view\tclip_tiles\tstack_set_mib\tdiffering_pixels\tdiffering_pct\tpsnr_db\tground_truth_psnr_db\n");
  const TexelFunction truth_texels = [&spec](uint32_t level, uint64_t x, uint64_t y, uint8_t rgba[4]) {
    proceduralTexel(spec, level, x, y, rgba);
  };
  for (const View& v : views) {
    if (!only.empty() && only != v.name) continue;
    Camera cam;
    cam.position = {mid + 0.37, v.height, mid + 0.61};
    cam.pitch_rad = v.pitch_deg * deg;
    cam.heading_rad = v.heading_deg * deg;
    std::vector<uint8_t> base, truth;
    renderReference(g, truth_texels, cam, vp, ReferenceOptions{}, &truth);
    std::vector<int> clips = {0};
    for (int d : deltas) clips.push_back(d);
    for (int d : clips) {
      PlannerConfig planner;
      planner.clip_tiles = uint32_t(std::max(4, int(planned) + d));
      std::unique_ptr<IdealReference> ref;
      if (Status s = IdealReference::create(source, vp, planner, &ref); !s) {
        std::fprintf(stderr, "%s\n", s.toString().c_str());
        return 1;
      }
      std::vector<uint8_t> frame;
      if (Status s = ref->render(cam, &frame); !s) {
        std::fprintf(stderr, "%s\n", s.toString().c_str());
        return 1;
      }
      if (d == 0) base = frame;
      size_t differing = 0;
      for (size_t i = 0; i < frame.size(); i += 4)
        differing += std::memcmp(&frame[i], &base[i], 3) != 0;
      const FrameError e = compareFrames(frame, base);
      const ClipmapPlan plan = planClipmap(g, vp, cam, planner);
      table.row("%s\t%u\t%.1f\t%zu\t%.3f\t%.2f\t%.2f\n", v.name, planner.clip_tiles,
                  double(stackBytes(g, plan)) / 1048576.0, differing,
                  100.0 * double(differing) / double(vp.width_px * vp.height_px), e.psnr_db,
                  compareFrames(frame, truth).psnr_db);
      if (const char* dir = std::getenv("CLIPSTREAM_BENCH_DUMP")) {
        const std::string path = std::string(dir) + "/" + v.name + "_clip" + std::to_string(planner.clip_tiles) + ".ppm";
        if (FILE* f = std::fopen(path.c_str(), "wb")) {
          std::fprintf(f, "P6\n%u %u\n255\n", vp.width_px, vp.height_px);
          for (size_t i = 0; i < frame.size(); i += 4) std::fwrite(&frame[i], 1, 3, f);
          std::fclose(f);
        }
      }
      std::fflush(stdout);
    }
  }
  return table.commit() ? 0 : 1;
}
