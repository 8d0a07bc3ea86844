// The draws of TerrainRenderer (terrain_impl.h) that the methods share: the
// per-frame and per-grid uniforms of terrain.vert, the frustum, the nested
// rings of the geometry clipmap and the patches of the full-resolution
// mesh, both drawn block by block with culling. The quadtree's own draw is
// in terrain_quadtree.cpp.
#include "terrain_impl.h"

#include "gl.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace clipstream {
namespace {

GLint loc(GLuint program, const char* name) { return glGetUniformLocation(program, name); }

}  // namespace

double TerrainRendererImpl::farDistance(const Camera& camera) const {
  // Beyond the outermost ring's corner and the highest ground.
  const TerrainMapping& m = m_config.mapping;
  const double extent = double(uint64_t(m_config.ring_cells) << m_coarsest) *
                        std::max(m.world_per_sample.x, m.world_per_sample.y);
  return 2.0 * extent + std::abs(camera.position.y) * 2.0 + 1.0;
}

void TerrainRendererImpl::setFrameUniforms(uint32_t p, const Camera& camera,
                                           const Viewport& viewport) const {
  const uint32_t n = m_config.ring_cells;
  const TerrainMapping& m = m_config.mapping;
  const glm::dvec2 cam = cameraSamples(m, camera);
  const glm::dvec2 cam_int = glm::floor(cam);
  const double far_dist = farDistance(camera);
  const glm::mat4 view_proj =
      glm::mat4(cameraProjection(camera, viewport, far_dist) * cameraRelativeView(camera));
  glProgramUniformMatrix4fv(p, loc(p, "uViewProj"), 1, GL_FALSE, &view_proj[0][0]);
  glProgramUniform1i(p, loc(p, "uN"), GLint(n));
  // No transition band for the full-resolution mesh and the quadtree
  // (uCoarsest 0: every level counts as the coarsest).
  const bool rings = m_config.method == TerrainMethod::kClipmap && !m_config.full_resolution;
  glProgramUniform1i(p, loc(p, "uCoarsest"), GLint(rings ? m_coarsest : 0));
  glProgramUniform1i(p, loc(p, "uTransition"),
                     GLint(std::max(1u, n / renderer_config::kTerrainTransitionDivisor)));
  glProgramUniform1i(p, loc(p, "uHeightPeriod"), GLint(m_stack->slots() * m_geometry.tile_px));
  glProgramUniform2f(p, loc(p, "uCamFrac"), float(cam.x - cam_int.x), float(cam.y - cam_int.y));
  glProgramUniform2f(p, loc(p, "uWorldPerSample"), float(m.world_per_sample.x),
                     float(m.world_per_sample.y));
  // The flat method: every height at flatHeight() (heights scaled by 0,
  // the camera lifted by as much).
  const bool flat = m_config.method == TerrainMethod::kFlat;
  glProgramUniform1f(p, loc(p, "uWorldPerHeight"), flat ? 0.0f : float(m.world_per_height));
  glProgramUniform1f(p, loc(p, "uCamY"),
                     float(camera.position.y - (flat ? flatHeight() * m.world_per_height : 0.0)));
  std::array<GLint, 2 * renderer_config::kMaxLevels> sizes{};
  for (uint32_t l = 0; l < m_geometry.levelCount(); ++l) {
    sizes[2 * l] = GLint(m_geometry.levels[l].width_px);
    sizes[2 * l + 1] = GLint(m_geometry.levels[l].height_px);
  }
  glProgramUniform2iv(p, loc(p, "uLevelSize"), GLsizei(m_geometry.levelCount()), sizes.data());
  glProgramUniform1i(p, loc(p, "uStoredLevels"), GLint(m_geometry.levelCount()));
  // Sun from the north-west, 45 degrees up (the cartographic convention for
  // hillshading: slopes facing the viewer's upper left are lit).
  const glm::vec3 sun = glm::normalize(glm::vec3(-1.0f, 1.41421356f, -1.0f));
  glProgramUniform3f(p, loc(p, "uSunDir"), sun.x, sun.y, sun.z);
  glProgramUniform1i(p, loc(p, "uHeights"), 2);
  glBindTextureUnit(2, m_stack->texture());
  // Per-pixel lighting: the camera's sample, whole (the shader splits it by
  // level), and the stored gradients with what the shader needs to find
  // them (the reference computes its own from level 0).
  glProgramUniform2i(p, loc(p, "uCamSample"), GLint(cam_int.x), GLint(cam_int.y));
  if (m_stack->gradientsTexture() != 0) {
    glProgramUniform1i(p, loc(p, "uGradients"), 3);
    glBindTextureUnit(3, m_stack->gradientsTexture());
    // Per level: the block of samples whose tiles are held around the
    // camera, and where the camera's sample lies in the level's layer.
    std::array<GLint, 4 * renderer_config::kMaxLevels> resident{};
    std::array<GLint, 2 * renderer_config::kMaxLevels> texel{};
    const int64_t period = int64_t(m_stack->slots()) * m_geometry.tile_px;
    for (uint32_t l = 0; l < m_geometry.levelCount(); ++l) {
      const glm::i64vec4 r = m_stack->residentSamples(l, glm::i64vec2(cam_int));
      for (int k = 0; k < 4; ++k) resident[size_t(4 * l + k)] = GLint(r[k]);
      for (int k = 0; k < 2; ++k) {
        const int64_t s = int64_t(cam_int[k]) >> l;
        texel[size_t(2 * l + k)] = GLint(((s % period) + period) % period);
      }
    }
    glProgramUniform4iv(p, loc(p, "uResidentSamples"), GLsizei(m_geometry.levelCount()), resident.data());
    glProgramUniform2iv(p, loc(p, "uCamTexel"), GLsizei(m_geometry.levelCount()), texel.data());
  }
  if (m_detail) {
    // The detail's repeat, and the camera's ground position within it (the
    // shader adds only small camera-relative offsets to it).
    const double period = double(renderer_config::kDetailTexturePx) / renderer_config::kDetailTexelsPerTexel;
    glProgramUniform1i(p, loc(p, "uDetail"), 4);
    glBindTextureUnit(4, m_detail->texture());
    glProgramUniform1f(p, loc(p, "uDetailPeriod"), float(period));
    glProgramUniform2f(p, loc(p, "uDetailOrigin"),
                       float(camera.position.x - period * std::floor(camera.position.x / period)),
                       float(camera.position.z - period * std::floor(camera.position.z / period)));
    // The DEM's range: its coarsest level's one tile (always held).
    const uint32_t last = m_geometry.levelCount() - 1;
    const glm::vec2 range = m_stack->holds(last, 0, 0) ? m_stack->tileBounds(last, 0, 0) : glm::vec2(0.0f, 1.0f);
    glProgramUniform2f(p, loc(p, "uHeightRange"), range.x, range.y);
  }
}

