// The one measured frame loop. See flight_run.h and docs/renderer.md.
#include <clipstream/eval/flight_run.h>

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/util/process_memory.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <thread>
#include <unordered_set>

namespace clipstream {

Camera cameraAboveGround(Camera path_camera, double ground) {
  path_camera.position.y = ground + std::max(path_camera.position.y, renderer_config::kTerrainClearance);
  return path_camera;
}

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point a) {
  return std::chrono::duration<double, std::milli>(Clock::now() - a).count();
}

// Counts fetches made on one thread (the render thread) while armed: the
// streamer must only ever fetch on its workers.
class ThreadWatchSource final : public TileSource {
 public:
  explicit ThreadWatchSource(std::shared_ptr<TileSource> inner)
      : m_inner(std::move(inner)), m_render_thread(std::this_thread::get_id()) {}
  const PyramidGeometry& geometry() const override { return m_inner->geometry(); }
  TileContent content() const override { return m_inner->content(); }
  Status fetch(const TileKey& key, std::vector<uint8_t>* rgba) override {
    note();
    return m_inner->fetch(key, rgba);
  }
  Status fetchWithInfo(const TileKey& key, std::vector<uint8_t>* rgba, FetchInfo* info) override {
    note();
    return m_inner->fetchWithInfo(key, rgba, info);
  }
  std::string describe() const override { return m_inner->describe(); }
  unsigned suggestedLoaderThreads() const override { return m_inner->suggestedLoaderThreads(); }
  size_t maxBatch() const override { return m_inner->maxBatch(); }
  void fetchBatch(std::span<const TileKey> keys, std::span<std::vector<uint8_t>* const> rgba,
                  std::span<Status> statuses, std::span<FetchInfo> infos) override {
    note();
    m_inner->fetchBatch(keys, rgba, statuses, infos);
  }
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

FrameRecord recordOf(const FlightRunFrame& f) {
  FrameRecord r;
  r.frame = f.sample.frame;
  r.cut = f.sample.cut;
  r.has_error = f.accuracy.measured;
  r.psnr_db = f.accuracy.error.psnr_db;
  r.max_abs_error = f.accuracy.error.max_abs_error;
  r.frame_ms = f.sample.frame_ms;
  r.bytes_read = f.sample.total.bytes_read;
  r.tiles_uploaded = f.sample.tiles_uploaded;
  r.tiles_loaded = f.sample.tiles_loaded;
  r.ram_hits = f.sample.total.ram_hits;
  r.ram_misses = f.sample.total.ram_misses;
  r.gpu_hits = f.sample.total.gpu_hits;
  r.gpu_misses = f.sample.total.gpu_misses;
  return r;
}

// Mean absolute grey change per pixel between two RGBA8 frames.
double meanGreyChange(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  double sum = 0.0;
  for (size_t k = 0; k + 3 < a.size() && k + 3 < b.size(); k += 4)
    sum += std::abs((int(a[k]) + a[k + 1] + a[k + 2]) - (int(b[k]) + b[k + 1] + b[k + 2])) / 3.0;
  return a.empty() ? 0.0 : sum / double(a.size() / 4);
}

// A blurry judged frame kept for the garbage check after the flight.
struct GarbageCandidate {
  double psnr_db;
  Camera camera;
  Viewport viewport;
  std::vector<uint8_t> rgba;
};

// The terrain frames judged: this frame's pictures and the last judged
// frame's, for the change between consecutive judged frames.
struct TerrainJudging {
  std::vector<uint8_t> streamed_rgba, reference_rgba;
  std::vector<uint8_t> previous_streamed, previous_reference;
  uint32_t previous_judged = UINT32_MAX;
  std::vector<float> reference_xyzw;
  std::vector<glm::vec2> displacement, previous_displacement;  // geometricError()'s
  // Synthesized relief: the DEM's own surface (loaded at the first judged frame).
  std::unique_ptr<ReferenceSurface> data_surface;
};

// Judges recorded frame i over terrain: geometric error against the
// full-resolution surface, PSNR against the full-resolution mesh with the
// ideal texture, the fewest triangles (when `fewest`), and the change from
// the last judged frame; adds them to the run's sums (averaged at the end).
Status judgeTerrainFrame(const FlightRunOptions& o, uint32_t i, uint32_t total, const Camera& camera,
                         const ReferenceSurface& surface, TerrainReference& terrain_reference,
                         FewestTriangles* fewest, Flight& flight, TerrainJudging* judging, FlightRunFrame* frame,
                         FlightRun* run) {
  TerrainJudging& j = *judging;
  FlightRunFrame& f = *frame;
  std::vector<float> xyzw;
  if (Status s = flight.terrain()->readPositions(camera, flight.viewport(), flight.renderer(), &xyzw); !s)
    return s;
  flight.target()->readRgba(&j.streamed_rgba);
  if (Status s = terrain_reference.render(camera, &j.reference_rgba, &j.reference_xyzw); !s) return s;
  f.geometry = geometricError(xyzw, camera, flight.viewport(), surface, &j.reference_xyzw, &j.displacement);
  if (o.terrain->data_source && f.geometry.pixels > 0) {
    // The surface drawn against the DEM's alone: what the synthesis adds
    // (projection only: the reference draws the synthesized surface).
    if (!j.data_surface)
      if (Status s = ReferenceSurface::load(*o.terrain->data_source, o.terrain->data_alignment, &j.data_surface); !s)
        return s;
    const GeometryError data = geometricError(xyzw, camera, flight.viewport(), *j.data_surface);
    run->geometry_data_mean_px += data.mean_px;
    run->geometry_data_p95_px += data.p95_px;
  }
  const TerrainFrameError te = compareTerrainFrames(j.streamed_rgba, xyzw, j.reference_rgba, j.reference_xyzw, flight.viewport());
  f.accuracy.measured = true;
  f.accuracy.error = te.error;
  f.terrain_agree_pixels = te.agree_pixels;
  f.terrain_agree_mismatched = te.agree_mismatched;
  if (fewest) {
    // At the error this frame achieved (not below kFewestFloorPx): what it
    // draws beyond that is what it models beyond the frame's need.
    if (Status s = fewest->count(camera, flight.viewport(), flight.renderer(), surface,
                                 std::max(f.geometry.p95_px, kFewestFloorPx),
                                 &f.fewest_triangles, &j.reference_xyzw);
        !s)
      return s;
  }
  if (!j.previous_streamed.empty() && j.previous_judged + 1 == i && !f.sample.cut) {
    run->change_pairs += 1;
    run->change_mean += meanGreyChange(j.streamed_rgba, j.previous_streamed);
    run->reference_change_mean += meanGreyChange(j.reference_rgba, j.previous_reference);
    const double moved = displacementChange(j.displacement, j.previous_displacement);
    run->geometry_change_mean += moved;
    run->geometry_change_max = std::max(run->geometry_change_max, moved);
  }
  std::swap(j.displacement, j.previous_displacement);
  j.previous_judged = i;
  j.previous_streamed = j.streamed_rgba;
  j.previous_reference = j.reference_rgba;
  if (i + 1 == total) run->final_max_abs_error = te.error.max_abs_error;
  if (i >= o.frames) {
    run->terrain_rest_agree_pixels += te.agree_pixels;
    run->terrain_rest_agree_mismatched += te.agree_mismatched;
    run->terrain_rest_agree_max_diff = std::max(run->terrain_rest_agree_max_diff, te.agree_max_diff);
  }
  if (f.geometry.pixels > 0) {
    const bool rest = i >= o.frames;
    run->geometry_frames += 1;
    run->geometry_mean_px += f.geometry.mean_px;
    run->geometry_p95_px += f.geometry.p95_px;
    run->geometry_max_px = std::max(run->geometry_max_px, f.geometry.max_px);
    run->coverage_pixels_mean += double(f.geometry.coverage_pixels);
    const TexelDensity density =
        texelDensity(xyzw, flight.viewport(), double(renderer_config::kDetailTexelsPerTexel));
    run->texel_density_median += density.median;
    run->texel_density_p5 += density.p5;
    run->detail_texel_density_median += density.detail_median;
    run->detail_texel_density_p5 += density.detail_p5;
    run->silhouette_mean_px += f.geometry.silhouette_mean_px;
    run->silhouette_p95_px += f.geometry.silhouette_p95_px;
    run->silhouette_max_px = std::max(run->silhouette_max_px, f.geometry.silhouette_max_px);
    run->judged_triangles_mean += double(f.sample.terrain_triangles);
    run->fewest_triangles_mean += double(f.fewest_triangles);
    if (rest) {
      run->geometry_rest_frames += 1;
      run->geometry_rest_mean_px += f.geometry.mean_px;
      run->geometry_rest_p95_px += f.geometry.p95_px;
      run->geometry_rest_max_px = std::max(run->geometry_rest_max_px, f.geometry.max_px);
    }
  }
  return okStatus();
}

// Judges recorded frame i against the flat reference (every
// o.reference_every frames, every rest frame and the last) and the CPU
// ground truth; keeps the o.garbage_checks blurriest frames as garbage
// check candidates, sharpest dropped first.
Status judgeFlatFrame(const FlightRunOptions& o, uint32_t i, uint32_t total, const Camera& camera,
                      FlyAccuracy& accuracy, Flight& flight, std::vector<GarbageCandidate>* candidates_out,
                      FlightRunFrame* frame, FlightRun* run) {
  std::vector<GarbageCandidate>& candidates = *candidates_out;
  FlightRunFrame& f = *frame;
  const bool compare =
      o.reference_every > 0 && (i % o.reference_every == 0 || i >= o.frames || i + 1 == total);
  const bool truth = compare && o.ground_truth_every > 0 && i % o.ground_truth_every == 0;
  if (Status s = accuracy.measure(camera, *flight.target(), compare, truth, &f.accuracy); !s) return s;
  const AccuracyFrame& a = f.accuracy;
  if (a.measured) {
    if (i + 1 == total) run->final_max_abs_error = a.error.max_abs_error;
    if (a.hole_pixels > 0) ++run->frames_with_holes;
    if (o.garbage_checks > 0 && a.error.psnr_db < kSharpPsnrDb) {
      candidates.push_back({a.error.psnr_db, camera, flight.viewport(), accuracy.lastStreamed()});
      std::sort(candidates.begin(), candidates.end(),
                [](const GarbageCandidate& x, const GarbageCandidate& y) { return x.psnr_db < y.psnr_db; });
      if (candidates.size() > o.garbage_checks) candidates.pop_back();
    }
  }
  if (a.ground_truth_measured) {
    run->ground_truth_psnr_min_db = run->ground_truth_frames == 0
                                        ? a.ground_truth.psnr_db
                                        : std::min(run->ground_truth_psnr_min_db, a.ground_truth.psnr_db);
    run->ground_truth_psnr_mean_db += a.ground_truth.psnr_db;
    ++run->ground_truth_frames;
  }
  return okStatus();
}

// The references a terrain flight is judged by: the full-resolution
// surface, the fewest-triangles counter (when asked) and the
// full-resolution mesh with the ideal texture, drawn from `reference`.
Status createTerrainReferences(const FlightRunOptions& o, const std::shared_ptr<TileSource>& reference,
                               std::unique_ptr<ReferenceSurface>* surface,
                               std::unique_ptr<FewestTriangles>* fewest,
                               std::unique_ptr<TerrainReference>* terrain_reference) {
  if (Status s = ReferenceSurface::load(*o.terrain->source, o.terrain->alignment, surface); !s) return s;
  if (o.fewest_triangles)
    if (Status s = FewestTriangles::create(**surface, *o.terrain->source, fewest); !s) return s;
  TerrainConfig tc;
  tc.ring_cells = o.terrain->ring_cells;
  tc.mapping = o.terrain->alignment;
  tc.lighting = o.reference_lighting.value_or(o.terrain->lighting);
  tc.detail_textures = o.terrain->detail_textures;  // the reference shows the same detail
  if (Status s = TerrainReference::create(reference, *o.terrain->source, tc, o.viewport, o.streamer.planner,
                                          terrain_reference);
      !s)
    return s;
  return okStatus();
}

// One layer's clip levels (those below `pyramid_level`): the tiles of
// `sampled` there (packTileKey()), the loads `levels` counted there (null:
// none), and loads over sampled (left as it is when none was sampled).
void clipLevelOverFetch(const std::unordered_set<uint64_t>& sampled, uint32_t pyramid_level,
                        const std::vector<LevelCounters>* levels, uint64_t* loaded, uint64_t* sampled_count,
                        double* ratio) {
  for (uint64_t key : sampled)
    if ((key >> 58) < pyramid_level) ++*sampled_count;
  for (uint32_t l = 0; levels && l < pyramid_level && l < levels->size(); ++l) *loaded += (*levels)[l].loads;
  if (*sampled_count > 0) *ratio = double(*loaded) / double(*sampled_count);
}

// The run's summary from its frames (over-fetch ratios included), and the
// per-judged-frame sums turned into means. `accuracy` is null without the
// flat reference; over terrain `terrain_sampled` holds the sampled tiles.
void summarizeFlight(const FlightRunOptions& o, const Flight& flight, const FlyAccuracy* accuracy,
                     const std::unordered_set<uint64_t>& terrain_sampled,
                     const std::unordered_set<uint64_t>& height_sampled, FlightRun* run) {
  std::vector<FrameRecord> records;
  records.reserve(run->frames.size());
  for (const FlightRunFrame& f : run->frames) records.push_back(recordOf(f));
  run->summary = summarizeRun(records, accuracy ? accuracy->tilesSampled() : terrain_sampled.size(),
                              peakRssBytes());
  if (run->geometry_frames > 0) {
    run->geometry_mean_px /= run->geometry_frames;
    run->geometry_p95_px /= run->geometry_frames;
    run->coverage_pixels_mean /= run->geometry_frames;
    run->texel_density_median /= run->geometry_frames;
    run->geometry_data_mean_px /= run->geometry_frames;
    run->geometry_data_p95_px /= run->geometry_frames;
    run->texel_density_p5 /= run->geometry_frames;
    run->detail_texel_density_median /= run->geometry_frames;
    run->detail_texel_density_p5 /= run->geometry_frames;
    run->silhouette_mean_px /= run->geometry_frames;
    run->silhouette_p95_px /= run->geometry_frames;
    run->judged_triangles_mean /= run->geometry_frames;
    run->fewest_triangles_mean /= run->geometry_frames;
  }
  if (run->change_pairs > 0) {
    run->change_mean /= run->change_pairs;
    run->reference_change_mean /= run->change_pairs;
    run->geometry_change_mean /= run->change_pairs;
  }
  if (run->geometry_rest_frames > 0) {
    run->geometry_rest_mean_px /= run->geometry_rest_frames;
    run->geometry_rest_p95_px /= run->geometry_rest_frames;
  }
  if (!run->frames.empty()) {
    for (const FlightRunFrame& f : run->frames) run->render_cpu_ms_mean += f.sample.cpu_ms;
    run->render_cpu_ms_mean /= double(run->frames.size());
  }
  if (o.terrain && !run->frames.empty()) {
    double triangles = 0.0;
    for (const FlightRunFrame& f : run->frames) triangles += double(f.sample.terrain_triangles);
    run->terrain_triangles_mean = triangles / double(run->frames.size());
    double bound = 0.0;
    for (const FlightRunFrame& f : run->frames) {
      bound += f.sample.terrain_error_px;
      run->terrain_error_px_max = std::max(run->terrain_error_px_max, f.sample.terrain_error_px);
    }
    run->terrain_error_px_mean = bound / double(run->frames.size());
    run->terrain_method = terrainMethodName(o.terrain->method);
    run->terrain_lighting = terrainLightingName(o.terrain->lighting);
    run->reference_lighting = terrainLightingName(o.reference_lighting.value_or(o.terrain->lighting));
  }
  // Loads include the streamer's reads of the pyramid, as sampled tiles
  // include the pyramid tiles seen. Over terrain, the colour layer's loads
  // only: height tiles are not sampled by the texture.
  const uint64_t colour_loads = o.terrain && !run->streamer.layers.empty()
                                    ? run->streamer.layers[0].total.loads
                                    : run->summary.tiles_loaded + run->warmup_loads;
  if (run->summary.tiles_sampled > 0)
    run->summary.over_fetch_ratio = double(colour_loads) / double(run->summary.tiles_sampled);
  // Without the pyramid: the clip levels' loads over their sampled tiles.
  RunSummary& sum = run->summary;
  const std::unordered_set<uint64_t>& sampled = accuracy ? accuracy->sampledSet() : terrain_sampled;
  clipLevelOverFetch(sampled, flight.firstPlan().pyramid_level,
                     run->streamer.layers.empty() ? nullptr : &run->streamer.layers[0].levels,
                     &sum.tiles_loaded_stack, &sum.tiles_sampled_stack, &sum.over_fetch_stack_ratio);
  // The height layer's clip levels (layer 1 over terrain): the levels its
  // plan holds whole are loaded once, as the colour's pyramid.
  if (o.terrain && run->streamer.layers.size() > 1)
    clipLevelOverFetch(height_sampled, flight.streamer().plan(1).pyramid_level, &run->streamer.layers[1].levels,
                       &sum.height_tiles_loaded_stack, &sum.height_tiles_sampled_stack,
                       &sum.height_over_fetch_stack_ratio);
}

// The flight's settings from the run's options.
FlightConfig flightConfigOf(const FlightRunOptions& o) {
  FlightConfig fc;
  fc.viewport = o.viewport;
  fc.streamer = o.streamer;
  fc.upload_tiles = o.upload_tiles;
  fc.buffering = o.buffering;
  fc.texture_memory = o.texture_memory;
  fc.pool_bytes = o.pool_bytes;
  fc.overlay = o.overlay;
  fc.warmup_frames = o.warmup_frames;
  fc.offscreen = true;  // frames are judged and saved from the flight's own target
  fc.terrain = o.terrain;
  return fc;
}

// The flat reference (and the over-fetch sampling), drawn from `reference`.
Status createFlatReference(const FlightRunOptions& o, const std::shared_ptr<TileSource>& reference,
                           std::unique_ptr<FlyAccuracy>* accuracy) {
  AccuracyOptions ao;
  ao.ground_truth = o.ground_truth_every > 0;
  ao.sample_tiles = o.sample_tiles;
  ao.reference = o.reference_every > 0;
  ao.texture_memory = o.texture_memory;
  if (Status s = FlyAccuracy::create(reference, o.viewport, o.streamer.planner, ao, accuracy); !s) return s;
  return okStatus();
}

// Counts the garbage pixels (texels of no level in reach) of the kept
// blurry frames; the run records the worst frame's count.
void checkGarbage(const FlightRunOptions& o, const PyramidGeometry& geometry,
                  const std::vector<GarbageCandidate>& candidates, FlightRun* run) {
  const TexelFunction texels = o.garbage_texels ? o.garbage_texels : texelsFromSource(o.source);
  for (const GarbageCandidate& c : candidates) {
    ++run->garbage_checked_frames;
    run->garbage_pixels_max = std::max(
        run->garbage_pixels_max,
        countGarbagePixels(c.rgba, geometry, texels, c.camera, c.viewport, o.garbage_tolerance));
  }
}

}  // namespace

