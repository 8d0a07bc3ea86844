#include <clipstream/eval/terrain_accuracy.h>
#include <clipstream/renderer/testing/terrain_measure.h>

#include <clipstream/eval/metrics.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

namespace clipstream {

Status ReferenceSurface::load(TileSource& heights, const LayerAlignment& alignment,
                              std::unique_ptr<ReferenceSurface>* out) {
  out->reset();
  if (heights.content() != TileContent::kHeightF32) {
    return Status::error(ErrorCode::kInvalidArgument, "reference surface: not a height source");
  }
  const PyramidGeometry& g = heights.geometry();
  if (g.levelCount() == 0 || g.width_px * g.height_px > kMaxReferenceSamples) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "reference surface: " + std::to_string(g.width_px) + "x" +
                             std::to_string(g.height_px) + " samples is more than the " +
                             std::to_string(kMaxReferenceSamples) + " measured in memory");
  }
  std::unique_ptr<ReferenceSurface> s(new ReferenceSurface());
  s->m_width = g.width_px;
  s->m_height = g.height_px;
  s->m_alignment = alignment;
  s->m_samples.resize(g.width_px * g.height_px);
  const LevelInfo& level = g.levels[0];
  const uint32_t t = g.tile_px;
  std::vector<uint8_t> bytes;
  for (uint32_t ty = 0; ty < level.tiles_y; ++ty)
    for (uint32_t tx = 0; tx < level.tiles_x; ++tx) {
      if (Status st = heights.fetch(TileKey{0, tx, ty}, &bytes); !st) return st;
      if (bytes.size() != size_t(t) * t * sizeof(float)) {
        return Status::error(ErrorCode::kCorruptTile, "reference surface: a tile of the wrong size");
      }
      for (uint32_t y = 0; y < t && uint64_t(ty) * t + y < g.height_px; ++y) {
        const uint64_t gy = uint64_t(ty) * t + y;
        const uint32_t w = uint32_t(std::min<uint64_t>(t, g.width_px - uint64_t(tx) * t));
        std::memcpy(s->m_samples.data() + gy * g.width_px + uint64_t(tx) * t,
                    bytes.data() + size_t(y) * t * sizeof(float), size_t(w) * sizeof(float));
      }
    }
  *out = std::move(s);
  return okStatus();
}

double ReferenceSurface::heightAt(double x, double z) const {
  const LayerAlignment& a = m_alignment;
  const double fx = std::clamp((x - a.sample0_world.x) / a.world_per_sample.x, 0.0, double(m_width - 1));
  const double fz = std::clamp((z - a.sample0_world.y) / a.world_per_sample.y, 0.0, double(m_height - 1));
  const uint64_t i0 = uint64_t(fx), j0 = uint64_t(fz);
  const uint64_t i1 = std::min(i0 + 1, m_width - 1), j1 = std::min(j0 + 1, m_height - 1);
  auto at = [&](uint64_t i, uint64_t j) { return double(m_samples[j * m_width + i]); };
  const double u = fx - double(i0), v = fz - double(j0);
  const double h00 = at(i0, j0), h10 = at(i1, j0), h01 = at(i0, j1), h11 = at(i1, j1);
  const double h = u >= v ? h00 + u * (h10 - h00) + v * (h11 - h10) : h00 + v * (h01 - h00) + u * (h11 - h01);
  return h * a.world_per_height;
}

