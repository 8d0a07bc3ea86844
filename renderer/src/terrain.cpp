// TerrainRenderer (terrain.h), which forwards to TerrainRendererImpl
// (terrain_impl.h), and the impl's life and CPU side: create()'s steps, the
// height uploads, the coarsest ring, the ground queries and the position
// pass. The draws are in terrain_draw.cpp and terrain_quadtree.cpp.
#include <clipstream/renderer/terrain.h>
#include <clipstream/renderer/testing/terrain_measure.h>

#include "clipmap_renderer_impl.h"
#include "gl.h"
#include "terrain_impl.h"

#include <algorithm>
#include <cmath>

namespace clipstream {
namespace {

bool isPowerOfTwo(uint32_t v) { return v != 0 && (v & (v - 1)) == 0; }

}  // namespace

const char* terrainMethodName(TerrainMethod method) {
  switch (method) {
    case TerrainMethod::kClipmap: return "clipmap";
    case TerrainMethod::kQuadtree: return "quadtree";
    case TerrainMethod::kFlat: return "flat";
    case TerrainMethod::kFull: return "full";
  }
  return "?";
}

const char* terrainLightingName(TerrainLighting lighting) {
  switch (lighting) {
    case TerrainLighting::kVertex: return "vertex";
    case TerrainLighting::kPixel: return "pixel";
  }
  return "?";
}

// ---- TerrainRenderer: the installed API, forwarded ----

TerrainRenderer::TerrainRenderer(std::unique_ptr<TerrainRendererImpl> impl) : m_impl(std::move(impl)) {}
TerrainRenderer::~TerrainRenderer() = default;

Status TerrainRenderer::create(const PyramidGeometry& heights, const TerrainConfig& config,
                               std::unique_ptr<TerrainRenderer>* out) {
  out->reset();
  std::unique_ptr<TerrainRendererImpl> impl;
  if (Status s = TerrainRendererImpl::create(heights, config, &impl); !s) return s;
  out->reset(new TerrainRenderer(std::move(impl)));
  return okStatus();
}

void TerrainRenderer::uploadTile(const TileKey& key, const float* heights) { m_impl->uploadTile(key, heights); }
uint32_t TerrainRenderer::preloadCoarseLevels(const HeightTileFn& tile) { return m_impl->preloadCoarseLevels(tile); }
void TerrainRenderer::draw(const Camera& camera, const Viewport& viewport, const ClipmapRenderer& colour) {
  m_impl->draw(camera, viewport, colour);
}
bool TerrainRenderer::groundHeight(const glm::dvec2& world_xz, double* height, uint32_t* level) const {
  return m_impl->groundHeight(world_xz, height, level);
}
Status TerrainRenderer::readPositions(const Camera& camera, const Viewport& viewport,
                                      const ClipmapRenderer& colour, std::vector<float>* xyzw) {
  return m_impl->readPositions(camera, viewport, colour, xyzw);
}
bool TerrainRenderer::groundRange(const Camera& camera, double* lowest, double* highest) const {
  return m_impl->groundRange(camera, lowest, highest);
}
void TerrainRenderer::setBounds(std::shared_ptr<const TerrainBounds> bounds) { m_impl->setBounds(std::move(bounds)); }
void TerrainRenderer::setErrorBound(double error_px) { m_impl->setErrorBound(error_px); }
Status TerrainRenderer::setLighting(TerrainLighting lighting) { return m_impl->setLighting(lighting); }
Status TerrainRenderer::setDetailTextures(bool on) { return m_impl->setDetailTextures(on); }
const TerrainFrame& TerrainRenderer::lastFrame() const { return m_impl->lastFrame(); }
const std::vector<TerrainNode>& TerrainRenderer::lastNodes() const { return m_impl->lastNodes(); }
const std::vector<TileKey>& TerrainRenderer::lastHeightTiles() const { return m_impl->lastHeightTiles(); }
const HeightReads& TerrainRenderer::heightReads() const { return m_impl->heightReads(); }
uint64_t TerrainRenderer::textureBytes() const { return m_impl->textureBytes(); }
const PyramidGeometry& TerrainRenderer::geometry() const { return m_impl->geometry(); }
const TerrainConfig& TerrainRenderer::config() const { return m_impl->config(); }

// ---- TerrainRendererImpl ----

Status TerrainRendererImpl::create(const PyramidGeometry& heights, const TerrainConfig& config,
                                   std::unique_ptr<TerrainRendererImpl>* out) {
  out->reset();
  if (Status s = checkConfig(heights, config); !s) return s;
  std::unique_ptr<TerrainRendererImpl> r(new TerrainRendererImpl());
  r->m_geometry = heights;
  r->m_config = config;
  if (config.method == TerrainMethod::kFull) r->m_config.full_resolution = true;
  // The outermost ring covers the whole height field (and the colour image)
  // from wherever the camera is: chosen every frame (updateCoarsest()).
  // Rings may be coarser than the pyramid's last level (its one tile,
  // decimated further in the shader). Until the first frame: the field
  // seen from its centre.
  r->m_coarsest = r->coarsestFor(glm::dvec2(heights.width_px, heights.height_px) * 0.5);
  if (Status s = TerrainPrograms::create(r->m_config.full_resolution, &r->m_programs); !s) return s;
  if (Status s = r->buildMeshes(); !s) return s;
  // The full-resolution mesh holds level 0 alone.
  const uint32_t layers = r->m_config.full_resolution ? 1 : heights.levelCount();
  const uint32_t slots = TerrainHeightStack::slotsFor(heights, r->m_config);
  // Per-pixel lighting reads stored gradients; the full-resolution mesh
  // (the reference) computes its own from level 0.
  const bool gradients = config.lighting == TerrainLighting::kPixel && !r->m_config.full_resolution;
  if (Status s = TerrainHeightStack::create(heights, slots, layers, gradients, &r->m_stack); !s) return s;
  if (config.detail_textures)
    if (Status s = TerrainDetailTexture::create(&r->m_detail); !s) return s;
  *out = std::move(r);
  return okStatus();
}

TerrainRendererImpl::~TerrainRendererImpl() = default;

Status TerrainRendererImpl::checkConfig(const PyramidGeometry& heights, const TerrainConfig& config) {
  const uint32_t n = config.ring_cells;
  if (!isPowerOfTwo(n) || n < 16 || n > 1024) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "terrain ring of " + std::to_string(n) +
                             " cells: must be a power of two from 16 to 1024");
  }
  const TerrainMapping& m = config.mapping;
  if (!(m.world_per_sample.x > 0.0) || !(m.world_per_sample.y > 0.0) ||
      !std::isfinite(m.world_per_sample.x) || !std::isfinite(m.world_per_sample.y) ||
      !std::isfinite(m.world_per_height) || !(m.world_per_height > 0.0) ||
      !std::isfinite(m.sample0_world.x) || !std::isfinite(m.sample0_world.y)) {
    return Status::error(ErrorCode::kInvalidArgument, "terrain mapping must be finite and positive");
  }
  const uint32_t p = config.patch_cells;
  const bool patches = config.method == TerrainMethod::kQuadtree || config.method == TerrainMethod::kFlat;
  if (patches && (!isPowerOfTwo(p) || p < 4 || p > 256)) {
    // A power of two divides every tile size (and is divided by any
    // smaller one), so a node never straddles part of a tile's block.
    return Status::error(ErrorCode::kInvalidArgument, "terrain patch of " + std::to_string(p) +
                                                          " cells: must be a power of two from 4 to 256");
  }
  if (!(config.error_px >= kMinTerrainErrorPx && config.error_px <= kMaxTerrainErrorPx)) {
    return Status::error(ErrorCode::kInvalidArgument, "terrain error bound must be from 0.01 to 1000 pixels");
  }
  if (heights.levelCount() == 0 || heights.levelCount() > renderer_config::kMaxLevels) {
    return Status::error(ErrorCode::kInvalidArgument, "terrain: height pyramid has no level or too many");
  }
  return okStatus();
}

