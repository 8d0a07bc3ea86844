// The frame loop's one step. See flight.h and docs/renderer.md.
#include <clipstream/renderer/flight.h>

#include "gl.h"

#include <clipstream/renderer/config.h>
#include <clipstream/renderer/gl_context.h>
#include <clipstream/store/cog.h>
#include <clipstream/store/tile_store.h>
#include <clipstream/streamer/alignment.h>

#include <algorithm>
#include <chrono>
#include <cmath>

namespace clipstream {
namespace {

using Clock = std::chrono::steady_clock;

double msBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

}  // namespace

bool isCut(const Camera& previous, const Camera& current, double previous_step_texels) {
  const double step = glm::length(current.position - previous.position);
  const double two_pi = 6.283185307179586;
  double turn = std::fmod(std::abs(current.heading_rad - previous.heading_rad), two_pi);
  turn = std::min(turn, two_pi - turn);
  if (turn > kCutTurnRad || std::abs(current.pitch_rad - previous.pitch_rad) > kCutTurnRad) return true;
  return step > 0.5 * std::max(previous.position.y, 1.0) &&
         step > 8.0 * std::max(previous_step_texels, 1.0);
}

Status createClipmapRenderer(TileSource& source, const Viewport& viewport, const Camera& camera,
                             const PlannerConfig& planner, Buffering buffering,
                             std::unique_ptr<ClipmapRenderer>* out, uint32_t* failures,
                             ClipmapPlan* plan, uint32_t upload_tiles, TextureMemory memory,
                             uint64_t pool_bytes) {
  out->reset();
  const ClipmapPlan first = planClipmap(source.geometry(), viewport, camera, planner);
  std::unique_ptr<ClipmapRenderer> renderer;
  RendererConfig rc{first.clip_tiles, first.pyramid_level, buffering, source.content(), upload_tiles, memory,
                    pool_bytes != 0 ? pool_bytes
                                    : defaultPoolBytes(viewport, source.geometry().tile_px, source.content())};
  if (Status s = ClipmapRenderer::create(source.geometry(), rc, &renderer); !s) return s;
  renderer->beginFrame();
  const uint32_t missing = renderer->loadPyramid(
      [&](const TileKey& key) -> std::shared_ptr<const std::vector<uint8_t>> {
        auto px = std::make_shared<std::vector<uint8_t>>();
        if (!source.fetch(key, px.get()).ok()) return nullptr;  // filled from its ancestor
        return px;
      });
  renderer->endUploads();
  if (failures != nullptr) *failures += missing;
  if (plan != nullptr) *plan = first;
  *out = std::move(renderer);
  return okStatus();
}

Status synthesizeRelief(uint32_t levels, TerrainLayerConfig* layer) {
  if (levels == 0) return okStatus();
  Status s;
  std::shared_ptr<TileSource> synthesized = makeSynthesizedHeightSource(layer->source, levels, &s);
  if (!synthesized) return s;
  layer->data_source = std::move(layer->source);
  layer->data_alignment = layer->alignment;
  layer->source = std::move(synthesized);
  layer->alignment.world_per_sample /= double(uint64_t(1) << levels);
  layer->synthesized_levels = levels;
  return okStatus();
}

Status aimAtMapPoint(const LookAt& look, const GeoReference& colour_geo, const PyramidGeometry& colour,
                     const TerrainLayerConfig* terrain, Camera* out, double* camera_ground) {
  glm::dvec2 map = look.map;
  if (look.lon_lat) {
    if (!colour_geo.present) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "longitude and latitude need a georeferenced colour store; give texels");
    }
    if (Status s = lonLatToMap(colour_geo.crs, look.map, &map); !s) return s;
  }
  glm::dvec2 world;
  if (Status s = mapToWorld(colour_geo, map, &world); !s) return s;
  double y = 0.0;
  if (look.height)
    y = *look.height * (terrain ? terrain->alignment.world_per_height : 1.0);
  else if (terrain)
    if (Status s = groundHeightAt(*terrain->source, terrain->alignment, world, &y); !s) return s;
  const double distance = kLookAtDistanceFraction * double(std::max(colour.width_px, colour.height_px));
  *out = lookAtCamera({world.x, y, world.y}, distance, 0.0, kLookAtPitchRad);
  *camera_ground = 0.0;
  if (terrain)
    if (Status s = groundHeightAt(*terrain->source, terrain->alignment, {out->position.x, out->position.z},
                                  camera_ground);
        !s)
      return s;
  return okStatus();
}

