// The clipstream-fly frame loop. See fly.h and docs/renderer.md.
#include <clipstream/renderer/fly.h>

#include "gl.h"

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/flight_path.h>
#include <clipstream/renderer/frame_writer.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/streamer/streamer.h>
#include <clipstream/streamer/tile_source.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <ostream>

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
};

Status writeFileAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return Status::error(ErrorCode::kIo, "cannot write " + tmp);
    out << text;
    if (!out.flush()) return Status::error(ErrorCode::kIo, "cannot write " + tmp);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0)
    return Status::error(ErrorCode::kIo, "cannot rename " + tmp);
  return Status::ok();
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t i = size_t(std::clamp(p, 0.0, 1.0) * double(v.size() - 1) + 0.5);
  return v[i];
}

}  // namespace

Status parseViewport(const std::string& text, Viewport* out) {
  unsigned w = 0, h = 0;
  char tail = 0;
  if (std::sscanf(text.c_str(), "%ux%u%c", &w, &h, &tail) != 2 || w == 0 || h == 0 ||
      w > 16384 || h > 16384)
    return Status::error(ErrorCode::kInvalidArgument,
                         "size \"" + text + "\" is not WIDTHxHEIGHT (e.g. 1280x720)");
  *out = {w, h};
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

Status runFly(const FlyOptions& o, std::ostream& log) {
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
  const PyramidGeometry geometry = source->geometry();

  // Path.
  FlightPath path;
  {
    const auto names = FlightPath::builtinNames();
    Status s = std::find(names.begin(), names.end(), o.path) != names.end()
                   ? FlightPath::builtin(o.path, geometry, &path)
                   : FlightPath::load(o.path, &path);
    if (!s) return s;
  }
  const double speed = o.speed > 0.0 ? o.speed : 1.0;
  const uint32_t frames =
      o.frames > 0 ? o.frames
                   : uint32_t(std::ceil(path.durationS() / (speed * renderer_config::kSimulatedFrameSeconds))) + 1;

  std::error_code ec;
  std::filesystem::create_directories(o.out_dir, ec);
  if (ec) return Status::error(ErrorCode::kIo, "cannot create " + o.out_dir + ": " + ec.message());

  // GL.
  std::unique_ptr<HeadlessContext> context;
  if (Status s = HeadlessContext::create(&context); !s) return s;
  std::unique_ptr<OffscreenTarget> target;
  if (Status s = OffscreenTarget::create(o.viewport, &target); !s) return s;

  StreamerConfig sc;
  sc.ram_budget_bytes = o.cache_mb << 20;
  sc.io_threads = o.io_threads;
  const ClipmapPlan first = planClipmap(geometry, o.viewport, path.sample(0.0), sc.planner);
  std::unique_ptr<ClipmapRenderer> renderer;
  RendererConfig rc{first.clip_tiles, first.pyramid_level, o.buffering};
  if (Status s = ClipmapRenderer::create(geometry, rc, &renderer); !s) return s;
  renderer->setOverlay(o.overlay ? Overlay::kLevels : Overlay::kOff);

  // The coarse pyramid is loaded before the first frame, so every frame
  // has something correct to draw. A tile that fails stays black (counted).
  const auto preload_start = Clock::now();
  uint32_t preload_failures = 0;
  renderer->beginFrame();
  for (uint32_t l = first.pyramid_level; l < geometry.levelCount(); ++l)
    for (uint32_t y = 0; y < geometry.levels[l].tiles_y; ++y)
      for (uint32_t x = 0; x < geometry.levels[l].tiles_x; ++x) {
        auto px = std::make_shared<std::vector<uint8_t>>();
        if (source->fetch({l, x, y}, px.get()).isOk()) renderer->uploadTile({l, x, y}, px);
        else ++preload_failures;
      }
  renderer->endUploads();
  const double preload_ms = msBetween(preload_start, Clock::now());

  Streamer streamer(source, sc);
  FrameWriter writer(renderer_config::kMaxQueuedPngFrames);
  std::vector<FrameRow> rows;
  rows.reserve(frames);
  StreamerStats before = streamer.stats();
  const uint32_t levels = geometry.levelCount();
  const auto run_start = Clock::now();

  for (uint32_t i = 0; i < frames; ++i) {
    FrameRow row;
    row.frame = i;
    row.t_s = i * renderer_config::kSimulatedFrameSeconds * speed;
    const Camera camera = path.sample(row.t_s);
    const auto t0 = Clock::now();
    streamer.update(camera, o.viewport, i * renderer_config::kSimulatedFrameSeconds);
    const FrameHandoff handoff = streamer.takeReady(o.upload_tiles);
    const auto t_streamer = Clock::now();
    renderer->applyHandoff(handoff);
    const auto t_upload = Clock::now();
    target->bind();
    ClipmapRenderer::clearSky();
    renderer->draw(camera, o.viewport);
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

    const bool save = o.save_every > 0 && (i % o.save_every == 0 || i + 1 == frames);
    if (save) {
      std::vector<uint8_t> rgba;
      target->readRgba(&rgba);
      char name[64];
      std::snprintf(name, sizeof name, "/frame_%05u.png", i);
      writer.submit(o.out_dir + name, o.viewport.width_px, o.viewport.height_px, std::move(rgba));
      row.readback_ms = msBetween(t1, Clock::now());
    }

    const StreamerStats now = streamer.stats();
    row.queue_depth = now.queue_depth;
    row.in_flight = now.in_flight;
    row.ram_bytes = now.ram_bytes;
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
  }
  const double run_ms = msBetween(run_start, Clock::now());
  const StreamerStats final_stats = streamer.stats();
  streamer.shutdown();
  Status write_status = writer.close();

  // CSV: one row per frame; per-level columns after the totals.
  std::string csv =
      "frame,t_s,frame_ms,streamer_ms,upload_ms,draw_ms,readback_ms,tiles_uploaded,second_copies,max_texture_lod,"
      "finest_needed,queue_depth,in_flight,ram_bytes,bytes_read,ram_hits,ram_misses,gpu_hits,"
      "gpu_misses";
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
                       {"levels", jl}});
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
  nlohmann::json summary = {
      {"source", source->describe()},
      {"path", o.path},
      {"frames", frames},
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
      {"frame_ms_p50", percentile(frame_ms, 0.5)},
      {"frame_ms_p99", percentile(frame_ms, 0.99)},
      {"frame_ms_max", percentile(frame_ms, 1.0)},
      {"tiles_uploaded", tiles},
      {"gpu_hit_ratio", gpu_hits + gpu_misses ? double(gpu_hits) / double(gpu_hits + gpu_misses) : 1.0},
      {"pngs_written", writer.written()},
      {"pngs_dropped", writer.dropped()},
      {"streamer", nlohmann::json::parse(final_stats.toJson(), nullptr, false)}};
  nlohmann::json doc = {{"summary", summary}, {"frames", jframes}};
  if (Status s = writeFileAtomically(o.out_dir + "/frames.csv", csv); !s) return s;
  if (Status s = writeFileAtomically(o.out_dir + "/frames.json", doc.dump(1) + "\n"); !s) return s;
  if (!write_status) return write_status;

  if (!o.quiet) {
    char buf[256];
    log << "clipstream-fly: " << source->describe() << ", path " << o.path << ", " << frames
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
    row("frame_ms_p50", percentile(frame_ms, 0.5), "%.2f");
    row("frame_ms_p99", percentile(frame_ms, 0.99), "%.2f");
    row("frame_ms_max", percentile(frame_ms, 1.0), "%.2f");
    row("preload_ms", preload_ms, "%.1f");
    row("tiles_uploaded", double(tiles), "%.0f");
    row("gpu_hit_ratio", summary["gpu_hit_ratio"].get<double>(), "%.4f");
    row("ram_hits", double(final_stats.total.ram_hits), "%.0f");
    row("ram_misses", double(final_stats.total.ram_misses), "%.0f");
    row("bytes_read_MiB", double(final_stats.total.bytes_read) / (1 << 20), "%.1f");
    row("tile_failures", double(final_stats.total.failures + preload_failures), "%.0f");
    row("ram_peak_MiB", double(final_stats.ram_peak_bytes) / (1 << 20), "%.1f");
    row("pngs_written", double(writer.written()), "%.0f");
    log << "wrote " << o.out_dir << "/frames.csv, frames.json\n";
  }
  return Status::ok();
}

}  // namespace clipstream
