// clipstream-fly: headless flythrough with per-frame statistics.
// Usage and output formats: docs/renderer.md; exit codes: docs/cli.md.
#include <clipstream/cli/cli.h>
#include <clipstream/cli/progress.h>
#include <clipstream/cli/renderer_options.h>
#include <clipstream/cli/sizes.h>
#include <clipstream/eval/fly.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <iostream>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <system_error>

namespace {

// The command line as given, before it is checked: each option's variable,
// holding its default until parse(). Options that map one to one onto
// FlyOptions are bound to `o` directly.
struct Args {
  clipstream::FlyOptions o;
  std::string size = "1280x720", buffering = clipstream::bufferingName(o.buffering);
  uint64_t cache_mb = o.streamer.ram_budget_bytes >> 20;
  uint32_t save_every = 0;
  CLI::Option* save_frames = nullptr;
  std::string texture_memory = "auto";
  std::string tile_format = clipstream::tileContentName(o.tile_format), reference_tile_format;
  std::string resize;
  bool no_throttle = false, no_prefetch = false, no_frustum = false, no_terrain_bounds = false;
  bool no_over_fetch = false;
  std::string plan_scope = "sampled";
  std::string terrain_method = clipstream::terrainMethodName(o.terrain_method);
  std::string terrain_lighting = clipstream::terrainLightingName(o.terrain_lighting), reference_lighting;
  std::string look_at;
};

// Declares every option and the footer, in the order --help lists them,
// each bound to its variable in *args (which must outlive the parse).
// Long: one declaration per option in --help order, a flat list to read down.
void addOptions(CLI::App& app, Args* args) {
  using namespace clipstream;
  Args& a = *args;
  FlyOptions& o = a.o;
  StreamerConfig& streamer = o.streamer;
  const auto frames = cli::wholeInRange(1, kMaxFlyFrames);
  const auto delay_ms = cli::inRange(0.0, kMaxFlyDelayMs);
  app.add_option("store", o.store_path, "Tile store file or http(s):// URL (omit with --procedural)");
  app.add_option("--path", o.path,
                 "Built-in path (pass, dive, orbit, teleport, zoom, valley; over terrain also summit, the orbit "
                 "around the highest point, and rough, the orbit around the roughest area) or JSON file");
  app.add_flag("--path-in-map-units", o.path_in_map_units,
               "The --path JSON file's x and z are the colour store's map coordinates and its heights are "
               "in the elevation's unit (docs/cli.md, \"Cameras in map coordinates\")");
  app.add_option("--look-at", a.look_at,
                 "X,Y[,HEIGHT] or lonlat:LON,LAT[,HEIGHT]: instead of --path, hold the camera that looks at "
                 "this point, in the colour store's map coordinates (level-0 texels without a georeference) "
                 "or in degrees, from the south, 30 degrees down; HEIGHT in the elevation's unit (default: "
                 "the ground's)");
  app.add_option("--frames", o.frames, "Frames to render (default: the whole path at --speed)")
      ->transform(frames);
  app.add_option("--size", a.size, "Viewport WIDTHxHEIGHT");
  app.add_option("--speed", o.speed, "Path seconds per simulated second")
      ->transform(cli::inRange(0.001, kMaxFlySpeed));
  app.add_option("--cache-mb", a.cache_mb, "Streamer RAM budget in MiB")
      ->transform(cli::wholeInRange(1, int64_t(1) << 30));
  app.add_option("--upload-tiles", o.upload_tiles, "GPU tile uploads per frame")
      ->transform(cli::wholeInRange(1, 1000000));
  app.add_option("--io-threads", streamer.io_threads,
                 "Loader threads (0 = cores; for a URL store, one per HTTP connection)")
      ->transform(cli::wholeInRange(0, kMaxIoThreads));
  cli::addRemoteOptions(app, &o.remote);
  app.add_option("--out", o.out_dir,
                 "Output directory (holds one run: an earlier run's frames and statistics there are "
                 "removed first)");
  a.save_frames =
      app.add_option("--save-frames", a.save_every,
                     "Save every Nth frame (and the last) as PNG; 0 = none (default: five frames, "
                     "the first, one each quarter of the run and the last)")
          ->transform(cli::wholeInRange(0, kMaxFlyFrames));
  app.add_option("--procedural", o.procedural_px, "Use a procedural texture of this side (texels)")
      ->transform(cli::wholeInRange(1, int64_t(kMaxProceduralSidePx)));
  app.add_option("--buffering", a.buffering, "single, double-upload, double-copy or staged");
  app.add_option("--texture-memory", a.texture_memory,
                 "Where colour tiles live on the GPU: stack (every level's whole window), paged (a "
                 "fixed pool of pages holding the tiles the frames sample; docs/renderer.md), or auto: "
                 "paged, but stack with --elevation or double buffering, which paged does not draw yet");
  app.add_option("--pool-mb", o.pool_mb,
                 "The page pool's size with --texture-memory paged (default: 5.5 pages of 128^2 per 128^2 "
                 "of the viewport, 59 MiB of RGBA8 at 1920x1080)")
      ->transform(cli::wholeInRange(1, 65536));
  app.add_option("--tile-format", a.tile_format,
                 "Colour tiles on the GPU: rgba8, or bc1 (transcoded by the loader threads, an eighth of "
                 "the video memory)");
  app.add_option("--reference-tile-format", a.reference_tile_format,
                 "Tiles of the ideal reference (with --reference): rgba8 or bc1; default: --tile-format");
  app.add_flag("--overlay", o.overlay, "Tint by level, mark missing/throttled tiles");
  app.add_flag("--reference", o.reference,
               "Compare each frame with the ideal reference (PSNR, max abs error; docs/accuracy.md)");
  app.add_flag("--fewest-triangles", o.fewest_triangles,
               "Over terrain, with --reference: also count the fewest triangles that model each judged "
               "frame within its own p95 geometric error (docs/terrain.md; a dozen position passes a judged frame)");
  app.add_option("--reference-every", o.reference_every, "Compare every Nth frame (with --reference)")
      ->transform(frames);
  app.add_flag("--no-over-fetch", a.no_over_fetch,
               "With --reference: skip the over-fetch ratio (which traces every pixel of every frame on the "
               "CPU, judged or not: most of a judged run's time at 3840x2160); it reads 0");
  app.add_option("--ground-truth-every", o.ground_truth_every,
                 "Also compare the reference with the CPU ground truth every Nth frame (0 = never)")
      ->transform(cli::wholeInRange(0, kMaxFlyFrames));
  app.add_flag("--no-throttle", a.no_throttle, "Never lower MaxTextureLOD");
  app.add_flag("--no-prefetch", a.no_prefetch, "No velocity-predictive prefetch");
  app.add_flag("--no-frustum-priority", a.no_frustum, "Load visible tiles no earlier than hidden ones");
  app.add_option("--plan-scope", a.plan_scope,
                 "What of each clip level is loaded: sampled (the tiles the frames sample and their "
                 "ancestors, the default) or window (the whole clip window, the classic clipmap); over "
                 "terrain always the window")
      ->check(CLI::IsMember({"sampled", "window"}));
  app.add_flag("--no-terrain-bounds", a.no_terrain_bounds,
               "Over terrain, plan against the plane under the camera and the resident heights' relief "
               "instead of the elevation store's per-tile height bounds");
  app.add_flag("--path-hint", o.path_hint,
               "Tell the streamer the scripted path: eviction keeps what the path comes back to, and "
               "prefetch follows the path (jumps included). Off: the streamer sees the camera only, as in "
               "an interactive flight");
  CLI::Option* deterministic = app.add_flag(
      "--deterministic", streamer.deterministic_io.enabled,
      "Repeatable run for benchmarks: tile reads land on a simulated I/O clock (--io-reads-per-frame, "
      "--io-latency-frames), so the frames never depend on thread timing; frames wait for the reads "
      "due. Off: reads land as fast as the loaders go (an application's behaviour)");
  app.add_option("--io-reads-per-frame", streamer.deterministic_io.reads_per_frame,
                 "With --deterministic: tile reads issued per frame (default " +
                     std::to_string(kDefaultIoReadsPerFrame) + ")")
      ->transform(cli::wholeInRange(1, kMaxFlyIoReadsPerFrame))
      ->needs(deterministic);
  app.add_option("--io-latency-frames", streamer.deterministic_io.latency_frames,
                 "With --deterministic: frames from a read's request to its tile in RAM (default " +
                     std::to_string(kDefaultIoLatencyFrames) + ")")
      ->transform(cli::wholeInRange(1, kMaxFlyIoLatencyFrames))
      ->needs(deterministic);
  app.add_option("--fault-latency-ms", o.fault_latency_ms, "Added latency per tile read (ms)")
      ->transform(delay_ms);
  app.add_option("--fault-corrupt", o.fault_corrupt_fraction, "Fraction of tiles failing as corrupt")
      ->transform(cli::inRange(0.0, 1.0));
  app.add_option("--max-failed-reads", o.max_failed_reads_percent,
                 "Fail the run (exit 1, after writing its statistics) when more than this per cent of "
                 "the tile reads failed, or reads failed and none loaded")
      ->transform(cli::inRange(0.0, 100.0));
  app.add_option("--resize-at", a.resize, "Resize the viewport before frame F: F:WxH");
  app.add_option("--rest-frames", o.rest_frames, "Then hold the last camera for N more frames")
      ->transform(cli::wholeInRange(0, kMaxFlyFrames));
  app.add_option("--warmup-frames", o.warmup_frames,
                 "First hold the first camera for N frames that are not recorded (start-up excluded)")
      ->transform(cli::wholeInRange(0, kMaxFlyFrames));
  app.add_option("--rest-frame-ms", o.rest_frame_ms, "Rest frames last at least this wall time (ms)")
      ->transform(delay_ms);
  app.add_flag("--loop", o.loop, "Wrap path time instead of stopping at the path's end");
  app.add_option("--teleport-frames", o.teleport_frames, "Frames between jumps of the teleport path")
      ->transform(frames);
  app.add_option("--trace", streamer.trace_path, "Record the streamer's request trace (clipstream-trace)");
  app.add_option("--elevation", o.elevation_path,
                 "Elevation store (clipstream-tile DEM.tif) under the colour layer: fly over terrain");
  app.add_option("--vertical-scale", o.vertical_scale, "Height exaggeration (with --elevation)")
      ->transform(cli::inRange(0.001, kMaxVerticalScale));
  app.add_flag("--stretch-elevation", o.stretch_elevation,
               "Stretch the elevation store over the colour image instead of placing it by georeference");
  app.add_option("--terrain-ring", o.terrain_ring, "Cells per geometry clipmap ring side (power of two, 16..1024)")
      ->transform(cli::wholeInRange(16, 1024));
  app.add_option("--terrain", a.terrain_method,
                 "Terrain geometry with --elevation: clipmap (default), quadtree; for comparison flat "
                 "(the plane) or full (the full-resolution mesh)");
  app.add_option("--terrain-error", o.terrain_error_px,
                 "Quadtree: split a node while its projected error bound exceeds this many pixels")
      ->transform(cli::inRange(kMinTerrainErrorPx, kMaxTerrainErrorPx));
  app.add_option("--terrain-triangle-budget", o.terrain_triangle_budget,
                 "Quadtree: the most triangles a frame draws, 0 for none (default " +
                     std::to_string(renderer_config::kTerrainTriangleBudget) +
                     "); over it the frame's error bound rises, the largest errors split first")
      ->transform(cli::wholeInRange(0, int64_t(1) << 32));
  app.add_option("--terrain-lighting", a.terrain_lighting,
                 "Terrain lit by vertex (default: the vertices' normals) or by pixel (the normal of the "
                 "finest resident heights under each pixel)");
  app.add_flag("--terrain-detail", o.terrain_detail,
               "Detail textures where the colour is magnified, by material rules on slope and height "
               "(docs/terrain.md, \"Detail textures\")");
  app.add_option("--synthesize-relief", o.synthesized_levels,
                 "Synthesized relief below the DEM's resolution: this many levels, each 2x finer, of "
                 "noise scaled by the DEM's roughness (docs/terrain.md, \"Synthesized relief\")")
      ->transform(cli::wholeInRange(1, kMaxSynthesizedLevels));
  app.add_option("--reference-lighting", a.reference_lighting,
                 "The terrain reference's lighting (with --reference): vertex or pixel; default: "
                 "--terrain-lighting");
  app.footer(
      "Exit codes: 0 success, 1 failure (store, GL context, an output that cannot be written,\n"
      "tile reads failed past --max-failed-reads; nothing half-written is left), 2 command-line\n"
      "mistake, killed by INT/TERM/HUP after removing its temporaries (shell status 128+N).\n"
      "docs/cli.md.");
  app.footer(
      "Exit codes: 0 success, 1 failure (store, GL context, an output that cannot be written,\n"
      "tile reads failed past --max-failed-reads; nothing half-written is left), 2 command-line\n"
      "mistake, killed by INT/TERM/HUP after removing its temporaries (shell status 128+N).\n"
      "docs/cli.md.");
}

// Checks what the options alone cannot and completes a.o from the parsed
// command line. Returns the usage error to report, or nothing when the
// command line is whole.
std::optional<std::string> toFlyOptions(const CLI::App& app, Args& a) {
  using namespace clipstream;
  FlyOptions& o = a.o;
  StreamerConfig& streamer = o.streamer;
  if (Status s = cli::parseTerrainMethod(a.terrain_method, &o.terrain_method); !s)
    return "--terrain: " + s.message;
  if ((app.count("--terrain") || app.count("--terrain-error") || app.count("--terrain-triangle-budget")) &&
      o.elevation_path.empty())
    return "--terrain, --terrain-error and --terrain-triangle-budget need --elevation";
  if (Status s = cli::parseTerrainLighting(a.terrain_lighting, &o.terrain_lighting); !s)
    return "--terrain-lighting: " + s.message;
  if (app.count("--terrain-lighting") && o.elevation_path.empty()) return "--terrain-lighting needs --elevation";
  if (o.terrain_detail && o.elevation_path.empty()) return "--terrain-detail needs --elevation";
  if (app.count("--synthesize-relief") && o.elevation_path.empty()) return "--synthesize-relief needs --elevation";
  if (!a.look_at.empty()) {
    LookAt look;
    if (Status s = cli::parseLookAt(a.look_at, &look); !s) return "--look-at: " + s.message;
    if (app.count("--path")) return "give --path or --look-at, not both";
    if (o.path_in_map_units) return "--path-in-map-units is for a --path file, not --look-at";
    o.look_at = look;
  }
  if (!a.reference_lighting.empty()) {
    TerrainLighting reference = TerrainLighting::kVertex;
    if (Status s = cli::parseTerrainLighting(a.reference_lighting, &reference); !s)
      return "--reference-lighting: " + s.message;
    if (o.elevation_path.empty() || !o.reference) return "--reference-lighting needs --elevation and --reference";
    o.reference_lighting = reference;
  }

  if (o.store_path.empty() && o.procedural_px == 0)
    return "give a STORE or --procedural SIDE";
  if (!o.store_path.empty() && o.procedural_px > 0)
    return "give a STORE or --procedural SIDE, not both";
  Status s = cli::parseSize(a.size, &o.viewport.width_px, &o.viewport.height_px);
  if (s) s = cli::parseBuffering(a.buffering, &o.buffering);
  if (s)
    s = cli::parseTextureMemory(a.texture_memory, !o.elevation_path.empty(), o.buffering, app.count("--pool-mb") > 0,
                                &o.texture_memory);
  if (s) s = cli::parseTileFormat(a.tile_format, &o.tile_format);
  if (s && !a.reference_tile_format.empty()) {
    TileContent reference = TileContent::kRgba8;
    s = cli::parseTileFormat(a.reference_tile_format, &reference);
    o.reference_tile_format = reference;
  }
  if (s && !a.resize.empty())
    s = cli::parseResize(a.resize, kMaxFlyFrames, &o.resize_at_frame, &o.resize_to.width_px,
                         &o.resize_to.height_px);
  if (!s) return s.message;
  streamer.ram_budget_bytes = a.cache_mb << 20;
  streamer.throttle = !a.no_throttle;
  streamer.prefetch = !a.no_prefetch;
  streamer.frustum_priority = !a.no_frustum;
  streamer.planner.scope = a.plan_scope == "window" ? PlanScope::kWindow : PlanScope::kSampled;
  streamer.terrain_bounds = !a.no_terrain_bounds;
  o.over_fetch = !a.no_over_fetch;

  if (a.save_frames->count() > 0) o.save_every = a.save_every;
  return std::nullopt;
}

}  // namespace

