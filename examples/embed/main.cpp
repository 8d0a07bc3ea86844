// A host program that embeds clipstream (docs/api.md): the host owns the GL
// context, the camera and the frame loop; clipstream streams the tiles and
// draws the ground into whatever framebuffer the host binds.
//
//   clipstream-embed [STORE] [--frames N]
//
// STORE is a tile store made by clipstream-tile; without one, a procedural
// texture of 2^20 x 2^20 texels. Flies one orbit of N frames (240) headless
// (EGL, no window), holds the last view until its tiles have arrived, checks
// that the picture shows ground, and prints a few statistics; it writes no
// file. Exit 0 on success; 1 with a message on stderr when the store or GL
// fails or the picture is wrong; 2 for a command-line mistake.
//
// Threads: everything here runs on the main thread, which owns the GL
// context. The streamer's loader threads read and decode tiles; no call in
// the frame loop waits on a disk.
#include <clipstream/renderer/config.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>  // the host's own GL calls (glvnd's libOpenGL, no loader)

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

namespace cs = clipstream;

namespace {

int fail(const std::string& what, const cs::Status& status) {
  std::fprintf(stderr, "clipstream-embed: %s: %s\n", what.c_str(), status.toString().c_str());
  return 1;
}

// The host's camera: one orbit round the texture's centre, looking ahead and
// down, at a height of an eighth of the texture's shorter side.
cs::Camera orbitCamera(const cs::PyramidGeometry& geometry, double turn) {
  const double side = double(std::min(geometry.width_px, geometry.height_px));
  const double angle = 2.0 * std::numbers::pi * turn;
  cs::Camera camera;
  camera.position = {geometry.width_px / 2.0 + side / 4.0 * std::sin(angle), side / 8.0,
                     geometry.height_px / 2.0 - side / 4.0 * std::cos(angle)};
  camera.heading_rad = angle + std::numbers::pi / 2.0;  // along the orbit
  camera.pitch_rad = -0.9;
  return camera;
}

}  // namespace

