// The quadtree terrain method of TerrainRenderer (terrain.h,
// TerrainMethod::kQuadtree) and the flat plane drawn the same way: node
// selection by projected geometric error, largest first and within the
// triangle budget, the restriction to neighbours within one level (a
// worklist), and the draws with the edge patterns that stitch a node to a
// coarser neighbour, one instanced draw per pattern. The nodes' error
// bounds are terrain_node_error.cpp's. docs/terrain.md, "Geometry: a
// restricted quadtree", explains it.
#include "terrain_impl.h"

#include "gl.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <unordered_map>
#include <unordered_set>

namespace clipstream {
namespace {

int64_t floorDiv(int64_t a, int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

}  // namespace

// One frame's choice of leaves, in three steps (selectNodes()): split by
// error from the roots down, largest projected error first, within the
// triangle budget; restrict neighbours to one level apart; list the leaves
// with their coarse sides. Lives for one selectNodes() call, on the GL
// thread.
class TerrainRendererImpl::NodeSelection {
 public:
  using NodeKey = NodeId;
  NodeSelection(TerrainRendererImpl& terrain, const Camera& camera, const Viewport& viewport);
  // 1. Best first from the roots: splits the node of largest projected
  // error while that exceeds error_px and its children are resident. A
  // child's error is capped by its parent's, so the first n splits are
  // exactly those of one bound (the split rule at the next one's error).
  // The splits, in order: splitCount() of them. With a budget, it stops
  // once the splits draw over twice `budget_triangles` (kept splits are a
  // prefix that fits, and a split draws fewer only when all its children
  // are culled, so no later prefix fits again in practice): on a cold
  // frame whose budget binds, the evaluations of splits never kept cost
  // most of the selection (the spikes of tests/eval/test_terrain_flight.cpp:
  // 377 splits for 42 kept, 3.6 ms).
  void splitByError(uint64_t budget_triangles = 0);
  // The most of the first splits that draw at most `budget_triangles`,
  // each drawn node a whole patch (2 P^2 triangles); all when all fit.
  size_t splitsWithin(uint64_t budget_triangles) const;
  // Instead, the reference (setReferenceSelection()): depth first, no
  // budget, visibility not cached. Returns the fallbacks.
  uint32_t splitDepthFirst();
  size_t splitCount() const { return m_order.size(); }
  // Keeps the first `count` splits (a tree), undoing any restriction.
  void keepSplits(size_t count);
  // 2. Restriction: a visible leaf's neighbours are at most one level
  // coarser. Returns the splits made only for that. Leaves the leaves.
  // Over a budget, searches for the most of step 1's splits (*kept) that fit.
  uint32_t restrictWithin(uint64_t budget_triangles, size_t* kept);
  // Instead, the reference: a full scan of the leaves after each mend.
  uint32_t restrictNeighboursByRescan();
  // Instead, for measuring (setExactNodeError()): the leaves as split,
  // neighbours unrestricted. Returns 0 (no forced split).
  uint32_t unrestricted();
  // The bound (pixels) the first `count` splits meet: error_px when they
  // are every split the error asks for, else the next split's error
  // (at most kMaxTerrainErrorPx).
  double boundWith(size_t count) const;
  // Nodes that wanted to split, children not resident, among the roots and
  // the children of the first `count` splits.
  uint32_t fallbacksWith(size_t count) const;
  // Leaves the restriction drew coarser (a neighbour could not split).
  uint32_t coarsened() const { return m_coarsened; }
  // 3. The leaves with their coarse sides.
  void leaves(std::vector<TerrainNode>* out) const;

 private:
  static NodeKey parentOf(const NodeKey& k) { return {k.level + 1, floorDiv(k.x, 2), floorDiv(k.y, 2)}; }
  static NodeKey childOf(const NodeKey& k, int c) { return {k.level - 1, 2 * k.x + (c & 1), 2 * k.y + (c >> 1)}; }
  // Visibility of a node's box, computed once a selection.
  bool visible(const NodeKey& k) const;
  // Drawn when a leaf: visible, and its samples (one beyond) resident.
  bool drawn(const NodeKey& k) const;
  bool childrenResident(const NodeKey& k) const;
  // Whether the node's error asks for a split; *projected_px: its error
  // projected at its nearest point (infinite with the camera in its box).
  bool wantsSplit(const NodeKey& k, const NodeBox& b, double* projected_px) const;
  enum class Want { kNo, kSplit, kFallback };
  Want evaluate(const NodeKey& k, double* projected_px) const;
  bool inRoots(const NodeKey& k) const;
  bool isLeaf(const NodeKey& k) const;
  bool leafAt(uint32_t level, int64_t x, int64_t y, NodeKey* leaf) const;
  // A visible leaf beside `l` on side `s` two or more levels coarser.
  bool coarserNeighbour(const NodeKey& l, int s, NodeKey* nb) const;
  void collectLeaves();
  uint32_t restrictNeighbours();
  uint64_t leafTriangles() const;
  int64_t splitTriangles(size_t count) const { return m_drawn_after[count] * 2 * m_patch * m_patch; }

