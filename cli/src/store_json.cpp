#include <clipstream/cli/store_json.h>

#include <vector>

namespace clipstream::cli {

nlohmann::json georeferenceJson(const GeoReference& geo) {
  if (!geo.present) return nullptr;
  const double* t = geo.transform;
  return {{"transform", std::vector<double>(t, t + 6)},
          {"origin", {t[0], t[3]}},
          {"pixel_size", {t[1], t[5]}},
          {"crs", geo.crs}};
}

nlohmann::json elevationJson(const ElevationInfo& e) {
  return {{"units", heightUnitsName(e.units)},
          {"units_assumed", e.units_assumed},
          {"scale", e.scale},
          {"offset", e.offset},
          {"quantised", e.quantised},
          {"error_bound", e.quantised ? e.scale / 2 : 0.0},
          {"max_error", e.max_error},
          {"min_height", e.min_height},
          {"max_height", e.max_height},
          {"nodata", e.has_nodata ? nlohmann::json(e.nodata) : nlohmann::json()},
          {"filled_samples", e.filled_samples}};
}

nlohmann::json shardJson(const ShardInfo& s) {
  return {{"index", s.index},
          {"count", s.count},
          {"full_width_px", s.full_width_px},
          {"full_height_px", s.full_height_px},
          {"x0_px", s.x0_px},
          {"y0_px", s.y0_px},
          {"owned_levels", s.owned_levels}};
}

const char* layerName(const ElevationInfo& e) { return e.present ? "elevation" : "colour"; }

}  // namespace clipstream::cli
