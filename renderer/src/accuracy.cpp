// Image error, run summaries and the ideal reference. See accuracy.h and
// docs/accuracy.md.
#include <clipstream/renderer/accuracy.h>

#include "gl.h"

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/renderer/reference.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>

namespace clipstream {

FrameError compareFrames(const std::vector<uint8_t>& streamed, const std::vector<uint8_t>& reference) {
  FrameError e;
  if (streamed.size() != reference.size() || streamed.empty()) {
    e.psnr_db = 0.0;
    e.max_abs_error = 255;
    return e;
  }
  double sum = 0.0;
  int worst = 0;
  const size_t pixels = streamed.size() / 4;
  for (size_t i = 0; i < pixels; ++i)
    for (int c = 0; c < 3; ++c) {
      const int d = int(streamed[i * 4 + c]) - int(reference[i * 4 + c]);
      sum += double(d) * double(d);
      worst = std::max(worst, std::abs(d));
    }
  e.max_abs_error = worst;
  if (sum == 0.0) {
    e.psnr_db = kIdenticalPsnrDb;
  } else {
    const double mse = sum / double(pixels * 3);
    e.psnr_db = std::min(kIdenticalPsnrDb, 10.0 * std::log10(255.0 * 255.0 / mse));
  }
  return e;
}

double percentileOf(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const size_t i = size_t(std::clamp(p, 0.0, 1.0) * double(values.size() - 1) + 0.5);
  return values[std::min(i, values.size() - 1)];
}

RunSummary summarizeRun(const std::vector<FrameRecord>& frames, uint64_t tiles_sampled,
                        uint64_t peak_rss_bytes) {
  RunSummary s;
  s.frames = uint32_t(frames.size());
  s.peak_rss_bytes = peak_rss_bytes;
  s.tiles_sampled = tiles_sampled;
  std::vector<double> ms;
  ms.reserve(frames.size());
  double psnr_sum = 0.0;
  uint64_t ram_hits = 0, ram_misses = 0, gpu_hits = 0, gpu_misses = 0;
  // Time to sharp: an open cut waits for the first sharp frame.
  bool cut_open = false;
  uint32_t cut_frame = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameRecord& f = frames[i];
    ms.push_back(f.frame_ms);
    s.bytes_read += f.bytes_read;
    s.tiles_uploaded += f.tiles_uploaded;
    s.tiles_loaded += f.tiles_loaded;
    ram_hits += f.ram_hits;
    ram_misses += f.ram_misses;
    gpu_hits += f.gpu_hits;
    gpu_misses += f.gpu_misses;
    const bool cut = f.cut;
    if (cut) {
      if (cut_open) s.time_to_sharp_frames.push_back(-1);
      cut_open = true;
      cut_frame = uint32_t(i);
    }
    if (!f.has_error) continue;
    ++s.measured_frames;
    psnr_sum += f.psnr_db;
    s.psnr_min_db = std::min(s.psnr_min_db, f.psnr_db);
    if (f.psnr_db < kDegradedPsnrDb) ++s.frames_below_30db;
    if (f.max_abs_error == 0) ++s.identical_frames;
    if (cut_open && f.psnr_db >= kSharpPsnrDb) {
      s.time_to_sharp_frames.push_back(int32_t(i - cut_frame));
      cut_open = false;
    }
  }
  if (cut_open) s.time_to_sharp_frames.push_back(-1);
  if (s.measured_frames > 0) s.psnr_mean_db = psnr_sum / double(s.measured_frames);
  uint32_t sharp = 0;
  double sharp_sum = 0.0;
  for (int32_t t : s.time_to_sharp_frames) {
    if (t < 0) {
      s.time_to_sharp_max = -1;
      continue;
    }
    ++sharp;
    sharp_sum += t;
    if (s.time_to_sharp_max >= 0) s.time_to_sharp_max = std::max(s.time_to_sharp_max, t);
  }
  if (sharp > 0) s.time_to_sharp_mean = sharp_sum / double(sharp);
  s.frame_ms_p50 = percentileOf(ms, 0.5);
  s.frame_ms_p99 = percentileOf(ms, 0.99);
  s.frame_ms_max = percentileOf(ms, 1.0);
  for (double v : ms) s.frame_ms_mean += v / double(ms.size());
  if (ram_hits + ram_misses > 0) s.ram_hit_rate = double(ram_hits) / double(ram_hits + ram_misses);
  if (gpu_hits + gpu_misses > 0) s.gpu_hit_rate = double(gpu_hits) / double(gpu_hits + gpu_misses);
  if (tiles_sampled > 0) s.over_fetch_ratio = double(s.tiles_loaded) / double(tiles_sampled);
  return s;
}

