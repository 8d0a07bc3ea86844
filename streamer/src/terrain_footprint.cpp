// The ground a view sees over terrain, from per-tile height bounds. See
// footprint.h; docs/terrain.md, "Planning against the terrain".
//
// A tile of the bounds is a box: its x/z extent (from its first sample's
// centre to its +x+z neighbour's first sample's centre; tiles on the
// terrain's edge reach on without end, since the ground beyond the samples
// takes the edge heights) times its height range. Two questions are asked
// of the boxes, coarse to fine (a parent box holds its children):
//  - how near is the nearest one in the frustum: best-first search on a
//    lower bound of the distance, refining a box while it is large for
//    that distance, so the bound is close where it matters;
//  - what does each ray of a grid over the screen see: the ray may touch
//    the ground from the first box whose top it is under, and is surely
//    under the ground (so it hit before) at the first box whose bottom it
//    is under. Between those two points lies what it shows; nothing behind
//    counts, which is how a slope in front hides the ground behind it.
#include "footprint.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <unordered_map>

namespace clipstream {
namespace {

// Rays on a (kRayGrid + 1)^2 grid over the screen, borders and corners
// included (the flat planner's 8 border samples a side are among them). 8
// puts a ray every 160 pixels of a 1280-pixel screen: ground seen only
// between rays is missed by the footprint (a bounding box, which other
// rays mostly widen over it anyway), not by the nearest distance, which
// the boxes give. 16 cost about twice as much a plan.
constexpr int kRayGrid = 8;
// A box is refined while its side exceeds this fraction of its distance
// from the camera: the nearest distance is then within about a quarter of
// the truth (under half a level), and a ray's stop point within a quarter
// of its length behind the slope that stopped it.
constexpr double kRefineRatio = 0.25;
constexpr double kInf = std::numeric_limits<double>::infinity();

struct Box {
  glm::dvec3 lo, hi;
};

class Terrain {
 public:
  Terrain(const TerrainView& view, glm::dvec3 eye, double far_h)
      : m_view(view), m_b(*view.bounds), m_detail(view.detail.get()), m_eye(eye), m_far_h(far_h) {}

  int coarsest() const { return int(m_b.levels.size()) - 1; }

  // Tiles of `level` a side (x or z). Levels below 0 are a tile's detail
  // cells: level -k has tiles of tile_px / 2^k samples.
  int64_t tiles(int level, bool z) const {
    const uint64_t w = z ? m_b.height_samples : m_b.width_samples;
    if (level >= 0) return int64_t(((w - 1) >> level) / m_b.tile_px + 1);
    return int64_t(((w << -level) - 1) / m_b.tile_px + 1);
  }

  // Side of a tile of `level` in planning units (the larger of x and z).
  double side(int level) const {
    const double span = std::ldexp(double(m_b.tile_px), level);
    return span * std::max(m_view.units_per_sample.x, m_view.units_per_sample.y);
  }

  // The tile's box: x/z from its first sample's centre to the first
  // sample's centre of its +x+z neighbour, heights from its range and its
  // +x, +z and +x+z neighbours' (the surface between two tiles is made of
  // both); edge tiles reach on without end in x and z.
  Box box(int level, int64_t tx, int64_t ty) const {
    Box b = extent(level, tx, ty);
    // Rays pass the same boxes near the camera again and again: each
    // box's heights are worked out once per footprint.
    const uint64_t key = (uint64_t(level + 64) << 56) ^ (uint64_t(ty) << 28) ^ uint64_t(tx);
    auto [it, fresh] = m_heights.try_emplace(key);
    if (fresh) {
      const int64_t nx = tiles(level, false), ny = tiles(level, true);
      glm::vec2 r = rangeAt(level, tx, ty);
      for (int dy = 0; dy < 2; ++dy)
        for (int dx = 0; dx < 2; ++dx) {
          if ((dx == 0 && dy == 0) || tx + dx >= nx || ty + dy >= ny) continue;
          const glm::vec2 n = rangeAt(level, tx + dx, ty + dy);
          r = {std::min(r.x, n.x), std::max(r.y, n.y)};
        }
      it->second = r;
    }
    b.lo.y = double(it->second.x) * m_view.units_per_height;
    b.hi.y = double(it->second.y) * m_view.units_per_height;
    return b;
  }

