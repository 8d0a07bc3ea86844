// The streamer: planning on the render thread, loading on a worker pool, a
// RAM cache with a hard byte budget, and the per-frame GPU hand-off, for a
// scene of one or more layers. This file is the render thread's
// half: planning, the queue's order, the hand-off and statistics; the
// loaders' half is streamer_load.cpp, their shared state streamer_impl.h
// (with the locking rule). The pieces have files of their own: the RAM
// cache and its eviction order (ram_cache.h), the loader threads and their
// batches (loader_pool.h), the deterministic I/O device (io_device.h), the
// camera's motion for prefetch (motion.h), the request trace
// (trace_recorder.h) and the scene layers' checks (stream_layer.cpp).
#include "streamer_impl.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <deque>
#include <limits>
#include <mutex>
#include <optional>
#include <thread>
#include <tuple>
#include <unordered_map>
#include <unordered_set>

namespace clipstream {
namespace {

// True when a plan made from the path hint matches the real one: the same
// levels needed, and each needed window within a tile of the real one.
bool hintAgrees(const ClipmapPlan& hinted, const ClipmapPlan& real) {
  if (hinted.pyramid_level != real.pyramid_level || hinted.clip_tiles != real.clip_tiles ||
      hinted.stack.size() != real.stack.size())
    return false;
  for (size_t i = 0; i < real.stack.size(); ++i) {
    const ClipLevelPlan &h = hinted.stack[i], &r = real.stack[i];
    if (h.needed != r.needed) return false;
    if (r.needed && (std::abs(h.window.x0 - r.window.x0) > 1 || std::abs(h.window.y0 - r.window.y0) > 1))
      return false;
  }
  return true;
}

bool sameWindows(const ClipmapPlan& a, const ClipmapPlan& b) {
  if (a.pyramid_level != b.pyramid_level || a.clip_tiles != b.clip_tiles ||
      a.stack.size() != b.stack.size() || a.pyramid != b.pyramid)
    return false;
  for (size_t i = 0; i < a.stack.size(); ++i) {
    const ClipLevelPlan &x = a.stack[i], &y = b.stack[i];
    if (x.needed != y.needed || x.window != y.window || x.visible != y.visible ||
        x.sampled != y.sampled)
      return false;
  }
  return true;
}


// The order of roles among equally coarse tiles: elevation first.
int roleOrder(LayerRole role) { return role == LayerRole::kElevation ? 0 : 1; }

const PyramidGeometry kNoGeometry{};
const ClipmapPlan kNoPlan{};

}  // namespace


// ---------------------------------------------------------------------------
// Render thread

// Every layer's wanted tiles in the one load order (docs/architecture.md,
// "Layers"): every layer's pyramid before any stack level; then, in each
// group, coarse to fine by world-space coarseness; among equally coarse
// levels elevation before colour, then layer order; inside a layer's level
// rankPlanTiles()'s order (visible first, near the focus first). With one
// layer this is rankPlanTiles() itself.
std::vector<LayerTile> Streamer::Impl::rankScene() const {
  struct Ranked {
    int stack;               // 0: pyramid, 1: stack
    int64_t neg_coarseness;  // coarse first
    int role;
    uint32_t layer;
    LayerTile tile;
  };
  size_t active = 0;
  for (const Layer& layer : layers) active += layer.active() ? 1 : 0;
  if (active == 1) {
    // rankPlanTiles() already lists one layer in this order: skip the sort.
    std::vector<LayerTile> out;
    for (uint32_t i = 0; i < layers.size(); ++i) {
      if (!layers[i].active()) continue;
      const std::vector<TileKey> keys =
          rankPlanTiles(layers[i].geometry, layers[i].plan, config.frustum_priority);
      out.reserve(keys.size());
      for (const TileKey& k : keys) out.push_back({i, k});
    }
    return out;
  }
  std::vector<Ranked> ranked;
  for (uint32_t i = 0; i < layers.size(); ++i) {
    const Layer& layer = layers[i];
    if (!layer.active()) continue;
    for (const TileKey& k : rankPlanTiles(layer.geometry, layer.plan, config.frustum_priority))
      ranked.push_back({k.level < layer.plan.pyramid_level ? 1 : 0, -layer.coarseness(k.level),
                        layer.role_order, i, {i, k}});
  }
  // Stable: inside one layer's level rankPlanTiles()'s order stays.
  std::stable_sort(ranked.begin(), ranked.end(), [](const Ranked& a, const Ranked& b) {
    return std::tie(a.stack, a.neg_coarseness, a.role, a.layer) <
           std::tie(b.stack, b.neg_coarseness, b.role, b.layer);
  });
  std::vector<LayerTile> out;
  out.reserve(ranked.size());
  for (const Ranked& r : ranked) out.push_back(r.tile);
  return out;
}

// The predicted plans' tiles that entered and are not wanted now, coarse
// levels first: their tiles cover the most ground.
std::vector<LayerTile> Streamer::Impl::rankPrefetch(
    const std::unordered_set<LayerTile, FastKeyHash>& wanted_now) const {
  struct Predicted {
    int64_t neg_coarseness;
    int role;
    uint32_t layer;
    LayerTile tile;
  };
  std::vector<Predicted> predicted;
  for (uint32_t i = 0; i < layers.size(); ++i) {
    const Layer& layer = layers[i];
    if (!layer.active()) continue;
    for (const TileKey& k : diffPlans(layer.plan, layer.predicted_plan).entered)
      if (wanted_now.count({i, k}) == 0)
        predicted.push_back({-layer.coarseness(k.level), layer.role_order, i, {i, k}});
  }
  std::stable_sort(predicted.begin(), predicted.end(), [](const Predicted& a, const Predicted& b) {
    return std::tie(a.neg_coarseness, a.role, a.layer) < std::tie(b.neg_coarseness, b.role, b.layer);
  });
  std::vector<LayerTile> out;
  out.reserve(predicted.size());
  for (const Predicted& p : predicted) out.push_back(p.tile);
  return out;
}

// Recomputes the wanted list, ranks, pending hand-offs and the queue after
// the plans (or the predictions) changed.
void Streamer::Impl::rebuild(const Viewport& viewport) {
  std::vector<LayerTile> new_wanted = rankScene();
  std::unordered_set<LayerTile, FastKeyHash> new_set(new_wanted.begin(), new_wanted.end());
  std::vector<LayerTile> new_prefetch;
  if (config.prefetch && have_plan) new_prefetch = rankPrefetch(new_set);
  RamCache::Ranks new_rank;
  new_rank.reserve(new_wanted.size() + new_prefetch.size());
  uint32_t next_rank = 0;
  for (const LayerTile& k : new_wanted) new_rank.emplace(k, next_rank++);
  for (const LayerTile& k : new_prefetch) new_rank.emplace(k, next_rank++);

  // GPU residency survives while the tile stays in its needed window (or
  // the pyramid): the renderer reuses a slot as soon as its tile leaves the
  // window, and keeps it until then, so a tile that is no longer sampled
  // (PlanScope::kSampled) but still in the window is drawn again, without
  // a new upload, when it is sampled again.
  for (auto it = gpu.begin(); it != gpu.end();) {
    if (new_set.count(*it) == 0 && !inNeededWindow(*it)) it = gpu.erase(it); else ++it;
  }
  pending.clear();
  for (const LayerTile& k : new_wanted)
    if (gpu.count(k) == 0) pending.push_back(k);

  std::vector<PlanWindows> new_windows(layers.size()), new_predicted(layers.size());
  std::vector<std::shared_ptr<const LookaheadSnapshot>> new_ahead(layers.size());
  for (size_t i = 0; i < layers.size(); ++i) {
    Layer& layer = layers[i];
    new_windows[i] = planWindows(layer.plan);
    if (config.prefetch && have_plan) new_predicted[i] = planWindows(layer.predicted_plan);
    if (hint_used && config.eviction == EvictionMode::kGpuFirst) new_ahead[i] = layer.lookahead.snapshot();
  }
  hint_used_by_plan = hint_used;
  if (trace.active() && !layers.empty()) {
    trace.beginPlan(frame, now_s, hint_used, viewport, new_windows[0], new_predicted[0]);
    for (const LayerTile& k : new_wanted)
      if (k.layer == 0 && wanted_set.count(k) == 0) trace.tile(k.key, false);
    for (const LayerTile& k : wanted)
      if (k.layer == 0 && new_set.count(k) == 0) trace.tile(k.key, true);
    trace.endPlan();
  }

  if (!requeue(new_wanted, new_prefetch, std::move(new_rank), std::move(new_windows),
               std::move(new_predicted), std::move(new_ahead)))
    return;  // stopping
  wanted.swap(new_wanted);
  wanted_set.swap(new_set);
  prefetch.swap(new_prefetch);
}

// rebuild()'s shared part, under the lock: the cache learns the new ranks
// and windows; RAM hits and misses are counted for tiles that became wanted
// (GPU re-entries for those still on the GPU); the queue becomes the wanted
// and prefetched tiles not held, in rank order, keeping the queue time of
// those already queued and cancelling those no longer wanted. False when
// the streamer is stopping (nothing changed).
bool Streamer::Impl::requeue(const std::vector<LayerTile>& new_wanted, const std::vector<LayerTile>& new_prefetch,
                             RamCache::Ranks new_rank, std::vector<PlanWindows> new_windows,
                             std::vector<PlanWindows> new_predicted,
                             std::vector<std::shared_ptr<const LookaheadSnapshot>> new_ahead) {
  const auto now = Clock::now();
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (stopping) return false;
    shared_now_s = now_s;
    shared_frame = frame;
    for (auto& [key, entry] : cache->entries()) entry.gpu = gpu.count(key) != 0;
    for (const LayerTile& k : new_wanted) {
      CacheEntry* c = cache->find(k);
      if (c) c->last_wanted_frame = frame;
      if (wanted_set.count(k) == 0) {
        // A tile back in the wanted set that never left its needed window
        // is still on the GPU: drawn again, not read from RAM.
        if (gpu.count(k) != 0) counters(k).gpu_reentries++;
        else if (c && c->state == EntryState::kReady) counters(k).ram_hits++;
        else counters(k).ram_misses++;
      }
    }
    std::unordered_map<LayerTile, Clock::time_point, FastKeyHash> queued_at;
    for (const Request& r : queue) queued_at.emplace(r.key, r.queued_at);
    std::deque<Request> new_queue;
    std::unordered_set<LayerTile, FastKeyHash> kept;
    auto consider = [&](const LayerTile& k) {
      if (gpu.count(k) != 0 || cache->contains(k)) return;
      auto f = failed.find(k);
      if (f != failed.end()) {
        if (f->second.code != ErrorCode::kUnavailable || now_s < f->second.retry_at_s) return;
      }
      const auto q = queued_at.find(k);
      if (q != queued_at.end()) {
        kept.insert(k);
        new_queue.push_back({k, new_rank[k], q->second});
      } else {
        counters(k).requests++;
        new_queue.push_back({k, new_rank[k], now});
      }
    };
    for (const LayerTile& k : new_wanted) consider(k);
    for (const LayerTile& k : new_prefetch) consider(k);
    for (const Request& r : queue)
      if (kept.count(r.key) == 0) counters(r.key).cancellations++;
    queue.swap(new_queue);
    cache->setRanks(std::move(new_rank));
    for (uint32_t i = 0; i < layers.size(); ++i)
      cache->setWindows(i, std::move(new_windows[i]), std::move(new_predicted[i]), std::move(new_ahead[i]));
  }
  work_cv.notify_all();
  return true;
}