namespace {

// Squared distance (pixels) from every pixel to the nearest pixel where
// `feature` is set (Felzenszwalb & Huttenlocher's exact transform: a lower
// envelope of parabolas per column, then per row); kNone where there is no
// feature at all.
constexpr double kNone = 1e30;
std::vector<double> squaredDistanceTo(const std::vector<uint8_t>& feature, uint32_t w, uint32_t h) {
  std::vector<double> d(feature.size());
  for (size_t p = 0; p < feature.size(); ++p) d[p] = feature[p] ? 0.0 : kNone;
  const uint32_t n_max = std::max(w, h);
  std::vector<double> f(n_max), out(n_max), z(n_max + 1);
  std::vector<uint32_t> v(n_max);
  auto pass = [&](uint32_t n) {  // f[0..n) -> out[0..n)
    uint32_t first = 0;
    while (first < n && f[first] >= kNone) ++first;
    if (first == n) {
      std::fill(out.begin(), out.begin() + n, kNone);
      return;
    }
    uint32_t k = 0;
    v[0] = first;
    z[0] = -kNone;
    z[1] = kNone;
    auto meet = [&](uint32_t q, uint32_t r) {  // where parabolas q and r cross
      return ((f[q] + double(q) * q) - (f[r] + double(r) * r)) / (2.0 * (double(q) - double(r)));
    };
    for (uint32_t q = first + 1; q < n; ++q) {
      if (f[q] >= kNone) continue;
      double s = meet(q, v[k]);
      while (s <= z[k]) s = meet(q, v[--k]);  // z[0] = -kNone ends it
      ++k;
      v[k] = q;
      z[k] = s;
      z[k + 1] = kNone;
    }
    k = 0;
    for (uint32_t q = 0; q < n; ++q) {
      while (z[k + 1] < double(q)) ++k;
      const double dq = double(q) - v[k];
      out[q] = dq * dq + f[v[k]];
    }
  };
  for (uint32_t x = 0; x < w; ++x) {
    for (uint32_t y = 0; y < h; ++y) f[y] = d[size_t(y) * w + x];
    pass(h);
    for (uint32_t y = 0; y < h; ++y) d[size_t(y) * w + x] = out[y];
  }
  for (uint32_t y = 0; y < h; ++y) {
    std::copy_n(d.begin() + size_t(y) * w, w, f.begin());
    pass(w);
    std::copy_n(out.begin(), w, d.begin() + size_t(y) * w);
  }
  return d;
}

// Pixels showing terrain (w >= 1) in a position buffer.
std::vector<uint8_t> terrainMask(const std::vector<float>& xyzw, size_t pixels) {
  std::vector<uint8_t> m(pixels);
  for (size_t p = 0; p < pixels; ++p) m[p] = xyzw[p * 4 + 3] >= 1.0f;
  return m;
}

// Terrain pixels with a 4-neighbour inside the viewport that is not terrain.
std::vector<uint8_t> outline(const std::vector<uint8_t>& terrain, uint32_t w, uint32_t h) {
  std::vector<uint8_t> o(terrain.size(), 0);
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) {
      const size_t p = size_t(y) * w + x;
      if (!terrain[p]) continue;
      o[p] = (x > 0 && !terrain[p - 1]) || (x + 1 < w && !terrain[p + 1]) || (y > 0 && !terrain[p - w]) ||
             (y + 1 < h && !terrain[p + w]);
    }
  return o;
}

double farPx(const Viewport& viewport) { return std::hypot(double(viewport.width_px), double(viewport.height_px)); }

// The silhouette figure: each frame's outline pixels against the other's outline.
void measureSilhouette(const std::vector<uint8_t>& ours, const std::vector<uint8_t>& theirs,
                       const Viewport& viewport, GeometryError* e) {
  const uint32_t w = viewport.width_px, h = viewport.height_px;
  const std::vector<uint8_t> a = outline(ours, w, h), b = outline(theirs, w, h);
  const std::vector<double> to_a = squaredDistanceTo(a, w, h), to_b = squaredDistanceTo(b, w, h);
  std::vector<double> d;
  for (size_t p = 0; p < a.size(); ++p) {
    if (a[p]) d.push_back(to_b[p] >= kNone ? farPx(viewport) : std::sqrt(to_b[p]));
    if (b[p]) d.push_back(to_a[p] >= kNone ? farPx(viewport) : std::sqrt(to_a[p]));
  }
  e->silhouette_pixels = uint32_t(d.size());
  if (d.empty()) return;
  double sum = 0.0;
  for (double v : d) {
    sum += v;
    e->silhouette_max_px = std::max(e->silhouette_max_px, v);
  }
  e->silhouette_mean_px = sum / double(d.size());
  e->silhouette_p95_px = percentileOf(std::move(d), 0.95);
}

}  // namespace