TerrainGridOrigin TerrainRendererImpl::gridOrigin(const Camera& camera, uint32_t level,
                                                  const glm::i64vec2& o) const {
  const glm::dvec2 cam_int = glm::floor(cameraSamples(m_config.mapping, camera));
  const int64_t scale = int64_t(1) << level;
  return {{int32_t(o.x), int32_t(o.y)},
          {int32_t(o.x * scale - int64_t(cam_int.x)), int32_t(o.y * scale - int64_t(cam_int.y))},
          int32_t(level)};
}

TerrainRendererImpl::Frustum TerrainRendererImpl::frustum(const Camera& camera,
                                                          const Viewport& viewport) const {
  // Planes of the camera-relative view-projection (Gribb & Hartmann).
  const glm::dmat4 vp = cameraProjection(camera, viewport, farDistance(camera)) * cameraRelativeView(camera);
  Frustum planes;
  for (int i = 0; i < 3; ++i) {
    const glm::dvec4 row_w(vp[0][3], vp[1][3], vp[2][3], vp[3][3]);
    const glm::dvec4 row_i(vp[0][i], vp[1][i], vp[2][i], vp[3][i]);
    planes[size_t(2 * i)] = row_w + row_i;
    planes[size_t(2 * i + 1)] = row_w - row_i;
  }
  return planes;
}