  // The box's x/z extent alone (heights 0).
  Box extent(int level, int64_t tx, int64_t ty) const {
    const double span = std::ldexp(double(m_b.tile_px), level);
    const glm::dvec2 o = m_view.sample_origin, u = m_view.units_per_sample;
    Box b{};
    b.lo.x = tx == 0 ? -kInf : o.x + double(tx) * span * u.x;
    b.hi.x = tx + 1 >= tiles(level, false) ? kInf : o.x + double(tx + 1) * span * u.x;
    b.lo.z = ty == 0 ? -kInf : o.y + double(ty) * span * u.y;
    b.hi.z = ty + 1 >= tiles(level, true) ? kInf : o.y + double(ty + 1) * span * u.y;
    return b;
  }

  // The box cut to the square of half-side far_h around the camera's
  // nadir (the planner's far limit); false when nothing is left.
  bool clipped(Box* b) const {
    b->lo.x = std::max(b->lo.x, m_eye.x - m_far_h);
    b->hi.x = std::min(b->hi.x, m_eye.x + m_far_h);
    b->lo.z = std::max(b->lo.z, m_eye.z - m_far_h);
    b->hi.z = std::min(b->hi.z, m_eye.z + m_far_h);
    return b->lo.x <= b->hi.x && b->lo.z <= b->hi.z;
  }

  // Whether refining a tile of `level` can tell more: its children have
  // bounds of their own (index bounds, or some tile's detail).
  bool refinable(int level, int64_t tx, int64_t ty) const {
    if (level - 1 >= int(m_b.finest_level)) return true;
    if (!m_detail) return false;
    bool any = false;
    children(level, tx, ty, [&](int l, int64_t x, int64_t y) {
      glm::vec2 r;
      any = any || own(l, x, y, &r);
    });
    return any;
  }

  // Calls f(level - 1, x, y) for each child of a tile of `level`.
  template <typename F>
  void children(int level, int64_t tx, int64_t ty, F&& f) const {
    const int64_t nx = tiles(level - 1, false), ny = tiles(level - 1, true);
    for (int64_t y = 2 * ty; y < std::min(2 * ty + 2, ny); ++y)
      for (int64_t x = 2 * tx; x < std::min(2 * tx + 2, nx); ++x) f(level - 1, x, y);
  }

 private:
  // What is known of tile (level, tx, ty)'s heights, false when nothing
  // is at this level: on a level with bounds, its index range (the ground's
  // exact bounds; a coarser tile's cells, its samples widened by its error,
  // are seldom tighter); below, the cell of the finest read tile whose
  // detail has this tile as a cell (a finer tile's samples carry less
  // error).
  bool own(int level, int64_t tx, int64_t ty, glm::vec2* out) const {
    if (level >= int(m_b.finest_level)) {
      const TerrainBounds::Level& lv = m_b.levels[size_t(level)];
      *out = lv.range[size_t(ty) * lv.tiles_x + size_t(tx)];
      return true;
    }
    if (!m_detail) return false;
    for (int tl = std::max(level, 0); tl <= std::min(level + int(kTileDetailLog2), coarsest()); ++tl) {
      const int j = tl - level;  // detail cells 2^j a side
      const TileKey key{uint32_t(tl), uint32_t(tx >> j), uint32_t(ty >> j)};
      const auto it = m_detail->tiles.find(key);
      if (it == m_detail->tiles.end() || uint32_t(j) > it->second->log2) continue;
      const int64_t cx = tx - (int64_t(key.x) << j), cy = ty - (int64_t(key.y) << j);
      *out = it->second->cells[j][size_t(cy << j) + size_t(cx)];
      return true;
    }
    return false;
  }

  // own() of the tile, or of its nearest ancestor that has a range.
  glm::vec2 rangeAt(int level, int64_t tx, int64_t ty) const {
    glm::vec2 r;
    while (!own(level, tx, ty, &r)) {
      ++level;
      tx >>= 1;
      ty >>= 1;
    }
    return r;
  }

