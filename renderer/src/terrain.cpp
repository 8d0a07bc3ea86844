#include <clipstream/renderer/terrain.h>

#include "gl.h"
#include "gl_util.h"
#include "shaders.h"
#include "terrain_mesh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace clipstream {
namespace {

GLint loc(GLuint program, const char* name) { return glGetUniformLocation(program, name); }

bool isPowerOfTwo(uint32_t v) { return v != 0 && (v & (v - 1)) == 0; }

// The camera in level-0 sample coordinates (sample i at i).
glm::dvec2 cameraSamples(const TerrainMapping& m, const Camera& camera) {
  return {(camera.position.x - m.sample0_world.x) / m.world_per_sample.x,
          (camera.position.z - m.sample0_world.y) / m.world_per_sample.y};
}

// Index buffer configuration of a ring: 0 without hole, else the finer
// ring's offset (n/4 + hx, n/4 + hy), hx, hy in {0, 1}.
int holeConfig(const glm::i64vec2& fine_origin, const glm::i64vec2& origin, uint32_t n) {
  // The finer ring's origin in this level's samples (both are even at their own level).
  const int64_t kx = fine_origin.x / 2 - origin.x, ky = fine_origin.y / 2 - origin.y;
  const int64_t base = int64_t(n / 4);
  return 1 + int(kx - base) + 2 * int(ky - base);
}

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

Status terrainMethodFromName(const std::string& name, TerrainMethod* out) {
  for (TerrainMethod m : {TerrainMethod::kClipmap, TerrainMethod::kQuadtree, TerrainMethod::kFlat,
                          TerrainMethod::kFull}) {
    if (name == terrainMethodName(m)) {
      *out = m;
      return okStatus();
    }
  }
  return Status::error(ErrorCode::kInvalidArgument,
                       "terrain method '" + name + "': must be clipmap, quadtree, flat or full");
}

glm::i64vec2 TerrainRenderer::ringOrigin(const TerrainConfig& config, const Camera& camera,
                                         uint32_t level) {
  const glm::dvec2 cam = cameraSamples(config.mapping, camera) / std::ldexp(1.0, int(level));
  const double half = double(config.ring_cells) / 2.0;
  return {2 * int64_t(std::floor((cam.x - half) / 2.0)), 2 * int64_t(std::floor((cam.y - half) / 2.0))};
}

Status TerrainRenderer::create(const PyramidGeometry& heights, const TerrainConfig& config,
                               std::unique_ptr<TerrainRenderer>* out) {
  out->reset();
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
  std::unique_ptr<TerrainRenderer> r(new TerrainRenderer());
  r->m_geometry = heights;
  r->m_config = config;
  if (config.method == TerrainMethod::kFull) r->m_config.full_resolution = true;
  // Slots: a ring spans n + 1 samples plus one on each side for normals,
  // which touches at most ceil((n + 3) / tile) + 1 tiles a side; one more
  // slot keeps a tile that just left from sharing a slot with one needed.
  const uint32_t tile = heights.tile_px;
  // ... and at least the streamer's window plus two (as the colour stack),
  // so no two tiles it hands over share a slot.
  r->m_slots = std::max((n + 3 + tile - 1) / tile + 2, (config.clip_tiles / 2) * 2 + 2);
  // The outermost ring covers the whole height field (and the colour image)
  // from wherever the camera is: chosen every frame (updateCoarsest()).
  // Rings may be coarser than the pyramid's last level (its one tile,
  // decimated further in the shader). Until the first frame: the field
  // seen from its centre.
  r->m_coarsest = r->coarsestFor(glm::dvec2(heights.width_px, heights.height_px) * 0.5);
  if (r->m_config.full_resolution) {
    // Level 0 whole, one slot per tile (the toroidal period never wraps),
    // and no transition band anywhere (uCoarsest 0).
    r->m_slots = std::max(heights.levels[0].tiles_x, heights.levels[0].tiles_y);
  }

  const std::string fragment = std::string(shaders::k_terrain_ground_glsl) + "\n" +
                               shaders::k_ground_clipmap_frag;
  for (int overlay = 0; overlay < 2; ++overlay) {
    Status s = gl_util::buildProgram(shaders::k_terrain_vert, fragment, &r->m_program[overlay],
                                     std::string("#define TERRAIN 1\n") +
                                         (overlay ? "#define OVERLAY 1\n" : ""));
    if (!s) return s;
  }
  Status fs = gl_util::buildProgram(shaders::k_terrain_vert, fragment, &r->m_feedback_program,
                                    "#define TERRAIN 1\n", {"vNormal", "vHeight"});
  if (!fs) return fs;
  fs = gl_util::buildProgram(shaders::k_terrain_vert, shaders::k_terrain_position_frag,
                             &r->m_position_program);
  if (!fs) return fs;

  // One vertex grid; five index patterns (no hole, four hole offsets).
  std::vector<int32_t> grid;
  grid.reserve(size_t(n + 1) * (n + 1) * 2);
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) {
      grid.push_back(int32_t(i));
      grid.push_back(int32_t(j));
    }
  std::vector<uint32_t> indices;
  const uint32_t block_cells = n / kBlocks;
  // The full-resolution mesh has one pattern, a plain grid.
  const bool full = r->m_config.full_resolution;
  const int patterns = full ? 1 : 5;
  for (int c = 0; c < patterns; ++c) {
    const int hx = c == 0 ? -1 : int(n / 4) + (c - 1) % 2;
    const int hy = c == 0 ? -1 : int(n / 4) + (c - 1) / 2;
    const std::vector<uint32_t> ring =
        full ? terrain_mesh::gridTriangles(n) : terrain_mesh::ringTriangles(n, hx, hy);
    std::vector<std::vector<uint32_t>> blocks(kBlocks * kBlocks);
    for (size_t t = 0; t < ring.size(); t += 3) {
      uint32_t sx = 0, sy = 0;
      for (int k = 0; k < 3; ++k) {
        sx += ring[t + k] % (n + 1);
        sy += ring[t + k] / (n + 1);
      }
      const uint32_t bx = std::min(sx / 3 / block_cells, kBlocks - 1);
      const uint32_t by = std::min(sy / 3 / block_cells, kBlocks - 1);
      blocks[by * kBlocks + bx].insert(blocks[by * kBlocks + bx].end(), ring.begin() + long(t),
                                       ring.begin() + long(t) + 3);
    }
    // Each block draws from its own copy of the vertices it uses, stored
    // together after the plain grid (which ringVertices() reads): a
    // driver that shades the whole index range of a draw (llvmpipe does)
    // then shades each vertex of the block once instead of every grid row
    // the block spans, and its per-draw vertex buffers stay small.
    for (uint32_t b = 0; b < kBlocks * kBlocks; ++b) {
      std::vector<uint32_t> used(blocks[b]);
      std::sort(used.begin(), used.end());
      used.erase(std::unique(used.begin(), used.end()), used.end());
      const uint32_t base = uint32_t(grid.size() / 2);
      for (uint32_t v : used) {
        grid.push_back(int32_t(v % (n + 1)));
        grid.push_back(int32_t(v / (n + 1)));
      }
      r->m_first_index[c][b] = uint32_t(indices.size());
      r->m_index_count[c][b] = uint32_t(blocks[b].size());
      for (uint32_t v : blocks[b])
        indices.push_back(base + uint32_t(std::lower_bound(used.begin(), used.end(), v) - used.begin()));
    }
  }
  gl_util::clearErrors();
  glCreateBuffers(1, &r->m_vertices);
  glNamedBufferStorage(r->m_vertices, GLsizeiptr(grid.size() * sizeof(int32_t)), grid.data(), 0);
  glCreateBuffers(1, &r->m_indices);
  glNamedBufferStorage(r->m_indices, GLsizeiptr(indices.size() * sizeof(uint32_t)), indices.data(), 0);
  auto makeVao = [](uint32_t vertices, uint32_t index_buffer, uint32_t* vao) {
    glCreateVertexArrays(1, vao);
    glVertexArrayVertexBuffer(*vao, 0, vertices, 0, 2 * sizeof(int32_t));
    glVertexArrayElementBuffer(*vao, index_buffer);
    glEnableVertexArrayAttrib(*vao, 0);
    glVertexArrayAttribIFormat(*vao, 0, 2, GL_INT, 0);
    glVertexArrayAttribBinding(*vao, 0, 0);
  };
  makeVao(r->m_vertices, r->m_indices, &r->m_vao);
  if (Status s = gl_util::checkCreated("the terrain's ring meshes"); !s) return s;
  if (patches) {
    // The quadtree's patch: one (P + 1)^2 grid, its 16 edge patterns.
    std::vector<int32_t> patch_grid;
    for (uint32_t j = 0; j <= p; ++j)
      for (uint32_t i = 0; i <= p; ++i) patch_grid.insert(patch_grid.end(), {int32_t(i), int32_t(j)});
    std::vector<uint32_t> patch_indices;
    for (uint32_t mask = 0; mask < 16; ++mask) {
      const std::vector<uint32_t> t = terrain_mesh::patchTriangles(p, mask);
      r->m_patch_first[mask] = uint32_t(patch_indices.size());
      r->m_patch_count[mask] = uint32_t(t.size());
      patch_indices.insert(patch_indices.end(), t.begin(), t.end());
    }
    glCreateBuffers(1, &r->m_patch_vertices);
    glNamedBufferStorage(r->m_patch_vertices, GLsizeiptr(patch_grid.size() * sizeof(int32_t)),
                         patch_grid.data(), 0);
    glCreateBuffers(1, &r->m_patch_indices);
    glNamedBufferStorage(r->m_patch_indices, GLsizeiptr(patch_indices.size() * sizeof(uint32_t)),
                         patch_indices.data(), 0);
    makeVao(r->m_patch_vertices, r->m_patch_indices, &r->m_patch_vao);
    if (Status s = gl_util::checkCreated("the quadtree's patch meshes"); !s) return s;
  }

