// A scene layer's checks and its map from world units to its texels
// (StreamLayer, streamer.h). Pure functions; thread-safe.
#include "streamer_impl.h"

#include <cmath>
#include <string>

namespace clipstream {
namespace {

bool finitePositive(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace

Status checkStreamLayer(const StreamLayer& l, size_t index) {
  const std::string name = "scene layer " + std::to_string(index);
  if (!l.source) return Status::error(ErrorCode::kInvalidArgument, name + " has no source");
  const std::string what = name + " (" + l.source->describe() + ")";
  if (!finitePositive(l.texels_per_unit.x) || !finitePositive(l.texels_per_unit.y))
    return Status::error(ErrorCode::kInvalidArgument,
                         what + ": texels per world unit (" + std::to_string(l.texels_per_unit.x) +
                             ", " + std::to_string(l.texels_per_unit.y) +
                             ") must be finite and positive");
  if (!std::isfinite(l.origin_texel.x) || !std::isfinite(l.origin_texel.y))
    return Status::error(ErrorCode::kInvalidArgument, what + ": the origin texel is not finite");
  const TileContent content = l.source->content();
  if (l.role == LayerRole::kColour && content != TileContent::kRgba8 && content != TileContent::kBc1)
    return Status::error(ErrorCode::kInvalidArgument,
                         what + " is a colour layer but its source hands out heights");
  if (l.role == LayerRole::kElevation && content != TileContent::kHeightF32)
    return Status::error(ErrorCode::kInvalidArgument,
                         what + " is an elevation layer but its source hands out colour");
  if (!(std::isfinite(l.world_per_height) && l.world_per_height >= 0.0))
    return Status::error(ErrorCode::kInvalidArgument,
                         what + " has a height scale that is not finite and >= 0");
  return okStatus();
}

Status checkStreamLayers(const std::vector<StreamLayer>& layers) {
  for (size_t i = 0; i < layers.size(); ++i)
    if (Status s = checkStreamLayer(layers[i], i); !s) return s;
  return okStatus();
}

Camera layerCamera(const StreamLayer& layer, const Camera& world) {
  const glm::dvec2 k = layer.texels_per_unit;
  if (k == glm::dvec2(1.0, 1.0) && layer.origin_texel == glm::dvec2(0.0, 0.0)) return world;
  const double s = std::sqrt(k.x * k.y);
  Camera c = world;
  c.position.x = layer.origin_texel.x + k.x * world.position.x;
  c.position.z = layer.origin_texel.y + k.y * world.position.z;
  c.position.y = world.position.y * s;
  c.near_dist = world.near_dist * s;
  return c;
}

}  // namespace clipstream
