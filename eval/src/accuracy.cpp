// The ideal reference and per-frame accuracy. See accuracy.h and
// docs/accuracy.md.
#include <clipstream/eval/accuracy.h>

#include <clipstream/renderer/config.h>

#include <algorithm>

namespace clipstream {

IdealReference::~IdealReference() = default;

Status IdealReference::create(std::shared_ptr<TileSource> source, const Viewport& viewport,
                              const PlannerConfig& planner, std::unique_ptr<IdealReference>* out,
                              TextureMemory memory) {
  std::unique_ptr<IdealReference> r(new IdealReference());
  r->m_source = std::move(source);
  r->m_geometry = r->m_source->geometry();
  r->m_planner = plannerFor(memory, planner);
  r->m_memory = memory;
  if (Status s = r->resize(viewport); !s) return s;
  *out = std::move(r);
  return okStatus();
}

Status IdealReference::resize(const Viewport& viewport) {
  m_viewport = viewport;
  m_renderer.reset();
  m_target.reset();
  // The clip size depends on the viewport only, not the camera.
  const ClipmapPlan plan = planClipmap(m_geometry, viewport, Camera{}, m_planner);
  RendererConfig rc{plan.clip_tiles, plan.pyramid_level, Buffering::kSingle, m_source->content()};
  rc.texture_memory = m_memory;
  // Four times the flight's default pool: prepare() fails rather than
  // draw a reference that fell short of a page.
  if (m_memory == TextureMemory::kPaged)
    rc.pool_bytes = 4 * defaultPoolBytes(viewport, m_geometry.tile_px, m_source->content());
  if (Status s = ClipmapRenderer::create(m_geometry, rc, &m_renderer); !s) return s;
  if (Status s = OffscreenTarget::create(viewport, &m_target); !s) return s;
  m_loaded.assign(plan.pyramid_level, TileRect{});
  // The pyramid: every tile of every level that fits one clip, once.
  m_renderer->beginFrame();
  // Tiles that failed show their ancestor, as in the streamed renderer.
  m_renderer->loadPyramid([this](const TileKey& key) { return tile(key); });
  m_renderer->endUploads();
  return okStatus();
}

std::shared_ptr<const std::vector<uint8_t>> IdealReference::tile(const TileKey& key) {
  const uint64_t packed = packTileKey(key);
  auto it = m_cache.find(packed);
  if (it != m_cache.end()) return it->second;
  auto px = std::make_shared<std::vector<uint8_t>>();
  std::shared_ptr<const std::vector<uint8_t>> value;
  if (m_source->fetch(key, px.get()).ok()) value = std::move(px);
  m_cache.emplace(packed, value);
  return value;
}

Status IdealReference::render(const Camera& camera, std::vector<uint8_t>* rgba) {
  if (Status s = prepare(camera, false); !s) return s;
  m_target->bind();
  ClipmapRenderer::clearSky();
  m_renderer->draw(camera, m_viewport);
  m_target->readRgba(rgba);
  return okStatus();
}

Status IdealReference::prepare(const Camera& camera, bool every_level) {
  m_plan = planClipmap(m_geometry, m_viewport, camera, m_planner);
  if (every_level)
    for (ClipLevelPlan& lp : m_plan.stack) lp.needed = true;
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
      // The streamer's rule for a tile that failed: it keeps its neighbours
      // from being drawn only where a tap of the frame reads it.
      if (!lp.sampled.empty()) {
        r.unread.assign(r.resident.size(), 0);
        size_t j = 0;
        for (int64_t y = lp.window.y0; y < lp.window.y1; ++y)
          for (int64_t x = lp.window.x0; x < lp.window.x1; ++x, ++j) r.unread[j] = lp.wants(x, y) ? 0 : 1;
      }
    } else {
      m_loaded[lp.level] = TileRect{};
    }
    residency.push_back(std::move(r));
  }
  m_renderer->setResidency(residency);
  m_renderer->setMaxTextureLod(0);
  m_renderer->endUploads();
  if (const uint32_t short_of = m_renderer->lastUploads().pages_short; short_of > 0)
    return Status::error(ErrorCode::kOutOfMemory,
                         "ideal reference: its page pool (" + std::to_string(m_renderer->poolPages()) +
                             " pages) is " + std::to_string(short_of) + " short for this view");
  return okStatus();
}

Status FlyAccuracy::create(std::shared_ptr<TileSource> source, const Viewport& viewport,
                           const PlannerConfig& planner, const AccuracyOptions& options,
                           std::unique_ptr<FlyAccuracy>* out) {
  std::unique_ptr<FlyAccuracy> a(new FlyAccuracy());
  a->m_source = source;
  a->m_options = options;
  a->m_viewport = viewport;
  if (options.reference)
    if (Status s = IdealReference::create(source, viewport, planner, &a->m_reference, options.texture_memory); !s)
      return s;
  if (options.ground_truth) a->m_texels = texelsFromSource(source);
  *out = std::move(a);
  return okStatus();
}

Status FlyAccuracy::resize(const Viewport& viewport) {
  m_viewport = viewport;
  return m_reference ? m_reference->resize(viewport) : okStatus();
}

Status FlyAccuracy::measure(const Camera& camera, const OffscreenTarget& target, bool compare,
                            bool ground_truth, AccuracyFrame* out) {
  *out = AccuracyFrame{};
  if (m_options.sample_tiles) sampledTiles(m_source->geometry(), camera, m_viewport, &m_sampled);
  if (!compare) return okStatus();
  if (!m_reference)
    return Status::error(ErrorCode::kInvalidArgument, "accuracy: a comparison asked of a run without a reference");
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
  return okStatus();
}

}  // namespace clipstream
