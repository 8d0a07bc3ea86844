// Report formats of a measured flight. See report.h and docs/renderer.md.
#include <clipstream/eval/report.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ostream>

namespace clipstream {
namespace {

std::string dbText(bool measured, double db) {
  if (!measured) return "";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f", db);
  return buf;
}

double mib(uint64_t bytes) { return double(bytes) / 1048576.0; }

struct Means {
  double streamer = 0.0, upload = 0.0, draw = 0.0;
};

Means meansOf(const FlightRun& run) {
  Means m;
  const double n = double(std::max<size_t>(run.frames.size(), 1));
  for (const FlightRunFrame& f : run.frames) {
    m.streamer += f.sample.streamer_ms / n;
    m.upload += f.sample.upload_ms / n;
    m.draw += f.sample.draw_ms / n;
  }
  return m;
}

std::string viewportText(const Viewport& v) {
  return std::to_string(v.width_px) + "x" + std::to_string(v.height_px);
}

nlohmann::json remoteJson(const RemoteStats& r) {
  return {{"http_requests", r.requests},         {"http_retries", r.retries},
          {"http_bytes", r.bytes},               {"http_failures", r.failures},
          {"http_connections", r.connections},   {"http2_requests", r.http2_requests},
          {"disk_cache_hits", r.disk_cache_hits}, {"disk_cache_misses", r.disk_cache_misses},
          {"disk_cache_dropped", r.disk_cache_dropped},
          {"disk_cache_folders_refused", r.disk_cache_folders_refused}};
}

// Whether the run read a store over HTTP (RemoteStats are all zero otherwise).
bool readRemotely(const FlightRun& run) { return run.remote.requests > 0 || run.remote.disk_cache_hits > 0; }

// The RAM budget as the reports name it: cache_mb, whole MiB.
uint64_t cacheMib(const RunDescription& d) { return d.streamer.ram_budget_bytes >> 20; }

// A summary.tsv number: four decimals, 0 for a value that is not finite.
std::string num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.4f", std::isfinite(v) ? v : 0.0);
  return std::string(b);
}

}  // namespace

std::string framesCsv(const FlightRun& run, uint32_t levels) {
  std::string csv =
      "frame,t_s,frame_ms,streamer_ms,upload_ms,draw_ms,readback_ms,tiles_uploaded,second_copies,max_texture_lod,"
      "finest_needed,queue_depth,in_flight,ram_bytes,bytes_read,ram_hits,ram_misses,gpu_hits,"
      "gpu_misses,tiles_loaded,cut,psnr_db,max_abs_error,hole_pixels,gt_psnr_db,gt_max_abs_error,"
      "terrain_triangles,terrain_rings,terrain_finest_level,height_tiles_uploaded,ground_height,"
      "geo_error_mean_px,geo_error_p95_px,geo_error_max_px,geo_coverage_pixels,geo_silhouette_mean_px,"
      "geo_silhouette_p95_px,terrain_error_px,terrain_select_ms";
  for (uint32_t l = 0; l < levels; ++l)
    for (const char* f : {"ram_hits", "ram_misses", "gpu_hits", "gpu_misses"})
      csv += ",L" + std::to_string(l) + "_" + f;
  csv += "\n";
  for (const FlightRunFrame& f : run.frames) {
    const FrameSample& r = f.sample;
    char buf[512];
    std::snprintf(buf, sizeof buf, "%u,%.4f,%.3f,%.3f,%.3f,%.3f,%.3f,%u,%u,%u,%u,%llu,%llu,%llu,%llu,%llu,%llu,%u,%u",
                  r.frame, f.t_s, r.frame_ms, r.streamer_ms, r.upload_ms, r.draw_ms, f.readback_ms,
                  r.tiles_uploaded,
                  r.second_copies, r.max_texture_lod, r.finest_needed, (unsigned long long)r.queue_depth,
                  (unsigned long long)r.in_flight, (unsigned long long)r.ram_bytes,
                  (unsigned long long)r.total.bytes_read, (unsigned long long)r.total.ram_hits,
                  (unsigned long long)r.total.ram_misses, r.total.gpu_hits, r.total.gpu_misses);
    csv += buf;
    const AccuracyFrame& a = f.accuracy;
    csv += "," + std::to_string(r.tiles_loaded) + "," + (r.cut ? "1" : "0") + "," +
           dbText(a.measured, a.error.psnr_db) + "," + (a.measured ? std::to_string(a.error.max_abs_error) : "") +
           "," + (a.measured ? std::to_string(a.hole_pixels) : "") + "," +
           dbText(a.ground_truth_measured, a.ground_truth.psnr_db) + "," +
           (a.ground_truth_measured ? std::to_string(a.ground_truth.max_abs_error) : "");
    std::snprintf(buf, sizeof buf, ",%llu,%u,%u,%u,%.3f", (unsigned long long)r.terrain_triangles,
                  r.terrain_rings, r.terrain_finest_level, r.height_tiles_uploaded, r.ground_height);
    csv += buf;
    if (f.geometry.measured) {
      std::snprintf(buf, sizeof buf, ",%.4f,%.4f,%.4f", f.geometry.mean_px, f.geometry.p95_px, f.geometry.max_px);
      csv += buf;
    } else {
      csv += ",,,";
    }
    if (f.geometry.coverage) {
      std::snprintf(buf, sizeof buf, ",%u,%.4f,%.4f", f.geometry.coverage_pixels, f.geometry.silhouette_mean_px,
                    f.geometry.silhouette_p95_px);
      csv += buf;
    } else {
      csv += ",,,";
    }
    // The quadtree's achieved error bound (0 for the other methods) and selection time.
    std::snprintf(buf, sizeof buf, ",%.3f,%.3f", r.terrain_error_px, r.terrain_select_ms);
    csv += buf;
    for (uint32_t l = 0; l < levels; ++l) {
      const LevelFrame lf = l < r.levels.size() ? r.levels[l] : LevelFrame{};
      csv += "," + std::to_string(lf.ram_hits) + "," + std::to_string(lf.ram_misses) + "," +
             std::to_string(lf.gpu_hits) + "," + std::to_string(lf.gpu_misses);
    }
    csv += "\n";
  }
  return csv;
}