Status TerrainRendererImpl::buildMeshes() {
  // The rings' five index patterns over one vertex grid, or the
  // full-resolution mesh's one pattern, a plain grid.
  const terrain_mesh::RingMesh ring = terrain_mesh::buildRingMesh(m_config.ring_cells, m_config.full_resolution);
  if (Status s = TerrainMeshBuffers::create(ring.vertices, ring.indices, false, "the terrain's ring meshes",
                                            &m_ring_mesh);
      !s)
    return s;
  m_ring_blocks = ring.blocks;
  const bool patches = m_config.method == TerrainMethod::kQuadtree || m_config.method == TerrainMethod::kFlat;
  if (!patches) return okStatus();
  // The quadtree's patch: one (P + 1)^2 grid, its 16 edge patterns.
  const terrain_mesh::PatchMesh patch = terrain_mesh::buildPatchMesh(m_config.patch_cells);
  if (Status s =
          TerrainMeshBuffers::create(patch.vertices, patch.indices, true, "the quadtree's patch meshes", &m_patch_mesh);
      !s)
    return s;
  m_patch_masks = patch.masks;
  return okStatus();
}

uint32_t TerrainRendererImpl::coarsestFor(const glm::dvec2& cam) const {
  // Samples to cover: the height field and the colour image (in samples)
  // beyond it, as far as either reaches from the camera along each axis.
  const TerrainMapping& m = m_config.mapping;
  const glm::dvec2 field(double(m_geometry.width_px), double(m_geometry.height_px));
  const glm::dvec2 lo = glm::min(glm::dvec2(0.0), -m.sample0_world / m.world_per_sample);
  const glm::dvec2 hi = glm::max(field, (m_image_px - m.sample0_world) / m.world_per_sample);
  const glm::dvec2 reach = glm::max(glm::abs(cam - lo), glm::abs(hi - cam));
  const double need = std::max(reach.x, reach.y) + 2.0;
  // A ring of level l reaches at least (n / 2 - 2) << l samples from the
  // camera on every side (its origin snaps to even samples).
  const double half = double(m_config.ring_cells) / 2.0 - 2.0;
  for (uint32_t l = 0; l + 2 < renderer_config::kMaxLevels; ++l)
    if (std::ldexp(half, int(l)) >= need) return l;
  return renderer_config::kMaxLevels - 2;
}