GeometryError geometricError(const std::vector<float>& xyzw, const Camera& camera, const Viewport& viewport,
                             const ReferenceSurface& surface, const std::vector<float>* reference_xyzw,
                             std::vector<glm::vec2>* displacement) {
  GeometryError e;
  const size_t pixels = size_t(viewport.width_px) * viewport.height_px;
  if (displacement) displacement->assign(xyzw.size() >= pixels * 4 ? pixels : 0, glm::vec2(NAN));
  if (xyzw.size() < pixels * 4) return e;
  const bool coverage = reference_xyzw && reference_xyzw->size() >= pixels * 4;
  std::vector<uint8_t> ours, theirs;
  std::vector<double> to_ours, to_theirs;
  if (coverage) {
    ours = terrainMask(xyzw, pixels);
    theirs = terrainMask(*reference_xyzw, pixels);
    to_ours = squaredDistanceTo(ours, viewport.width_px, viewport.height_px);
    to_theirs = squaredDistanceTo(theirs, viewport.width_px, viewport.height_px);
  }
  auto coverageError = [&](const std::vector<double>& to_other, size_t p) {
    return to_other[p] >= kNone ? farPx(viewport) : std::sqrt(to_other[p]);
  };
  const glm::dmat4 vp = cameraProjection(camera, viewport, 1e9) * cameraRelativeView(camera);
  std::vector<double> errors;
  errors.reserve(pixels / 2);
  for (uint32_t py = 0; py < viewport.height_px; ++py)
    for (uint32_t px = 0; px < viewport.width_px; ++px) {
      const size_t i = size_t(py) * viewport.width_px + px;
      const float* p = xyzw.data() + i * 4;
      if (p[3] < 1.0f) {
        if (coverage && theirs[i]) {  // terrain in the reference only
          errors.push_back(coverageError(to_ours, i));
          ++e.coverage_pixels;
        }
        continue;
      }
      const double wx = camera.position.x + double(p[0]), wz = camera.position.z + double(p[2]);
      const double y_rel = surface.heightAt(wx, wz) - camera.position.y;
      const glm::dvec4 clip = vp * glm::dvec4(double(p[0]), y_rel, double(p[2]), 1.0);
      double err = double(viewport.width_px);
      if (clip.w > 1e-9) {
        const double sx = (clip.x / clip.w * 0.5 + 0.5) * viewport.width_px;
        const double sy = (0.5 - clip.y / clip.w * 0.5) * viewport.height_px;
        err = std::hypot(sx - (px + 0.5), sy - (py + 0.5));
        if (displacement) (*displacement)[i] = glm::vec2(float(sx - (px + 0.5)), float(sy - (py + 0.5)));
      }
      if (coverage && !theirs[i]) {  // terrain in this frame only
        err = std::max(err, coverageError(to_theirs, i));
        ++e.coverage_pixels;
      }
      errors.push_back(err);
    }
  e.measured = true;
  e.coverage = coverage;
  if (coverage) measureSilhouette(ours, theirs, viewport, &e);
  e.pixels = uint32_t(errors.size());
  if (errors.empty()) return e;
  double sum = 0.0;
  for (double v : errors) {
    sum += v;
    e.max_px = std::max(e.max_px, v);
  }
  e.mean_px = sum / double(errors.size());
  e.p95_px = percentileOf(std::move(errors), 0.95);
  return e;
}

double displacementChange(const std::vector<glm::vec2>& a, const std::vector<glm::vec2>& b) {
  if (a.size() != b.size()) return 0.0;
  double sum = 0.0;
  size_t n = 0;
  for (size_t p = 0; p < a.size(); ++p) {
    if (std::isnan(a[p].x) || std::isnan(b[p].x)) continue;
    sum += double(glm::length(a[p] - b[p]));
    ++n;
  }
  return n ? sum / double(n) : 0.0;
}