namespace {
// Frames in which a tile the frame samples got no page (kPaged).
uint64_t pagesShortFrames(const FlightRun& run) {
  uint64_t n = 0;
  for (const FlightRunFrame& f : run.frames) n += f.sample.pages_short > 0 ? 1 : 0;
  return n;
}
// The most pages a recorded frame needed (kPaged): the working set.
uint32_t pagesWantedMax(const FlightRun& run) {
  uint32_t n = 0;
  for (const FlightRunFrame& f : run.frames) n = std::max(n, f.sample.pages_wanted);
  return n;
}
// One recorded frame's object in frames.json: its timings and counters,
// then what was measured of it (geometry, terrain, accuracy) when it was.
nlohmann::json frameJson(const FlightRunFrame& f) {
  const FrameSample& r = f.sample;
  nlohmann::json jl = nlohmann::json::array();
  for (const LevelFrame& lf : r.levels)
    jl.push_back({{"ram_hits", lf.ram_hits}, {"ram_misses", lf.ram_misses}, {"gpu_hits", lf.gpu_hits},
                  {"gpu_misses", lf.gpu_misses}, {"bytes_read", lf.bytes_read}});
  nlohmann::json j = {{"frame", r.frame}, {"t_s", f.t_s}, {"frame_ms", r.frame_ms},
                      {"streamer_ms", r.streamer_ms}, {"upload_ms", r.upload_ms},
                      {"draw_ms", r.draw_ms}, {"readback_ms", f.readback_ms},
                      {"tiles_uploaded", r.tiles_uploaded},
                      {"second_copies", r.second_copies}, {"max_texture_lod", r.max_texture_lod},
                      {"finest_needed", r.finest_needed}, {"queue_depth", r.queue_depth},
                      {"in_flight", r.in_flight}, {"ram_bytes", r.ram_bytes},
                      {"bytes_read", r.total.bytes_read}, {"ram_hits", r.total.ram_hits},
                      {"ram_misses", r.total.ram_misses}, {"gpu_hits", r.total.gpu_hits},
                      {"gpu_misses", r.total.gpu_misses}, {"tiles_loaded", r.tiles_loaded},
                      {"cut", r.cut}, {"levels", jl}};
  if (f.geometry.measured) {
    j["geo_error_mean_px"] = f.geometry.mean_px;
    j["geo_error_p95_px"] = f.geometry.p95_px;
    j["geo_error_max_px"] = f.geometry.max_px;
    if (f.geometry.coverage) {
      j["geo_coverage_pixels"] = f.geometry.coverage_pixels;
      j["geo_silhouette_pixels"] = f.geometry.silhouette_pixels;
      j["geo_silhouette_mean_px"] = f.geometry.silhouette_mean_px;
      j["geo_silhouette_p95_px"] = f.geometry.silhouette_p95_px;
      j["geo_silhouette_max_px"] = f.geometry.silhouette_max_px;
    }
    j["texture_agree_pixels"] = f.terrain_agree_pixels;
    j["texture_agree_mismatched"] = f.terrain_agree_mismatched;
  }
  if (r.terrain_rings > 0 || r.height_tiles_uploaded > 0) {
    j["terrain_triangles"] = r.terrain_triangles;
    j["terrain_rings"] = r.terrain_rings;
    j["terrain_finest_level"] = r.terrain_finest_level;
    j["terrain_error_px"] = r.terrain_error_px;
    j["terrain_select_ms"] = r.terrain_select_ms;
    j["height_tiles_uploaded"] = r.height_tiles_uploaded;
    j["ground_height"] = r.ground_height;
  }
  if (f.accuracy.measured) {
    j["psnr_db"] = f.accuracy.error.psnr_db;
    j["max_abs_error"] = f.accuracy.error.max_abs_error;
    j["hole_pixels"] = f.accuracy.hole_pixels;
  }
  if (f.accuracy.ground_truth_measured) {
    j["gt_psnr_db"] = f.accuracy.ground_truth.psnr_db;
    j["gt_max_abs_error"] = f.accuracy.ground_truth.max_abs_error;
  }
  return j;
}

// The run's "accuracy" object in frames.json: the summary's accuracy
// fields, the streamer's settings and the terrain measurements.
nlohmann::json accuracyJson(const FlightRun& run, const RunDescription& d) {
  const RunSummary& s = run.summary;
  nlohmann::json acc = nlohmann::json::parse(s.toJson(), nullptr, false);
  acc["reference"] = d.reference;
  acc["reference_tile_format"] = tileContentName(d.reference_tile_format);
  acc["frames_with_holes"] = run.frames_with_holes;
  acc["ground_truth_frames"] = run.ground_truth_frames;
  acc["ground_truth_psnr_mean_db"] = run.ground_truth_psnr_mean_db;
  acc["ground_truth_psnr_min_db"] = run.ground_truth_psnr_min_db;
  acc["resizes"] = run.resizes;
  acc["warmup_frames"] = d.warmup_frames;
  acc["warmup_tiles_loaded"] = run.warmup_loads;
  acc["ram_peak_bytes"] = run.streamer.ram_peak_bytes;
  acc["ram_budget_bytes"] = run.streamer.ram_budget_bytes;
  acc["tile_failures"] = run.tile_failures;
  const DeterministicIo& io = d.streamer.deterministic_io;
  acc["throttle"] = d.streamer.throttle;
  acc["prefetch"] = d.streamer.prefetch;
  acc["frustum_priority"] = d.streamer.frustum_priority;
  acc["plan_scope"] = d.streamer.planner.scope == PlanScope::kSampled ? "sampled" : "window";
  acc["path_hint"] = d.path_hint;
  acc["io_mode"] = io.enabled ? "deterministic" : "real-time";
  acc["io_reads_per_frame"] = io.enabled ? io.reads_per_frame : 0;
  acc["io_latency_frames"] = io.enabled ? io.latency_frames : 0;
  acc["path_hint_frames"] = run.streamer.path_hint_frames;
  acc["path_hint_ignored_frames"] = run.streamer.path_hint_ignored_frames;
  acc["upload_tiles"] = d.upload_tiles;
  acc["cache_mb"] = cacheMib(d);
  acc["terrain"] = run.height_texture_bytes > 0;
  acc["terrain_triangles_mean"] = run.terrain_triangles_mean;
  acc["terrain_method"] = run.terrain_method;
  acc["terrain_lighting"] = run.terrain_lighting;
  acc["reference_lighting"] = run.reference_lighting;
  acc["terrain_error_px_mean"] = run.terrain_error_px_mean;
  acc["terrain_error_px_max"] = run.terrain_error_px_max;
  acc["render_cpu_ms_mean"] = run.render_cpu_ms_mean;
  acc["judged_triangles_mean"] = run.judged_triangles_mean;
  acc["fewest_triangles_mean"] = run.fewest_triangles_mean;
  acc["change_pairs"] = run.change_pairs;
  acc["change_mean"] = run.change_mean;
  acc["reference_change_mean"] = run.reference_change_mean;
  acc["geometry_change_mean_px"] = run.geometry_change_mean;
  acc["geometry_change_max_px"] = run.geometry_change_max;
  acc["plans_on_terrain"] = run.plans_on_terrain;
  acc["seen_level_frames"] = run.seen_frames;
  acc["needed_coarser_frames"] = run.needed_coarser_frames;
  acc["needed_finer_frames"] = run.needed_finer_frames;
  acc["height_texture_bytes"] = run.height_texture_bytes;
  acc["geometry_frames"] = run.geometry_frames;
  acc["geo_error_mean_px"] = run.geometry_mean_px;
  acc["geo_error_p95_px"] = run.geometry_p95_px;
  acc["geo_error_max_px"] = run.geometry_max_px;
  acc["geo_coverage_pixels_mean"] = run.coverage_pixels_mean;
  acc["geo_error_data_mean_px"] = run.geometry_data_mean_px;
  acc["geo_error_data_p95_px"] = run.geometry_data_p95_px;
  acc["texel_density_median"] = run.texel_density_median;
  acc["texel_density_p5"] = run.texel_density_p5;
  acc["detail_texel_density_median"] = run.detail_texel_density_median;
  acc["detail_texel_density_p5"] = run.detail_texel_density_p5;
  acc["geo_silhouette_mean_px"] = run.silhouette_mean_px;
  acc["geo_silhouette_p95_px"] = run.silhouette_p95_px;
  acc["geo_silhouette_max_px"] = run.silhouette_max_px;
  acc["geometry_rest_frames"] = run.geometry_rest_frames;
  acc["geo_error_rest_mean_px"] = run.geometry_rest_mean_px;
  acc["geo_error_rest_p95_px"] = run.geometry_rest_p95_px;
  acc["geo_error_rest_max_px"] = run.geometry_rest_max_px;
  acc["texture_agree_pixels_rest"] = run.terrain_rest_agree_pixels;
  acc["texture_agree_mismatched_rest"] = run.terrain_rest_agree_mismatched;
  return acc;
}

}  // namespace