void TerrainRendererImpl::drawRings(uint32_t p, const Camera& camera, const Viewport& viewport) {
  m_height_tiles.clear();
  m_reads.camera = camera;
  m_reads.rects.clear();
  // terrain.vert's four clip distances bound the ground to the colour image.
  for (GLenum c = GL_CLIP_DISTANCE0; c < GL_CLIP_DISTANCE0 + 4; ++c) glEnable(c);
  if (m_config.full_resolution)
    drawPatches(p, camera, viewport);
  else if (m_config.method != TerrainMethod::kClipmap)
    drawQuadtree(p, camera, viewport);
  else
    drawClipmapRings(p, camera, viewport);
  for (GLenum c = GL_CLIP_DISTANCE0; c < GL_CLIP_DISTANCE0 + 4; ++c) glDisable(c);
}

void TerrainRendererImpl::drawClipmapRings(uint32_t p, const Camera& camera, const Viewport& viewport) {
  m_frame = TerrainFrame{};
  const uint32_t n = m_config.ring_cells;
  const uint32_t coarsest = m_coarsest;
  std::vector<glm::i64vec2> origins(coarsest + 1);
  for (uint32_t l = 0; l <= coarsest; ++l) {
    origins[l] = ringOrigin(m_config, camera, l);
    // Every ring's square, resident or not (its normals one sample beyond;
    // its transition band reads the next ring's square): a ring is drawn
    // only when all of it is resident. And one step of the ring further
    // each way (its origin moves two samples at a time): the square it
    // snaps to next is wanted before the camera gets there.
    if (l < m_geometry.levelCount())
      m_reads.rects.push_back({l, origins[l] - int64_t(3), origins[l] + int64_t(n + 3)});
  }
  // The innermost ring: the finest level that, with every coarser ring, is
  // resident. A gap below it only coarsens the geometry.
  int64_t finest = -1;
  for (int64_t l = coarsest; l >= 0; --l) {
    if (!m_stack->ringResident(uint32_t(l), origins[size_t(l)], n)) break;
    finest = l;
  }
  if (finest < 0) return;

  glUseProgram(p);
  glBindVertexArray(m_ring_mesh->vao());
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  const Frustum planes = frustum(camera, viewport);
  for (uint32_t l = uint32_t(finest); l <= coarsest; ++l) {
    const glm::i64vec2 o = origins[l];
    const int pattern = l == uint32_t(finest) ? 0 : terrain_mesh::holePattern(origins[l - 1], o, n);
    if (pattern < 0 || pattern > 4) continue;  // cannot happen: origins nest (see ringOrigin)
    drawGrid(camera, planes, l, o, pattern);
    ++m_frame.rings;
  }
  m_frame.finest_level = uint32_t(finest);
  m_frame.coarsest_level = coarsest;
  glDisable(GL_DEPTH_TEST);
  glBindVertexArray(0);
  glUseProgram(0);
}