Status TerrainReference::create(std::shared_ptr<TileSource> colour, TileSource& heights,
                                const TerrainConfig& terrain, const Viewport& viewport,
                                const PlannerConfig& planner, std::unique_ptr<TerrainReference>* out) {
  out->reset();
  if (heights.content() != TileContent::kHeightF32) {
    return Status::error(ErrorCode::kInvalidArgument, "terrain reference: not a height source");
  }
  const PyramidGeometry& g = heights.geometry();
  if (g.levelCount() == 0 || g.width_px * g.height_px > kMaxReferenceSamples) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "terrain reference: " + std::to_string(g.width_px) + "x" +
                             std::to_string(g.height_px) + " samples is more than the " +
                             std::to_string(kMaxReferenceSamples) + " drawn at full resolution");
  }
  std::unique_ptr<TerrainReference> r(new TerrainReference());
  TerrainConfig tc = terrain;
  tc.full_resolution = true;
  tc.clip_tiles = 0;
  if (Status s = TerrainRenderer::create(g, tc, &r->m_mesh); !s) return s;
  Status failed;
  const uint32_t missing = r->m_mesh->preloadCoarseLevels([&](const TileKey& key) {
    auto bytes = std::make_shared<std::vector<uint8_t>>();
    if (Status s = heights.fetch(key, bytes.get()); !s) {
      if (failed.ok()) failed = s;
      return std::shared_ptr<const std::vector<uint8_t>>();
    }
    return std::shared_ptr<const std::vector<uint8_t>>(std::move(bytes));
  });
  if (missing > 0) {
    return failed.ok() ? Status::error(ErrorCode::kCorruptTile, "terrain reference: a height tile of the wrong size")
                         : failed;
  }
  if (Status s = IdealReference::create(std::move(colour), viewport, planner, &r->m_colour); !s) return s;
  if (Status s = r->resize(viewport); !s) return s;
  *out = std::move(r);
  return okStatus();
}

Status TerrainReference::resize(const Viewport& viewport) {
  m_viewport = viewport;
  m_target.reset();
  if (Status s = m_colour->resize(viewport); !s) return s;
  return OffscreenTarget::create(viewport, &m_target);
}

Status TerrainReference::render(const Camera& camera, std::vector<uint8_t>* rgba, std::vector<float>* xyzw) {
  if (Status s = m_colour->prepare(camera, true); !s) return s;
  m_target->bind();
  ClipmapRenderer::clearSky();
  m_mesh->draw(camera, m_viewport, m_colour->renderer());
  m_target->readRgba(rgba);
  if (Status s = m_mesh->readPositions(camera, m_viewport, m_colour->renderer(), xyzw); !s) return s;
  m_target->bind();
  return okStatus();
}

TexelDensity texelDensity(const std::vector<float>& xyzw, const Viewport& viewport, double detail_texels_per_texel) {
  TexelDensity d;
  const uint32_t w = viewport.width_px, h = viewport.height_px;
  if (xyzw.size() != size_t(w) * h * 4) return d;
  std::vector<double> plain, detail;
  auto ground = [&](size_t p) { return xyzw[p * 4 + 3] >= 1.0f; };
  auto across = [&](size_t a, size_t b) {
    return std::hypot(double(xyzw[a * 4] - xyzw[b * 4]), double(xyzw[a * 4 + 2] - xyzw[b * 4 + 2]));
  };
  for (uint32_t y = 0; y + 1 < h; ++y)
    for (uint32_t x = 0; x + 1 < w; ++x) {
      const size_t p = size_t(y) * w + x, right = p + 1, below = p + w;
      if (!ground(p) || !ground(right) || !ground(below)) continue;
      const double texels = std::max(across(p, right), across(p, below));
      plain.push_back(texels);
      detail.push_back(texels < 1.0 ? texels * detail_texels_per_texel : texels);
    }
  d.pixels = uint32_t(plain.size());
  if (plain.empty()) return d;
  d.median = percentileOf(plain, 0.5);
  d.p5 = percentileOf(std::move(plain), 0.05);
  d.detail_median = percentileOf(detail, 0.5);
  d.detail_p5 = percentileOf(std::move(detail), 0.05);
  return d;
}

