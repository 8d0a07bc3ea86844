#include "test_helpers.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace clipstream::test {

HeadlessContext* sharedContext(std::string* why) {
  static std::unique_ptr<HeadlessContext> context;
  static Status status = HeadlessContext::create(&context);
  if (why != nullptr) *why = status.toString();
  return context.get();
}

std::vector<uint8_t> patternImage(uint32_t width_px, uint32_t height_px) {
  std::vector<uint8_t> rgba(size_t(width_px) * height_px * 4);
  for (uint32_t y = 0; y < height_px; ++y) {
    for (uint32_t x = 0; x < width_px; ++x) {
      uint8_t* p = rgba.data() + (size_t(y) * width_px + x) * 4;
      p[0] = uint8_t(128 + 100 * std::sin(x * 0.071) * std::cos(y * 0.053));
      p[1] = uint8_t(128 + 90 * std::sin((x + 2.0 * y) * 0.019));
      p[2] = ((x / 8 + y / 8) & 1) ? 200 : 60;
      p[3] = 255;
    }
  }
  return rgba;
}

std::vector<LevelResidency> fullResidency(const ClipmapPlan& plan, uint32_t finest_loaded) {
  std::vector<LevelResidency> out;
  for (const ClipLevelPlan& l : plan.stack) {
    LevelResidency r;
    r.level = l.level;
    r.window = l.window;
    r.resident.assign(size_t(l.window.width()) * size_t(l.window.height()),
                      l.level >= finest_loaded ? 1 : 0);
    out.push_back(std::move(r));
  }
  return out;
}

void loadPlan(ClipmapRenderer& renderer, TileSource& source, const ClipmapPlan& plan,
              uint32_t finest_loaded) {
  const PyramidGeometry& g = source.geometry();
  renderer.beginFrame();
  auto upload = [&](uint32_t level, int64_t x, int64_t y) {
    auto px = std::make_shared<std::vector<uint8_t>>();
    if (!source.fetch({level, uint32_t(x), uint32_t(y)}, px.get())) return;
    renderer.uploadTile({level, uint32_t(x), uint32_t(y)}, px);
  };
  for (uint32_t l = plan.pyramid_level; l < g.levelCount(); ++l)
    for (uint32_t y = 0; y < g.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < g.levels[l].tiles_x; ++x) upload(l, x, y);
  for (const ClipLevelPlan& l : plan.stack) {
    if (l.level < finest_loaded) continue;
    for (int64_t y = l.window.y0; y < l.window.y1; ++y)
      for (int64_t x = l.window.x0; x < l.window.x1; ++x) upload(l.level, x, y);
  }
  renderer.setResidency(fullResidency(plan, finest_loaded));
  renderer.setMaxTextureLod(0);
  renderer.endUploads();
  // Double-buffered: bring the other set up to date too, so a following
  // frame that uploads nothing draws the same.
  renderer.beginFrame();
  renderer.endUploads();
}

std::vector<uint8_t> renderFrame(ClipmapRenderer& renderer, OffscreenTarget& target,
                                 const Camera& camera) {
  target.bind();
  ClipmapRenderer::clearSky();
  renderer.draw(camera, target.viewport());
  std::vector<uint8_t> rgba;
  target.readRgba(&rgba);
  return rgba;
}

}  // namespace clipstream::test

namespace clipstream::test {
void dumpPpm(const std::string& name, const std::vector<uint8_t>& rgba, const Viewport& vp) {
  const char* dir = std::getenv("CLIPSTREAM_TEST_DUMP");
  if (dir == nullptr) return;
  FILE* f = std::fopen((std::string(dir) + "/" + name + ".ppm").c_str(), "wb");
  if (f == nullptr) return;
  std::fprintf(f, "P6 %u %u 255\n", vp.width_px, vp.height_px);
  for (size_t i = 0; i < rgba.size(); i += 4) std::fwrite(&rgba[i], 1, 3, f);
  std::fclose(f);
}
}  // namespace clipstream::test