std::string framesJson(const FlightRun& run, const RunDescription& d) {
  nlohmann::json jframes = nlohmann::json::array();
  for (const FlightRunFrame& f : run.frames) jframes.push_back(frameJson(f));
  const RunSummary& s = run.summary;
  const nlohmann::json acc = accuracyJson(run, d);
  const Means m = meansOf(run);
  nlohmann::json summary = {
      {"source", run.source},
      {"path", d.path},
      {"frames", run.frames.size()},
      {"viewport", viewportText(d.viewport)},
      {"speed", d.speed},
      {"buffering", bufferingName(d.buffering)},
      {"clip_tiles", run.clip_tiles},
      {"pyramid_level", run.pyramid_level},
      {"gl", run.gl},
      {"tile_format", tileContentName(run.tile_content)},
      {"gpu_texture_bytes", run.texture_bytes.total()},
      {"gpu_stack_bytes", run.texture_bytes.stack},
      {"gpu_usable_bytes", run.texture_bytes.usable},
      {"texture_memory", textureMemoryName(run.texture_memory)},
      {"pool_pages", run.pool_pages},
      {"frames_pages_short", pagesShortFrames(run)},
      {"pool_pages_wanted_max", pagesWantedMax(run)},
      {"preload_ms", run.preload_ms},
      {"preload_failures", run.preload_failures},
      {"run_ms", run.run_ms},
      {"frame_ms_mean", s.frame_ms_mean},
      {"streamer_ms_mean", m.streamer},
      {"upload_ms_mean", m.upload},
      {"draw_ms_mean", m.draw},
      {"frame_ms_p50", s.frame_ms_p50},
      {"frame_ms_p99", s.frame_ms_p99},
      {"frame_ms_max", s.frame_ms_max},
      {"tiles_uploaded", s.tiles_uploaded},
      {"gpu_hit_rate", s.gpu_hit_rate},
      {"render_thread_fetches", run.render_thread_fetches},
      {"pngs_written", d.pngs_written},
      {"pngs_dropped", d.pngs_dropped},
      {"remote", remoteJson(run.remote)},
      {"streamer", nlohmann::json::parse(run.streamer.toJson(), nullptr, false)},
      {"accuracy", acc}};
  return nlohmann::json{{"summary", summary}, {"frames", jframes}}.dump(1) + "\n";
}