TerrainFrameError compareTerrainFrames(const std::vector<uint8_t>& streamed_rgba,
                                       const std::vector<float>& streamed_xyzw,
                                       const std::vector<uint8_t>& reference_rgba,
                                       const std::vector<float>& reference_xyzw, const Viewport& viewport) {
  TerrainFrameError e;
  e.error = compareFrames(streamed_rgba, reference_rgba);
  const uint32_t w = viewport.width_px, h = viewport.height_px;
  const size_t pixels = size_t(w) * h;
  if (streamed_rgba.size() != pixels * 4 || reference_rgba.size() != pixels * 4 ||
      streamed_xyzw.size() != pixels * 4 || reference_xyzw.size() != pixels * 4) {
    return e;
  }
  std::vector<uint8_t> same(pixels, 0);
  for (size_t p = 0; p < pixels; ++p) {
    const float* a = streamed_xyzw.data() + p * 4;
    const float* b = reference_xyzw.data() + p * 4;
    same[p] = a[3] == 1.0f && b[3] == 1.0f && std::memcmp(a, b, 3 * sizeof(float)) == 0;
  }
  // w = 1 exactly: outside the streamed rings' transition bands, whose
  // blended normals shade differently at the same position.
  // The texture's level comes from derivatives across the pixel's 2x2 quad
  // (columns 2k, 2k + 1; GL rows, counted from the bottom, 2k, 2k + 1): the
  // geometry agrees at a pixel when it agrees at all four.
  for (uint32_t y = 0; y < h; ++y) {
    const uint32_t gl_row = h - 1 - y;
    if ((gl_row ^ 1u) >= h) continue;
    const uint32_t y2 = h - 1 - (gl_row ^ 1u);
    for (uint32_t x = 0; x < w; ++x) {
      if ((x ^ 1u) >= w) continue;
      const size_t p = size_t(y) * w + x;
      if (!same[p] || !same[size_t(y) * w + (x ^ 1u)] || !same[size_t(y2) * w + x] ||
          !same[size_t(y2) * w + (x ^ 1u)])
        continue;
      ++e.agree_pixels;
      if (std::memcmp(&streamed_rgba[p * 4], &reference_rgba[p * 4], 3) != 0) {
        ++e.agree_mismatched;
        for (size_t c = 0; c < 3; ++c)
          e.agree_max_diff = std::max(e.agree_max_diff,
                                      uint32_t(std::abs(int(streamed_rgba[p * 4 + c]) - int(reference_rgba[p * 4 + c]))));
      }
    }
  }
  return e;
}

}  // namespace clipstream