// MaxTextureLOD with throttling on (docs/decisions.md D60): the
// finest needed level that streaming serves now, i.e. that has a wanted
// tile on the GPU or in RAM or on its way there; the pyramid level (always
// resident) when none has. Levels finer than that have nothing to draw, so
// the clamp never hides a tile the renderer holds: the per-tile fallback
// (the usable map) draws every missing tile from its finest resident
// ancestor, and a uniform clamp that hid resident tiles was measured to
// cost 5-7 dB at x50-x100. What
// throttling does is on the reads (setReadAllowance()); this level shows it.
uint32_t Streamer::Impl::servedLod(const Layer& layer, uint32_t index) const {
  const uint32_t levels = layer.geometry.levelCount();
  if (levels == 0) return 0;
  const ClipmapPlan& plan = layer.plan;
  std::lock_guard<std::mutex> lock(mutex);  // for the cache
  for (uint32_t l = plan.finest_level; l < plan.pyramid_level && l < plan.stack.size(); ++l) {
    const ClipLevelPlan& lp = plan.stack[l];
    if (!lp.needed) continue;
    for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
      for (int64_t x = lp.window.x0; x < lp.window.x1; ++x) {
        if (!lp.wants(x, y)) continue;
        const LayerTile k{index, {l, uint32_t(x), uint32_t(y)}};
        if (gpu.count(k) != 0 || cache->contains(k)) return l;
      }
  }
  return std::min(plan.pyramid_level, levels - 1);
}

