// clipstream-view: interactive viewer. GLFW window, mouse look + WASD,
// wheel/shift for speed, the statistics on screen, keys for the overlay and
// its legend, recording the flown path to JSON for clipstream-fly, going
// home and screenshots (kKeys below). Usage: docs/renderer.md.
#include <clipstream/store/cog.h>
#include <clipstream/cli/cli.h>
#include <clipstream/cli/renderer_options.h>
#include <clipstream/cli/sizes.h>
#include <clipstream/renderer/config.h>
#include <clipstream/renderer/flight.h>
#include <clipstream/renderer/hud.h>
#include <clipstream/renderer/renderer.h>
#include <clipstream/util/output_file.h>
#include <clipstream/streamer/flight_path.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

// PNG encoding of screenshots (stb, header-only: its implementation here).
#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#pragma GCC diagnostic ignored "-Wshadow"
#endif
#define STB_IMAGE_WRITE_IMPLEMENTATION
#define STB_IMAGE_WRITE_STATIC
#include <stb/stb_image_write.h>
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif

#include <algorithm>
#include <chrono>
#include <optional>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <numbers>
#include <sstream>

using namespace clipstream;

namespace {

// The keys, in --help and on screen (F1) alike.
constexpr const char* kKeys =
    "W A S D      move (Shift: 10x faster)\n"
    "Q E          down, up\n"
    "drag         look around (left mouse button)\n"
    "wheel        slower, faster\n"
    "H, Home      back to the starting view\n"
    "O            overlay: clipmap levels, missing tiles, throttling\n"
    "L            terrain lit by vertex or by pixel (with --elevation)\n"
    "T            terrain detail textures, on and off (with --elevation)\n"
    "I            statistics on screen, on and off\n"
    "P, F12       screenshot (PNG in --screenshot-dir; Shift: with this text)\n"
    "R            record the flown path (again: write --record-out)\n"
    "F1, ?        this help\n"
    "Esc          quit";

// Speed: this fraction of the height above the ground per second (the
// ground seems to move at the same pace at any height), at most a tenth of
// the scene's larger side per second; the wheel scales the fraction.
constexpr double kDefaultSpeedPerHeight = 0.5;
constexpr double kMinSpeedPerHeight = 0.01, kMaxSpeedPerHeight = 50.0;
constexpr double kMaxSceneFractionPerSecond = 0.1;
// The camera stays within this many scene sides around the scene.
constexpr double kBoundsMargin = 0.5;

struct Input {
  double speed_per_height = kDefaultSpeedPerHeight;
  bool overlay_toggled = false;
  bool lighting_toggled = false;
  bool detail_toggled = false;
  bool record_toggled = false;
  bool home = false;
  bool screenshot = false;
  bool screenshot_hud = false;  // with the HUD drawn over the frame
  bool help_toggled = false;
  bool stats_toggled = false;
  bool dragging = false;
  double last_x = 0, last_y = 0;
  double d_heading = 0, d_pitch = 0;
};

Input* inputOf(GLFWwindow* w) { return static_cast<Input*>(glfwGetWindowUserPointer(w)); }

// Writes the window's current back buffer to the first free
// DIR/clipstream-view-NNN.png, never replacing a file. The path, or a Status.
Status saveScreenshot(const std::string& dir, uint32_t width_px, uint32_t height_px, std::string* path) {
  std::vector<uint8_t> rgba;
  readWindowPixels(width_px, height_px, &rgba);
  for (uint8_t* a = rgba.data() + 3; a < rgba.data() + rgba.size(); a += 4) *a = 255;  // opaque
  std::string png;
  const auto append = [](void* context, void* data, int size) {
    static_cast<std::string*>(context)->append(static_cast<const char*>(data), size_t(size));
  };
  if (!stbi_write_png_to_func(append, &png, int(width_px), int(height_px), 4, rgba.data(), int(width_px * 4)))
    return Status::error(ErrorCode::kIo, "screenshot: PNG encoding failed");
  OutputOptions options;
  options.existing = ExistingOutput::kRefuse;
  options.fsync = false;
  for (int n = 1; n < 100000; ++n) {
    char name[64];
    std::snprintf(name, sizeof name, "clipstream-view-%03d.png", n);
    *path = (std::filesystem::path(dir) / name).string();
    std::error_code ec;
    if (std::filesystem::symlink_status(*path, ec).type() != std::filesystem::file_type::not_found) continue;
    Status s = writeOutputFile(*path, png, options);
    if (s.code != ErrorCode::kAlreadyExists) return s;  // written, or a real failure
  }
  return Status::error(ErrorCode::kAlreadyExists, "screenshot: no free name left in " + dir);
}

HudColour levelColour(uint32_t level) {
  // levelTint() of renderer/shaders/ground_clipmap.frag, as bytes.
  static constexpr HudColour k[8] = {{255, 51, 51, 255},  {255, 153, 26, 255}, {255, 255, 51, 255},
                                     {77, 255, 77, 255},  {51, 255, 255, 255}, {77, 128, 255, 255},
                                     {179, 77, 255, 255}, {255, 102, 204, 255}};
  return k[level & 7];
}

// Lines of text on a dark translucent panel at (x, y); the panel's height.
float panel(Hud& hud, float x, float y, const std::string& text, float scale) {
  int lines = 1;
  for (char c : text) lines += c == '\n';
  const float pad = 4.0f * scale, height = float(lines) * Hud::kLinePx * scale + 2 * pad;
  hud.box(x, y, Hud::textWidth(text, scale) + 2 * pad, height, {0, 0, 0, 160});
  hud.text(x + pad, y + pad, text, {255, 255, 255, 255}, scale);
  return height;
}

// kKeys as two columns (the glyphs are not all of one width, so the
// spaces that align it in --help do not on screen), on a panel at (x, y).
void keysPanel(Hud& hud, float x, float y, float scale) {
  constexpr size_t kKeyColumn = 13;  // where kKeys' descriptions start
  std::vector<std::pair<std::string, std::string>> rows{{"Keys", ""}};
  std::istringstream lines(kKeys);
  for (std::string line; std::getline(lines, line);)
    rows.push_back({line.substr(0, line.find_last_not_of(' ', kKeyColumn - 1) + 1), line.substr(kKeyColumn)});
  float key_width = 0, text_width = 0;
  for (const auto& [key, text] : rows) {
    key_width = std::max(key_width, Hud::textWidth(key, scale));
    text_width = std::max(text_width, Hud::textWidth(text, scale));
  }
  const float pad = 4.0f * scale, gap = 3 * pad, row = Hud::kLinePx * scale;
  hud.box(x, y, key_width + gap + text_width + 2 * pad, float(rows.size()) * row + 2 * pad, {0, 0, 0, 160});
  for (const auto& [key, text] : rows) {
    hud.text(x + pad, y + pad, key, {255, 255, 160, 255}, scale);
    hud.text(x + pad + key_width + gap, y + pad, text, {255, 255, 255, 255}, scale);
    y += row;
  }
}

// The overlay's legend (what O tints and stripes mean), bottom left.
void legend(Hud& hud, float x, float bottom, uint32_t levels, bool terrain, float scale) {
  const float row = Hud::kLinePx * scale, swatch = row * 0.8f, pad = 4.0f * scale;
  std::vector<std::pair<HudColour, std::string>> rows;
  for (uint32_t l = 0; l < std::min(levels, 8u); ++l)
    rows.push_back({levelColour(l), "level " + std::to_string(l) + (l + 8 < levels ? " (and " + std::to_string(l + 8) + ")" : "") +
                                        (l == 0 ? ": the finest" : "")});
  rows.push_back({{255, 0, 0, 255}, "red stripes: finer level wanted, not loaded yet"});
  rows.push_back({{0, 0, 255, 255}, "blue stripes: finest level lowered (MaxTextureLOD)"});
  rows.push_back({{77, 77, 77, 255}, "dark lines: tile edges"});
  if (terrain) rows.push_back({{255, 0, 255, 255}, "magenta: terrain transition bands"});
  float width = 0;
  for (const auto& r : rows) width = std::max(width, Hud::textWidth(r.second, scale));
  const float height = float(rows.size()) * row + 2 * pad;
  float y = bottom - height;
  hud.box(x, y, width + swatch + 3 * pad, height, {0, 0, 0, 160});
  y += pad;
  for (const auto& [colour, label] : rows) {
    hud.box(x + pad, y + (row - swatch) * 0.5f, swatch, swatch, colour);
    hud.text(x + 2 * pad + swatch, y, label, {255, 255, 255, 255}, scale);
    y += row;
  }
}

// The command line, as parsed.
struct Args {
  std::string store_path, size = "1280x720", record_path = "recorded_path.json", elevation_path;
  double vertical_scale = 1.0;
  bool stretch_elevation = false;
  uint64_t procedural_px = 0, cache_mb = 512;
  uint32_t upload_tiles = renderer_config::kDefaultUploadTilesPerFrame, max_frames = 0;
  RemoteOptions remote;
  std::string tile_format = "rgba8";
  std::string texture_memory = "auto";
  uint64_t pool_mb = 0;
  std::string screenshot_dir = ".";
  std::string terrain_method = "clipmap";
  std::string look_at;
  double terrain_error_px = renderer_config::kTerrainErrorPx;
  uint64_t terrain_triangle_budget = renderer_config::kTerrainTriangleBudget;
  std::string terrain_lighting = "vertex";
  bool terrain_detail = false;
  uint32_t synthesized_levels = 0;
};

// What the checked options chose.
struct Choices {
  Viewport vp;
  std::optional<LookAt> look_at;
  TerrainMethod method = TerrainMethod::kClipmap;
  TerrainLighting lighting = TerrainLighting::kVertex;
  TileContent tile_content = TileContent::kRgba8;
  TextureMemory memory = TextureMemory::kStack;
};

void addOptions(CLI::App& app, Args* a) {
  app.add_option("store", a->store_path, "Tile store file or http(s):// URL (omit with --procedural)");
  cli::addRemoteOptions(app, &a->remote);
  app.add_option("--procedural", a->procedural_px, "Procedural texture of this side instead")
      ->transform(cli::wholeInRange(1, int64_t(kMaxProceduralSidePx)));
  app.add_option("--size", a->size, "Window WIDTHxHEIGHT");
  app.add_option("--cache-mb", a->cache_mb, "Streamer RAM budget in MiB")
      ->transform(cli::wholeInRange(1, int64_t(1) << 30));
  app.add_option("--upload-tiles", a->upload_tiles, "GPU tile uploads per frame")
      ->transform(cli::wholeInRange(1, 1000000));
  app.add_option("--tile-format", a->tile_format,
                 "Colour tiles on the GPU: rgba8, or bc1 (transcoded by the loader threads)");
  app.add_option("--texture-memory", a->texture_memory,
                 "Where colour tiles live on the GPU: stack (every level's whole window), paged (a "
                 "fixed pool of pages holding the tiles the frames sample), or auto: paged, but stack "
                 "with --elevation, which paged does not draw yet");
  app.add_option("--pool-mb", a->pool_mb,
                 "The page pool's size with --texture-memory paged (default: 5.5 pages of 128^2 per 128^2 "
                 "of the viewport, 59 MiB of RGBA8 at 1920x1080)")
      ->transform(cli::wholeInRange(1, 65536));
  app.add_option("--record-out", a->record_path, "Where R writes the recorded path");
  app.add_option("--screenshot-dir", a->screenshot_dir, "Where P writes clipstream-view-NNN.png");
  app.add_option("--frames", a->max_frames, "Exit after this many frames (0 = run until closed)")
      ->transform(cli::wholeInRange(0, UINT32_MAX));
  app.add_option("--elevation", a->elevation_path, "Elevation store under the texture: fly over terrain");
  app.add_option("--vertical-scale", a->vertical_scale, "Height exaggeration (with --elevation)")
      ->transform(cli::inRange(0.001, 1000.0));
  app.add_flag("--stretch-elevation", a->stretch_elevation,
               "Stretch the elevation store over the texture instead of placing it by georeference");
  app.add_option("--look-at", a->look_at,
                 "X,Y[,HEIGHT] or lonlat:LON,LAT[,HEIGHT]: start looking at this point, in the store's map "
                 "coordinates (level-0 texels without a georeference) or in degrees; HEIGHT in the "
                 "elevation's unit (default: the ground's)");
  app.add_option("--terrain", a->terrain_method,
                 "Terrain geometry with --elevation: clipmap (default), quadtree, flat or full");
  app.add_option("--terrain-error", a->terrain_error_px,
                 "Quadtree: split a node while its projected error bound exceeds this many pixels")
      ->transform(cli::inRange(kMinTerrainErrorPx, kMaxTerrainErrorPx));
  app.add_option("--terrain-triangle-budget", a->terrain_triangle_budget,
                 "Quadtree: the most triangles a frame draws, 0 for none (default " +
                     std::to_string(renderer_config::kTerrainTriangleBudget) +
                     "); over it the frame's error bound rises, the largest errors split first")
      ->transform(cli::wholeInRange(0, int64_t(1) << 32));
  app.add_option("--terrain-lighting", a->terrain_lighting,
                 "Terrain lit by vertex (default: the vertices' normals) or by pixel (the normal of the "
                 "finest resident heights under each pixel)");
  app.add_flag("--terrain-detail", a->terrain_detail,
               "Detail textures where the colour is magnified, by material rules on slope and height");
  app.add_option("--synthesize-relief", a->synthesized_levels,
                 "Synthesized relief below the DEM's resolution: this many levels, each 2x finer")
      ->transform(cli::wholeInRange(1, kMaxSynthesizedLevels));
  app.footer(std::string("Keys:\n") + kKeys +
             "\n\nExit codes: 0 success, 1 failure, 2 command-line mistake. docs/cli.md.");
}

// The options' checks, in the order they are reported; an exit code when
// one fails.
std::optional<int> checkArgs(CLI::App& app, const Args& a, Choices* c) {
  if (Status s = cli::parseTerrainMethod(a.terrain_method, &c->method); !s)
    return cli::usageError(app, "--terrain: " + s.message);
  if ((app.count("--terrain") || app.count("--terrain-error") || app.count("--terrain-triangle-budget")) &&
      a.elevation_path.empty())
    return cli::usageError(app, "--terrain, --terrain-error and --terrain-triangle-budget need --elevation");
  if (!a.look_at.empty()) {
    LookAt look;
    if (Status s = cli::parseLookAt(a.look_at, &look); !s) return cli::usageError(app, "--look-at: " + s.message);
    c->look_at = look;
  }
  if (Status s = cli::parseTerrainLighting(a.terrain_lighting, &c->lighting); !s)
    return cli::usageError(app, "--terrain-lighting: " + s.message);
  if (app.count("--terrain-lighting") && a.elevation_path.empty())
    return cli::usageError(app, "--terrain-lighting needs --elevation");
  if (a.terrain_detail && a.elevation_path.empty()) return cli::usageError(app, "--terrain-detail needs --elevation");
  if (app.count("--synthesize-relief") && a.elevation_path.empty())
    return cli::usageError(app, "--synthesize-relief needs --elevation");
  if (Status s = cli::parseSize(a.size, &c->vp.width_px, &c->vp.height_px); !s)
    return cli::usageError(app, s.message);
  if (Status s = cli::parseTileFormat(a.tile_format, &c->tile_content); !s)
    return cli::usageError(app, s.message);
  if (Status s = cli::parseTextureMemory(a.texture_memory, !a.elevation_path.empty(), kDefaultBuffering,
                                        app.count("--pool-mb") > 0, &c->memory);
      !s)
    return cli::usageError(app, s.message);
  if (!a.store_path.empty() && a.procedural_px > 0)
    return cli::usageError(app, "give a STORE or --procedural SIDE, not both");
  std::error_code ec;
  if (!a.store_path.empty() && !isStoreUrl(a.store_path) &&
      (sameFile(a.store_path, a.record_path) || std::filesystem::weakly_canonical(a.store_path, ec) ==
                                                    std::filesystem::weakly_canonical(a.record_path, ec)))
    return cli::usageError(app, "--record-out " + a.record_path + " is the store being viewed");
  OutputOptions record_options;
  record_options.existing = ExistingOutput::kReplaceRegular;
  if (Status s = checkOutputPath(a.record_path, record_options); !s) {
    cli::printError(app, "--record-out: " + s.toString());
    return cli::kExitFailure;
  }
  return std::nullopt;
}

// The colour source (a store, or the procedural texture; BC1 transcoded if
// asked) and the terrain under it; an exit code when one cannot be had.
std::optional<int> openScene(CLI::App& app, const Args& a, const Choices& c, std::shared_ptr<TileSource>* out,
                             std::optional<TerrainLayerConfig>* terrain) {
  std::shared_ptr<TileSource> source;
  if (a.procedural_px > 0) {
    ProceduralSpec spec;
    spec.width_px = spec.height_px = a.procedural_px;
    source = makeProceduralSource(spec);
  } else if (!a.store_path.empty()) {
    Status s;
    source = openStoreSource(a.store_path, a.remote, &s);
    if (!source) {
      cli::printError(app, s.toString());
      return 1;
    }
  }
  if (!source) {
    return cli::usageError(app, "give a STORE or --procedural SIDE");
  }
  if (c.tile_content == TileContent::kBc1) {
    Status s;
    source = makeBc1Source(source, &s);
    if (!source) {
      cli::printError(app, s.toString());
      return 1;
    }
  }
  if (!a.elevation_path.empty()) {
    TerrainLayerConfig layer;
    std::vector<std::string> notes;
    if (Status s = openTerrainLayer(a.procedural_px > 0 ? std::string() : a.store_path, source->geometry(),
                                    a.elevation_path, a.vertical_scale, a.stretch_elevation,
                                    renderer_config::kTerrainRingCells, &layer, &notes, a.remote);
        !s) {
      cli::printError(app, s.toString());
      return 1;
    }
    for (const std::string& w : notes) cli::printError(app, "warning: " + w);
    layer.method = c.method;
    layer.error_px = a.terrain_error_px;
    layer.triangle_budget = a.terrain_triangle_budget;
    layer.lighting = c.lighting;
    layer.detail_textures = a.terrain_detail;
    if (Status s = synthesizeRelief(a.synthesized_levels, &layer); !s) {
      cli::printError(app, s.toString());
      return 1;
    }
    *terrain = std::move(layer);
  }
  *out = std::move(source);
  return std::nullopt;
}

// The window with an OpenGL 4.5 core context, current, its input going to
// *input; null (with the reason on stderr, GLFW terminated) when none.
GLFWwindow* openWindow(const Viewport& vp, Input* input) {
  if (!glfwInit()) {
    std::cerr << "clipstream-view: GLFW could not initialise (no display?)\n";
    return nullptr;
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
    return nullptr;
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(1);
  glfwSetWindowUserPointer(window, input);
  glfwSetKeyCallback(window, [](GLFWwindow* w, int key, int, int action, int mods) {
    if (action != GLFW_PRESS) return;
    Input* in = inputOf(w);
    if (key == GLFW_KEY_O) in->overlay_toggled = true;
    if (key == GLFW_KEY_L) in->lighting_toggled = true;
    if (key == GLFW_KEY_T) in->detail_toggled = true;
    if (key == GLFW_KEY_R) in->record_toggled = true;
    if (key == GLFW_KEY_H || key == GLFW_KEY_HOME) in->home = true;
    if (key == GLFW_KEY_P || key == GLFW_KEY_F12) {
      in->screenshot = true;
      in->screenshot_hud = (mods & GLFW_MOD_SHIFT) != 0;
    }
    if (key == GLFW_KEY_I) in->stats_toggled = true;
    if (key == GLFW_KEY_F1 || (key == GLFW_KEY_SLASH && (mods & GLFW_MOD_SHIFT))) in->help_toggled = true;
    if (key == GLFW_KEY_ESCAPE) glfwSetWindowShouldClose(w, GLFW_TRUE);
  });
  glfwSetScrollCallback(window, [](GLFWwindow* w, double, double dy) {
    Input* in = inputOf(w);
    in->speed_per_height =
        std::clamp(in->speed_per_height * std::pow(1.25, dy), kMinSpeedPerHeight, kMaxSpeedPerHeight);
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
  return window;
}

// One frame's move of the camera by the keys and the mouse, at `speed`
// (texels a second, returned: Shift multiplies it), kept near the scene and
// above the ground.
// The store's georeference, read from its header or a COG's tags (none for
// --procedural).
Status storeGeoReference(const Args& a, GeoReference* out) {
  *out = GeoReference{};
  if (a.store_path.empty()) return okStatus();
  StoreInfo info;
  if (Status s = readRasterInfo(a.store_path, a.remote, &info); !s) return s;
  *out = info.geo;
  return okStatus();
}

double moveCamera(GLFWwindow* window, Input& input, const Flight& flight, const PyramidGeometry& g,
                  double scene_side, double dt, Camera* camera_io, double* ground_below) {
  Camera& camera = *camera_io;
  camera.heading_rad += input.d_heading;
  camera.pitch_rad = std::clamp(camera.pitch_rad + input.d_pitch, -1.55, 1.2);
  input.d_heading = input.d_pitch = 0;
  *ground_below = 0.0;
  const bool over_ground = flight.groundHeight({camera.position.x, camera.position.z}, ground_below);
  double speed = std::clamp(input.speed_per_height * std::max(camera.position.y - *ground_below, 1.0), 1.0,
                            kMaxSceneFractionPerSecond * scene_side);
  if (glfwGetKey(window, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS ||
      glfwGetKey(window, GLFW_KEY_RIGHT_SHIFT) == GLFW_PRESS)
    speed *= 10.0;
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
  // Within the scene's neighbourhood: a key held too long never loses it.
  camera.position.x = std::clamp(camera.position.x, -kBoundsMargin * scene_side,
                                 double(g.width_px) + kBoundsMargin * scene_side);
  camera.position.z = std::clamp(camera.position.z, -kBoundsMargin * scene_side,
                                 double(g.height_px) + kBoundsMargin * scene_side);
  camera.position.y = std::clamp(camera.position.y, 1.0, (over_ground ? *ground_below : 0.0) + 2.0 * scene_side);
  if (double ground = 0.0; flight.groundHeight({camera.position.x, camera.position.z}, &ground)) {
    // Over terrain the camera never goes under the ground (nor closer
    // than the clearance, where the near plane would cut the slope).
    camera.position.y = std::max(camera.position.y, ground + renderer_config::kTerrainClearance);
  }
  return speed;
}

}  // namespace

// Long: the frame loop (keys, recording, the step, screenshots, the HUD,
// the title) keeps its state from frame to frame in these locals; the rest
// of the program is in the functions above.
int main(int argc, char** argv) {
  CLI::App app{"Interactive clipmap viewer (GLFW window).", "clipstream-view"};
  Args args;
  addOptions(app, &args);
  if (std::optional<int> code = cli::parse(app, argc, argv)) return *code;
  Choices choices;
  if (std::optional<int> code = checkArgs(app, args, &choices)) return *code;
  const Viewport vp = choices.vp;
  cli::installSignalHandlers();
  std::shared_ptr<TileSource> source;
  std::optional<TerrainLayerConfig> terrain;
  if (std::optional<int> code = openScene(app, args, choices, &source, &terrain)) return *code;
  const PyramidGeometry& g = source->geometry();

  Input input;
  GLFWwindow* window = openWindow(vp, &input);
  if (window == nullptr) return 1;

  Camera camera;
  camera.position = {double(g.width_px) * 0.5, std::min<double>(std::max(g.width_px, g.height_px) * 0.2, 5000.0),
                     double(g.height_px) * 0.5};
  camera.pitch_rad = -0.6;
  if (terrain) {
    // Start above the highest ground; each frame then keeps above the ground.
    camera.position.y += terrain->source->elevationInfo().max_height * terrain->alignment.world_per_height;
  }
  if (choices.look_at) {
    GeoReference geo;
    Status s = storeGeoReference(args, &geo);
    double ground = 0.0;
    if (s) s = aimAtMapPoint(*choices.look_at, geo, g, terrain ? &*terrain : nullptr, &camera, &ground);
    if (!s) {
      std::cerr << "clipstream-view: --look-at: " << s.toString() << "\n";
      glfwTerminate();
      return 1;
    }
  }
  const Camera home = camera;
  const double scene_side = double(std::max(g.width_px, g.height_px));

  // The one frame loop's step, drawing into the window. The coarse pyramid
  // is loaded before any frame, so there is always something correct to draw.
  FlightConfig fc;
  fc.viewport = vp;
  fc.streamer.ram_budget_bytes = args.cache_mb << 20;
  fc.upload_tiles = args.upload_tiles;
  fc.texture_memory = choices.memory;
  fc.pool_bytes = args.pool_mb << 20;
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
  std::unique_ptr<Hud> hud;
  if (Status s = Hud::create(&hud); !s) {
    cli::printError(app, s.toString());
    flight.reset();
    glfwDestroyWindow(window);
    glfwTerminate();
    return cli::kExitFailure;
  }
  // Text a little larger on larger windows (2 at 1280 wide).
  const float hud_scale = std::max(1.0f, std::round(float(fc.framebuffer.width_px) / 640.0f));
  bool show_stats = true, show_help = false;
  int code = cli::kExitOk;
  FlightPath recording;
  bool recording_on = false;
  double last_key_s = -1.0;
  const auto start = std::chrono::steady_clock::now();
  auto last = start;
  double title_timer = 0.0, frame_ms_avg = 0.0;
  uint32_t frames = 0;
  while (!glfwWindowShouldClose(window) && (args.max_frames == 0 || frames < args.max_frames)) {
    glfwPollEvents();
    const auto now = std::chrono::steady_clock::now();
    const double dt = std::min(std::chrono::duration<double>(now - last).count(), 0.1);
    const double t = std::chrono::duration<double>(now - start).count();
    last = now;

    if (input.home) {
      input.home = false;
      camera = home;
      input.speed_per_height = kDefaultSpeedPerHeight;
    }
    double ground_below = 0.0;
    const double speed = moveCamera(window, input, *flight, g, scene_side, dt, &camera, &ground_below);

    if (input.overlay_toggled) {
      ClipmapRenderer& renderer = flight->renderer();
      renderer.setOverlay(renderer.overlay() == Overlay::kOff ? Overlay::kLevels : Overlay::kOff);
      input.overlay_toggled = false;
    }
    if (input.lighting_toggled) {
      input.lighting_toggled = false;
      if (TerrainRenderer* drawn = flight->terrain()) {
        const TerrainLighting next = drawn->config().lighting == TerrainLighting::kPixel ? TerrainLighting::kVertex
                                                                                         : TerrainLighting::kPixel;
        if (Status s = drawn->setLighting(next); !s) std::cerr << "clipstream-view: " << s.toString() << "\n";
      }
    }
    if (input.detail_toggled) {
      input.detail_toggled = false;
      if (TerrainRenderer* drawn = flight->terrain()) {
        if (Status s = drawn->setDetailTextures(!drawn->config().detail_textures); !s) {
          std::cerr << "clipstream-view: " << s.toString() << "\n";
        }
      }
    }
    if (input.record_toggled) {
      input.record_toggled = false;
      recording_on = !recording_on;
      if (recording_on) {
        recording = FlightPath{};
        last_key_s = -1.0;
      } else {
        Status s = recording.save(args.record_path);
        cli::printError(app, s ? "recorded path written to " + args.record_path : s.toString());
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
    const auto screenshot = [&] {
      input.screenshot = false;
      std::string path;
      Status s = saveScreenshot(args.screenshot_dir, fc.framebuffer.width_px, fc.framebuffer.height_px, &path);
      char where[160];
      std::snprintf(where, sizeof where, " (camera %.2f %.2f %.2f, heading %.2f, pitch %.2f degrees)",
                    camera.position.x, camera.position.y, camera.position.z,
                    camera.heading_rad * 180.0 / std::numbers::pi, camera.pitch_rad * 180.0 / std::numbers::pi);
      cli::printError(app, s ? "screenshot written to " + path + where : s.toString());
    };
    if (input.screenshot && !input.screenshot_hud) screenshot();  // the frame itself
    if (input.stats_toggled) show_stats = !show_stats;
    if (input.help_toggled) show_help = !show_help;
    input.stats_toggled = input.help_toggled = false;
    hud->clear();
    const float margin = 8.0f * hud_scale;
    float y = margin;
    if (show_stats) {
      const StreamerStats st = flight->streamer().stats();
      char text[512];
      std::snprintf(text, sizeof text,
                    "%.1f ms a frame   LOD %u (finest level drawn)   queue %llu   RAM %.0f MiB   GPU %.0f MiB\n"
                    "speed %.0f texels/s   height %.0f above the ground%s%s\nF1: keys",
                    frame_ms_avg, st.max_texture_lod, (unsigned long long)st.queue_depth,
                    double(st.ram_bytes) / (1 << 20),
                    double(flight->renderer().textureBytes().total()) / (1 << 20), speed,
                    camera.position.y - ground_below, recording_on ? "   REC" : "",
                    flight->renderer().overlay() == Overlay::kOff ? "" : "   overlay");
      y += panel(*hud, margin, y, text, hud_scale) + margin;
    }
    if (show_help) keysPanel(*hud, margin, y, hud_scale);
    if (flight->renderer().overlay() != Overlay::kOff)
      legend(*hud, margin, float(fc.framebuffer.height_px) - margin, g.levelCount(), terrain.has_value(),
             hud_scale);
    hud->draw(fc.framebuffer.width_px, fc.framebuffer.height_px);
    if (input.screenshot) screenshot();  // Shift: as the window shows it
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
  if (recording_on) {
    Status s = recording.save(args.record_path);
    cli::printError(app, s ? "recorded path written to " + args.record_path : s.toString());
    if (!s) code = cli::kExitFailure;
  }
  flight->finish();
  hud.reset();
  flight.reset();  // GL objects go before the context
  glfwDestroyWindow(window);
  glfwTerminate();
  return cli::finish(app, code);
}