// Long: the example a newcomer reads top to bottom: every call of the
// embedding (open, create, frame loop, shutdown) in order, in one place.
int main(int argc, char** argv) {
  std::string store_path;
  unsigned long frames = 240;
  for (int i = 1; i < argc; ++i) {
    char* end = nullptr;
    if (std::strcmp(argv[i], "--frames") == 0 && i + 1 < argc &&
        (frames = std::strtoul(argv[i + 1], &end, 10), *end == '\0') && frames >= 1 && frames <= 100000) {
      ++i;
    } else if (argv[i][0] != '-' && store_path.empty()) {
      store_path = argv[i];
    } else {
      std::fprintf(stderr, "usage: clipstream-embed [STORE] [--frames N (1..100000)]\n");
      return 2;
    }
  }

  // 1. Where tiles come from. A source is thread-safe: the streamer's loader
  //    threads call it, and so does the pyramid preload below.
  std::shared_ptr<cs::TileSource> source;
  if (store_path.empty()) {
    cs::ProceduralSpec spec;
    spec.width_px = spec.height_px = uint64_t(1) << 20;
    source = cs::makeProceduralSource(spec);
  } else {
    cs::Status status;
    source = cs::openStoreSource(store_path, &status);
    if (!status.ok()) return fail("store", status);  // and source is null
  }
  const cs::PyramidGeometry& geometry = source->geometry();

  // 2. The host's GL context, current on this thread. A host with a window
  //    makes its own context current instead; the renderer needs OpenGL 4.5
  //    core and uses whatever context is current.
  std::unique_ptr<cs::HeadlessContext> context;
  if (cs::Status s = cs::HeadlessContext::create(&context); !s.ok()) return fail("no OpenGL 4.5 context", s);

  // 3. The host's framebuffer: here an offscreen one; a window's would do.
  const cs::Viewport viewport{640, 360};
  std::unique_ptr<cs::OffscreenTarget> target;
  if (cs::Status s = cs::OffscreenTarget::create(viewport, &target); !s.ok()) return fail("framebuffer", s);

  // 4. The streamer (loader threads start here) and the renderer. The clip
  //    size and the coarse pyramid's level come from the plan of the first
  //    frame; the coarse pyramid is read and uploaded now, on this thread,
  //    so the very first frame has something correct to draw.
  cs::StreamerConfig config;
  config.ram_budget_bytes = uint64_t(64) << 20;
  cs::Streamer streamer(source, config);
  const cs::ClipmapPlan first = cs::planClipmap(geometry, viewport, orbitCamera(geometry, 0.0), config.planner);
  std::unique_ptr<cs::ClipmapRenderer> renderer;
  if (cs::Status s = cs::ClipmapRenderer::create(
          geometry, cs::RendererConfig{first.clip_tiles, first.pyramid_level, cs::Buffering::kSingle}, &renderer);
      !s)
    return fail("renderer", s);
  renderer->beginFrame();
  const uint32_t pyramid_failures = renderer->loadPyramid(
      [&](const cs::TileKey& key) -> std::shared_ptr<const std::vector<uint8_t>> {
        auto rgba = std::make_shared<std::vector<uint8_t>>();
        if (!source->fetch(key, rgba.get())) return nullptr;  // filled from its ancestor
        return rgba;
      });
  renderer->endUploads();

  // 5. The frame loop. The clock is the host's (seconds, never decreasing):
  //    a fixed 60 Hz step here, wall time in an interactive program.
  uint64_t frame_count = 0, tiles_uploaded = 0;
  auto drawFrame = [&](const cs::Camera& camera) {
    streamer.update(camera, viewport, double(frame_count++) / 60.0);  // plan, queue, cancel: no I/O
    const cs::FrameHandoff handoff = streamer.takeReady(16);  // at most 16 tiles per frame
    renderer->applyHandoff(handoff);  // uploads, residency, MaxTextureLOD; the handoff may go now
    tiles_uploaded += renderer->lastUploads().tiles;
    target->bind();
    cs::ClipmapRenderer::clearSky();  // or the host's own background
    renderer->draw(camera, viewport);
    glFlush();  // where a windowed host would swap buffers
  };
  for (unsigned long i = 0; i < frames; ++i) drawFrame(orbitCamera(geometry, double(i) / double(frames)));

  // 6. Before checking its picture, the host holds the last camera until
  //    every tile the view needs is on the GPU (settled()), for at most
  //    10 s, so the check does not depend on how fast the loader threads were.
  const cs::Camera last = orbitCamera(geometry, double(frames - 1) / double(frames));
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!streamer.settled() && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(2));  // a display's frame interval, shortened
    drawFrame(last);
  }
  const bool settled = streamer.settled();

  // 7. The host checks its picture: most of it is ground, not sky.
  std::vector<uint8_t> rgba;
  target->readRgba(&rgba);
  size_t ground_px = 0;
  for (size_t p = 0; p + 4 <= rgba.size(); p += 4)
    if (std::memcmp(&rgba[p], cs::renderer_config::kSkyRgba, 4) != 0) ++ground_px;

  // 8. Shut down: the streamer first (stops its threads; handed-off tiles
  //    stay valid, they are shared_ptr), then GL objects while the context
  //    is still current, the context last.
  streamer.shutdown();
  const cs::StreamerStats stats = streamer.stats();
  renderer.reset();
  target.reset();
  context.reset();

  const double ground_fraction = double(ground_px) / double(viewport.width_px * viewport.height_px);
  std::printf("source\t%s\nframes\t%llu\ntiles_uploaded\t%llu\nram_hits\t%llu\nram_misses\t%llu\n"
              "tile_failures\t%llu\nground_fraction\t%.3f\n",
              source->describe().c_str(), (unsigned long long)frame_count, (unsigned long long)tiles_uploaded,
              (unsigned long long)stats.total.ram_hits, (unsigned long long)stats.total.ram_misses,
              (unsigned long long)(stats.total.failures + pyramid_failures), ground_fraction);
  if (!settled || tiles_uploaded == 0 || ground_fraction < 0.5) {
    std::fprintf(stderr, "clipstream-embed: %s\n",
                 !settled ? "the view's tiles did not all arrive within 10 s"
                 : tiles_uploaded == 0 ? "no streamed tile reached the GPU"
                                       : "the last frame is mostly sky: the ground was not drawn");
    return 1;
  }
  return 0;
}
