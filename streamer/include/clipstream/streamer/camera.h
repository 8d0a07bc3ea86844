// World and camera conventions shared by the streamer (planning) and the
// renderer (drawing). Pure data and functions; no GL.
//
// Thread rule: plain values and pure functions, safe from any thread.
//
// World space: the texture lies on the ground plane y = 0. World x is the
// level-0 texel column, world z the level-0 texel row (both grow from the
// texture's top-left corner), y is height above the ground in level-0 texel
// units. Right-handed: x east, y up, z south. Positions are doubles so a
// 2^26-texel texture keeps sub-texel precision everywhere.
#pragma once

#include <glm/glm.hpp>

#include <cstdint>

namespace clipstream {

struct Viewport {
  uint32_t width_px = 1280;
  uint32_t height_px = 720;
};

// A perspective camera. heading 0 looks toward -z (north), increasing
// heading turns toward +x (east); pitch 0 is level, negative looks down.
struct Camera {
  glm::dvec3 position{0.0, 100.0, 0.0};
  double heading_rad = 0.0;
  double pitch_rad = -0.5;
  double vfov_rad = 1.0471975511965976;  // 60 degrees
  double near_dist = 0.5;                // world units (texels)

  glm::dvec3 forward() const;  // unit view direction
  glm::dvec3 right() const;    // unit, horizontal
  glm::dvec3 up() const;       // unit, completes the basis
};

// View matrix relative to the camera position (the camera sits at the
// origin; the renderer subtracts the camera position in double precision
// before converting to float). Projection is a reverse-free standard GL
// perspective with the given far distance.
glm::dmat4 cameraRelativeView(const Camera& camera);
glm::dmat4 cameraProjection(const Camera& camera, const Viewport& viewport, double far_dist);

// Where the ray through pixel (px, py) (top-left origin, pixel centres at
// +0.5) meets the ground plane. Returns false if it does not (looks up).
bool groundHit(const Camera& camera, const Viewport& viewport, double px, double py,
               glm::dvec2* texel_xz);

}  // namespace clipstream
