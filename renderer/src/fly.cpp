// The clipstream-fly frame loop. See fly.h and docs/renderer.md.
#include <clipstream/renderer/fly.h>

#include "gl.h"

#include <clipstream/renderer/accuracy.h>
#include <clipstream/renderer/config.h>
#include <clipstream/renderer/flight_path.h>
#include <clipstream/renderer/frame_writer.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/store/output_file.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <thread>

#include <unistd.h>

namespace clipstream {
namespace {

using Clock = std::chrono::steady_clock;

double msBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

struct LevelFrame {
  uint64_t ram_hits = 0, ram_misses = 0, bytes_read = 0;
  uint32_t gpu_hits = 0, gpu_misses = 0;  // visible tiles of needed levels usable / not
};

struct FrameRow {
  uint32_t frame = 0;
  double t_s = 0;
  double frame_ms = 0, streamer_ms = 0, upload_ms = 0, draw_ms = 0, readback_ms = 0;
  uint32_t tiles_uploaded = 0, second_copies = 0;
  uint32_t max_texture_lod = 0, finest_needed = 0;
  uint64_t queue_depth = 0, in_flight = 0;
  uint64_t ram_bytes = 0;
  std::vector<LevelFrame> levels;
  LevelFrame total;
  uint64_t tiles_loaded = 0;   // loader reads into RAM this frame
  bool cut = false;            // first frame or a jump of the camera (isCut())
  AccuracyFrame accuracy;      // --reference only
};

std::string dbText(bool measured, double db) {
  if (!measured) return "";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f", db);
  return buf;
}

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
  return Status::ok();
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
  for (const std::string& input : {o.store_path, o.path}) {
    if (input.empty() || !fs::exists(input, ec)) continue;
    if (!o.trace_path.empty() && (sameFile(input, o.trace_path) || canonical(input) == canonical(o.trace_path)))
      return Status::error(ErrorCode::kInvalidArgument,
                           "--trace " + o.trace_path + " is the input " + input + "; refusing to overwrite it");
    const fs::path in = canonical(input);
    if (in.parent_path().string() == out_dir && isRunFileName(in.filename().string()))
      return Status::error(ErrorCode::kInvalidArgument,
                           input + " is in --out " + o.out_dir + " under a name the run replaces");
  }
  if (!o.trace_path.empty()) {
    const fs::path trace = canonical(o.trace_path);
    if (trace.parent_path().string() == out_dir && isRunFileName(trace.filename().string()))
      return Status::error(ErrorCode::kInvalidArgument,
                           "--trace " + o.trace_path + " is one of the run's own files in --out");
    OutputOptions trace_options;
    trace_options.existing = ExistingOutput::kReplaceRegular;
    if (Status s = checkOutputPath(o.trace_path, trace_options); !s) return s;
  }
  return Status::ok();
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
  return Status::ok();
}

// Library-side guard for values a program's command line already bounds
// (docs/cli.md): non-finite or absurd numbers would hang or mislead.
Status checkFlyOptions(const FlyOptions& o) {
  auto bad = [](const std::string& what) { return Status::error(ErrorCode::kInvalidArgument, what); };
  if (!std::isfinite(o.speed) || o.speed <= 0.0 || o.speed > kMaxFlySpeed)
    return bad("speed must be a number from 0.001 to " + std::to_string(int(kMaxFlySpeed)));
  if (o.cache_mb == 0) return bad("the RAM budget (cache MiB) must be at least 1");
  if (o.upload_tiles == 0) return bad("uploads per frame must be at least 1");
  if (o.io_threads > kMaxIoThreads)
    return bad("io threads must be at most " + std::to_string(kMaxIoThreads));
  if (!std::isfinite(o.fault_latency_ms) || o.fault_latency_ms < 0.0 || o.fault_latency_ms > kMaxFlyDelayMs)
    return bad("fault latency must be from 0 to " + std::to_string(int(kMaxFlyDelayMs)) + " ms");
  if (!std::isfinite(o.rest_frame_ms) || o.rest_frame_ms < 0.0 || o.rest_frame_ms > kMaxFlyDelayMs)
    return bad("rest frame time must be from 0 to " + std::to_string(int(kMaxFlyDelayMs)) + " ms");
  if (!(o.fault_corrupt_fraction >= 0.0 && o.fault_corrupt_fraction <= 1.0))
    return bad("fault corrupt fraction must be from 0 to 1");
  return Status::ok();
}

}  // namespace