std::string RunSummary::toJson() const {
  auto finite = [](double v) { return std::isfinite(v) ? v : 0.0; };
  nlohmann::json j = {
      {"frames", frames},
      {"measured_frames", measured_frames},
      {"psnr_mean_db", finite(psnr_mean_db)},
      {"psnr_min_db", finite(psnr_min_db)},
      {"frames_below_30db", frames_below_30db},
      {"identical_frames", identical_frames},
      {"time_to_sharp_frames", time_to_sharp_frames},
      {"time_to_sharp_mean", finite(time_to_sharp_mean)},
      {"time_to_sharp_max", time_to_sharp_max},
      {"frame_ms_mean", finite(frame_ms_mean)},
      {"frame_ms_p50", finite(frame_ms_p50)},
      {"frame_ms_p99", finite(frame_ms_p99)},
      {"frame_ms_max", finite(frame_ms_max)},
      {"bytes_read", bytes_read},
      {"tiles_uploaded", tiles_uploaded},
      {"tiles_loaded", tiles_loaded},
      {"ram_hit_rate", finite(ram_hit_rate)},
      {"gpu_hit_rate", finite(gpu_hit_rate)},
      {"peak_rss_bytes", peak_rss_bytes},
      {"tiles_sampled", tiles_sampled},
      {"over_fetch_ratio", finite(over_fetch_ratio)}};
  return j.dump();
}

bool isCut(const Camera& previous, const Camera& current, double previous_step_texels) {
  const double step = glm::length(current.position - previous.position);
  return step > 0.5 * std::max(previous.position.y, 1.0) &&
         step > 8.0 * std::max(previous_step_texels, 1.0);
}

namespace {

uint64_t statusKb(const char* field) {
  std::ifstream in("/proc/self/status");
  const size_t n = std::strlen(field);
  for (std::string line; std::getline(in, line);)
    if (line.compare(0, n, field) == 0) {
      unsigned long long kb = 0;
      if (std::sscanf(line.c_str() + n, " %llu", &kb) == 1) return uint64_t(kb) * 1024;
    }
  return 0;
}

}  // namespace

uint64_t currentRssBytes() { return statusKb("VmRSS:"); }
uint64_t peakRssBytes() { return statusKb("VmHWM:"); }

void sampledTiles(const PyramidGeometry& geometry, const Camera& camera, const Viewport& viewport,
                  std::unordered_set<uint64_t>* out) {
  const uint32_t tp = geometry.tile_px;
  // Consecutive texel reads mostly hit the same tile or two: remember the
  // last few so the set sees one insert per run of reads.
  uint64_t last[2] = {~uint64_t(0), ~uint64_t(0)};
  TexelFunction record = [&](uint32_t level, uint64_t x, uint64_t y, uint8_t rgba[4]) {
    const uint64_t key = packTileKey({level, uint32_t(x / tp), uint32_t(y / tp)});
    if (key != last[0] && key != last[1]) {
      out->insert(key);
      last[1] = last[0];
      last[0] = key;
    }
    rgba[0] = rgba[1] = rgba[2] = 128;
    rgba[3] = 255;
  };
  std::vector<uint8_t> ignored;
  renderReference(geometry, record, camera, viewport, ReferenceOptions{}, &ignored);
}

// ---------------------------------------------------------------------------

IdealReference::~IdealReference() = default;