Status openTerrainLayer(const std::string& colour_path, const PyramidGeometry& colour_geometry,
                        const std::string& elevation_path, double vertical_scale, bool stretch,
                        uint32_t ring_cells, TerrainLayerConfig* out,
                        std::vector<std::string>* warnings, const RemoteOptions& remote) {
  *out = TerrainLayerConfig{};
  Status s;
  out->source = openElevationSource(elevation_path, remote, &s);
  if (!out->source) return s;
  out->ring_cells = ring_cells;
  StoreInfo colour;
  colour.geometry = colour_geometry;
  if (!colour_path.empty())
    if (s = readRasterInfo(colour_path, remote, &colour); !s) return s;
  StoreInfo heights;
  {
    std::unique_ptr<TileStoreReader> reader;
    if (s = TileStoreReader::open(elevation_path, remote, &reader); !s) return s;
    heights = reader->info();
  }
  if (s = alignElevation(colour, heights, vertical_scale, stretch, &out->alignment); !s) {
    return Status::error(s.code, elevation_path + ": " + s.message);
  }
  if (warnings != nullptr) {
    warnings->insert(warnings->end(), out->alignment.warnings.begin(), out->alignment.warnings.end());
  }
  return okStatus();
}

Status Flight::create(std::shared_ptr<TileSource> source, const FlightConfig& config,
                      const Camera& first, std::unique_ptr<Flight>* out) {
  out->reset();
  if (!source) return Status::error(ErrorCode::kInvalidArgument, "flight: no tile source");
  if (config.upload_tiles == 0)
    return Status::error(ErrorCode::kInvalidArgument, "flight: uploads per frame must be at least 1");
  keepHeapForSoftwareGl();
  if (config.texture_memory == TextureMemory::kPaged && config.terrain)
    return Status::error(ErrorCode::kInvalidArgument,
                         "flight: paged texture memory does not draw terrain yet; terrain takes the stack "
                         "(--texture-memory stack)");
  std::unique_ptr<Flight> f(new Flight());
  f->m_source = std::move(source);
  f->m_config = config;
  f->m_config.streamer.planner = plannerFor(config.texture_memory, config.streamer.planner);
  if (Status s = f->makeRenderer(config.viewport, first, &f->m_preload_ms); !s) return s;
  if (config.terrain) {
    const TerrainLayerConfig& t = *config.terrain;
    if (!t.source || t.source->content() != TileContent::kHeightF32)
      return Status::error(ErrorCode::kInvalidArgument, "flight: the terrain layer is not a height source");
    // Two layers through one cache: the colour texels are the world; the
    // elevation's texel under world (x, z) is (x - sample0) / spacing + 0.5
    // (sample i's centre lies at texel i + 0.5).
    const LayerAlignment& a = config.terrain->alignment;
    StreamLayer colour{f->m_source, LayerRole::kColour, {1.0, 1.0}, {0.0, 0.0}};
    StreamLayer heights{config.terrain->source, LayerRole::kElevation,
                        1.0 / a.world_per_sample, 0.5 - a.sample0_world / a.world_per_sample,
                        TerrainRenderer::windowTiles(config.terrain->ring_cells,
                                                     config.terrain->source->geometry().tile_px),
                        a.world_per_height};
    std::vector<StreamLayer> layers{colour, heights};
    if (Status s = checkStreamLayers(layers); !s) return s;
    f->m_streamer = std::make_unique<Streamer>(std::move(layers), f->m_config.streamer);
    // After the streamer: the terrain takes the height bounds it read.
    if (Status s = f->makeTerrain(); !s) return s;
  } else {
    f->m_streamer = std::make_unique<Streamer>(f->m_source, f->m_config.streamer);
  }
  f->m_before = f->m_streamer->stats();
  f->m_previous = first;
  *out = std::move(f);
  return okStatus();
}

Flight::~Flight() {
  // The streamer first: its workers may still hold the source.
  m_streamer.reset();
}