namespace {
// summary.tsv's coverage, silhouette and geometry-only change columns
// (empty when not measured).
std::vector<std::pair<std::string, std::string>> terrainMeasureColumns(const FlightRun& run) {
  auto judged = [&](double v) { return run.geometry_frames ? num(v) : std::string(); };
  auto paired = [&](double v) { return run.change_pairs ? num(v) : std::string(); };
  return {{"geo_coverage_pixels_mean", judged(run.coverage_pixels_mean)},
          {"geo_silhouette_mean_px", judged(run.silhouette_mean_px)},
          {"geo_silhouette_p95_px", judged(run.silhouette_p95_px)},
          {"geo_silhouette_max_px", judged(run.silhouette_max_px)},
          {"geometry_change_mean_px", paired(run.geometry_change_mean)},
          {"geometry_change_max_px", paired(run.geometry_change_max)},
          {"geo_error_data_mean_px", judged(run.geometry_data_mean_px)},
          {"geo_error_data_p95_px", judged(run.geometry_data_p95_px)},
          {"texel_density_median", judged(run.texel_density_median)},
          {"texel_density_p5", judged(run.texel_density_p5)},
          {"detail_texel_density_median", judged(run.detail_texel_density_median)},
          {"detail_texel_density_p5", judged(run.detail_texel_density_p5)}};
}
}  // namespace