namespace clipstream {

Status FewestTriangles::create(const ReferenceSurface& surface, TileSource& heights,
                               std::unique_ptr<FewestTriangles>* out) {
  out->reset();
  std::unique_ptr<FewestTriangles> f(new FewestTriangles());
  const int64_t w = int64_t(surface.width()), h = int64_t(surface.height()), p = kFewestPatchCells;
  const std::vector<float>& s = surface.samples();
  auto at = [&](int64_t i, int64_t j) { return s[size_t(std::min(j, h - 1) * w + std::min(i, w - 1))]; };
  // Levels until one node covers the whole surface.
  for (uint32_t l = 0; l < renderer_config::kMaxLevels; ++l) {
    const int64_t span = p << l, step = int64_t(1) << l;
    const int64_t wl = (w + step - 1) / step, hl = (h + step - 1) / step;  // the level's samples
    Level lv;
    lv.nodes_x = std::max<int64_t>((w - 1 + span - 1) / span, 1);
    lv.nodes_y = std::max<int64_t>((h - 1 + span - 1) / span, 1);
    lv.error.assign(size_t(lv.nodes_x * lv.nodes_y), 0.0f);
    // Every level-0 sample against the level-l surface (cells cut along
    // the diagonal, as the renderer's), into every node whose cells hold
    // it (a sample on a border counts for both sides).
    for (int64_t j = 0; j < h && l > 0; ++j)
      for (int64_t i = 0; i < w; ++i) {
        const int64_t ci = i / step, cj = j / step;
        const double u = double(i - ci * step) / double(step), v = double(j - cj * step) / double(step);
        // Level-l sample k is level-0 sample k 2^l, k clamped to the level's
        // last (as the renderer clamps it), not the position to level 0's.
        const int64_t ci1 = std::min(ci + 1, wl - 1), cj1 = std::min(cj + 1, hl - 1);
        const double h00 = at(ci * step, cj * step), h10 = at(ci1 * step, cj * step);
        const double h01 = at(ci * step, cj1 * step), h11 = at(ci1 * step, cj1 * step);
        const double coarse = u >= v ? h00 + u * (h10 - h00) + v * (h11 - h10) : h00 + v * (h01 - h00) + u * (h11 - h01);
        const float e = float(std::abs(double(s[size_t(j * w + i)]) - coarse));
        const int64_t nx0 = i == 0 ? 0 : (i - 1) / span, nx1 = std::min(i / span, lv.nodes_x - 1);
        const int64_t ny0 = j == 0 ? 0 : (j - 1) / span, ny1 = std::min(j / span, lv.nodes_y - 1);
        for (int64_t ny = ny0; ny <= ny1; ++ny)
          for (int64_t nx = nx0; nx <= nx1; ++nx) {
            float& n = lv.error[size_t(ny * lv.nodes_x + nx)];
            n = std::max(n, e);
          }
      }
    f->m_levels.push_back(std::move(lv));
    if (f->m_levels.back().error.size() == 1) break;
  }
  TerrainConfig tc;
  tc.method = TerrainMethod::kQuadtree;
  tc.patch_cells = p;
  tc.mapping = surface.alignment();
  const PyramidGeometry& g = heights.geometry();
  tc.clip_tiles = std::max(g.levels[0].tiles_x, g.levels[0].tiles_y);  // every tile its own slot
  const FewestTriangles* self = f.get();
  if (Status st = TerrainRenderer::create(g, tc, &f->m_quadtree); !st) return st;
  setExactNodeError(*f->m_quadtree, [self](uint32_t level, int64_t x, int64_t y) -> double {
    if (level >= self->m_levels.size()) return INFINITY;
    const Level& lv = self->m_levels[level];
    // Nodes beyond the surface show its edge heights: the nearest node's.
    x = std::clamp<int64_t>(x, 0, lv.nodes_x - 1);
    y = std::clamp<int64_t>(y, 0, lv.nodes_y - 1);
    return double(lv.error[size_t(y * lv.nodes_x + x)]);
  });
  Status fetch_status;
  const uint32_t missing = f->m_quadtree->preloadCoarseLevels(
      [&](const TileKey& key) -> std::shared_ptr<const std::vector<uint8_t>> {
        auto px = std::make_shared<std::vector<uint8_t>>();
        if (Status st = heights.fetch(key, px.get()); !st) {
          fetch_status = st;
          return nullptr;
        }
        return px;
      });
  if (missing > 0) return fetch_status.ok() ? Status::error(ErrorCode::kIo, "fewest triangles: a height tile missing") : fetch_status;
  *out = std::move(f);
  return okStatus();
}

Status FewestTriangles::count(const Camera& camera, const Viewport& viewport, const ClipmapRenderer& colour,
                              const ReferenceSurface& surface, double p95_px, uint64_t* triangles,
                              const std::vector<float>* reference_xyzw) {
  if (m_last_camera && m_last_camera->position == camera.position &&
      m_last_camera->heading_rad == camera.heading_rad && m_last_camera->pitch_rad == camera.pitch_rad &&
      m_last_camera->vfov_rad == camera.vfov_rad && m_last_viewport.width_px == viewport.width_px &&
      m_last_viewport.height_px == viewport.height_px && m_last_p95 == p95_px) {
    *triangles = m_last_count;
    return okStatus();
  }
  m_last_camera.reset();  // set again once this count is whole
  // The p95 error grows with the bound (coarser nodes); bisect the bound
  // on a log scale for the largest whose frame is within p95_px.
  std::vector<float> xyzw;
  Status failed;
  auto measure = [&](double bound_px, uint64_t* count) {
    m_quadtree->setErrorBound(bound_px);
    if (Status s = m_quadtree->readPositions(camera, viewport, colour, &xyzw); !s) {
      failed = s;
      return 0.0;
    }
    *count = m_quadtree->lastFrame().triangles;
    const GeometryError e = geometricError(xyzw, camera, viewport, surface, reference_xyzw);
    return e.pixels == 0 ? 0.0 : e.p95_px;
  };
  double lo = std::log(kMinTerrainErrorPx), hi = std::log(kMaxTerrainErrorPx);
  uint64_t best = 0;
  if (measure(std::exp(hi), &best) > p95_px && failed.ok() && measure(std::exp(lo), &best) <= p95_px) {
    // Even the finest missing counts the finest; else bisect.
    for (int k = 0; k < 10 && failed.ok(); ++k) {
      const double mid = 0.5 * (lo + hi);
      uint64_t t = 0;
      if (measure(std::exp(mid), &t) <= p95_px) {
        lo = mid;
        best = t;
      } else {
        hi = mid;
      }
    }
  }
  if (!failed) return failed;
  m_last_camera = camera;
  m_last_viewport = viewport;
  m_last_p95 = p95_px;
  m_last_count = best;
  *triangles = best;
  return okStatus();
}

}  // namespace clipstream