Status IdealReference::create(std::shared_ptr<TileSource> source, const Viewport& viewport,
                              const PlannerConfig& planner, std::unique_ptr<IdealReference>* out) {
  std::unique_ptr<IdealReference> r(new IdealReference());
  r->m_source = std::move(source);
  r->m_geometry = r->m_source->geometry();
  r->m_planner = planner;
  if (Status s = r->resize(viewport); !s) return s;
  *out = std::move(r);
  return Status::ok();
}

Status IdealReference::resize(const Viewport& viewport) {
  m_viewport = viewport;
  m_renderer.reset();
  m_target.reset();
  // The clip size depends on the viewport only, not the camera.
  const ClipmapPlan plan = planClipmap(m_geometry, viewport, Camera{}, m_planner);
  RendererConfig rc{plan.clip_tiles, plan.pyramid_level, Buffering::kSingle};
  if (Status s = ClipmapRenderer::create(m_geometry, rc, &m_renderer); !s) return s;
  if (Status s = OffscreenTarget::create(viewport, &m_target); !s) return s;
  m_loaded.assign(plan.pyramid_level, TileRect{});
  // The pyramid: every tile of every level that fits one clip, once.
  m_renderer->beginFrame();
  // Tiles that failed show their ancestor, as in the streamed renderer.
  m_renderer->loadPyramid([this](const TileKey& key) { return tile(key); });
  m_renderer->endUploads();
  return Status::ok();
}

std::shared_ptr<const std::vector<uint8_t>> IdealReference::tile(const TileKey& key) {
  const uint64_t packed = packTileKey(key);
  auto it = m_cache.find(packed);
  if (it != m_cache.end()) return it->second;
  auto px = std::make_shared<std::vector<uint8_t>>();
  ++m_fetched;
  std::shared_ptr<const std::vector<uint8_t>> value;
  if (m_source->fetch(key, px.get()).isOk()) {
    m_cached_bytes += px->size();
    value = std::move(px);
  } else {
    ++m_failures;
  }
  m_cache.emplace(packed, value);
  return value;
}

Status IdealReference::render(const Camera& camera, std::vector<uint8_t>* rgba) {
  m_plan = planClipmap(m_geometry, m_viewport, camera, m_planner);
  if (m_plan.pyramid_level != m_loaded.size())
    return Status::error(ErrorCode::kInvalidArgument, "ideal reference: plan changed its pyramid level");
  m_renderer->beginFrame();
  std::vector<LevelResidency> residency;
  for (const ClipLevelPlan& lp : m_plan.stack) {
    LevelResidency r;
    r.level = lp.level;
    r.window = lp.window;
    r.resident.assign(size_t(lp.window.width()) * size_t(lp.window.height()), 0);
    if (lp.needed) {
      const TileRect& had = m_loaded[lp.level];
      for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
        for (int64_t x = lp.window.x0; x < lp.window.x1; ++x) {
          const TileKey key{lp.level, uint32_t(x), uint32_t(y)};
          auto px = tile(key);
          if (!px) continue;
          // Tiles of the previous window keep their toroidal slot.
          if (!had.contains(x, y)) m_renderer->uploadTile(key, px);
          r.resident[size_t(y - lp.window.y0) * size_t(lp.window.width()) + size_t(x - lp.window.x0)] = 1;
        }
      m_loaded[lp.level] = lp.window;
    } else {
      m_loaded[lp.level] = TileRect{};
    }
    residency.push_back(std::move(r));
  }
  m_renderer->setResidency(residency);
  m_renderer->setMaxTextureLod(0);
  m_renderer->endUploads();
  m_target->bind();
  ClipmapRenderer::clearSky();
  m_renderer->draw(camera, m_viewport);
  m_target->readRgba(rgba);
  return Status::ok();
}



