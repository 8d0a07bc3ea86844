// clipstream-fly's run: options, outputs and reports around runFlight(). See
// fly.h and docs/renderer.md.
#include <clipstream/eval/fly.h>

#include <clipstream/streamer/flight_path.h>
#include <clipstream/eval/flight_run.h>
#include <clipstream/eval/frame_writer.h>
#include <clipstream/eval/report.h>
#include <clipstream/renderer/config.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/util/output_file.h>
#include <clipstream/store/cog.h>
#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/alignment.h>
#include <clipstream/streamer/tile_source.h>
#include <clipstream/streamer/testing/faulty_source.h>

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <ostream>

#include <unistd.h>

namespace clipstream {
namespace {

// The run's statistics files, under OutputFile's rule, published together
// and only when every one was written (and the frames before them): a failed
// run leaves no statistics that look complete. --out was emptied of an
// earlier run's files first (prepareOutDir), so nothing is replaced.
Status writeRunFiles(const std::vector<std::pair<std::string, std::string>>& files) {
  OutputOptions options;
  options.fsync = false;  // measurements a rerun remakes; atomicity is what matters
  std::vector<std::unique_ptr<OutputFile>> outputs(files.size());
  for (size_t i = 0; i < files.size(); ++i) {
    if (Status s = OutputFile::create(files[i].first, options, &outputs[i]); !s) return s;
    if (Status s = outputs[i]->append(files[i].second); !s) return s;
  }
  for (std::unique_ptr<OutputFile>& output : outputs)
    if (Status s = output->commit(); !s) return s;
  return okStatus();
}

// "frame_NNNNN.png" exactly as the frame loop names frames ("%05u"): five
// digits, or more without a leading zero.
bool isFrameName(const std::string& name) {
  if (name.size() < 15 || name.compare(0, 6, "frame_") != 0 ||
      name.compare(name.size() - 4, 4, ".png") != 0)
    return false;
  const std::string digits = name.substr(6, name.size() - 10);
  if (digits.size() > 10 || digits.find_first_not_of("0123456789") != std::string::npos) return false;
  return digits.size() == 5 || (digits[0] != '0' && std::stoull(digits) <= UINT32_MAX);
}

bool isRunFileName(const std::string& name) {
  return isFrameName(name) || name == "frames.csv" || name == "frames.json" || name == "summary.tsv";
}

// --trace must not be an input (the store, the path file) nor one of the
// run's own files in --out; the inputs must not sit in --out under a name the
// run removes. Compared as files (links included) and as paths.
Status checkFlyOutputs(const FlyOptions& o) {
  namespace fs = std::filesystem;
  std::error_code ec;
  auto canonical = [&](const std::string& p) { return fs::weakly_canonical(p, ec).string(); };
  const std::string out_dir = canonical(o.out_dir);
  const std::string& trace_path = o.streamer.trace_path;
  for (const std::string& input : {o.store_path, o.path}) {
    if (input.empty() || !fs::exists(input, ec)) continue;
    if (!trace_path.empty() && (sameFile(input, trace_path) || canonical(input) == canonical(trace_path)))
      return Status::error(ErrorCode::kInvalidArgument,
                           "--trace " + trace_path + " is the input " + input + "; refusing to overwrite it");
    const fs::path in = canonical(input);
    if (in.parent_path().string() == out_dir && isRunFileName(in.filename().string()))
      return Status::error(ErrorCode::kInvalidArgument,
                           input + " is in --out " + o.out_dir + " under a name the run replaces");
  }
  if (!trace_path.empty()) {
    const fs::path trace = canonical(trace_path);
    if (trace.parent_path().string() == out_dir && isRunFileName(trace.filename().string()))
      return Status::error(ErrorCode::kInvalidArgument,
                           "--trace " + trace_path + " is one of the run's own files in --out");
    OutputOptions trace_options;
    trace_options.existing = ExistingOutput::kReplaceRegular;
    if (Status s = checkOutputPath(trace_path, trace_options); !s) return s;
  }
  return okStatus();
}

// --out holds one run: creates it if needed, then removes what an earlier run
// wrote there (frame_NNNNN.png, frames.csv, frames.json, summary.tsv; regular
// files only) and the temporaries of killed runs, so a reader never mixes
// two runs. Appends what it swept to *swept.
Status prepareOutDir(const std::string& dir, std::vector<std::string>* swept) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Status::error(ErrorCode::kIo, "cannot create --out " + dir + ": " + ec.message());
  if (!fs::is_directory(dir, ec))
    return Status::error(ErrorCode::kInvalidArgument, "--out " + dir + " is not a directory");
  std::vector<std::string> stale;
  for (const fs::directory_entry& entry : fs::directory_iterator(dir, ec)) {
    const std::string name = entry.path().filename().string();
    if (isRunFileName(name)) {
      if (!entry.is_regular_file(ec) || entry.is_symlink(ec))
        return Status::error(ErrorCode::kInvalidArgument,
                             entry.path().string() + " is not a regular file; the run would write there");
      stale.push_back(entry.path().string());
    }
    // ".NAME.tmp-..." of one of our names: its writer may be dead.
    const size_t tmp = name.find(".tmp-");
    if (name.size() > 1 && name[0] == '.' && tmp != std::string::npos) {
      const std::string final_name = name.substr(1, tmp - 1);
      if (isRunFileName(final_name)) sweepOutputTemporaries(dir + "/" + final_name, swept);
    }
  }
  if (ec) return Status::error(ErrorCode::kIo, "cannot list --out " + dir + ": " + ec.message());
  for (const std::string& path : stale) {
    if (::unlink(path.c_str()) != 0 && errno != ENOENT)
      return Status::error(ErrorCode::kIo, "cannot remove " + path + " of an earlier run: " +
                                               std::strerror(errno));
  }
  return okStatus();
}

// Library-side guard for values a program's command line already bounds
// (docs/cli.md): non-finite or absurd numbers would hang or mislead.
Status checkFlyOptions(const FlyOptions& o) {
  auto bad = [](const std::string& what) { return Status::error(ErrorCode::kInvalidArgument, what); };
  if (!std::isfinite(o.speed) || o.speed <= 0.0 || o.speed > kMaxFlySpeed)
    return bad("speed must be a number from 0.001 to " + std::to_string(int(kMaxFlySpeed)));
  if (o.streamer.ram_budget_bytes < (uint64_t(1) << 20))
    return bad("the RAM budget (cache MiB) must be at least 1");
  if (o.upload_tiles == 0) return bad("uploads per frame must be at least 1");
  if (o.streamer.io_threads > kMaxIoThreads)
    return bad("io threads must be at most " + std::to_string(kMaxIoThreads));
  if (o.remote.connections == 0 || o.remote.connections > kMaxRemoteConnections)
    return bad("HTTP connections must be from 1 to " + std::to_string(kMaxRemoteConnections));
  if (!o.remote.disk_cache_dir.empty() && o.remote.disk_cache_bytes == 0)
    return bad("the disk cache cap must be at least 1 MiB");
  if (!std::isfinite(o.fault_latency_ms) || o.fault_latency_ms < 0.0 || o.fault_latency_ms > kMaxFlyDelayMs)
    return bad("fault latency must be from 0 to " + std::to_string(int(kMaxFlyDelayMs)) + " ms");
  if (!std::isfinite(o.rest_frame_ms) || o.rest_frame_ms < 0.0 || o.rest_frame_ms > kMaxFlyDelayMs)
    return bad("rest frame time must be from 0 to " + std::to_string(int(kMaxFlyDelayMs)) + " ms");
  if (!(o.fault_corrupt_fraction >= 0.0 && o.fault_corrupt_fraction <= 1.0))
    return bad("fault corrupt fraction must be from 0 to 1");
  if (!std::isfinite(o.vertical_scale) || o.vertical_scale <= 0.0 || o.vertical_scale > kMaxVerticalScale)
    return bad("vertical scale must be a number above 0 and at most " + std::to_string(int(kMaxVerticalScale)));
  const DeterministicIo& io = o.streamer.deterministic_io;
  if (io.reads_per_frame == 0 || io.reads_per_frame > kMaxFlyIoReadsPerFrame)
    return bad("reads per frame must be from 1 to " + std::to_string(kMaxFlyIoReadsPerFrame));
  if (io.latency_frames == 0 || io.latency_frames > kMaxFlyIoLatencyFrames)
    return bad("I/O latency must be from 1 to " + std::to_string(kMaxFlyIoLatencyFrames) + " frames");
  if (o.terrain_ring < 16 || o.terrain_ring > 1024 || (o.terrain_ring & (o.terrain_ring - 1)) != 0)
    return bad("terrain ring must be a power of two from 16 to 1024");
  if (!(o.max_failed_reads_percent >= 0.0 && o.max_failed_reads_percent <= 100.0))
    return bad("failed reads allowed must be from 0 to 100 per cent");
  if (!std::isfinite(o.terrain_error_px) || o.terrain_error_px < kMinTerrainErrorPx ||
      o.terrain_error_px > kMaxTerrainErrorPx)
    return bad("terrain error must be from 0.01 to 1000 pixels");
  return okStatus();
}

// Failed tile reads: a warning when there are any, an error past the
// allowed share or when nothing loaded (the statistics are written first:
// they say where it failed).
Status checkFailedReads(const FlyOptions& o, const FlightRun& run, std::ostream& warnings) {
  const uint64_t failed = run.tile_failures;
  if (failed == 0) return okStatus();
  const uint64_t loaded = run.streamer.total.loads;
  const double percent = 100.0 * double(failed) / double(failed + loaded);
  char share[32];
  std::snprintf(share, sizeof share, "%.2f", percent);
  const std::string what = std::to_string(failed) + " of " + std::to_string(failed + loaded) +
                           " tile reads failed (" + share + " %; the first are named above)";
  if (loaded == 0 || percent > o.max_failed_reads_percent) {
    char allowed[32];
    std::snprintf(allowed, sizeof allowed, "%g", o.max_failed_reads_percent);
    return Status::error(ErrorCode::kUnavailable,
                         what + (loaded == 0 ? std::string(": none loaded")
                                             : std::string(": more than the ") + allowed +
                                                   " % allowed (--max-failed-reads)") +
                             "; the run's statistics are in " + o.out_dir);
  }
  warnings << "clipstream-fly: warning: " << what << ": those tiles showed coarser levels\n";
  return okStatus();
}

// Opens the flight's tile source (store or procedural, behind the fault
// injector and the BC1 encoder when asked) into out->source, the
// reference's tiles into out->reference_source and the elevation layer into
// out->terrain; *geometry_out is the colour pyramid's. The terrain layer's
// warnings go to `notes_out`.
Status openFlySources(const FlyOptions& o, FlightRunOptions* out, PyramidGeometry* geometry_out,
                      std::ostream& notes_out) {
  FlightRunOptions& r = *out;
  // Source.
  std::shared_ptr<TileSource> source;
  if (o.procedural_px > 0) {
    ProceduralSpec spec;
    spec.width_px = spec.height_px = o.procedural_px;
    source = makeProceduralSource(spec);
    if (!source)
      return Status::error(ErrorCode::kInvalidArgument,
                           "procedural size " + std::to_string(o.procedural_px) + " not supported");
  } else {
    Status s;
    source = openStoreSource(o.store_path, o.remote, &s);
    if (!source) return s.ok() ? Status::error(ErrorCode::kIo, "cannot open " + o.store_path) : s;
  }
  if (o.fault_latency_ms > 0.0 || o.fault_corrupt_fraction > 0.0) {
    FaultSpec fault;
    fault.latency_ms = o.fault_latency_ms;
    fault.fail_fraction = o.fault_corrupt_fraction;
    fault.fail_code = ErrorCode::kCorruptTile;
    source = makeFaultySource(source, fault);
  }
  const PyramidGeometry geometry = source->geometry();
  *geometry_out = geometry;
  std::shared_ptr<TileSource> rgba8_source = source;
  if (o.tile_format == TileContent::kBc1) {
    Status s;
    source = makeBc1Source(source, &s);
    if (!source) return s;
  }

  r.source = source;
  if (o.reference_tile_format && *o.reference_tile_format != o.tile_format) {
    Status s;
    r.reference_source = *o.reference_tile_format == TileContent::kBc1 ? makeBc1Source(rgba8_source, &s)
                                                                       : rgba8_source;
    if (!r.reference_source) return s;
  }
  if (!o.elevation_path.empty()) {
    TerrainLayerConfig terrain;
    const RemoteOptions& remote = o.remote;
    std::vector<std::string> notes;
    if (Status s = openTerrainLayer(o.procedural_px > 0 ? std::string() : o.store_path, geometry,
                                    o.elevation_path, o.vertical_scale, o.stretch_elevation,
                                    o.terrain_ring, &terrain, &notes, remote);
        !s)
      return s;
    for (const std::string& w : notes) notes_out << "clipstream-fly: warning: " << w << "\n";
    terrain.method = o.terrain_method;
    terrain.error_px = o.terrain_error_px;
    terrain.triangle_budget = o.terrain_triangle_budget;
    terrain.lighting = o.terrain_lighting;
    terrain.detail_textures = o.terrain_detail;
    if (Status s = synthesizeRelief(o.synthesized_levels, &terrain); !s) return s;
    r.terrain = std::move(terrain);
  }
  return okStatus();
}

// The colour layer's georeference, from its store's header or COG's tags
// (none for --procedural).
Status colourGeoReference(const FlyOptions& o, GeoReference* out) {
  *out = GeoReference{};
  if (o.store_path.empty()) return okStatus();
  StoreInfo info;
  if (Status s = readRasterInfo(o.store_path, o.remote, &info); !s) return s;
  *out = info.geo;
  return okStatus();
}

// The path, its frame count and the flight's settings from the options.
Status setFlightPlan(const FlyOptions& o, const PyramidGeometry& geometry, FlightRunOptions* out) {
  FlightRunOptions& r = *out;
  if (o.look_at) {
    // One camera, held: two equal keyframes a second apart (over terrain a
    // path's heights are above the ground under the camera).
    GeoReference geo;
    if (Status s = colourGeoReference(o, &geo); !s) return s;
    Camera camera;
    double ground = 0.0;
    const TerrainLayerConfig* terrain = r.terrain ? &*r.terrain : nullptr;
    if (Status s = aimAtMapPoint(*o.look_at, geo, geometry, terrain, &camera, &ground); !s)
      return Status::error(s.code, "--look-at: " + s.message);
    Keyframe k;
    k.position = {camera.position.x, camera.position.y - ground, camera.position.z};
    k.heading_deg = camera.heading_rad * 180.0 / M_PI;
    k.pitch_deg = camera.pitch_rad * 180.0 / M_PI;
    r.path.keyframes = {k, k};
    r.path.keyframes[1].t_s = 1.0;
  } else if (o.path == kSummitPath || o.path == kRoughPath) {
    // The built-in orbit around the terrain's highest point, or the middle
    // of its roughest area, instead of the texture's centre.
    if (!r.terrain) return Status::error(ErrorCode::kInvalidArgument, "--path " + o.path + " needs --elevation");
    glm::dvec3 peak;
    Status found = o.path == kSummitPath ? highestPoint(*r.terrain->source, r.terrain->alignment, &peak)
                                         : roughestPoint(*r.terrain->source, r.terrain->alignment, &peak);
    if (!found) return found;
    if (Status s = FlightPath::builtin("orbit", geometry, &r.path); !s) return s;
    const glm::dvec2 shift = glm::dvec2(peak.x, peak.z) - 0.5 * glm::dvec2(geometry.width_px, geometry.height_px);
    for (Keyframe& k : r.path.keyframes) k.position += glm::dvec3(shift.x, 0.0, shift.y);
  } else {
    const auto names = FlightPath::builtinNames();
    const bool builtin = std::find(names.begin(), names.end(), o.path) != names.end();
    if (builtin && o.path_in_map_units)
      return Status::error(ErrorCode::kInvalidArgument,
                           "--path-in-map-units is for a JSON path file, not the built-in path " + o.path);
    Status s = builtin ? FlightPath::builtin(o.path, geometry, &r.path, std::max(1u, o.teleport_frames))
                       : FlightPath::load(o.path, &r.path);
    if (!s) return s;
    if (o.path_in_map_units) {
      GeoReference geo;
      if (s = colourGeoReference(o, &geo); !s) return s;
      if (!geo.present)
        return Status::error(ErrorCode::kInvalidArgument,
                             "--path-in-map-units: the colour store has no georeference (give the path in texels)");
      if (s = pathFromMapUnits(geo, r.terrain ? &r.terrain->alignment : nullptr, &r.path); !s)
        return Status::error(s.code, "--path-in-map-units: " + s.message);
    }
  }
  r.speed = o.speed;
  // The whole path at this speed, bounded like --frames: a long path flown
  // slowly would otherwise ask for billions of frames.
  const double path_frames =
      std::ceil(r.path.durationS() / (r.speed * renderer_config::kSimulatedFrameSeconds)) + 1.0;
  if (o.frames == 0 && !(path_frames <= double(kMaxFlyFrames)))
  {
    char text[200];
    std::snprintf(text, sizeof text,
                  "the path lasts %.6g s: at speed %.6g that is more than %u frames; give a higher "
                  "speed or --frames",
                  r.path.durationS(), r.speed, unsigned(kMaxFlyFrames));
    return Status::error(ErrorCode::kInvalidArgument, text);
  }
  r.frames = o.frames > 0 ? o.frames : uint32_t(path_frames);
  r.warmup_frames = o.warmup_frames;
  r.rest_frames = o.rest_frames;
  r.rest_frame_ms = o.rest_frame_ms;
  r.loop = o.loop;
  r.viewport = o.viewport;
  r.resize_at_frame = o.resize_at_frame;
  r.resize_to = o.resize_to;
  r.streamer = o.streamer;
  r.upload_tiles = o.upload_tiles;
  r.buffering = o.buffering;
  r.texture_memory = o.texture_memory;
  r.pool_bytes = o.pool_mb << 20;
  r.overlay = o.overlay ? Overlay::kLevels : Overlay::kOff;
  r.path_hint = o.path_hint;
  r.reference_every = o.reference ? std::max(1u, o.reference_every) : 0;
  r.ground_truth_every = o.reference ? o.ground_truth_every : 0;
  r.sample_tiles = o.reference && o.over_fetch;
  r.fewest_triangles = o.fewest_triangles;
  r.reference_lighting = o.reference_lighting;
  return okStatus();
}

}  // namespace