Status Flight::makeRenderer(const Viewport& viewport, const Camera& camera, double* preload_ms) {
  std::unique_ptr<OffscreenTarget> target;
  if (m_config.offscreen)
    if (Status s = OffscreenTarget::create(viewport, &target); !s) return s;
  // The old renderer's textures go first: two clipmaps need not fit at once.
  m_renderer.reset();
  std::unique_ptr<ClipmapRenderer> renderer;
  ClipmapPlan plan;
  const auto start = Clock::now();
  if (Status s = createClipmapRenderer(*m_source, viewport, camera, m_config.streamer.planner,
                                       m_config.buffering, &renderer, &m_preload_failures, &plan,
                                       m_config.upload_tiles, m_config.texture_memory, m_config.pool_bytes);
      !s)
    return s;
  *preload_ms = msBetween(start, Clock::now());
  renderer->setOverlay(m_config.overlay);
  m_renderer = std::move(renderer);
  m_target = std::move(target);
  m_first_plan = std::move(plan);
  return okStatus();
}

Status Flight::makeTerrain() {
  const TerrainLayerConfig& t = *m_config.terrain;
  TerrainConfig tc;
  tc.ring_cells = t.ring_cells;
  tc.clip_tiles = TerrainRenderer::windowTiles(t.ring_cells, t.source->geometry().tile_px);
  tc.mapping = t.alignment;
  tc.method = t.method;
  tc.error_px = t.error_px;
  tc.triangle_budget = t.triangle_budget;
  tc.lighting = t.lighting;
  tc.detail_textures = t.detail_textures;
  std::unique_ptr<TerrainRenderer> terrain;
  if (Status s = TerrainRenderer::create(t.source->geometry(), tc, &terrain); !s) return s;
  if (t.method == TerrainMethod::kQuadtree || t.method == TerrainMethod::kFlat) {
    // The per-tile errors the quadtree refines by: the streamer's, read
    // once for its planner; a streamer planning against the plane reads
    // none, so then they are read here, once (kept for resize()).
    if (!m_terrain_bounds) m_terrain_bounds = m_streamer->terrainBounds();
    if (!m_terrain_bounds && !m_config.streamer.terrain_bounds)
      (void)loadTerrainBounds(*t.source, kTerrainBoundsMaxLevelTiles, &m_terrain_bounds);
    if (m_terrain_bounds) terrain->setBounds(m_terrain_bounds);
  }
  TileSource& source = *t.source;
  m_preload_failures += terrain->preloadCoarseLevels(
      [&](const TileKey& key) -> std::shared_ptr<const std::vector<uint8_t>> {
        auto px = std::make_shared<std::vector<uint8_t>>();
        if (!source.fetch(key, px.get()).ok()) return nullptr;
        return px;
      });
  m_terrain = std::move(terrain);
  return okStatus();
}

bool Flight::groundHeight(const glm::dvec2& world_xz, double* height) const {
  *height = 0.0;
  return m_terrain && m_terrain->groundHeight(world_xz, height);
}

Status Flight::resize(const Viewport& viewport, const Camera& camera, const Viewport& framebuffer) {
  double preload_ms = 0.0;
  if (Status s = makeRenderer(viewport, camera, &preload_ms); !s) {
    // Without a renderer there is nothing to step: put one back for the old viewport.
    if (!m_renderer) (void)makeRenderer(m_config.viewport, camera, &preload_ms);
    return s;
  }
  m_config.viewport = viewport;
  m_config.framebuffer = framebuffer;
  // The height stack follows the clip size too (TerrainConfig::clip_tiles).
  if (m_terrain)
    if (Status s = makeTerrain(); !s) return s;
  m_streamer->resetGpuResidency();
  m_seen.reset();  // read again at the new size
  ++m_resizes;
  return okStatus();
}