uint32_t countHolePixels(const std::vector<uint8_t>& streamed, const std::vector<uint8_t>& reference) {
  static constexpr uint8_t kBlack[4] = {0, 0, 0, 255};
  auto same = [](const uint8_t* p, const uint8_t* q) { return p[0] == q[0] && p[1] == q[1] && p[2] == q[2]; };
  if (streamed.size() != reference.size()) return uint32_t(reference.size() / 4);
  uint32_t holes = 0;
  for (size_t p = 0; p + 3 < reference.size(); p += 4) {
    if (same(&reference[p], renderer_config::kSkyRgba)) continue;
    if (same(&streamed[p], renderer_config::kSkyRgba) ||
        (same(&streamed[p], kBlack) && !same(&reference[p], kBlack)))
      ++holes;
  }
  return holes;
}

uint32_t countGarbagePixels(const std::vector<uint8_t>& streamed, const PyramidGeometry& geometry,
                            const TexelFunction& texel, const Camera& camera,
                            const Viewport& viewport, int tolerance) {
  const size_t pixels = size_t(viewport.width_px) * viewport.height_px;
  if (streamed.size() != pixels * 4) return uint32_t(pixels);
  std::vector<int> best(pixels, 256);
  std::vector<uint8_t> ref;
  for (uint32_t level = 0; level < geometry.levelCount(); ++level) {
    ReferenceOptions options;
    options.min_level = level;
    renderReference(geometry, texel, camera, viewport, options, &ref);
    for (size_t p = 0; p < pixels; ++p) {
      int worst = 0;
      for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(int(streamed[p * 4 + c]) - int(ref[p * 4 + c])));
      best[p] = std::min(best[p], worst);
    }
  }
  uint32_t garbage = 0;
  for (int b : best)
    if (b > tolerance) ++garbage;
  return garbage;
}

Status FlyAccuracy::create(std::shared_ptr<TileSource> source, const Viewport& viewport,
                           const PlannerConfig& planner, const AccuracyOptions& options,
                           std::unique_ptr<FlyAccuracy>* out) {
  std::unique_ptr<FlyAccuracy> a(new FlyAccuracy());
  a->m_source = source;
  a->m_options = options;
  a->m_viewport = viewport;
  if (Status s = IdealReference::create(source, viewport, planner, &a->m_reference); !s) return s;
  if (options.ground_truth) a->m_texels = texelsFromSource(source);
  *out = std::move(a);
  return Status::ok();
}

Status FlyAccuracy::resize(const Viewport& viewport) {
  m_viewport = viewport;
  return m_reference->resize(viewport);
}

Status FlyAccuracy::measure(const Camera& camera, const OffscreenTarget& target, bool compare,
                            bool ground_truth, AccuracyFrame* out) {
  *out = AccuracyFrame{};
  if (m_options.sample_tiles) sampledTiles(m_source->geometry(), camera, m_viewport, &m_sampled);
  if (!compare) return Status::ok();
  target.readRgba(&m_streamed);
  if (Status s = m_reference->render(camera, &m_ideal); !s) return s;
  out->measured = true;
  out->error = compareFrames(m_streamed, m_ideal);
  out->hole_pixels = countHolePixels(m_streamed, m_ideal);
  if (ground_truth && m_texels) {
    renderReference(m_source->geometry(), m_texels, camera, m_viewport, ReferenceOptions{}, &m_truth);
    out->ground_truth_measured = true;
    out->ground_truth = compareFrames(m_ideal, m_truth);
  }
  return Status::ok();
}

// ---------------------------------------------------------------------------

namespace {

// Counts fetches made on one thread (the render thread) while armed: the
// streamer must only ever fetch on its workers.
class ThreadWatchSource final : public TileSource {
 public:
  explicit ThreadWatchSource(std::shared_ptr<TileSource> inner)
      : m_inner(std::move(inner)), m_render_thread(std::this_thread::get_id()) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    note();
    return m_inner->fetch(key, rgba);
  }
  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) override {
    note();
    return m_inner->fetchWithInfo(key, rgba, info);
  }
  std::string describe() const override { return m_inner->describe(); }
  void arm(bool on) { m_armed.store(on); }
  uint64_t renderThreadFetches() const { return m_count.load(); }

 private:
  void note() {
    if (m_armed.load() && std::this_thread::get_id() == m_render_thread) m_count.fetch_add(1);
  }
  std::shared_ptr<TileSource> m_inner;
  std::thread::id m_render_thread;
  std::atomic<bool> m_armed{false};
  std::atomic<uint64_t> m_count{0};
};

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point a) {
  return std::chrono::duration<double, std::milli>(Clock::now() - a).count();
}


}  // namespace

