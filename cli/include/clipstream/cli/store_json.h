// The store's properties as JSON, one vocabulary for every program that
// writes them (clipstream-info --json, clipstream-tile --json-summary):
// the same thing has the same key everywhere (docs/cli.md, "JSON outputs").
//
// Pure functions; any thread.
#pragma once

#include <nlohmann/json.hpp>

#include "clipstream/store/tile_store.h"
#include "clipstream/store/types.h"

namespace clipstream::cli {

// {"transform": [6], "origin": [x, y], "pixel_size": [x, y], "crs": "..."},
// or null for a store without a georeference.
nlohmann::json georeferenceJson(const GeoReference& geo);

// {"units", "units_assumed", "scale", "offset", "quantised", "error_bound",
//  "max_error", "min_height", "max_height", "nodata" (null if none),
//  "filled_samples"}. Only meaningful when `e.present`.
nlohmann::json elevationJson(const ElevationInfo& e);

// {"index", "count", "full_width_px", "full_height_px", "x0_px", "y0_px",
//  "owned_levels"}. Only meaningful when `s.present`.
nlohmann::json shardJson(const ShardInfo& s);

// "elevation" or "colour".
const char* layerName(const ElevationInfo& e);

}  // namespace clipstream::cli
