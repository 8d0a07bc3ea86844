// What the planner needs to know of the ground a view sees: where it lies
// (x, z points whose bounding box is the footprint) and how near it comes.
// Two ways to find it: the flat plane (planner.cpp) and the terrain's
// per-tile height bounds (terrain_footprint.cpp).
//
// Thread rule: pure functions.
#pragma once

#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/terrain_bounds.h>

#include <glm/glm.hpp>

#include <vector>

namespace clipstream {

struct Footprint {
  std::vector<glm::dvec2> points;  // ground points (x, z); the footprint is their bounding box
  double nearest_dist = 0.0;       // nearest visible ground point (3D distance), a lower bound
  bool any_hit = false;
};

// The footprint of the ground `camera` sees over the terrain `terrain`
// (bounds non-null), up to far_h from the camera's nadir, in the planning
// space of `terrain` (docs/terrain.md, "Planning against the terrain"):
//  - nearest_dist: the least distance from the camera to any terrain box
//    (a tile's x/z extent times its height range) inside the frustum,
//    boxes refined from coarse to fine while large for their distance;
//  - points: where a grid of rays over the screen meets the boxes, from
//    the first box a ray may touch to the point where it is surely under
//    the ground (so ground hidden behind a slope is left out).
Footprint terrainFootprint(const TerrainView& terrain, const Viewport& viewport, const Camera& camera,
                           double far_h);

}  // namespace clipstream