namespace {

// The frame's per-level counters: RAM hits, misses and bytes read since
// `before` (of the colour layer), and GPU hits and misses of the needed
// stack levels' visible tiles; then their totals.
void countLevels(const StreamerStats& now, const StreamerStats& before, uint32_t levels, const ClipmapPlan& plan,
                 const UsableMap& usable, FrameSample* f) {
  f->levels.resize(levels);
  // The colour layer's counters (with terrain, `levels` sums both layers).
  const std::vector<LevelCounters>& now_levels = now.layers.empty() ? now.levels : now.layers[0].levels;
  const std::vector<LevelCounters>& before_levels =
      before.layers.empty() ? before.levels : before.layers[0].levels;
  for (uint32_t l = 0; l < levels; ++l) {
    const LevelCounters c = l < now_levels.size() ? now_levels[l] : LevelCounters{};
    const LevelCounters b = l < before_levels.size() ? before_levels[l] : LevelCounters{};
    LevelFrame& lf = f->levels[l];
    lf.ram_hits = c.ram_hits - b.ram_hits;
    lf.ram_misses = c.ram_misses - b.ram_misses;
    lf.bytes_read = c.bytes_read - b.bytes_read;
  }
  // GPU hits: visible tiles of the needed stack levels the shader may sample
  // (usable) this frame; misses draw from a coarser level.
  for (const ClipLevelPlan& lp : plan.stack) {
    if (!lp.needed || lp.level >= usable.usable.size() || lp.level >= levels) continue;
    LevelFrame& lf = f->levels[lp.level];
    for (int64_t y = lp.visible.y0; y < lp.visible.y1; ++y)
      for (int64_t x = lp.visible.x0; x < lp.visible.x1; ++x) {
        const bool ok =
            usable.windows[lp.level].contains(x, y) &&
            usable.usable[lp.level][size_t(toroidalSlot(y, usable.clip_tiles)) * usable.clip_tiles +
                                    toroidalSlot(x, usable.clip_tiles)] != 0;
        (ok ? lf.gpu_hits : lf.gpu_misses)++;
      }
  }
  for (const LevelFrame& lf : f->levels) {
    f->total.ram_hits += lf.ram_hits;
    f->total.ram_misses += lf.ram_misses;
    f->total.bytes_read += lf.bytes_read;
    f->total.gpu_hits += lf.gpu_hits;
    f->total.gpu_misses += lf.gpu_misses;
  }
}

}  // namespace

void Flight::bindFrame() {
  if (m_target) {
    m_target->bind();
  } else {
    const Viewport fb = m_config.framebuffer.width_px > 0 ? m_config.framebuffer : m_config.viewport;
    bindWindowFramebuffer(fb);
  }
}

void Flight::readGroundSeen(const Camera& camera) {
  auto seen = std::make_shared<GroundSeen>();
  const Viewport fb = !m_target && m_config.framebuffer.width_px > 0 ? m_config.framebuffer : m_config.viewport;
  m_terrain->readGroundSeen(camera, m_config.viewport, fb, seen.get());
  m_seen = std::move(seen);
  m_reads = std::make_shared<HeightReads>(m_terrain->heightReads());
}

void Flight::handGroundSeen(const Camera& camera, const Camera& planning) {
  // In the planner's space: without height bounds its camera stands at its
  // height above this frame's ground (planningCamera()), and the ground
  // seen moves with it, so that the distances from the camera hold.
  m_streamer->setHeightReads(m_reads);
  const double dy = planning.position.y - camera.position.y;
  if (dy == 0.0) {
    m_streamer->setGroundSeen(m_seen);
    return;
  }
  auto moved = std::make_shared<GroundSeen>(*m_seen);
  moved->camera.position.y += dy;
  for (glm::dvec3& p : moved->points) p.y += dy;
  m_streamer->setGroundSeen(std::move(moved));
}

Camera Flight::planningCamera(const Camera& camera, double* ground_height) {
  // Over terrain with the elevation store's per-tile bounds the streamer
  // plans against the terrain itself and takes the real camera. Without
  // them the planner sees the ground under the camera as its plane (the
  // flat planner's assumption, moved to the local ground height).
  Camera planning = camera;
  if (m_terrain && m_terrain->groundHeight({camera.position.x, camera.position.z}, ground_height) &&
      !m_streamer->plansOnTerrain()) {
    planning.position.y = std::max(camera.position.y - *ground_height, camera.near_dist);
    // ... and sees the relief around it: the footprint also covers the
    // highest and lowest ground in reach (a slope in front loads what the
    // frame shows of it).
    double lowest = 0.0, highest = 0.0;
    if (m_terrain->groundRange(camera, &lowest, &highest)) {
      m_streamer->setGroundRelief(highest - *ground_height, *ground_height - lowest);
    }
  }
  return planning;
}

FrameSample Flight::step(const Camera& camera) {
  return step(camera, double(m_steps) * renderer_config::kSimulatedFrameSeconds);
}

