#include <clipstream/streamer/alignment.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>

namespace clipstream {
namespace {

// Metres per degree of longitude and latitude (WGS84 mean, good to 0.5 %).
constexpr double kMetresPerDegreeLat = 110574.0;
constexpr double kMetresPerDegreeLonAtEquator = 111320.0;

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

// The factor of the last UNIT["...", f] or LENGTHUNIT["...", f] in WKT.
bool lastUnitFactor(const std::string& wkt, double* factor) {
  size_t at = std::string::npos;
  for (const char* key : {"LENGTHUNIT[", "UNIT["}) {
    const size_t k = wkt.rfind(key);
    if (k != std::string::npos && (at == std::string::npos || k > at)) at = k;
  }
  if (at == std::string::npos) return false;
  const size_t comma = wkt.find(',', at);
  if (comma == std::string::npos) return false;
  char* end = nullptr;
  const double v = std::strtod(wkt.c_str() + comma + 1, &end);
  if (end == wkt.c_str() + comma + 1 || !(v > 0.0) || !std::isfinite(v)) return false;
  *factor = v;
  return true;
}

bool isGeographic(const std::string& crs) {
  if (startsWith(crs, "GEOGCS[") || startsWith(crs, "GEOGCRS[")) return true;
  if (startsWith(crs, "EPSG:")) {
    const long code = std::strtol(crs.c_str() + 5, nullptr, 10);
    return code >= 4000 && code < 5000;
  }
  return false;
}

bool rotated(const GeoReference& g) { return g.transform[2] != 0.0 || g.transform[4] != 0.0; }

}  // namespace

glm::dvec2 metresPerCrsUnit(const std::string& crs, double latitude_deg, bool* assumed) {
  *assumed = false;
  if (isGeographic(crs)) {
    const double lat = std::clamp(latitude_deg, -89.0, 89.0) * (3.14159265358979323846 / 180.0);
    return {kMetresPerDegreeLonAtEquator * std::cos(lat), kMetresPerDegreeLat};
  }
  double factor = 1.0;
  if ((startsWith(crs, "PROJCS[") || startsWith(crs, "PROJCRS[")) && lastUnitFactor(crs, &factor)) {
    return {factor, factor};
  }
  *assumed = true;
  return {1.0, 1.0};
}

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
                             "); reproject one to the other's, e.g. with gdalwarp -t_srs");
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
    const glm::dvec2 unit = metresPerCrsUnit(cg.crs, lat, &assumed);
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
      const glm::dvec2 unit = metresPerCrsUnit(eg.crs, lat, &assumed);
      sample_metres = {std::abs(eg.transform[1]) * unit.x, std::abs(eg.transform[5]) * unit.y};
    } else if (cg.present) {
      const double lat = cg.transform[3] + cg.transform[5] * ch * 0.5;
      const glm::dvec2 unit = metresPerCrsUnit(cg.crs, lat, &assumed);
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
                            " m); the scene is drawn with square texels and heights at their mean");
  }
  out->world_per_height = metres_per_height / metres_per_world * vertical_scale;
  return okStatus();
}

}  // namespace clipstream