Status parseViewport(const std::string& text, Viewport* out) {
  constexpr uint64_t kMaxSidePx = 16384;  // GL_MAX_RENDERBUFFER_SIZE of common drivers
  const size_t sep = text.find('x');
  uint64_t side[2] = {0, 0};
  bool digits = sep != std::string::npos && sep > 0 && sep + 1 < text.size();
  for (size_t i = 0; digits && i < text.size(); ++i) {
    if (i == sep) continue;
    if (text[i] < '0' || text[i] > '9') digits = false;
    uint64_t& v = side[i < sep ? 0 : 1];
    if (digits && v <= kMaxSidePx) v = v * 10 + uint64_t(text[i] - '0');
  }
  if (!digits)
    return Status::error(ErrorCode::kInvalidArgument,
                         "size \"" + printableText(text, 40) + "\" is not WIDTHxHEIGHT (e.g. 1280x720)");
  if (side[0] == 0 || side[1] == 0 || side[0] > kMaxSidePx || side[1] > kMaxSidePx)
    return Status::error(ErrorCode::kInvalidArgument,
                         "size \"" + printableText(text, 40) + "\": each side must be from 1 to " +
                             std::to_string(kMaxSidePx) + " px");
  *out = {uint32_t(side[0]), uint32_t(side[1])};
  return Status::ok();
}

Status parseBuffering(const std::string& text, Buffering* out) {
  for (Buffering b : {Buffering::kSingle, Buffering::kDoubleUploadTwice, Buffering::kDoubleCopy})
    if (text == bufferingName(b)) {
      *out = b;
      return Status::ok();
    }
  return Status::error(ErrorCode::kInvalidArgument,
                       "buffering \"" + text + "\" is not single, double-upload or double-copy");
}

Status parseResize(const std::string& text, uint32_t* frame, Viewport* out) {
  const size_t colon = text.find(':');
  const std::string digits = colon == std::string::npos ? std::string() : text.substr(0, colon);
  if (digits.empty() || digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos ||
      std::stoul(digits) == 0 || std::stoul(digits) > kMaxFlyFrames)
    return Status::error(ErrorCode::kInvalidArgument,
                         "resize \"" + printableText(text, 40) + "\" is not FRAME:WIDTHxHEIGHT with FRAME from 1 to " +
                             std::to_string(kMaxFlyFrames) + " (e.g. 120:640x360)");
  if (Status s = parseViewport(text.substr(colon + 1), out); !s) return s;
  *frame = uint32_t(std::stoul(digits));
  return Status::ok();
}