// Long: one column a line, in the file's order; splitting the list would only scatter it.
std::string summaryTsv(const FlightRun& run, const RunDescription& d) {
  const RunSummary& s = run.summary;
  std::string keys, values;
  auto add = [&](const std::string& k, const std::string& v) {
    keys += (keys.empty() ? "" : "\t") + k;
    values += (values.empty() ? "" : "\t") + v;
  };
  add("frames", std::to_string(s.frames));
  add("speed", num(d.speed));
  add("upload_tiles", std::to_string(d.upload_tiles));
  add("cache_mb", std::to_string(cacheMib(d)));
  // Accuracy: empty when no frame was compared with the reference.
  const bool judged = s.measured_frames > 0;
  auto judgedNum = [&](double v) { return judged ? num(v) : std::string(); };
  auto judgedCount = [&](int64_t v) { return judged ? std::to_string(v) : std::string(); };
  add("psnr_mean_db", judgedNum(s.psnr_mean_db));
  add("psnr_min_db", judgedNum(s.psnr_min_db));
  add("frames_below_30db", judgedCount(s.frames_below_30db));
  add("identical_frames", judgedCount(s.identical_frames));
  add("time_to_sharp_mean", judgedNum(s.time_to_sharp_mean));
  add("time_to_sharp_max", judgedCount(s.time_to_sharp_max));
  add("frame_ms_mean", num(s.frame_ms_mean));
  add("frame_ms_p50", num(s.frame_ms_p50));
  add("frame_ms_p99", num(s.frame_ms_p99));
  add("frame_ms_max", num(s.frame_ms_max));
  add("bytes_read", std::to_string(s.bytes_read));
  add("tiles_uploaded", std::to_string(s.tiles_uploaded));
  add("tiles_loaded", std::to_string(s.tiles_loaded));
  add("tiles_sampled", std::to_string(s.tiles_sampled));
  add("over_fetch_ratio", num(s.over_fetch_ratio));
  add("tiles_loaded_stack", std::to_string(s.tiles_loaded_stack));
  add("tiles_sampled_stack", std::to_string(s.tiles_sampled_stack));
  add("over_fetch_stack_ratio", num(s.over_fetch_stack_ratio));
  add("height_tiles_loaded_stack", std::to_string(s.height_tiles_loaded_stack));
  add("height_tiles_sampled_stack", std::to_string(s.height_tiles_sampled_stack));
  add("height_over_fetch_stack_ratio", num(s.height_over_fetch_stack_ratio));
  add("ram_hit_rate", num(s.ram_hit_rate));
  add("gpu_hit_rate", num(s.gpu_hit_rate));
  add("peak_rss_mib", num(mib(s.peak_rss_bytes)));
  add("gpu_texture_mib", num(mib(run.texture_bytes.total())));
  add("tile_format", tileContentName(run.tile_content));
  // Per tile: the renderer's texture work over the tiles it uploaded, and
  // the loaders' decode (and transcode) time over the tiles they loaded.
  const Means m = meansOf(run);
  add("upload_ms_per_tile",
      num(s.tiles_uploaded ? m.upload * double(run.frames.size()) / double(s.tiles_uploaded) : 0.0));
  add("decode_ms_per_tile", num(run.streamer.total.loads
                                    ? run.streamer.decode_ms_total / double(run.streamer.total.loads)
                                    : 0.0));
  add("ram_peak_mib", num(mib(run.streamer.ram_peak_bytes)));
  add("ram_budget_mib", num(mib(run.streamer.ram_budget_bytes)));
  add("frames_with_holes", judgedCount(run.frames_with_holes));
  // Empty: not measured.
  add("ground_truth_psnr_mean_db", run.ground_truth_frames ? num(run.ground_truth_psnr_mean_db) : std::string());
  add("tile_failures", std::to_string(run.tile_failures));
  add("terrain_triangles_mean", num(run.terrain_triangles_mean));
  add("height_texture_mib", num(mib(run.height_texture_bytes)));
  add("terrain_method", run.terrain_method);
  add("render_cpu_ms_mean", num(run.render_cpu_ms_mean));
  add("judged_triangles_mean", run.geometry_frames ? num(run.judged_triangles_mean) : std::string());
  add("fewest_triangles_mean", run.fewest_triangles_mean > 0 ? num(run.fewest_triangles_mean) : std::string());
  add("change_mean", run.change_pairs ? num(run.change_mean) : std::string());
  add("reference_change_mean", run.change_pairs ? num(run.reference_change_mean) : std::string());
  add("geo_error_mean_px", run.geometry_frames ? num(run.geometry_mean_px) : std::string());
  add("geo_error_p95_px", run.geometry_frames ? num(run.geometry_p95_px) : std::string());
  add("geo_error_max_px", run.geometry_frames ? num(run.geometry_max_px) : std::string());
  add("geo_error_rest_mean_px", run.geometry_rest_frames ? num(run.geometry_rest_mean_px) : std::string());
  add("geo_error_rest_p95_px", run.geometry_rest_frames ? num(run.geometry_rest_p95_px) : std::string());
  add("texture_agree_pixels_rest",
      run.geometry_rest_frames ? std::to_string(run.terrain_rest_agree_pixels) : std::string());
  add("texture_agree_mismatched_rest",
      run.geometry_rest_frames ? std::to_string(run.terrain_rest_agree_mismatched) : std::string());
  add("needed_coarser_frames", run.seen_frames ? std::to_string(run.needed_coarser_frames) : std::string());
  add("needed_finer_frames", run.seen_frames ? std::to_string(run.needed_finer_frames) : std::string());
  // Last, so scripts reading columns by position before it see no change.
  const DeterministicIo& io = d.streamer.deterministic_io;
  add("io_mode", io.enabled ? "deterministic" : "real-time");
  add("io_reads_per_frame", io.enabled ? std::to_string(io.reads_per_frame) : "0");
  add("io_latency_frames", io.enabled ? std::to_string(io.latency_frames) : "0");
  add("pngs_written", std::to_string(d.pngs_written));
  add("pngs_dropped", std::to_string(d.pngs_dropped));
  add("texture_memory", textureMemoryName(run.texture_memory));
  add("pool_pages", std::to_string(run.pool_pages));
  add("frames_pages_short", std::to_string(pagesShortFrames(run)));
  add("pool_pages_wanted_max", std::to_string(pagesWantedMax(run)));
  // A store read over HTTP: the requests, bytes and retries it cost, and
  // what the disk cache served. Empty for local stores.
  const bool remote = readRemotely(run);
  auto remoteCount = [&](uint64_t v) { return remote ? std::to_string(v) : std::string(); };
  add("http_requests", remoteCount(run.remote.requests));
  add("http_bytes", remoteCount(run.remote.bytes));
  add("http_retries", remoteCount(run.remote.retries));
  add("disk_cache_hits", remoteCount(run.remote.disk_cache_hits));
  add("disk_cache_misses", remoteCount(run.remote.disk_cache_misses));
  for (const auto& [k, v] : terrainMeasureColumns(run)) add(k, v);
  // The quadtree's error bound met (its --terrain-error, or more where the
  // triangle budget bound); empty for the other methods.
  const bool quadtree = run.terrain_error_px_max > 0;
  add("terrain_error_px_mean", quadtree ? num(run.terrain_error_px_mean) : std::string());
  add("terrain_error_px_max", quadtree ? num(run.terrain_error_px_max) : std::string());
  return keys + "\n" + values + "\n";
}