// One colour layer with the identity map (elevation if the source hands out
// heights: a single source is streamed as what it is).
Streamer::Streamer(std::shared_ptr<TileSource> source, const StreamerConfig& config)
    : Streamer(
          [&] {
            StreamLayer layer;
            layer.role = source && source->content() == TileContent::kHeightF32 ? LayerRole::kElevation
                                                                                : LayerRole::kColour;
            layer.source = std::move(source);
            return std::vector<StreamLayer>{std::move(layer)};
          }(),
          config) {}

Streamer::Streamer(std::vector<StreamLayer> layers, const StreamerConfig& config)
    : m_impl(std::make_unique<Impl>()) {
  Impl& s = *m_impl;
  s.config = config;
  s.layers.resize(layers.size());
  for (size_t i = 0; i < layers.size(); ++i) {
    Impl::Layer& layer = s.layers[i];
    layer.spec = std::move(layers[i]);
    if (layer.spec.source) {
      const Status check = checkStreamLayer(layer.spec, i);
      if (!check) {
        std::fprintf(stderr, "clipstream: %s; the layer stays empty\n", check.toString().c_str());
        layer.spec.source = nullptr;
      }
    }
    if (layer.spec.source) layer.geometry = layer.spec.source->geometry();
    layer.tile_bytes =
        tileContentBytes(layer.spec.source ? layer.spec.source->content() : TileContent::kRgba8,
                         layer.geometry.tile_px);
    layer.entry_bytes = layer.tile_bytes + kCacheEntryOverheadBytes;
    const glm::dvec2 k = layer.spec.texels_per_unit;
    layer.log2_units_per_texel = layer.spec.source ? -0.5 * std::log2(k.x * k.y) : 0.0;
    layer.role_order = roleOrder(layer.spec.role);
    layer.counters.resize(layer.geometry.levelCount());
    layer.published_lod = layer.geometry.levelCount() ? layer.geometry.levelCount() - 1 : 0;
    s.any_active = s.any_active || layer.spec.source != nullptr;
  }
  std::vector<uint64_t> entry_bytes;
  for (const Impl::Layer& layer : s.layers) entry_bytes.push_back(layer.entry_bytes);
  s.cache = std::make_unique<RamCache>(config.ram_budget_bytes, config.eviction, std::move(entry_bytes),
                                       [&s](const LayerTile& key) { s.counters(key).evictions++; });
  s.loadTerrain();
  if (!config.trace_path.empty()) s.trace.open(config.trace_path);
  if (!s.any_active) return;  // nothing to load; update() plans nothing
  unsigned suggested = 0;
  for (const Impl::Layer& layer : s.layers)
    if (layer.spec.source) suggested = std::max(suggested, layer.spec.source->suggestedLoaderThreads());
  const unsigned threads = loaderThreadCount(config.io_threads, suggested, std::thread::hardware_concurrency());
  s.loader_threads = s.loaders.start(threads, [this] { m_impl->workerLoop(); });
}

