// clipstream-view: interactive viewer. GLFW window, mouse look + WASD,
// wheel/shift for speed, O toggles the overlay, R records the flown path to
// JSON for clipstream-fly. Usage: docs/renderer.md.
#include <clipstream/cli/cli.h>
#include <clipstream/cli/sizes.h>
#include <clipstream/renderer/config.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/store/output_file.h>
#include <clipstream/streamer/flight_path.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <algorithm>
#include <chrono>
#include <optional>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <numbers>

using namespace clipstream;

namespace {

struct Input {
  double speed_texels_s = 200.0;
  bool overlay_toggled = false;
  bool record_toggled = false;
  bool dragging = false;
  double last_x = 0, last_y = 0;
  double d_heading = 0, d_pitch = 0;
};

Input* inputOf(GLFWwindow* w) { return static_cast<Input*>(glfwGetWindowUserPointer(w)); }

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Interactive clipmap viewer (GLFW window).", "clipstream-view"};
  std::string store_path, size = "1280x720", record_path = "recorded_path.json", elevation_path;
  double vertical_scale = 1.0;
  bool stretch_elevation = false;
  uint64_t procedural_px = 0, cache_mb = 512;
  uint32_t upload_tiles = renderer_config::kDefaultUploadTilesPerFrame, max_frames = 0;
  app.add_option("store", store_path, "Tile store file or http(s):// URL (omit with --procedural)");
  RemoteOptions remote;
  cli::addRemoteOptions(app, &remote);
  app.add_option("--procedural", procedural_px, "Procedural texture of this side instead")
      ->transform(cli::wholeInRange(1, int64_t(kMaxProceduralSidePx)));
  app.add_option("--size", size, "Window WIDTHxHEIGHT");
  app.add_option("--cache-mb", cache_mb, "Streamer RAM budget in MiB")
      ->transform(cli::wholeInRange(1, int64_t(1) << 30));
  app.add_option("--upload-tiles", upload_tiles, "GPU tile uploads per frame")
      ->transform(cli::wholeInRange(1, 1000000));
  std::string tile_format = "rgba8";
  app.add_option("--tile-format", tile_format,
                 "Colour tiles on the GPU: rgba8, or bc1 (transcoded by the loader threads)");
  app.add_option("--record-out", record_path, "Where R writes the recorded path");
  app.add_option("--frames", max_frames, "Exit after this many frames (0 = run until closed)")
      ->transform(cli::wholeInRange(0, UINT32_MAX));
  app.add_option("--elevation", elevation_path, "Elevation store under the texture: fly over terrain");
  app.add_option("--vertical-scale", vertical_scale, "Height exaggeration (with --elevation)")
      ->transform(cli::inRange(0.001, 1000.0));
  app.add_flag("--stretch-elevation", stretch_elevation,
               "Stretch the elevation store over the texture instead of placing it by georeference");
  std::string terrain_method = "clipmap";
  double terrain_error_px = renderer_config::kTerrainErrorPx;
  app.add_option("--terrain", terrain_method,
                 "Terrain geometry with --elevation: clipmap (default), quadtree, flat or full");
  app.add_option("--terrain-error", terrain_error_px,
                 "Quadtree: split a node while its projected error bound exceeds this many pixels")
      ->transform(cli::inRange(kMinTerrainErrorPx, kMaxTerrainErrorPx));
  app.footer("Exit codes: 0 success, 1 failure, 2 command-line mistake. docs/cli.md.");
  if (std::optional<int> code = cli::parse(app, argc, argv)) return *code;
  TerrainMethod method = TerrainMethod::kClipmap;
  if (Status s = terrainMethodFromName(terrain_method, &method); !s)
    return cli::usageError(app, "--terrain: " + s.message);
  if ((app.count("--terrain") || app.count("--terrain-error")) && elevation_path.empty())
    return cli::usageError(app, "--terrain and --terrain-error need --elevation");