namespace {

// One row of the summary table: NAME, a tab, the value as `fmt` prints it.
void printRow(std::ostream& out, const char* name, double v, const char* fmt) {
  char buf[256];
  std::snprintf(buf, sizeof buf, fmt, v);
  out << name << "\t" << buf << "\n";
}

// The summary table's rows of a flight over terrain: triangles, geometric
// error, frame-to-frame change, the rest frames and the levels seen.
void printTerrainRows(std::ostream& out, const FlightRun& run) {
  const RunSummary& s = run.summary;
  auto row = [&](const char* name, double v, const char* fmt) { printRow(out, name, v, fmt); };
  row("terrain_triangles_mean", run.terrain_triangles_mean, "%.0f");
  if (run.terrain_error_px_max > 0) {
    // The quadtree's error bound met: its --terrain-error, or more where
    // the triangle budget bound.
    row("terrain_error_px_mean", run.terrain_error_px_mean, "%.2f");
    row("terrain_error_px_max", run.terrain_error_px_max, "%.2f");
  }
  row("render_cpu_ms_mean", run.render_cpu_ms_mean, "%.2f");
  row("height_texture_mib", mib(run.height_texture_bytes), "%.1f");
  if (run.geometry_frames > 0) {
    row("geo_error_mean_px", run.geometry_mean_px, "%.3f");
    row("geo_error_p95_px", run.geometry_p95_px, "%.3f");
    row("geo_error_max_px", run.geometry_max_px, "%.2f");
    // Pixels that are terrain in one frame and sky in the other (counted
    // above), and the distance between the two outlines.
    row("geo_coverage_pixels_mean", run.coverage_pixels_mean, "%.1f");
    row("geo_silhouette_mean_px", run.silhouette_mean_px, "%.3f");
    row("geo_silhouette_p95_px", run.silhouette_p95_px, "%.3f");
    // Level-0 texels across a pixel (median, 5th percentile), and with the
    // detail textures where the colour is magnified.
    if (run.geometry_data_mean_px > 0) {
      // Synthesized relief: the same frames against the DEM's own surface.
      row("geo_error_data_mean_px", run.geometry_data_mean_px, "%.3f");
      row("geo_error_data_p95_px", run.geometry_data_p95_px, "%.3f");
    }
    row("texel_density_median", run.texel_density_median, "%.3f");
    row("texel_density_p5", run.texel_density_p5, "%.3f");
    row("detail_texel_density_median", run.detail_texel_density_median, "%.3f");
    row("detail_texel_density_p5", run.detail_texel_density_p5, "%.3f");
    // Triangles of the judged frames against the fewest that model them
    // within their own p95 (FewestTriangles).
    row("judged_triangles_mean", run.judged_triangles_mean, "%.0f");
    if (run.fewest_triangles_mean > 0) row("fewest_triangles_mean", run.fewest_triangles_mean, "%.0f");
  }
  if (run.change_pairs > 0) {
    row("change_mean", run.change_mean, "%.3f");
    row("reference_change_mean", run.reference_change_mean, "%.3f");
    row("geometry_change_mean_px", run.geometry_change_mean, "%.4f");
    row("geometry_change_max_px", run.geometry_change_max, "%.4f");
  }
  if (run.geometry_rest_frames > 0) {
    row("geo_error_rest_mean_px", run.geometry_rest_mean_px, "%.3f");
    row("geo_error_rest_p95_px", run.geometry_rest_p95_px, "%.3f");
    // Where the geometry agrees with the full-resolution mesh to the bit,
    // the texture must too.
    row("texture_agree_pixels_rest", double(run.terrain_rest_agree_pixels), "%.0f");
    row("texture_agree_mismatched_rest", double(run.terrain_rest_agree_mismatched), "%.0f");
  }
  if (s.height_tiles_sampled_stack > 0) {
    row("height_tiles_loaded_stack", double(s.height_tiles_loaded_stack), "%.0f");
    row("height_tiles_sampled_stack", double(s.height_tiles_sampled_stack), "%.0f");
    row("height_over_fetch_stack_ratio", s.height_over_fetch_stack_ratio, "%.3f");
  }
  if (run.seen_frames > 0) {
    row("over_fetch_ratio", s.over_fetch_ratio, "%.3f");
    row("over_fetch_stack_ratio", s.over_fetch_stack_ratio, "%.3f");
    row("needed_coarser_frames", double(run.needed_coarser_frames), "%.0f");
    row("needed_finer_frames", double(run.needed_finer_frames), "%.0f");
  }
}

}  // namespace