// The first elevation layer with a height scale and bounds is the scene's
// terrain; each layer sees it through its own map (as layerCamera() maps
// the camera: x and z by the map, heights by the mean scale).
void Streamer::Impl::loadTerrain() {
  if (!config.terrain_bounds) return;
  for (const Layer& e : layers) {
    if (!e.active() || e.spec.role != LayerRole::kElevation || e.spec.world_per_height <= 0.0) continue;
    std::shared_ptr<const TerrainBounds> bounds;
    const Status st = loadTerrainBounds(*e.spec.source, kTerrainBoundsMaxLevelTiles, &bounds);
    if (!st) {
      if (st.code != ErrorCode::kUnsupported)
        std::fprintf(stderr, "clipstream: %s; planning against the plane\n", st.toString().c_str());
      continue;
    }
    // The elevation's texel under world x is origin + k x, and sample i's
    // centre is its texel i + 0.5.
    const glm::dvec2 k = e.spec.texels_per_unit;
    const glm::dvec2 world_origin = (glm::dvec2(0.5) - e.spec.origin_texel) / k;
    for (Layer& layer : layers) {
      if (!layer.active()) continue;
      const glm::dvec2 kl = layer.spec.texels_per_unit;
      layer.terrain.bounds = bounds;
      layer.terrain.sample_origin = layer.spec.origin_texel + kl * world_origin;
      layer.terrain.units_per_sample = kl / k;
      layer.terrain.units_per_height = std::sqrt(kl.x * kl.y) * e.spec.world_per_height;
    }
    terrain_layer = int(&e - layers.data());
    return;
  }
}