  const TerrainView& m_view;
  const TerrainBounds& m_b;
  const TerrainDetail* m_detail;
  glm::dvec3 m_eye;
  double m_far_h;
  // box() heights by tile (level + 64 in the top byte; x and y below
  // 2^28 tiles, which a 2^31-sample terrain's detail cells stay under).
  mutable std::unordered_map<uint64_t, glm::vec2> m_heights;
};

// The view's four side planes (through the eye, normals inward) and the
// sines of its steepest downward and upward rays (0: none).
struct Frustum {
  glm::dvec3 eye;
  glm::dvec3 normals[4];
  double sin_down = 0.0, sin_up = 0.0;

  // Conservative: false only when the box is wholly outside one plane.
  bool touches(const Box& b) const {
    for (const glm::dvec3& n : normals) {
      const glm::dvec3 p{n.x > 0 ? b.hi.x : b.lo.x, n.y > 0 ? b.hi.y : b.lo.y, n.z > 0 ? b.hi.z : b.lo.z};
      if (glm::dot(n, p - eye) < 0.0) return false;
    }
    return true;
  }

  // A lower bound of the distance from the eye to any point of the box a
  // ray of the view can reach: the distance to the box, and, for a box
  // wholly below (above) the eye, its height difference over the sine of
  // the steepest ray down (up). Infinite when no ray can reach it.
  double lowerBound(const Box& b) const {
    const glm::dvec3 out = glm::max(b.lo - eye, glm::dvec3(0.0)) + glm::max(eye - b.hi, glm::dvec3(0.0));
    double d = glm::length(out);
    if (b.hi.y < eye.y) d = sin_down > 0.0 ? std::max(d, (eye.y - b.hi.y) / sin_down) : kInf;
    if (b.lo.y > eye.y) d = sin_up > 0.0 ? std::max(d, (b.lo.y - eye.y) / sin_up) : kInf;
    return d;
  }
};

glm::dvec3 rayDirection(const Camera& camera, const Viewport& viewport, double px, double py) {
  const double w = viewport.width_px, h = viewport.height_px;
  const double aspect = w / (h > 0 ? h : 1.0);
  const double tan_half = std::tan(camera.vfov_rad * 0.5);
  return camera.forward() + camera.right() * ((2.0 * px / w - 1.0) * tan_half * aspect) +
         camera.up() * ((1.0 - 2.0 * py / h) * tan_half);
}

Frustum makeFrustum(const Camera& camera, const Viewport& viewport) {
  Frustum f;
  f.eye = camera.position;
  const double w = viewport.width_px, h = viewport.height_px;
  const glm::dvec3 c[4] = {rayDirection(camera, viewport, 0, 0), rayDirection(camera, viewport, w, 0),
                           rayDirection(camera, viewport, w, h), rayDirection(camera, viewport, 0, h)};
  const glm::dvec3 fwd = camera.forward();
  for (int i = 0; i < 4; ++i) {
    glm::dvec3 n = glm::cross(c[i], c[(i + 1) % 4]);
    if (glm::dot(n, fwd) < 0.0) n = -n;
    f.normals[i] = n;
  }
  // No roll: the steepest rays are the middle of the bottom and top edges.
  const double pi_2 = 1.5707963267948966;
  const double down = camera.pitch_rad - 0.5 * camera.vfov_rad;
  const double up = camera.pitch_rad + 0.5 * camera.vfov_rad;
  f.sin_down = down < 0.0 ? std::sin(std::min(-down, pi_2)) : 0.0;
  f.sin_up = up > 0.0 ? std::sin(std::min(up, pi_2)) : 0.0;
  return f;
}

// Best-first search for the nearest box in the frustum (see the file's
// comment). Returns the distance, or infinity when no box is in view;
// *nearest receives that box (clipped to the far limit).
double nearestBox(const Terrain& t, const Frustum& f, Box* nearest) {
  struct Node {
    double d;
    bool leaf;
    int level;
    int64_t x, y;
    Box box;
    bool operator>(const Node& o) const { return d > o.d; }
  };
  std::priority_queue<Node, std::vector<Node>, std::greater<Node>> open;
  auto push = [&](int level, int64_t x, int64_t y) {
    Box b = t.box(level, x, y);
    if (!t.clipped(&b) || !f.touches(b)) return;
    const double d = f.lowerBound(b);
    if (!std::isfinite(d)) return;
    const double side = std::max(b.hi.x - b.lo.x, b.hi.z - b.lo.z);
    const bool leaf = side <= kRefineRatio * d || !t.refinable(level, x, y);
    open.push({d, leaf, level, x, y, b});
  };
  const int top = t.coarsest();
  for (int64_t y = 0; y < t.tiles(top, true); ++y)
    for (int64_t x = 0; x < t.tiles(top, false); ++x) push(top, x, y);
  while (!open.empty()) {
    const Node n = open.top();
    open.pop();
    if (n.leaf) {
      *nearest = n.box;
      return n.d;
    }
    t.children(n.level, n.x, n.y, push);
  }
  return kInf;
}

// One ray's walk through the boxes, front to back.
struct RayWalk {
  glm::dvec3 o, d;      // origin and direction (not unit)
  double len = 1.0;     // |d|
  bool ghost = false;   // keep going past the first sure hit (see terrainFootprint)
  double enter = kInf;  // first t where the ray may touch the ground
  double last = -kInf;  // last t where it may (before a sure hit)
  bool hit = false;     // it is surely under the ground at `last`
};

// The parameter interval [*ta, *tb] cut to the box's x/z extent.
bool clipToExtent(const RayWalk& r, const Box& b, double* ta, double* tb) {
  for (int axis : {0, 2}) {
    const double o = r.o[axis], d = r.d[axis], lo = b.lo[axis], hi = b.hi[axis];
    if (d == 0.0) {
      if (o < lo || o > hi) return false;
      continue;
    }
    double t0 = (lo - o) / d, t1 = (hi - o) / d;
    if (t0 > t1) std::swap(t0, t1);
    *ta = std::max(*ta, t0);
    *tb = std::min(*tb, t1);
  }
  return *ta <= *tb;
}

void walk(const Terrain& t, int level, int64_t tx, int64_t ty, double ta, double tb, RayWalk* r) {
  if (r->hit) return;
  const Box b = t.box(level, tx, ty);
  const double ya = r->o.y + r->d.y * ta, yb = r->o.y + r->d.y * tb;
  if (std::min(ya, yb) > b.hi.y) return;  // above this ground
  // The t where the ray's height is y (the ray is not level here).
  auto at = [&](double y) { return std::clamp(ta + (y - ya) / r->d.y, ta, tb); };
  if (std::max(ya, yb) <= b.lo.y) {  // wholly under it: a sure hit at ta
    r->enter = std::min(r->enter, ta);
    if (r->ghost) {
      r->last = std::max(r->last, tb);
    } else {
      r->last = std::max(r->last, ta);
      r->hit = true;
    }
    return;
  }
  if (t.side(level) > kRefineRatio * ta * r->len && t.refinable(level, tx, ty)) {
    struct Part {
      double ta, tb;
      int64_t x, y;
    };
    Part parts[4];
    int n = 0;
    t.children(level, tx, ty, [&](int, int64_t x, int64_t y) {
      double a = ta, c = tb;
      if (clipToExtent(*r, t.extent(level - 1, x, y), &a, &c)) parts[n++] = {a, c, x, y};
    });
    // At most four: insertion sort by entry.
    for (int i = 1; i < n; ++i)
      for (int j = i; j > 0 && parts[j].ta < parts[j - 1].ta; --j) std::swap(parts[j], parts[j - 1]);
    for (int i = 0; i < n && !r->hit; ++i) walk(t, level - 1, parts[i].x, parts[i].y, parts[i].ta, parts[i].tb, r);
    return;
  }
  // A leaf: the ray may touch the ground where it is under the box's top,
  // and is surely under it where it is under the box's bottom.
  r->enter = std::min(r->enter, ya <= b.hi.y ? ta : at(b.hi.y));
  if (!r->ghost && std::min(ya, yb) <= b.lo.y) {
    r->last = std::max(r->last, ya <= b.lo.y ? ta : at(b.lo.y));
    r->hit = true;
    return;
  }
  r->last = std::max(r->last, yb <= b.hi.y ? tb : at(b.hi.y));
}

// Walks the ray from the eye to the far limit, through the coarsest
// level's tiles in the order it meets them.
void walkRay(const Terrain& t, double t_far, RayWalk* r) {
  const int top = t.coarsest();
  struct Part {
    double ta, tb;
    int64_t x, y;
  };
  std::vector<Part> parts;
  for (int64_t y = 0; y < t.tiles(top, true); ++y)
    for (int64_t x = 0; x < t.tiles(top, false); ++x) {
      double ta = 0.0, tb = t_far;
      if (clipToExtent(*r, t.extent(top, x, y), &ta, &tb)) parts.push_back({ta, tb, x, y});
    }
  std::sort(parts.begin(), parts.end(), [](const Part& p, const Part& q) { return p.ta < q.ta; });
  for (size_t i = 0; i < parts.size() && !r->hit; ++i)
    walk(t, top, parts[i].x, parts[i].y, parts[i].ta, parts[i].tb, r);
}

}  // namespace

Footprint terrainFootprint(const TerrainView& view, const Viewport& viewport, const Camera& camera,
                           double far_h) {
  Footprint fp;
  if (!view.bounds || view.bounds->levels.empty() || viewport.width_px == 0 || viewport.height_px == 0)
    return fp;
  const Terrain t(view, camera.position, far_h);
  const Frustum f = makeFrustum(camera, viewport);
  Box nearest{};
  const double nearest_dist = nearestBox(t, f, &nearest);

  // The ray grid, bottom row first in each column.
  constexpr int n = kRayGrid + 1;
  const double w = viewport.width_px, h = viewport.height_px;
  auto makeRay = [&](int i, int j) {
    RayWalk r;
    r.o = camera.position;
    r.d = rayDirection(camera, viewport, w * i / kRayGrid, h - h * j / kRayGrid);
    r.len = glm::length(r.d);
    return r;
  };
  auto farT = [&](const RayWalk& r) {
    return far_h / std::max(glm::length(glm::dvec2(r.d.x, r.d.z)), 1e-12);
  };
  auto point = [&](const RayWalk& r, double s) {
    fp.points.push_back({r.o.x + r.d.x * s, r.o.z + r.d.z * s});
  };
  for (int i = 0; i < n; ++i) {
    bool below_hit = false;  // the ray below this one surely hit
    RayWalk below;
    for (int j = 0; j < n; ++j) {
      RayWalk r = makeRay(i, j);
      const double t_far = farT(r);
      walkRay(t, t_far, &r);
      if (r.enter <= t_far) {
        point(r, r.enter);
        point(r, std::min(r.last, t_far));
      } else if (r.d.y < 0.0) {
        // Going down but past the far limit: the rays just under it meet
        // the ground up to the far limit along its direction (as on the
        // flat plane).
        point(r, t_far);
      } else if (below_hit) {
        // Sky above a ray that hit: the rays between the two pass over
        // what the lower one hit and may see ground behind it. They are
        // no lower than the lower ray continued, so that ray walked on
        // past its hit (a ghost) bounds what they can reach.
        below.ghost = true;
        below.hit = false;
        walkRay(t, farT(below), &below);
        if (below.enter <= farT(below)) point(below, std::min(below.last, farT(below)));
      }
      below_hit = r.hit;
      below = makeRay(i, j);
    }
  }
  fp.any_hit = !fp.points.empty() || std::isfinite(nearest_dist);
  if (!fp.any_hit) return fp;
  if (fp.points.empty()) {
    // In view between the rays only: the nearest box stands for it.
    fp.points.push_back({nearest.lo.x, nearest.lo.z});
    fp.points.push_back({nearest.hi.x, nearest.hi.z});
  }
  if (std::isfinite(nearest_dist)) {
    fp.nearest_dist = nearest_dist;
  } else {
    // Rays met boxes the frustum test did not: take the nearest entry.
    fp.nearest_dist = kInf;
    for (const glm::dvec2& p : fp.points)
      fp.nearest_dist = std::min(fp.nearest_dist, glm::length(glm::dvec3(p.x, 0.0, p.y) -
                                                              glm::dvec3(camera.position.x, 0.0, camera.position.z)));
  }
  return fp;
}

}  // namespace clipstream