FrameSample Flight::step(const Camera& camera, double clock_s) {
  FrameSample f;
  f.warmup = m_steps < m_config.warmup_frames;
  f.frame = f.warmup ? m_steps : m_steps - m_config.warmup_frames;
  f.clock_s = clock_s;
  const double step_texels = glm::length(camera.position - m_previous.position);
  const bool jumped = m_steps > 0 && isCut(m_previous, camera, m_previous_step);
  if (!f.warmup) f.cut = f.frame == 0 ? m_config.warmup_frames == 0 : jumped;
  m_previous_step = step_texels;
  m_previous = camera;
  ++m_steps;

  const auto t0 = Clock::now();
  timespec cpu0{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &cpu0);
  const Camera planning = planningCamera(camera, &f.ground_height);
  // Over terrain the plan loads the ground the last frame showed. At the
  // first frame and after a jump there is none that says anything of this
  // view: the terrain is drawn once first, from what is resident (the
  // coarse levels at least), to read what this view shows.
  const bool read_seen = m_terrain && m_config.streamer.planner.scope == PlanScope::kSampled;
  if (read_seen && (jumped || !m_seen)) {
    bindFrame();
    ClipmapRenderer::clearSky();
    m_terrain->draw(camera, m_config.viewport, *m_renderer);
    readGroundSeen(camera);
  }
  if (read_seen) handGroundSeen(camera, planning);
  m_streamer->update(planning, m_config.viewport, clock_s);
  FrameHandoff handoff;
  if (m_terrain) {
    std::vector<FrameHandoff> all = m_streamer->takeReadyAll(m_config.upload_tiles);
    handoff = std::move(all[0]);
    const size_t floats = size_t(m_terrain->geometry().tile_px) * m_terrain->geometry().tile_px;
    for (const ReadyTile& t : all[1].tiles) {
      if (!t.rgba || t.rgba->size() != floats * sizeof(float)) continue;
      m_terrain->uploadTile(t.key, reinterpret_cast<const float*>(t.rgba->data()));
      ++f.height_tiles_uploaded;
    }
  } else {
    handoff = m_streamer->takeReady(m_config.upload_tiles);
  }
  const auto t_streamer = Clock::now();
  m_renderer->applyHandoff(handoff);
  const auto t_upload = Clock::now();
  bindFrame();
  ClipmapRenderer::clearSky();
  if (m_terrain) {
    m_terrain->draw(camera, m_config.viewport, *m_renderer);
    const TerrainFrame& tf = m_terrain->lastFrame();
    f.terrain_rings = tf.rings;
    f.terrain_finest_level = tf.finest_level;
    f.terrain_triangles = tf.triangles;
    f.terrain_error_px = tf.achieved_error_px;
    f.terrain_select_ms = tf.select_ms;
    // What this frame showed, for the next frames' plans.
    if (read_seen) readGroundSeen(camera);
  } else {
    m_renderer->draw(camera, m_config.viewport);
  }
  glFinish();  // frame time includes the GPU's (llvmpipe's) work
  const auto t1 = Clock::now();
  f.frame_ms = msBetween(t0, t1);
  timespec cpu1{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &cpu1);
  f.cpu_ms = double(cpu1.tv_sec - cpu0.tv_sec) * 1e3 + double(cpu1.tv_nsec - cpu0.tv_nsec) * 1e-6;
  f.streamer_ms = msBetween(t0, t_streamer);
  f.draw_ms = msBetween(t_upload, t1);
  const UploadStats& uploads = m_renderer->lastUploads();
  f.upload_ms = uploads.upload_ms;
  f.tiles_uploaded = uploads.tiles;
  f.second_copies = uploads.second_copies;
  f.pages_short = uploads.pages_short;
  f.pages_wanted = uploads.pages_wanted;
  f.max_texture_lod = handoff.max_texture_lod;
  const ClipmapPlan& plan = m_streamer->plan();
  f.finest_needed = plan.finest_level;

  const StreamerStats now = m_streamer->stats();
  f.queue_depth = now.queue_depth;
  f.in_flight = now.in_flight;
  f.ram_bytes = now.ram_bytes;
  f.tiles_loaded = now.total.loads - m_before.total.loads;
  countLevels(now, m_before, m_source->geometry().levelCount(), plan, m_renderer->usableMap(), &f);
  if (f.warmup) m_warmup_loads += f.tiles_loaded;
  m_before = now;
  return f;
}

StreamerStats Flight::finish() {
  const StreamerStats final_stats = m_streamer->stats();
  m_streamer->shutdown();
  return final_stats;
}

}  // namespace clipstream
