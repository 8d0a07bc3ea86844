#include <clipstream/streamer/alignment.h>

#include <algorithm>
#include <cmath>

namespace clipstream {
namespace {

bool rotated(const GeoReference& g) { return g.transform[2] != 0.0 || g.transform[4] != 0.0; }

// The ground size of a CRS unit as a vector; *assumed when not known here.
glm::dvec2 unitMetres(const std::string& crs, double latitude_deg, bool* assumed) {
  const CrsUnitMetres u = metresPerCrsUnit(crs, latitude_deg);
  *assumed = u.assumed;
  return {u.x, u.y};
}

}  // namespace

Status alignElevation(const StoreInfo& colour, const StoreInfo& elevation, double vertical_scale,
                      bool stretch, LayerAlignment* out) {
  *out = LayerAlignment{};
  if (!elevation.elevation.present) {
    return Status::error(ErrorCode::kInvalidArgument, "the elevation layer is not an elevation store");
  }
  if (!(vertical_scale > 0.0) || !std::isfinite(vertical_scale)) {
    return Status::error(ErrorCode::kInvalidArgument, "vertical scale must be a positive number");
  }
  const GeoReference& cg = colour.geo;
  const GeoReference& eg = elevation.geo;
  const double cw = double(colour.geometry.width_px), ch = double(colour.geometry.height_px);
  const double ew = double(elevation.geometry.width_px), eh = double(elevation.geometry.height_px);
  const double metres_per_height = metresPerUnit(elevation.elevation.units);
  if ((cg.present && rotated(cg)) || (eg.present && rotated(eg))) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "rotated georeferences are not supported (warp to north-up first, e.g. "
                         "with gdalwarp)");
  }
  const bool by_georef = !stretch && cg.present && eg.present;
  if (by_georef && cg.crs != eg.crs && !cg.crs.empty() && !eg.crs.empty()) {
    return Status::error(ErrorCode::kInvalidArgument,
                         "the colour and elevation stores use different coordinate systems (" +
                             printableText(cg.crs, 80) + " and " + printableText(eg.crs, 80) +
                             "); tile one again in the other's CRS, e.g. clipstream-tile DEM "
                             "OUTPUT --t-srs '" + printableText(cg.crs.size() <= 40 ? cg.crs : "<the colour's CRS>", 80) +
                             "' (or --t-srs with the colour's source raster file)");
  }
  if (by_georef) {
    // Elevation sample (i, j) has its centre at pixel (i + 0.5, j + 0.5).
    const double* t = cg.transform;
    const double* e = eg.transform;
    auto toWorld = [&](double col, double row) {
      const double x = e[0] + col * e[1], y = e[3] + row * e[5];
      return glm::dvec2((x - t[0]) / t[1], (y - t[3]) / t[5]);
    };
    out->world_per_sample = {e[1] / t[1], e[5] / t[5]};
    out->sample0_world = toWorld(0.5, 0.5);
    // Overlap of the two extents, in world units.
    const glm::dvec2 a = toWorld(0.0, 0.0), b = toWorld(ew, eh);
    const double x0 = std::max(0.0, std::min(a.x, b.x)), x1 = std::min(cw, std::max(a.x, b.x));
    const double z0 = std::max(0.0, std::min(a.y, b.y)), z1 = std::min(ch, std::max(a.y, b.y));
    if (!(x1 > x0 && z1 > z0) || !(out->world_per_sample.x > 0.0) || !(out->world_per_sample.y > 0.0)) {
      return Status::error(ErrorCode::kInvalidArgument,
                           "the elevation store does not overlap the colour store (their "
                           "georeferences place them apart, or one is mirrored)");
    }
    if (x1 - x0 < cw * 0.999 || z1 - z0 < ch * 0.999) {
      out->warnings.push_back("the elevation store covers only part of the colour image; the rest "
                              "is drawn at the nearest edge height");
    }
    const double lat = cg.transform[3] + cg.transform[5] * ch * 0.5;
    bool assumed = false;
    const glm::dvec2 unit = unitMetres(cg.crs, lat, &assumed);
    out->metres_per_world = {std::abs(t[1]) * unit.x, std::abs(t[5]) * unit.y};
    if (assumed) {
      out->warnings.push_back("the coordinate system's unit is not known here (" +
                              (cg.crs.empty() ? std::string("no CRS text") : printableText(cg.crs, 40)) +
                              "); metres assumed for the vertical scale");
    }
  } else {
    out->stretched = true;
    out->world_per_sample = {cw / ew, ch / eh};
    out->sample0_world = {0.5 * out->world_per_sample.x, 0.5 * out->world_per_sample.y};
    // Heights keep the elevation's own proportions: a sample spans what its
    // georeference says (or, without one, what a colour texel does).
    glm::dvec2 sample_metres{1.0, 1.0};
    bool assumed = true;
    if (eg.present) {
      const double lat = eg.transform[3] + eg.transform[5] * eh * 0.5;
      const glm::dvec2 unit = unitMetres(eg.crs, lat, &assumed);
      sample_metres = {std::abs(eg.transform[1]) * unit.x, std::abs(eg.transform[5]) * unit.y};
    } else if (cg.present) {
      const double lat = cg.transform[3] + cg.transform[5] * ch * 0.5;
      const glm::dvec2 unit = unitMetres(cg.crs, lat, &assumed);
      sample_metres = glm::dvec2(std::abs(cg.transform[1]) * unit.x, std::abs(cg.transform[5]) * unit.y) *
                      out->world_per_sample;
    }
    out->metres_per_world = sample_metres / out->world_per_sample;
    out->warnings.push_back(std::string("the elevation store is stretched over the colour image") +
                            (stretch ? " (asked for)" : " (one of them has no georeference)") +
                            "; its heights keep its own proportions");
    if (assumed) {
      out->warnings.push_back(std::string("the ") + (eg.present ? "elevation" : "colour") +
                              " store's coordinate unit is not known here; metres assumed for the "
                              "vertical scale");
    }
  }
  // World units are square texels: heights use the mean texel size.
  const double metres_per_world = 0.5 * (out->metres_per_world.x + out->metres_per_world.y);
  if (std::abs(out->metres_per_world.x - out->metres_per_world.y) > 0.01 * metres_per_world) {
    out->warnings.push_back("colour texels are not square on the ground (" +
                            std::to_string(out->metres_per_world.x) + " x " +
                            std::to_string(out->metres_per_world.y) +
                            " m); the scene is drawn with square texels and heights at their mean "
                            "(tile a geographic input with --t-srs auto: a UTM zone)");
  }
  out->world_per_height = metres_per_height / metres_per_world * vertical_scale;
  return okStatus();
}

}  // namespace clipstream