// Long: the measured loop in its order (references before the streamer,
// warm-up, recorded frames, finish, summary) shares the flight, its
// lambdas and the trace guard; judging, references and totals are split out.
Status runFlight(const FlightRunOptions& o, FlightRun* run) {
  *run = FlightRun{};
  if (!o.source) return Status::error(ErrorCode::kInvalidArgument, "flight: no tile source");
  if (o.frames == 0) return Status::error(ErrorCode::kInvalidArgument, "flight: no frames to fly");
  run->gl = currentGlDescription();
  run->source = o.source->describe();
  const PyramidGeometry& geometry = o.source->geometry();
  const double speed = o.speed > 0.0 ? o.speed : 1.0;
  const uint32_t total = o.frames + o.rest_frames;

  // Path time of recorded frame `frame` (fractional for the hint): held at
  // the last pose through the rest frames. Captures values only: the path
  // hint keeps a copy for the streamer's lifetime.
  const double last_frame = double(o.frames - 1);
  const double duration_s = o.loop ? o.path.durationS() : 0.0;
  auto pathTimeOfFrame = [last_frame, speed, duration_s](double frame) {
    double t = std::clamp(frame, 0.0, last_frame) * renderer_config::kSimulatedFrameSeconds * speed;
    if (duration_s > 0.0) t = std::fmod(t, duration_s);
    return t;
  };

  auto watched = std::make_shared<ThreadWatchSource>(o.source);
  const FlightConfig fc = flightConfigOf(o);
  // The reference (its own renderer and a synchronous pyramid load) is set
  // up before the flight's streamer exists, as clipstream-fly always did:
  // with the streamer created first, a timing-sensitive flight reached sharp
  // frames 7 frames earlier in 5 of 6 runs (docs/benchmarks.md), a change of
  // results this loop must not make.
  std::unique_ptr<FlyAccuracy> accuracy;
  // Both references draw the tiles of `reference_source` when the flight
  // names one (a BC1 flight judged against RGBA8 tiles), else the flight's.
  const std::shared_ptr<TileSource>& reference = o.reference_source ? o.reference_source : o.source;
  // This reference draws the flat plane; over terrain the TerrainReference
  // below judges the frames instead (docs/terrain.md, "Accuracy").
  if (!o.terrain && (o.reference_every > 0 || o.sample_tiles))
    if (Status s = createFlatReference(o, reference, &accuracy); !s) return s;
  // Before the flight exists no height is known: the first camera is put
  // above the highest ground, then every frame above the ground under it.
  Camera first = o.path.sample(0.0);
  if (o.terrain && o.terrain->source) {
    first = cameraAboveGround(first, o.terrain->source->elevationInfo().max_height *
                                         o.terrain->alignment.world_per_height);
  }
  // Over terrain the judged frames are measured against the full-resolution
  // surface (geometric error) and the full-resolution mesh with the ideal
  // texture (PSNR).
  std::unique_ptr<ReferenceSurface> surface;
  std::unique_ptr<FewestTriangles> fewest;
  std::unique_ptr<TerrainReference> terrain_reference;
  if (o.terrain && o.terrain->source && o.reference_every > 0)
    if (Status s = createTerrainReferences(o, reference, &surface, &fewest, &terrain_reference); !s) return s;
  std::unique_ptr<Flight> flight;
  if (Status s = Flight::create(watched, fc, first, &flight); !s) return s;
  auto onGround = [&](const Camera& path_camera) {
    double ground = 0.0;
    if (!o.terrain || !flight->groundHeight({path_camera.position.x, path_camera.position.z}, &ground))
      return path_camera;
    return cameraAboveGround(path_camera, ground);
  };
  run->height_texture_bytes = flight->terrain() ? flight->terrain()->textureBytes() : 0;
  run->plans_on_terrain = flight->streamer().plansOnTerrain();
  // Over terrain the tiles a frame samples come from the ground points its
  // pixels show (the flat reference would judge the wrong picture).
  // Returns the planner's level for the nearest ground the frame shows
  // (-1: none, or not sampled).
  std::unordered_set<uint64_t> terrain_sampled;
  // The height tiles the drawn geometry read, every frame.
  std::unordered_set<uint64_t> height_sampled;
  auto noteHeightTiles = [&] {
    if (flight->terrain())
      for (const TileKey& k : flight->terrain()->lastHeightTiles()) height_sampled.insert(packTileKey(k));
  };
  Status sample_error;  // a failed readPositions(), returned after the frame
  auto sampleTerrainTiles = [&](const Camera& camera) -> int32_t {
    if (!o.terrain || !o.sample_tiles || !flight->terrain()) return -1;
    std::vector<float> xyzw;
    if (Status s = flight->terrain()->readPositions(camera, flight->viewport(), flight->renderer(), &xyzw); !s) {
      sample_error = s;
      return -1;
    }
    sampledTilesOfPositions(geometry, xyzw, camera, flight->viewport(), &terrain_sampled);
    const double nearest = nearestPositionDistance(xyzw);
    if (!std::isfinite(nearest)) return -1;
    return int32_t(finestLevelAt(nearest, flight->viewport(), camera, o.streamer.planner, geometry.levelCount()));
  };
  run->preload_ms = flight->preloadMs();
  // A run that fails from here on publishes no trace.
  struct DiscardTraceUnlessDone {
    Flight& flight;
    bool done = false;
    ~DiscardTraceUnlessDone() {
      if (!done) flight.streamer().discardTrace();
    }
  } trace_guard{*flight};
  if (o.path_hint) {
    // The streamer's clock runs from the first warm-up frame, so recorded
    // frame 0 is at clock0_s.
    const double clock0_s = o.warmup_frames * renderer_config::kSimulatedFrameSeconds;
    PathHint hint;
    hint.camera_at = [path = o.path, clock0_s, pathTimeOfFrame](double clock_s) {
      return path.sample(pathTimeOfFrame((clock_s - clock0_s) / renderer_config::kSimulatedFrameSeconds));
    };
    flight->streamer().setPathHint(std::move(hint));
  }

  if (o.on_start)
    if (Status s = o.on_start(); !s) return s;
  std::vector<GarbageCandidate> candidates;
  TerrainJudging judging;
  run->frames.reserve(std::min<uint32_t>(total, 100000));  // grows past that as frames come
  const auto run_start = Clock::now();
  watched->arm(true);

  for (uint32_t w = 0; w < o.warmup_frames; ++w) {
    // Start-up excluded from the statistics: the camera holds its first
    // position while the streamer fills the first windows. Warm-up frames
    // count in the over-fetch ratio (loads and sampled tiles alike).
    const Camera camera = onGround(o.path.sample(0.0));
    flight->step(camera);
    noteHeightTiles();
    (void)sampleTerrainTiles(camera);
    if (!sample_error) return sample_error;
    AccuracyFrame ignored;
    if (accuracy)
      if (Status s = accuracy->measure(camera, *flight->target(), false, false, &ignored); !s) return s;
  }
  run->warmup_loads = flight->warmupLoads();

  Camera previous = onGround(o.path.sample(0.0));
  for (uint32_t i = 0; i < total; ++i) {
    if (o.resize_at_frame > 0 && i == o.resize_at_frame && o.resize_to.width_px > 0) {
      watched->arm(false);
      if (Status s = flight->resize(o.resize_to, previous); !s) return s;
      if (accuracy)
        if (Status s = accuracy->resize(o.resize_to); !s) return s;
      if (terrain_reference)
        if (Status s = terrain_reference->resize(o.resize_to); !s) return s;
      watched->arm(true);
    }
    FlightRunFrame f;
    f.t_s = pathTimeOfFrame(double(i));
    const Camera camera = onGround(o.path.sample(f.t_s));
    previous = camera;
    const auto t0 = Clock::now();
    f.sample = flight->step(camera);
    noteHeightTiles();
    if (o.on_frame)
      if (Status s = o.on_frame(f.sample, *flight->target(), &f.readback_ms); !s) return s;
    f.seen_level = sampleTerrainTiles(camera);
    if (!sample_error) return sample_error;
    if (f.seen_level >= 0) {
      run->seen_frames += 1;
      run->needed_coarser_frames += int32_t(f.sample.finest_needed) > f.seen_level;
      run->needed_finer_frames += int32_t(f.sample.finest_needed) < f.seen_level;
    }
    if (surface && flight->terrain() &&
        (i % o.reference_every == 0 || i >= o.frames || i + 1 == total)) {
      if (Status s = judgeTerrainFrame(o, i, total, camera, *surface, *terrain_reference, fewest.get(), *flight,
                                       &judging, &f, run);
          !s)
        return s;
    }
    // Judged after the frame is timed: the reference fetches synchronously.
    if (accuracy)
      if (Status s = judgeFlatFrame(o, i, total, camera, *accuracy, *flight, &candidates, &f, run); !s) return s;
    run->frames.push_back(std::move(f));
    if (i == total / 4) run->rss_after_warmup_bytes = currentRssBytes();
    // Rest frames at display pace: a slow source gets real time to land.
    if (i >= o.frames && o.rest_frame_ms > 0.0) {
      const double left = o.rest_frame_ms - msSince(t0);
      if (left > 0.0) std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(left));
    }
  }
  watched->arm(false);
  run->run_ms = msSince(run_start);
  if (run->ground_truth_frames > 0) run->ground_truth_psnr_mean_db /= run->ground_truth_frames;

  if (!candidates.empty()) checkGarbage(o, geometry, candidates, run);
  // The renderer in use at the end (after a resize, the new one).
  run->clip_tiles = flight->firstPlan().clip_tiles;
  run->pyramid_level = flight->firstPlan().pyramid_level;
  run->texture_bytes = flight->renderer().textureBytes();
  run->tile_content = flight->renderer().tileContent();
  run->texture_memory = flight->renderer().textureMemory();
  run->pool_pages = flight->renderer().poolPages();
  run->resizes = flight->resizes();
  run->preload_failures = flight->preloadFailures();
  // The run's statistics end with its last frame: reads that land while the
  // PNG writer drains are not the run's.
  run->streamer = flight->streamer().stats();
  if (o.before_finish)
    if (Status s = o.before_finish(); !s) return s;
  trace_guard.done = true;
  flight->finish();
  run->trace_status = flight->streamer().traceStatus();
  run->render_thread_fetches = watched->renderThreadFetches();
  run->tile_failures = run->streamer.total.failures + run->preload_failures;
  run->remote = o.source->remoteStats();
  if (o.terrain && o.terrain->source) run->remote += o.terrain->source->remoteStats();
  run->rss_end_bytes = currentRssBytes();

  summarizeFlight(o, *flight, accuracy.get(), terrain_sampled, height_sampled, run);
  return okStatus();
}

}  // namespace clipstream