void TerrainRendererImpl::updateCoarsest(const Camera& camera, const ClipmapRenderer& colour) {
  m_image_px = {double(colour.geometry().width_px), double(colour.geometry().height_px)};
  m_coarsest = coarsestFor(cameraSamples(m_config.mapping, camera));
}

void TerrainRendererImpl::uploadTile(const TileKey& key, const float* heights) {
  if (heights == nullptr || !m_geometry.contains(key)) return;
  if (m_config.full_resolution && key.level != 0) return;
  m_stack->upload(key, heights);
  if (m_config.method == TerrainMethod::kQuadtree) {
    forgetNodeErrors(key);
    // Each node-sized block's largest cell twist.
    m_stack->storeTwist(key, heights, std::min(m_config.patch_cells, m_geometry.tile_px));
  }
}

uint32_t TerrainRendererImpl::preloadCoarseLevels(const TerrainRenderer::HeightTileFn& tile) {
  uint32_t missing = 0;
  const size_t floats = size_t(m_geometry.tile_px) * m_geometry.tile_px;
  const uint32_t levels = m_config.full_resolution ? 1 : m_geometry.levelCount();
  for (uint32_t l = 0; l < levels; ++l) {
    const LevelInfo& info = m_geometry.levels[l];
    if (info.tiles_x > m_stack->slots() || info.tiles_y > m_stack->slots()) continue;
    for (uint32_t y = 0; y < info.tiles_y; ++y)
      for (uint32_t x = 0; x < info.tiles_x; ++x) {
        const std::shared_ptr<const std::vector<uint8_t>> bytes = tile(TileKey{l, x, y});
        if (!bytes || bytes->size() != floats * sizeof(float)) {
          ++missing;
          continue;
        }
        uploadTile(TileKey{l, x, y}, reinterpret_cast<const float*>(bytes->data()));
      }
  }
  return missing;
}

bool TerrainRendererImpl::groundRange(const Camera& camera, double* lowest, double* highest) const {
  for (uint32_t l = std::min(m_frame.finest_level + TerrainRenderer::kReliefRings, m_coarsest); l <= m_coarsest;
       ++l) {
    const glm::i64vec2 o = ringOrigin(m_config, camera, l);
    const int64_t n = m_config.ring_cells;
    const glm::vec2 b = m_stack->heightBounds(l, o, o + glm::i64vec2(n, n));
    if (!std::isfinite(b.x) || !std::isfinite(b.y)) continue;
    *lowest = double(b.x) * m_config.mapping.world_per_height;
    *highest = double(b.y) * m_config.mapping.world_per_height;
    return true;
  }
  return false;
}

