// The quadtree terrain method of TerrainRenderer (terrain.h,
// TerrainMethod::kQuadtree) and the flat plane drawn the same way: node
// selection by projected geometric error, the restriction to neighbours
// within one level, and the draws with the edge patterns that stitch a
// node to a coarser neighbour. docs/terrain.md, "Quadtree", explains it.
#include "terrain_impl.h"

#include "gl.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>
#include <unordered_set>

namespace clipstream {
namespace {

int64_t floorDiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

// One frame's choice of leaves, in three steps (selectNodes()): split by
// error from the roots down, restrict neighbours to one level apart, list
// the leaves with their coarse sides. Lives for one selectNodes() call, on
// the GL thread.
class TerrainRendererImpl::NodeSelection {
 public:
  using NodeKey = NodeId;
  NodeSelection(TerrainRendererImpl& terrain, const Camera& camera, const Viewport& viewport);
  // 1. Top-down: splits while the error asks and the children are resident.
  // Returns the nodes that wanted to split but could not (drawn coarser).
  uint32_t splitByError();
  // 2. Restriction: a visible leaf's neighbours are at most one level
  // coarser. Returns the splits made only for that. Leaves the leaves.
  uint32_t restrictNeighbours();
  // Instead of restrictNeighbours(), for measuring (setExactNodeError()):
  // the leaves as split, neighbours unrestricted. Returns 0 (no forced split).
  uint32_t unrestricted();
  // 3. The leaves with their coarse sides.
  void leaves(std::vector<TerrainNode>* out) const;

 private:
  static NodeKey parentOf(const NodeKey& k) { return {k.level + 1, floorDiv(k.x, 2), floorDiv(k.y, 2)}; }
  // Whether `a` is `k` or one of its ancestors.
  static bool isAncestorOrSelf(const NodeKey& a, NodeKey k) {
    while (k.level < a.level) k = parentOf(k);
    return k == a;
  }
  bool visible(const NodeKey& k) const {
    return m_terrain.nodeVisible(m_camera, m_terrain.nodeBox(m_camera, k.level, k.x, k.y));
  }
  bool childrenResident(const NodeKey& k) const;
  bool wantsSplit(const NodeKey& k, const NodeBox& b) const;
  bool leafAt(uint32_t level, int64_t x, int64_t y, NodeKey* leaf) const;
  void collectLeaves();