// New detail into the render thread's map (the oldest dropped past
// kTerrainDetailTiles), and a new snapshot for every layer's plans.
void Streamer::Impl::takeDetail() {
  if (terrain_layer < 0) return;
  std::vector<std::pair<TileKey, std::shared_ptr<const TileDetail>>> incoming;
  {
    std::lock_guard<std::mutex> lock(mutex);
    incoming.swap(new_detail);
  }
  if (incoming.empty()) return;
  for (auto& [key, d] : incoming) {
    if (detail.insert_or_assign(key, std::move(d)).second) detail_order.push_back(key);
  }
  while (detail.size() > kTerrainDetailTiles && !detail_order.empty()) {
    detail.erase(detail_order.front());
    detail_order.pop_front();
  }
  auto snapshot = std::make_shared<TerrainDetail>();
  snapshot->tiles = detail;
  for (Layer& layer : layers)
    if (layer.terrain.bounds) layer.terrain.detail = snapshot;
}

bool Streamer::plansOnTerrain() const {
  for (const Impl::Layer& layer : m_impl->layers)
    if (layer.terrain.bounds) return true;
  return false;
}

std::shared_ptr<const TerrainBounds> Streamer::terrainBounds() const {
  const Impl& s = *m_impl;
  return s.terrain_layer >= 0 ? s.layers[size_t(s.terrain_layer)].terrain.bounds : nullptr;
}

Status Streamer::traceStatus() const { return m_impl->trace.status(); }

void Streamer::discardTrace() { m_impl->trace.discard(); }

Streamer::~Streamer() { shutdown(); }

size_t Streamer::layerCount() const { return m_impl->layers.size(); }

const StreamLayer& Streamer::layer(size_t layer) const {
  assert(layer < m_impl->layers.size());
  return m_impl->layers[layer].spec;
}

const PyramidGeometry& Streamer::geometry(size_t layer) const {
  const Impl& s = *m_impl;
  assert(layer < s.layers.size() || (layer == 0 && s.layers.empty()));
  return layer < s.layers.size() ? s.layers[layer].geometry : kNoGeometry;
}

// Plans every active layer for `cam` (a world camera) into *plans.
void Streamer::Impl::planAll(const Camera& cam, const Viewport& viewport, std::vector<ClipmapPlan>* plans) const {
  plans->resize(layers.size());
  for (size_t i = 0; i < layers.size(); ++i) {
    const Layer& layer = layers[i];
    if (layer.active())
      (*plans)[i] = planClipmap(layer.geometry, viewport, layerCamera(layer.spec, cam), layer.planner(config.planner));
  }
}

// The path hint counts only while it agrees with the real camera's plans
// (`next`), on every layer. When it does, the lookahead moves on with it.
bool Streamer::Impl::trustHint(const Viewport& viewport, double time_s, const std::vector<ClipmapPlan>& next) {
  if (!hint.camera_at || !std::isfinite(time_s)) return false;
  const Camera hinted = hint.camera_at(time_s);
  bool agrees = finiteCamera(hinted);
  for (size_t i = 0; i < layers.size() && agrees; ++i) {
    const Layer& layer = layers[i];
    if (layer.active())
      agrees = hintAgrees(
          planClipmap(layer.geometry, viewport, layerCamera(layer.spec, hinted), layer.planner(config.planner)), next[i]);
  }
  // The lookahead serves eviction by return time, which only kGpuFirst does.
  if (agrees && config.eviction == EvictionMode::kGpuFirst)
    for (Layer& layer : layers)
      if (layer.active())
        layer.lookahead.advance(layer.geometry, viewport, layer.planner(config.planner, false), layer.hint, time_s);
  return agrees;
}

// The plans for prefetch: those of the hinted camera prefetch_ahead_s ahead
// while the hint is trusted, else of the camera moving on at its recorded
// velocity (motion.h) with today's orientation; the current plans when
// neither (no prefetch, too short a history, a teleport).
std::vector<ClipmapPlan> Streamer::Impl::predictPlans(const Camera& camera, const Viewport& viewport, double time_s,
                                                      const std::vector<ClipmapPlan>& next) {
  motion.record(time_s, camera.position);
  std::vector<ClipmapPlan> predicted = next;
  if (!config.prefetch) return predicted;
  if (hint_used) {
    const Camera hinted_ahead = hint.camera_at(time_s + config.prefetch_ahead_s);
    if (finiteCamera(hinted_ahead)) {
      planAll(hinted_ahead, viewport, &predicted);
      return predicted;
    }
  }
  // A jump since the last frame farther than two windows of the finest
  // needed level, of any layer in its texels, is a teleport.
  std::vector<MotionPredictor::JumpLimit> limits;
  for (size_t i = 0; i < layers.size(); ++i) {
    const Layer& layer = layers[i];
    if (!layer.active()) continue;
    const double window_texels = double(next[i].clip_tiles) * double(layer.geometry.tile_px) *
                                 std::ldexp(1.0, int(next[i].finest_level));
    limits.push_back({layer.spec.texels_per_unit, MotionPredictor::teleportTexels(window_texels)});
  }
  if (const std::optional<Camera> ahead = motion.predict(camera, config.prefetch_ahead_s, limits))
    planAll(*ahead, viewport, &predicted);
  return predicted;
}