  const uint32_t period = r->m_slots * tile;
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  if (period > uint32_t(max_size)) {
    return Status::error(ErrorCode::kUnavailable, "terrain: height stack of " +
                                                      std::to_string(period) +
                                                      " texels exceeds GL_MAX_TEXTURE_SIZE");
  }
  const GLsizei layers = full ? 1 : GLsizei(heights.levelCount());
  gl_util::clearErrors();
  glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &r->m_heights);
  glTextureStorage3D(r->m_heights, 1, GL_R32F, GLsizei(period), GLsizei(period), layers);
  glTextureParameteri(r->m_heights, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTextureParameteri(r->m_heights, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  const float zero = 0.0f;
  glClearTexImage(r->m_heights, 0, GL_RED, GL_FLOAT, &zero);
  r->m_texture_bytes = uint64_t(period) * period * 4 * uint64_t(layers);
  r->m_slot_tile.assign(heights.levelCount(),
                        std::vector<uint64_t>(size_t(r->m_slots) * r->m_slots, kNoTile));
  r->m_slot_heights.assign(heights.levelCount(),
                           std::vector<std::vector<float>>(size_t(r->m_slots) * r->m_slots));
  r->m_slot_twist.assign(heights.levelCount(),
                         std::vector<std::vector<float>>(size_t(r->m_slots) * r->m_slots));
  r->m_slot_bounds.assign(heights.levelCount(),
                          std::vector<glm::vec2>(size_t(r->m_slots) * r->m_slots, glm::vec2(0.0f)));
  if (Status s = gl_util::checkCreated("the terrain's height stack (" +
                                       std::to_string(r->m_texture_bytes >> 20) + " MiB of R32F)");
      !s)
    return s;
  *out = std::move(r);
  return okStatus();
}

TerrainRenderer::~TerrainRenderer() {
  for (uint32_t p : m_program) glDeleteProgram(p);
  glDeleteProgram(m_feedback_program);
  glDeleteProgram(m_position_program);
  glDeleteFramebuffers(1, &m_position_fbo);
  glDeleteRenderbuffers(1, &m_position_color);
  glDeleteRenderbuffers(1, &m_position_depth);
  glDeleteVertexArrays(1, &m_vao);
  glDeleteBuffers(1, &m_vertices);
  glDeleteBuffers(1, &m_indices);
  glDeleteVertexArrays(1, &m_patch_vao);
  glDeleteBuffers(1, &m_patch_vertices);
  glDeleteBuffers(1, &m_patch_indices);
  glDeleteTextures(1, &m_heights);
}

uint32_t TerrainRenderer::coarsestFor(const glm::dvec2& cam) const {
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

void TerrainRenderer::updateCoarsest(const Camera& camera, const ClipmapRenderer& colour) {
  m_image_px = {double(colour.geometry().width_px), double(colour.geometry().height_px)};
  m_coarsest = coarsestFor(cameraSamples(m_config.mapping, camera));
}

uint32_t TerrainRenderer::slotOf(int64_t tile) const {
  const int64_t s = tile % int64_t(m_slots);
  return uint32_t(s < 0 ? s + m_slots : s);
}

void TerrainRenderer::uploadTile(const TileKey& key, const float* heights) {
  if (heights == nullptr || !m_geometry.contains(key)) return;
  if (m_config.full_resolution && key.level != 0) return;
  const uint32_t tile = m_geometry.tile_px;
  const uint32_t sx = slotOf(key.x), sy = slotOf(key.y);
  glTextureSubImage3D(m_heights, 0, GLint(sx * tile), GLint(sy * tile), GLint(key.level),
                      GLsizei(tile), GLsizei(tile), 1, GL_RED, GL_FLOAT, heights);
  const size_t slot = size_t(sy) * m_slots + sx;
  m_slot_tile[key.level][slot] = uint64_t(key.x) | (uint64_t(key.y) << 32);
  m_slot_heights[key.level][slot].assign(heights, heights + size_t(tile) * tile);
  const auto [lo, hi] = std::minmax_element(heights, heights + size_t(tile) * tile);
  m_slot_bounds[key.level][slot] = {*lo, *hi};
  if (m_config.method == TerrainMethod::kQuadtree) {
    // Node errors that read this tile: nodes at its level or coarser whose
    // ground (clamped to the field: nodes beyond it read its edge) meets
    // the tile's, one sample around (their bounds take their children's).
    const int64_t p = m_config.patch_cells, w = int64_t(m_geometry.width_px), h = int64_t(m_geometry.height_px);
    const int64_t span0 = int64_t(tile) << key.level, margin = int64_t(1) << key.level;
    const int64_t tx0 = int64_t(key.x) * span0 - margin, tx1 = (int64_t(key.x) + 1) * span0 + margin;
    const int64_t ty0 = int64_t(key.y) * span0 - margin, ty1 = (int64_t(key.y) + 1) * span0 + margin;
    // Bounded: nodes of tiles long evicted are never asked again.
    if (m_error_cache.size() > kMaxCachedNodeErrors) m_error_cache.clear();
    for (auto it = m_error_cache.begin(); it != m_error_cache.end();) {
      const NodeId& n = it->first;
      const int64_t span = p << n.level;
      const int64_t nx0 = std::clamp<int64_t>(n.x * span, 0, w - 1), nx1 = std::clamp<int64_t>((n.x + 1) * span, 0, w - 1);
      const int64_t ny0 = std::clamp<int64_t>(n.y * span, 0, h - 1), ny1 = std::clamp<int64_t>((n.y + 1) * span, 0, h - 1);
      const bool meets = n.level >= key.level && nx1 >= tx0 && nx0 <= tx1 && ny1 >= ty0 && ny0 <= ty1;
      it = meets ? m_error_cache.erase(it) : std::next(it);
    }
    // Each node-sized block's largest cell twist (cells inside the tile).
    const uint32_t block = std::min(m_config.patch_cells, tile), blocks = tile / block;
    std::vector<float>& twist = m_slot_twist[key.level][slot];
    twist.assign(size_t(blocks) * blocks, 0.0f);
    for (uint32_t j = 0; j + 1 < tile; ++j)
      for (uint32_t i = 0; i + 1 < tile; ++i) {
        const float* a = heights + size_t(j) * tile + i;
        const float t = std::abs(a[0] - a[1] - a[tile] + a[tile + 1]) * 0.25f;
        float& b = twist[size_t(j / block) * blocks + i / block];
        b = std::max(b, t);
      }
  }
}

glm::vec2 TerrainRenderer::heightBounds(uint32_t ring_level, glm::i64vec2 s0, glm::i64vec2 s1) const {
  const uint32_t level = std::min(ring_level, m_geometry.levelCount() - 1);
  const int shift = int(ring_level - level);
  s0 *= int64_t(1) << shift;
  s1 *= int64_t(1) << shift;
  const LevelInfo& info = m_geometry.levels[level];
  const int64_t tile = m_geometry.tile_px;
  const int64_t tx0 = std::clamp<int64_t>(s0.x, 0, int64_t(info.width_px) - 1) / tile;
  const int64_t tx1 = std::clamp<int64_t>(s1.x, 0, int64_t(info.width_px) - 1) / tile;
  const int64_t ty0 = std::clamp<int64_t>(s0.y, 0, int64_t(info.height_px) - 1) / tile;
  const int64_t ty1 = std::clamp<int64_t>(s1.y, 0, int64_t(info.height_px) - 1) / tile;
  glm::vec2 b(INFINITY, -INFINITY);
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      const size_t slot = size_t(slotOf(ty)) * m_slots + slotOf(tx);
      if (m_slot_tile[level][slot] != (uint64_t(tx) | (uint64_t(ty) << 32))) {
        // Not resident (the ring does not read it): no bound, never culled.
        return {-INFINITY, INFINITY};
      }
      const glm::vec2 t = m_slot_bounds[level][slot];
      b = {std::min(b.x, t.x), std::max(b.y, t.y)};
    }
  return b;
}

bool TerrainRenderer::groundRange(const Camera& camera, double* lowest, double* highest) const {
  for (uint32_t l = std::min(m_frame.finest_level + kReliefRings, m_coarsest); l <= m_coarsest; ++l) {
    const glm::i64vec2 o = ringOrigin(m_config, camera, l);
    const int64_t n = m_config.ring_cells;
    const glm::vec2 b = heightBounds(l, o, o + glm::i64vec2(n, n));
    if (!std::isfinite(b.x) || !std::isfinite(b.y)) continue;
    *lowest = double(b.x) * m_config.mapping.world_per_height;
    *highest = double(b.y) * m_config.mapping.world_per_height;
    return true;
  }
  return false;
}

uint32_t TerrainRenderer::preloadCoarseLevels(const HeightTileFn& tile) {
  uint32_t missing = 0;
  const size_t floats = size_t(m_geometry.tile_px) * m_geometry.tile_px;
  const uint32_t levels = m_config.full_resolution ? 1 : m_geometry.levelCount();
  for (uint32_t l = 0; l < levels; ++l) {
    const LevelInfo& info = m_geometry.levels[l];
    if (info.tiles_x > m_slots || info.tiles_y > m_slots) continue;
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

bool TerrainRenderer::groundHeight(const glm::dvec2& world_xz, double* height,
                                   uint32_t* level_used) const {
  const TerrainMapping& m = m_config.mapping;
  const glm::dvec2 s0 = (world_xz - m.sample0_world) / m.world_per_sample;  // level-0 samples
  const int64_t tile = m_geometry.tile_px;
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
      const int64_t tx = i / tile, ty = j / tile;
      const size_t slot = size_t(slotOf(ty)) * m_slots + slotOf(tx);
      if (m_slot_tile[level][slot] != (uint64_t(tx) | (uint64_t(ty) << 32))) {
        have = false;
        return 0.0;
      }
      return m_slot_heights[level][slot][size_t(j - ty * tile) * tile + size_t(i - tx * tile)];
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

bool TerrainRenderer::levelResident(uint32_t ring_level, const glm::i64vec2& ring_origin) const {
  // Samples the ring reads: its (n + 1)^2 vertices and one more on each
  // side (normals), clamped to the level; a ring past the last stored
  // level reads that level's samples 2^k apart.
  const uint32_t last_level = m_geometry.levelCount() - 1;
  const uint32_t level = std::min(ring_level, last_level);
  const int shift = int(ring_level - level);
  const glm::i64vec2 origin = ring_origin * (int64_t(1) << shift);
  const LevelInfo& info = m_geometry.levels[level];
  const int64_t tile = m_geometry.tile_px;
  const int64_t n = int64_t(m_config.ring_cells) << shift;
  auto tiles = [&](int64_t first, int64_t last, uint64_t size, int64_t* t0, int64_t* t1) {
    first = std::clamp<int64_t>(first, 0, int64_t(size) - 1);
    last = std::clamp<int64_t>(last, 0, int64_t(size) - 1);
    *t0 = first / tile;
    *t1 = last / tile;
  };
  int64_t tx0, tx1, ty0, ty1;
  tiles(origin.x - 1, origin.x + n + 1, info.width_px, &tx0, &tx1);
  tiles(origin.y - 1, origin.y + n + 1, info.height_px, &ty0, &ty1);
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      const uint64_t want = uint64_t(tx) | (uint64_t(ty) << 32);
      if (m_slot_tile[level][size_t(slotOf(ty)) * m_slots + slotOf(tx)] != want) return false;
    }
  return true;
}

double TerrainRenderer::farDistance(const Camera& camera) const {
  // Beyond the outermost ring's corner and the highest ground.
  const TerrainMapping& m = m_config.mapping;
  const double extent = double(uint64_t(m_config.ring_cells) << m_coarsest) *
                        std::max(m.world_per_sample.x, m.world_per_sample.y);
  return 2.0 * extent + std::abs(camera.position.y) * 2.0 + 1.0;
}

void TerrainRenderer::setFrameUniforms(uint32_t p, const Camera& camera,
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
  glProgramUniform1i(p, loc(p, "uHeightPeriod"), GLint(m_slots * m_geometry.tile_px));
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
  glBindTextureUnit(2, m_heights);
}

void TerrainRenderer::setRingUniforms(uint32_t p, const Camera& camera, uint32_t level,
                                      const glm::i64vec2& o) const {
  const glm::dvec2 cam_int = glm::floor(cameraSamples(m_config.mapping, camera));
  glProgramUniform1i(p, loc(p, "uLevel"), GLint(level));
  glProgramUniform2i(p, loc(p, "uOriginLevel"), GLint(o.x), GLint(o.y));
  const int64_t scale = int64_t(1) << level;
  glProgramUniform2i(p, loc(p, "uOriginRel"), GLint(o.x * scale - int64_t(cam_int.x)),
                     GLint(o.y * scale - int64_t(cam_int.y)));
}

std::vector<glm::vec4> TerrainRenderer::ringVertices(const Camera& camera, const Viewport& viewport,
                                                     uint32_t level) {
  const uint32_t n = m_config.ring_cells;
  const size_t count = size_t(n + 1) * (n + 1);
  std::vector<glm::vec4> out(count);
  if (level >= m_geometry.levelCount()) return {};
  const GLuint p = m_feedback_program;
  setFrameUniforms(p, camera, viewport);
  setRingUniforms(p, camera, level, ringOrigin(m_config, camera, level));
  GLuint buffer = 0;
  glCreateBuffers(1, &buffer);
  glNamedBufferStorage(buffer, GLsizeiptr(count * sizeof(glm::vec4)), nullptr, GL_MAP_READ_BIT);
  glUseProgram(p);
  glBindVertexArray(m_vao);
  glEnable(GL_RASTERIZER_DISCARD);
  glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, buffer);
  glBeginTransformFeedback(GL_POINTS);
  glDrawArrays(GL_POINTS, 0, GLsizei(count));
  glEndTransformFeedback();
  glDisable(GL_RASTERIZER_DISCARD);
  glBindVertexArray(0);
  glUseProgram(0);
  glGetNamedBufferSubData(buffer, 0, GLsizeiptr(count * sizeof(glm::vec4)), out.data());
  glDeleteBuffers(1, &buffer);
  return out;
}

void TerrainRenderer::draw(const Camera& camera, const Viewport& viewport,
                           const ClipmapRenderer& colour) {
  const GLuint p = m_program[colour.overlay() == Overlay::kOff ? 0 : 1];
  updateCoarsest(camera, colour);
  colour.bindColour(p, camera, viewport);
  setFrameUniforms(p, camera, viewport);
  drawRings(p, camera, viewport);
}

Status TerrainRenderer::readPositions(const Camera& camera, const Viewport& viewport,
                                      const ClipmapRenderer& colour, std::vector<float>* xyzw) {
  if (m_position_size.width_px != viewport.width_px || m_position_size.height_px != viewport.height_px) {
    gl_util::clearErrors();
    glDeleteFramebuffers(1, &m_position_fbo);
    glDeleteRenderbuffers(1, &m_position_color);
    glDeleteRenderbuffers(1, &m_position_depth);
    glCreateRenderbuffers(1, &m_position_color);
    glNamedRenderbufferStorage(m_position_color, GL_RGBA32F, GLsizei(viewport.width_px), GLsizei(viewport.height_px));
    glCreateRenderbuffers(1, &m_position_depth);
    glNamedRenderbufferStorage(m_position_depth, GL_DEPTH_COMPONENT24, GLsizei(viewport.width_px),
                               GLsizei(viewport.height_px));
    glCreateFramebuffers(1, &m_position_fbo);
    glNamedFramebufferRenderbuffer(m_position_fbo, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, m_position_color);
    glNamedFramebufferRenderbuffer(m_position_fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, m_position_depth);
    if (Status s = gl_util::checkCreated("the terrain's position target (" + std::to_string(viewport.width_px) +
                                         "x" + std::to_string(viewport.height_px) + " RGBA32F)");
        !s) {
      m_position_size = Viewport{};  // made again on the next call
      return s;
    }
    m_position_size = viewport;
  }
  GLint previous_fbo = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &previous_fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, m_position_fbo);
  glViewport(0, 0, GLsizei(viewport.width_px), GLsizei(viewport.height_px));
  const float none[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  glClearNamedFramebufferfv(m_position_fbo, GL_COLOR, 0, none);
  glClearNamedFramebufferfi(m_position_fbo, GL_DEPTH_STENCIL, 0, 1.0f, 0);
  const GLuint p = m_position_program;
  updateCoarsest(camera, colour);
  colour.bindColour(p, camera, viewport);  // the image's extent (uImageRel)
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

TerrainRenderer::Frustum TerrainRenderer::frustum(const Camera& camera, const Viewport& viewport) const {
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

void TerrainRenderer::drawRings(uint32_t p, const Camera& camera, const Viewport& viewport) {
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

void TerrainRenderer::drawClipmapRings(uint32_t p, const Camera& camera, const Viewport& viewport) {
  m_frame = TerrainFrame{};
  const uint32_t n = m_config.ring_cells;
  const uint32_t coarsest = m_coarsest;
  std::vector<glm::i64vec2> origins(coarsest + 1);
  for (uint32_t l = 0; l <= coarsest; ++l) origins[l] = ringOrigin(m_config, camera, l);
  // The innermost ring: the finest level that, with every coarser ring, is
  // resident. A gap below it only coarsens the geometry.
  int64_t finest = -1;
  for (int64_t l = coarsest; l >= 0; --l) {
    if (!levelResident(uint32_t(l), origins[size_t(l)])) break;
    finest = l;
  }
  if (finest < 0) return;

  glUseProgram(p);
  glBindVertexArray(m_vao);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  const Frustum planes = frustum(camera, viewport);
  for (uint32_t l = uint32_t(finest); l <= coarsest; ++l) {
    const glm::i64vec2 o = origins[l];
    const int config = l == uint32_t(finest) ? 0 : holeConfig(origins[l - 1], o, n);
    if (config < 0 || config > 4) continue;  // cannot happen: origins nest (see ringOrigin)
    drawGrid(p, camera, planes, l, o, config);
    ++m_frame.rings;
  }
  m_frame.finest_level = uint32_t(finest);
  m_frame.coarsest_level = coarsest;
  glDisable(GL_DEPTH_TEST);
  glBindVertexArray(0);
  glUseProgram(0);
}

void TerrainRenderer::drawPatches(uint32_t p, const Camera& camera, const Viewport& viewport) {
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
  glBindVertexArray(m_vao);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  const Frustum planes = frustum(camera, viewport);
  for (int64_t py = floorDiv(s0y, n); py * n < s1y; ++py)
    for (int64_t px = floorDiv(s0x, n); px * n < s1x; ++px) drawGrid(p, camera, planes, 0, {px * n, py * n}, 0);
  m_frame.rings = 1;
  glDisable(GL_DEPTH_TEST);
  glBindVertexArray(0);
  glUseProgram(0);
}

void TerrainRenderer::drawGrid(uint32_t p, const Camera& camera, const Frustum& planes, uint32_t l,
                               const glm::i64vec2& o, int config) {
  const uint32_t n = m_config.ring_cells;
  const TerrainMapping& m = m_config.mapping;
  const glm::dvec2 cam = cameraSamples(m, camera);
  const uint32_t block_cells = n / kBlocks;
  setRingUniforms(p, camera, l, o);
  std::vector<GLsizei> counts;
  std::vector<const void*> offsets;
  const double spacing = std::ldexp(1.0, int(l));
  for (uint32_t b = 0; b < kBlocks * kBlocks; ++b) {
    if (m_index_count[config][b] == 0) continue;
    // The block's box, camera-relative: its cells (plus the two samples
    // the transition and normals reach beyond them) and the heights of
    // the tiles under it.
    const glm::i64vec2 c0 = o + glm::i64vec2((b % kBlocks) * block_cells, (b / kBlocks) * block_cells);
    const glm::i64vec2 c1 = c0 + glm::i64vec2(block_cells, block_cells);
    const glm::vec2 h = heightBounds(l, glm::max(c0 - int64_t(2), o - int64_t(1)),
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
    counts.push_back(GLsizei(m_index_count[config][b]));
    offsets.push_back(reinterpret_cast<const void*>(uintptr_t(m_first_index[config][b]) * sizeof(uint32_t)));
    m_frame.triangles += m_index_count[config][b] / 3;
    ++m_frame.blocks;
  }
  if (!counts.empty()) {
    glMultiDrawElements(GL_TRIANGLES, counts.data(), GL_UNSIGNED_INT, offsets.data(), GLsizei(counts.size()));
  }
}

}  // namespace clipstream