  // Sides in PatchSide order: top, right, bottom, left.
  static constexpr int kSideDx[4] = {0, 1, 0, -1}, kSideDy[4] = {-1, 0, 1, 0};
  TerrainRendererImpl& m_terrain;
  const Camera& m_camera;
  const int64_t m_patch;
  const uint32_t m_root;
  double m_pixels = 0.0;  // pixels per world unit at unit distance
  // The grid of level-m_root nodes over the field and the image.
  int64_t m_rx0 = 0, m_ry0 = 0, m_rx1 = 0, m_ry1 = 0;
  std::vector<NodeKey> m_roots;
  std::unordered_set<NodeKey, NodeIdHash> m_split;
  std::vector<NodeKey> m_leaves;
};

TerrainRendererImpl::NodeSelection::NodeSelection(TerrainRendererImpl& terrain, const Camera& camera,
                                                  const Viewport& viewport)
    : m_terrain(terrain), m_camera(camera), m_patch(terrain.m_config.patch_cells), m_root(terrain.rootLevel()) {
  const TerrainMapping& m = terrain.m_config.mapping;
  m_pixels = double(viewport.height_px) / (2.0 * std::tan(camera.vfov_rad / 2.0));
  const glm::dvec2 img0 = (-m.sample0_world) / m.world_per_sample;
  const glm::dvec2 img1 = (terrain.m_image_px - m.sample0_world) / m.world_per_sample;
  const LevelInfo& l0 = terrain.m_geometry.levels[0];
  const int64_t span = m_patch << m_root;
  m_rx0 = floorDiv(std::min<int64_t>(0, int64_t(std::floor(img0.x)) - 1), span);
  m_ry0 = floorDiv(std::min<int64_t>(0, int64_t(std::floor(img0.y)) - 1), span);
  m_rx1 = floorDiv(std::max<int64_t>(int64_t(l0.width_px), int64_t(std::ceil(img1.x)) + 1), span);
  m_ry1 = floorDiv(std::max<int64_t>(int64_t(l0.height_px), int64_t(std::ceil(img1.y)) + 1), span);
  for (int64_t y = m_ry0; y <= m_ry1; ++y)
    for (int64_t x = m_rx0; x <= m_rx1; ++x) m_roots.push_back({m_root, x, y});
}

bool TerrainRendererImpl::NodeSelection::childrenResident(const NodeKey& k) const {
  // A node may split when its four children can be drawn: their samples
  // (one beyond, for normals) are resident.
  const glm::i64vec2 s0(2 * k.x * m_patch - 1, 2 * k.y * m_patch - 1);
  return m_terrain.samplesResident(k.level - 1, s0, s0 + glm::i64vec2(2 * m_patch + 2, 2 * m_patch + 2));
}

bool TerrainRendererImpl::NodeSelection::wantsSplit(const NodeKey& k, const NodeBox& b) const {
  if (k.level == 0 || m_terrain.m_config.method == TerrainMethod::kFlat) return false;
  const double e = m_terrain.nodeError(k.level, k.x, k.y) * m_terrain.m_config.mapping.world_per_height;
  if (!(e > 0.0)) return false;
  // Distance from the camera (the origin) to the box.
  const glm::dvec3 d = glm::max(glm::max(b.lo, -b.hi), glm::dvec3(0.0));
  const double dist = glm::length(d);
  return dist <= 0.0 || e * m_pixels / dist > m_terrain.m_config.error_px;
}

uint32_t TerrainRendererImpl::NodeSelection::splitByError() {
  std::vector<NodeKey> stack = m_roots;
  uint32_t fallbacks = 0;
  while (!stack.empty()) {
    const NodeKey k = stack.back();
    stack.pop_back();
    const NodeBox b = m_terrain.nodeBox(m_camera, k.level, k.x, k.y);
    if (!m_terrain.nodeVisible(m_camera, b) || !wantsSplit(k, b)) continue;
    if (!childrenResident(k)) {
      ++fallbacks;
      continue;
    }
    m_split.insert(k);
    for (int c = 0; c < 4; ++c) stack.push_back({k.level - 1, 2 * k.x + (c & 1), 2 * k.y + (c >> 1)});
  }
  return fallbacks;
}

bool TerrainRendererImpl::NodeSelection::leafAt(uint32_t level, int64_t x, int64_t y, NodeKey* leaf) const {
  // The leaf holding the level-`level` square (x, y): its deepest ancestor
  // (or itself) that is not split, if a root holds it.
  NodeKey k{level, x, y};
  std::vector<NodeKey> chain;
  while (k.level < m_root) {
    chain.push_back(k);
    k = parentOf(k);
  }
  if (k.x < m_rx0 || k.x > m_rx1 || k.y < m_ry0 || k.y > m_ry1) return false;
  // Walk down from the root while split.
  while (m_split.count(k) && !chain.empty()) {
    k = chain.back();
    chain.pop_back();
  }
  if (m_split.count(k)) return false;  // finer than `level` there
  *leaf = k;
  return true;
}

void TerrainRendererImpl::NodeSelection::collectLeaves() {
  m_leaves.clear();
  std::vector<NodeKey> s = m_roots;
  while (!s.empty()) {
    const NodeKey k = s.back();
    s.pop_back();
    if (!m_split.count(k)) {
      m_leaves.push_back(k);
      continue;
    }
    for (int c = 0; c < 4; ++c) s.push_back({k.level - 1, 2 * k.x + (c & 1), 2 * k.y + (c >> 1)});
  }
}

uint32_t TerrainRendererImpl::NodeSelection::restrictNeighbours() {
  // A coarser neighbour is split; one that cannot be (its children not
  // resident) instead coarsens the finer side (the leaf's ancestor one
  // level finer than the neighbour becomes a leaf, and is never split again
  // this frame, so this ends).
  std::unordered_set<NodeKey, NodeIdHash> frozen;
  uint32_t forced = 0;
  for (bool changed = true; changed;) {
    changed = false;
    collectLeaves();
    for (const NodeKey& l : m_leaves) {
      if (!visible(l)) continue;
      for (int s = 0; s < 4 && !changed; ++s) {
        NodeKey nb;
        if (!leafAt(l.level, l.x + kSideDx[s], l.y + kSideDy[s], &nb) || nb.level <= l.level + 1) continue;
        if (!visible(nb)) continue;
        if (!frozen.count(nb) && childrenResident(nb)) {
          m_split.insert(nb);
          ++forced;
        } else {
          NodeKey a = l;
          while (a.level + 1 < nb.level) a = parentOf(a);
          for (auto it = m_split.begin(); it != m_split.end();)
            it = isAncestorOrSelf(a, *it) ? m_split.erase(it) : std::next(it);
          frozen.insert(a);
        }
        changed = true;
      }
      if (changed) break;
    }
  }
  return forced;
}

uint32_t TerrainRendererImpl::NodeSelection::unrestricted() {
  collectLeaves();
  return 0;
}

void TerrainRendererImpl::NodeSelection::leaves(std::vector<TerrainNode>* out) const {
  for (const NodeKey& l : m_leaves) {
    TerrainNode node;
    node.level = l.level;
    node.x = l.x;
    node.y = l.y;
    // A root whose heights are not resident yet is not drawn (children
    // are only made where they are).
    const glm::i64vec2 s0(l.x * m_patch - 1, l.y * m_patch - 1);
    node.drawn = visible(l) && m_terrain.samplesResident(l.level, s0, s0 + glm::i64vec2(m_patch + 2, m_patch + 2));
    for (int s = 0; s < 4; ++s) {
      NodeKey nb;
      if (leafAt(l.level, l.x + kSideDx[s], l.y + kSideDy[s], &nb) && nb.level > l.level)
        node.coarse_sides |= 1u << s;
    }
    out->push_back(node);
  }
}

double TerrainRendererImpl::flatHeight() const {
  if (m_bounds) return double(m_bounds->range.x);
  // The pyramid's last level: one tile, preloaded.
  const uint32_t last = m_geometry.levelCount() - 1;
  return m_stack->holds(last, 0, 0) ? double(m_stack->tileBounds(last, 0, 0).x) : 0.0;
}

uint32_t TerrainRendererImpl::rootLevel() const {
  // Roots cover the height field and the colour image beyond it (as the
  // full-resolution mesh does), no coarser than the pyramid's last level
  // (preloaded, so every root is resident from the first frame).
  const int64_t p = m_config.patch_cells;
  const TerrainMapping& m = m_config.mapping;
  const glm::dvec2 img0 = (-m.sample0_world) / m.world_per_sample;
  const glm::dvec2 img1 = (m_image_px - m.sample0_world) / m.world_per_sample;
  const LevelInfo& l0 = m_geometry.levels[0];
  const double ex = std::max(double(l0.width_px), img1.x) - std::min(0.0, img0.x) + 2.0;
  const double ey = std::max(double(l0.height_px), img1.y) - std::min(0.0, img0.y) + 2.0;
  uint32_t r = m_geometry.levelCount() - 1;
  while (std::ldexp(double(p), int(r)) < std::max(ex, ey) && r + 3 < renderer_config::kMaxLevels) ++r;
  return r;
}

bool TerrainRendererImpl::samplesResident(uint32_t level, glm::i64vec2 s0, glm::i64vec2 s1) const {
  // heightBounds() has no bound (infinite) exactly where a tile is missing.
  return std::isfinite(m_stack->heightBounds(level, s0, s1).x);
}

TerrainRendererImpl::NodeBox TerrainRendererImpl::nodeBox(const Camera& camera, uint32_t level, int64_t x,
                                                          int64_t y) const {
  const int64_t p = m_config.patch_cells;
  const TerrainMapping& m = m_config.mapping;
  const glm::dvec2 cam = cameraSamples(m, camera);
  const double spacing = std::ldexp(1.0, int(level));
  const glm::i64vec2 s0(x * p, y * p), s1 = s0 + glm::i64vec2(p, p);
  // Heights the node's vertices and normals read (one sample beyond).
  glm::vec2 h = m_stack->heightBounds(level, s0 - int64_t(1), s1 + int64_t(1));
  if (m_config.method == TerrainMethod::kFlat) h = glm::vec2(float(flatHeight()));
  NodeBox b;
  const glm::dvec2 x0 = (glm::dvec2(s0) * spacing - cam) * m.world_per_sample;
  const glm::dvec2 x1 = (glm::dvec2(s1) * spacing - cam) * m.world_per_sample;
  b.lo = {x0.x, double(h.x) * m.world_per_height - camera.position.y, x0.y};
  b.hi = {x1.x, double(h.y) * m.world_per_height - camera.position.y, x1.y};
  return b;
}

bool TerrainRendererImpl::nodeVisible(const Camera& camera, const NodeBox& b) const {
  // Wholly outside the colour image: clipped by terrain.vert anyway.
  if (b.hi.x <= -camera.position.x || b.hi.z <= -camera.position.z ||
      b.lo.x >= m_image_px.x - camera.position.x || b.lo.z >= m_image_px.y - camera.position.z)
    return false;
  for (const glm::dvec4& pl : m_frustum_cache) {
    const glm::dvec3 far_corner(pl.x >= 0 ? b.hi.x : b.lo.x, pl.y >= 0 ? b.hi.y : b.lo.y,
                                pl.z >= 0 ? b.hi.z : b.lo.z);
    if (glm::dot(glm::dvec3(pl), far_corner) + pl.w < 0.0) return false;
  }
  return true;
}

bool TerrainRendererImpl::cpuHeight(uint32_t level, int64_t i, int64_t j, float* h) const {
  const uint32_t last = m_geometry.levelCount() - 1;
  if (level > last) {
    i *= int64_t(1) << (level - last);
    j *= int64_t(1) << (level - last);
    level = last;
  }
  return m_stack->sample(level, i, j, h);
}

double TerrainRendererImpl::nodeError(uint32_t level, int64_t x, int64_t y) {
  if (level == 0) return 0.0;
  if (m_exact_node_error) return m_exact_node_error(level, x, y);
  const auto cached = m_error_cache.find(NodeId{level, x, y});
  if (cached != m_error_cache.end()) return double(cached->second);
  double error = tileErrorBound(level, x, y);
  // Where the next finer level is resident under the node: the exact
  // largest distance of its samples from this node's surface (the two
  // surfaces are piecewise linear on the finer grid, whose triangles lie
  // inside the coarser ones, so the largest distance is at a finer
  // sample), plus the children's own bounds.
  const int64_t p = m_config.patch_cells;
  const glm::i64vec2 f0(2 * x * p, 2 * y * p);
  // Only nodes over the field (beyond it the resident edge tiles would
  // make a whole unbounded margin look resident).
  const uint32_t stored = std::min(level - 1, m_geometry.levelCount() - 1);
  const int64_t scale = int64_t(1) << (level - 1 - stored);
  const LevelInfo& fine_level = m_geometry.levels[stored];
  const bool inside = f0.x >= 0 && f0.y >= 0 && f0.x * scale < int64_t(fine_level.width_px) - 1 &&
                      f0.y * scale < int64_t(fine_level.height_px) - 1;
  if (error > 0.0 && inside && samplesResident(level - 1, f0, f0 + glm::i64vec2(2 * p, 2 * p))) {
    double local = 0.0;
    bool ok = true;
    for (int64_t j = f0.y; j <= f0.y + 2 * p && ok; ++j)
      for (int64_t i = f0.x; i <= f0.x + 2 * p && ok; ++i) {
        // The coarser surface at finer sample (i, j): the coarse cell's
        // diagonal cut (terrain.vert's coarseAt()).
        float fine = 0, c0 = 0, c1 = 0;
        ok = cpuHeight(level - 1, i, j, &fine) && cpuHeight(level, i >> 1, j >> 1, &c0) &&
             cpuHeight(level, (i + 1) >> 1, (j + 1) >> 1, &c1);
        local = std::max(local, std::abs(double(fine) - 0.5 * (double(c0) + double(c1))));
      }
    if (ok) {
      double children = 0.0;
      for (int c = 0; c < 4; ++c)
        children = std::max(children, nodeError(level - 1, 2 * x + (c & 1), 2 * y + (c >> 1)));
      error = std::min(error, local + children);
    }
  }
  m_error_cache[NodeId{level, x, y}] = float(error);
  return error;
}

double TerrainRendererImpl::tileErrorBound(uint32_t level, int64_t x, int64_t y) const {
  const int64_t p = m_config.patch_cells, tile = m_geometry.tile_px;
  const uint32_t levels = m_geometry.levelCount();
  if (level >= levels) {
    // Coarser than the pyramid: no stored bound; the whole height range.
    if (m_bounds) return double(m_bounds->range.y - m_bounds->range.x);
    return INFINITY;
  }
  const LevelInfo& info = m_geometry.levels[level];
  // Beyond a corner of the field the surface is the corner's height, flat:
  // no error (beyond one side it is the edge's profile, the edge tiles').
  const bool beyond_x = (x + 1) * p <= 0 || x * p >= int64_t(info.width_px) - 1;
  const bool beyond_y = (y + 1) * p <= 0 || y * p >= int64_t(info.height_px) - 1;
  if (beyond_x && beyond_y) return 0.0;
  // The tiles under the node (clamped to the level: beyond the field the
  // surface is the edge's).
  const int64_t tx0 = std::clamp<int64_t>(x * p, 0, int64_t(info.width_px) - 1) / tile;
  const int64_t tx1 = std::clamp<int64_t>((x + 1) * p - 1, 0, int64_t(info.width_px) - 1) / tile;
  const int64_t ty0 = std::clamp<int64_t>(y * p, 0, int64_t(info.height_px) - 1) / tile;
  const int64_t ty1 = std::clamp<int64_t>((y + 1) * p - 1, 0, int64_t(info.height_px) - 1) / tile;
  double error = 0.0;
  for (int64_t ty = ty0; ty <= ty1; ++ty)
    for (int64_t tx = tx0; tx <= tx1; ++tx) {
      // The index's bound of |level-0 ground - bilinear surface of the
      // tile's samples|; for a level finer than the bounds hold, the
      // height range of its ancestor at the finest level held (the level-0
      // ground and the node's samples both lie in it). No bounds: none
      // (the exact pass in nodeError() may give one).
      double e = INFINITY;
      if (m_bounds && !m_bounds->levels.empty()) {
        const uint32_t bl = std::max(level, m_bounds->finest_level);
        const TerrainBounds::Level& lv = m_bounds->levels[bl];
        if (!lv.error.empty()) {
          const int64_t bx = std::min<int64_t>(tx >> (bl - level), lv.tiles_x - 1);
          const int64_t by = std::min<int64_t>(ty >> (bl - level), lv.tiles_y - 1);
          const size_t t = size_t(by) * lv.tiles_x + size_t(bx);
          e = bl == level ? double(lv.error[t]) : double(lv.range[t].y - lv.range[t].x);
        }
      }
      // The mesh cuts cells along a diagonal: add the distance between
      // that surface and the bilinear one (a quarter of the cell's twist).
      if (m_stack->holds(level, tx, ty) && !m_stack->tileTwist(level, tx, ty).empty()) {
        const std::vector<float>& twist = m_stack->tileTwist(level, tx, ty);
        const int64_t block = std::min<int64_t>(p, tile), blocks = tile / block;
        const int64_t i0 = std::max<int64_t>(x * p - tx * tile, 0) / block;
        const int64_t i1 = std::min<int64_t>((x + 1) * p - 1 - tx * tile, tile - 1) / block;
        const int64_t j0 = std::max<int64_t>(y * p - ty * tile, 0) / block;
        const int64_t j1 = std::min<int64_t>((y + 1) * p - 1 - ty * tile, tile - 1) / block;
        float t = 0.0f;
        for (int64_t j = j0; j <= j1; ++j)
          for (int64_t i = i0; i <= i1; ++i) t = std::max(t, twist[size_t(j * blocks + i)]);
        e += double(t);
      }
      error = std::max(error, e);
    }
  return error;
}

void TerrainRendererImpl::selectNodes(const Camera& camera, const Viewport& viewport) {
  m_nodes.clear();
  m_frustum_cache = frustum(camera, viewport);
  NodeSelection selection(*this, camera, viewport);
  const uint32_t fallbacks = selection.splitByError();
  // Unrestricted when measuring with exact node errors (no stitching).
  const uint32_t forced = m_exact_node_error ? selection.unrestricted() : selection.restrictNeighbours();
  selection.leaves(&m_nodes);
  m_frame.fallback_nodes = fallbacks;
  m_frame.forced_splits = forced;
}

void TerrainRendererImpl::forgetNodeErrors(const TileKey& key) {
  // Node errors that read this tile: nodes at its level or coarser whose
  // ground (clamped to the field: nodes beyond it read its edge) meets
  // the tile's, one sample around (their bounds take their children's).
  const int64_t p = m_config.patch_cells, w = int64_t(m_geometry.width_px), h = int64_t(m_geometry.height_px);
  const int64_t span0 = int64_t(m_geometry.tile_px) << key.level, margin = int64_t(1) << key.level;
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
}

void TerrainRendererImpl::drawQuadtree(uint32_t p, const Camera& camera, const Viewport& viewport) {
  m_frame = TerrainFrame{};
  selectNodes(camera, viewport);
  glUseProgram(p);
  glBindVertexArray(m_patch_mesh->vao());
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  const int64_t cells = m_config.patch_cells;
  uint32_t finest = std::numeric_limits<uint32_t>::max(), coarsest = 0;
  std::unordered_set<uint32_t> levels;
  for (const TerrainNode& node : m_nodes) {
    if (!node.drawn) continue;
    setRingUniforms(p, camera, node.level, {node.x * cells, node.y * cells});
    const uint32_t mask = node.coarse_sides;
    const terrain_mesh::IndexRange range = m_patch_masks[mask];
    glDrawElements(GL_TRIANGLES, GLsizei(range.count), GL_UNSIGNED_INT,
                   reinterpret_cast<const void*>(uintptr_t(range.first) * sizeof(uint32_t)));
    m_frame.triangles += range.count / 3;
    ++m_frame.nodes;
    ++m_frame.blocks;
    levels.insert(node.level);
    finest = std::min(finest, node.level);
    coarsest = std::max(coarsest, node.level);
  }
  m_frame.culled_blocks = uint32_t(m_nodes.size()) - m_frame.nodes;
  m_frame.rings = uint32_t(levels.size());
  m_frame.finest_level = m_frame.nodes ? finest : 0;
  m_frame.coarsest_level = coarsest;
  glDisable(GL_DEPTH_TEST);
  glBindVertexArray(0);
  glUseProgram(0);
}

}  // namespace clipstream