void Streamer::update(const Camera& camera, const Viewport& viewport, double time_s) {
  Impl& s = *m_impl;
  bool any_levels = false;
  for (const Impl::Layer& layer : s.layers) any_levels = any_levels || layer.active();
  if (!any_levels) return;
  s.frame++;
  s.now_s = time_s;
  if (s.deterministic()) s.publishDueReads(false);
  s.takeDetail();
  std::vector<ClipmapPlan> next;
  s.planAll(camera, viewport, &next);
  s.hint_used = s.trustHint(viewport, time_s, next);
  std::vector<ClipmapPlan> predicted = s.predictPlans(camera, viewport, time_s, next);

  bool retry_due = false;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    s.shared_now_s = time_s;
    if (s.hint.camera_at) (s.hint_used ? s.hint_frames : s.hint_ignored_frames)++;
    for (const auto& [key, f] : s.failed) {
      if (f.code == ErrorCode::kUnavailable && time_s >= f.retry_at_s && s.wanted_set.count(key)) {
        retry_due = true;
        break;
      }
    }
  }
  bool changed = !s.have_plan || s.force_rebuild || retry_due || s.hint_used != s.hint_used_by_plan;
  for (size_t i = 0; i < s.layers.size(); ++i) {
    Impl::Layer& layer = s.layers[i];
    changed = changed || !sameWindows(layer.plan, next[i]) ||
              !sameWindows(layer.predicted_plan, predicted[i]);
    layer.plan = std::move(next[i]);
    layer.predicted_plan = std::move(predicted[i]);
  }
  if (changed) {
    s.have_plan = true;
    s.force_rebuild = false;
    s.rebuild(viewport);
  }
  if (s.deterministic()) s.issueReads();
}

// Hands off ready tiles of layers [0, layer_count) in rank order within one
// shared per-frame budget, then each layer's MaxTextureLOD and residency.
std::vector<FrameHandoff> Streamer::Impl::handOff(size_t layer_count, size_t max_tiles,
                                                  size_t max_bytes) {
  std::vector<FrameHandoff> out(layer_count);
  for (size_t i = 0; i < layer_count; ++i) out[i].layer = uint32_t(i);
  {
    std::lock_guard<std::mutex> lock(mutex);
    size_t bytes = 0, tiles = 0;
    std::vector<LayerTile> still_pending;
    still_pending.reserve(pending.size());
    for (const LayerTile& k : pending) {
      if (k.layer >= layer_count) {
        still_pending.push_back(k);
        continue;
      }
      const size_t tile_bytes = layers[k.layer].tile_bytes;
      const bool room = tiles < max_tiles && (max_bytes == 0 || bytes + tile_bytes <= max_bytes);
      CacheEntry* c = room ? cache->find(k) : nullptr;
      if (!c || c->state != EntryState::kReady) {
        still_pending.push_back(k);
        continue;
      }
      c->gpu = true;
      cache->invalidateOrder();  // it may be scored for eviction now
      gpu.insert(k);
      counters(k).gpu_handoffs++;
      out[k.layer].tiles.push_back({k.key, c->rgba});
      ++tiles;
      bytes += tile_bytes;
    }
    pending.swap(still_pending);
    // A budget of 0 hands nothing and tells nothing of the renderer's rate.
    if (max_tiles > 0) upload_budget = max_tiles;
    setReadAllowance(upload_budget);
  }
  work_cv.notify_all();  // the loaders may read again

  for (uint32_t i = 0; i < layer_count; ++i) {
    Layer& layer = layers[i];
    FrameHandoff& h = out[i];
    h.max_texture_lod = config.throttle ? servedLod(layer, i) : layer.plan.finest_level;
    {
      std::lock_guard<std::mutex> lock(mutex);
      layer.published_lod = h.max_texture_lod;
    }
    layerResidency(i, &h);
  }
  return out;
}

