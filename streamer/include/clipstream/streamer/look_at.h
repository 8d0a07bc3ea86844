// Cameras aimed at a point of the map (--look-at X,Y[,HEIGHT]): a map point
// in the colour layer's georeference turned into world units, the ground
// height there from an elevation layer, and the camera that looks at it.
// docs/cli.md, "Cameras in map coordinates".
//
// Thread-safe: pure functions, but for groundHeightAt(), which reads tiles
// of its source on the calling thread (call it before a flight, not per
// frame).
#pragma once

#include <clipstream/store/types.h>
#include <clipstream/streamer/alignment.h>
#include <clipstream/streamer/camera.h>
#include <clipstream/streamer/flight_path.h>
#include <clipstream/streamer/tile_source.h>

#include <glm/glm.hpp>

#include <optional>
#include <string>

namespace clipstream {

// What --look-at names: a map point and, optionally, its height (the
// elevation's unit, before any vertical scale; unset: the ground's).
struct LookAt {
  glm::dvec2 map{0.0, 0.0};
  std::optional<double> height;
  bool lon_lat = false;  // map holds longitude and latitude in degrees (WGS 84)
};

// Longitude and latitude in degrees (WGS 84) as map coordinates of `crs`
// (a store's CRS text: EPSG:n or WKT), by PROJ. kInvalidArgument when the
// CRS is empty or PROJ does not know it, or the point has no place in it.
Status lonLatToMap(const std::string& crs, const glm::dvec2& lon_lat, glm::dvec2* map);

// Map point `map` (the georeference's CRS units) in world units (the
// colour layer's level-0 texels, x and z): the inverse of its transform.
// Without a georeference (present = false) the point is taken as texels.
// kInvalidArgument for a rotated or degenerate transform.
Status mapToWorld(const GeoReference& colour, const glm::dvec2& map, glm::dvec2* world);

// The height (world units, the vertical scale included) of the elevation
// layer `heights` placed by `alignment` at world point `world_xz`: its
// level-0 samples there, bilinear (clamped to its edges). Reads at most
// four level-0 tiles; their errors.
Status groundHeightAt(TileSource& heights, const LayerAlignment& alignment, const glm::dvec2& world_xz,
                      double* world_y);

// A path whose keyframes' x and z are map coordinates of `colour` and whose
// heights are in the elevation's unit (`elevation` null: map units, as
// far as the georeference's x pixel size makes them texels), turned into
// texels in place. Errors as mapToWorld().
Status pathFromMapUnits(const GeoReference& colour, const LayerAlignment* elevation, FlightPath* path);

// The highest point of the elevation layer `heights` placed by `alignment`
// (world x, height, z): the highest sample of its coarsest level of at
// most 16 tiles, then, level by level, the highest sample within two of it
// at each finer level (a local climb: the summit of the coarse level's
// highest hill). Reads at most 16 tiles, then 4 a level; their errors.
Status highestPoint(TileSource& heights, const LayerAlignment& alignment, glm::dvec3* world);

// The middle of the roughest area of the elevation layer `heights` placed
// by `alignment` (world x, ground height, z): on its coarsest level of at
// most 16 tiles, each sample's roughness is the magnitude of the
// heights' Laplacian (curvature: a steady slope is not rough), and the
// roughest area is the square of kRoughAreaFraction of the level's larger
// side whose mean roughness is highest. Reads at most 16 tiles; their
// errors.
Status roughestPoint(TileSource& heights, const LayerAlignment& alignment, glm::dvec3* world);

// The side of the square roughestPoint() scores, as a fraction of the
// DEM's larger side: about the footprint the built-in orbit circles.
inline constexpr double kRoughAreaFraction = 0.125;

// The camera that looks along heading `heading_rad`, pitched `pitch_rad`
// (negative: down), at world point `target` from `distance` world units.
Camera lookAtCamera(const glm::dvec3& target, double distance, double heading_rad, double pitch_rad);

// How far a look-at camera stands from its point by default: a tenth of the
// scene's larger side (as the built-in orbit's height), looking north, 30
// degrees down.
inline constexpr double kLookAtDistanceFraction = 0.1;
inline constexpr double kLookAtPitchRad = -0.5235987755982988;

}  // namespace clipstream
