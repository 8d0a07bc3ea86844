// How an elevation layer sits under a colour layer: the affine map from
// world space (the colour layer's level-0 texels, y up) to the elevation
// store's samples, and the scale of heights in world units, worked out from
// the two stores' georeferences (docs/terrain.md, "A scene of layers").
//
// Thread-safe: pure functions.
#pragma once

#include <clipstream/store/tile_store.h>

#include <glm/glm.hpp>

#include <string>
#include <vector>

namespace clipstream {

struct LayerAlignment {
  // World units per level-0 elevation sample, along x and z.
  glm::dvec2 world_per_sample{1.0, 1.0};
  // World position of the centre of elevation sample (0, 0).
  glm::dvec2 sample0_world{0.5, 0.5};
  // World units per height unit, the vertical scale included.
  double world_per_height = 1.0;
  // Metres one world unit spans on the ground (the colour texel), x and z.
  glm::dvec2 metres_per_world{1.0, 1.0};
  bool stretched = false;             // placed by extent, not by georeference
  std::vector<std::string> warnings;  // what the user should know (assumed units, stretching)
};


// Aligns `elevation` under `colour`. Both georeferenced in the same CRS:
// by their transforms (an elevation store larger or smaller than the image,
// coarser or finer, is fine). Either without georeference, or `stretch`:
// the elevation's extent is stretched over the colour's, and its heights
// keep the proportions its own georeference (or, without one, the colour's)
// gives them; a warning says so. `vertical_scale` multiplies heights
// (exaggeration; > 0). kInvalidArgument for georeferences in different
// CRSs (the text differs; reproject one, e.g. with gdalwarp), rotated
// transforms, layers that do not overlap, or a non-positive scale.
Status alignElevation(const StoreInfo& colour, const StoreInfo& elevation, double vertical_scale,
                      bool stretch, LayerAlignment* out);

}  // namespace clipstream