bool TerrainRendererImpl::groundHeight(const glm::dvec2& world_xz, double* height,
                                       uint32_t* level_used) const {
  const TerrainMapping& m = m_config.mapping;
  const glm::dvec2 s0 = (world_xz - m.sample0_world) / m.world_per_sample;  // level-0 samples
  // The coarsest level the next frame may draw here: the innermost ring's
  // (a coarser ring lies farther out); for the quadtree any level drawn (a
  // leaf may coarsen by several levels from one frame to the next, when a
  // tile's arrival tightens its bound or the restriction coarsens it).
  uint32_t top = m_frame.finest_level;
  // The flat method draws no terrain: the finest resident surface alone.
  if (m_config.method == TerrainMethod::kFlat) top = 0;
  if (m_config.method == TerrainMethod::kQuadtree && !m_config.full_resolution)
    top = std::max(m_frame.coarsest_level, m_frame.finest_level);
  bool found = false;
  uint32_t first = 0;
  double highest = -INFINITY;
  for (uint32_t level = 0; level < m_geometry.levelCount(); ++level) {
    if (found && level > std::max(first, top)) break;
    const LevelInfo& info = m_geometry.levels[level];
    const glm::dvec2 s = s0 / std::ldexp(1.0, int(level));
    const double fx = std::clamp(s.x, 0.0, double(info.width_px - 1));
    const double fz = std::clamp(s.y, 0.0, double(info.height_px - 1));
    const int64_t i0 = int64_t(std::floor(fx)), j0 = int64_t(std::floor(fz));
    const int64_t i1 = std::min<int64_t>(i0 + 1, int64_t(info.width_px) - 1);
    const int64_t j1 = std::min<int64_t>(j0 + 1, int64_t(info.height_px) - 1);
    bool have = true;
    auto at = [&](int64_t i, int64_t j) -> double {
      float h = 0.0f;
      if (!m_stack->sample(level, i, j, &h)) have = false;
      return double(h);
    };
    const double h00 = at(i0, j0), h10 = at(i1, j0), h01 = at(i0, j1), h11 = at(i1, j1);
    if (!have) continue;
    // The triangle of the cell (diagonal (i0, j0)-(i1, j1)) the point is in.
    const double u = fx - double(i0), v = fz - double(j0);
    const double h = u >= v ? h00 + u * (h10 - h00) + v * (h11 - h10)
                            : h00 + v * (h01 - h00) + u * (h11 - h01);
    if (!found) first = level;
    found = true;
    highest = std::max(highest, h);
  }
  if (!found) return false;
  *height = highest * m.world_per_height;
  if (level_used != nullptr) *level_used = first;
  return true;
}

void TerrainRendererImpl::draw(const Camera& camera, const Viewport& viewport, const ClipmapRenderer& colour) {
  const GLuint p = m_programs->ground(colour.overlay() != Overlay::kOff, m_config.lighting == TerrainLighting::kPixel,
                                      m_config.detail_textures);
  updateCoarsest(camera, colour);
  colour.impl().bindColour(p, camera, viewport);
  setFrameUniforms(p, camera, viewport);
  drawRings(p, camera, viewport);
}

Status TerrainRendererImpl::readPositions(const Camera& camera, const Viewport& viewport,
                                          const ClipmapRenderer& colour, std::vector<float>* xyzw) {
  if (Status s = m_position_target.fit(viewport); !s) return s;
  const GLuint fbo = m_position_target.framebuffer();
  GLint previous_fbo = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &previous_fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo);
  glViewport(0, 0, GLsizei(viewport.width_px), GLsizei(viewport.height_px));
  const float none[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  glClearNamedFramebufferfv(fbo, GL_COLOR, 0, none);
  glClearNamedFramebufferfi(fbo, GL_DEPTH_STENCIL, 0, 1.0f, 0);
  const GLuint p = m_programs->position();
  updateCoarsest(camera, colour);
  colour.impl().bindColour(p, camera, viewport);  // the image's extent (uImageRel)
  setFrameUniforms(p, camera, viewport);
  drawRings(p, camera, viewport);
  xyzw->resize(size_t(viewport.width_px) * viewport.height_px * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadPixels(0, 0, GLsizei(viewport.width_px), GLsizei(viewport.height_px), GL_RGBA, GL_FLOAT, xyzw->data());
  // GL rows run bottom to top: put the top row first, like OffscreenTarget.
  const size_t row = size_t(viewport.width_px) * 4;
  for (uint32_t y = 0; y < viewport.height_px / 2; ++y)
    std::swap_ranges(xyzw->begin() + long(y * row), xyzw->begin() + long((y + 1) * row),
                     xyzw->begin() + long((viewport.height_px - 1 - y) * row));
  glBindFramebuffer(GL_FRAMEBUFFER, GLuint(previous_fbo));
  return okStatus();
}

void setExactNodeError(TerrainRenderer& terrain, std::function<double(uint32_t, int64_t, int64_t)> error) {
  terrain.impl().setExactNodeError(std::move(error));
}

}  // namespace clipstream