Status runFly(const FlyOptions& o, std::ostream& log, std::ostream* warnings) {
  if (Status s = checkFlyOptions(o); !s) return s;
  FlightRunOptions r;
  PyramidGeometry geometry;
  if (Status s = openFlySources(o, &r, &geometry, warnings ? *warnings : log); !s) return s;
  if (Status s = setFlightPlan(o, geometry, &r); !s) return s;

  // Outputs are checked before any work, and none of them may be an input.
  if (Status s = checkFlyOutputs(o); !s) return s;

  std::unique_ptr<HeadlessContext> context;
  if (Status s = HeadlessContext::create(&context); !s) return s;

  // Everything that can fail before the first frame has been tried when
  // on_start runs: only then are an earlier run's files in --out removed.
  std::vector<std::string> swept;
  r.on_start = [&]() -> Status {
    if (Status s = prepareOutDir(o.out_dir, &swept); !s) return s;
    if (!o.streamer.trace_path.empty()) sweepOutputTemporaries(o.streamer.trace_path, &swept);
    return okStatus();
  };
  FrameWriter writer(kMaxQueuedPngFrames);
  const uint32_t total_frames = r.frames + r.rest_frames;
  const uint32_t save_every = o.save_every.value_or(std::max(1u, (total_frames + 3) / 4));
  r.on_frame = [&](const FrameSample& frame, const OffscreenTarget& target, double* readback_ms) -> Status {
    const uint32_t i = frame.frame;
    if (o.on_progress) o.on_progress(i + 1, total_frames);
    if (save_every == 0 || !(i % save_every == 0 || i + 1 == total_frames)) return okStatus();
    const auto start = std::chrono::steady_clock::now();
    std::vector<uint8_t> rgba;
    target.readRgba(&rgba);
    char name[64];
    std::snprintf(name, sizeof name, "/frame_%05u.png", i);
    writer.submit(o.out_dir + name, target.viewport().width_px, target.viewport().height_px, std::move(rgba));
    *readback_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    return okStatus();
  };
  // The frames are written before the streamer publishes its trace: a
  // frame that failed leaves no trace.
  r.before_finish = [&]() { return writer.close(); };

  FlightRun run;
  if (Status s = runFlight(r, &run); !s) return s;
  if (!run.trace_status) return run.trace_status;

  RunDescription d;
  d.path = o.path;
  d.speed = r.speed;
  d.viewport = o.viewport;
  d.buffering = o.buffering;
  d.upload_tiles = o.upload_tiles;
  d.warmup_frames = o.warmup_frames;
  d.reference = o.reference;
  d.reference_tile_format = o.reference_tile_format.value_or(o.tile_format);
  d.path_hint = o.path_hint;
  d.streamer = o.streamer;
  d.pngs_written = writer.written();
  d.pngs_dropped = writer.dropped();
  if (Status s = writeRunFiles({{o.out_dir + "/frames.csv", framesCsv(run, geometry.levelCount())},
                                {o.out_dir + "/frames.json", framesJson(run, d)},
                                {o.out_dir + "/summary.tsv", summaryTsv(run, d)}});
      !s)
    return s;

  if (run.remote.disk_cache_folders_refused > 0)
    (warnings ? *warnings : log) << "clipstream-fly: warning: the disk cache " << o.remote.disk_cache_dir
                                 << " did not cache this store: its sub-folder there is a symlink or another "
                                    "user's, which the cache never follows nor writes; remove it, or give "
                                    "--disk-cache a folder of your own\n";
  for (const std::string& line : swept)
    (warnings ? *warnings : log) << "clipstream-fly: warning: removed a temporary file left by an interrupted "
                                    "earlier run: " << printableText(line, 300) << "\n";
  if (!o.quiet) {
    printSummary(log, run, d);
    log << "wrote " << o.out_dir << "/frames.csv, frames.json\n";
  }
  return checkFailedReads(o, run, warnings ? *warnings : log);
}

}  // namespace clipstream