void TerrainRendererImpl::drawPatches(uint32_t p, const Camera& camera, const Viewport& viewport) {
  m_frame = TerrainFrame{};
  const int64_t n = m_config.ring_cells;
  const TerrainMapping& m = m_config.mapping;
  // Samples to cover: the height field, and the colour image beyond it
  // (where the rings show the edge samples clamped), one more each side.
  const LevelInfo& l0 = m_geometry.levels[0];
  const glm::dvec2 img0 = (-m.sample0_world) / m.world_per_sample;
  const glm::dvec2 img1 = (m_image_px - m.sample0_world) / m.world_per_sample;
  const int64_t s0x = std::min<int64_t>(0, int64_t(std::floor(img0.x)) - 1);
  const int64_t s0y = std::min<int64_t>(0, int64_t(std::floor(img0.y)) - 1);
  const int64_t s1x = std::max<int64_t>(int64_t(l0.width_px) - 1, int64_t(std::ceil(img1.x)) + 1);
  const int64_t s1y = std::max<int64_t>(int64_t(l0.height_px) - 1, int64_t(std::ceil(img1.y)) + 1);
  auto floorDiv = [](int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); };
  glUseProgram(p);
  glBindVertexArray(m_ring_mesh->vao());
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  const Frustum planes = frustum(camera, viewport);
  for (int64_t py = floorDiv(s0y, n); py * n < s1y; ++py)
    for (int64_t px = floorDiv(s0x, n); px * n < s1x; ++px) drawGrid(camera, planes, 0, {px * n, py * n}, 0);
  m_frame.rings = 1;
  glDisable(GL_DEPTH_TEST);
  glBindVertexArray(0);
  glUseProgram(0);
}

