// TerrainRenderer::readGroundSeen() (terrain.h): the ground a drawn frame
// showed, from its depth, for the streamer's planner.
#include "terrain_impl.h"

#include "gl.h"

#include <cmath>
#include <limits>

namespace clipstream {

void TerrainRenderer::readGroundSeen(const Camera& camera, const Viewport& viewport, const Viewport& framebuffer,
                                     GroundSeen* out) const {
  out->camera = camera;
  out->viewport = viewport;
  groundSeenGrid(viewport, &out->xs, &out->ys);
  const size_t w = out->xs.size(), h = out->ys.size();
  out->points.assign(w * h, glm::dvec3(std::numeric_limits<double>::quiet_NaN()));
  const uint32_t fb_w = framebuffer.width_px, fb_h = framebuffer.height_px;
  if (fb_w == 0 || fb_h == 0 || viewport.width_px == 0 || viewport.height_px == 0) return;
  // The draw's own matrix (setFrameUniforms()), camera-relative.
  const glm::dmat4 inverse = glm::inverse(cameraProjection(camera, viewport, m_impl->farDistance(camera)) *
                                          cameraRelativeView(camera));
  const double sx = double(fb_w) / viewport.width_px, sy = double(fb_h) / viewport.height_px;
  std::vector<float> row(fb_w);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  for (size_t j = 0; j < h; ++j) {
    const uint32_t fb_row = std::min(fb_h - 1, uint32_t(out->ys[j] * sy));  // from the top
    glReadPixels(0, GLint(fb_h - 1 - fb_row), GLsizei(fb_w), 1, GL_DEPTH_COMPONENT, GL_FLOAT, row.data());
    for (size_t i = 0; i < w; ++i) {
      const uint32_t fb_col = std::min(fb_w - 1, uint32_t(out->xs[i] * sx));
      const double depth = row[fb_col];
      if (!(depth < 1.0)) continue;  // the sky's clear: no ground here
      const glm::dvec4 ndc{2.0 * (fb_col + 0.5) / fb_w - 1.0, 1.0 - 2.0 * (fb_row + 0.5) / fb_h, 2.0 * depth - 1.0,
                           1.0};
      const glm::dvec4 p = inverse * ndc;
      if (!(std::abs(p.w) > 0.0)) continue;
      out->points[j * w + i] = camera.position + glm::dvec3(p) / p.w;
    }
  }
}

}  // namespace clipstream
