#include <clipstream/eval/terrain_accuracy.h>

#include <clipstream/eval/metrics.h>

#include <algorithm>
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
  return Status::ok();
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

GeometryError geometricError(const std::vector<float>& xyzw, const Camera& camera,
                             const Viewport& viewport, const ReferenceSurface& surface) {
  GeometryError e;
  const size_t pixels = size_t(viewport.width_px) * viewport.height_px;
  if (xyzw.size() < pixels * 4) return e;
  const glm::dmat4 vp = cameraProjection(camera, viewport, 1e9) * cameraRelativeView(camera);
  std::vector<double> errors;
  errors.reserve(pixels / 2);
  for (uint32_t py = 0; py < viewport.height_px; ++py)
    for (uint32_t px = 0; px < viewport.width_px; ++px) {
      const float* p = xyzw.data() + (size_t(py) * viewport.width_px + px) * 4;
      if (p[3] != 1.0f) continue;
      const double wx = camera.position.x + double(p[0]), wz = camera.position.z + double(p[2]);
      const double y_rel = surface.heightAt(wx, wz) - camera.position.y;
      const glm::dvec4 clip = vp * glm::dvec4(double(p[0]), y_rel, double(p[2]), 1.0);
      double err = double(viewport.width_px);
      if (clip.w > 1e-9) {
        const double sx = (clip.x / clip.w * 0.5 + 0.5) * viewport.width_px;
        const double sy = (0.5 - clip.y / clip.w * 0.5) * viewport.height_px;
        err = std::hypot(sx - (px + 0.5), sy - (py + 0.5));
      }
      errors.push_back(err);
    }
  e.measured = true;
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

}  // namespace clipstream