  // The restriction's worklist: leaves in collectLeaves()' order (roots
  // last to first, children 3 to 0, depth first), so the first leaf it
  // mends is the one a scan of every leaf would mend first.
  struct Queued {
    uint64_t root, path;  // the root's rank; child digits 3 - c, two bits each from the top
    uint32_t depth;       // below the root (an ancestor comes before its descendants)
    NodeKey key;
    bool operator>(const Queued& o) const {
      return root != o.root ? root > o.root : path != o.path ? path > o.path : depth > o.depth;
    }
  };
  using Worklist = std::priority_queue<Queued, std::vector<Queued>, std::greater<Queued>>;
  Queued queued(const NodeKey& k) const;
  // Coarsens the finer side of leaf l's too-coarse neighbour nb: l's
  // ancestor one level finer than nb becomes a leaf (its split subtree
  // erased) and is frozen for the frame. Returns that ancestor.
  NodeKey coarsenBeside(const NodeKey& l, const NodeKey& nb, std::unordered_set<NodeKey, NodeIdHash>* frozen);
  void pushLeavesAround(const NodeKey& a, Worklist* work) const;  // the leaves touching a's sides
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
  mutable std::unordered_map<NodeKey, bool, NodeIdHash> m_visible;
  const bool m_reference;  // setReferenceSelection(): visibility not cached
  // Step 1's splits in order, with what each changed.
  struct Split {
    NodeKey key;
    double error_px;     // projected, capped by the parent's
    uint32_t fallbacks;  // children that wanted to split, not resident
  };
  std::vector<Split> m_order;
  std::vector<int64_t> m_drawn_after;  // [n]: nodes drawn after the first n splits
  uint32_t m_root_fallbacks = 0;
  uint32_t m_coarsened = 0;
};

TerrainRendererImpl::NodeSelection::NodeSelection(TerrainRendererImpl& terrain, const Camera& camera,
                                                  const Viewport& viewport)
    : m_terrain(terrain),
      m_camera(camera),
      m_patch(terrain.m_config.patch_cells),
      m_root(terrain.rootLevel()),
      m_reference(terrain.m_reference_selection) {
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

bool TerrainRendererImpl::NodeSelection::visible(const NodeKey& k) const {
  const auto it = m_reference ? m_visible.end() : m_visible.find(k);
  if (it != m_visible.end()) return it->second;
  const bool v = m_terrain.nodeVisible(m_camera, m_terrain.nodeBox(m_camera, k.level, k.x, k.y));
  if (!m_reference) m_visible.emplace(k, v);
  return v;
}

bool TerrainRendererImpl::NodeSelection::drawn(const NodeKey& k) const {
  // A root whose heights are not resident yet is not drawn (children are
  // only made where they are).
  const glm::i64vec2 s0(k.x * m_patch - 1, k.y * m_patch - 1);
  return visible(k) && m_terrain.samplesResident(k.level, s0, s0 + glm::i64vec2(m_patch + 2, m_patch + 2));
}

bool TerrainRendererImpl::NodeSelection::childrenResident(const NodeKey& k) const {
  // A node may split when its four children can be drawn: their samples
  // (one beyond, for normals) are resident.
  const glm::i64vec2 s0(2 * k.x * m_patch - 1, 2 * k.y * m_patch - 1);
  return m_terrain.samplesResident(k.level - 1, s0, s0 + glm::i64vec2(2 * m_patch + 2, 2 * m_patch + 2));
}

bool TerrainRendererImpl::NodeSelection::wantsSplit(const NodeKey& k, const NodeBox& b, double* projected_px) const {
  if (k.level == 0 || m_terrain.m_config.method == TerrainMethod::kFlat) return false;
  const double world_per_height = m_terrain.m_config.mapping.world_per_height;
  const double dist = b.distance();
  // The tiles' bound first: the node's is never above it (nor rounded to a
  // float), so where it asks for no split nodeError()'s exact pass (most
  // of a selection on a cold cache: a first frame, a teleport) is skipped.
  if (!m_terrain.m_exact_node_error && !m_reference && dist > 0.0 &&
      !(m_terrain.tileErrorBound(k.level, k.x, k.y) * (1.0 + 1e-6) * world_per_height * m_pixels / dist >
        m_terrain.m_config.error_px))
    return false;
  const double e = m_terrain.nodeError(k.level, k.x, k.y) * world_per_height;
  if (!(e > 0.0)) return false;
  *projected_px = dist > 0.0 ? e * m_pixels / dist : INFINITY;
  return dist <= 0.0 || e * m_pixels / dist > m_terrain.m_config.error_px;
}

TerrainRendererImpl::NodeSelection::Want TerrainRendererImpl::NodeSelection::evaluate(const NodeKey& k,
                                                                                       double* projected_px) const {
  const NodeBox b = m_terrain.nodeBox(m_camera, k.level, k.x, k.y);
  const bool v = m_terrain.nodeVisible(m_camera, b);
  m_visible.emplace(k, v);
  if (!v || !wantsSplit(k, b, projected_px)) return Want::kNo;
  return childrenResident(k) ? Want::kSplit : Want::kFallback;
}

void TerrainRendererImpl::NodeSelection::splitByError(uint64_t budget_triangles) {
  struct Candidate {
    double error_px;
    NodeKey key;
    bool operator<(const Candidate& o) const { return error_px < o.error_px; }
  };
  std::priority_queue<Candidate> candidates;
  int64_t drawn_nodes = 0;
  for (const NodeKey& r : m_roots) {
    double e = 0.0;
    const Want w = evaluate(r, &e);
    if (drawn(r)) ++drawn_nodes;
    if (w == Want::kFallback) ++m_root_fallbacks;
    if (w == Want::kSplit) candidates.push({e, r});
  }
  m_drawn_after.assign(1, drawn_nodes);
  const int64_t enough = budget_triangles > 0 ? 2 * int64_t(std::min<uint64_t>(budget_triangles, INT64_MAX / 4)) : -1;
  while (!candidates.empty() && (enough < 0 || splitTriangles(m_order.size()) <= enough)) {
    const Candidate c = candidates.top();
    candidates.pop();
    // The split draws its visible children (resident: it may split)
    // instead of itself (drawn unless a root whose heights are missing).
    Split split{c.key, c.error_px, 0};
    int64_t delta = c.key.level < m_root || drawn(c.key) ? -1 : 0;
    Candidate children[4];
    int wanting = 0;
    for (int i = 0; i < 4; ++i) {
      const NodeKey child = childOf(c.key, i);
      double e = 0.0;
      const Want w = evaluate(child, &e);
      if (visible(child)) ++delta;
      if (w == Want::kFallback) ++split.fallbacks;
      if (w == Want::kSplit) children[wanting++] = {std::min(e, c.error_px), child};
    }
    drawn_nodes += delta;
    m_split.insert(c.key);
    m_order.push_back(split);
    m_drawn_after.push_back(drawn_nodes);
    for (int i = 0; i < wanting; ++i) candidates.push(children[i]);
  }
}

uint32_t TerrainRendererImpl::NodeSelection::splitDepthFirst() {
  std::vector<NodeKey> stack = m_roots;
  uint32_t fallbacks = 0;
  while (!stack.empty()) {
    const NodeKey k = stack.back();
    stack.pop_back();
    const NodeBox b = m_terrain.nodeBox(m_camera, k.level, k.x, k.y);
    double e = 0.0;
    if (!m_terrain.nodeVisible(m_camera, b) || !wantsSplit(k, b, &e)) continue;
    if (!childrenResident(k)) {
      ++fallbacks;
      continue;
    }
    m_split.insert(k);
    for (int c = 0; c < 4; ++c) stack.push_back(childOf(k, c));
  }
  return fallbacks;
}

size_t TerrainRendererImpl::NodeSelection::splitsWithin(uint64_t budget_triangles) const {
  // The triangles drawn need not grow with every split (one whose children
  // are culled draws fewer), so the longest prefix that fits, not the
  // first that does not.
  size_t n = m_order.size();
  if (budget_triangles == 0) return n;
  while (n > 0 && splitTriangles(n) > int64_t(budget_triangles)) --n;
  return n;
}

void TerrainRendererImpl::NodeSelection::keepSplits(size_t count) {
  m_split.clear();
  for (size_t i = 0; i < count && i < m_order.size(); ++i) m_split.insert(m_order[i].key);
}

double TerrainRendererImpl::NodeSelection::boundWith(size_t count) const {
  const double error_px = m_terrain.m_config.error_px;
  const double next = count < m_order.size() ? m_order[count].error_px : error_px;
  // Above kMaxTerrainErrorPx (a node nearer than its error is high, or
  // with the camera in its box: infinite) the bound reported is that.
  return std::min(std::max(error_px, next), kMaxTerrainErrorPx);
}

uint32_t TerrainRendererImpl::NodeSelection::fallbacksWith(size_t count) const {
  uint32_t n = m_root_fallbacks;
  for (size_t i = 0; i < count && i < m_order.size(); ++i) n += m_order[i].fallbacks;
  return n;
}

bool TerrainRendererImpl::NodeSelection::inRoots(const NodeKey& k) const {
  NodeKey r = k;
  while (r.level < m_root) r = parentOf(r);
  return r.x >= m_rx0 && r.x <= m_rx1 && r.y >= m_ry0 && r.y <= m_ry1;
}

bool TerrainRendererImpl::NodeSelection::isLeaf(const NodeKey& k) const {
  if (m_split.count(k)) return false;
  return k.level == m_root ? inRoots(k) : m_split.count(parentOf(k)) > 0;
}

bool TerrainRendererImpl::NodeSelection::leafAt(uint32_t level, int64_t x, int64_t y, NodeKey* leaf) const {
  // The leaf holding the level-`level` square (x, y): its deepest ancestor
  // (or itself) that is not split, if a root holds it.
  NodeKey k{level, x, y};
  NodeKey chain[renderer_config::kMaxLevels + 1];
  size_t depth = 0;
  while (k.level < m_root) {
    chain[depth++] = k;
    k = parentOf(k);
  }
  if (k.x < m_rx0 || k.x > m_rx1 || k.y < m_ry0 || k.y > m_ry1) return false;
  // Walk down from the root while split.
  while (depth > 0 && m_split.count(k)) k = chain[--depth];
  if (m_split.count(k)) return false;  // finer than `level` there
  *leaf = k;
  return true;
}

bool TerrainRendererImpl::NodeSelection::coarserNeighbour(const NodeKey& l, int s, NodeKey* nb) const {
  return leafAt(l.level, l.x + kSideDx[s], l.y + kSideDy[s], nb) && nb->level > l.level + 1 && visible(*nb);
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
    for (int c = 0; c < 4; ++c) s.push_back(childOf(k, c));
  }
}

uint32_t TerrainRendererImpl::NodeSelection::restrictWithin(uint64_t budget_triangles, size_t* kept) {
  uint32_t forced = restrictNeighbours();
  const uint64_t drawn_triangles = leafTriangles();
  if (budget_triangles == 0 || drawn_triangles <= budget_triangles || *kept == 0) return forced;
  // The forced splits took the frame over the budget: the most of step 1's
  // splits whose restricted frame fits, between `lo` splits (fits; 0: the
  // roots alone) and `hi` (over), by false position on the triangles
  // drawn, every other step halving. Past kTerrainBudgetSearchSteps the
  // last that fitted stays (its bound a little above the lowest).
  size_t lo = 0, hi = *kept, restricted = hi;
  double drawn_lo = double(splitTriangles(0)), drawn_hi = double(drawn_triangles);
  for (uint32_t step = 0; step < renderer_config::kTerrainBudgetSearchSteps && hi - lo > 1; ++step) {
    const double share = (double(budget_triangles) - drawn_lo) / std::max(drawn_hi - drawn_lo, 1.0);
    size_t n = step % 2 ? lo + (hi - lo) / 2 : lo + size_t(std::max(share, 0.0) * double(hi - lo));
    n = std::clamp(n, lo + 1, hi - 1);
    keepSplits(n);
    forced = restrictNeighbours();
    restricted = n;
    const uint64_t drawn = leafTriangles();
    (drawn <= budget_triangles ? lo : hi) = n;
    (drawn <= budget_triangles ? drawn_lo : drawn_hi) = double(drawn);
  }
  if (restricted != lo) {
    keepSplits(lo);
    forced = restrictNeighbours();
  }
  *kept = lo;
  return forced;
}

TerrainRendererImpl::NodeSelection::Queued TerrainRendererImpl::NodeSelection::queued(const NodeKey& k) const {
  Queued q{0, 0, m_root - k.level, k};
  NodeKey a = k;
  for (uint32_t d = q.depth; d > 0; --d) {  // d: depth of `a` below the root
    const uint64_t c = uint64_t(a.x & 1) | (uint64_t(a.y & 1) << 1);
    q.path |= (3 - c) << (64 - 2 * d);
    a = parentOf(a);
  }
  const int64_t index = (a.y - m_ry0) * (m_rx1 - m_rx0 + 1) + (a.x - m_rx0);
  q.root = uint64_t(int64_t(m_roots.size()) - 1 - index);
  return q;
}

TerrainRendererImpl::NodeSelection::NodeKey TerrainRendererImpl::NodeSelection::coarsenBeside(
    const NodeKey& l, const NodeKey& nb, std::unordered_set<NodeKey, NodeIdHash>* frozen) {
  NodeKey a = l;
  while (a.level + 1 < nb.level) a = parentOf(a);
  frozen->insert(a);
  ++m_coarsened;
  // Split nodes form a tree: split descendants lie under split nodes.
  std::vector<NodeKey> s{a};
  while (!s.empty()) {
    const NodeKey k = s.back();
    s.pop_back();
    if (m_split.erase(k))
      for (int c = 0; c < 4; ++c) s.push_back(childOf(k, c));
  }
  return a;
}

void TerrainRendererImpl::NodeSelection::pushLeavesAround(const NodeKey& a, Worklist* work) const {
  // Each side's square of a's size, and where it is split, its children
  // along the side facing a (top: its bottom two; right: its left two...).
  static constexpr int kFacing[4][2] = {{2, 3}, {0, 2}, {0, 1}, {1, 3}};
  for (int s = 0; s < 4; ++s) {
    const NodeKey square{a.level, a.x + kSideDx[s], a.y + kSideDy[s]};
    NodeKey leaf;
    if (leafAt(square.level, square.x, square.y, &leaf)) {
      work->push(queued(leaf));
      continue;
    }
    if (!inRoots(square)) continue;
    std::vector<NodeKey> split{square};
    while (!split.empty()) {
      const NodeKey k = split.back();
      split.pop_back();
      for (int c : kFacing[s]) {
        const NodeKey child = childOf(k, c);
        if (m_split.count(child))
          split.push_back(child);
        else
          work->push(queued(child));
      }
    }
  }
}

uint32_t TerrainRendererImpl::NodeSelection::restrictNeighbours() {
  // A coarser neighbour is split; one that cannot be (its children not
  // resident, or frozen) instead coarsens the finer side: the leaf's
  // ancestor one level finer than the neighbour becomes a leaf, frozen
  // (never split again this frame, so this ends). The worklist holds every
  // leaf that may need mending: all at first; then a split's children and
  // the leaf that asked (it may need more), or the coarsened node and the
  // leaves around it (their neighbour grew coarser). A split never makes a
  // leaf outside it need mending (its neighbours only grow finer). Popped
  // in collectLeaves()' order, the mends are those of a full scan of the
  // leaves after each one (restrictNeighboursByRescan(), the reference).
  std::unordered_set<NodeKey, NodeIdHash> frozen;
  m_coarsened = 0;
  uint32_t forced = 0;
  collectLeaves();
  std::vector<Queued> first;
  first.reserve(m_leaves.size());
  for (const NodeKey& l : m_leaves)
    if (visible(l)) first.push_back(queued(l));
  Worklist work(std::greater<Queued>(), std::move(first));
  while (!work.empty()) {
    const NodeKey l = work.top().key;
    work.pop();
    if (!isLeaf(l) || !visible(l)) continue;
    NodeKey nb;
    int side = 0;
    while (side < 4 && !coarserNeighbour(l, side, &nb)) ++side;
    if (side == 4) continue;
    if (!frozen.count(nb) && childrenResident(nb)) {
      m_split.insert(nb);
      ++forced;
      for (int c = 0; c < 4; ++c) work.push(queued(childOf(nb, c)));
      work.push(queued(l));
    } else {
      const NodeKey a = coarsenBeside(l, nb, &frozen);
      work.push(queued(a));
      pushLeavesAround(a, &work);
    }
  }
  collectLeaves();
  return forced;
}

uint32_t TerrainRendererImpl::NodeSelection::restrictNeighboursByRescan() {
  // The restriction restrictNeighbours() replaced: after each
  // mend, every leaf is scanned again from the first. Kept as the reference
  // of the tests and the selection benchmark (setReferenceSelection()).
  std::unordered_set<NodeKey, NodeIdHash> frozen;
  m_coarsened = 0;
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
          coarsenBeside(l, nb, &frozen);
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

uint64_t TerrainRendererImpl::NodeSelection::leafTriangles() const {
  uint64_t n = 0;
  for (const NodeKey& l : m_leaves) n += drawn(l) ? 1 : 0;
  return n * uint64_t(2 * m_patch * m_patch);
}

void TerrainRendererImpl::NodeSelection::leaves(std::vector<TerrainNode>* out) const {
  for (const NodeKey& l : m_leaves) {
    TerrainNode node;
    node.level = l.level;
    node.x = l.x;
    node.y = l.y;
    node.drawn = drawn(l);
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

void TerrainRendererImpl::selectNodes(const Camera& camera, const Viewport& viewport) {
  const auto start = std::chrono::steady_clock::now();
  m_nodes.clear();
  m_frustum_cache = frustum(camera, viewport);
  NodeSelection selection(*this, camera, viewport);
  size_t kept = 0;
  if (m_reference_selection) {
    m_frame.fallback_nodes = selection.splitDepthFirst();
    m_frame.forced_splits = selection.restrictNeighboursByRescan();
  } else {
    // Measuring with exact node errors: no budget, and unrestricted (no
    // stitching).
    const uint64_t budget = m_exact_node_error ? 0 : m_config.triangle_budget;
    selection.splitByError(budget);
    kept = selection.splitsWithin(budget);
    if (kept < selection.splitCount()) selection.keepSplits(kept);
    m_frame.forced_splits = m_exact_node_error ? selection.unrestricted() : selection.restrictWithin(budget, &kept);
    m_frame.fallback_nodes = selection.fallbacksWith(kept);
  }
  selection.leaves(&m_nodes);
  m_frame.coarsened_nodes = selection.coarsened();
  // The flat method selects its roots here too; it has no bound to meet.
  m_frame.achieved_error_px = m_config.method == TerrainMethod::kQuadtree ? selection.boundWith(kept) : 0.0;
  m_frame.select_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
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
  // One instanced draw per edge pattern (a draw call per node cost llvmpipe
  // as much as its triangles at 8-cell nodes): the nodes' origins sorted by
  // pattern, each pattern's a run of instances, nearest first.
  std::array<std::vector<std::pair<double, TerrainGridOrigin>>,
             std::tuple_size<terrain_mesh::PatchMesh::Masks>::value>
      by_mask;
  for (const TerrainNode& node : m_nodes) {
    if (!node.drawn) continue;
    // Its samples and their normals' (no transition band here).
    noteHeightReads(node.level, glm::i64vec2(node.x, node.y) * cells - int64_t(1),
                    glm::i64vec2(node.x + 1, node.y + 1) * cells + int64_t(1));
    by_mask[node.coarse_sides].emplace_back(nodeBox(camera, node.level, node.x, node.y).distance(),
                                            gridOrigin(camera, node.level, {node.x * cells, node.y * cells}));
    m_frame.triangles += m_patch_masks[node.coarse_sides].count / 3;
    ++m_frame.nodes;
    ++m_frame.blocks;
    levels.insert(node.level);
    finest = std::min(finest, node.level);
    coarsest = std::max(coarsest, node.level);
  }
  std::vector<TerrainGridOrigin> origins;
  origins.reserve(m_frame.nodes);
  for (auto& v : by_mask) {
    std::sort(v.begin(), v.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [distance, origin] : v) origins.push_back(origin);
  }
  if (!origins.empty()) m_patch_mesh->setInstances(origins);
  GLuint first = 0;
  for (size_t mask = 0; mask < by_mask.size(); ++mask) {
    const GLsizei count = GLsizei(by_mask[mask].size());
    if (count == 0) continue;
    const terrain_mesh::IndexRange range = m_patch_masks[mask];
    glDrawElementsInstancedBaseInstance(GL_TRIANGLES, GLsizei(range.count), GL_UNSIGNED_INT,
                                        reinterpret_cast<const void*>(uintptr_t(range.first) * sizeof(uint32_t)),
                                        count, first);
    first += GLuint(count);
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