  Viewport vp;
  if (Status s = cli::parseSize(size, &vp.width_px, &vp.height_px); !s) return cli::usageError(app, s.message);
  TileContent tile_content = TileContent::kRgba8;
  if (Status s = colourTileContentFromName(tile_format, &tile_content); !s)
    return cli::usageError(app, s.message);
  if (!store_path.empty() && procedural_px > 0)
    return cli::usageError(app, "give a STORE or --procedural SIDE, not both");
  {
    std::error_code ec;
    if (!store_path.empty() && !isStoreUrl(store_path) &&
        (sameFile(store_path, record_path) || std::filesystem::weakly_canonical(store_path, ec) ==
                                                   std::filesystem::weakly_canonical(record_path, ec)))
      return cli::usageError(app, "--record-out " + record_path + " is the store being viewed");
    OutputOptions record_options;
    record_options.existing = ExistingOutput::kReplaceRegular;
    if (Status s = checkOutputPath(record_path, record_options); !s) {
      cli::printError(app, "--record-out: " + s.toString());
      return cli::kExitFailure;
    }
  }
  cli::installSignalHandlers();
  std::shared_ptr<TileSource> source;
  if (procedural_px > 0) {
    ProceduralSpec spec;
    spec.width_px = spec.height_px = procedural_px;
    source = makeProceduralSource(spec);
  } else if (!store_path.empty()) {
    Status s;
    source = openStoreSource(store_path, remote, &s);
    if (!source) {
      cli::printError(app, s.toString());
      return 1;
    }
  }
  if (!source) {
    return cli::usageError(app, "give a STORE or --procedural SIDE");
  }
  if (tile_content == TileContent::kBc1) {
    Status s;
    source = makeBc1Source(source, &s);
    if (!source) {
      cli::printError(app, s.toString());
      return 1;
    }
  }
  const PyramidGeometry& g = source->geometry();
  std::optional<TerrainLayerConfig> terrain;
  if (!elevation_path.empty()) {
    TerrainLayerConfig layer;
    std::vector<std::string> notes;
    if (Status s = openTerrainLayer(procedural_px > 0 ? std::string() : store_path, g, elevation_path,
                                    vertical_scale, stretch_elevation,
                                    renderer_config::kTerrainRingCells, &layer, &notes, remote);
        !s) {
      cli::printError(app, s.toString());
      return 1;
    }
    for (const std::string& w : notes) cli::printError(app, "warning: " + w);
    layer.method = method;
    layer.error_px = terrain_error_px;
    terrain = std::move(layer);
  }

