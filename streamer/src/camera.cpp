// Camera basis, matrices and ground picking. See camera.h for the world
// conventions; everything here is double precision so positions on a
// 2^26-texel texture keep sub-texel accuracy.
#include <clipstream/streamer/camera.h>

#include <glm/gtc/matrix_transform.hpp>

#include <cmath>

namespace clipstream {

glm::dvec3 Camera::forward() const {
  // heading 0 looks toward -z; positive heading turns toward +x.
  const double cp = std::cos(pitch_rad);
  return {std::sin(heading_rad) * cp, std::sin(pitch_rad), -std::cos(heading_rad) * cp};
}

glm::dvec3 Camera::right() const {
  // Horizontal even when looking straight down, so the basis never degenerates.
  return {std::cos(heading_rad), 0.0, std::sin(heading_rad)};
}

glm::dvec3 Camera::up() const {
  return glm::cross(right(), forward());
}

glm::dmat4 cameraRelativeView(const Camera& camera) {
  return glm::lookAt(glm::dvec3(0.0), camera.forward(), camera.up());
}

glm::dmat4 cameraProjection(const Camera& camera, const Viewport& viewport, double far_dist) {
  const double aspect =
      double(viewport.width_px) / double(viewport.height_px > 0 ? viewport.height_px : 1);
  return glm::perspective(camera.vfov_rad, aspect, camera.near_dist, far_dist);
}

bool groundHit(const Camera& camera, const Viewport& viewport, double px, double py,
               glm::dvec2* texel_xz) {
  if (viewport.width_px == 0 || viewport.height_px == 0 || camera.position.y <= 0.0) return false;
  const double aspect = double(viewport.width_px) / double(viewport.height_px);
  const double tan_half = std::tan(camera.vfov_rad * 0.5);
  const double ndc_x = 2.0 * px / double(viewport.width_px) - 1.0;
  const double ndc_y = 1.0 - 2.0 * py / double(viewport.height_px);
  const glm::dvec3 dir = camera.forward() + camera.right() * (ndc_x * tan_half * aspect) +
                         camera.up() * (ndc_y * tan_half);
  if (dir.y >= -1e-12) return false;
  const double t = -camera.position.y / dir.y;
  *texel_xz = {camera.position.x + t * dir.x, camera.position.z + t * dir.z};
  return true;
}

}  // namespace clipstream