// Which tiles of each needed level's window the GPU holds, and which of them
// no frame samples (PlanScope::kSampled), for the renderer's usable map.
void Streamer::Impl::layerResidency(uint32_t i, FrameHandoff* out) const {
  const Layer& layer = layers[i];
  out->residency.reserve(layer.plan.stack.size());
  for (const ClipLevelPlan& lp : layer.plan.stack) {
    LevelResidency r;
    r.level = lp.level;
    r.window = lp.window;
    r.resident.assign(size_t(lp.window.width() * lp.window.height()), 0);
    if (lp.needed) {
      size_t j = 0;
      for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
        for (int64_t x = lp.window.x0; x < lp.window.x1; ++x, ++j)
          r.resident[j] = gpu.count({i, {lp.level, uint32_t(x), uint32_t(y)}}) ? 1 : 0;
      if (!lp.sampled.empty()) {
        r.unread.assign(r.resident.size(), 0);
        j = 0;
        for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
          for (int64_t x = lp.window.x0; x < lp.window.x1; ++x, ++j) r.unread[j] = lp.wants(x, y) ? 0 : 1;
      }
    }
    out->residency.push_back(std::move(r));
  }
}

FrameHandoff Streamer::takeReady(size_t max_tiles, size_t max_bytes) {
  Impl& s = *m_impl;
  if (s.layers.empty()) return {};
  return std::move(s.handOff(1, max_tiles, max_bytes).front());
}

std::vector<FrameHandoff> Streamer::takeReadyAll(size_t max_tiles, size_t max_bytes) {
  Impl& s = *m_impl;
  return s.handOff(s.layers.size(), max_tiles, max_bytes);
}

void Streamer::setGroundRelief(double above, double below) {
  Impl& s = *m_impl;
  s.config.planner.ground_above = std::isfinite(above) ? std::max(above, 0.0) : 0.0;
  s.config.planner.ground_below = std::isfinite(below) ? std::max(below, 0.0) : 0.0;
}

void Streamer::setGroundSeen(std::shared_ptr<const GroundSeen> seen) {
  Impl& s = *m_impl;
  for (Impl::Layer& layer : s.layers) {
    layer.seen = nullptr;
    if (!seen || !layer.active() || layer.spec.role != LayerRole::kColour) continue;
    // The layer's texels, as layerCamera() maps the camera.
    const glm::dvec2 k = layer.spec.texels_per_unit;
    const double scale = std::sqrt(k.x * k.y);
    auto mapped = std::make_shared<GroundSeen>(*seen);
    mapped->camera = layerCamera(layer.spec, seen->camera);
    for (glm::dvec3& p : mapped->points)
      p = {layer.spec.origin_texel.x + k.x * p.x, p.y * scale, layer.spec.origin_texel.y + k.y * p.z};
    layer.seen = std::move(mapped);
  }
}

void Streamer::setHeightReads(std::shared_ptr<const HeightReads> reads) {
  Impl& s = *m_impl;
  for (Impl::Layer& layer : s.layers) {
    layer.reads = nullptr;
    if (!reads || !layer.active() || layer.spec.role != LayerRole::kElevation) continue;
    // The rects are in the layer's samples already; the camera as
    // layerCamera() maps it.
    auto mapped = std::make_shared<HeightReads>(*reads);
    mapped->camera = layerCamera(layer.spec, reads->camera);
    layer.reads = std::move(mapped);
  }
}

void Streamer::setPathHint(PathHint hint) {
  Impl& s = *m_impl;
  s.hint = std::move(hint);
  for (Impl::Layer& layer : s.layers) {
    layer.lookahead.reset();
    layer.hint = s.hint;
    if (s.hint.camera_at) {
      // The layer's lookahead plans in its texels: the hinted camera mapped.
      StreamLayer map = layer.spec;
      map.source = nullptr;
      layer.hint.camera_at = [camera_at = s.hint.camera_at, map](double t_s) {
        return layerCamera(map, camera_at(t_s));
      };
    }
  }
  s.hint_used = false;
  s.force_rebuild = true;  // the next update() plans with (or without) the new hint
  std::lock_guard<std::mutex> lock(s.mutex);
  s.cache->clearAhead();  // no eviction by the old path meanwhile
}

void Streamer::resetGpuResidency() {
  Impl& s = *m_impl;
  s.gpu.clear();
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    for (auto& [key, entry] : s.cache->entries()) entry.gpu = false;
  }
  s.force_rebuild = true;  // re-queue wanted tiles no longer in RAM
  s.pending = s.wanted;
}

const ClipmapPlan& Streamer::plan(size_t layer) const {
  const Impl& s = *m_impl;
  assert(layer < s.layers.size() || (layer == 0 && s.layers.empty()));
  return layer < s.layers.size() ? s.layers[layer].plan : kNoPlan;
}