void printSummary(std::ostream& out, const FlightRun& run, const RunDescription& d) {
  const RunSummary& s = run.summary;
  const Means m = meansOf(run);
  out << "clipstream-fly: " << run.source << ", path " << d.path << ", " << run.frames.size()
      << " frames at " << viewportText(d.viewport) << " on " << run.gl << "\n";
  out << "metric\tvalue\n";
  auto row = [&](const char* name, double v, const char* fmt) { printRow(out, name, v, fmt); };
  row("frame_ms_mean", s.frame_ms_mean, "%.2f");
  row("streamer_ms_mean", m.streamer, "%.2f");
  row("upload_ms_mean", m.upload, "%.2f");
  row("draw_ms_mean", m.draw, "%.2f");
  row("frame_ms_p50", s.frame_ms_p50, "%.2f");
  row("frame_ms_p99", s.frame_ms_p99, "%.2f");
  row("frame_ms_max", s.frame_ms_max, "%.2f");
  row("preload_ms", run.preload_ms, "%.1f");
  row("tiles_uploaded", double(s.tiles_uploaded), "%.0f");
  row("gpu_hit_rate", s.gpu_hit_rate, "%.4f");
  row("ram_hits", double(run.streamer.total.ram_hits), "%.0f");
  row("ram_misses", double(run.streamer.total.ram_misses), "%.0f");
  row("gpu_reentries", double(run.streamer.total.gpu_reentries), "%.0f");
  row("bytes_read_mib", mib(run.streamer.total.bytes_read), "%.1f");
  row("tile_failures", double(run.tile_failures), "%.0f");
  if (d.path_hint) {
    row("path_hint_frames", double(run.streamer.path_hint_frames), "%.0f");
    row("path_hint_ignored_frames", double(run.streamer.path_hint_ignored_frames), "%.0f");
  }
  row("ram_peak_mib", mib(run.streamer.ram_peak_bytes), "%.1f");
  row("pngs_written", double(d.pngs_written), "%.0f");
  if (d.pngs_dropped > 0) row("pngs_dropped", double(d.pngs_dropped), "%.0f");
  if (readRemotely(run)) {
    row("http_requests", double(run.remote.requests), "%.0f");
    row("http_mib", mib(run.remote.bytes), "%.1f");
    row("http_retries", double(run.remote.retries), "%.0f");
    row("disk_cache_hits", double(run.remote.disk_cache_hits), "%.0f");
    row("disk_cache_misses", double(run.remote.disk_cache_misses), "%.0f");
  }
  row("peak_rss_mib", mib(s.peak_rss_bytes), "%.1f");
  out << "tile_format\t" << tileContentName(run.tile_content) << "\n";
  const DeterministicIo& io = d.streamer.deterministic_io;
  out << "io_mode\t"
      << (io.enabled ? "deterministic, " + std::to_string(io.reads_per_frame) + " reads/frame, " +
                           std::to_string(io.latency_frames) + " frames latency"
                     : std::string("real-time"))
      << "\n";
  row("gpu_texture_bytes", double(run.texture_bytes.total()), "%.0f");
  row("gpu_texture_mib", mib(run.texture_bytes.total()), "%.1f");
  out << "texture_memory\t" << textureMemoryName(run.texture_memory) << "\n";
  if (run.pool_pages > 0) {
    row("pool_pages", double(run.pool_pages), "%.0f");
    row("frames_pages_short", double(pagesShortFrames(run)), "%.0f");
    row("pool_pages_wanted_max", double(pagesWantedMax(run)), "%.0f");
  }
  row("tiles_loaded", double(s.tiles_loaded), "%.0f");
  if (run.height_texture_bytes > 0) printTerrainRows(out, run);
  if (d.reference) {
    row("psnr_mean_db", s.psnr_mean_db, "%.2f");
    row("psnr_min_db", s.psnr_min_db, "%.2f");
    row("frames_below_30db", double(s.frames_below_30db), "%.0f");
    row("identical_frames", double(s.identical_frames), "%.0f");
    row("time_to_sharp_mean", s.time_to_sharp_mean, "%.1f");
    row("time_to_sharp_max", double(s.time_to_sharp_max), "%.0f");
    row("over_fetch_ratio", s.over_fetch_ratio, "%.3f");
    row("over_fetch_stack_ratio", s.over_fetch_stack_ratio, "%.3f");
    row("frames_with_holes", double(run.frames_with_holes), "%.0f");
    if (run.ground_truth_frames > 0) row("ground_truth_psnr_mean_db", run.ground_truth_psnr_mean_db, "%.2f");
  }
}