Status runScenario(const ScenarioOptions& o, ScenarioResult* result) {
  if (!o.source) return Status::error(ErrorCode::kInvalidArgument, "scenario: no tile source");
  *result = ScenarioResult{};
  result->gl = currentGlDescription();
  const PyramidGeometry geometry = o.source->geometry();
  auto watched = std::make_shared<ThreadWatchSource>(o.source);
  Viewport viewport = o.viewport;
  const double speed = o.speed > 0.0 ? o.speed : 1.0;

  std::unique_ptr<IdealReference> reference;
  if (o.reference_every > 0)
    if (Status s = IdealReference::create(o.source, viewport, o.streamer.planner, &reference); !s) return s;

  // Streamed renderer with the coarse pyramid preloaded (kept in RAM here so
  // a resize can re-upload it without reading).
  std::unordered_map<uint64_t, std::shared_ptr<const std::vector<uint8_t>>> pyramid;
  std::unique_ptr<ClipmapRenderer> renderer;
  std::unique_ptr<OffscreenTarget> target;
  auto makeRenderer = [&](const Camera& camera) -> Status {
    renderer.reset();
    target.reset();
    const ClipmapPlan first = planClipmap(geometry, viewport, camera, o.streamer.planner);
    RendererConfig rc{first.clip_tiles, first.pyramid_level, o.buffering};
    if (Status s = ClipmapRenderer::create(geometry, rc, &renderer); !s) return s;
    if (Status s = OffscreenTarget::create(viewport, &target); !s) return s;
    renderer->beginFrame();
    renderer->loadPyramid([&](const TileKey& key) {
      auto it = pyramid.find(packTileKey(key));
      if (it == pyramid.end()) {
        auto px = std::make_shared<std::vector<uint8_t>>();
        std::shared_ptr<const std::vector<uint8_t>> value;
        if (o.source->fetch(key, px.get()).isOk()) value = std::move(px);
        else ++result->tile_failures;
        it = pyramid.emplace(packTileKey(key), value).first;
      }
      return it->second;
    });
    renderer->endUploads();
    return Status::ok();
  };
  if (Status s = makeRenderer(o.path.sample(0.0)); !s) return s;

  Streamer streamer(watched, o.streamer);
  watched->arm(true);
  StreamerStats before = streamer.stats();
  std::unordered_set<uint64_t> sampled;
  const uint32_t total = o.frames + o.rest_frames;
  result->frames.reserve(total);
  Camera previous = o.path.sample(0.0);
  double previous_step = 0.0;
  std::vector<uint8_t> streamed, ideal;
  struct Candidate {
    double psnr_db;
    Camera camera;
    Viewport viewport;
    std::vector<uint8_t> rgba;
  };
  std::vector<Candidate> candidates;

  for (uint32_t i = 0; i < total; ++i) {
    if (o.resize_at_frame > 0 && i == o.resize_at_frame && o.resize_to.width_px > 0) {
      viewport = o.resize_to;
      watched->arm(false);
      if (Status s = makeRenderer(previous); !s) return s;
      if (reference)
        if (Status s = reference->resize(viewport); !s) return s;
      streamer.resetGpuResidency();
      watched->arm(true);
    }
    FrameRecord f;
    f.frame = i;
    const double t_s = std::min(i, o.frames > 0 ? o.frames - 1 : 0) *
                       renderer_config::kSimulatedFrameSeconds * speed;
    const Camera camera = o.path.sample(t_s);
    const double step = glm::length(camera.position - previous.position);
    f.cut = i == 0 || isCut(previous, camera, previous_step);
    previous_step = step;
    previous = camera;

    const auto t0 = Clock::now();
    streamer.update(camera, viewport, i * renderer_config::kSimulatedFrameSeconds);
    const FrameHandoff handoff = streamer.takeReady(o.upload_tiles);
    renderer->applyHandoff(handoff);
    target->bind();
    ClipmapRenderer::clearSky();
    renderer->draw(camera, viewport);
    glFinish();
    f.frame_ms = msSince(t0);
    f.tiles_uploaded = renderer->lastUploads().tiles;
    result->max_texture_lod.push_back(handoff.max_texture_lod);

    const StreamerStats now = streamer.stats();
    f.bytes_read = now.total.bytes_read - before.total.bytes_read;
    f.tiles_loaded = now.total.loads - before.total.loads;
    f.ram_hits = now.total.ram_hits - before.total.ram_hits;
    f.ram_misses = now.total.ram_misses - before.total.ram_misses;
    before = now;
    const ClipmapPlan& plan = streamer.plan();
    const UsableMap& usable = renderer->usableMap();
    for (const ClipLevelPlan& lp : plan.stack) {
      if (!lp.needed || lp.level >= usable.usable.size()) continue;
      for (int64_t y = lp.visible.y0; y < lp.visible.y1; ++y)
        for (int64_t x = lp.visible.x0; x < lp.visible.x1; ++x) {
          const bool ok = usable.windows[lp.level].contains(x, y) &&
                          usable.usable[lp.level][size_t(toroidalSlot(y, usable.clip_tiles)) *
                                                      usable.clip_tiles +
                                                  toroidalSlot(x, usable.clip_tiles)] != 0;
          (ok ? f.gpu_hits : f.gpu_misses)++;
        }
    }
    if (o.sample_tiles) sampledTiles(geometry, camera, viewport, &sampled);

    uint32_t holes = 0;
    const bool compare = reference && (i % o.reference_every == 0 || i >= o.frames || i + 1 == total);
    if (compare) {
      target->readRgba(&streamed);
      if (Status s = reference->render(camera, &ideal); !s) return s;
      const FrameError e = compareFrames(streamed, ideal);
      f.has_error = true;
      f.psnr_db = e.psnr_db;
      f.max_abs_error = e.max_abs_error;
      holes = countHolePixels(streamed, ideal);
      if (i + 1 == total) result->final_max_abs_error = e.max_abs_error;
      if (o.garbage_checks > 0 && e.psnr_db < kSharpPsnrDb) {
        candidates.push_back({e.psnr_db, camera, viewport, streamed});
        std::sort(candidates.begin(), candidates.end(),
                  [](const Candidate& a, const Candidate& b) { return a.psnr_db < b.psnr_db; });
        if (candidates.size() > o.garbage_checks) candidates.pop_back();
      }
    }
    result->hole_pixels.push_back(holes);
    result->frames.push_back(f);
    if (i == total / 4) result->rss_after_warmup_bytes = currentRssBytes();
    if (i >= o.frames && o.rest_frame_ms > 0.0) {
      const double left = o.rest_frame_ms - msSince(t0);
      if (left > 0.0) std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(left));
    }
  }
  watched->arm(false);
  if (!candidates.empty()) {
    const TexelFunction texels = o.garbage_texels ? o.garbage_texels : texelsFromSource(o.source);
    for (const Candidate& c : candidates) {
      ++result->garbage_checked_frames;
      result->garbage_pixels_max = std::max(
          result->garbage_pixels_max,
          countGarbagePixels(c.rgba, geometry, texels, c.camera, c.viewport, o.garbage_tolerance));
    }
  }
  const StreamerStats final_stats = streamer.stats();
  streamer.shutdown();
  result->render_thread_fetches = watched->renderThreadFetches();
  result->ram_peak_bytes = final_stats.ram_peak_bytes;
  result->ram_budget_bytes = final_stats.ram_budget_bytes;
  result->tile_failures += final_stats.total.failures;
  result->rss_end_bytes = currentRssBytes();
  result->summary = summarizeRun(result->frames, o.sample_tiles ? sampled.size() : 0, peakRssBytes());
  return Status::ok();
}

}  // namespace clipstream