bool Streamer::settled() const {
  const Impl& s = *m_impl;
  if (!s.have_plan) return false;
  std::lock_guard<std::mutex> lock(s.mutex);
  for (const LayerTile& k : s.pending) {
    const auto f = s.failed.find(k);
    if (f == s.failed.end() || f->second.code == ErrorCode::kUnavailable) return false;
  }
  return true;
}

namespace {

void addCounters(const LevelCounters& c, LevelCounters* sum) {
  sum->requests += c.requests;
  sum->ram_hits += c.ram_hits;
  sum->ram_misses += c.ram_misses;
  sum->gpu_reentries += c.gpu_reentries;
  sum->gpu_handoffs += c.gpu_handoffs;
  sum->cancellations += c.cancellations;
  sum->evictions += c.evictions;
  sum->redundant_reads += c.redundant_reads;
  sum->bytes_read += c.bytes_read;
  sum->failures += c.failures;
  sum->loads += c.loads;
  sum->budget_skips += c.budget_skips;
}

}  // namespace

StreamerStats Streamer::stats() const {
  const Impl& s = *m_impl;
  StreamerStats out;
  std::vector<double> lat;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    out.layers.resize(s.layers.size());
    for (size_t i = 0; i < s.layers.size(); ++i) {
      const Impl::Layer& layer = s.layers[i];
      LayerStats& ls = out.layers[i];
      ls.levels = layer.counters;
      ls.ram_bytes = s.cache->layerBytes(uint32_t(i));
      ls.ram_entries = s.cache->layerEntries(uint32_t(i));
      ls.max_texture_lod = layer.published_lod;
    }
    out.ram_bytes = s.cache->bytes();
    out.ram_peak_bytes = s.cache->peakBytes();
    out.queue_depth = s.queue.size();
    out.in_flight = s.in_flight;
    out.reads_held = !s.queue.empty() && s.read_allowance <= 0;
    out.decode_ms_total = s.decode_ms_total;
    out.max_texture_lod = s.layers.empty() ? 0 : s.layers[0].published_lod;
    out.ram_entries = s.cache->size();
    out.path_hint_frames = s.hint_frames;
    out.path_hint_ignored_frames = s.hint_ignored_frames;
    out.loader_threads = s.loader_threads;
    lat = s.latency_ms;
  }
  out.ram_budget_bytes = s.config.ram_budget_bytes;
  out.entry_overhead_bytes = kCacheEntryOverheadBytes;
  for (LayerStats& ls : out.layers) {
    if (out.levels.size() < ls.levels.size()) out.levels.resize(ls.levels.size());
    for (size_t l = 0; l < ls.levels.size(); ++l) {
      addCounters(ls.levels[l], &ls.total);
      addCounters(ls.levels[l], &out.levels[l]);
    }
  }
  for (const LevelCounters& c : out.levels) addCounters(c, &out.total);
  if (!lat.empty()) {
    std::sort(lat.begin(), lat.end());
    out.queue_latency_p50_ms = lat[(lat.size() - 1) / 2];
    out.queue_latency_p99_ms = lat[std::min(lat.size() - 1, size_t(double(lat.size()) * 0.99))];
  }
  return out;
}

std::vector<TileKey> Streamer::queuedTiles() const {
  const Impl& s = *m_impl;
  std::lock_guard<std::mutex> lock(s.mutex);
  std::vector<TileKey> out;
  out.reserve(s.queue.size());
  for (const Impl::Request& r : s.queue) out.push_back(r.key.key);
  return out;
}

std::vector<LayerTile> Streamer::queuedLayerTiles() const {
  const Impl& s = *m_impl;
  std::lock_guard<std::mutex> lock(s.mutex);
  std::vector<LayerTile> out;
  out.reserve(s.queue.size());
  for (const Impl::Request& r : s.queue) out.push_back(r.key);
  return out;
}

void Streamer::shutdown() {
  Impl& s = *m_impl;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    if (!s.stopping) {
      s.stopping = true;
      for (const Impl::Request& r : s.queue) s.counters(r.key).cancellations++;
      s.queue.clear();
    }
  }
  s.work_cv.notify_all();
  // Workers finish the read they are in, publish it, then see `stopping`
  // (with deterministic I/O: finish every ticket issued, which this thread
  // then publishes).
  s.loaders.join();
  s.publishDueReads(true);
  s.trace.finish();
}

}  // namespace clipstream