  if (!glfwInit()) {
    std::cerr << "clipstream-view: GLFW could not initialise (no display?)\n";
    return 1;
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_RESIZABLE, GLFW_FALSE);  // the clip size follows the viewport
  GLFWwindow* window = glfwCreateWindow(int(vp.width_px), int(vp.height_px), "clipstream-view",
                                        nullptr, nullptr);
  if (window == nullptr) {
    std::cerr << "clipstream-view: no OpenGL 4.5 core window\n";
    glfwTerminate();
    return 1;
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(1);
  Input input;
  glfwSetWindowUserPointer(window, &input);
  glfwSetKeyCallback(window, [](GLFWwindow* w, int key, int, int action, int) {
    if (action != GLFW_PRESS) return;
    if (key == GLFW_KEY_O) inputOf(w)->overlay_toggled = true;
    if (key == GLFW_KEY_R) inputOf(w)->record_toggled = true;
    if (key == GLFW_KEY_ESCAPE) glfwSetWindowShouldClose(w, GLFW_TRUE);
  });
  glfwSetScrollCallback(window, [](GLFWwindow* w, double, double dy) {
    Input* in = inputOf(w);
    in->speed_texels_s = std::clamp(in->speed_texels_s * std::pow(1.25, dy), 1.0, 1e9);
  });
  glfwSetMouseButtonCallback(window, [](GLFWwindow* w, int button, int action, int) {
    if (button != GLFW_MOUSE_BUTTON_LEFT) return;
    Input* in = inputOf(w);
    in->dragging = action == GLFW_PRESS;
    glfwGetCursorPos(w, &in->last_x, &in->last_y);
  });
  glfwSetCursorPosCallback(window, [](GLFWwindow* w, double x, double y) {
    Input* in = inputOf(w);
    if (in->dragging) {
      in->d_heading += (x - in->last_x) * 0.003;
      in->d_pitch -= (y - in->last_y) * 0.003;
    }
    in->last_x = x;
    in->last_y = y;
  });

  Camera camera;
  camera.position = {double(g.width_px) * 0.5, std::min<double>(std::max(g.width_px, g.height_px) * 0.2, 5000.0),
                     double(g.height_px) * 0.5};
  camera.pitch_rad = -0.6;
  if (terrain) {
    // Start above the highest ground; each frame then keeps above the ground.
    camera.position.y += terrain->source->elevationInfo().max_height * terrain->alignment.world_per_height;
  }
  input.speed_texels_s = camera.position.y;

  // The one frame loop's step, drawing into the window. The coarse pyramid
  // is loaded before any frame, so there is always something correct to draw.
  FlightConfig fc;
  fc.viewport = vp;
  fc.streamer.ram_budget_bytes = cache_mb << 20;
  fc.upload_tiles = upload_tiles;
  fc.offscreen = false;
  fc.terrain = terrain;
  {
    int fb_w = 0, fb_h = 0;
    glfwGetFramebufferSize(window, &fb_w, &fb_h);
    fc.framebuffer = {uint32_t(std::max(fb_w, 1)), uint32_t(std::max(fb_h, 1))};
  }
  std::unique_ptr<Flight> flight;
  if (Status s = Flight::create(source, fc, camera, &flight); !s) {
    cli::printError(app, s.toString());
    glfwDestroyWindow(window);
    glfwTerminate();
    return cli::kExitFailure;
  }
  FlightPath recording;
  bool recording_on = false;
  double last_key_s = -1.0;
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  double title_timer = 0.0, frame_ms_avg = 0.0;
  uint32_t frames = 0;
  while (!glfwWindowShouldClose(window) && (max_frames == 0 || frames < max_frames)) {
    glfwPollEvents();
    const auto now = std::chrono::steady_clock::now();
    const double dt = std::min(std::chrono::duration<double>(now - last).count(), 0.1);
    const double t = std::chrono::duration<double>(now - start).count();
    last = now;

    camera.heading_rad += input.d_heading;
    camera.pitch_rad = std::clamp(camera.pitch_rad + input.d_pitch, -1.55, 1.2);
    input.d_heading = input.d_pitch = 0;
    double speed = input.speed_texels_s;
    if (glfwGetKey(window, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS) speed *= 10.0;
    const glm::dvec3 fwd{std::sin(camera.heading_rad), 0.0, -std::cos(camera.heading_rad)};
    const glm::dvec3 right = camera.right();
    glm::dvec3 move{0.0};
    if (glfwGetKey(window, GLFW_KEY_W) == GLFW_PRESS) move += fwd;
    if (glfwGetKey(window, GLFW_KEY_S) == GLFW_PRESS) move -= fwd;
    if (glfwGetKey(window, GLFW_KEY_D) == GLFW_PRESS) move += right;
    if (glfwGetKey(window, GLFW_KEY_A) == GLFW_PRESS) move -= right;
    if (glfwGetKey(window, GLFW_KEY_E) == GLFW_PRESS) move.y += 1.0;
    if (glfwGetKey(window, GLFW_KEY_Q) == GLFW_PRESS) move.y -= 1.0;
    camera.position += move * (speed * dt);
    camera.position.y = std::max(camera.position.y, 1.0);
    if (double ground = 0.0; flight->groundHeight({camera.position.x, camera.position.z}, &ground)) {
      // Over terrain the camera never goes under the ground (nor closer
      // than the clearance, where the near plane would cut the slope).
      camera.position.y = std::max(camera.position.y, ground + renderer_config::kTerrainClearance);
    }

    if (input.overlay_toggled) {
      ClipmapRenderer& renderer = flight->renderer();
      renderer.setOverlay(renderer.overlay() == Overlay::kOff ? Overlay::kLevels : Overlay::kOff);
      input.overlay_toggled = false;
    }
    if (input.record_toggled) {
      input.record_toggled = false;
      recording_on = !recording_on;
      if (recording_on) {
        recording = FlightPath{};
        last_key_s = -1.0;
      } else {
        Status s = recording.save(record_path);
        cli::printError(app, s ? "recorded path written to " + record_path : s.toString());
      }
    }
    if (recording_on && (last_key_s < 0 || t - last_key_s >= 0.25)) {
      // Path time counts from the first keyframe, in real seconds.
      const double key_s = recording.keyframes.empty()
                               ? 0.0
                               : recording.keyframes.back().t_s + (t - last_key_s);
      recording.keyframes.push_back({key_s, camera.position, camera.heading_rad * 180.0 / std::numbers::pi,
                                     camera.pitch_rad * 180.0 / std::numbers::pi});
      last_key_s = t;
    }

    // Wall-clock time drives the streamer (an interactive flight).
    const FrameSample frame = flight->step(camera, t);
    frame_ms_avg = frame_ms_avg * 0.9 + frame.frame_ms * 0.1;
    glfwSwapBuffers(window);
    ++frames;

    title_timer += dt;
    if (title_timer > 0.25 || frames == 1) {
      title_timer = 0.0;
      const StreamerStats st = flight->streamer().stats();
      char title[256];
      std::snprintf(title, sizeof title,
                    "clipstream-view | %.1f ms | lod %u | queue %llu | RAM %.0f MiB | speed %.0f/s%s%s",
                    frame_ms_avg, st.max_texture_lod, (unsigned long long)st.queue_depth,
                    double(st.ram_bytes) / (1 << 20), speed,
                    flight->renderer().overlay() == Overlay::kOff ? "" : " | overlay",
                    recording_on ? " | REC" : "");
      glfwSetWindowTitle(window, title);
    }
  }
  int code = cli::kExitOk;
  if (recording_on) {
    Status s = recording.save(record_path);
    cli::printError(app, s ? "recorded path written to " + record_path : s.toString());
    if (!s) code = cli::kExitFailure;
  }
  flight->finish();
  flight.reset();  // GL objects go before the context
  glfwDestroyWindow(window);
  glfwTerminate();
  return cli::finish(app, code);
}