Status runFly(const FlyOptions& o, std::ostream& log, std::ostream* warnings) {
  if (Status s = checkFlyOptions(o); !s) return s;
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
    source = openStoreSource(o.store_path, &s);
    if (!source) return s.isOk() ? Status::error(ErrorCode::kIo, "cannot open " + o.store_path) : s;
  }
  if (o.fault_latency_ms > 0.0 || o.fault_corrupt_fraction > 0.0) {
    FaultSpec fault;
    fault.latency_ms = o.fault_latency_ms;
    fault.fail_fraction = o.fault_corrupt_fraction;
    fault.fail_code = ErrorCode::kCorruptTile;
    source = makeFaultySource(source, fault);
  }
  const PyramidGeometry geometry = source->geometry();

  // Path.
  FlightPath path;
  {
    const auto names = FlightPath::builtinNames();
    Status s = std::find(names.begin(), names.end(), o.path) != names.end()
                   ? FlightPath::builtin(o.path, geometry, &path, std::max(1u, o.teleport_frames))
                   : FlightPath::load(o.path, &path);
    if (!s) return s;
  }
  const double speed = o.speed > 0.0 ? o.speed : 1.0;
  // The whole path at this speed, bounded like --frames: a long path flown
  // slowly would otherwise ask for billions of frames.
  const double path_frames =
      std::ceil(path.durationS() / (speed * renderer_config::kSimulatedFrameSeconds)) + 1.0;
  if (o.frames == 0 && !(path_frames <= double(kMaxFlyFrames)))
    return Status::error(ErrorCode::kInvalidArgument,
                         "the path lasts " + std::to_string(path.durationS()) + " s: at speed " +
                             std::to_string(speed) + " that is more than " + std::to_string(kMaxFlyFrames) +
                             " frames; give a higher speed or --frames");
  const uint32_t frames = o.frames > 0 ? o.frames : uint32_t(path_frames);

  // Outputs are checked before any work, and none of them may be an input.
  if (Status s = checkFlyOutputs(o); !s) return s;

  // GL.
  std::unique_ptr<HeadlessContext> context;
  if (Status s = HeadlessContext::create(&context); !s) return s;
  std::unique_ptr<OffscreenTarget> target;
  if (Status s = OffscreenTarget::create(o.viewport, &target); !s) return s;

  StreamerConfig sc;
  sc.ram_budget_bytes = o.cache_mb << 20;
  sc.io_threads = o.io_threads;
  sc.throttle = o.throttle;
  sc.prefetch = o.prefetch;
  sc.frustum_priority = o.frustum_priority;
  sc.trace_path = o.trace_path;
  Viewport viewport = o.viewport;
  ClipmapPlan first = planClipmap(geometry, viewport, path.sample(0.0), sc.planner);
  std::unique_ptr<ClipmapRenderer> renderer;

  // The coarse pyramid is loaded before the first frame, so every frame
  // has something correct to draw. A tile that fails is filled from its
  // ancestor (counted).
  // A viewport resize makes a new renderer (the clip size follows the
  // viewport) and loads the pyramid again the same way.
  uint32_t preload_failures = 0;
  auto makeRenderer = [&]() -> Status {
    renderer.reset();
    RendererConfig rc{first.clip_tiles, first.pyramid_level, o.buffering};
    if (Status s = ClipmapRenderer::create(geometry, rc, &renderer); !s) return s;
    renderer->setOverlay(o.overlay ? Overlay::kLevels : Overlay::kOff);
    renderer->beginFrame();
    // A tile that fails is filled from its ancestor (and counted).
    preload_failures += renderer->loadPyramid(
        [&](const TileKey& key) -> std::shared_ptr<const std::vector<uint8_t>> {
          auto px = std::make_shared<std::vector<uint8_t>>();
          if (!source->fetch(key, px.get()).isOk()) return nullptr;
          return px;
        });
    renderer->endUploads();
    return Status::ok();
  };
  const auto preload_start = Clock::now();
  if (Status s = makeRenderer(); !s) return s;
  const double preload_ms = msBetween(preload_start, Clock::now());

  std::unique_ptr<FlyAccuracy> accuracy;
  if (o.reference) {
    AccuracyOptions ao;
    ao.ground_truth = o.ground_truth_every > 0;
    if (Status s = FlyAccuracy::create(source, viewport, sc.planner, ao, &accuracy); !s) return s;
  }

  // Everything that can fail before the first frame has been tried: only now
  // are an earlier run's files in --out removed.
  std::vector<std::string> swept;
  if (Status s = prepareOutDir(o.out_dir, &swept); !s) return s;
  if (!o.trace_path.empty()) sweepOutputTemporaries(o.trace_path, &swept);

  // Path time of recorded frame `frame` (fractional for the hint): `speed`
  // times the simulated time, held at the last pose through the rest frames.
  // The streamer's clock runs at kSimulatedFrameSeconds per frame from the
  // first warm-up frame, so recorded frame 0 is at clock0_s.
  auto pathTimeOfFrame = [&](double frame) {
    double t = std::clamp(frame, 0.0, double(frames - 1)) * renderer_config::kSimulatedFrameSeconds * speed;
    if (o.loop && path.durationS() > 0.0) t = std::fmod(t, path.durationS());
    return t;
  };
  const double clock0_s = o.warmup_frames * renderer_config::kSimulatedFrameSeconds;
  Streamer streamer(source, sc);
  // A run that fails after this point leaves no trace: published only when
  // everything else was written.
  bool run_succeeded = false;
  struct DiscardTraceUnlessDone {
    Streamer& streamer;
    const bool& done;
    ~DiscardTraceUnlessDone() {
      if (!done) streamer.discardTrace();
    }
  } discard_trace_unless_done{streamer, run_succeeded};
  if (o.path_hint) {
    PathHint hint;
    hint.camera_at = [&](double clock_s) {
      return path.sample(pathTimeOfFrame((clock_s - clock0_s) / renderer_config::kSimulatedFrameSeconds));
    };
    streamer.setPathHint(std::move(hint));
  }
  FrameWriter writer(renderer_config::kMaxQueuedPngFrames);
  const uint32_t total_frames = frames + o.rest_frames;
  std::vector<FrameRow> rows;
  rows.reserve(std::min<uint32_t>(total_frames, 100000));  // grows past that as frames come
  StreamerStats before = streamer.stats();
  const uint32_t levels = geometry.levelCount();
  const auto run_start = Clock::now();
  Camera previous = path.sample(0.0);
  double previous_step = 0.0;
  uint32_t resizes = 0;

  for (uint32_t w = 0; w < o.warmup_frames; ++w) {
    // Start-up excluded from the statistics: the camera holds its first
    // position while the streamer fills the first windows.
    const Camera camera = path.sample(0.0);
    streamer.update(camera, viewport, w * renderer_config::kSimulatedFrameSeconds);
    renderer->applyHandoff(streamer.takeReady(o.upload_tiles));
    target->bind();
    ClipmapRenderer::clearSky();
    renderer->draw(camera, viewport);
    glFinish();
    // Warm-up frames count in the over-fetch ratio (loads and sampled
    // tiles alike), nowhere else.
    AccuracyFrame ignored;
    if (accuracy)
      if (Status s = accuracy->measure(camera, *target, false, false, &ignored); !s) return s;
  }
  const uint64_t warmup_loads = streamer.stats().total.loads - before.total.loads;
  before = streamer.stats();

  for (uint32_t i = 0; i < total_frames; ++i) {
    if (o.resize_at_frame > 0 && i == o.resize_at_frame && o.resize_to.width_px > 0) {
      viewport = o.resize_to;
      first = planClipmap(geometry, viewport, previous, sc.planner);
      target.reset();
      if (Status s = OffscreenTarget::create(viewport, &target); !s) return s;
      if (Status s = makeRenderer(); !s) return s;
      if (accuracy)
        if (Status s = accuracy->resize(viewport); !s) return s;
      streamer.resetGpuResidency();
      ++resizes;
    }
    FrameRow row;
    row.frame = i;
    row.t_s = pathTimeOfFrame(double(i));
    const Camera camera = path.sample(row.t_s);
    const double step = glm::length(camera.position - previous.position);
    row.cut = (i == 0 && o.warmup_frames == 0) || (i > 0 && isCut(previous, camera, previous_step));
    previous_step = step;
    previous = camera;
    const auto t0 = Clock::now();
    streamer.update(camera, viewport, clock0_s + i * renderer_config::kSimulatedFrameSeconds);
    const FrameHandoff handoff = streamer.takeReady(o.upload_tiles);
    const auto t_streamer = Clock::now();
    renderer->applyHandoff(handoff);
    const auto t_upload = Clock::now();
    target->bind();
    ClipmapRenderer::clearSky();
    renderer->draw(camera, viewport);
    glFinish();  // frame time includes the GPU (llvmpipe) work
    const auto t1 = Clock::now();
    row.frame_ms = msBetween(t0, t1);
    row.streamer_ms = msBetween(t0, t_streamer);
    row.draw_ms = msBetween(t_upload, t1);
    row.upload_ms = renderer->lastUploads().upload_ms;
    row.tiles_uploaded = renderer->lastUploads().tiles;
    row.second_copies = renderer->lastUploads().second_copies;
    row.max_texture_lod = handoff.max_texture_lod;
    row.finest_needed = streamer.plan().finest_level;

    const bool save = o.save_every > 0 && (i % o.save_every == 0 || i + 1 == total_frames);
    if (save) {
      std::vector<uint8_t> rgba;
      target->readRgba(&rgba);
      char name[64];
      std::snprintf(name, sizeof name, "/frame_%05u.png", i);
      writer.submit(o.out_dir + name, viewport.width_px, viewport.height_px, std::move(rgba));
      row.readback_ms = msBetween(t1, Clock::now());
    }
    // Measured after the frame is timed: the reference fetches synchronously.
    if (accuracy) {
      const uint32_t every = std::max(1u, o.reference_every);
      const bool compare = i % every == 0 || i >= frames || i + 1 == total_frames;
      const bool truth = compare && o.ground_truth_every > 0 && i % o.ground_truth_every == 0;
      if (Status s = accuracy->measure(camera, *target, compare, truth, &row.accuracy); !s) return s;
    }

    const StreamerStats now = streamer.stats();
    row.queue_depth = now.queue_depth;
    row.in_flight = now.in_flight;
    row.ram_bytes = now.ram_bytes;
    row.tiles_loaded = now.total.loads - before.total.loads;
    row.levels.resize(levels);
    for (uint32_t l = 0; l < levels; ++l) {
      const LevelCounters c = l < now.levels.size() ? now.levels[l] : LevelCounters{};
      const LevelCounters b = l < before.levels.size() ? before.levels[l] : LevelCounters{};
      LevelFrame& lf = row.levels[l];
      lf.ram_hits = c.ram_hits - b.ram_hits;
      lf.ram_misses = c.ram_misses - b.ram_misses;
      lf.bytes_read = c.bytes_read - b.bytes_read;
    }
    // GPU hits: visible tiles of the needed stack levels the shader may
    // sample (usable) this frame; misses draw from a coarser level.
    const ClipmapPlan& plan = streamer.plan();
    const UsableMap& usable = renderer->usableMap();
    for (const ClipLevelPlan& lp : plan.stack) {
      if (!lp.needed || lp.level >= usable.usable.size()) continue;
      LevelFrame& lf = row.levels[lp.level];
      for (int64_t y = lp.visible.y0; y < lp.visible.y1; ++y)
        for (int64_t x = lp.visible.x0; x < lp.visible.x1; ++x) {
          const bool ok =
              usable.windows[lp.level].contains(x, y) &&
              usable.usable[lp.level][size_t(toroidalSlot(y, usable.clip_tiles)) * usable.clip_tiles +
                                      toroidalSlot(x, usable.clip_tiles)] != 0;
          (ok ? lf.gpu_hits : lf.gpu_misses)++;
        }
    }
    for (const LevelFrame& lf : row.levels) {
      row.total.ram_hits += lf.ram_hits;
      row.total.ram_misses += lf.ram_misses;
      row.total.bytes_read += lf.bytes_read;
      row.total.gpu_hits += lf.gpu_hits;
      row.total.gpu_misses += lf.gpu_misses;
    }
    before = now;
    rows.push_back(std::move(row));
    // Rest frames at display pace: a slow source gets real time to land.
    if (i >= frames && o.rest_frame_ms > 0.0) {
      const double left = o.rest_frame_ms - msBetween(t0, Clock::now());
      if (left > 0.0) std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(left));
    }
  }
  const double run_ms = msBetween(run_start, Clock::now());
  const StreamerStats final_stats = streamer.stats();
  Status write_status = writer.close();
  if (!write_status) streamer.discardTrace();
  streamer.shutdown();
  if (write_status) write_status = streamer.traceStatus();

  // CSV: one row per frame; per-level columns after the totals.
  std::string csv =
      "frame,t_s,frame_ms,streamer_ms,upload_ms,draw_ms,readback_ms,tiles_uploaded,second_copies,max_texture_lod,"
      "finest_needed,queue_depth,in_flight,ram_bytes,bytes_read,ram_hits,ram_misses,gpu_hits,"
      "gpu_misses,tiles_loaded,cut,psnr_db,max_abs_error,hole_pixels,gt_psnr_db,gt_max_abs_error";
  for (uint32_t l = 0; l < levels; ++l)
    for (const char* f : {"ram_hits", "ram_misses", "gpu_hits", "gpu_misses"})
      csv += ",L" + std::to_string(l) + "_" + f;
  csv += "\n";
  nlohmann::json jframes = nlohmann::json::array();
  for (const FrameRow& r : rows) {
    char buf[512];
    std::snprintf(buf, sizeof buf, "%u,%.4f,%.3f,%.3f,%.3f,%.3f,%.3f,%u,%u,%u,%u,%llu,%llu,%llu,%llu,%llu,%llu,%u,%u",
                  r.frame, r.t_s, r.frame_ms, r.streamer_ms, r.upload_ms, r.draw_ms, r.readback_ms, r.tiles_uploaded,
                  r.second_copies, r.max_texture_lod, r.finest_needed,
                  (unsigned long long)r.queue_depth, (unsigned long long)r.in_flight,
                  (unsigned long long)r.ram_bytes, (unsigned long long)r.total.bytes_read,
                  (unsigned long long)r.total.ram_hits, (unsigned long long)r.total.ram_misses,
                  r.total.gpu_hits, r.total.gpu_misses);
    csv += buf;
    const AccuracyFrame& a = r.accuracy;
    csv += "," + std::to_string(r.tiles_loaded) + "," + (r.cut ? "1" : "0") + "," +
           dbText(a.measured, a.error.psnr_db) + "," +
           (a.measured ? std::to_string(a.error.max_abs_error) : "") + "," +
           (a.measured ? std::to_string(a.hole_pixels) : "") + "," +
           dbText(a.ground_truth_measured, a.ground_truth.psnr_db) + "," +
           (a.ground_truth_measured ? std::to_string(a.ground_truth.max_abs_error) : "");
    nlohmann::json jl = nlohmann::json::array();
    for (const LevelFrame& lf : r.levels) {
      csv += "," + std::to_string(lf.ram_hits) + "," + std::to_string(lf.ram_misses) + "," +
             std::to_string(lf.gpu_hits) + "," + std::to_string(lf.gpu_misses);
      jl.push_back({{"ram_hits", lf.ram_hits}, {"ram_misses", lf.ram_misses},
                    {"gpu_hits", lf.gpu_hits}, {"gpu_misses", lf.gpu_misses},
                    {"bytes_read", lf.bytes_read}});
    }
    csv += "\n";
    jframes.push_back({{"frame", r.frame}, {"t_s", r.t_s}, {"frame_ms", r.frame_ms},
                       {"streamer_ms", r.streamer_ms}, {"upload_ms", r.upload_ms},
                       {"draw_ms", r.draw_ms}, {"readback_ms", r.readback_ms},
                       {"tiles_uploaded", r.tiles_uploaded}, {"second_copies", r.second_copies},
                       {"max_texture_lod", r.max_texture_lod}, {"finest_needed", r.finest_needed},
                       {"queue_depth", r.queue_depth}, {"in_flight", r.in_flight},
                       {"ram_bytes", r.ram_bytes}, {"bytes_read", r.total.bytes_read},
                       {"ram_hits", r.total.ram_hits}, {"ram_misses", r.total.ram_misses},
                       {"gpu_hits", r.total.gpu_hits}, {"gpu_misses", r.total.gpu_misses},
                       {"tiles_loaded", r.tiles_loaded}, {"cut", r.cut},
                       {"levels", jl}});
    if (r.accuracy.measured) {
      jframes.back()["psnr_db"] = r.accuracy.error.psnr_db;
      jframes.back()["max_abs_error"] = r.accuracy.error.max_abs_error;
      jframes.back()["hole_pixels"] = r.accuracy.hole_pixels;
    }
    if (r.accuracy.ground_truth_measured) {
      jframes.back()["gt_psnr_db"] = r.accuracy.ground_truth.psnr_db;
      jframes.back()["gt_max_abs_error"] = r.accuracy.ground_truth.max_abs_error;
    }
  }
  std::vector<double> frame_ms;
  uint64_t tiles = 0, gpu_hits = 0, gpu_misses = 0;
  for (const FrameRow& r : rows) {
    frame_ms.push_back(r.frame_ms);
    tiles += r.tiles_uploaded;
    gpu_hits += r.total.gpu_hits;
    gpu_misses += r.total.gpu_misses;
  }
  double mean = 0.0, streamer_mean = 0.0, upload_mean = 0.0, draw_mean = 0.0;
  for (const FrameRow& r : rows) {
    streamer_mean += r.streamer_ms / std::max<size_t>(rows.size(), 1);
    upload_mean += r.upload_ms / std::max<size_t>(rows.size(), 1);
    draw_mean += r.draw_ms / std::max<size_t>(rows.size(), 1);
  }
  for (double v : frame_ms) mean += v;
  mean /= std::max<size_t>(frame_ms.size(), 1);
  // Run summary (docs/accuracy.md): PSNR, time to sharp, over-fetch, RSS.
  std::vector<FrameRecord> records;
  records.reserve(rows.size());
  double gt_sum = 0.0, gt_min = kIdenticalPsnrDb;
  uint32_t gt_count = 0, holes_frames = 0;
  for (const FrameRow& r : rows) {
    FrameRecord f;
    f.frame = r.frame;
    f.cut = r.cut;
    f.has_error = r.accuracy.measured;
    f.psnr_db = r.accuracy.error.psnr_db;
    f.max_abs_error = r.accuracy.error.max_abs_error;
    f.frame_ms = r.frame_ms;
    f.bytes_read = r.total.bytes_read;
    f.tiles_uploaded = r.tiles_uploaded;
    f.tiles_loaded = r.tiles_loaded;
    f.ram_hits = r.total.ram_hits;
    f.ram_misses = r.total.ram_misses;
    f.gpu_hits = r.total.gpu_hits;
    f.gpu_misses = r.total.gpu_misses;
    records.push_back(f);
    if (r.accuracy.measured && r.accuracy.hole_pixels > 0) ++holes_frames;
    if (r.accuracy.ground_truth_measured) {
      ++gt_count;
      gt_sum += r.accuracy.ground_truth.psnr_db;
      gt_min = std::min(gt_min, r.accuracy.ground_truth.psnr_db);
    }
  }
  RunSummary run = summarizeRun(records, accuracy ? accuracy->tilesSampled() : 0, peakRssBytes());
  if (run.tiles_sampled > 0)
    run.over_fetch_ratio = double(run.tiles_loaded + warmup_loads) / double(run.tiles_sampled);
  nlohmann::json acc = nlohmann::json::parse(run.toJson(), nullptr, false);
  acc["reference"] = o.reference;
  acc["frames_with_holes"] = holes_frames;
  acc["ground_truth_frames"] = gt_count;
  acc["ground_truth_psnr_mean_db"] = gt_count ? gt_sum / gt_count : 0.0;
  acc["ground_truth_psnr_min_db"] = gt_count ? gt_min : 0.0;
  acc["resizes"] = resizes;
  acc["warmup_frames"] = o.warmup_frames;
  acc["warmup_tiles_loaded"] = warmup_loads;
  acc["ram_peak_bytes"] = final_stats.ram_peak_bytes;
  acc["ram_budget_bytes"] = final_stats.ram_budget_bytes;
  acc["tile_failures"] = final_stats.total.failures + preload_failures;
  acc["throttle"] = o.throttle;
  acc["prefetch"] = o.prefetch;
  acc["frustum_priority"] = o.frustum_priority;
  acc["path_hint"] = o.path_hint;
  acc["path_hint_frames"] = final_stats.path_hint_frames;
  acc["path_hint_ignored_frames"] = final_stats.path_hint_ignored_frames;
  acc["upload_tiles"] = o.upload_tiles;
  acc["cache_mb"] = o.cache_mb;
  nlohmann::json summary = {
      {"source", source->describe()},
      {"path", o.path},
      {"frames", total_frames},
      {"viewport", std::to_string(o.viewport.width_px) + "x" + std::to_string(o.viewport.height_px)},
      {"speed", speed},
      {"buffering", bufferingName(o.buffering)},
      {"clip_tiles", first.clip_tiles},
      {"pyramid_level", first.pyramid_level},
      {"gl", context->describe()},
      {"texture_bytes", renderer->textureBytes()},
      {"preload_ms", preload_ms},
      {"preload_failures", preload_failures},
      {"run_ms", run_ms},
      {"frame_ms_mean", mean},
      {"streamer_ms_mean", streamer_mean},
      {"upload_ms_mean", upload_mean},
      {"draw_ms_mean", draw_mean},
      {"frame_ms_p50", percentileOf(frame_ms, 0.5)},
      {"frame_ms_p99", percentileOf(frame_ms, 0.99)},
      {"frame_ms_max", percentileOf(frame_ms, 1.0)},
      {"tiles_uploaded", tiles},
      {"gpu_hit_ratio", gpu_hits + gpu_misses ? double(gpu_hits) / double(gpu_hits + gpu_misses) : 1.0},
      {"pngs_written", writer.written()},
      {"pngs_dropped", writer.dropped()},
      {"streamer", nlohmann::json::parse(final_stats.toJson(), nullptr, false)},
      {"accuracy", acc}};
  nlohmann::json doc = {{"summary", summary}, {"frames", jframes}};
  if (!write_status) return write_status;  // a frame or the trace failed: no statistics
  std::vector<std::pair<std::string, std::string>> run_files = {
      {o.out_dir + "/frames.csv", csv}, {o.out_dir + "/frames.json", doc.dump(1) + "\n"}};
  // summary.tsv: one header line, one value line (for scripts/sweep.sh).
  {
    std::string keys, values;
    auto add = [&](const std::string& k, const std::string& v) {
      keys += (keys.empty() ? "" : "\t") + k;
      values += (values.empty() ? "" : "\t") + v;
    };
    auto num = [](double v) {
      char b[32];
      std::snprintf(b, sizeof b, "%.4f", std::isfinite(v) ? v : 0.0);
      return std::string(b);
    };
    add("frames", std::to_string(run.frames));
    add("speed", num(speed));
    add("upload_tiles", std::to_string(o.upload_tiles));
    add("cache_mb", std::to_string(o.cache_mb));
    add("psnr_mean_db", num(run.psnr_mean_db));
    add("psnr_min_db", num(run.psnr_min_db));
    add("frames_below_30db", std::to_string(run.frames_below_30db));
    add("identical_frames", std::to_string(run.identical_frames));
    add("time_to_sharp_mean", num(run.time_to_sharp_mean));
    add("time_to_sharp_max", std::to_string(run.time_to_sharp_max));
    add("frame_ms_mean", num(run.frame_ms_mean));
    add("frame_ms_p50", num(run.frame_ms_p50));
    add("frame_ms_p99", num(run.frame_ms_p99));
    add("frame_ms_max", num(run.frame_ms_max));
    add("bytes_read", std::to_string(run.bytes_read));
    add("tiles_uploaded", std::to_string(run.tiles_uploaded));
    add("tiles_loaded", std::to_string(run.tiles_loaded));
    add("tiles_sampled", std::to_string(run.tiles_sampled));
    add("over_fetch_ratio", num(run.over_fetch_ratio));
    add("ram_hit_rate", num(run.ram_hit_rate));
    add("gpu_hit_rate", num(run.gpu_hit_rate));
    add("peak_rss_mib", num(double(run.peak_rss_bytes) / 1048576.0));
    add("ram_peak_mib", num(double(final_stats.ram_peak_bytes) / 1048576.0));
    add("ram_budget_mib", num(double(final_stats.ram_budget_bytes) / 1048576.0));
    add("frames_with_holes", std::to_string(holes_frames));
    add("gt_psnr_mean_db", gt_count ? num(gt_sum / gt_count) : std::string());  // empty: not measured
    add("tile_failures", std::to_string(final_stats.total.failures + preload_failures));
    run_files.push_back({o.out_dir + "/summary.tsv", keys + "\n" + values + "\n"});
  }
  if (Status s = writeRunFiles(run_files); !s) return s;
  run_succeeded = true;

  for (const std::string& line : swept)
    (warnings ? *warnings : log) << "clipstream-fly: warning: removed a temporary file left by an interrupted "
                                    "earlier run: " << printableText(line, 300) << "\n";
  if (!o.quiet) {
    char buf[256];
    log << "clipstream-fly: " << source->describe() << ", path " << o.path << ", " << total_frames
        << " frames at " << summary["viewport"].get<std::string>() << " on " << context->describe()
        << "\n";
    log << "metric\tvalue\n";
    auto row = [&](const char* name, double v, const char* fmt) {
      std::snprintf(buf, sizeof buf, fmt, v);
      log << name << "\t" << buf << "\n";
    };
    row("frame_ms_mean", mean, "%.2f");
    row("streamer_ms_mean", streamer_mean, "%.2f");
    row("upload_ms_mean", upload_mean, "%.2f");
    row("draw_ms_mean", draw_mean, "%.2f");
    row("frame_ms_p50", percentileOf(frame_ms, 0.5), "%.2f");
    row("frame_ms_p99", percentileOf(frame_ms, 0.99), "%.2f");
    row("frame_ms_max", percentileOf(frame_ms, 1.0), "%.2f");
    row("preload_ms", preload_ms, "%.1f");
    row("tiles_uploaded", double(tiles), "%.0f");
    row("gpu_hit_ratio", summary["gpu_hit_ratio"].get<double>(), "%.4f");
    row("ram_hits", double(final_stats.total.ram_hits), "%.0f");
    row("ram_misses", double(final_stats.total.ram_misses), "%.0f");
    row("bytes_read_MiB", double(final_stats.total.bytes_read) / (1 << 20), "%.1f");
    row("tile_failures", double(final_stats.total.failures + preload_failures), "%.0f");
    if (o.path_hint) {
      row("path_hint_frames", double(final_stats.path_hint_frames), "%.0f");
      row("path_hint_ignored_frames", double(final_stats.path_hint_ignored_frames), "%.0f");
    }
    row("ram_peak_MiB", double(final_stats.ram_peak_bytes) / (1 << 20), "%.1f");
    row("pngs_written", double(writer.written()), "%.0f");
    row("peak_rss_MiB", double(run.peak_rss_bytes) / 1048576.0, "%.1f");
    row("tiles_loaded", double(run.tiles_loaded), "%.0f");
    if (o.reference) {
      row("psnr_mean_db", run.psnr_mean_db, "%.2f");
      row("psnr_min_db", run.psnr_min_db, "%.2f");
      row("frames_below_30db", double(run.frames_below_30db), "%.0f");
      row("identical_frames", double(run.identical_frames), "%.0f");
      row("time_to_sharp_mean_frames", run.time_to_sharp_mean, "%.1f");
      row("time_to_sharp_max_frames", double(run.time_to_sharp_max), "%.0f");
      row("over_fetch_ratio", run.over_fetch_ratio, "%.3f");
      row("frames_with_holes", double(holes_frames), "%.0f");
      if (gt_count > 0) row("ground_truth_psnr_mean_db", gt_sum / gt_count, "%.2f");
    }
    log << "wrote " << o.out_dir << "/frames.csv, frames.json\n";
  }
  return Status::ok();
}

}  // namespace clipstream