void TerrainRendererImpl::drawGrid(const Camera& camera, const Frustum& planes, uint32_t l, const glm::i64vec2& o,
                                   int pattern) {
  constexpr uint32_t kBlocks = terrain_mesh::RingMesh::kBlocks;
  const uint32_t n = m_config.ring_cells;
  const TerrainMapping& m = m_config.mapping;
  const glm::dvec2 cam = cameraSamples(m, camera);
  const uint32_t block_cells = n / kBlocks;
  TerrainMeshBuffers::setOrigin(gridOrigin(camera, l, o));
  // The visible blocks, nearest first: a slope hidden behind a nearer one
  // of the same ring then fails the depth test instead of being shaded
  // (the rings themselves are drawn finest, nearest, first).
  struct Block {
    double distance;
    GLsizei count;
    const void* offset;
  };
  std::vector<Block> blocks;
  const double spacing = std::ldexp(1.0, int(l));
  // Cells of the transition band (terrain.vert: alpha > 0 beyond n / 2 -
  // w - 1 from the centre); none on the coarsest ring and the patches.
  const bool rings = m_config.method == TerrainMethod::kClipmap && !m_config.full_resolution;
  const int64_t transition =
      rings && l < m_coarsest ? int64_t(std::max(1u, n / renderer_config::kTerrainTransitionDivisor)) + 1 : 0;
  for (uint32_t b = 0; b < kBlocks * kBlocks; ++b) {
    const terrain_mesh::IndexRange range = m_ring_blocks[size_t(pattern)][b];
    if (range.count == 0) continue;
    // The block's box, camera-relative: its cells (plus the two samples
    // the transition and normals reach beyond them) and the heights of
    // the tiles under it.
    const glm::i64vec2 c0 = o + glm::i64vec2((b % kBlocks) * block_cells, (b / kBlocks) * block_cells);
    const glm::i64vec2 c1 = c0 + glm::i64vec2(block_cells, block_cells);
    const glm::vec2 h = m_stack->heightBounds(l, glm::max(c0 - int64_t(2), o - int64_t(1)),
                                              glm::min(c1 + int64_t(2), o + int64_t(n + 1)));
    const glm::dvec2 x0 = (glm::dvec2(c0) * spacing - cam) * m.world_per_sample;
    const glm::dvec2 x1 = (glm::dvec2(c1) * spacing - cam) * m.world_per_sample;
    const double y0 = double(h.x) * m.world_per_height - camera.position.y;
    const double y1 = double(h.y) * m.world_per_height - camera.position.y;
    // Ground outside the colour image is not drawn (terrain.vert clips
    // it): a block wholly outside costs vertices for nothing. Its
    // triangles reach two cells beyond its cells (they are filed by centroid).
    const glm::dvec2 reach = 2.0 * spacing * m.world_per_sample;
    bool outside = x1.x + reach.x <= -camera.position.x || x1.y + reach.y <= -camera.position.z ||
                   x0.x - reach.x >= m_image_px.x - camera.position.x ||
                   x0.y - reach.y >= m_image_px.y - camera.position.z;
    for (const glm::dvec4& pl : planes) {
      // The box corner farthest along the plane's normal.
      const glm::dvec3 far_corner(pl.x >= 0 ? x1.x : x0.x, pl.y >= 0 ? y1 : y0, pl.z >= 0 ? x1.y : x0.y);
      if (glm::dot(glm::dvec3(pl), far_corner) + pl.w < 0.0) {
        outside = true;
        break;
      }
    }
    if (outside) {
      ++m_frame.culled_blocks;
      continue;
    }
    // The samples its vertices read: their own and their normals' (one
    // further), and in the ring's transition band the coarser level's
    // under it (terrain.vert's coarseAt() and its normal).
    noteHeightReads(l, c0 - int64_t(1), c1 + int64_t(1));
    if (transition > 0) {
      const glm::i64vec2 band0 = o + int64_t(transition), band1 = o + int64_t(n - transition);
      // The parts of the block outside the band's inner square, as rects.
      auto coarse = [&](glm::i64vec2 lo, glm::i64vec2 hi) {
        if (lo.x <= hi.x && lo.y <= hi.y)
          noteHeightReads(l + 1, (lo >> int64_t(1)) - int64_t(1), (hi >> int64_t(1)) + int64_t(1));
      };
      coarse(c0, {std::min(c1.x, band0.x), c1.y});
      coarse({std::max(c0.x, band1.x), c0.y}, c1);
      coarse(c0, {c1.x, std::min(c1.y, band0.y)});
      coarse({c0.x, std::max(c0.y, band1.y)}, c1);
    }
    const double distance = NodeBox{{x0.x, y0, x0.y}, {x1.x, y1, x1.y}}.distance();
    blocks.push_back({distance, GLsizei(range.count),
                      reinterpret_cast<const void*>(uintptr_t(range.first) * sizeof(uint32_t))});
    m_frame.triangles += range.count / 3;
    ++m_frame.blocks;
  }
  if (!blocks.empty()) {
    std::sort(blocks.begin(), blocks.end(), [](const Block& a, const Block& b) { return a.distance < b.distance; });
    std::vector<GLsizei> counts;
    std::vector<const void*> offsets;
    for (const Block& b : blocks) {
      counts.push_back(b.count);
      offsets.push_back(b.offset);
    }
    glMultiDrawElements(GL_TRIANGLES, counts.data(), GL_UNSIGNED_INT, offsets.data(), GLsizei(counts.size()));
  }
}

void TerrainRendererImpl::noteHeightReads(uint32_t level, glm::i64vec2 s0, glm::i64vec2 s1) {
  const uint32_t stored = m_geometry.levelCount();
  if (stored == 0) return;
  if (level >= stored) {
    const int shift = int(level - stored + 1);
    s0 <<= int64_t(shift);
    s1 <<= int64_t(shift);
    level = stored - 1;
  }
  const LevelInfo& info = m_geometry.levels[level];
  const glm::i64vec2 last(int64_t(info.width_px) - 1, int64_t(info.height_px) - 1);
  const glm::i64vec2 t0 = glm::clamp(s0, glm::i64vec2(0), last) / int64_t(m_geometry.tile_px);
  const glm::i64vec2 t1 = glm::clamp(s1, glm::i64vec2(0), last) / int64_t(m_geometry.tile_px);
  for (int64_t y = t0.y; y <= t1.y; ++y)
    for (int64_t x = t0.x; x <= t1.x; ++x) {
      const TileKey key{level, uint32_t(x), uint32_t(y)};
      if (std::find(m_height_tiles.begin(), m_height_tiles.end(), key) == m_height_tiles.end())
        m_height_tiles.push_back(key);
    }
}

}  // namespace clipstream