int restFramesToIdentical(const FlightRun& run, uint32_t moving_frames) {
  for (size_t i = moving_frames; i < run.frames.size(); ++i)
    if (run.frames[i].accuracy.measured && run.frames[i].accuracy.error.max_abs_error == 0)
      return int(i - moving_frames);
  return -1;
}

std::string scenarioJsonLine(const FlightRun& run, const ScenarioDescription& scenario) {
  nlohmann::json j = nlohmann::json::parse(run.summary.toJson(), nullptr, false);
  j["scenario"] = scenario.name;
  j["moving_frames"] = scenario.moving_frames;
  j["rest_frames"] = scenario.rest_frames;
  j["rest_frames_to_identical"] = restFramesToIdentical(run, scenario.moving_frames);
  j["render_thread_fetches"] = run.render_thread_fetches;
  j["ram_peak_bytes"] = run.streamer.ram_peak_bytes;
  j["ram_budget_bytes"] = run.streamer.ram_budget_bytes;
  j["rss_after_warmup_bytes"] = run.rss_after_warmup_bytes;
  j["rss_end_bytes"] = run.rss_end_bytes;
  j["garbage_checked_frames"] = run.garbage_checked_frames;
  j["garbage_pixels_max"] = run.garbage_pixels_max;
  j["result"] = scenario.passed ? "pass" : "FAIL";
  return j.dump() + "\n";
}

}  // namespace clipstream