// The program in its steps: declare and parse the options, turn them into
// the flight's options, fly with signals caught, then report failure.
int main(int argc, char** argv) {
  using namespace clipstream;
  CLI::App app{"Headless clipmap flythrough: renders a flight path over a tile store and "
               "writes per-frame statistics (CSV, JSON) and PNG frames.",
               "clipstream-fly"};
  Args args;
  addOptions(app, &args);
  if (std::optional<int> code = cli::parse(app, argc, argv)) return *code;
  if (std::optional<std::string> problem = toFlyOptions(app, args)) return cli::usageError(app, *problem);
  FlyOptions& o = args.o;
  Status s;
  // A progress line on a terminal (CLIPSTREAM_PROGRESS=0/1 overrides),
  // finished before the summary table is printed.
  std::unique_ptr<cli::ProgressBar> bar;
  const bool progress = !o.quiet && cli::progressEnabledByDefault();
  o.on_progress = [&](uint32_t done, uint32_t total) {
    if (!progress) return;
    if (!bar) bar = std::make_unique<cli::ProgressBar>("flying", total, true, "frames");
    bar->update(done);
    if (done == total) bar->finish();
  };

  cli::installSignalHandlers();
  try {
    s = runFly(o, std::cout, &std::cerr);
  } catch (const std::bad_alloc&) {
    s = Status::error(ErrorCode::kOutOfMemory, "out of memory");  // temporaries removed while unwinding
  } catch (const std::system_error& e) {
    s = Status::error(ErrorCode::kIo, std::string("cannot start a thread: ") + e.what());
  }
  if (bar) bar->finish();  // before any message
  if (!s) {
    cli::printError(app, s.toString());
    return cli::finish(app, cli::kExitFailure);
  }
  return cli::finish(app, cli::kExitOk);
}
